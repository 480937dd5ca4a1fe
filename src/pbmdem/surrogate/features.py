"""Features and target of the encounter surrogate.

Input is the aggregated collision table of ``docs/architecture.md`` (one row per unordered class
pair and DEM run, ``point_id`` identifies the run). Every row becomes one sample with the
features in :data:`FEATURE_NAMES`; the target is ``log10(encounter_frequency_per_pair)``, the
frequency per pair of *encounters* (impacts of granules that were apart), averaged over the DEM
replicates (insertion seeds) of the run. The raw ``collisions``, ``frequency_per_pair`` are not learned.

:func:`training_data` is the one place that turns a collision table (and its impact-velocity
table) into what every model is fitted on: ``X``, ``y``, ``groups`` (DEM runs), the replicate
noise variance and the impact-speed targets. The impeller radius for the tip-speed feature is
always passed in (``granulator.impeller.blade_length``); nothing here reads the config.

The PBM's class pairs get their features from the same definition (:func:`pair_table` with
:func:`make_features`, or :func:`pair_features` without DataFrames), so training and prediction
cannot disagree about a feature.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from pbmdem.config.granulator import tip_speed as granulator_tip_speed
from pbmdem.frequency import upper_pairs
from pbmdem.impact import N_VELOCITY_BINS

from .errors import CollisionTableError
from .velocity import attach_velocity_bins, bin_counts, fit_speed_law, n_law_parameters, velocity_rows

#: Columns that name a row of the collision table: its run, its class pair and their diameters.
PAIR_ID_COLUMNS = ("point_id", "rpm", "distribution", "class_i", "class_j", "d_i", "d_j")

#: Columns needed to build features (the others are needed only for the target).
FEATURE_SOURCE_COLUMNS = ("point_id", "rpm", "class_i", "class_j", "d_i", "d_j", "n_i", "n_j", "n_total")

#: Model inputs, in this order.
FEATURE_NAMES = (
    "d_small",  # smaller diameter of the colliding pair (m)
    "d_large",  # larger diameter of the colliding pair (m)
    "frac_small",  # number fraction of the smaller particle's class in the run
    "frac_large",  # number fraction of the larger particle's class in the run
    "n_total",  # particles in the run
    "tip_speed",  # impeller tip speed 2 pi R rpm / 60 (m/s)
    "rel_small",  # d_small / d32, d32 = sum n d^3 / sum n d^2 the run's Sauter mean diameter
    "rel_large",  # d_large / d32: where the pair sits in its run's distribution
)
# Not features, because they duplicate one above (docs/surrogate.md, "Features"):
# * rpm: tip_speed = 2 pi R rpm / 60 with one impeller radius R;
# * d_mean (number-mean diameter of the run): every DEM bed has the same solid volume, so
#   n_total ~ 1 / <d^3>, and on the configured grid log n_total and log d_mean correlate at -0.9994.

#: |Pearson r| above which two features of a training table count as duplicates (warned at fit).
DUPLICATE_CORRELATION = 0.999

#: Column of the collision table that is learned (1/s per pair, mean over replicates).
TARGET_COLUMN = "encounter_frequency_per_pair"
#: Its standard error over replicates (for the replicate noise floor).
TARGET_SE_COLUMN = "encounter_frequency_per_pair_se"
TARGET_NAME = "log10_encounter_frequency_per_pair"
#: Delta-method variance of TARGET_NAME from the replicate SE: (SE / (c ln 10))^2 (decades^2).
TARGET_NOISE_VAR = "log10_noise_var"

#: How rows with zero collisions are treated when building the target.
ZERO_POLICIES = ("drop", "floor")


def check_impeller_radius(impeller_radius) -> float:
    """The impeller radius (m) as a float; ValueError unless it is a finite number > 0."""
    try:
        value = float(impeller_radius)
    except (TypeError, ValueError):
        value = float("nan")
    if isinstance(impeller_radius, bool) or not (math.isfinite(value) and value > 0):
        raise ValueError(
            f"impeller_radius (granulator.impeller.blade_length) must be a finite number > 0 m, got {impeller_radius!r}"
        )
    return value


def tip_speed(rpm, impeller_radius: float):
    """Impeller tip speed (m/s) for a speed in rpm and a radius in m (pbmdem.config's formula)."""
    return granulator_tip_speed(np.asarray(rpm, dtype=float), check_impeller_radius(impeller_radius))


def check_table(table: pd.DataFrame, columns=FEATURE_SOURCE_COLUMNS) -> None:
    """Raise :class:`CollisionTableError` if ``table`` lacks columns or has invalid values."""
    if not isinstance(table, pd.DataFrame):
        raise TypeError(f"expected a pandas DataFrame collision table, got {type(table).__name__}")
    missing = [c for c in columns if c not in table.columns]
    if missing:
        raise CollisionTableError(f"collision table lacks column(s) {missing}")
    if len(table) == 0:
        raise CollisionTableError("collision table has no rows")
    numeric = [c for c in columns if c not in ("point_id", "distribution")]
    values = table[numeric].apply(pd.to_numeric, errors="coerce")
    bad = values.columns[values.isna().any()].tolist()
    if bad:
        raise CollisionTableError(f"non-numeric or missing values in column(s) {bad}")
    bounds = {"d_i": ">", "d_j": ">", "n_total": ">", "rpm": ">", "n_i": ">=", "n_j": ">=", "sampling_time": ">"}
    for col, low in bounds.items():
        if col in values and ((values[col] <= 0) if low == ">" else (values[col] < 0)).any():
            raise CollisionTableError(f"column {col!r} must be {low} 0")
    if (values["class_i"] > values["class_j"]).any():
        raise CollisionTableError("rows must have class_i <= class_j")
    per_run = table.groupby("point_id")[["rpm", "n_total"]].nunique()
    inconsistent = per_run.index[(per_run > 1).any(axis=1)].tolist()
    if inconsistent:
        raise CollisionTableError(f"rpm or n_total not constant within run(s) {inconsistent}")


def run_classes(table: pd.DataFrame) -> pd.DataFrame:
    """Size classes of every run: one row per (point_id, class) with columns d, n.

    Collected from both sides of every row, so any number of classes per run works (the diagonal
    rows alone already list every class; off-diagonal rows only confirm them).
    """
    left = table[["point_id", "class_i", "d_i", "n_i"]].set_axis(["point_id", "cls", "d", "n"], axis=1)
    right = table[["point_id", "class_j", "d_j", "n_j"]].set_axis(["point_id", "cls", "d", "n"], axis=1)
    both = pd.concat([left, right], ignore_index=True)
    both["d"] = both["d"].astype(float)
    both["n"] = both["n"].astype(float)
    spread = both.groupby(["point_id", "cls"])[["d", "n"]].agg(lambda s: s.max() - s.min())
    if (spread["d"] > 1e-12 * both["d"].abs().max()).any() or (spread["n"] > 0).any():
        bad = spread.index[(spread > 0).any(axis=1)].tolist()[:5]
        raise CollisionTableError(f"a class has different d or n in different rows of one run: {bad}")
    return both.drop_duplicates(["point_id", "cls"]).sort_values(["point_id", "cls"]).reset_index(drop=True)


def _checked_runs(table: pd.DataFrame):
    """The runs' classes (:func:`run_classes`, grouped by ``point_id``), after checking that they
    are consistent; warns where their numbers do not add up to the run's ``n_total``."""
    runs = run_classes(table).groupby("point_id")
    n_sum = runs["n"].sum()
    if (n_sum <= 0).any():
        raise CollisionTableError("a run has no particles in its classes")
    n_total = table.groupby("point_id")["n_total"].first().astype(float)
    mismatch = n_sum.index[~np.isclose(n_sum, n_total, rtol=1e-9)].tolist()
    if mismatch:
        warnings.warn(
            f"run(s) {mismatch[:5]}: class numbers do not add up to n_total; "
            "fractions use n_total, the mean diameter uses the listed classes",
            stacklevel=3,
        )
    return runs


def make_features(table: pd.DataFrame, impeller_radius: float) -> pd.DataFrame:
    """Feature frame (columns :data:`FEATURE_NAMES`, same index as ``table``) of a collision table."""
    check_table(table)
    runs = _checked_runs(table)  # a statement, not inside the comprehension: its warning's stacklevel
    d32 = {p: sauter_diameter(c["d"].to_numpy(), c["n"].to_numpy()) for p, c in runs}
    columns = (table[c].to_numpy(float) for c in ("d_i", "d_j", "n_i", "n_j", "n_total", "rpm"))
    X = _feature_array(*columns, table["point_id"].map(d32).to_numpy(float), impeller_radius)
    return pd.DataFrame(X, index=table.index, columns=list(FEATURE_NAMES))


def sauter_diameter(d: np.ndarray, n: np.ndarray) -> float:
    """Sauter mean diameter sum n d^3 / sum n d^2 of classes of sizes ``d`` and numbers ``n``."""
    return float((n * d**3).sum() / (n * d**2).sum())


def _feature_array(d_i, d_j, n_i, n_j, n_total, rpm, d32, impeller_radius: float) -> np.ndarray:
    """(n, len(FEATURE_NAMES)) features of pairs of classes (sizes d, numbers n) in beds of
    ``n_total`` particles at ``rpm`` whose Sauter mean diameter is ``d32``: the one definition of
    :data:`FEATURE_NAMES`."""
    f_i, f_j = n_i / n_total, n_j / n_total
    i_small = d_i <= d_j
    X = np.empty((np.size(d_i), len(FEATURE_NAMES)))
    X[:, 0] = np.where(i_small, d_i, d_j)
    X[:, 1] = np.where(i_small, d_j, d_i)
    X[:, 2] = np.where(i_small, f_i, f_j)
    X[:, 3] = np.where(i_small, f_j, f_i)
    X[:, 4] = n_total
    X[:, 5] = tip_speed(rpm, impeller_radius)
    X[:, 6] = X[:, 0] / d32
    X[:, 7] = X[:, 1] / d32
    return X


def duplicated_features(
    features: pd.DataFrame, threshold: float = DUPLICATE_CORRELATION
) -> list[tuple[str, str, float]]:
    """Pairs of feature columns whose |Pearson r| (of the values and of their logs) exceeds ``threshold``.

    Such a pair carries one piece of information twice on this table: the network cannot tell
    the two apart, and predictions where they disagree are extrapolations.
    """
    out = []
    with np.errstate(divide="ignore"):
        for values in (features.astype(float), np.log(features.abs().astype(float))):
            r = values.replace([np.inf, -np.inf], np.nan).corr(min_periods=3)  # pairwise-complete rows
            for a, b in zip(*np.triu_indices(len(r), 1)):
                pair = (r.index[a], r.columns[b])
                if abs(r.iat[a, b]) > threshold and not any(p[:2] == pair for p in out):
                    out.append((*pair, float(r.iat[a, b])))
    return out


def prepare_training_table(table: pd.DataFrame, zero_policy: str = "drop") -> pd.DataFrame:
    """Rows usable for fitting, with columns :data:`TARGET_NAME` and :data:`TARGET_NOISE_VAR` added.

    The target is ``log10(encounter_frequency_per_pair)`` (mean over the run's replicates).

    * rows without any particle pair (pairs = 0) or with a non-finite encounter frequency are
      dropped with a warning;
    * rows with zero encounters: ``"drop"`` (default) removes them with a warning; ``"floor"``
      replaces the count by half an encounter over all replicates, i.e. the frequency by the
      detection limit ``0.5 / (n_replicates x pairs x sampling_time)``, also with a warning.
      Column ``floored`` marks such rows.

    :data:`TARGET_NOISE_VAR` is the replicate noise of the target by the delta method,
    ``(SE / (c ln 10))^2`` (NaN where the SE is unknown, e.g. a single replicate or a floored row).
    """
    if zero_policy not in ZERO_POLICIES:
        raise ValueError(f"zero_policy must be one of {ZERO_POLICIES}, got {zero_policy!r}")
    check_table(table, FEATURE_SOURCE_COLUMNS + ("encounters", "sampling_time"))
    if TARGET_COLUMN not in table.columns:
        raise CollisionTableError(f"collision table lacks column(s) {[TARGET_COLUMN]}")
    out = table.copy()
    n_i, n_j = out["n_i"].to_numpy(float), out["n_j"].to_numpy(float)
    pairs = np.where(out["class_i"].to_numpy() == out["class_j"].to_numpy(), n_i * (n_i - 1.0) / 2.0, n_i * n_j)
    fpp = pd.to_numeric(out[TARGET_COLUMN], errors="coerce").to_numpy(float)
    counts = out["encounters"].to_numpy(float)
    if "n_replicates" in out:
        reps = pd.to_numeric(out["n_replicates"], errors="coerce").to_numpy(float)
        if not (np.isfinite(reps) & (reps >= 1)).all():
            raise CollisionTableError("column 'n_replicates' must be an integer >= 1 in every row")
    else:
        reps = np.ones(len(out))
    if TARGET_SE_COLUMN in out:
        se = pd.to_numeric(out[TARGET_SE_COLUMN], errors="coerce").to_numpy(float)
        if (se < 0).any():
            raise CollisionTableError(f"column {TARGET_SE_COLUMN!r} must be >= 0 (or NaN for one replicate)")
    else:
        se = np.full(len(out), np.nan)
    no_pairs = ~(pairs > 0)
    if no_pairs.any():
        warnings.warn(
            f"dropping {int(no_pairs.sum())} row(s) without particle pairs "
            f"(e.g. a class with a single particle on the diagonal)",
            stacklevel=2,
        )
    zero = ~no_pairs & ((counts <= 0) | (np.nan_to_num(fpp, nan=1.0) <= 0))
    out["floored"] = False
    if zero.any():
        ids = sorted(set(out.loc[zero, "point_id"].astype(str)))
        if zero_policy == "drop":
            warnings.warn(
                f"dropping {int(zero.sum())} row(s) with zero encounters (log10 undefined) in run(s) {ids[:5]}",
                stacklevel=2,
            )
        else:
            warnings.warn(
                f"flooring {int(zero.sum())} row(s) with zero encounters at half an encounter "
                f"over all replicates of the sampling window, run(s) {ids[:5]}",
                stacklevel=2,
            )
            fpp = fpp.copy()
            fpp[zero] = 0.5 / (reps[zero] * pairs[zero] * out["sampling_time"].to_numpy(float)[zero])
            out[TARGET_COLUMN] = fpp
            out.loc[zero, "floored"] = True
            se = np.where(zero, np.nan, se)
    drop = no_pairs | (zero if zero_policy == "drop" else np.zeros_like(zero))
    bad = ~drop & ~(np.isfinite(fpp) & (fpp > 0))
    if bad.any():
        warnings.warn(f"dropping {int(bad.sum())} row(s) with a non-finite {TARGET_COLUMN}", stacklevel=2)
    keep = ~(drop | bad)
    with np.errstate(divide="ignore", invalid="ignore"):
        noise_var = (se / (fpp * math.log(10.0))) ** 2
    out[TARGET_NOISE_VAR] = noise_var
    out = out.loc[keep].copy()
    out[TARGET_NAME] = np.log10(out[TARGET_COLUMN].to_numpy(float))
    if len(out) == 0:
        raise CollisionTableError("no usable rows left in the collision table")
    return out


def pair_table(diameters, numbers, rpm: float) -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """Collision-table-like frame of all unordered class pairs (i <= j) of one size distribution
    and the row/column indices (``iu``, ``ju``) of each row in the (K, K) matrix."""
    d, n = _distribution(diameters, numbers, rpm)
    iu, ju = upper_pairs(d.size)
    columns = {"point_id": "query", "rpm": float(rpm), "class_i": iu, "class_j": ju, "d_i": d[iu], "d_j": d[ju]}
    return pd.DataFrame({**columns, "n_i": n[iu], "n_j": n[ju], "n_total": n.sum()}), iu, ju


def _distribution(diameters, numbers, rpm) -> tuple[np.ndarray, np.ndarray]:
    """The class diameters and numbers of one size distribution, checked (ValueError)."""
    d = np.asarray(diameters, dtype=float)
    n = np.asarray(numbers, dtype=float)
    if d.ndim != 1 or n.shape != d.shape or d.size == 0:
        raise ValueError(f"diameters and numbers must be 1-d of the same length, got {d.shape} and {n.shape}")
    if not (np.all(np.isfinite(d)) and np.all(d > 0)):
        raise ValueError("diameters must be finite and > 0")
    if not (np.all(np.isfinite(n)) and np.all(n >= 0)) or n.sum() <= 0:
        raise ValueError("numbers must be finite, >= 0 and not all zero")
    if not (np.isfinite(rpm) and rpm > 0):
        raise ValueError(f"rpm must be finite and > 0, got {rpm!r}")
    return d, n


def pair_features(diameters, numbers, rpm: float, impeller_radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The feature matrix (K (K + 1) / 2, len(FEATURE_NAMES)) of all unordered class pairs of one
    size distribution, without DataFrames: the values of ``make_features(pair_table(...)[0])``
    (the same operations), for the PBM's calls. Returns the matrix (C-ordered, columns
    :data:`FEATURE_NAMES`) and the row/column indices ``iu``, ``ju`` of each row."""
    d, n = _distribution(diameters, numbers, rpm)
    iu, ju = upper_pairs(d.size)
    rpm = np.full(iu.size, float(rpm))
    return _feature_array(d[iu], d[ju], n[iu], n[ju], n.sum(), rpm, sauter_diameter(d, n), impeller_radius), iu, ju


@dataclass(frozen=True)
class TrainingData:
    """Model inputs and targets of a collision table, one row per usable class pair and run.

    Every surrogate model (the MLP surrogate and its baselines) is fitted as
    ``model.fit(X, y, groups=groups)`` (plus ``velocity=velocity`` and ``velocity_counts`` for the models
    that learn the impact speeds); the rows are those of ``table``, in the same order (index 0..n-1).
    """

    X: pd.DataFrame
    """Features, columns :data:`FEATURE_NAMES`."""
    y: np.ndarray
    """Target :data:`TARGET_NAME`: log10 of the encounter frequency per pair (1/s)."""
    groups: np.ndarray
    """``point_id`` (str) of every row: one group per DEM run."""
    noise_var: np.ndarray
    """:data:`TARGET_NOISE_VAR`: replicate noise variance of ``y`` (decades^2, NaN if unknown)."""
    velocity: np.ndarray
    """(n, 2) impact-speed law (``speed_law``) of every row: ``mu`` (log10 median speed, m/s), ``sigma``
    (std of log10 v, decades), for ``gengamma`` the shape q; fitted to its bins; NaN without bins."""
    table: pd.DataFrame
    """The rows used (:func:`prepare_training_table`), with the target columns and ``floored``."""
    n_dropped: int
    """Rows of the input table left out (no pairs, zero encounters with ``drop``, non-finite)."""
    n_floored: int
    """Rows whose zero count was floored (``zero_policy="floor"``)."""
    speed_law: str = "lognormal"
    """The impact-speed law ``velocity`` was fitted with (:data:`~pbmdem.surrogate.velocity.SPEED_LAWS`)."""
    speed_law_from: float | None = None
    """The speed (m/s) from which the law was fitted to the bins (slower impacts one cell); None: every bin."""
    velocity_counts: np.ndarray | None = None
    """(n, bins) impacts per velocity bin of every row (NaN: no bins): the pooled fast tail's data."""


def training_data(
    table: pd.DataFrame,
    impeller_radius: float,
    zero_policy: str = "drop",
    velocity_table: pd.DataFrame | None = None,
    velocity_source: str = "impact-velocity table",
    speed_law: str = "lognormal",
    speed_law_from: float | None = None,
) -> TrainingData:
    """Features, target, groups, replicate noise and impact-speed targets of a collision table.

    ``table`` is the collision table (``results/dem/collisions.csv``); ``velocity_table`` the
    impact-velocity table (``results/dem/impact_velocity.csv``, long format), attached with
    :func:`~pbmdem.surrogate.velocity.attach_velocity_bins` (named ``velocity_source`` in errors);
    a table whose bins are already attached needs none. Without bins only the encounter frequency
    can be learned (a warning says so). ``impeller_radius`` (m) is
    ``granulator.impeller.blade_length``, for the tip-speed feature. ``speed_law`` is the
    impact-speed law fitted to every row's bins (:data:`~pbmdem.surrogate.velocity.SPEED_LAWS`),
    from the speed ``speed_law_from`` up (:func:`~pbmdem.surrogate.velocity.fit_speed_law`'s ``fit_from``).
    """
    if velocity_table is not None:
        table = attach_velocity_bins(table, velocity_table, source=velocity_source)
    data = prepare_training_table(table, zero_policy).reset_index(drop=True)
    X = make_features(data, impeller_radius)
    velocity, vmask = np.full((len(data), n_law_parameters(speed_law)), np.nan), velocity_rows(data)
    counts = np.full((len(data), N_VELOCITY_BINS), np.nan)
    if vmask.any():
        counts[vmask] = bin_counts(data.loc[vmask])
        velocity[vmask] = np.column_stack(fit_speed_law(counts[vmask], speed_law, speed_law_from))
    else:
        warnings.warn(
            "the collision table carries no impact-velocity bins (results/dem/impact_velocity.csv "
            "not attached): the surrogate predicts encounter frequencies only",
            UserWarning,
            stacklevel=2,
        )
    return TrainingData(
        X=X,
        y=data[TARGET_NAME].to_numpy(float),
        groups=data["point_id"].astype(str).to_numpy(),
        noise_var=data[TARGET_NOISE_VAR].to_numpy(float),
        velocity=velocity,
        table=data,
        n_dropped=int(len(table) - len(data)),
        n_floored=int(data["floored"].sum()),
        speed_law=speed_law,
        speed_law_from=speed_law_from,
        velocity_counts=counts,
    )
