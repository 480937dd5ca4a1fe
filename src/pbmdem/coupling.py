"""Coupled PBM-DEM and PBM-ANN loops: the validation study of the seed paper.

Both loops run the same PBM over the same coupling intervals. At the start of each interval the
PBM's current size distribution is turned into a **representative DEM sample**
(`representative_sample`) and the per-pair collision frequencies of its classes come either from
a LIGGGHTS run of that sample (PBM-DEM) or from the surrogate (PBM-ANN). The class frequencies
are interpolated onto the PBM bins (power law in size, clamped beyond the classes, as
`pbm.kernels.TableFrequency` does) and held for the interval.

Representative sample rule (documented in docs/validation.md):
1. the DEM bed holds the PBM's solid volume (the PBM models the DEM bed), so the particle number
   of bin k is the PBM number N_k;
2. neighbouring bins are merged, from small to large, until a class holds at least
   `min_particles_per_class` particles; a remainder at the large end joins the previous class; then
   the two neighbouring classes with the fewest particles are merged until at most `max_classes`
   remain. A class's diameter is the volume-equivalent diameter of its mean solid volume, so
   merging conserves number and solid volume. Diameters are rounded to whole nanometres
   (`DIAMETER_RESOLUTION`): the DEM is chaotic, and an input changed by round-off alone, for
   example a diameter one unit in the last place apart, changes its collision counts and the loop's
   final d50 by about 2 %. Rounding keeps the reference reproducible when the PBM's arithmetic is
   reordered;
3. class numbers are rounded; if they exceed `max_particles` all are scaled down (a smaller bed,
   with a warning).

Every finished interval is written to disk (`interval_NN/`: state, PBM records, class
frequencies, timings) before the next begins; a rerun resumes after the last finished interval.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pbmdem.atomic import atomic_path, write_csv, write_json
from pbmdem.collisions import pair_weighted_mean
from pbmdem.impact import EncounterRates
from pbmdem.readers import read_json, read_table

log = logging.getLogger(__name__)

DEFAULTS = {
    "rpm": [450, 900],
    "distribution": "mixed",
    "coupling_intervals": 6,
    "dem_sampling_time": 0.1,
    "max_classes": 5,
    "min_particles_per_class": 20,
    "max_particles": 4000,
    "sweep": {"start": 300, "stop": 1200, "num": 10},
}


class CouplingError(RuntimeError):
    """The coupled loop stopped; finished intervals are kept on disk."""


@contextlib.contextmanager
def out_of_domain_recorded(where: str, log_each: bool = True):
    """Collect the surrogate's OutOfDomainWarning messages (its own mechanism for inputs outside
    the training range) into the yielded list and log each one; every other warning is passed on
    unchanged. Nothing is silenced: the caller counts and reports what was collected."""
    from pbmdem.surrogate import OutOfDomainWarning

    found: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", OutOfDomainWarning)
        yield found
    for w in caught:
        if issubclass(w.category, OutOfDomainWarning):
            found.append(str(w.message))
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if log_each:
        for message in found:
            log.warning("%s: surrogate out of its training domain: %s", where, message)


def settings_from_config(cfg: dict) -> dict:
    out = json.loads(json.dumps(DEFAULTS))
    for key, value in (cfg.get("validation") or {}).items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key].update(value)
        else:
            out[key] = value
    return out


@dataclass
class DemSample:
    diameters: list[float]
    counts: list[int]
    bins: list[list[int]]  # PBM bins merged into each class
    scaled_down: float = 1.0  # < 1 when the sample was capped at max_particles

    @property
    def n_particles(self) -> int:
        return int(sum(self.counts))

    @property
    def number_fractions(self) -> list[float]:
        n = np.asarray(self.counts, float)
        return (n / n.sum()).tolist()


#: class diameters handed to LIGGGHTS are rounded to this (m); see the module docstring, rule 2
DIAMETER_RESOLUTION = 1e-9


def representative_sample(volumes, numbers, *, max_classes: int = 5, min_particles_per_class: int = 20,
                          max_particles: int = 4000) -> DemSample:
    """DEM classes for a PBM distribution (bin solid volumes `volumes`, numbers `numbers`)."""
    x = np.asarray(volumes, float)
    n = np.asarray(numbers, float)
    if x.shape != n.shape or x.ndim != 1:
        raise ValueError(f"volumes {x.shape} and numbers {n.shape} must be 1-D of the same length")
    if max_classes < 1 or min_particles_per_class < 1:
        raise ValueError(f"max_classes = {max_classes}, min_particles_per_class = {min_particles_per_class}: "
                         "both must be at least 1")
    total = n.sum()
    if not total >= min_particles_per_class:
        raise ValueError(f"the PBM holds {total:.3g} particles, fewer than min_particles_per_class = "
                         f"{min_particles_per_class}: no representative DEM bed can be formed")
    groups: list[list[int]] = []
    current: list[int] = []
    acc = 0.0
    for k in np.flatnonzero(n > 0):
        current.append(int(k))
        acc += n[k]
        if acc >= min_particles_per_class:
            groups.append(current)
            current, acc = [], 0.0
    if current:
        if groups:
            groups[-1].extend(current)
        else:
            groups.append(current)
    count = lambda g: float(n[g].sum())  # noqa: E731
    while len(groups) > max_classes:
        pair_counts = [count(a) + count(b) for a, b in zip(groups, groups[1:])]
        j = int(np.argmin(pair_counts))
        groups[j: j + 2] = [groups[j] + groups[j + 1]]
    diam = [round(float((6.0 / math.pi * float((n[g] * x[g]).sum() / n[g].sum())) ** (1.0 / 3.0))
                  / DIAMETER_RESOLUTION) * DIAMETER_RESOLUTION for g in groups]
    counts = np.array([count(g) for g in groups])
    scale = 1.0
    if counts.sum() > max_particles:
        scale = max_particles / counts.sum()
        warnings.warn(f"representative DEM sample of {counts.sum():.0f} particles capped at max_particles = "
                      f"{max_particles}: the DEM bed is scaled down by {scale:.3f}", stacklevel=2)
    rounded = np.maximum(1, np.round(counts * scale)).astype(int)
    return DemSample(diameters=diam, counts=rounded.tolist(), bins=groups, scaled_down=scale)


def class_table(diameters, matrix) -> pd.DataFrame:
    """Upper-triangular class-pair frame with d_i, d_j, frequency_per_pair (TableFrequency input)."""
    d = np.asarray(diameters, float)
    i, j = np.triu_indices(len(d))
    return pd.DataFrame({"d_i": d[i], "d_j": d[j], "frequency_per_pair": np.asarray(matrix, float)[i, j]})


def fractions_from_table(velocities: pd.DataFrame, k: int) -> np.ndarray:
    """(K, K, V) fraction of each class pair's encounters per velocity bin, from one DEM run's
    impact_velocity.csv (a pair without encounters gets the fractions pooled over all pairs)."""
    from pbmdem.impact import N_VELOCITY_BINS, velocity_bin

    upper = np.zeros((k, k, N_VELOCITY_BINS))
    b = velocity_bin(velocities.v_lo.to_numpy(float))
    np.add.at(upper, (velocities.class_i.to_numpy(), velocities.class_j.to_numpy(), b),
              velocities.encounters.to_numpy(float))
    counts = upper + np.transpose(np.triu(np.ones((k, k)), 1)[:, :, None] * upper, (1, 0, 2))
    pooled = upper.sum(axis=(0, 1))
    fallback = pooled / pooled.sum() if pooled.sum() > 0 else np.full(N_VELOCITY_BINS, 1.0 / N_VELOCITY_BINS)
    total = counts.sum(axis=2, keepdims=True)
    return np.where(total > 0, counts / np.where(total > 0, total, 1.0), fallback)


def matrix_from_table(table: pd.DataFrame, k: int) -> np.ndarray:
    c = np.zeros((k, k))
    c[table.class_i.to_numpy(), table.class_j.to_numpy()] = table.encounter_frequency_per_pair.to_numpy()
    return np.triu(c) + np.triu(c, 1).T


class ClassFrequencySource:
    """Hold class frequencies for an interval and interpolate them onto any PBM bins.

    `matrix` is the (K, K) encounter frequency per class pair, or a pbmdem.impact.EncounterRates
    whose velocity fractions then make the source velocity-resolved (:meth:`encounters`): a PBM
    bin takes the fractions of the DEM class nearest to it in log diameter."""

    def __init__(self, diameters, matrix, label: str):
        from pbmdem.impact import EncounterRates
        from pbmdem.pbm.kernels import TableFrequency

        self.diameters = list(map(float, diameters))
        self.fractions = None
        if isinstance(matrix, EncounterRates):
            self.fractions = np.asarray(matrix.velocity_fractions, float)
            matrix = matrix.frequency
        self.matrix = np.asarray(matrix, float)
        self.label = label
        if len(self.diameters) == 1:
            self._value = float(self.matrix[0, 0])
            self._table = None
        else:
            self._table = TableFrequency(class_table(self.diameters, self.matrix), extrapolation="clamp",
                                         column="frequency_per_pair")

    def __repr__(self) -> str:
        return f"ClassFrequencySource({self.label}, classes={len(self.diameters)})"

    def encounters(self, diameters, numbers, rpm):
        from pbmdem.impact import EncounterRates

        if self.fractions is None:
            raise ValueError(f"{self.label}: no impact-velocity distribution for a velocity-dependent success model")
        d = np.log(np.atleast_1d(np.asarray(diameters, float)))
        nearest = np.abs(d[:, None] - np.log(np.asarray(self.diameters))[None, :]).argmin(axis=1)
        return EncounterRates(self(diameters, numbers, rpm), self.fractions[np.ix_(nearest, nearest)])

    def __call__(self, diameters, numbers, rpm) -> np.ndarray:
        # within an interval the class frequencies are fixed and the PBM bins do not move, so the
        # interpolated matrix is computed once per set of bin diameters
        key = np.asarray(diameters, float).tobytes()
        if getattr(self, "_cache_key", None) == key:
            return self._cache
        if self._table is None:
            k = np.atleast_1d(diameters).size
            out = np.full((k, k), self._value)
        else:
            out = self._table(diameters, numbers, rpm)
        self._cache_key, self._cache = key, out
        return out


# ----------------------------------------------------------------------------- providers
class DemProvider:
    """Class collision frequencies from a LIGGGHTS run of the representative sample."""

    name = "pbm_dem"

    def __init__(self, cfg: dict, rpm: float, sampling_time: float):
        self.cfg = json.loads(json.dumps(cfg))
        self.cfg["dem"]["sampling_time"] = float(sampling_time)
        self.cfg["dem"]["keep_contact_dumps"] = False
        self.rpm = float(rpm)

    def fingerprint(self) -> dict:
        return {"name": self.name, "dem": self.cfg["dem"], "rpm": self.rpm}

    def __call__(self, sample: DemSample, interval_dir: Path, index: int) -> tuple[np.ndarray, dict]:
        from pbmdem import dem

        plan = dem.plan_point(self.cfg, self.rpm, f"interval{index:02d}", n_particles=sample.n_particles,
                              diameters=sample.diameters, number_fractions=sample.number_fractions)
        plan.counts = list(sample.counts)
        # an interval without interval.json is unfinished, whatever its DEM folder holds
        summary = dem.run_point(self.cfg, plan, interval_dir / "dem", timeout=self.cfg["dem"].get("timeout"),
                                force=True)
        table = read_table(interval_dir / "dem" / "collisions.csv", "collision table of a coupling interval",
                           columns=("class_i", "class_j", "encounter_frequency_per_pair"),
                           finite=("encounter_frequency_per_pair",))
        velocities = read_table(interval_dir / "dem" / "impact_velocity.csv",
                                "impact-velocity table of a coupling interval",
                                columns=("class_i", "class_j", "v_lo", "encounters"), finite=("encounters",))
        k = len(sample.diameters)
        rates = EncounterRates(matrix_from_table(table, k), fractions_from_table(velocities, k))
        return rates, {
            "dem_wall_time_s": summary["liggghts_wall_time_s"] + summary["parse_time_s"],
            "dem_particles": summary["n_particles"], "dem_collisions": summary["total_collisions"],
            "dem_encounters": summary["total_encounters"],
        }


class SurrogateProvider:
    """Class collision frequencies from the trained surrogate (one vectorised call)."""

    name = "pbm_ann"

    def __init__(self, model_path: str | Path, rpm: float):
        from pbmdem.surrogate import load_surrogate

        self.model = load_surrogate(model_path)
        self.model_path = Path(model_path)
        self.rpm = float(rpm)
        # with a velocity model the provider also hands over impact-velocity fractions (one call)
        self.velocity_resolved = self.model.has_velocity_model()

    def fingerprint(self) -> dict:
        import hashlib

        return {"name": self.name, "rpm": self.rpm,
                "model_sha256": hashlib.sha256(self.model_path.read_bytes()).hexdigest()}

    def __call__(self, sample: DemSample, interval_dir: Path, index: int) -> tuple[np.ndarray, dict]:
        t0 = time.perf_counter()
        d, n = np.asarray(sample.diameters), np.asarray(sample.counts, float)
        with out_of_domain_recorded(f"{self.name} at rpm {self.rpm:g}, interval {index}") as found:
            if self.velocity_resolved:
                c = self.model.encounters(d, n, self.rpm)
            else:
                c = np.asarray(self.model.frequency_matrix(d, n, self.rpm), float)
        return c, {"ann_wall_time_s": time.perf_counter() - t0,
                                      "out_of_domain": "; ".join(sorted(set(found))),
                                      "out_of_domain_count": len(found)}


# ----------------------------------------------------------------------------- the loop
def _discard_stale_intervals(outdir: Path, inputs: dict) -> None:
    """Finished intervals are reused only if they were computed from the same inputs (config,
    speed, sample rule and provider, e.g. the surrogate file's hash); otherwise they are removed."""
    import hashlib
    import shutil

    digest = hashlib.sha256(json.dumps(inputs, sort_keys=True, default=str).encode()).hexdigest()
    stamp = outdir / "loop_inputs.json"
    if stamp.exists() and json.loads(stamp.read_text()).get("sha256") == digest:
        return
    stale = sorted(outdir.glob("interval_*"))
    if stale:
        log.warning("inputs of %s changed: discarding %d finished intervals", outdir, len(stale))
        for folder in stale:
            shutil.rmtree(folder)
    write_json(stamp, {"sha256": digest, "inputs": inputs}, default=str)


def _save_interval(folder: Path, result, sample: DemSample, matrix: np.ndarray, info: dict) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_path(folder / "records.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, times=result.times, number=result.number, liquid=result.liquid, gas=result.gas,
                     liquid_added=result.liquid_added, refused=result.refused_volume, steps=result.steps,
                     state_t=result.state.t, state_number=result.state.number, state_liquid=result.state.liquid,
                     state_gas=result.state.gas, state_refused=result.state.refused_volume,
                     state_liquid_added=result.state.liquid_added, state_steps=result.state.steps,
                     class_matrix=matrix)
    # interval.json is written last: its presence marks the interval as finished
    write_json(folder / "interval.json", {**info, "sample": asdict(sample)})


def _load_interval(folder: Path, grid):
    from pbmdem.pbm.model import State
    from pbmdem.pbm.results import Result

    data = np.load(folder / "records.npz")

    class _Records:
        pass

    rec = _Records()
    for name in ("times", "number", "liquid", "gas", "liquid_added", "refused", "steps"):
        setattr(rec, name, data[name])
    state = State(float(data["state_t"]), data["state_number"], data["state_liquid"], data["state_gas"],
                  float(data["state_refused"]), float(data["state_liquid_added"]), int(data["state_steps"]))
    info = read_json(folder / "interval.json", "coupling interval record")
    return Result(grid, rec, state, {"wall_time_s": info.get("pbm_wall_time_s", 0.0)}), info, data["class_matrix"]


def run_loop(cfg: dict, provider, rpm: float, distribution: str, outdir: str | Path, *,
             intervals: int, sample_settings: dict) -> dict:
    """Run the PBM over `intervals` equal coupling intervals of the whole process, asking
    `provider(sample, interval_dir, index) -> (class matrix, info)` for frequencies at each.

    Writes `outdir/interval_NN/` per interval, then `summary.csv` (PBM time series),
    `intervals.csv` (per interval: classes, frequencies, wall times) and `final_bins.csv`.
    """
    from pbmdem.pbm.kernels import ConstantFrequency
    from pbmdem.pbm.results import Result
    from pbmdem.pbm.settings import build_model, initial_state_from_config, process_times, resolve_settings

    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    _discard_stale_intervals(outdir, {
        "config": cfg, "rpm": float(rpm), "distribution": distribution, "intervals": int(intervals),
        "sample_settings": sample_settings, "provider": provider.fingerprint(),
    })
    settings = resolve_settings(cfg)
    model = build_model(settings, ConstantFrequency(1.0), rpm=rpm)
    state = initial_state_from_config(cfg, model, distribution, settings)
    _, _, t_final = process_times(settings)
    bounds = np.linspace(0.0, t_final, int(intervals) + 1)
    out_step = float(settings["output"]["interval"])
    results, rows = [], []
    for k in range(int(intervals)):
        folder = outdir / f"interval_{k:02d}"
        if (folder / "interval.json").exists():
            result, info, _ = _load_interval(folder, model.grid)
            log.info("interval %d of %s: resumed from %s", k, provider.name, folder)
            results.append(result)
            rows.append({k2: v for k2, v in info.items() if k2 != "sample"})
            state = result.state
            continue
        t0, t1 = bounds[k], bounds[k + 1]
        sample = representative_sample(model.grid.x, state.number, **sample_settings)
        t_provider = time.perf_counter()
        try:
            rates, extra = provider(sample, folder, k)
        except Exception as exc:
            raise CouplingError(f"{provider.name} at rpm {rpm:g}: interval {k} ({t0:g}-{t1:g} s) failed: {exc}. "
                                f"Intervals 0..{k - 1} are kept in {outdir}; rerun to resume.") from exc
        provider_wall = time.perf_counter() - t_provider
        model.kernel.set_source(ClassFrequencySource(sample.diameters, rates, f"{provider.name} interval {k}"))
        matrix = rates.frequency if isinstance(rates, EncounterRates) else np.asarray(rates, float)
        times = np.arange(t0, t1 + 0.5 * out_step, out_step)
        times = times[(times >= t0) & (times <= t1)]
        t_pbm = time.perf_counter()
        result = model.run(t0, t1, state, output_times=times)
        pbm_wall = time.perf_counter() - t_pbm
        iu = np.triu_indices(len(sample.counts))
        info = {
            "interval": k, "t_start": t0, "t_end": t1, "rpm": rpm, "method": provider.name,
            "classes": len(sample.counts), "class_diameters": json.dumps(sample.diameters),
            "class_counts": json.dumps(sample.counts), "sample_particles": sample.n_particles,
            "class_frequencies": json.dumps(matrix[iu].tolist()),
            "mean_frequency_per_pair": pair_weighted_mean(matrix, sample.counts),
            "provider_wall_time_s": provider_wall, "pbm_wall_time_s": pbm_wall, **extra,
        }
        _save_interval(folder, result, sample, matrix, info)
        log.info("%s at rpm %g: interval %d of %d (%.4g-%.4g s) done: %s wall time %.2f s, PBM wall time %.3f s, "
                 "%d surrogate out-of-domain warning(s)", provider.name, rpm, k + 1, int(intervals), t0, t1,
                 "DEM" if provider.name == "pbm_dem" else "provider", provider_wall, pbm_wall,
                 int(extra.get("out_of_domain_count", 0)))
        results.append(result)
        rows.append(info)
        state = result.state
    full = Result.concat(results)
    write_csv(outdir / "summary.csv", full.summary())
    write_csv(outdir / "intervals.csv", pd.DataFrame(rows))
    bins = full.bins()
    write_csv(outdir / "final_bins.csv", bins[bins.time == bins.time.max()])
    totals = {
        "method": provider.name, "rpm": rpm, "distribution": distribution, "intervals": int(intervals),
        "provider_wall_time_s": float(sum(r["provider_wall_time_s"] for r in rows)),
        "pbm_wall_time_s": float(sum(r["pbm_wall_time_s"] for r in rows)),
    }
    if any("out_of_domain_count" in r for r in rows):
        per_interval = [int(r.get("out_of_domain_count", 0) or 0) for r in rows]
        totals["out_of_domain_count"] = int(sum(per_interval))
        totals["out_of_domain_intervals"] = int(sum(c > 0 for c in per_interval))
        if totals["out_of_domain_count"]:
            log.warning("%s at rpm %g: the surrogate was outside its training domain in %d of %d intervals "
                        "(%d warnings; see intervals.csv)", provider.name, rpm, totals["out_of_domain_intervals"],
                        len(rows), totals["out_of_domain_count"])
    totals["total_wall_time_s"] = totals["provider_wall_time_s"] + totals["pbm_wall_time_s"]
    write_json(outdir / "timing.json", totals)
    return totals


def run_constant(cfg: dict, rpm: float, distribution: str, outdir: str | Path, frequency: float,
                 info: dict | None = None) -> dict:
    """PBM with one constant c for every pair (`frequency`, 1/s per pair)."""
    from pbmdem.pbm.kernels import ConstantFrequency
    from pbmdem.pbm.settings import run_pbm

    outdir = Path(outdir)
    t0 = time.perf_counter()
    result = run_pbm(cfg, ConstantFrequency(frequency), rpm=rpm, distribution_name=distribution)
    wall = time.perf_counter() - t0
    write_csv(outdir / "summary.csv", result.summary())
    bins = result.bins()
    write_csv(outdir / "final_bins.csv", bins[bins.time == bins.time.max()])
    totals = {"method": "pbm_constant", "rpm": rpm, "distribution": distribution, "frequency": frequency,
              "total_wall_time_s": wall, "pbm_wall_time_s": wall, "provider_wall_time_s": 0.0, **(info or {})}
    write_json(outdir / "timing.json", totals)
    return totals


def initial_frequency(cfg: dict, model_path: str | Path, rpm: float, distribution: str,
                      sample_settings: dict, out_of_domain: list | None = None) -> float:
    """Pair-weighted mean per-pair frequency of the surrogate for the initial distribution: the
    constant kernel is calibrated to the same initial collision rate sum_ij c_ij pairs_ij.
    The surrogate's out-of-domain warnings are logged and appended to `out_of_domain`."""
    from pbmdem.pbm.kernels import ConstantFrequency
    from pbmdem.pbm.settings import build_model, initial_state_from_config, resolve_settings
    from pbmdem.surrogate import load_surrogate

    settings = resolve_settings(cfg)
    model = build_model(settings, ConstantFrequency(1.0), rpm=rpm)
    state = initial_state_from_config(cfg, model, distribution, settings)
    sample = representative_sample(model.grid.x, state.number, **sample_settings)
    surrogate = load_surrogate(model_path)
    with out_of_domain_recorded(f"constant-kernel calibration at rpm {rpm:g}") as found:
        c = surrogate.frequency_matrix(np.asarray(sample.diameters), np.asarray(sample.counts, float), rpm)
    if out_of_domain is not None:
        out_of_domain.extend(found)
    return pair_weighted_mean(c, sample.counts)


def sample_settings(validation: dict) -> dict:
    return {k: int(validation[k]) for k in ("max_classes", "min_particles_per_class", "max_particles")}


def run_method(method: str, cfg: dict, rpm: float, outdir: str | Path, model_path: str | Path | None = None) -> dict:
    """One validation run: method 'dem' (PBM-DEM), 'ann' (PBM-ANN) or 'constant' (PBM-constant)."""
    v = settings_from_config(cfg)
    dist = v["distribution"]
    samples = sample_settings(v)
    if method == "dem":
        provider = DemProvider(cfg, rpm, v["dem_sampling_time"])
        return run_loop(cfg, provider, rpm, dist, outdir, intervals=v["coupling_intervals"], sample_settings=samples)
    if model_path is None:
        raise ValueError(f"method {method!r} needs the trained surrogate (model_path)")
    if method == "ann":
        provider = SurrogateProvider(model_path, rpm)
        return run_loop(cfg, provider, rpm, dist, outdir, intervals=v["coupling_intervals"], sample_settings=samples)
    if method == "constant":
        found: list[str] = []
        c0 = initial_frequency(cfg, model_path, rpm, dist, samples, out_of_domain=found)
        return run_constant(cfg, rpm, dist, outdir, c0, info={"out_of_domain": "; ".join(sorted(set(found))),
                                                               "out_of_domain_count": len(found)})
    raise ValueError(f"validation method {method!r}: allowed 'dem', 'ann', 'constant'")


def rpm_sweep(cfg: dict, model_path: str | Path, table_path: str | Path, plot_path: str | Path) -> pd.DataFrame:
    """PBM-ANN at every speed of validation.sweep (evenly spaced, grid speeds and speeds between
    them): final d10/d50/d90 and mean diameters, and the d50(t) curves as a plot."""
    import tempfile

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = settings_from_config(cfg)
    sweep = v["sweep"]
    speeds = np.linspace(float(sweep["start"]), float(sweep["stop"]), int(sweep["num"]))
    rows, curves = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for rpm in speeds:
            provider = SurrogateProvider(model_path, rpm)
            t0 = time.perf_counter()
            run_loop(cfg, provider, float(rpm), v["distribution"], Path(tmp) / f"rpm{rpm:g}",
                     intervals=v["coupling_intervals"], sample_settings=sample_settings(v))
            wall = time.perf_counter() - t0
            summary = pd.read_csv(Path(tmp) / f"rpm{rpm:g}" / "summary.csv")
            ood = pd.read_csv(Path(tmp) / f"rpm{rpm:g}" / "intervals.csv").get("out_of_domain_count", pd.Series([0]))
            last = summary.iloc[-1]
            rows.append({"rpm": float(rpm), "d10": last.d10, "d50": last.d50, "d90": last.d90,
                         "number_mean_diameter": last.number_mean_diameter,
                         "mass_mean_diameter": last.mass_mean_diameter, "total_number": last.total_number,
                         "wall_time_s": wall, "out_of_domain_intervals": int((ood.fillna(0) > 0).sum()),
                         "out_of_domain_count": int(ood.fillna(0).sum())})
            curves.append((rpm, summary.time.to_numpy(), summary.d50.to_numpy()))
            log.info("rpm sweep: %g rpm done (%d of %d) in %.2f s; final d50 %.4g m; surrogate out of its "
                     "training domain in %d interval(s)", rpm, len(rows), len(speeds), wall, last.d50,
                     rows[-1]["out_of_domain_intervals"])
    table = pd.DataFrame(rows)
    write_csv(table_path, table)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    cmap = plt.get_cmap("viridis")
    for k, (rpm, t, d50) in enumerate(curves):
        ax1.plot(t, 1e3 * d50, color=cmap(k / max(1, len(curves) - 1)), label=f"{rpm:g} rpm")
    ax1.set_xlabel("time (s)")
    ax1.set_ylabel("d50 (mm)")
    ax1.set_title("PBM-ANN: d50 over the batch")
    ax1.legend(fontsize=7, ncol=2)
    ax2.plot(table.rpm, 1e3 * table.d50, "o-", label="d50")
    ax2.plot(table.rpm, 1e3 * table.d90, "s--", label="d90")
    ax2.plot(table.rpm, 1e3 * table.d10, "^--", label="d10")
    ax2.set_xlabel("impeller speed (rpm)")
    ax2.set_ylabel("final size (mm)")
    ax2.set_title("PBM-ANN: final sizes vs impeller speed")
    ax2.legend()
    fig.tight_layout()
    with atomic_path(plot_path) as tmp_png:
        fig.savefig(tmp_png, dpi=110)
    plt.close(fig)
    return table


class SampledSurrogateSource:
    """The surrogate as a PBM collision-frequency source: the PBM distribution is reduced to the
    representative DEM sample (as in the coupled loops), the surrogate predicts its class-pair
    frequencies, and these are interpolated back onto the bins. Used by `pbmdem pbm --kernel ann`."""

    def __init__(self, model_path: str | Path, sample_settings: dict | None = None):
        from pbmdem.surrogate import load_surrogate

        self.model = load_surrogate(model_path)
        self.sample_settings = sample_settings or sample_settings_default()
        self.calls = 0  # surrogate evaluations
        self.calls_out_of_domain = 0  # of which with at least one input outside the training range
        self.out_of_domain: dict[str, int] = {}  # feature -> evaluations with it out of range
        self.first_message: dict[str, str] = {}

    def __repr__(self) -> str:
        return f"SampledSurrogateSource({self.sample_settings})"

    def __call__(self, diameters, numbers, rpm) -> np.ndarray:
        d = np.asarray(diameters, float)
        sample = representative_sample(np.pi / 6.0 * d**3, np.asarray(numbers, float), **self.sample_settings)
        with out_of_domain_recorded("pbm --kernel ann", log_each=False) as found:
            c = self.model.frequency_matrix(np.asarray(sample.diameters), np.asarray(sample.counts, float), rpm)
        self.calls += 1
        self.calls_out_of_domain += bool(found)
        for message in found:  # the PBM evaluates the kernel often: log each input's first excursion
            feature = message.split(" = ", 1)[0]
            if feature not in self.out_of_domain:
                self.first_message[feature] = message
                log.warning("pbm --kernel ann: surrogate out of its training domain: %s", message)
            self.out_of_domain[feature] = self.out_of_domain.get(feature, 0) + 1
        return ClassFrequencySource(sample.diameters, c, "surrogate")(d, numbers, rpm)

    def domain_report(self) -> dict:
        """Counts of out-of-domain evaluations, for run.json and the CLI's message."""
        return {"surrogate_evaluations": self.calls, "out_of_domain_evaluations": self.calls_out_of_domain,
                "out_of_domain_by_feature": dict(self.out_of_domain),
                "out_of_domain_first": dict(self.first_message)}


def sample_settings_default() -> dict:
    return sample_settings(DEFAULTS)
