"""The compiled (numba) backend, the PBM's one implementation of its rates and stages, and the
kernel caches: the same numbers as the numpy oracle (tests/pbm_oracle.py: the sparse map, the
success models, spraying, consolidation, the SSP stages) and the same kernels as the formula, to
the bit; a kernel called in Python and the same kernel factored give the same run to the bit; no
numba on `import pbmdem.pbm`."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pbm_oracle as oracle
import pytest

from pbmdem.config import Solver
from pbmdem.pbm import (
    SCHEMES,
    CollisionKernel,
    Consolidation,
    ConstantFrequency,
    ConstantKernel,
    GranulationPBM,
    Grid,
    KernelInput,
    LiquidAddition,
    PBMInputError,
    SuccessProbability,
    TableFrequency,
)
from pbmdem.pbm.errors import KernelShapeError
from pbmdem.pbm.kernels import KernelFactors


def random_totals(rng, M, empty=5):
    """(3, M) class totals spanning 30 decades, with empty top classes (as a run's state)."""
    nlg = rng.random((3, M)) * 10.0 ** rng.uniform(-30, 3, (3, M))
    nlg[:, M - empty :] = 0.0
    return nlg


@pytest.mark.parametrize("scheme", sorted(SCHEMES))
@pytest.mark.parametrize("K,extra", [(37, (2.0, 3.375, 8.0)), (20, ()), (60, (1.7,))])
def test_compiled_totals_equal_the_sparse_map_to_the_bit(scheme, K, extra):
    rng = np.random.default_rng(K)
    g = Grid(K, 2.0 ** (1 / 3), v0=1.0)
    op = SCHEMES[scheme](g.x, g.edges[1:-1], extra=extra)
    m = oracle.sparse_map(op)
    for _ in range(5):
        beta = rng.random((op.M, op.M))
        beta = beta + beta.T
        nlg = random_totals(rng, op.M)
        d, refused = oracle.compiled_totals(op, beta, nlg)
        d_ref, refused_ref = oracle.aggregation_totals(op, beta, nlg, m)
        # the same products summed in the same order: equal to the bit
        np.testing.assert_array_equal(d, d_ref)
        assert refused == refused_ref
        # the totals are a fresh array each time (the integrator keeps the stages' rates)
        assert oracle.compiled_totals(op, beta, nlg)[0] is not d


#: the breakage arguments of the compiled rates without breakage (an empty selection)
NO_BREAKAGE = (np.zeros(0), np.zeros((3, 0, 0)), np.zeros((4, 0)), np.zeros((2, 0)))


def _compiled_rates(op, u, beta, model, threshold, width, vectors, spray_rate, consolidation_rate, brk=NO_BREAKAGE):
    from pbmdem.pbm import _compiled

    M = op.M
    d, tally = np.empty((3, M)), np.empty(3)
    params = np.array([0.0, 0.0, threshold, width, spray_rate, consolidation_rate])
    _compiled.class_rates(
        u, beta, _compiled.SUCCESS_CODES[model], vectors, params, *op.compiled_arrays(), *brk, np.zeros((2, M)), d,
        tally,
    )  # fmt: skip
    return d.reshape(-1), tally


@pytest.mark.parametrize("scheme", sorted(SCHEMES))
@pytest.mark.parametrize("model", ["always", "step", "logistic"])
def test_compiled_class_rates_and_stages_equal_the_oracle(scheme, model):
    # every process on: aggregation with a success model, spraying, consolidation; then the stages
    # of one step of every order
    from pbmdem.pbm import _compiled, _compiled_steps

    rng = np.random.default_rng(7)
    g = Grid(30, 2.0 ** (1 / 3), v0=1.0)
    op = SCHEMES[scheme](g.x, g.edges[1:-1], extra=(1.5, 4.0))
    M = op.M
    xc = op.class_volumes
    beta = rng.random((M, M)) * 1e-3
    beta = beta + beta.T
    N = rng.uniform(1.0, 100.0, M) * (np.arange(M) < M - 6)
    N[-2:] = rng.uniform(1.0, 100.0, 2)  # the feed classes
    u = np.concatenate([N, N * xc * rng.uniform(0.0, 0.08, M), N * xc * rng.uniform(0.0, 0.06, M)])
    weight, gas_min = (xc ** (2 / 3)).copy(), 0.25 * xc
    vectors = np.ascontiguousarray(np.stack([xc, weight, gas_min]))
    args = (model, 0.02, 0.005)
    Q, c = 3.0, 0.02

    def oracle_rates(v):
        return oracle.class_rates(op, v, beta, *args, spray=(Q, weight), consol=(c, gas_min))

    d, refused = _compiled_rates(op, u, beta, *args, vectors, Q, c)
    d_ref, refused_ref = oracle_rates(u)
    # the same operations in the same order (numba's exp and numpy's may differ in the last digit)
    exact = model != "logistic"
    check = np.testing.assert_array_equal if exact else lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-12)
    check(d, d_ref)
    assert refused[0] == refused_ref[0] or not exact
    assert np.all(refused[1:] == 0.0) and np.all(refused_ref[1:] == 0.0)  # no breakage: nothing merged
    params = np.array([0.0, 0.0, 0.02, 0.005, Q, c])
    for order in (1, 2, 3):
        dt = 0.3 * _compiled_steps.depletion_time(u, d)
        k, r = np.zeros((3, 3 * M)), np.zeros((4, 3))
        k[0], r[0] = d, refused
        u_new, u_low, stage = np.empty(3 * M), np.empty(3 * M), np.empty(3 * M)
        _compiled_steps.ssp_step(
            u, k, r, dt, order, beta, _compiled.SUCCESS_CODES[model], vectors, params, *op.compiled_arrays(),
            *NO_BREAKAGE, np.zeros((2, M)), u_new, u_low, stage,
        )  # fmt: skip
        ref_new, ref_low, ref_refused = oracle.ssp_step(oracle_rates, u, dt, order)
        check(u_new, ref_new)
        if order > 1:
            check(u_low, ref_low)
        np.testing.assert_allclose(r[3], ref_refused, rtol=1e-12, atol=0.0)


