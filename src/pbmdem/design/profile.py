"""Profile-likelihood intervals of a least-squares fit in ln theta, the measurement part of a
calibration's uncertainty (docs/calibration.md, "Intervals, correlation and identifiability").
`residuals` is a `calibration.Residuals`."""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np
from scipy.optimize import least_squares

#: forward-difference step in ln theta (2 %): well above the PBM's own step-control noise (rtol 1e-3)
LN_STEP = 0.02


def forward_jacobian(evaluate, x) -> np.ndarray:
    """Forward-difference Jacobian (step LN_STEP in each coordinate) of the residual vectors that
    `evaluate` gives for a list of points, all points of one Jacobian evaluated in one call."""
    x = np.asarray(x, float)
    steps = [x + LN_STEP * np.eye(x.size)[i] for i in range(x.size)]
    base, *shifted = evaluate([x, *steps])
    return np.column_stack([(s - base) / LN_STEP for s in shifted])


class _Profiled:
    """`residuals` with parameter `index` held at `value`: the residuals and forward-difference
    Jacobian of the other parameters (the inner fit of a profile likelihood)."""

    def __init__(self, residuals, x: np.ndarray, index: int, value: float):
        self.residuals, self.free = residuals, np.arange(x.size) != index
        self.full = np.array(x, float)
        self.full[index] = value

    def _point(self, y) -> np.ndarray:
        x = self.full.copy()
        x[self.free] = y
        return x

    def __call__(self, y) -> np.ndarray:
        return self.residuals(self._point(y))

    def jacobian(self, y) -> np.ndarray:
        return forward_jacobian(lambda points: self.residuals._evaluate([self._point(v) for v in points]), y)


def profile_chi2(residuals, x: np.ndarray, index: int, value: float, lower, upper) -> tuple[float, np.ndarray]:
    """(sum of squares, ln theta) with parameter `index` held at `value` and the others fitted
    again, started from `x`."""
    if x.size == 1:
        point = np.array([value])
        return float(np.sum(residuals(point) ** 2)), point
    inner = _Profiled(residuals, x, index, value)
    free = inner.free
    start = np.clip(x[free], lower[free] + 1e-9, upper[free] - 1e-9)
    result = least_squares(
        inner,
        start,
        jac=inner.jacobian,
        bounds=(lower[free], upper[free]),
        method="trf",
        xtol=1e-3,
        ftol=1e-4,
        max_nfev=20,
    )
    return float(2 * result.cost), inner._point(result.x)


#: first ln offset of a profile scan (0.5 %), doubled at every step out to the search box's bound
PROFILE_FIRST_STEP = 0.005
#: a scan stops early once the profile rises this many times z^2 above its minimum: no valley
#: of the sum of squares beyond such a wall was seen (the step success model's jumps were <= 12 z^2)
PROFILE_GIVE_UP = 30.0


def profile_side(residuals, x: np.ndarray, index: int, sign: int, lower, upper, rise: float):
    """The ln offset (>= 0) from the estimate `x` towards `sign` (+1, -1) of the far end of the set
    where the profile sum of squares of parameter `index` stays less than `rise` above its value at
    `x`, or None when that set reaches the search box's bound (the scan: docs/calibration.md)."""
    chi2_min = float(np.sum(residuals(x) ** 2))
    limit = (upper[index] - x[index]) if sign > 0 else (x[index] - lower[index])
    if limit <= 0:
        return None
    inside, outside, t, start = 0.0, None, min(PROFILE_FIRST_STEP, limit), x
    while True:
        value, start = profile_chi2(residuals, start, index, x[index] + sign * t, lower, upper)
        if value - chi2_min < rise:
            inside, outside = t, None
        elif outside is None:
            outside = t
        if t >= limit or value - chi2_min > PROFILE_GIVE_UP * rise:
            break
        t = min(2 * t, limit)
    if outside is None:
        return None
    for _ in range(4):
        middle = 0.5 * (inside + outside)
        value, _ = profile_chi2(residuals, x, index, x[index] + sign * middle, lower, upper)
        inside, outside = (inside, middle) if value - chi2_min >= rise else (middle, outside)
    return outside


def profile_widths(residuals, x: np.ndarray, lower, upper, z: float, n_jobs: int = 1) -> np.ndarray:
    """(p, 2) ln widths below and above the estimate of each parameter's profile-likelihood interval
    (rise z^2; np.inf: open), the 2p sides scanned at once on up to `n_jobs` forked processes."""
    sides = [(i, sign) for i in range(x.size) for sign in (-1, +1)]
    global _PROFILE
    _PROFILE = (residuals, x, lower, upper, z * z)
    try:
        if n_jobs > 1 and len(sides) > 1:
            context = multiprocessing.get_context("fork")
            with ProcessPoolExecutor(max_workers=min(n_jobs, len(sides)), mp_context=context) as pool:
                ends = list(pool.map(_profile_side_in_process, sides))
        else:
            ends = [profile_side(residuals, x, i, sign, lower, upper, z * z) for i, sign in sides]
    finally:
        _PROFILE = None
    return np.array([np.inf if t is None else t for t in ends], float).reshape(x.size, 2)


#: what the processes of profile_widths scan (set by the parent before it forks them)
_PROFILE = None


def _profile_side_in_process(side: tuple[int, int]):
    residuals, x, lower, upper, rise = _PROFILE
    model = getattr(residuals, "model", None)
    if model is not None:  # one process per side already: no pool inside it
        residuals.model = replace(model, n_jobs=1)
    return profile_side(residuals, x, side[0], side[1], lower, upper, rise)
