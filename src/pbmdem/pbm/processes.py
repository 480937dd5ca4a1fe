"""Liquid addition and consolidation, the rate processes besides aggregation: their settings; the
rates are computed in the compiled backend (``_compiled.add_processes``). docs/pbm.md ("Rate
processes") gives their balances."""

from __future__ import annotations

import numpy as np


class LiquidAddition:
    def __init__(self, rate: float, t_start: float, t_end: float, rule: str = "surface_area"):
        self.rate, self.t_start, self.t_end, self.rule = float(rate), float(t_start), float(t_end), rule

    def __repr__(self) -> str:
        return (
            f"LiquidAddition(rate={self.rate:g} m3/s, window=[{self.t_start:g}, {self.t_end:g}] s, rule={self.rule!r})"
        )

    def active(self, t: float) -> bool:
        """Spraying during the step that starts at t (steps never straddle the window edges)."""
        return self.t_start <= t < self.t_end

    def edges(self) -> tuple[float, float]:
        return self.t_start, self.t_end

    def added(self, t0: float, t1: float) -> float:
        """Liquid volume sprayed between t0 and t1 (m3)."""
        return self.rate * max(0.0, min(t1, self.t_end) - max(t0, self.t_start))


class Consolidation:
    def __init__(self, rate: float, min_porosity: float):
        self.rate, self.min_porosity = float(rate), float(min_porosity)
        self.gas_per_solid = self.min_porosity / (1.0 - self.min_porosity)

    def __repr__(self) -> str:
        return f"Consolidation(rate={self.rate:g} 1/s, min_porosity={self.min_porosity:g})"

    def gas(self, t: float, S: np.ndarray, G0: np.ndarray) -> np.ndarray:
        """Closed form without aggregation: G(t) = G_min + (G0 - G_min) exp(-c t)."""
        g_min = self.gas_per_solid * np.asarray(S, float)
        return g_min + (np.asarray(G0, float) - g_min) * np.exp(-self.rate * t)
