"""What lumping leaves out: the lumped (1-D) PBM beside the size x liquid (2-D) one under PBM-ANN
(pbmdem.coupling.lumping's tables): one figure, one display table and the words of the findings,
the findings' answers computed in both models by the findings' own rules."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.plotting import ML_PER_MIN, log_ticks, pyplot

from . import words
from .breakage import peak_speed
from .display import MM, PERCENT, mm, number

#: a difference between the models below 1 % of a size is below the reproducibility of a measured
#: d50 (a sieve or laser diffraction of the same sample, calibration.relative_error_floor): the lumped
#: model is called adequate where d10, d50 and d90 of every case of a study differ by less
ADEQUATE = 0.01
#: size classes shown in the liquid panel: those holding at least this share of the solid
SHOWN_SOLID = 1e-6
#: a share of the batch's solid below this is "none" (round-off of the classes' totals)
NO_DRY = 1e-6
STUDY_NAMES = {
    "default": "default batch",
    "speed": "speed study",
    "binder": "binder rates",
    "feed": "feeds",
}


def largest_difference(cases: pd.DataFrame) -> pd.Series:
    """Per case the largest |relative difference| of d10, d50 and d90 between the models."""
    return cases[[f"{s}_rel_diff" for s in ("d10", "d50", "d90")]].abs().max(axis=1)


def turn_speeds(cases: pd.DataFrame) -> tuple[float | None, float | None]:
    """The speed above which the granules get smaller (`report.breakage.peak_speed`, the findings'
    rule, on the ensemble mean) in the 1-D and the 2-D model; None: no such speed in the range."""
    s = cases[cases.study == "speed"]
    return tuple(
        peak_speed(pd.DataFrame({"rpm": s.rpm.to_numpy(float), "d50": s[f"d50_{m}"].to_numpy(float)}))
        for m in ("1d", "2d")
    )


def feed_order(cases: pd.DataFrame, model: str) -> list[str]:
    """The feeds of the feed cases ordered by the final d50 of `model` ("1d" or "2d"), smallest first."""
    f = cases[cases.study == "feed"]
    return list(f.sort_values(f"d50_{model}", kind="stable").feed)


def _case_label(row) -> str:
    if row.study == "speed":
        return f"{row.rpm:g} rpm"
    if row.study == "binder":
        return f"{ML_PER_MIN * row.liquid_rate:.3g} mL/min"
    if row.study == "feed":
        return str(row.feed)
    return f"{row.rpm:g} rpm, {row.feed}, {ML_PER_MIN * row.liquid_rate:.3g} mL/min"


def lumping_table(cases: pd.DataFrame) -> pd.DataFrame:
    """The cases in display form: sizes in mm, differences in %."""
    rows = []
    for row in cases.itertuples(index=False):
        rows.append(
            {
                "study": STUDY_NAMES.get(row.study, row.study),
                "case": _case_label(row),
                "d50 1-D (mm)": mm(row.d50_1d),
                "d50 2-D (mm)": mm(row.d50_2d),
                "d10 2-D vs 1-D (%)": number(PERCENT * row.d10_rel_diff, ".2g"),
                "d50 2-D vs 1-D (%)": number(PERCENT * row.d50_rel_diff, ".2g"),
                "d90 2-D vs 1-D (%)": number(PERCENT * row.d90_rel_diff, ".2g"),
                "CPU s 1-D / 2-D": f"{number(row.cpu_time_s_1d, '.2f')} / {number(row.cpu_time_s_2d, '.2f')}",
            }
        )
    return pd.DataFrame(rows)


def lumping_figure(cases: pd.DataFrame, liquid: pd.DataFrame):
    """Final sizes against impeller speed, binder rate and feed in both models, and the liquid content
    per size class at the end of the default batch."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(10.0, 7.6))
    panels = (
        ("speed", "rpm", 1.0, "impeller speed (rpm)"),
        ("binder", "liquid_rate", ML_PER_MIN, "binder rate (mL/min)"),
        ("feed", "feed_d50", MM, "feed d50 (mm)"),
    )
    for ax, (study, column, scale, label) in zip(axes.ravel()[:3], panels):
        s = cases[cases.study == study].sort_values(column)
        x = scale * s[column].to_numpy(float)
        for stat, alpha in (("d10", 0.35), ("d50", 1.0), ("d90", 0.35)):
            main = stat == "d50"
            lw = 2.2 if main else 1.0
            one = "1-D (lumped)" if main else None
            two = "2-D (size x liquid)" if main else None
            ax.plot(x, MM * s[f"{stat}_1d"], "-", color="tab:blue", alpha=alpha, lw=lw, label=one)
            ax.plot(x, MM * s[f"{stat}_2d"], "o--", color="tab:red", alpha=alpha, ms=3.5, label=two)
        if study == "feed":
            for xk, name, y in zip(x, s.feed, MM * s.d50_1d):
                ax.annotate(str(name), (xk, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.set(xlabel=label, ylabel="final d10, d50, d90 (mm)")
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
    rpm = float(cases[cases.study == "default"].rpm.iloc[0]) if (cases.study == "default").any() else float("nan")
    axes[0, 0].set_title("against impeller speed", fontsize=10)
    axes[0, 1].set_title(f"against the binder rate, {rpm:g} rpm", fontsize=10)
    axes[1, 0].set_title(f"against the feed, {rpm:g} rpm", fontsize=10)
    ax = axes[1, 1]
    shown = liquid[np.maximum(liquid.solid_fraction_1d.fillna(0), liquid.solid_fraction_2d.fillna(0)) >= SHOWN_SOLID]
    for kind, marker in (("aggregate", "o"), ("feed", "s")):
        k = shown[shown.kind == kind].sort_values("diameter")
        if k.empty:
            continue
        d = MM * k.diameter.to_numpy(float)
        ax.plot(d, k.liquid_content_1d, marker + "-", color="tab:blue", ms=4, label=f"1-D class mean ({kind}s)")
        sd = k.liquid_content_2d_sd.to_numpy(float)
        two = f"2-D mean +- sd over liquid classes ({kind}s)"
        ax.errorbar(
            d, k.liquid_content_2d_mean, yerr=sd, fmt=marker, mfc="none", color="tab:red", ms=6, capsize=2, label=two
        )
        if kind == "aggregate":
            span = "2-D range of the liquid classes (>= 0.1 % of a class's solid)"
            lo, hi = k.liquid_content_2d_min, k.liquid_content_2d_max
            ax.fill_between(d, lo, hi, color="tab:red", alpha=0.12, lw=0, label=span)
    ax.set_xscale("log")
    log_ticks(ax, "x")
    ax.set(xlabel="granule diameter (mm)", ylabel="liquid content L/S (m3 liquid / m3 solid)")
    ax.set_title(f"liquid per size class at the end of the default batch, {rpm:g} rpm", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    fig.suptitle("What lumping leaves out: PBM-ANN with the lumped (1-D) and the size x liquid (2-D) PBM")
    fig.tight_layout()
    return fig


def _per_study(cases: pd.DataFrame) -> list[tuple]:
    """Per study: its name, its largest difference between the models and the case where it is
    largest (None for the default batch)."""
    worst = largest_difference(cases)
    parts = []
    for study in STUDY_NAMES:
        mask = cases.study == study
        if not mask.any():
            continue
        case = cases.loc[worst[mask].idxmax()]
        parts.append((STUDY_NAMES[study], worst[mask].max(), None if study == "default" else _case_label(case)))
    return parts


def _liquid(liquid: pd.DataFrame, info: dict) -> dict | None:
    """The widest liquid spread within a size class holding 1 % of the solid or more at the end of
    the default batch, and the share of the solid below the success threshold in each model."""
    if not len(liquid):
        return None
    big = liquid[np.maximum(liquid.solid_fraction_1d.fillna(0), liquid.solid_fraction_2d.fillna(0)) >= 0.01]
    big = big if len(big) else liquid
    row = liquid.loc[big.liquid_content_2d_sd.idxmax()]
    return {
        "sd": row.liquid_content_2d_sd,
        "diameter": row.diameter,
        "min": row.liquid_content_2d_min,
        "max": row.liquid_content_2d_max,
        "mean": row.liquid_content_2d_mean,
        "lumped": row.liquid_content_1d,
        # the share of the batch's solid whose surface liquid is below the success threshold
        "dry1": float(np.nansum(liquid.dry_solid_fraction_1d * liquid.solid_fraction_1d)),
        "dry2": float(np.nansum(liquid.dry_solid_fraction_2d * liquid.solid_fraction_2d)),
        "threshold": info.get("success_threshold"),
        "no_dry": NO_DRY,
    }


def lumping_words(cases: pd.DataFrame, liquid: pd.DataFrame, info: dict) -> str:
    """The finding in words (template lumping.j2)."""
    worst = largest_difference(cases)
    failed = cases[cases.failed.fillna("").astype(str) != ""]
    turn1, turn2 = turn_speeds(cases)
    studies = [s for s in STUDY_NAMES if (cases.study == s).any()]
    fine = {s: float(worst[cases.study == s].max()) < ADEQUATE for s in studies}
    cpu1, cpu2 = info.get("cpu_time_s_1d"), info.get("cpu_time_s_2d")
    return words.paragraph(
        "lumping",
        cases=len(cases),
        worst=worst.max(),
        per_study=_per_study(cases[np.isfinite(worst)]),
        failed=[_case_label(row) for row in failed.itertuples()],
        turn1=turn1,
        turn2=turn2,
        order1=feed_order(cases, "1d"),
        order2=feed_order(cases, "2d"),
        liquid=_liquid(liquid, info),
        adequate=[STUDY_NAMES[s] for s in studies if fine[s]],
        not_adequate=[STUDY_NAMES[s] for s in studies if not fine[s]],
        limit=ADEQUATE,
        cost=None
        if cpu1 is None or cpu2 is None
        else {"batches": int(info.get("batches", 0)) // 2, "cpu1": cpu1, "cpu2": cpu2},
    )
