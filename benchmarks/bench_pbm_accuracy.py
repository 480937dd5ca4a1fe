"""Accuracy of the aggregation schemes against closed-form solutions (prints figures, no
assertions).

Pure aggregation, N0 = 1 and unit mean (exponential start) or monomer (monodisperse start)
volume, kernels beta = 1 (constant), u + v (sum) and u v (product, before gelation), two growths:

* constant and sum kernels: the mean volume M1/M0 grows 10x and 50x;
* product kernel: the mean volume can grow at most 4/3x (exponential) or 2x (monodisperse) before
  gelation, so the growth is that of the mass-mean volume M2/M1 (10x and 50x; 50x is 2 % of
  t_gel before gelation).

Grids: ratio 2^(1/q), q = 1, 2, 3, 4, 8, from 1e-3 (exponential) or 1 (monomer) to 400 final
mass-mean volumes. Printed: relative errors of M0, M1, M2 at the end, the L1 error of the cell
numbers (relative to the total number) and the largest error of the cumulative mass fraction
(PSD), and the observed orders of |M2 error| and L1 per halving of ln r. The product kernel from
the exponential has no closed-form density here: moments only.

Grid convergence of the default batch (``--grid``, also printed after the analytical cases):
``run_batch`` of config/config.yaml (feed ``fine``, constant c_ij, 600 rpm, 480 s) with the grid
ratio 2^(1/q), q = 1, 2, 3, 4, 6, 8, 12, 16, 24 (the default is q = 3; the criterion compares it
with the 4x finer q = 12), for the defaults and for the variants that locate the cause of the
non-convergence of the lumped model: feed granules sharing their bins' liquid (``separate_feed:
false``, the model before), spraying by solid volume, the logistic success probability. Printed:
d10 / d50 / d90 at 480 s, their deviation from the 4x finer grid and from q = 24, and the liquid
content and surface-liquid fraction of the 4 mm feed granules at the end.

Breakage (``--breakage``, also printed after the aggregation cases): the cell average's breakage
on grids of ratio 2^(1/q) from 1e-6 to 60 initial mean volumes, exponential start, against
Ziff & McGrady (1985): uniform daughters with S = v (t = 9: the number grows 10x) and S = v^2
(t = 10: 3.7x); binary equal fragments with S = v (number only: M0 = 1 + t); and constant
aggregation (beta = 1) with uniform-daughter breakage S = 2 v at t = 12 (the number against the
Riccati solution, the PSD against the steady state n = 4 e^(-2 v)). Printed as the aggregation
cases, with the observed orders of |M0 error|, |M2 error| and L1. Then uniform-daughter breakage
S = v from a monodisperse start (every granule at v = 1, a pivot of every grid; grids from 2^-20)
against its closed form (Ziff & McGrady 1985), at a l t = 0.25 to 10 breakages per starting
granule: L1 and the cumulative-mass error with their observed orders, lower while the start's jump
dominates than after it has decayed.

Run: .venv/bin/python benchmarks/bench_pbm_accuracy.py [--quick] [--fixed-pivot] [--grid] [--breakage]
(about 2-3 min; --grid alone about 1 min, --breakage alone about 1 min; --quick, the suite's smoke
test, about 20 s: q = 1, 2, 4, the grid convergence up to q = 16)
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.integrate import IntegrationWarning

from pbmdem.config import Solver
from pbmdem.pbm import ConstantKernel, GranulationPBM, Grid, GridOverflowError, State, SumKernel, surface_fraction
from pbmdem.pbm.breakage import Breakage, PowerLawSelection
from pbmdem.pbm.kernels import Kernel

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the verification harness
import pbm_analytical as an  # noqa: E402 (found on the tests folder added above)
import pbm_verification as ver  # noqa: E402


class ProductKernel(Kernel):
    """beta_ij = b v_i v_j (verification only; gelation at t = 1 / (b M2(0)))."""

    def __init__(self, b: float):
        self.b = float(b)
        self._cache = None

    def __repr__(self) -> str:
        return f"ProductKernel(b={self.b:g})"

    def __call__(self, inp):
        v = inp.volumes
        if self._cache is None or self._cache[0] != v.size:
            self._cache = (v.size, self.b * np.outer(v, v))
        return self._cache[1]


KERNELS = {"constant": ConstantKernel(1.0), "sum": SumKernel(1.0), "product": ProductKernel(1.0)}


def end_time(kernel: str, start: str, growth: float) -> float:
    """Time at which the mean (constant, sum) or mass-mean (product) volume has grown ``growth``x."""
    if kernel == "constant":
        return 2.0 * (growth - 1.0) if start == "exponential" else 2.0 * (growth - 1.0)
    if kernel == "sum":
        return float(np.log(growth))
    m2 = 2.0 if start == "exponential" else 1.0  # M2(0); gelation at 1 / M2(0)
    return (1.0 - 1.0 / growth) / m2


def exact_moments(kernel: str, start: str, t: float) -> np.ndarray:
    if start == "exponential":
        if kernel == "product":
            return np.array(an.product_moments(t, 1.0, 1.0, 1.0, 2.0))
        return np.array(an.moments(KERNELS[kernel], t, 1.0, 1.0))
    k = np.arange(1.0, 1.0 + _kmax(kernel, start, t))
    c = an.monodisperse_numbers(kernel, t, k)
    return np.array([c.sum(), (c * k).sum(), (c * k * k).sum()])


def _top(kernel: str, start: str, t: float) -> float:
    """400 final mass-mean volumes (the mass beyond is below ~1e-15); for the product kernel, whose
    tail near gelation is a power law cut off at about (M2/M1)^2, 1000 (M2/M1)^2."""
    if start == "exponential" and kernel == "product":
        M0, M1, M2 = an.product_moments(t, 1.0, 1.0, 1.0, 2.0)
    elif start == "exponential":
        M0, M1, M2 = an.moments(KERNELS[kernel], t, 1.0, 1.0)
    else:
        M2 = {"constant": 1.0 + t, "sum": float(np.exp(2 * t)), "product": 1.0 / (1.0 - t)}[kernel]
        M1 = 1.0
    if kernel == "product":
        return 1000.0 * (M2 / M1) ** 2
    return 400.0 * M2 / M1


def _kmax(kernel, start, t):
    return int(min(4e7, 2 * _top(kernel, start, t)))


def grid_for(q: int, start: str, top: float) -> Grid:
    x0 = 1e-3 if start == "exponential" else 1.0
    r = 2.0 ** (1.0 / q)
    return Grid(int(np.ceil(np.log(top / x0) / np.log(r))) + 1, r, v0=x0)


def initial_numbers(grid: Grid, start: str) -> np.ndarray:
    if start == "exponential":
        return ver.discretise_exponential(grid, 1.0, 1.0)
    N = np.zeros(grid.bins)
    N[0] = 1.0
    return N


def psd_errors(kernel: str, start: str, grid: Grid, number: np.ndarray, t: float):
    """(L1 of the cell numbers / total, max error of the cumulative mass fraction)."""
    if start == "exponential":
        if kernel == "product":
            return np.nan, np.nan
        return ver.cell_errors(KERNELS[kernel], grid, number, t)
    k = np.arange(1.0, 1.0 + _kmax(kernel, start, t))
    c = an.monodisperse_numbers(kernel, t, k)
    cell = np.searchsorted(grid.edges[1:-1], k, side="right")
    num = np.bincount(cell, c, grid.bins)
    vol = np.bincount(cell, c * k, grid.bins)
    l1 = np.abs(number - num).sum() / num.sum()
    Q = np.cumsum(number * grid.x) / np.sum(number * grid.x)
    return float(l1), float(np.abs(Q - np.cumsum(vol) / vol.sum()).max())


def run_case(kernel: str, start: str, growth: float, q: int, scheme: str):
    t_end = end_time(kernel, start, growth)
    grid = grid_for(q, start, _top(kernel, start, t_end))
    model = GranulationPBM(
        grid,
        KERNELS[kernel],
        scheme=scheme,
        solver=Solver().replace(rtol=1e-5, atol=1e-12, max_step=np.inf, max_overflow_fraction=1.0),
    )
    N = initial_numbers(grid, start)
    t0 = time.perf_counter()
    res = model.run(0.0, t_end, State(0.0, N, np.zeros(grid.bins), np.zeros(grid.bins)))
    wall = time.perf_counter() - t0
    err = res.moments()[-1] / exact_moments(kernel, start, t_end) - 1.0
    l1, psd = psd_errors(kernel, start, grid, res.number[-1], t_end)
    return grid, err, l1, psd, wall, res


def _orders(qs, errs):
    e = np.abs(np.asarray(errs, float))
    out = []
    for (q1, e1), (q2, e2) in zip(zip(qs[:-1], e[:-1]), zip(qs[1:], e[1:])):
        out.append(np.log(e1 / e2) / np.log(q2 / q1) if e1 > 0 and e2 > 0 and np.isfinite(e1 / e2) else np.nan)
    return ", ".join("  -  " if np.isnan(o) else f"{o:5.2f}" for o in out)


#: variants of the default batch in the grid-convergence table: (label, pbm section over the config's)
GRID_VARIANTS = (
    ("defaults (surface_area, step, separate feed)", {}),
    ("feed shares its bins (separate_feed: false)", {"grid": {"separate_feed": False}}),
    ("solid_volume spraying, separate feed", {"liquid_addition": {"distribution": "solid_volume"}}),
    ("logistic success (width 0.005), separate feed", {"aggregation": {"success": {"model": "logistic"}}}),
)
GRID_QS = (1, 2, 3, 4, 6, 8, 12, 16, 24)


def batch_with(cfg, section: dict, distribution: str = "fine"):
    """The config's batch with its pbm settings replaced by a (partial) pbm section over the
    schema's defaults (the first pivot stays the config's)."""
    from pbmdem.config import Pbm

    pbm = Pbm.from_dict(section, "pbm")
    if section.get("grid", {}).get("min_diameter") is None:
        pbm = pbm.replace(grid=pbm.grid.replace(min_diameter=cfg.pbm.grid.min_diameter))
    return cfg.pbm_batch(distribution).replace(pbm=pbm)


def _feed_4mm(res) -> tuple[float, float]:
    """(liquid / solid, surface-liquid fraction) of the 4 mm feed granules at the end: their own
    class with separate feed, else the 4 mm bin they share with aggregates (it is on a pivot)."""
    st, g = res.state, res.grid
    if st.feed is not None:
        k = int(np.argmin(np.abs(st.feed.volumes - np.pi / 6 * 4e-3**3)))
        S, L, G = st.feed.number[k] * st.feed.volumes[k], st.feed.liquid[k], st.feed.gas[k]
    else:
        k = int(np.argmin(np.abs(g.d - 4e-3)))
        S, L, G = st.number[k] * g.x[k], st.liquid[k], st.gas[k]
    return L / S, float(surface_fraction(S, L, G))


def grid_convergence(qs=GRID_QS):
    """Print the grid-convergence table of the default batch (module docstring)."""
    import copy
    from pathlib import Path

    from pbmdem.config import load_config
    from pbmdem.pbm.setup import run_batch

    cfg0 = load_config(Path(__file__).resolve().parents[1] / "config" / "config.yaml")
    q_default = 3
    print("\ngrid convergence of the default batch ('fine', constant c_ij, 600 rpm, 480 s): ratio 2^(1/q)")
    for label, pbm in GRID_VARIANTS:
        print(f"\n{label}")
        print(
            f"    q  bins   d10 / d50 / d90 (mm)        vs 4x finer (%)         vs q = {max(qs):<3d}(%)       "
            "4 mm feed: l/s, phi   steps  wall"
        )
        rows = {}
        for q in qs:
            section = copy.deepcopy(pbm)
            section.setdefault("grid", {})["ratio"] = 2.0 ** (1.0 / q)
            t0 = time.perf_counter()
            res = run_batch(batch_with(cfg0, section), None, 600)
            wall = time.perf_counter() - t0
            rows[q] = (res, res.summary()[["d10", "d50", "d90"]].iloc[-1].to_numpy() * 1e3, wall)
        ref = rows.get(max(qs))[1]
        for q in qs:
            res, d, wall = rows[q]
            fine = rows.get(4 * q)
            vs4 = "        -        " if fine is None else " ".join(f"{x:+5.2f}" for x in 100 * (d / fine[1] - 1))
            vsr = " ".join(f"{x:+5.2f}" for x in 100 * (d / ref - 1))
            ls, phi = _feed_4mm(res)
            mark = "*" if q == q_default else " "
            print(
                f"  {mark}{q:3d} {res.grid.bins:5d}   {d[0]:.3f} / {d[1]:.3f} / {d[2]:.3f}   {vs4:17s}   {vsr:17s}"
                f"    {ls:.4f}, {phi:.4f}    {res.info['steps']:4d} {wall:5.2f} s"
            )
    print("(* the default ratio 2^(1/3); criterion: d10, d50 and d90 within 1 % of the 4x finer grid)")


#: the breakage cases: (label, fragments, selection (a, p) of S = a v^p, aggregation beta or None, t_end)
BREAKAGE_CASES = (
    ("uniform daughters, S = v", "uniform", (1.0, 1), None, 9.0),
    ("uniform daughters, S = v^2", "uniform", (1.0, 2), None, 10.0),
    ("binary equal fragments, S = v", "binary", (1.0, 1), None, 9.0),
    ("aggregation beta = 1 + uniform daughters, S = 2 v", "uniform", (2.0, 1), 1.0, 12.0),
)


def _breakage_reference(fragments, sel, beta, t):
    """(exact (M0, M1, M2) with NaN where none is known, number density or None) of a case."""
    a, p = sel
    if beta is not None:  # the number (Riccati) and the steady density
        M0 = an.aggregation_breakage_number(t, beta, a, 1.0, 1.0)
        return np.array([M0, 1.0, np.nan]), lambda v: an.aggregation_breakage_steady_density(v, beta, a, 1.0)
    if fragments == "binary":  # two fragments per breakage, S = a v: M0 = 1 + a t
        return np.array([1.0 + a * t, 1.0, np.nan]), None
    return np.array(an.breakage_moments(t, a, p, 1.0, 1.0)), lambda v: an.breakage_number_density(v, t, a, p, 1.0, 1.0)


def breakage_accuracy(qs):
    """The breakage cases on the grids 2^(1/q): moments, L1 of the cell numbers, PSD, orders."""
    for label, fragments, sel, beta, t in BREAKAGE_CASES:
        print(f"\nbreakage: {label} (t = {t:g})")
        print("   ratio  bins    M0 err     M1 err     M2 err   |  L1 cells  | PSD (Q3) | steps  wall")
        exact, density = _breakage_reference(fragments, sel, beta, t)
        cols = {"M0": [], "M2": [], "L1": []}
        for q in qs:
            grid = ver.geometric_grid(q, x0=1e-6, x_max=60.0)
            t0 = time.perf_counter()
            res = ver.simulate_breakage(
                Breakage(PowerLawSelection(*sel), fragments),
                t,
                grid,
                kernel=None if beta is None else ConstantKernel(beta),
            )
            wall = time.perf_counter() - t0
            err = res.moments()[-1] / exact - 1.0
            l1, psd = ver.density_errors(density, grid, res.state.number) if density else (np.nan, np.nan)
            for key, value in zip(cols, (err[0], err[2], l1)):
                cols[key].append(value)
            fmt = [("    -    " if np.isnan(e) else f"{e:+.2e}") for e in err]
            l1s, psds = (("    -   " if np.isnan(e) else f"{e:.2e}") for e in (l1, psd))
            print(
                f"  {grid.ratio:6.4f} {grid.bins:5d}  {fmt[0]}  {fmt[1]}  {fmt[2]} |  {l1s}  | {psds} |"
                f" {res.info['steps']:5d} {wall:5.2f} s"
            )
        print("  observed order per halving of ln r: " + "; ".join(f"|{k}| {_orders(qs, v)}" for k, v in cols.items()))


#: the monodisperse breakage case: times (in units of 1 / (a l)) at which it is compared
MONODISPERSE_TIMES = (0.25, 0.5, 1.0, 2.0, 4.0, 10.0)


def monodisperse_breakage_cells(edges, t, a, l):
    """Exact number and volume per cell of pure breakage S = a v with uniform daughters (b = 2/u)
    from N0 = 1 granules of volume l (Ziff & McGrady 1985): e^(-a l t) granules still at l, and
    the fragments' density e^(-s v) (2 s + s^2 (l - v)) below l, s = a t (the number above v is
    G(v) = e^(-s v) (1 + s (l - v)) - e^(-s l), so that M0 = 1 + a l t)."""
    from scipy import integrate

    s_ = a * t

    def above(v):
        return np.exp(-s_ * v) * (1.0 + s_ * (l - v)) - np.exp(-s_ * l)

    num, vol = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        top = min(hi, l)
        if lo >= l:
            num.append(0.0)
            vol.append(0.0)
            continue
        num.append(above(lo) - above(top))
        vol.append(
            integrate.quad(lambda v: v * np.exp(-s_ * v) * (2 * s_ + s_**2 * (l - v)), lo, top, epsrel=1e-12, epsabs=0)[
                0
            ]
        )
    num, vol = np.array(num), np.array(vol)
    k = int(np.searchsorted(edges, l, side="right")) - 1  # the cell that holds l
    num[k] += np.exp(-s_ * l)
    vol[k] += np.exp(-s_ * l) * l
    return num, vol


def monodisperse_breakage(qs, a: float = 1.0, l: float = 1.0):
    """Cell-average breakage from a monodisperse start (all granules at the pivot l, grids of ratio
    2^(1/q) from 2^-20 l): L1 of the cell numbers and the cumulative-mass error at the times
    MONODISPERSE_TIMES (a l t = the number of breakages per starting granule so far), with their
    observed orders. While the start's jump dominates (a l t <= 1) the order is lower than after
    it has decayed."""
    print(f"\nbreakage from a monodisperse start: uniform daughters, S = {a:g} v, all granules at v = {l:g}")
    rows = {}
    for q in qs:
        grid = ver.geometric_grid(q, x0=2.0**-20 * l, x_max=2.0 * l)
        k = int(np.argmin(np.abs(grid.x - l)))
        assert abs(grid.x[k] / l - 1.0) < 1e-12, "the start must sit on a pivot"
        N = np.zeros(grid.bins)
        N[k] = 1.0
        solver = Solver().replace(rtol=1e-8, atol=1e-14, max_step=np.inf)
        model = GranulationPBM(
            grid, ver.NoAggregation(), solver=solver, breakage=Breakage(PowerLawSelection(a, 1.0), "uniform")
        )
        S = N * grid.x
        res = model.run(0.0, max(MONODISPERSE_TIMES), State(0.0, N, 0.3 * S, 0.1 * S), output_times=MONODISPERSE_TIMES)
        edges = np.concatenate([[0.0], grid.edges[1:-1], [np.inf]])
        times = np.asarray(res.times, float)
        for t in MONODISPERSE_TIMES:
            number = np.asarray(res.number[int(np.argmin(np.abs(times - t)))], float)
            num, vol = monodisperse_breakage_cells(edges, t, a, l)
            l1 = np.abs(number - num).sum() / num.sum()
            Q = np.cumsum(number * grid.x) / np.sum(number * grid.x)
            rows.setdefault(t, []).append((l1, float(np.abs(Q - np.cumsum(vol) / vol.sum()).max())))
    print("   a l t | L1 cells (ratio " + " / ".join(f"{2 ** (1 / q):.4f}" for q in qs) + ") | observed order"
          " | PSD (Q3) | observed order")  # fmt: skip
    for t, errs in rows.items():
        l1s, qs3 = [e[0] for e in errs], [e[1] for e in errs]
        print(
            f"  {a * l * t:6.2f} | "
            + " / ".join(f"{e:.2e}" for e in l1s)
            + f" | {_orders(qs, l1s)} | "
            + " / ".join(f"{e:.2e}" for e in qs3)
            + f" | {_orders(qs, qs3)}"
        )


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="q = 1, 2, 4 only")
    ap.add_argument("--fixed-pivot", action="store_true", help="also the fixed pivot scheme")
    ap.add_argument("--grid", action="store_true", help="only the grid convergence of the default batch")
    ap.add_argument("--breakage", action="store_true", help="only the breakage cases")
    args = ap.parse_args()
    warnings.simplefilter("ignore", IntegrationWarning)
    qs = (1, 2, 4) if args.quick else (1, 2, 3, 4, 8)
    if args.grid:
        grid_convergence()
        return
    if args.breakage:
        breakage_accuracy(qs)
        monodisperse_breakage((*qs, 8) if args.quick else qs)
        return
    schemes = ("cell_average", "fixed_pivot") if args.fixed_pivot else ("cell_average",)
    t_all = time.perf_counter()
    for scheme in schemes:
        for kernel in ("constant", "sum", "product"):
            for start in ("exponential", "monodisperse"):
                for growth in (10.0, 50.0):
                    what = "mass-mean volume" if kernel == "product" else "mean volume"
                    print(
                        f"\n{scheme}, {kernel} kernel, {start} start, {what} x{growth:g} "
                        f"(t = {end_time(kernel, start, growth):.4g})"
                    )
                    print("   ratio  bins    M0 err     M1 err     M2 err   |  L1 cells  | PSD (Q3) | steps  wall")
                    m2s, l1s = [], []
                    for q in qs:
                        try:
                            grid, err, l1, psd, wall, res = run_case(kernel, start, growth, q, scheme)
                        except GridOverflowError as exc:
                            print(f"  {2 ** (1 / q):6.4f}  stopped: {str(exc)[:90]}...")
                            m2s.append(np.nan)
                            l1s.append(np.nan)
                            continue
                        m2s.append(err[2])
                        l1s.append(l1)
                        lost = res.state.refused_volume
                        note = f"  ({lost:.1e} of the solid beyond the grid)" if lost > 1e-9 else ""
                        l1s_ = "    -   " if np.isnan(l1) else f"{l1:.2e}"
                        psd_ = "    -   " if np.isnan(psd) else f"{psd:.2e}"
                        print(
                            f"  {grid.ratio:6.4f} {grid.bins:5d}  {err[0]:+.2e}  {err[1]:+.2e}  {err[2]:+.2e} |"
                            f"  {l1s_}  | {psd_} | {res.info['steps']:5d} {wall:5.2f} s{note}"
                        )
                    print(f"  observed order per halving of ln r: |M2 err| {_orders(qs, m2s)}; L1 {_orders(qs, l1s)}")
    breakage_accuracy(qs)
    monodisperse_breakage(qs)
    grid_convergence((1, 2, 3, 4, 8, 12, 16) if args.quick else GRID_QS)
    print(f"\ntotal {time.perf_counter() - t_all:.0f} s")


if __name__ == "__main__":
    main()
