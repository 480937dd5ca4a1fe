"""Tables of the report in display form (strings, units in the column names, sizes in mm, fractions
in %): the process settings, the speeds, the comparison table in four parts, the design space and
the calibration check (docs/validation.md, "Report": Tables).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.config import Granulator, Pbm, SizeDistribution
from pbmdem.pbm.results import FLOOR_LIMIT
from pbmdem.plotting import ML_PER_MIN

from .display import MM, PERCENT, mm, number, percent, value_range, yes_no

#: m3 -> mL
ML = 1e6
SETTING_COLUMNS = ["setting", "value", "unit", "config key"]


def _joined(values, spec: str) -> str:
    return ", ".join(format(float(v), spec) for v in values)


def liquid_solid_ratio(pbm: Pbm, bed_solid_volume: float) -> float:
    """Liquid/solid volume ratio L/S at the end of the liquid addition (docs/validation.md, "Report")."""
    sprayed = pbm.liquid_addition.rate * pbm.process.liquid_addition_time
    return pbm.initial.liquid_content + sprayed / bed_solid_volume


def success_model(pbm: Pbm) -> str:
    """The success probability psi_ij in words (docs/pbm.md, "Success probability")."""
    s = pbm.aggregation.success
    if s.model == "step":
        text = f"step: p = 1 where the surface-liquid fraction phi >= {s.threshold:g}, else 0"
    elif s.model == "logistic":
        text = f"logistic in the surface-liquid fraction phi: threshold {s.threshold:g}, width {s.width:g}"
    else:
        text = s.model
    if s.velocity_model == "stokes":
        st = s.stokes
        text += (
            f"; and the Stokes criterion (binder viscosity {st.binder_viscosity:g} Pa s, restitution "
            f"{st.restitution:g}, asperity height {st.asperity_height:g} m, granule density "
            f"{st.granule_density:g} kg/m3)"
        )
    else:
        text += "; independent of the impact velocity"
    return text


def process_settings(
    pbm: Pbm,
    bed_solid_volume: float,
    feed_name: str,
    feed: SizeDistribution,
    coupling_intervals: int,
    dem_replicates: int,
    dem_sampling_time: float,
) -> pd.DataFrame:
    """The settings of the validation batch, one literal row per setting in the report's order."""
    p, agg = pbm.process, pbm.aggregation
    added = pbm.liquid_addition.rate * p.liquid_addition_time
    grid = pbm.grid
    bins = f"{grid.bins} bins" if grid.bins else f"up to {MM * grid.max_diameter:g} mm"
    start = "the smallest feed class" if grid.min_diameter is None else f"{MM * grid.min_diameter:g} mm"
    rows = [
        ("feed size distribution", feed_name, "-", "validation.distribution"),
        ("feed size classes", _joined(MM * pd.Series(feed.diameters), ".2f"), "mm", f"size_distributions.{feed_name}"),
        (
            "feed number fractions",
            _joined(PERCENT * pd.Series(feed.number_fractions), ".1f"),
            "%",
            f"size_distributions.{feed_name}",
        ),
        (
            "bed solid volume (DEM bed = PBM population)",
            number(ML * bed_solid_volume),
            "mL",
            "dem.bed_height, dem.packing_fraction, granulator.bowl",
        ),
        ("dry premixing", value_range(0.0, p.spray_start, 1), "s", "pbm.process.premixing_time"),
        (
            "liquid addition (spray window)",
            value_range(p.spray_start, p.spray_end, 1),
            "s",
            "pbm.process.liquid_addition_time",
        ),
        ("wet massing", value_range(p.spray_end, p.end, 1), "s", "pbm.process.wet_massing_time"),
        ("batch length", number(p.end), "s", "pbm.process"),
        ("binder addition rate", number(ML_PER_MIN * pbm.liquid_addition.rate), "mL/min", "pbm.liquid_addition.rate"),
        ("binder sprayed in total", number(ML * added), "mL", "pbm.liquid_addition"),
        (
            "binder distribution over the granules",
            pbm.liquid_addition.distribution,
            "-",
            "pbm.liquid_addition.distribution",
        ),
        (
            "initial liquid content L/S",
            number(pbm.initial.liquid_content),
            "m3 liquid / m3 solid",
            "pbm.initial.liquid_content",
        ),
        (
            "liquid/solid ratio L/S at the end of the liquid addition",
            number(liquid_solid_ratio(pbm, bed_solid_volume)),
            "m3 liquid / m3 solid",
            "pbm.liquid_addition",
        ),
        ("initial porosity", percent(pbm.initial.porosity, 1), "%", "pbm.initial.porosity"),
        ("consolidation rate", number(pbm.consolidation.rate), "1/s", "pbm.consolidation.rate"),
        ("minimum porosity", percent(pbm.consolidation.min_porosity, 1), "%", "pbm.consolidation.min_porosity"),
        ("aggregation rate constant beta0", number(agg.beta0), "-", "pbm.aggregation.beta0"),
        ("success probability", success_model(pbm), "-", "pbm.aggregation.success"),
        ("aggregation scheme", agg.scheme, "-", "pbm.aggregation.scheme"),
        (
            "collision-frequency refresh",
            number(agg.frequency_update_interval),
            "s",
            "pbm.aggregation.frequency_update_interval",
        ),
        ("PBM grid", f"{bins}, volume ratio {grid.ratio:.4g}, first pivot {start}", "-", "pbm.grid"),
        ("coupling intervals per batch", str(coupling_intervals), "-", "validation.coupling_intervals"),
        ("coupling interval length", number(p.end / coupling_intervals), "s", "validation.coupling_intervals"),
        ("PBM-DEM replicates (DEM insertion seeds)", str(dem_replicates), "-", "validation.dem_replicates"),
        (
            "DEM sampling window per coupling interval (at least)",
            number(dem_sampling_time),
            "s",
            "validation.dem_sampling_time",
        ),
    ]
    return pd.DataFrame(rows, columns=SETTING_COLUMNS)