def test_compiled_totals_take_any_layout_of_the_kernel():
    rng = np.random.default_rng(1)
    g = Grid(12, 2.0, v0=1.0)
    op = SCHEMES["cell_average"](g.x, g.edges[1:-1])
    beta = np.asfortranarray(rng.random((12, 12)))
    beta = beta + beta.T
    nlg = random_totals(rng, 12, empty=2)
    np.testing.assert_array_equal(
        oracle.compiled_totals(op, beta, nlg)[0], oracle.compiled_totals(op, np.ascontiguousarray(beta), nlg)[0]
    )


class _Counting:
    """A collision-frequency source that counts its calls and can change its answer."""

    def __init__(self, K, value=0.1):
        self.calls = 0
        self.c = np.full((K, K), value)

    def __call__(self, d, n, rpm):
        self.calls += 1
        return self.c

    def __repr__(self):
        return "CountingSource"


def _input(K, phi, t=0.0):
    x = 1e-9 * 2.0 ** np.arange(K)
    return KernelInput(
        t=t,
        volumes=x,
        diameters=(6 * x / np.pi) ** (1 / 3),
        numbers=np.ones(K),
        surface_fraction=np.asarray(phi, float),
        rpm=600.0,
    )


@pytest.mark.parametrize("model", ["step", "logistic", "always"])
def test_cached_kernel_equals_the_formula(model):
    K = 6
    src = _Counting(K)
    kern = CollisionKernel(src, 2e-4, SuccessProbability(model, threshold=0.02, width=0.005))
    rng = np.random.default_rng(0)
    for step in range(8):
        phi = rng.uniform(0.0, 0.04, K)
        inp = _input(K, phi, t=float(step))
        kern.prepare(inp)
        beta = kern(inp)
        expected = 2e-4 * src.c * kern.success(phi)
        np.testing.assert_array_equal(beta, expected)
        # the same input again: the same matrix (cached), still equal to the formula
        np.testing.assert_array_equal(kern(inp), expected)


def test_kernel_follows_a_changed_success_pattern_and_a_changed_source():
    K = 4
    src = _Counting(K)
    kern = CollisionKernel(src, 1.0, SuccessProbability("step", threshold=0.02), update_interval=0.0)
    wet = _input(K, [0.03, 0.03, 0.0, 0.0])
    kern.prepare(wet)
    first = kern(wet).copy()
    assert first[0, 1] == pytest.approx(0.1) and first[0, 2] == 0 and first[2, 3] == 0
    wetter = _input(K, [0.03, 0.03, 0.03, 0.0])
    assert kern(wetter)[0, 2] == pytest.approx(0.1) and kern(wetter)[2, 3] == 0
    # the source changes its answer at the next refresh: the kernel follows
    src.c = np.full((K, K), 0.3)
    later = _input(K, [0.03, 0.03, 0.03, 0.0], t=1.0)
    kern.prepare(later)
    assert kern(later)[0, 2] == pytest.approx(0.3)
    assert src.calls == 2


