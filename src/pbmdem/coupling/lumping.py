"""What lumping leaves out: PBM-ANN with the one-dimensional PBM beside the two-dimensional one
(`pbm.dimensions: 2`) on the same kernel source and cases (``study``: default, speed, binder, feed;
a case shared by studies runs once): final d10/d50/d90 of both, their relative differences, the 2-D
solid balance and CPU seconds; `liquid_per_size` the liquid content per size class at the end of the
default batch (docs/pbm.md, "What lumping leaves out, in the workflow")."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.config import CoupledLoop, SizeDistribution
from pbmdem.config.design import with_pbm_values
from pbmdem.pbm.errors import PBMError
from pbmdem.pbm.state import surface_fraction
from pbmdem.surrogate import load_surrogate
from pbmdem.tables import STATISTICS

from .loop import CouplingError
from .methods import pbm_ann
from .studies import feed_cases, final_statistics, with_feed

log = logging.getLogger(__name__)

LIQUID_KEY = "pbm.liquid_addition.rate"
#: the columns of the cases table (`lumping_study`), in order
CASE_COLUMNS = (
    "study",
    "rpm",
    "liquid_rate",
    "feed",
    "feed_d50",
    *(f"{s}_1d" for s in STATISTICS),
    *(f"{s}_2d" for s in STATISTICS),
    *(f"{s}_rel_diff" for s in STATISTICS),
    "solid_rel_change_2d",
    "out_of_domain_intervals",
    "cpu_time_s_1d",
    "cpu_time_s_2d",
    "failed",
)
#: the columns of the liquid-per-size table (`liquid_per_size`), in order
LIQUID_COLUMNS = (
    "size_class",
    "kind",
    "diameter",
    "solid_fraction_1d",
    "solid_fraction_2d",
    "liquid_content_1d",
    "liquid_content_2d_mean",
    "liquid_content_2d_sd",
    "liquid_content_2d_min",
    "liquid_content_2d_max",
    "dry_solid_fraction_1d",
    "dry_solid_fraction_2d",
)
#: a size class of the 1-D model holds no aggregates when its solid without the feed's share is below
#: this fraction of the total (the subtraction's round-off)
ROUND_OFF = 1e-12
#: a liquid class counts in a size class's range of liquid content when it holds this share of its solid
OCCUPIED = 1e-3


def with_dimensions(loop: CoupledLoop, dimensions: int) -> CoupledLoop:
    """`loop` with ``pbm.dimensions`` = `dimensions`."""
    return loop.replace(batch=loop.batch.replace(pbm=loop.batch.pbm.replace(dimensions=int(dimensions))))


def _run(loop: CoupledLoop, model, rpm: float):
    """(outcome or None, CPU seconds, error text) of one PBM-ANN batch in memory."""
    c0 = time.process_time()
    try:
        outcome = pbm_ann(loop, model, rpm, None, log_each=False)
    except (PBMError, CouplingError, ValueError) as exc:
        return None, time.process_time() - c0, str(exc)
    return outcome, time.process_time() - c0, ""


def _final(outcome) -> dict:
    return dict.fromkeys(STATISTICS, float("nan")) if outcome is None else final_statistics(outcome.result.summary())


def solid_change(result) -> float:
    """(final solid + solid refused beyond the grid - initial solid) / initial solid of a run."""
    s = result.summary()
    start = float(s.total_solid_volume.iloc[0])
    end = float(s.total_solid_volume.iloc[-1]) + float(s.refused_solid_volume.iloc[-1])
    return (end - start) / start


def compare_case(loop: CoupledLoop, model, rpm: float) -> tuple[dict, tuple]:
    """The row of one case (columns of CASE_COLUMNS without study/feed/liquid_rate) and the two
    outcomes (1-D, 2-D; None for a failed batch)."""
    one, cpu1, err1 = _run(with_dimensions(loop, 1), model, rpm)
    two, cpu2, err2 = _run(with_dimensions(loop, 2), model, rpm)
    f1, f2 = _final(one), _final(two)
    row = {"rpm": float(rpm)}
    row |= {f"{s}_1d": f1[s] for s in STATISTICS} | {f"{s}_2d": f2[s] for s in STATISTICS}
    row |= {f"{s}_rel_diff": (f2[s] - f1[s]) / f1[s] for s in STATISTICS}
    row["solid_rel_change_2d"] = solid_change(two.result) if two is not None else float("nan")
    finished = [o for o in (one, two) if o is not None]
    row["out_of_domain_intervals"] = max((int(o.totals.get("out_of_domain_intervals", 0)) for o in finished), default=0)
    row |= {"cpu_time_s_1d": cpu1, "cpu_time_s_2d": cpu2, "failed": "; ".join(e for e in (err1, err2) if e)}
    return row, (one, two)


def lumping_study(
    loop: CoupledLoop,
    model_path,
    rpm: float,
    speeds,
    liquid_rates,
    feeds: dict[str, SizeDistribution],
) -> tuple[pd.DataFrame, pd.DataFrame, dict]:
    """The cases table (CASE_COLUMNS), the liquid content per size class of the default batch
    (`liquid_per_size`) and the study's cost (batches, CPU and wall seconds). `loop`: the
    validation's coupled loop (its feed is the default batch's); `rpm`: the speed of the default
    batch, the binder rates and the feeds; `speeds`: the speed study's; `liquid_rates`: the design
    space's binder rates (m3/s); `feeds`: the grid's named feeds (`feed_cases` adds the blends)."""
    model = load_surrogate(model_path) if isinstance(model_path, (str, Path)) else model_path
    t0, c0 = time.perf_counter(), time.process_time()
    base_rate = float(loop.batch.pbm.liquid_addition.rate)
    base_feed = loop.batch.distribution
    wanted = [("default", float(rpm), base_rate, base_feed, loop.batch.sizes)]
    wanted += [("speed", float(r), base_rate, base_feed, loop.batch.sizes) for r in speeds]
    wanted += [("binder", float(rpm), float(q), base_feed, loop.batch.sizes) for q in liquid_rates]
    wanted += [("feed", float(rpm), base_rate, name, sizes) for name, sizes, _ in feed_cases(feeds)]
    done: dict[tuple, tuple] = {}
    rows = []
    for study, r, q, name, sizes in wanted:
        key = (r, q, name)
        if key not in done:
            case = with_feed(loop, name, sizes)
            if q != base_rate:
                case = case.replace(batch=case.batch.replace(pbm=with_pbm_values(case.batch.pbm, {LIQUID_KEY: q})))
            done[key] = compare_case(case, model, r)
            row = done[key][0]
            log.info(
                "lumping: %g rpm, binder %.3g m3/s, feed %s: d50 %.4f mm (1-D) / %.4f mm (2-D), %+.2e; "
                "CPU %.2f / %.2f s",
                *(r, q, name, 1e3 * row["d50_1d"], 1e3 * row["d50_2d"], row["d50_rel_diff"]),
                *(row["cpu_time_s_1d"], row["cpu_time_s_2d"]),
            )
        row = {"study": study, "liquid_rate": q, "feed": name, "feed_d50": sizes.mass_median} | done[key][0]
        rows.append(row)
    table = pd.DataFrame(rows)[list(CASE_COLUMNS)]
    one, two = done[(float(rpm), base_rate, base_feed)][1]
    threshold = float(loop.batch.pbm.aggregation.success.threshold)
    liquid = (
        liquid_per_size(one.result, two.result, threshold)
        if one is not None and two is not None
        else pd.DataFrame(columns=list(LIQUID_COLUMNS))
    )
    unique = [v[0] for v in done.values()]
    info = {
        "cases": len(table),
        "batches": 2 * len(unique),
        "cpu_time_s": time.process_time() - c0,
        "wall_time_s": time.perf_counter() - t0,
        "cpu_time_s_1d": float(sum(v["cpu_time_s_1d"] for v in unique)),
        "cpu_time_s_2d": float(sum(v["cpu_time_s_2d"] for v in unique)),
        "rpm": float(rpm),
        "success_threshold": threshold,
    }
    return table, liquid, info


def _classes_1d(result) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(volumes, kinds, solid, liquid, gas) of the 1-D model's final size classes: the K pivots'
    aggregates (the per-bin totals without the feed granules' lever-rule share) and the feed classes."""
    g, s = result.grid, result.state
    solid, liquid, gas = s.number * g.x, np.array(s.liquid, float), np.array(s.gas, float)
    vols, kinds = np.array(g.x, float), ["aggregate"] * g.bins
    if s.feed is not None and len(s.feed.volumes):
        wn, ws = g.lever_weights(s.feed.volumes)
        solid = np.maximum(solid - (s.feed.number * s.feed.volumes) @ ws, 0.0)
        liquid = np.maximum(liquid - s.feed.liquid @ ws, 0.0)
        gas = np.maximum(gas - s.feed.gas @ ws, 0.0)
        vols = np.concatenate([vols, s.feed.volumes])
        kinds += ["feed"] * len(s.feed.volumes)
        solid = np.concatenate([solid, s.feed.number * s.feed.volumes])
        liquid = np.concatenate([liquid, s.feed.liquid])
        gas = np.concatenate([gas, s.feed.gas])
    # what the subtraction leaves of a pivot that holds only feed granules' shares is round-off
    solid = np.where(solid > ROUND_OFF * solid.sum(), solid, 0.0)
    return vols, np.array(kinds), solid, liquid, gas


