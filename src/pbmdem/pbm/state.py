"""The resumable state of a PBM run: per-bin totals and the feed granules not yet aggregated."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
        return FeedGranules(
            np.array(self.volumes, float),
            np.array(self.number, float),
            np.array(self.liquid, float),
            np.array(self.gas, float),
        )


@dataclass
class State:
    """Resumable PBM state at time ``t``: per-bin number, liquid and gas (pore) volume (m3).

    ``refused_volume``: solid volume of aggregates refused beyond the last bin so far (m3);
    ``liquid_added``: binder sprayed so far (m3); ``steps``: time steps taken so far;
    ``feed``: the feed granules not yet aggregated (:class:`FeedGranules`, included in number,
    liquid and gas) or None (every particle of a bin shares the bin's liquid and gas).
    """

    t: float
    number: np.ndarray
    liquid: np.ndarray
    gas: np.ndarray
    refused_volume: float = 0.0
    liquid_added: float = 0.0
    steps: int = 0
    feed: FeedGranules | None = None

    def copy(self) -> State:
        return State(
            self.t,
            self.number.copy(),
            self.liquid.copy(),
            self.gas.copy(),
            self.refused_volume,
            self.liquid_added,
            self.steps,
            None if self.feed is None else self.feed.copy(),
        )


def surface_fraction(S: np.ndarray, L: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Surface-liquid volume fraction of the granules of each bin.

    Liquid fills the pores first; the excess is surface liquid: l_surf = max(l - g, 0). The granule
    volume is s + max(l, g) (pores, wet or dry, plus the surface layer). Ratios of bin totals
    equal ratios of per-particle values, so no division by N is needed.
    """
    S, L, G = np.broadcast_arrays(*(np.asarray(a, float) for a in (S, L, G)))
    V = S + np.maximum(L, G)
    return np.divide(np.maximum(L - G, 0.0), V, out=np.zeros(V.shape), where=V > 0)