def test_a_source_that_turns_bad_between_refreshes_is_refused():
    # an unchanged matrix is not checked again, a changed one is
    g = Grid(12, 2.0, min_diameter=1e-3)
    src = _Counting(12)
    model = GranulationPBM(
        g,
        CollisionKernel(src, 1e-4, SuccessProbability("always"), update_interval=0.5),
        solver=Solver().replace(max_step=0.25),
    )
    state = model.initial_state(np.pi / 6 * np.array([2e-3]) ** 3, [100])
    res = model.run(0.0, 2.0, state)
    assert res.info["step_limits"]["kernel_refreshes"] == src.calls >= 2

    class Turning(_Counting):
        def __call__(self, d, n, rpm):
            c = super().__call__(d, n, rpm)
            if self.calls >= 3:
                c = np.triu(c)
            return c

    model.kernel.set_source(Turning(12))
    with pytest.raises(KernelShapeError, match="non-symmetric"):
        model.run(0.0, 2.0, state)


def test_import_pbmdem_pbm_does_not_import_numba():
    code = "import sys, pbmdem.pbm; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    code = (
        "import sys, numpy as np, pbmdem.pbm as p; p.GranulationPBM(p.Grid(5, 2.0, v0=1.0), "
        "p.ConstantKernel(1.0)); print('numba' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "True"


def bin_rates(model, t, N, L, G, spraying):
    """Rates (dN, dL, dG) in m3 and the refused solid-volume rate (m3/s) of a one-dimensional model
    at the per-bin totals (t, N, L, G) without feed classes: its one rate evaluation, as a step
    calls it (the kernel prepared at that state)."""
    model._use_classes(np.zeros(0))
    g, x0 = model.grid, model.grid.x[0]
    model._prepare(oracle.bin_input(model, t, N, L, G))
    model._rates(t, np.concatenate([N, np.asarray(L, float) / x0, np.asarray(G, float) / x0]), spraying, 0)
    d, K = model._k[0].copy(), g.bins
    return d[:K], d[K : 2 * K] * x0, d[2 * K :] * x0, float(model._r[0, 0]) * x0


def test_spraying_and_consolidation_rates_follow_their_formulas():
    g = Grid(12, 2.0, min_diameter=1e-3)
    rng = np.random.default_rng(4)
    N = rng.uniform(1.0, 100.0, 12)
    L, G = N * g.x * rng.uniform(0.1, 0.5, 12), N * g.x * rng.uniform(0.2, 0.6, 12)
    Q, c, eps = 5e-8, 0.02, 0.2

    def rates(liquid, consolidation, spraying):
        model = GranulationPBM(g, ConstantKernel(1e-4), liquid, consolidation)
        return bin_rates(model, 1.0, N, L, G, spraying)

    plain = rates(None, None, False)
    for rule, w in (("surface_area", N * g.d**2), ("solid_volume", N * g.x)):
        sprayed = rates(LiquidAddition(Q, 0.0, 10.0, rule), None, True)
        np.testing.assert_allclose(sprayed[1] - plain[1], Q * w / w.sum(), rtol=1e-12, atol=1e-12 * Q)
        assert np.sum(sprayed[1] - plain[1]) == pytest.approx(Q, rel=1e-12)
        np.testing.assert_array_equal(sprayed[0], plain[0])
        not_spraying = rates(LiquidAddition(Q, 0.0, 10.0, rule), None, False)
        np.testing.assert_array_equal(not_spraying[1], plain[1])
    consolidated = rates(None, Consolidation(c, eps), False)
    np.testing.assert_allclose(
        consolidated[2] - plain[2], -c * (G - eps / (1 - eps) * N * g.x), rtol=1e-12, atol=1e-12 * np.abs(G).max() * c
    )


