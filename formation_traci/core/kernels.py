"""The one way a law becomes compiled code: :func:`kernel` (numba ``njit``, cached on disk).

Every physical and control law of the package is a ``@kernel`` function in its home module
(models/, control/, road/); the step kernels in sim/fleet.py call them. With the environment
variable ``NUMBA_DISABLE_JIT=1`` the same functions run as plain Python: that is the
reference the ``jit_off`` tests run (README, CI).

Three chores live here:

* what the user is told while kernels compile (a cold numba cache costs tens of seconds;
  the user should not see a silent stall): the notice with how long it takes, a failure, a
  slow compilation, the time it took (formation_traci/core/kernel_notice.py);
* numba keys its on-disk cache on the file that defines a function only, not on the files
  of the functions it calls: a digest of every module that defines kernels is stored next
  to each cache directory, and a directory whose digest differs is emptied of kernels;
* a kernel read from the on-disk cache is machine code that needs numba's runtime (NRT)
  only: it is loaded without first initialising numba's compiler
  registries (its ``target_context.refresh()``, which imports all of numba's lowering
  modules and scipy.linalg: 0.3-0.6 s of every warm start). A compilation
  initialises them itself (numba's compiler refreshes its contexts). It also reads
  numba's runtime from the cache and leaves the kernel's bitcode unparsed until a
  compilation links it (formation_traci/core/kernel_load.py, the one module that reaches into
  numba's internals).
"""
from __future__ import annotations

import hashlib
import math
import types
from pathlib import Path

import numpy as np
from numba import njit

from . import kernel_load, kernel_notice

_NOTICE = kernel_notice.NOTICE
_STAMP = "formation_kernels.digest"


def _package_digest() -> str:
    """sha256 over every module of the package that defines kernels."""
    h = hashlib.sha256()
    root = Path(__file__).resolve().parents[1]  # the package (this module is in core/)
    for p in sorted(root.rglob("*.py")):
        text = p.read_bytes()
        if b"@kernel" in text or p.name == "kernels.py":
            h.update(str(p.relative_to(root)).encode())
            h.update(text)
    return h.hexdigest()


_DIGEST = _package_digest()
_CHECKED: set = set()


def _drop_stale_cache(dispatcher) -> None:
    """Numba keys its on-disk cache on the file that defines a function only, not on the
    files of the functions it calls: when any kernel module changed since a cache directory
    was written, every cached kernel in it goes (they compile afresh)."""
    path = kernel_load.cache_path(dispatcher)
    if path is None or path in _CHECKED:
        return  # NUMBA_DISABLE_JIT, or this directory was checked already
    _CHECKED.add(path)
    try:
        stamp = Path(path) / _STAMP
        if (stamp.read_text().strip() if stamp.exists() else None) != _DIGEST:
            for pattern in ("*.nb[ic]",) + kernel_load.PATTERNS:
                for f in Path(path).glob(pattern):
                    f.unlink()
            stamp.parent.mkdir(parents=True, exist_ok=True)
            stamp.write_text(_DIGEST)
    except OSError:  # pragma: no cover - read-only install: the shipped cache is current
        pass


def kernel(fn=None, **options):
    """``numba.njit(cache=True, error_model="numpy")`` (options override), with the stale
    cache check of :func:`_drop_stale_cache` and the quick load of kernel_load.py."""
    def wrap(f):
        d = njit(**{"cache": True, "error_model": "numpy", **options})(f)
        kernel_load.quick_load(d)
        _drop_stale_cache(d)
        return d
    return wrap(fn) if fn is not None else wrap


def rebind(fn, **names):
    """A compiled copy of kernel (or plain function) ``fn`` whose globals ``names`` are
    replaced: how a law or model defined outside the package runs inside the compiled step
    (control/laws, models/integrator.py ``rk4_for``). Not cached on disk (numba cannot
    cache a function whose globals are not its module's); compiled on first call."""
    f = getattr(fn, "py_func", fn)
    glb = dict(f.__globals__)
    glb.update(names)
    copy = types.FunctionType(f.__code__, glb, f.__name__, f.__defaults__, f.__closure__)
    copy.__kwdefaults__, copy.__doc__ = f.__kwdefaults__, f.__doc__
    return njit(error_model="numpy")(copy)


def compiled_in_this_process() -> bool:
    """True once numba has compiled one of our kernels in this process (the notice was
    printed): the cache was cold (sim/warm.py then compiles the other scenario kinds' too)."""
    return kernel_notice.WATCH.printed


# --- scalar helpers with numpy's semantics (NaN propagates like np.maximum / np.minimum) ---

@kernel
def maximum(a, b):
    """np.maximum for scalars."""
    if a >= b or a != a:
        return a
    return b


@kernel
def minimum(a, b):
    """np.minimum for scalars."""
    if a <= b or a != a:
        return a
    return b


@kernel
def clip(x, lo, hi):
    """np.clip(x, lo, hi) == minimum(maximum(x, lo), hi) for scalars."""
    return minimum(maximum(x, lo), hi)


@kernel
def bisect_right(a, x):
    """Python's ``bisect.bisect_right`` on the increasing 1-D array ``a``: the number of
    entries <= x (numba's np.searchsorted lives in a module whose load imports scipy)."""
    lo, hi = 0, a.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@kernel
def wrap_angle(a):
    """Wrap an angle to (-pi, pi] [rad]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def substeps(dt: float, max_step: float) -> int:
    """Number of equal sub-steps of at most ``max_step`` [s] that cover ``dt`` [s]."""
    return max(1, math.ceil(dt / max_step - 1e-9))


_SPLIT = 134217729.0  # 2**27 + 1: Veltkamp's splitter of a float64


@kernel
def _two_product_lo(x, y, z):
    """x * y - z exactly, for z = x * y rounded (Dekker's product, no fma)."""
    c = _SPLIT * x
    xh = c - (c - x)
    xl = x - xh
    c = _SPLIT * y
    yh = c - (c - y)
    yl = y - yh
    return ((xh * yh - z) + xh * yl + xl * yh) + xl * yl


@kernel
def py_hypot(x, y):
    """math.hypot(x, y) of CPython (>= 3.10) bit for bit: its ``vector_norm`` for two
    coordinates (lossless scaling and squaring, compensated sum, one differential
    correction). It is not the C library's hypot (np.hypot), which differs in the last bit
    for about 1 in 1000 inputs."""
    ax = abs(x)
    ay = abs(y)
    if ax != ax or ay != ay:
        if ax == np.inf or ay == np.inf:
            return np.inf
        return np.nan
    mx = ax if ax > ay else ay
    if mx == np.inf:
        return mx
    if mx == 0.0:
        return mx
    m, e = math.frexp(mx)
    if e < -1023:  # subnormal largest coordinate (CPython rescales by DBL_MIN first)
        tiny = 2.2250738585072014e-308
        return tiny * py_hypot(ax / tiny, ay / tiny)
    scale = math.ldexp(1.0, -e)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    for v in (ax, ay):
        v = v * scale
        hi = v * v
        lo = _two_product_lo(v, v, hi)
        s = csum + hi
        frac2 += (csum - s) + hi
        csum = s
        frac1 += lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    hi = -h * h
    lo = _two_product_lo(-h, h, hi)
    s = csum + hi
    frac2 += (csum - s) + hi
    csum = s
    frac1 += lo
    v = csum - 1.0 + (frac1 + frac2)
    h += v / (2.0 * h)
    return h / scale
