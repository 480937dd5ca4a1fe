"""The report's figures, tables, statements and provenance on synthetic result folders written in
the workflow's layout (results/validation/rpm<rpm>/...; fast, no LIGGGHTS). The report on the
real tiny workflow, `snakemake --report report.zip` included, is tested in tests/test_workflow.py."""

from __future__ import annotations

import json
import re
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pbmdem.pbm.results import mass_quantiles
from pbmdem.readers import InputFileError
from pbmdem.surrogate.domain import OutOfDomainWarning

RPM = "600"
TIMES = np.linspace(0.0, 20.0, 21)
DIAMETERS = [0.002, 0.0025, 0.003]


def _summary(growth: float) -> pd.DataFrame:
    f = 1.0 + growth * np.clip((TIMES - 10.0) / 10.0, 0.0, None)
    return pd.DataFrame(
        {
            "time": TIMES,
            "d10": 0.0019 * f,
            "d50": 0.0026 * f,
            "d90": 0.0032 * f,
            "mean_liquid_content": 0.035 * np.clip(TIMES - 2.0, 0.0, 10.0),
            "mean_porosity": 0.2 + 0.3 * np.exp(-0.2 * TIMES),
        }
    )


def _bins(growth: float) -> pd.DataFrame:
    d = 0.0015 * 2.0 ** (np.arange(8) / 3.0)
    rows = []
    for t in TIMES:
        centre = 0.0026 * (1.0 + growth * max(t - 10.0, 0.0) / 10.0)
        q = np.exp(-0.5 * (np.log(d / centre) / 0.2) ** 2)
        rows += [
            {"time": t, "bin": k, "diameter": d[k], "mass_fraction": q[k] / q.sum(), "mass_density_lnd": q[k]}
            for k in range(len(d))
        ]
    return pd.DataFrame(rows)


def _intervals(method: str, frequency: float, outside: dict[int, str] | None = None) -> pd.DataFrame:
    rows = []
    for k, (t0, t1) in enumerate(((0.0, 10.0), (10.0, 20.0))):
        row = {
            "interval": k,
            "t_start": t0,
            "t_end": t1,
            "rpm": float(RPM),
            "method": method,
            "classes": 3,
            "class_diameters": json.dumps(DIAMETERS),
            "class_counts": json.dumps([230, 138, 92]),
            "sample_particles": 460,
            "class_frequencies": json.dumps([frequency * (1 + 0.1 * j) for j in range(6)]),
            "mean_frequency_per_pair": frequency * (1 + 0.05 * k),
            "provider_wall_time_s": 1.0,
            "pbm_wall_time_s": 0.1,
        }
        if method == "pbm_ann":
            message = (outside or {}).get(k)
            row.update(out_of_domain=message or np.nan, out_of_domain_count=1 if message else 0)
        rows.append(row)
    return pd.DataFrame(rows)