def test_table_frequency_from_matrix_is_the_table_of_the_matrix():
    import pandas as pd

    rng = np.random.default_rng(5)
    x = np.geomspace(1.5e-3, 1.5e-2, 30)
    for k in (2, 3, 6):
        d = np.geomspace(2e-3, 8e-3, k) * rng.uniform(0.97, 1.03, k)
        c = rng.uniform(0.0, 0.2, (k, k))
        c = 0.5 * (c + c.T)
        c[0, -1] = c[-1, 0] = 0.0  # a zero is floored as in the table
        iu, ju = np.triu_indices(k)
        table = pd.DataFrame({"d_i": d[iu], "d_j": d[ju], "frequency_per_pair": c[iu, ju]})
        for extrapolation in ("clamp", "linear"):
            ref = TableFrequency(table, extrapolation=extrapolation, column="frequency_per_pair")
            new = TableFrequency.from_matrix(d, c, extrapolation=extrapolation)
            np.testing.assert_array_equal(new(x, None, 600.0), ref(x, None, 600.0))
            assert new.ranges == ref.ranges and repr(new) == repr(ref)
    # diameters out of order go through the table
    d = np.array([4e-3, 2e-3])
    c = np.array([[0.1, 0.2], [0.2, 0.3]])
    np.testing.assert_allclose(TableFrequency.from_matrix(d, c)(d, None, 600.0), c, rtol=1e-12)
    with pytest.raises(PBMInputError, match="no positive frequency_per_pair"):
        TableFrequency.from_matrix([2e-3, 3e-3], np.zeros((2, 2)))


def test_table_frequency_from_matrix_merges_classes_of_equal_diameter_as_the_table_does():
    """A coupling interval's classes can repeat a diameter (a feed class on a pivot): from_matrix
    then averages their pairs without DataFrames, to the bit of the table's pandas mean (its
    compensated sums), on random matrices spanning decades with 2 and 3 copies and zeros."""
    import pandas as pd

    rng = np.random.default_rng(11)
    x = np.geomspace(5e-4, 2e-2, 25)
    for trial in range(200):
        base = np.sort(rng.uniform(1e-3, 1e-2, rng.integers(2, 7)))
        d = np.sort(np.concatenate([base, rng.choice(base, size=rng.integers(1, 3))]))
        c = rng.lognormal(0.0, 2.0, (d.size, d.size))
        c = 0.5 * (c + c.T)
        if trial % 4 == 0:
            c[0, :] = c[:, 0] = 0.0  # zeros are floored as in the table
        iu, ju = np.triu_indices(d.size)
        table = pd.DataFrame({"d_i": d[iu], "d_j": d[ju], "frequency_per_pair": c[iu, ju]})
        ref = TableFrequency(table, column="frequency_per_pair")
        new = TableFrequency.from_matrix(d, c)
        np.testing.assert_array_equal(new._interp[0].values, ref._interp[0].values)
        np.testing.assert_array_equal(new(x, None, 600.0), ref(x, None, 600.0))
        assert new.ranges == ref.ranges and repr(new) == repr(ref)


def test_bilinear_is_the_regular_grid_interpolator_to_the_bit():
    """TableFrequency's log frequencies: ``Bilinear`` gives what scipy's RegularGridInterpolator
    (linear, extrapolating) gives, to the bit, on random tables at points inside the grid, on its
    nodes and beyond it."""
    from scipy.interpolate import RegularGridInterpolator

    from pbmdem.pbm.bilinear import Bilinear

    rng = np.random.default_rng(3)
    for trial in range(300):
        lu = np.log(np.sort(rng.uniform(1e-3, 1e-2, rng.integers(2, 9))))
        values = rng.normal(0.0, 3.0, (lu.size, lu.size))
        ref = RegularGridInterpolator((lu, lu), values, method="linear", bounds_error=False, fill_value=None)
        ld = np.log(np.sort(rng.uniform(5e-4, 2e-2, rng.integers(1, 30))))
        if trial % 3 == 0:
            ld = np.concatenate([ld, lu])  # the nodes themselves
        a, b = np.meshgrid(ld, ld, indexing="ij")
        points = np.column_stack([a.ravel(), b.ravel()])
        np.testing.assert_array_equal(Bilinear(lu, values)(points), ref(points))
        # on the pairs of one set of values (TableFrequency's bins): the same numbers, reshaped
        assert Bilinear(lu, values).outer(ld).tobytes() == ref(points).reshape(ld.size, ld.size).tobytes()


class _Unfactored:
    """The same kernel without its factors: the model calls it at every evaluation."""

    def __init__(self, kernel):
        self.kernel = kernel

    def __call__(self, inp):
        return self.kernel(inp)

    def prepare(self, inp):
        self.kernel.prepare(inp)

    def reset(self):
        self.kernel.reset()

    def __getattr__(self, name):  # evaluations, ... but no factors
        if name == "factors":
            raise AttributeError(name)
        return getattr(self.kernel, name)


