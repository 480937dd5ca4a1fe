"""The DEM collision table as a collision-frequency source: :class:`TableFrequency`.

Per-pair encounter frequencies (and impact-velocity fractions) of the DEM grid's operating points,
interpolated onto the PBM's classes in (log d_i, log d_j) and over impeller speed; the
interface ``source(diameters, numbers, rpm) -> (K, K)`` of ``pbmdem.pbm.kernels`` (which re-exports
it; docs/pbm.md, "Collision frequency c_ij").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.interpolate import RegularGridInterpolator

from pbmdem.frequency import fractions_with_fallback, upper_pairs
from pbmdem.impact import N_VELOCITY_BINS, VELOCITY_KEYS, EncounterRates, ImpactRates, binned_counts
from pbmdem.readers import InputFileError, first_index
from pbmdem.tables import GRID_PAIRS, GRID_VELOCITIES, Table

from .bilinear import Bilinear
from .errors import PBMInputError

_KEY_TYPES = {"point_id": str, "class_i": int, "class_j": int}


#: The DEM table column the PBM kernel is built on (docs/architecture.md: encounters, i.e. impacts of
#: granules that were apart, not every contact that begins).
FREQUENCY_COLUMN = "encounter_frequency_per_pair"


class TableFrequency:
    """Per-pair encounter frequency interpolated from the DEM collision table (docs/pbm.md, "Rate
    processes": symmetric rows, zero frequencies floored at ``zero_floor`` x the smallest positive one,
    bilinear in (log d_i, log d_j) of log c, ``extrapolation`` ``"clamp"`` or ``"linear"`` beyond the
    table's sizes, log c linear in rpm between table speeds; ``numbers`` is ignored).

    ``velocity_table`` (optional): the impact-velocity table joined on (point_id, class_i, class_j);
    it enables :meth:`encounters`: per speed the pooled fractions of a pair's encounters per velocity
    bin (a pair without encounters gets all pairs' pooled distribution), interpolated in sizes always
    clamped and mixed in rpm with the frequency's weights."""

    def _set_options(self, extrapolation: str, zero_floor: float, column: str) -> None:
        self.extrapolation, self.zero_floor, self.column = extrapolation, float(zero_floor), column

    def __init__(
        self,
        table: pd.DataFrame,
        extrapolation: str = "clamp",
        zero_floor: float = 1e-3,
        column: str = FREQUENCY_COLUMN,
        velocity_table: pd.DataFrame | None = None,
    ):
        self._set_options(extrapolation, zero_floor, column)
        self.walls = None  # the wall impacts (pbmdem.pbm.wall_table.WallTable), for impacts()
        missing = [c for c in ("d_i", "d_j", column) if c not in table.columns]
        if missing:
            raise PBMInputError(
                f"collision table lacks columns {missing}; required: d_i, d_j, "
                f"{column} (and rpm); present: {list(table.columns)}"
            )
        if len(table) == 0:
            raise PBMInputError("collision table is empty")
        t = table.copy().reset_index(drop=True)
        if "rpm" not in t.columns:
            t["rpm"] = np.nan
        for col in ("d_i", "d_j"):
            _check_diameters(t[col].to_numpy(float), f"collision table column {col}")
        f = _checked_frequencies(t[column].to_numpy(float), column)
        counts = None if velocity_table is None else self._velocity_counts(t, velocity_table)
        floor = self.zero_floor * f[f > 0].min()
        self.rpms = []
        self._interp = []
        self._frac_interp = []
        self.ranges = []
        groups = [(np.nan, t)] if t["rpm"].isna().all() else sorted(t.groupby("rpm"), key=lambda kv: kv[0])
        for rpm, g in groups:
            sym = pd.concat(
                [g[["d_i", "d_j", column]], g.rename(columns={"d_i": "d_j", "d_j": "d_i"})[["d_i", "d_j", column]]]
            )
            mean = sym.groupby(["d_i", "d_j"])[column].mean()
            u = np.unique(np.concatenate([mean.index.get_level_values(0), mean.index.get_level_values(1)]))
            F = mean.unstack().reindex(index=u, columns=u).to_numpy(float)
            if (at := first_index(np.isnan(F))) is not None:
                a, b = at
                raise PBMInputError(
                    f"collision table at rpm {rpm:g}: no row for the pair d_i = {u[a]:g}, "
                    f"d_j = {u[b]:g}; every pair of the table's sizes is needed"
                )
            logF = np.log(np.maximum(F, floor))
            lu = np.log(u)
            self.rpms.append(float(rpm))
            self._interp.append(self._interpolator(Bilinear, lu, logF))
            self.ranges.append((float(u[0]), float(u[-1])))
            if counts is not None:
                fr = self._fraction_grid(g, counts[g.index.to_numpy()], u, rpm)
                self._frac_interp.append(self._interpolator(RegularGridInterpolator, lu, fr))
        self.rpms = np.array(self.rpms)

    @classmethod
    def from_matrix(
        cls,
        diameters,
        matrix,
        extrapolation: str = "clamp",
        zero_floor: float = 1e-3,
        column: str = "frequency_per_pair",
    ) -> TableFrequency:
        """The source of one speed's table of K classes given as their ascending ``diameters``
        (K,) and the symmetric (K, K) per-pair frequency ``matrix``: what the constructor makes
        of the upper-triangle table (d_i, d_j, ``column``), without DataFrames (a coupling
        interval's classes). Diameters that are not strictly ascending go through the table."""
        d = np.asarray(diameters, float)
        m = np.asarray(matrix, float)
        step = np.diff(d) if d.ndim == 1 else None
        if d.ndim != 1 or d.size < 2 or m.shape != (d.size, d.size) or not np.all(step >= 0):
            iu, ju = np.triu_indices(d.size) if d.ndim == 1 else (np.zeros(0, int),) * 2
            m2 = np.atleast_2d(m)
            table = pd.DataFrame({"d_i": d[iu], "d_j": d[ju], column: m2[iu, ju]})
            return cls(table, extrapolation=extrapolation, zero_floor=zero_floor, column=column)
        self = cls.__new__(cls)
        self._set_options(extrapolation, zero_floor, column)
        self.walls = None
        _check_diameters(d, "collision table column d_i")
        iu, ju = upper_pairs(d.size)
        f = _checked_frequencies(m[iu, ju], column)
        floor = self.zero_floor * f[f > 0].min()
        if np.all(step > 0):
            # the table's symmetric mean: each off-diagonal pair once per order, the diagonal twice
            F = np.empty((d.size, d.size))
            F[iu, ju] = f
            F[ju, iu] = f
        else:  # classes of equal diameter (a feed class on a pivot): the table's mean of their pairs
            d, F = _merged_pairs(d, iu, ju, f)
        lu = np.log(d)
        self.rpms = np.array([np.nan])
        self._interp = [self._interpolator(Bilinear, lu, np.log(np.maximum(F, floor)))]
        self._frac_interp = []
        self.ranges = [(float(d[0]), float(d[-1]))]
        return self

    @staticmethod
    def _interpolator(kind, lu: np.ndarray, values: np.ndarray):
        """Linear in (log d_i, log d_j), extrapolated linearly: ``Bilinear`` (the log frequencies)
        or scipy's RegularGridInterpolator (the velocity fractions, (n, n, V))."""
        if lu.size == 1:
            return (lambda value: lambda pts: np.repeat(value[None], pts.shape[0], axis=0))(values[0, 0])
        if kind is Bilinear:
            return Bilinear(lu, values)
        return kind((lu, lu), values, method="linear", bounds_error=False, fill_value=None)

    @staticmethod
    def _velocity_counts(t: pd.DataFrame, velocity_table: pd.DataFrame) -> np.ndarray:
        """(rows of t, V) encounter counts per velocity bin of every collision-table row (the
        velocity table read by `pbmdem.impact.binned_counts`, joined on its VELOCITY_KEYS)."""
        keys = list(VELOCITY_KEYS)
        missing = [c for c in keys if c not in t.columns]
        if missing:
            raise PBMInputError(
                f"collision table lacks columns {missing}, needed to join the impact-velocity "
                f"table on {keys}; present: {list(t.columns)}"
            )
        if "point_id" in velocity_table.columns:
            # rows of other DEM points (e.g. the grid's velocity table beside one point's collision table)
            points = set(t["point_id"].astype(str))
            velocity_table = velocity_table[velocity_table["point_id"].astype(str).isin(points)]
            if velocity_table.empty:
                raise PBMInputError(
                    f"impact-velocity table has no rows for the collision table's points "
                    f"{sorted(points)[:5]}; both tables must come from the same DEM runs"
                )
        try:
            pairs, counts = binned_counts(velocity_table)
        except InputFileError as exc:
            raise PBMInputError(str(exc)) from None
        row = pd.Series(np.arange(len(t)), index=pd.MultiIndex.from_frame(t[keys].astype(_KEY_TYPES)))
        if (k := first_index(row.index.duplicated())) is not None:
            raise PBMInputError(f"collision table has several rows for (point_id, class_i, class_j) = {row.index[k]}")
        idx = row.reindex(pd.MultiIndex.from_frame(pairs)).to_numpy(float)
        if (k := first_index(np.isnan(idx))) is not None:
            raise PBMInputError(
                f"impact-velocity table: (point_id, class_i, class_j) = {tuple(pairs.iloc[k])} "
                "has no row in the collision table; both tables must come from the same DEM runs"
            )
        out = np.zeros((len(t), N_VELOCITY_BINS))
        out[idx.astype(int)] = counts
        return out

    def _fraction_grid(self, g: pd.DataFrame, counts: np.ndarray, u: np.ndarray, rpm) -> np.ndarray:
        """(n, n, V) velocity fractions on the table sizes u of one speed's rows g."""
        has = g[self.column].to_numpy(float) > 0
        if (k := first_index(has & (counts.sum(axis=1) <= 0))) is not None:
            r = g.iloc[k]
            raise PBMInputError(
                f"collision table at rpm {rpm:g}: pair d_i = {r['d_i']:g}, d_j = {r['d_j']:g} has "
                f"{self.column} = {r[self.column]:g} but no encounters in the impact-velocity "
                "table; both tables must come from the same DEM runs"
            )
        pooled = counts.sum(axis=0)
        if not pooled.sum() > 0:
            raise PBMInputError(f"impact-velocity table: no encounters at rpm {rpm:g}")
        pos = {float(d): k for k, d in enumerate(u)}
        grid = np.zeros((u.size, u.size, counts.shape[1]))
        a = np.array([pos[float(d)] for d in g["d_i"]])
        b = np.array([pos[float(d)] for d in g["d_j"]])
        np.add.at(grid, (a, b), counts)
        np.add.at(grid, (b[a != b], a[a != b]), counts[a != b])
        return fractions_with_fallback(grid, pooled)

    def __repr__(self) -> str:
        speeds = "any" if np.isnan(self.rpms).all() else ",".join(f"{r:g}" for r in self.rpms)
        vel = ", velocities" if self._frac_interp else ""
        return f"TableFrequency(rpm=[{speeds}], extrapolation={self.extrapolation!r}{vel})"

    @classmethod
    def from_csv(
        cls, path, distribution: str | None = None, velocity_path=None, walls=None, **kwargs
    ) -> TableFrequency:
        """Read a collision table CSV; ``distribution`` keeps only that distribution's rows;
        ``velocity_path``: the impact-velocity table CSV (results/dem/impact_velocity.csv) that
        enables :meth:`encounters`; ``walls``: the wall impacts
        (:meth:`pbmdem.pbm.wall_table.WallTable.from_csv`) that enable :meth:`impacts`."""
        table = read_grid_table(path, GRID_PAIRS, distribution)
        velocity_table = None
        if velocity_path is not None:
            velocity_table = read_grid_table(velocity_path, GRID_VELOCITIES, distribution)
        try:
            source = cls(table, velocity_table=velocity_table, **kwargs)
        except PBMInputError as err:
            names = str(path) + ("" if velocity_path is None else f" / {velocity_path}")
            raise PBMInputError(f"{names}: {err}") from None
        source.walls = walls
        return source

    def _log(self, k: int, d: np.ndarray, clamp: bool) -> np.ndarray:
        ld = np.log(d)
        if clamp:
            lo, hi = self.ranges[k]
            ld = np.clip(ld, np.log(lo), np.log(hi))
        return ld

    def _log_pairs(self, k: int, d: np.ndarray, clamp: bool) -> np.ndarray:
        A, B = np.meshgrid(*(2 * [self._log(k, d, clamp)]), indexing="ij")
        return np.column_stack([A.ravel(), B.ravel()])

    def _log_matrix(self, k: int, d: np.ndarray) -> np.ndarray:
        interp, clamp = self._interp[k], self.extrapolation == "clamp"
        if isinstance(interp, Bilinear):  # on the pairs of the bins' log diameters (the same numbers)
            L = interp.outer(self._log(k, d, clamp))
        else:
            L = interp(self._log_pairs(k, d, clamp)).reshape(d.size, d.size)
        return 0.5 * (L + L.T)

    def _fractions(self, k: int, d: np.ndarray) -> np.ndarray:
        F = self._frac_interp[k](self._log_pairs(k, d, True)).reshape(d.size, d.size, -1)
        F = np.maximum(0.5 * (F + F.transpose(1, 0, 2)), 0.0)
        return F / F.sum(axis=2, keepdims=True)

    def __call__(self, diameters, numbers, rpm) -> np.ndarray:
        d = _check_diameters(np.atleast_1d(np.asarray(diameters, float)), "TableFrequency: diameters")
        return np.exp(sum(w * self._log_matrix(k, d) for k, w in speed_weights(self.rpms, rpm)))

    def encounters(self, diameters, numbers, rpm):
        """:class:`pbmdem.impact.EncounterRates` at the bins' diameters: the frequency of
        ``__call__`` and the interpolated velocity fractions (needs ``velocity_table``)."""
        if not self._frac_interp:
            raise PBMInputError(
                "TableFrequency.encounters needs the impact-velocity table "
                "(results/dem/impact_velocity.csv: velocity_table= / from_csv(velocity_path=...), "
                "pbmdem pbm --velocity-table)"
            )
        d = _check_diameters(np.atleast_1d(np.asarray(diameters, float)), "TableFrequency: diameters")
        fractions = sum(w * self._fractions(k, d) for k, w in speed_weights(self.rpms, rpm))
        return EncounterRates(self(d, numbers, rpm), fractions)

    def impacts(self, diameters, numbers, rpm):
        """:class:`pbmdem.impact.ImpactRates`: :meth:`encounters` and the wall impacts of the
        DEM's wall tables (``walls``: a :class:`pbmdem.pbm.wall_table.WallTable`, from_csv's
        ``wall_path`` and ``wall_velocity_path``), what breakage from impacts needs."""
        if self.walls is None:
            raise PBMInputError(
                "TableFrequency.impacts needs the wall tables (results/dem/wall_collisions.csv and "
                "wall_impact_velocity.csv: from_csv(walls=WallTable.from_csv(...)))"
            )
        return ImpactRates(self.encounters(diameters, numbers, rpm), self.walls.rates(diameters, rpm))


def read_grid_table(path, contract: Table, distribution: str | None = None) -> pd.DataFrame:
    """The DEM grid table at ``path`` read through its ``contract`` (pbmdem.tables; a source checks
    the columns it uses); ``distribution`` keeps only that distribution's rows."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{contract.what} {path} does not exist")
    try:
        table = contract.read(path, need=())
    except InputFileError as exc:
        raise PBMInputError(str(exc)) from None
    if distribution is not None:
        if "distribution" not in table.columns:
            raise PBMInputError(f"{path}: no 'distribution' column to select {distribution!r}")
        names = sorted(table["distribution"].astype(str).unique())
        table = table[table["distribution"].astype(str) == distribution]
        if table.empty:
            raise PBMInputError(f"{path}: no rows for distribution {distribution!r}; present: {names}")
    return table


def speed_weights(rpms: np.ndarray, rpm) -> list[tuple[int, float]]:
    """[(table speed index, weight)] of the interpolation in rpm between the ascending table speeds
    ``rpms``: linear between neighbours, the nearest speed outside them (one speed, or NaN: any)."""
    if rpms.size == 1 or np.isnan(rpms).all():
        return [(0, 1.0)]
    rpm = float(rpm)
    if rpm <= rpms[0]:
        return [(0, 1.0)]
    if rpm >= rpms[-1]:
        return [(rpms.size - 1, 1.0)]
    k = int(np.searchsorted(rpms, rpm, side="right") - 1)
    if rpm == rpms[k]:
        return [(k, 1.0)]
    w = (rpm - rpms[k]) / (rpms[k + 1] - rpms[k])
    return [(k, 1.0 - w), (k + 1, w)]


def _merged_pairs(d: np.ndarray, iu: np.ndarray, ju: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unique diameters u, (u, u) mean frequency of every pair of them) of the upper-triangle
    table (d[iu], d[ju], f) with repeated diameters, as the constructor's pandas mean of the
    symmetric table computes it (each row in both orders, rows in table order, compensated sums):
    the same numbers without the DataFrames (tests/test_pbm_kernels.py compares them to the bit)."""
    u, inv = np.unique(d, return_inverse=True)
    n = u.size
    total, comp, count = [[0.0] * n for _ in range(n)], [[0.0] * n for _ in range(n)], [[0] * n for _ in range(n)]
    a, b, values = inv[iu].tolist(), inv[ju].tolist(), f.tolist()
    for i, j in ((a, b), (b, a)):
        for p, q, v in zip(i, j, values, strict=True):
            y = v - comp[p][q]
            t = total[p][q] + y
            c = t - total[p][q] - y
            comp[p][q] = 0.0 if c != c else c
            total[p][q] = t
            count[p][q] += 1
    return u, np.array([[total[p][q] / count[p][q] for q in range(n)] for p in range(n)])


def _check_diameters(d: np.ndarray, what: str) -> np.ndarray:
    """``d`` if its class diameters are finite and positive, else an error naming ``what`` (a table's
    column or the diameters a caller asks for)."""
    bad = ~(np.isfinite(d) & (d > 0))
    if bad.any():
        raise PBMInputError(f"{what} has values {d[bad][:5]}; allowed: finite diameters > 0 (m)")
    return d


def _checked_frequencies(f: np.ndarray, column: str) -> np.ndarray:
    """``f`` if its per-pair frequencies are finite and >= 0 and one is positive (log interpolation)."""
    bad = ~(np.isfinite(f) & (f >= 0))
    if bad.any():
        raise PBMInputError(
            f"collision table {column} has values {f[bad][:5]}; allowed: finite values >= 0 (1/s per pair)"
        )
    if not (f > 0).any():
        raise PBMInputError(f"collision table has no positive {column}; cannot interpolate in log space")
    return f