def _write_run(folder: Path, growth: float, timing: dict, intervals: pd.DataFrame | None = None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    _summary(growth).to_csv(folder / "summary.csv", index=False)
    bins = _bins(growth)
    bins.to_csv(folder / "bins.csv", index=False)
    bins[bins.time == TIMES[-1]].to_csv(folder / "final_bins.csv", index=False)
    (folder / "timing.json").write_text(json.dumps(timing))
    if intervals is not None:
        intervals.to_csv(folder / "intervals.csv", index=False)


def write_validation(root: Path, replicates: int = 2, outside: dict[int, str] | None = None) -> Path:
    """A validation folder of one speed in the workflow's layout, with bands.csv and comparison.csv."""
    from pbmdem.validation.comparison import bands_of, compare
    from pbmdem.validation.results import load_speed

    vdir = root / "validation"
    speed = vdir / f"rpm{RPM}"
    for k in range(replicates):
        _write_run(
            speed / "pbm_dem" / f"rep{k}",
            0.04 + 0.01 * k,
            {
                "total_wall_time_s": 300.0,
                "provider_wall_time_s": 290.0,
                "pbm_wall_time_s": 10.0,
                "dem_cpu_time_s": 280.0,
                "pbm_cpu_time_s": 10.0,
            },
            _intervals("pbm_dem", 0.28 + 0.01 * k),
        )
    _write_run(
        speed / "pbm_ann",
        0.045,
        {
            "total_wall_time_s": 0.2,
            "provider_wall_time_s": 0.1,
            "pbm_wall_time_s": 0.1,
            "warm_wall_time_s_median": 0.2,
            "warm_cpu_time_s_median": 0.1,
        },
        _intervals("pbm_ann", 0.29, outside),
    )
    members = pd.concat(
        [_summary(0.044 + 0.002 * m).assign(member=m, out_of_domain_intervals=len(outside or {})) for m in range(2)]
    )
    members.to_csv(speed / "pbm_ann" / "members.csv", index=False)
    _write_run(
        speed / "pbm_constant",
        0.05,
        {
            "total_wall_time_s": 0.05,
            "provider_wall_time_s": 0.0,
            "pbm_wall_time_s": 0.05,
            "frequency": 0.29,
            "out_of_domain": "",
            "out_of_domain_count": 0,
        },
    )
    bands_of(load_speed(vdir, RPM, replicates)).to_csv(speed / "bands.csv", index=False)
    compare(vdir, [RPM], [600.0], replicates).to_csv(root / "comparison.csv", index=False)
    return vdir


class FakeSurrogate:
    """Frequencies of a constant; warns out-of-domain on the samples of the rpm in `outside_at`."""

    def __init__(self, outside_at=()):
        self.outside_at = set(outside_at)

    def frequency_matrix(self, diameters, numbers, rpm):
        if rpm in self.outside_at:
            warnings.warn(f"tip_speed {rpm:g} rpm outside the training range", OutOfDomainWarning, stacklevel=2)
        k = len(diameters)
        return np.full((k, k), 0.3)


# ----------------------------------------------------------------------------- tables
def test_comparison_in_display_form_has_units_mm_percent_and_fits_a_page(tmp_path):
    from pbmdem.report.display import MAX_COLUMNS
    from pbmdem.report.tables import comparison_tables

    write_validation(tmp_path)
    table = pd.read_csv(tmp_path / "comparison.csv")
    shown = comparison_tables(table)
    assert set(shown) == {"d50", "tails", "accuracy", "cost", "domain"}
    for name, frame in shown.items():
        assert frame.shape[1] <= MAX_COLUMNS, name
        for column in frame.columns:
            assert re.search(r"\((mm|%|s|rpm|-|count|of all|yes/no)\)$", column), column
    row = table.iloc[0]
    assert shown["d50"]["PBM-ANN d50 at end (mm)"].iloc[0] == f"{row.d50_end_ann_mm:.3f}"
    assert shown["d50"]["PBM-DEM d50 at end, mean +- SD (mm)"].iloc[0].endswith("(n = 2)")
    assert shown["accuracy"]["PBM-ANN d50 error, largest (%)"].iloc[0] == f"{100 * row.ann_d50_rel_error_max:.2f}"
    assert shown["cost"]["wall-time ratio PBM-DEM / PBM-ANN (-)"].iloc[0] == "1500"
    assert shown["cost"]["CPU-time ratio PBM-DEM / PBM-ANN (-)"].iloc[0] == "2900"


def test_process_settings_and_speeds_from_the_typed_config(tiny_config):
    from pbmdem.report.tables import liquid_solid_ratio, process_settings, speeds

    pbm, granulator = tiny_config.pbm, tiny_config.granulator
    v = tiny_config.validation
    table = process_settings(
        pbm,
        granulator.bed_solid_volume,
        v.distribution,
        tiny_config.distribution(v.distribution),
        v.coupling_intervals,
        v.dem_replicates,
        v.dem_sampling_time,
    ).set_index("setting")
    assert (table.unit != "").all() and (table["config key"] != "").all()
    p = pbm.process
    assert table.loc["liquid addition (spray window)", "value"] == f"{p.spray_start:.1f} - {p.spray_end:.1f}"
    assert table.loc["batch length", "value"] == f"{p.end:.4g}"
    sprayed = pbm.liquid_addition.rate * p.liquid_addition_time
    expected = pbm.initial.liquid_content + sprayed / granulator.bed_solid_volume
    assert liquid_solid_ratio(pbm, granulator.bed_solid_volume) == pytest.approx(expected)
    assert float(table.loc["liquid/solid ratio L/S at the end of the liquid addition", "value"]) == pytest.approx(
        expected, rel=1e-3
    )
    assert float(table.loc["binder addition rate", "value"]) == pytest.approx(6e7 * pbm.liquid_addition.rate, rel=1e-3)
    assert float(table.loc["aggregation rate constant beta0", "value"]) == pytest.approx(pbm.aggregation.beta0)
    assert table.loc["success probability", "value"].startswith(pbm.aggregation.success.model)
    assert table.loc["feed size classes", "unit"] == "mm"
    fast = speeds(granulator, v.rpm, tiny_config.grid.impeller_rpm).set_index("impeller speed (rpm)")
    assert set(fast.index) == {f"{r:g}" for r in (*v.rpm, *tiny_config.grid.impeller_rpm)}
    for rpm in fast.index:
        assert float(fast.loc[rpm, "tip speed (m/s)"]) == pytest.approx(granulator.tip_speed(float(rpm)), abs=5e-4)
        assert float(fast.loc[rpm, "Froude number at the tip (-)"]) == pytest.approx(
            granulator.froude_number(float(rpm)), rel=5e-3
        )
    assert fast.loc["900", "used in"] == "validation" and "DEM training grid" in fast.loc["1200", "used in"]


def test_wide_tables_are_split_with_their_key_repeated():
    from pbmdem.report.display import split_columns, table_html

    frame = pd.DataFrame({f"c{k} (mm)": [k] for k in range(12)})
    parts = split_columns(frame, keys=1, max_columns=8)
    assert [p.shape[1] for p in parts] == [8, 5]
    assert all(p.columns[0] == "c0 (mm)" for p in parts)
    assert table_html(frame).count("<table") == 2


# ----------------------------------------------------------------------------- statements
def test_targets_are_stated_met_or_not_met_with_the_measured_values():
    from pbmdem.report.statements import target_sentences, targets

    table = pd.DataFrame(
        [
            {
                "rpm": 300.0,
                "ann_d50_outside_band_max": 0.0,
                "ann_out_of_domain_intervals": 0,
                "ann_intervals": 6,
                "cpu_time_ratio_dem_over_ann": 3500.0,
            },
            {
                "rpm": 900.0,
                "ann_d50_outside_band_max": 0.031,
                "ann_out_of_domain_intervals": 6,
                "ann_intervals": 6,
                "cpu_time_ratio_dem_over_ann": float("nan"),
            },
        ]
    )
    rows = targets(table).set_index(["criterion", "speed (rpm)"])
    assert rows.loc[("ann_d50_outside_band_max <= 1.00 %", "300"), "met"] == "met"
    assert rows.loc[("ann_d50_outside_band_max <= 1.00 %", "900"), ["measured", "met"]].tolist() == [
        "3.10 %",
        "not met",
    ]
    assert rows.loc[("ann_out_of_domain_intervals = 0", "900"), "measured"] == "6 of 6 intervals"
    assert rows.loc[("cpu_time_ratio_dem_over_ann >= 3000x", "300"), ["measured", "met"]].tolist() == ["3500x", "met"]
    assert rows.loc[("cpu_time_ratio_dem_over_ann >= 3000x", "900"), "met"] == "not met (not measured)"
    sentences = target_sentences(table)
    assert len(sentences) == 3
    assert "not met at 900 rpm" in sentences[0] and "3.10 % at 900 rpm" in sentences[0]
    assert all("met at every speed" not in s for s in sentences)
    assert "met at every speed" in target_sentences(table.iloc[:1])[0]


def test_out_of_domain_statement_lists_every_interval(tmp_path):
    from pbmdem.report.statements import out_of_domain, out_of_domain_sentence
    from pbmdem.validation.results import load_speed

    vdir = write_validation(tmp_path, outside={1: "n_total 460 outside the training range [200, 400]"})
    table = out_of_domain(load_speed(vdir, RPM, 2))
    ann = table[table.model == "PBM-ANN (ensemble mean)"]
    assert ann["interval"].tolist() == ["0", "1"]  # every interval, inside or outside
    assert ann["outside the training domain"].tolist() == ["no", "yes"]
    assert ann["sample classes (mm)"].iloc[0] == "2.00, 2.50, 3.00"
    assert {"PBM-ANN member 0", "PBM-ANN member 1", "PBM-constant calibration"} <= set(table.model)
    sentence = out_of_domain_sentence(RPM, table)
    assert "outside its training domain in 1 of 2 coupling intervals" in sentence
    assert "interval 1 (10-20 s" in sentence and "n_total 460 outside" in sentence
    assert "calibration sample was inside it" in sentence

    inside = write_validation(tmp_path / "inside")
    sentence = out_of_domain_sentence(RPM, out_of_domain(load_speed(inside, RPM, 2)))
    assert "stayed inside the surrogate's training domain in all 2 coupling intervals" in sentence


# ----------------------------------------------------------------------------- figures
def _labels(fig) -> list[str]:
    return [text for ax in fig.axes for text in (ax.get_xlabel(), ax.get_ylabel()) if text]


def test_figures_have_units_legends_and_sizes_in_mm(tmp_path):
    from pbmdem.config.pbm import ProcessSettings
    from pbmdem.report import figures
    from pbmdem.report.frequencies import interval_frequencies, surrogate_on_dem_samples
    from pbmdem.validation.results import load_speed

    vdir = write_validation(tmp_path)
    speed = load_speed(vdir, RPM, 2)
    process = ProcessSettings(premixing_time=2.0, liquid_addition_time=10.0, wet_massing_time=8.0)
    bands = pd.read_csv(vdir / f"rpm{RPM}" / "bands.csv")
    fig = figures.size_bands(bands, process, RPM)
    assert _labels(fig) == ["time (s)", "d10 (mm)", "time (s)", "d50 (mm)", "time (s)", "d90 (mm)"]
    d50 = fig.axes[1]
    dem_mean = bands[bands.statistic == "d50"].dem_mean.to_numpy()
    line = next(ln for ln in d50.get_lines() if ln.get_label() == "PBM-DEM mean")
    np.testing.assert_allclose(line.get_ydata(), 1e3 * dem_mean)  # mm
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    band = next(t for t in labels if t.startswith("PBM-DEM band"))
    width = (bands[bands.statistic == "d50"].dem_max - bands[bands.statistic == "d50"].dem_min).max()
    # the band's width is stated, so that a band thinner than a line is not taken for a missing one
    assert band == f"PBM-DEM band (min-max of 2 replicates; up to {1e3 * width:.2g} mm wide in d50)", band
    assert "PBM-ANN band (min-max of the surrogate's members)" in labels and "PBM-constant" in labels
    figures.pyplot().close(fig)

    bins = {name: _bins(0.05) for name in ("PBM-DEM replicate 0", "PBM-ANN", "PBM-constant")}
    fig = figures.psd_evolution(bins, process, RPM)
    assert _labels(fig)[:2] == ["diameter (mm)", "mass finer than d (%)"]
    shown = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    # start, spray start/middle/end, end; the first three are the same distribution: one curve
    assert shown == ["t = 0 = 2 = 7 s", "t = 12 s", "t = 20 s"]
    for line in fig.axes[0].get_lines()[:3]:  # cumulative: smooth, from ~0 to 100 %, never falling
        y = line.get_ydata()
        assert np.all(np.diff(y) >= -1e-9) and y[-1] == pytest.approx(100.0) and y[0] < 10.0
    # each bin's mass is finer than its upper edge: the curve crosses 50 % at the d50 of summary.csv
    # (pbm.results.mass_quantiles on the bins' edges), not half a bin to its left
    final = bins["PBM-ANN"][bins["PBM-ANN"].time == max(TIMES)]
    d = final.diameter.to_numpy()
    edges = np.append(d[0] / 2 ** (1 / 6), d * 2 ** (1 / 6))  # the synthetic grid's ratio is 2^(1/3)
    d50 = mass_quantiles(final.mass_fraction.to_numpy(), edges, (0.5,))[0]
    last = next(ln for ln in fig.axes[1].get_lines() if ln.get_label() == f"t = {max(TIMES):g} s")
    x, y = last.get_xdata(), last.get_ydata()
    assert np.exp(np.interp(50.0, y, np.log(x))) == pytest.approx(1e3 * d50, rel=1e-9)
    assert fig.axes[0].get_title().startswith("PBM-DEM replicate 0")
    figures.pyplot().close(fig)

    fig = figures.liquid_porosity(speed, process, RPM)
    assert _labels(fig) == [
        "time (s)",
        "mean liquid content L/S (m3 liquid / m3 solid)",
        "time (s)",
        "mean porosity (%)",
    ]
    figures.pyplot().close(fig)

    frequency = interval_frequencies(speed)
    assert sorted(set(frequency.model)) == ["PBM-ANN", "PBM-DEM", "PBM-constant"]
    assert len(frequency[frequency.model == "PBM-DEM"]) == 4  # 2 replicates x 2 intervals
    pairs = surrogate_on_dem_samples(speed, FakeSurrogate(outside_at={600.0}))
    assert len(pairs) == 2 * 2 * 6 and pairs.out_of_domain.all() and (pairs.surrogate == 0.3).all()
    assert pairs.warnings.str.contains("outside the training range").all()
    fig = figures.collision_frequency(frequency, pairs, RPM)
    assert _labels(fig) == [
        "time (s)",
        "pair-weighted mean c (1/s per pair)",
        "DEM c_ij (1/s per pair)",
        "surrogate c_ij, same sample (1/s per pair)",
    ]
    assert any("outside its training domain on 4 of 4 PBM-DEM samples" in t.get_text() for t in fig.axes[1].texts)
    figures.pyplot().close(fig)


def test_speed_outputs_are_written_whole(tmp_path, monkeypatch):
    """The report files of one speed: valid PNGs and tables, no temporary file left beside them."""
    from pbmdem.report import figures
    from pbmdem.report.figures import write_speed

    vdir = write_validation(tmp_path, outside={0: "tip_speed outside the training range"})
    monkeypatch.setattr(figures, "load_surrogate", lambda path: FakeSurrogate())
    out_dir = tmp_path / "report" / f"rpm{RPM}"
    out = {
        "sizes": out_dir / "size_statistics.png",
        "psd": out_dir / "psd_evolution.png",
        "liquid": out_dir / "liquid_porosity.png",
        "frequency": out_dir / "collision_frequency.png",
        "domain_csv": out_dir / "out_of_domain.csv",
        "domain_html": out_dir / "out_of_domain.html",
    }
    write_speed(
        validation_dir=vdir,
        rpm=RPM,
        replicates=2,
        process={"premixing_time": 2.0, "liquid_addition_time": 10.0, "wet_massing_time": 8.0},
        bands=vdir / f"rpm{RPM}" / "bands.csv",
        model=tmp_path / "model.skops",
        out=out,
    )
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(p.name for p in out.values())
    for key in ("sizes", "psd", "liquid", "frequency"):
        assert out[key].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", key
    domain = pd.read_csv(out["domain_csv"])
    assert domain.loc[0, "outside the training domain"] == "yes"
    page = out["domain_html"].read_text()
    assert "outside its training domain in 1 of 2 coupling intervals" in page and "<table" in page


def test_bad_inputs_of_the_report_name_the_file(tmp_path, monkeypatch):
    from pbmdem.report import figures
    from pbmdem.report.figures import write_speed
    from pbmdem.report.outputs import write_comparison

    vdir = write_validation(tmp_path)
    bins = vdir / f"rpm{RPM}" / "pbm_ann" / "bins.csv"
    pd.read_csv(bins).drop(columns="mass_density_lnd").to_csv(bins, index=False)
    monkeypatch.setattr(figures, "load_surrogate", lambda path: FakeSurrogate())
    out = {k: tmp_path / "out" / f"{k}.png" for k in ("sizes", "psd", "liquid", "frequency")}
    with pytest.raises(InputFileError, match=re.escape(str(bins)) + ".*mass_density_lnd"):
        write_speed(
            validation_dir=vdir,
            rpm=RPM,
            replicates=2,
            process={"premixing_time": 2.0, "liquid_addition_time": 10.0, "wet_massing_time": 8.0},
            bands=vdir / f"rpm{RPM}" / "bands.csv",
            model=tmp_path / "model.skops",
            out=out,
        )
    summary = vdir / f"rpm{RPM}" / "pbm_dem" / "rep1" / "summary.csv"
    pd.read_csv(summary).drop(columns="mean_porosity").to_csv(summary, index=False)
    with pytest.raises(InputFileError, match=re.escape(str(summary)) + ".*mean_porosity"):
        write_speed(
            validation_dir=vdir,
            rpm=RPM,
            replicates=2,
            process={"premixing_time": 2.0, "liquid_addition_time": 10.0, "wet_massing_time": 8.0},
            bands=vdir / f"rpm{RPM}" / "bands.csv",
            model=tmp_path / "model.skops",
            out=out,
        )
    comparison = tmp_path / "comparison.csv"
    pd.read_csv(comparison).drop(columns="pbm_ann_wall_s").to_csv(comparison, index=False)
    with pytest.raises(InputFileError, match=re.escape(str(comparison)) + ".*pbm_ann_wall_s"):
        write_comparison(comparison=comparison, out={})


# ----------------------------------------------------------------------------- provenance
def test_provenance_hashes_commit_and_versions(tiny_config, tiny_mapping, root, tmp_path, monkeypatch):
    from pbmdem.config import Config
    from pbmdem.report.provenance import NOT_GIT, provenance, settings_mapping, sha256_of

    runs = tmp_path / "runs.csv"
    version = "LIGGGHTS-PUBLIC 3.8.0, compiled 2022-01-26-19:42:32 by buildd, git commit unknown"
    pd.DataFrame({"point_id": ["rpm600_small", "rpm600_large"], "liggghts_version": [version, version]}).to_csv(
        runs, index=False
    )
    meta = tmp_path / "model.json"
    meta.write_text(
        json.dumps(
            {"model_sha256": "ab" * 32, "created_utc": "2026-12-01T00:00:00+00:00", "versions": {"sklearn": "1.9.1"}}
        )
    )
    settings = settings_mapping(tiny_config.to_dict())
    table = provenance(tiny_config.sha256(), settings, root, runs, meta).set_index("quantity")["value"]
    assert table["config sha256"] == tiny_config.sha256()
    assert table["settings sha256"] == sha256_of(settings)
    assert table["LIGGGHTS"] == f"{version} (2 of 2 runs)"
    assert table["surrogate model sha256"] == "ab" * 32
    for name in ("Python", "numpy", "scipy", "pandas", "scikit-learn", "snakemake", "pbmdem"):
        assert table[name] and table[name] != "not installed in this environment", name
    head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True)
    assert table["git commit"] == (head.stdout.strip() if head.returncode == 0 else NOT_GIT)

    # the execution settings change the config hash, not the settings hash; a result setting both
    tiny_mapping["dem"]["mpi_ranks"], tiny_mapping["dem"]["timeout"] = 2, 99.0
    ranks = Config.from_mapping(tiny_mapping)
    assert ranks.sha256() != tiny_config.sha256()
    assert sha256_of(settings_mapping(ranks.to_dict())) == sha256_of(settings)
    tiny_mapping["dem"]["seed"] += 1
    assert sha256_of(settings_mapping(Config.from_mapping(tiny_mapping).to_dict())) != sha256_of(settings)

    # outside a git checkout the absence is stated; runs made before the version was recorded say so
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path))
    plain = tmp_path / "not_a_checkout"
    plain.mkdir()
    pd.DataFrame({"point_id": ["rpm600_small"]}).to_csv(runs, index=False)
    table = provenance(tiny_config.sha256(), settings, plain, runs).set_index("quantity")["value"]
    assert table["git commit"] == NOT_GIT and "git working tree" not in table.index
    assert table["LIGGGHTS"].startswith(f"not recorded in {runs}")