def speeds(granulator: Granulator, validation_rpm, grid_rpm) -> pd.DataFrame:
    """Every impeller speed of the DEM training grid and of the validation: tip speed and Froude number."""
    grid = {float(r) for r in grid_rpm}
    validation = {float(r) for r in validation_rpm}
    rows = []
    for rpm in sorted(grid | validation):
        role = " and ".join(
            name for name, speeds in (("DEM training grid", grid), ("validation", validation)) if rpm in speeds
        )
        rows.append(
            {
                "impeller speed (rpm)": f"{rpm:g}",
                "tip speed (m/s)": f"{granulator.tip_speed(rpm):.3f}",
                "Froude number at the tip (-)": f"{granulator.froude_number(rpm):.3g}",
                "used in": role,
            }
        )
    return pd.DataFrame(rows)


def _mean_sd(mean, sd, n) -> str:
    text = number(mean, ".3f")
    return text if number(sd) == "n/a" else f"{text} +- {float(sd):.3f} (n = {int(n)})"


def _of(count, total) -> str:
    return "n/a" if number(count) == "n/a" else f"{int(count)} of {int(total)}"


def comparison_tables(table: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The comparison table in display form, split to fit a page: name -> table
    (`d50`, `tails` (d10 and d90), `accuracy`, `cost`, `domain`), each keyed by the speed."""
    out = {"d50": [], "tails": [], "accuracy": [], "cost": [], "domain": []}
    for r in table.itertuples():
        speed = f"{r.rpm:g}"
        members = (
            value_range(r.ann_member_d50_end_min_mm, r.ann_member_d50_end_max_mm)
            if hasattr(r, "ann_member_d50_end_min_mm")
            else "n/a"
        )
        out["d50"].append(
            {
                "speed (rpm)": speed,
                "in DEM training grid (yes/no)": yes_no(r.in_training_grid),
                "d50 at start (mm)": number(r.d50_start_mm, ".3f"),
                "PBM-DEM d50 at end, mean +- SD (mm)": _mean_sd(
                    r.d50_end_dem_mm, r.d50_end_dem_sd_mm, r.n_dem_replicates
                ),
                "PBM-DEM replicates' range (mm)": value_range(r.d50_end_dem_min_mm, r.d50_end_dem_max_mm),
                "PBM-ANN d50 at end (mm)": number(r.d50_end_ann_mm, ".3f"),
                "PBM-ANN members' range (mm)": members,
                "PBM-constant d50 at end (mm)": number(r.d50_end_constant_mm, ".3f"),
            }
        )
        tails = {"speed (rpm)": speed}
        for q in ("d10", "d90"):
            ends = (getattr(r, f"{q}_end_dem_min_mm"), getattr(r, f"{q}_end_dem_max_mm"))
            tails[f"PBM-DEM {q} at end, replicates' range (mm)"] = value_range(*ends)
            tails[f"PBM-ANN {q} at end (mm)"] = number(getattr(r, f"{q}_end_ann_mm"), ".3f")
            tails[f"PBM-ANN {q} outside the PBM-DEM band, largest (%)"] = percent(
                getattr(r, f"ann_{q}_outside_band_max")
            )
        out["tails"].append(tails)
        out["accuracy"].append(
            {
                "speed (rpm)": speed,
                "PBM-ANN d50 error, largest (%)": percent(r.ann_d50_rel_error_max),
                "PBM-ANN d50 error at end (%)": percent(r.ann_d50_rel_error_end),
                "PBM-ANN d50 outside the PBM-DEM band, largest (%)": percent(r.ann_d50_outside_band_max),
                "a PBM-DEM replicate against the others, largest (%)": percent(r.dem_replicate_d50_rel_error_max),
                "PBM-constant d50 error, largest (%)": percent(r.constant_d50_rel_error_max),
                "PBM-constant d50 error at end (%)": percent(r.constant_d50_rel_error_end),
                "PBM-constant d50 outside the band, largest (%)": percent(r.constant_d50_outside_band_max),
            }
        )
        out["cost"].append(
            {
                "speed (rpm)": speed,
                "PBM-DEM CPU time, LIGGGHTS + PBM, mean of a loop (s)": number(r.pbm_dem_cpu_s, ".4g"),
                "PBM-DEM wall time, mean of a loop (s)": number(r.pbm_dem_wall_s, ".4g"),
                "PBM-ANN CPU time, median of warm batches (s)": number(r.pbm_ann_cpu_s, ".3g"),
                "PBM-ANN wall time, median of warm batches (s)": number(r.pbm_ann_wall_s, ".3g"),
                "PBM-ANN first batch of its process, wall (s)": number(r.pbm_ann_first_batch_wall_s, ".3g"),
                "CPU-time ratio PBM-DEM / PBM-ANN (-)": number(r.cpu_time_ratio_dem_over_ann, ".0f"),
                "wall-time ratio PBM-DEM / PBM-ANN (-)": number(r.wall_time_ratio_dem_over_ann, ".0f"),
            }
        )
        out["domain"].append(
            {
                "speed (rpm)": speed,
                "PBM-ANN intervals outside the training domain (of all)": _of(
                    r.ann_out_of_domain_intervals, r.ann_intervals
                ),
                "PBM-ANN out-of-domain warnings (count)": number(r.ann_out_of_domain_warnings, ".0f"),
                "PBM-constant calibration out-of-domain warnings (count)": number(
                    r.constant_calibration_out_of_domain_warnings, ".0f"
                ),
                "grid floor: merged fragments per final granule, PBM-DEM / PBM-ANN / PBM-constant (%)": " / ".join(
                    _floor(getattr(r, column, float("nan")))
                    for column in ("dem_merged_fraction_max", "ann_merged_fraction", "constant_merged_fraction")
                ),
            }
        )
    return {name: pd.DataFrame(rows) for name, rows in out.items()}


def _floor(fraction) -> str:
    """A share of a run's final number merged at the grid floor in %, FLAGGED above FLOOR_LIMIT."""
    if fraction is None or not np.isfinite(float(fraction)):
        return "n/a"
    shown = f"{PERCENT * float(fraction):.3g}"
    return shown + (" FLAGGED" if float(fraction) > FLOOR_LIMIT else "")


def design_space_table(table: pd.DataFrame, third_key: str) -> pd.DataFrame:
    """The design-space table (`results/design/design_space.csv`) in display form."""
    third = third_key.split(".")[-1].replace("_", " ")
    return pd.DataFrame(
        {
            "rpm": [f"{r:g}" for r in table.rpm],
            "binder (mL/min)": [f"{ML_PER_MIN * q:.2f}" for q in table.liquid_rate],
            third: [f"{v:g}" for v in table[third_key]],
            "d50 (mm)": [mm(v, 2) for v in table.d50],
            "d50 members (mm)": [
                value_range(MM * lo, MM * hi, 2) for lo, hi in zip(table.d50_member_min, table.d50_member_max)
            ],
            "d90 (mm)": [mm(v, 2) for v in table.d90],
            "d90 members (mm)": [
                value_range(MM * lo, MM * hi, 2) for lo, hi in zip(table.d90_member_min, table.d90_member_max)
            ],
            "status": [s.replace("_", " ") for s in table.spec_status],
        }
    )


def calibration_check_table(check: pd.DataFrame, confidence: float) -> pd.DataFrame:
    """The recovery table of the calibration check (`results/design/calibration_check.csv`) in display form."""
    return pd.DataFrame(
        {
            "case": check.case,
            "parameter": check.parameter,
            "true": [number(v) for v in check["true"]],
            "estimate": [number(v) for v in check.estimate],
            f"{PERCENT * confidence:g} % interval": [
                f"{number(lo)} - {number(hi)}" for lo, hi in zip(check.ci_low, check.ci_high)
            ],
            "recovered": [yes_no(v) for v in check.recovered],
            "sd ln (measurement / surrogate)": [
                f"{a:.3f} / {b:.3f}" for a, b in zip(check.sd_ln_measurement, check.sd_ln_surrogate)
            ],
            "chi2 / dof": [number(v, ".3g") for v in check.chi2_reduced],
        }
    )
