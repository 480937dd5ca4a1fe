"""The liquid axis of the two-dimensional PBM: classes of liquid-to-solid volume ratio.

Class e holds the granules whose ratio w = l / s lies in [b_(e-1), b_e) (b_(-1) = 0, the last class
open above): J classes from J - 1 ascending inner bounds; ``LiquidGrid.uniform(step, top)`` gives
step, 2 step, ..., top (``pbm.grid.liquid_step`` / ``liquid_max``). Why the ratio: docs/pbm.md,
"Two-dimensional PBM".
"""

from __future__ import annotations

import numpy as np

from .errors import PBMInputError, positive


class LiquidGrid:
    """J classes of liquid-to-solid volume ratio from the J - 1 ascending inner ``bounds`` (> 0);
    ``step`` > 0 if the bounds are step, 2 step, ... (a faster classification), else 0."""

    def __init__(self, bounds, step: float = 0.0):
        b = np.asarray(bounds, dtype=float).reshape(-1)
        if b.size < 1 or not np.all(np.isfinite(b)) or b[0] <= 0 or np.any(np.diff(b) <= 0):
            raise PBMInputError(
                f"liquid-ratio class bounds = {b.tolist()}; allowed: one or more finite, positive, ascending ratios"
            )
        self.bounds = np.ascontiguousarray(b)
        self.step = positive("liquid-ratio class step", step, allow_zero=True)
        if self.step > 0 and not np.allclose(b, self.step * np.arange(1, b.size + 1), rtol=1e-12, atol=0):
            raise PBMInputError(f"liquid-ratio class bounds {b.tolist()} are not multiples of step {step!r}")
        self.classes = b.size + 1
        #: (J,) the centre of every class: the middle of the bounded ones, half a neighbouring width
        #: above the lower bound for the open last one; an aggregate is shared between the two classes
        #: whose centres enclose its ratio (``_compiled2d.aggregation_totals2d``)
        lo = np.concatenate([[0.0], b])
        width = np.diff(lo)
        self.centres = np.ascontiguousarray(np.append(lo[:-1] + 0.5 * width, b[-1] + 0.5 * width[-1]))

    @classmethod
    def uniform(cls, step: float, top: float) -> LiquidGrid:
        """Classes [0, step), [step, 2 step), ..., [top, inf): top / step + 1 classes (top rounded to a
        whole number of steps, at least one)."""
        n = max(1, int(round(top / step)))
        return cls(step * np.arange(1, n + 1, dtype=float), step)

    def __repr__(self) -> str:
        kind = f"step={self.step:g}" if self.step > 0 else f"geometric {self.bounds[0]:g}..{self.bounds[-1]:g}"
        return f"LiquidGrid({self.classes} classes, {kind})"

    def classify(self, ratios) -> np.ndarray:
        """The class of every liquid-to-solid ratio (>= 0): the compiled classification of the model."""
        from ._compiled2d import ratio_classes  # lazy: numba + compiled cache ~2.6 s (measured)

        w = np.ascontiguousarray(np.atleast_1d(np.asarray(ratios, dtype=float)))
        out = np.empty(w.size, dtype=np.int64)
        ratio_classes(w, self.step, self.bounds, out)
        return out