def test_liggghts_version_is_read_from_the_log_header(tmp_path):
    from pbmdem.dem.engine import version_of_log

    log = tmp_path / "log.liggghts"
    log.write_text(
        "LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, compiled 2022-01-26 by buildd, git commit unknown)\n"
        "Created orthogonal box = (-0.0165 -0.0165 -0.0015) to (0.0165 0.0165 0.0315)\n"
    )
    assert version_of_log(log) == "LIGGGHTS-PUBLIC 3.8.0, compiled 2022-01-26 by buildd, git commit unknown"
    log.write_text("Created orthogonal box\n")
    with pytest.raises(InputFileError, match=re.escape(str(log)) + ".*no header line"):
        version_of_log(log)
    with pytest.raises(InputFileError, match=re.escape(str(tmp_path / "missing.log"))):
        version_of_log(tmp_path / "missing.log")


def test_breakage_words_leave_failed_speeds_out_of_the_peak():
    """A variant whose ensemble mean failed at the fastest speeds (d50 NaN) peaks where its
    finished speeds peak, not at the first failed one; one that falls from the lowest speed on is
    named as such."""
    from pbmdem.report.breakage import breakage_words, peak_speed

    rpm = [300.0, 450.0, 600.0, 750.0, 900.0]
    rows = {
        "off": [7.9, 9.1, 9.9, 10.6, 10.9],
        "default": [7.9, 3.7, 2.0, 2.0, 2.0],
        "Y/2": [4.7, 2.0, 2.0, np.nan, np.nan],
        "Yx2": [7.9, 8.6, 4.7, 2.0, np.nan],
    }
    study = pd.DataFrame(
        [
            {"variant": v, "rpm": r, "d50": 1e-3 * d, "critical_speed": 2.0}
            for v, d50s in rows.items()
            for r, d in zip(rpm, d50s, strict=True)
        ]
    )
    peaks = {v: peak_speed(s) for v, s in study.groupby("variant")}
    assert peaks == {"off": None, "default": None, "Y/2": None, "Yx2": 450.0}
    words = breakage_words(study)
    assert "falls above it for: Yx2 (450 rpm)." in words
    assert "from the lowest speed studied on for: Y/2, default." in words
    assert "v* = 2 m/s) the final d50" in words  # one strength at every porosity
    consolidating = breakage_words(study.assign(strength_porosity_exponent=2.0))
    assert "v* = 2 m/s for a fresh granule, rising as it consolidates (strength ~ ((1 - eps)/eps)^2)" in consolidating


