"""The compiled step loop (``pbm.fast_steps``, ``_compiled_steps.advance``) against the Python loop
of ``GranulationPBM.run`` (``GranulationPBM.fast_steps = False``: one step at a time, the kernel
and the selection prepared in Python): PBM-ANN batches with and without breakage give the same
states, steps and step limits to the bit, and a run that fails fails with the same error."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from pbmdem.coupling import pbm_ann
from pbmdem.pbm._compiled_steps import FALLBACK
from pbmdem.pbm.errors import GridOverflowError, SolverLimitError
from pbmdem.pbm.fast_steps import FastSteps
from pbmdem.pbm.model import GranulationPBM
from pbmdem.surrogate import load_surrogate


@pytest.fixture(scope="module")
def surrogate(tmp_path_factory, tiny_config, root):
    """A small surrogate with wall models (``benchmarks/quick.py``, trained in seconds), loaded."""
    sys.path.insert(0, str(root / "benchmarks"))
    try:
        import quick
    finally:
        sys.path.remove(str(root / "benchmarks"))
    return load_surrogate(quick.surrogate(tmp_path_factory.mktemp("fast_steps"), tiny_config))


def _loop(tiny_config, breakage: bool, porosity_exponent: float = 0.0):
    loop = tiny_config.coupled_loop().replace(coupling_intervals=3)
    pbm = loop.batch.pbm
    brk = pbm.breakage.replace(
        enabled=breakage,
        yield_strength=2.0e3,
        critical_stokes=0.2,
        strength_porosity_exponent=porosity_exponent,
        reference_porosity=0.4,
    )
    return loop.replace(batch=loop.batch.replace(pbm=pbm.replace(breakage=brk)))


def _both(monkeypatch, loop, surrogate, rpm):
    """(compiled, Python) outcomes of one in-memory PBM-ANN batch; the compiled one took its steps
    in compiled calls (counted)."""
    calls = []
    original = FastSteps.advance

    def counting(self, *args):
        calls.append(original(self, *args))
        return calls[-1]

    monkeypatch.setattr(FastSteps, "advance", counting)
    fast = pbm_ann(loop, surrogate, rpm, None, log_each=False)
    assert calls and FALLBACK not in calls
    monkeypatch.setattr(GranulationPBM, "fast_steps", False)
    slow = pbm_ann(loop, surrogate, rpm, None, log_each=False)
    return fast, slow


def _assert_same(fast, slow):
    a, b = fast.result, slow.result
    for name in ("number", "liquid", "gas"):
        np.testing.assert_array_equal(getattr(a.state, name), getattr(b.state, name))
    assert (a.state.steps, a.state.liquid_added, a.state.refused_volume) == (
        b.state.steps,
        b.state.liquid_added,
        b.state.refused_volume,
    )
    assert (a.state.merged_number, a.state.merged_volume) == (b.state.merged_number, b.state.merged_volume)
    if a.state.feed is not None:
        for name in ("number", "liquid", "gas"):
            np.testing.assert_array_equal(getattr(a.state.feed, name), getattr(b.state.feed, name))
    sa, sb = a.summary(), b.summary()
    assert sa.shape == sb.shape and len(sa) > 2
    for q in ("time", "d10", "d50", "d90", "mean_liquid_content", "mean_porosity"):
        np.testing.assert_array_equal(sa[q].to_numpy(), sb[q].to_numpy())
    assert a.info["step_limits"] == b.info["step_limits"]


@pytest.mark.parametrize(("breakage", "porosity_exponent"), [(False, 0.0), (True, 0.0), (True, 2.0)])
@pytest.mark.parametrize("rpm", [600.0, 900.0])
def test_compiled_steps_equal_the_python_loop_to_the_bit(
    tiny_config, surrogate, monkeypatch, breakage, porosity_exponent, rpm
):
    loop = _loop(tiny_config, breakage, porosity_exponent)
    fast, slow = _both(monkeypatch, loop, surrogate, rpm)
    _assert_same(fast, slow)
    assert fast.result.state.steps > 10


def test_breakage_changes_the_batch_it_is_compared_on(tiny_config, surrogate):
    """The comparison above covers breakage that acts: the final d50 with it differs."""
    on = pbm_ann(_loop(tiny_config, True), surrogate, 900.0, None, log_each=False)
    off = pbm_ann(_loop(tiny_config, False), surrogate, 900.0, None, log_each=False)
    assert on.result.summary().d50.iloc[-1] != off.result.summary().d50.iloc[-1]


def test_a_run_that_fails_fails_the_same_way(tiny_config, surrogate, monkeypatch):
    """Too few steps allowed (SolverLimitError) or too small a grid (GridOverflowError): the same
    error, word for word, from the compiled loop as from the Python loop."""
    base = _loop(tiny_config, True)
    pbm = base.batch.pbm
    few = base.replace(batch=base.batch.replace(pbm=pbm.replace(solver=pbm.solver.replace(max_steps=7))))
    plain = _loop(tiny_config, False)
    small = plain.replace(
        batch=plain.batch.replace(
            pbm=plain.batch.pbm.replace(
                grid=plain.batch.pbm.grid.replace(bins=5),
                solver=pbm.solver.replace(max_overflow_fraction=1e-9),
            )
        )
    )
    for loop, error in ((few, SolverLimitError), (small, GridOverflowError)):
        messages = []
        for fast in (True, False):
            monkeypatch.setattr(GranulationPBM, "fast_steps", fast)
            with pytest.raises(error) as info:
                pbm_ann(loop, surrogate, 900.0, None, log_each=False)
            messages.append(str(info.value))
        assert messages[0] == messages[1]


def test_a_step_handed_back_to_python_and_the_compiled_rest_give_the_python_loop(tiny_config, surrogate, monkeypatch):
    """The hand-over (FALLBACK) between the loops: every compiled call first hands its step back
    to the Python loop, which takes it, and the compiled loop then resumes from the state, step
    size, selection time and counts the Python step left; the batch is the Python loop's to the bit."""
    from pbmdem.pbm import _compiled_steps

    original = FastSteps.advance
    handed, compiled = [], []

    def hand_back_first(self, u, t, tallies):
        if self not in handed:  # the first step of every run
            handed.append(self)
            self.t, self.records = t, []  # as the compiled call leaves them when it hands back its first step
            return _compiled_steps.FALLBACK
        compiled.append(self.ctl.taken)
        code = original(self, u, t, tallies)
        compiled[-1] = self.ctl.taken - compiled[-1]
        return code

    loop = _loop(tiny_config, True, 2.0)
    slow = None
    for mode in ("python", "mixed"):
        monkeypatch.setattr(GranulationPBM, "fast_steps", mode == "mixed")
        monkeypatch.setattr(FastSteps, "advance", hand_back_first)
        out = pbm_ann(loop, surrogate, 900.0, None, log_each=False)
        slow = slow or out
    assert len(handed) >= 3 and sum(compiled) > 10 * len(handed)  # one hand-over per run, most steps compiled
    _assert_same(out, slow)


def test_a_batch_gives_the_same_result_whatever_ran_before_in_the_process(tiny_config, surrogate, monkeypatch):
    # the loop keeps the model of its batch settings across batches (coupling.loop._built):
    # a batch run after others (another speed, another setting, a member) equals one run on a fresh model
    from pbmdem.coupling import loop as coupling_loop

    on, off = _loop(tiny_config, True, 2.0), _loop(tiny_config, False)
    coupling_loop._built.cache_clear()
    fresh = pbm_ann(on, surrogate, 900.0, None, log_each=False)
    model = coupling_loop._built(on.batch)[0]
    for loop, rpm, member in ((on, 600.0, None), (off, 900.0, None), (on, 750.0, 0), (off, 600.0, 1)):
        pbm_ann(loop, surrogate if member is None else surrogate.member(member), rpm, None, log_each=False)
    again = pbm_ann(on, surrogate, 900.0, None, log_each=False)
    assert coupling_loop._built(on.batch)[0] is model and coupling_loop._built.cache_info().currsize == 2
    _assert_same(again, fresh)
    assert again.result.info["rpm"] == 900.0
