"""Issue 33 item 3, start-up: cached kernels read without parsing their bitcode and numba's
runtime read from the cache (formation_traci/core/kernel_load.py), and what a compilation tells
the user (formation_traci/core/kernel_notice.py)."""
from __future__ import annotations

import io
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit
from numba.core import event

from formation_traci.core.kernel_notice import CompileWatch, NOTICE

ROOT = Path(__file__).resolve().parents[1]

PROBE = '''
import numpy as np
from formation_traci.core.kernels import kernel, py_hypot

@kernel
def lengths(x):  # allocates (numba's runtime) and calls a kernel of the package
    out = np.empty_like(x)
    for i in range(x.size):
        out[i] = py_hypot(x[i], 2.0 * x[i])
    return out

@kernel
def total(x):
    return lengths(x).sum() + 1.0
'''
CALL = ("import sys, numpy as np, probe\n"
        "x = np.linspace(0.0, 3.0, 7)\n"
        "for name in sys.argv[1:]:\n"
        "    print(name, repr(np.asarray(getattr(probe, name)(x)).tolist()))\n")


def _call(tmp_path: Path, *names: str, before: str = "") -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(ROOT)]))
    env.pop("NUMBA_DISABLE_JIT", None)
    cp = subprocess.run([sys.executable, "-c", before + CALL, *names], env=env, cwd=tmp_path,
                        capture_output=True, text=True, timeout=300)
    assert cp.returncode == 0, cp.stderr
    return {ln.split(" ", 1)[0]: eval(ln.split(" ", 1)[1]) for ln in cp.stdout.splitlines()}


def test_a_kernel_read_lazily_gives_the_compiled_values_and_links_into_a_new_compilation(tmp_path):
    """Compiled (cold), read with its bitcode parsed (first warm read, the side file written),
    read lazily (the side file read), and linked into a kernel compiled in a process that read
    it lazily: the same floats each time, math.hypot's to the last bit."""
    (tmp_path / "probe.py").write_text(PROBE)
    x = np.linspace(0.0, 3.0, 7)
    want = [float(np.float64(__import__("math").hypot(v, 2.0 * v))) for v in x]
    cold = _call(tmp_path, "lengths", "total")
    assert cold["lengths"] == want and cold["total"] == sum(want) + 1.0
    cache = next(d for d in (tmp_path / "cache").iterdir() if list(d.glob("probe.*.nbi")))
    assert not list(cache.glob("symbols-*.nbsym"))  # compiled: nothing read yet
    assert _call(tmp_path, "lengths", "total") == cold  # read, bitcode parsed, names kept
    assert len(list(cache.glob("symbols-*.nbsym"))) == 2
    assert list(cache.glob("nrt-*.nbnrt"))  # the runtime's machine code kept on the first read
    assert _call(tmp_path, "lengths", "total") == cold  # read lazily
    for f in cache.glob("probe.total*"):
        f.unlink()  # total compiles again, linking the lazily read lengths into it
    assert _call(tmp_path, "lengths", "total") == cold
    for f in cache.glob("symbols-*.nbsym"):
        f.write_text(f.read_text()[:40])  # a truncated side file: ignored and written again
    assert _call(tmp_path, "lengths", "total") == cold
    # lengths' side file written again, the recompiled total's written (the first total's,
    # if its bitcode differs, stays truncated: read by no kernel)
    assert sum(f.read_text().endswith("\nend") for f in cache.glob("symbols-*.nbsym")) >= 2


MOVED = ("import formation_traci.core.kernel_load as kl\n"
         "def moved(*args):\n"
         "    raise TypeError('numba internals of another version')\n"
         "kl.{name} = moved\n")


def test_numba_internals_that_changed_fall_back_to_numbas_own_load(tmp_path):
    """Another numba whose internals kernel_load.py reads have changed (a TypeError, not only
    an AttributeError): the kernel is read from the cache by numba's own load, same values."""
    (tmp_path / "probe.py").write_text(PROBE)
    cold = _call(tmp_path, "lengths", "total")
    for name in ("lazy_unserialize", "init_runtime"):
        assert _call(tmp_path, "lengths", "total", before=MOVED.format(name=name)) == cold


def _ours(fn):
    """``fn`` as if defined in the package (the watch reports our kernels only)."""
    fn.__module__ = "formation_traci._probe"
    return njit(fn)


def _bad_py(x):
    return x + "a"  # float + str: numba cannot type it


_bad = _ours(_bad_py)


def _caller_py(x):
    return _bad(x) * 2.0


_caller = _ours(_caller_py)


def test_a_failing_compilation_names_the_innermost_kernel_and_the_error():
    out = io.StringIO()
    watch = CompileWatch(out=out, slow_s=1e9)
    with event.install_listener("numba:compile", watch):
        try:
            _caller(1.0)
        except Exception as exc:  # numba's TypingError goes on to the caller, as before
            raised = type(exc).__name__
        else:
            raised = None
    lines = out.getvalue().splitlines()
    assert raised == "TypingError"
    assert lines[0].startswith(NOTICE + ": at most ~75 s on a quiet 2-core machine")
    assert len(lines) == 2 and lines[1].startswith(
        "formation-traci: compiling kernel formation_traci._probe._bad_py failed after ")
    assert ": TypingError: " in lines[1]
    assert watch.depth == 0 and watch.started is None


def test_a_slow_compilation_is_said_to_be_slow_and_the_end_says_how_long_it_took():
    """A compilation event held open 1.5 s with a 'slow' threshold of 0.3 s: at least one
    'still compiling' line (at 0.3, 0.6, ... s: up to five), then the time compiling, >= 1.5 s."""
    out = io.StringIO()
    watch = CompileWatch(out=out, slow_s=0.3)
    disp = _ours(lambda x: x)
    data = {"dispatcher": disp, "args": (), "return_type": None}
    watch.on_start(event.Event("numba:compile", event.EventStatus.START, data))
    time.sleep(1.5)
    watch.on_end(event.Event("numba:compile", event.EventStatus.END, data))
    watch.finished()
    lines = out.getvalue().splitlines()
    slow = [ln for ln in lines if ln.startswith("formation-traci: still compiling the numba kernels after")]
    assert 1 <= len(slow) <= 5
    last = lines[-1]
    assert last.startswith("formation-traci: the numba kernels compiled in ")
    assert float(last.split(" in ")[1].split(" s")[0]) >= 1.5
    time.sleep(0.7)
    assert out.getvalue().splitlines()[-1] == last  # the watch stopped with finished()