def test_a_fall_within_the_members_range_is_not_a_peak():
    """Without breakage d50 levels off (10.9 mm at 900 rpm, 10.85 at 1200): inside the members'
    range at the peak that is no speed above which granules get smaller; a fall below that range is."""
    from pbmdem.report.breakage import peak_speed

    def study(d50s, member_min):
        rpm = [300.0, 600.0, 900.0, 1200.0]
        return pd.DataFrame({"rpm": rpm, "d50": 1e-3 * np.array(d50s), "d50_member_min": 1e-3 * np.array(member_min)})

    assert peak_speed(study([7.9, 9.9, 10.9, 10.85], [7.6, 9.4, 10.4, 10.5])) is None
    assert peak_speed(study([7.9, 9.9, 10.9, 10.2], [7.6, 9.4, 10.4, 9.8])) == 900.0


def test_the_findings_state_the_clipping_at_the_grid_floor():
    """The breakage section says 'clipping: none' when no batch of the studies merged a fragment at
    the grid floor, and otherwise names the batch with the largest share of its final number merged
    there, flagging those above 1 %, ensemble members included; studies written before the tally
    read 'not measured' (the findings text with the line: tests/test_findings.py)."""
    from pbmdem.report.breakage import clipping_words

    def study(fractions, members, variant=None):
        rows = [
            {"rpm": r, "feed": "fine", "merged_fraction": f, "merged_fraction_member_max": m}
            for r, f, m in zip((300.0, 900.0, 1200.0), fractions, members, strict=True)
        ]
        frame = pd.DataFrame(rows)
        return frame if variant is None else frame.assign(variant=variant)

    clean = {"speed study": study([0, 0, 0], [0, 0, 0]), "breakage study": study([0, 0, 0], [0, 0, 0], "Y/2")}
    assert "clipping: none: no breakage fragment fell below the grid's first pivot in any of the 6" in (
        clipping_words(clean)
    )
    small = {"speed study": study([0, 0.002, 0.004], [0, 0.003, 0.005])}
    words = clipping_words(small)
    assert "amount to 0.5 % of the final number of granules in the speed study's batch at 1200 rpm, feed fine " in words
    assert "(an ensemble member)" in words and "none above 1 %" in words and "FLAGGED" not in words
    strong = {"speed study": study([0, 0.002, 0.004], [0, 0.003, 0.005]), "breakage study": study(
        [0.0, 0.03, 0.25], [0.0, 0.02, 0.3], "Y/2")}  # fmt: skip
    words = clipping_words(strong)
    assert "amount to 30 % of the final number of granules in the breakage study's Y/2 batch at 1200 rpm" in words
    assert "FLAGGED: 4 above 1 % of their final number" in words
    assert "the breakage study's Y/2 batch at 900 rpm, feed fine (the ensemble mean): 3 %" in words
    assert "not measured" in clipping_words(
        {"speed study": study([0, 0, 0], [0, 0, 0]).drop(columns="merged_fraction")}
    )