@pytest.mark.parametrize(
    "kernel",
    [
        lambda: CollisionKernel(ConstantFrequency(0.12), 2e-4, SuccessProbability("step", 0.02), update_interval=1.0),
        lambda: CollisionKernel(ConstantFrequency(0.12), 2e-4, SuccessProbability("logistic", 0.02, 0.005)),
        lambda: CollisionKernel(ConstantFrequency(0.12), 2e-4, SuccessProbability("always")),
        lambda: ConstantKernel(2e-5),
    ],
    ids=["step", "logistic", "always", "constant"],
)
def test_factored_kernel_in_the_compiled_rates_equals_calling_the_kernel(kernel):
    # the default process with feed classes: the compiled path (factors) and the generic one
    g = Grid.spanning(2e-3, 32e-3, 2.0 ** (1 / 3))
    runs = []
    for k in (kernel(), _Unfactored(kernel())):
        model = GranulationPBM(g, k, LiquidAddition(5.8e-8, 60.0, 240.0), Consolidation(0.02, 0.2), rpm=600.0)
        state = model.initial_state(np.pi / 6 * np.array([2e-3, 3e-3, 4e-3]) ** 3, [900.0, 540.0, 360.0], porosity=0.5)
        runs.append(model.run(0.0, 480.0, state, output_times=np.arange(0.0, 481.0, 10.0)))
    fast, generic = runs
    assert fast.info["kernel_evaluation"] == "compiled" and generic.info["kernel_evaluation"] == "called"
    assert fast.info["steps"] == generic.info["steps"]
    assert fast.info["step_limits"] == generic.info["step_limits"]
    for a, b in ((fast.number, generic.number), (fast.liquid, generic.liquid), (fast.gas, generic.gas)):
        # one implementation of the rates, the stages and the success model: equal to the bit
        np.testing.assert_array_equal(a, b)
    assert fast.summary().d50.iloc[-1] > 1.2 * fast.summary().d50.iloc[0]  # it did granulate


def test_a_velocity_dependent_success_is_not_factored():
    from pbmdem.pbm import StokesCriterion

    kern = CollisionKernel(
        ConstantFrequency(0.12, impact_velocity=0.1),
        2e-4,
        SuccessProbability("step", 0.02, velocity=StokesCriterion(0.1, 0.4, 5e-6, 1000.0)),
    )
    inp = _input(4, [0.03, 0.03, 0.0, 0.0])
    kern.prepare(inp)
    assert kern.factors(inp) is None
    assert CollisionKernel(_Counting(4), 1.0).factors(inp)[1:] == ("step", 0.02, 0.005)


def test_shapes_are_checked_before_the_compiled_code():
    class WrongFactors(ConstantKernel):
        def factors(self, inp):
            return KernelFactors(np.ones((2, 2)))

    model = GranulationPBM(Grid(8, 2.0, min_diameter=1e-3), WrongFactors(1e-4))
    state = model.initial_state(np.pi / 6 * np.array([2e-3]) ** 3, [100])
    with pytest.raises(KernelShapeError, match=r"factors of shape \(2, 2\); expected \(9, 9\) for the 9 classes"):
        model.run(0.0, 1.0, state)


def test_rates_after_a_run_with_feed_classes_use_the_bins():
    # a run leaves flush levels and classes of its own; rates() of per-bin totals afterwards are
    # those of a fresh model (a called kernel sees the K bins, not the run's classes)
    g = Grid.spanning(2e-3, 32e-3, 2.0 ** (1 / 3))
    rng = np.random.default_rng(3)
    N = rng.uniform(1.0, 100.0, g.bins)
    L, G = N * g.x * 0.05, N * g.x * 0.3

    def model():
        kern = CollisionKernel(ConstantFrequency(0.12), 2e-4, SuccessProbability("logistic", 0.02, 0.005))
        return GranulationPBM(g, _Unfactored(kern), LiquidAddition(5.8e-8, 0.0, 240.0), Consolidation(0.02, 0.2))

    used = model()
    state = used.initial_state(np.pi / 6 * np.array([2e-3, 3e-3]) ** 3, [900.0, 540.0], porosity=0.5)
    used.run(0.0, 60.0, state)
    for a, b in zip(bin_rates(used, 1.0, N, L, G, True), bin_rates(model(), 1.0, N, L, G, True)):
        np.testing.assert_array_equal(a, b)