def _ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.divide(a, b, out=np.full(np.shape(a), np.nan), where=b > 0)


def liquid_per_size(one, two, threshold: float) -> pd.DataFrame:
    """The liquid content (liquid / solid volume) of every size class (the grid's pivots, then
    the feed classes) at the end of a batch run by the 1-D model (`one`) and the 2-D model
    (`two`, a Result with ``classes``): LIQUID_COLUMNS, one row per size class holding solid in
    either model. ``dry_solid_fraction``: the share of the class's solid whose surface-liquid
    fraction is below `threshold` (the 1-D model's class is wholly dry or wet)."""
    vols, kinds, s1, l1, g1 = _classes_1d(one)
    c = np.asarray(two.classes[-1], float)  # (3, Mx, J): number, liquid, gas
    v2 = np.asarray(two.class_volumes, float)
    if v2.shape != vols.shape or not np.allclose(v2, vols, rtol=1e-12, atol=0):
        raise PBMError(
            f"the 1-D and 2-D batches end with different size classes ({vols.size} and {v2.size}); "
            "they must start from the same feed on the same grid"
        )
    s2e, l2e, g2e = c[0] * v2[:, None], c[1], c[2]
    s2 = s2e.sum(axis=1)
    w = _ratio(l2e, s2e)
    mean2 = _ratio(l2e.sum(axis=1), s2)
    share = _ratio(s2e, s2[:, None])
    sd2 = np.sqrt(np.nansum(np.nan_to_num(share) * (np.nan_to_num(w) - mean2[:, None]) ** 2, axis=1))
    occupied = np.nan_to_num(share) >= OCCUPIED
    lo = np.where(occupied, w, np.inf).min(axis=1)
    hi = np.where(occupied, w, -np.inf).max(axis=1)
    dry2 = _ratio(np.where(surface_fraction(s2e, l2e, g2e) < threshold, s2e, 0.0).sum(axis=1), s2)
    dry1 = np.where(s1 > 0, (surface_fraction(s1, l1, g1) < threshold).astype(float), np.nan)
    frame = pd.DataFrame(
        {
            "size_class": np.arange(vols.size),
            "kind": kinds,
            "diameter": np.cbrt(6.0 / np.pi * vols),
            "solid_fraction_1d": s1 / s1.sum(),
            "solid_fraction_2d": s2 / s2.sum(),
            "liquid_content_1d": _ratio(l1, s1),
            "liquid_content_2d_mean": mean2,
            "liquid_content_2d_sd": np.where(s2 > 0, sd2, np.nan),
            "liquid_content_2d_min": np.where(np.isfinite(lo), lo, np.nan),
            "liquid_content_2d_max": np.where(np.isfinite(hi), hi, np.nan),
            "dry_solid_fraction_1d": dry1,
            "dry_solid_fraction_2d": dry2,
        }
    )
    keep = (s1 > ROUND_OFF * s1.sum()) | (s2 > ROUND_OFF * s2.sum())
    return frame[keep].reset_index(drop=True)[list(LIQUID_COLUMNS)]
