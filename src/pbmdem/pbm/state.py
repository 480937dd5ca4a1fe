"""The resumable state of a PBM run: per-bin totals and the feed granules not yet aggregated,
and the checks of a state against its grid."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pbmdem.readers import first_index

from .errors import NegativePopulationError, PBMInputError
from .grid import Grid, diameter_of


@dataclass
class FeedGranules:
    """Feed granules that have not aggregated yet: P classes of solid ``volumes`` (P,) (m3, the
    feed classes' own sizes, in the grid's unit) with their number, liquid (m3) and gas (m3)
    totals (P,). They are part of the per-bin totals of their :class:`State`, put on the pivots
    by the lever rule (number and solid exact; liquid and gas follow the solid); the rest of each
    bin are aggregates. Aggregation removes feed granules but never adds any."""

    volumes: np.ndarray
    number: np.ndarray
    liquid: np.ndarray
    gas: np.ndarray

    def copy(self) -> FeedGranules:
        return FeedGranules(*(np.array(v, float) for v in (self.volumes, self.number, self.liquid, self.gas)))


@dataclass
class State:
    """Resumable PBM state at time ``t``: per-bin number, liquid and gas (pore) volume (m3).

    ``refused_volume``: solid volume of aggregates refused beyond the last bin so far (m3);
    ``liquid_added``: binder sprayed so far (m3); ``steps``: time steps taken so far;
    ``feed``: the feed granules not yet aggregated (:class:`FeedGranules`, included in number,
    liquid and gas) or None (every particle of a bin shares the bin's liquid and gas);
    ``merged_number``, ``merged_volume``: breakage fragments smaller than the first pivot so far
    and their solid volume (m3), merged into the first pivot as merged_volume / x_0 granules (the
    grid floor: solid exact, merged_number - merged_volume / x_0 granules lost).
    """

    t: float
    number: np.ndarray
    liquid: np.ndarray
    gas: np.ndarray
    refused_volume: float = 0.0
    liquid_added: float = 0.0
    steps: int = 0
    feed: FeedGranules | None = None
    merged_number: float = 0.0
    merged_volume: float = 0.0

    def copy(self) -> State:
        """A copy of the same class whose arrays (and feed granules) are copies."""
        # the fields' values, as dataclasses.replace would set them (without its per-call field scan)
        out = object.__new__(type(self))
        out.__dict__.update({k: v.copy() if hasattr(v, "copy") else v for k, v in self.__dict__.items()})
        return out


def surface_fraction(S: np.ndarray, L: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Surface-liquid volume fraction of the granules of each bin.

    Liquid fills the pores first; the excess is surface liquid: l_surf = max(l - g, 0). The granule
    volume is s + max(l, g) (pores, wet or dry, plus the surface layer). Ratios of bin totals
    equal ratios of per-particle values, so no division by N is needed.
    """
    S, L, G = np.broadcast_arrays(*(np.asarray(a, float) for a in (S, L, G)))
    V = S + np.maximum(L, G)
    return np.divide(np.maximum(L - G, 0.0), V, out=np.zeros(V.shape), where=V > 0)


def check_state(grid: Grid, s: State, where: str = "") -> None:
    """NegativePopulationError naming the first entry of `s` that is negative or not finite."""
    parts = [s.number, s.liquid, s.gas]
    if s.feed is not None:
        parts += [s.feed.number, s.feed.liquid, s.feed.gas]
    if _all_finite_nonnegative(parts):
        return  # the usual case: no entry to name
    arrays = [("number", s.number, None), ("liquid", s.liquid, None), ("gas", s.gas, None)]
    if s.feed is not None:
        d = diameter_of(s.feed.volumes)
        arrays += [("feed number", s.feed.number, d), ("feed liquid", s.feed.liquid, d), ("feed gas", s.feed.gas, d)]
    for name, arr, d in arrays:
        if (k := first_index(~np.isfinite(arr) | (arr < 0))) is not None:
            where_k = (
                f"bin {k} (diameter {grid.d[k]:.4g} m)" if d is None else f"the feed class of diameter {d[k]:.4g} m"
            )
            raise NegativePopulationError(
                f"{name} of {where_k} is {float(arr[k])!r} at t = {s.t:.6g} s{where}; allowed: finite values >= 0"
            )


def _all_finite_nonnegative(parts: list) -> bool:
    """True if every entry of the 1-D arrays ``parts`` is finite and >= 0 (False: look closer; also
    for a sum that overflows)."""
    try:
        values = np.concatenate([np.asarray(p, float) for p in parts])
    except (ValueError, TypeError):  # not 1-D numbers: the entry-by-entry check names it
        return False
    return bool(values.size == 0 or (values.min() >= 0.0 and np.isfinite(values.sum())))


def feed_volumes(grid: Grid, s: State) -> np.ndarray:
    """Volumes of the state's feed classes (checked: distinct, on the grid, shapes; their share
    of every bin at most the bin's total); empty without feed classes."""
    f = s.feed
    if f is None:
        return np.zeros(0)
    g = grid
    v = np.asarray(f.volumes, float)
    P = v.size
    if (
        v.ndim != 1
        or (P > 1 and bool((np.diff(np.sort(v)) == 0).any()))
        # NaN fails both comparisons, infinities one
        or (P and not (g.x[0] * (1 - 1e-12) <= v.min() and v.max() <= g.x[-1] * (1 + 1e-12)))
    ):
        raise PBMInputError(
            f"state.feed.volumes = {v.tolist()}; allowed: distinct solid volumes within the "
            f"grid, {g.x[0]:.4g} .. {g.x[-1]:.4g} (x_0 .. x_(K-1))"
        )
    for name in ("number", "liquid", "gas"):
        if np.shape(getattr(f, name)) != (P,):
            raise PBMInputError(f"state.feed.{name} has shape {np.shape(getattr(f, name))}; expected ({P},)")
    wn, ws = g.lever_weights(v)
    part = np.concatenate([np.asarray(f.number, float) @ wn, (np.stack([f.liquid, f.gas]).astype(float) @ ws).ravel()])
    total = np.concatenate([s.number, s.liquid, s.gas])
    if np.all(part <= total * (1.0 + 1e-9) + 1e-300):
        return v  # the usual case: no bin to name
    for name, w in (("number", wn), ("liquid", ws), ("gas", ws)):
        part, total = np.asarray(getattr(f, name), float) @ w, getattr(s, name)
        if (k := first_index(part > total * (1.0 + 1e-9) + 1e-300)) is not None:
            raise PBMInputError(
                f"state.feed.{name} puts {part[k]!r} into bin {k}, more than the bin's total "
                f"{total[k]!r}; the feed granules are part of the bin totals"
            )
    return v


@dataclass
class State2D(State):
    """State of the two-dimensional PBM (``model2d``): besides the per-bin totals of :class:`State`
    (the size marginal, feed classes put on the pivots by the lever rule, what results and the
    coupled loop read), ``classes`` (3, Mx, J): number, liquid (m3) and gas (m3) of every size class
    (the K pivots, then the feed classes of solid volume ``class_volumes[K:]``) and liquid class;
    ``class_volumes`` (Mx,): the size classes' solid volumes (m3)."""

    classes: np.ndarray | None = None
    class_volumes: np.ndarray | None = None
