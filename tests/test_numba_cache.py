"""numba's on-disk cache and functions compiled in other files (pbm._compiled_steps.drop_stale_cache).

numba invalidates a cached function when its own source file changes, not when a compiled function
it calls from another file does. The PBM's step loop (``_compiled_steps.advance``) calls the rates
of ``_compiled`` and the selection of ``_compiled_selection``: without ``drop_stale_cache`` an update
of those files left the cached loop computing the old rates.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

CALLEE = """
from numba import njit


@njit("f8(f8)", cache=True)
def f(x):
    return x + {increment}
"""

CALLER = """
from numba import njit

import callee
{check}

@njit(cache=True)
def g(x):
    return 2.0 * callee.f(x)
"""


def _value(folder, module: str) -> float:
    code = f"import sys; sys.path.insert(0, {str(folder)!r}); import {module}; print({module}.g(1.0))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.split()[-1])


def test_a_cached_caller_follows_a_changed_callee_in_another_file(tmp_path):
    check = "from pbmdem.pbm._compiled_steps import drop_stale_cache\n\ndrop_stale_cache(__file__, callee.__file__)"
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(increment=1.0)))
    (tmp_path / "checked.py").write_text(CALLER.format(check=check))
    (tmp_path / "plain.py").write_text(CALLER.format(check=""))
    assert _value(tmp_path, "checked") == 4.0 and _value(tmp_path, "plain") == 4.0  # compiled and cached
    cache = tmp_path / "__pycache__"
    assert list(cache.glob("checked.*.nbi")) and (cache / "checked.deps").exists()
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(increment=2.0)))  # the callee changes
    # numba's own check misses it: the plain caller still runs the cached code of the old callee
    # (if this ever fails, numba follows its callees and drop_stale_cache may go)
    assert _value(tmp_path, "plain") == 4.0
    assert _value(tmp_path, "checked") == 6.0  # its stale cache was dropped: the new callee
    assert _value(tmp_path, "checked") == 6.0  # and cached again (the stamp now matches)
