"""Versions of installed distributions and the platform's name, for run.json, sweep summaries
and cache keys, read without the start-up cost of ``importlib.metadata`` (issue 18: a run's
start <= 1 s): parsing nine METADATA files took ~20 ms, ``platform.platform()`` ~15 ms (it
scans the Python executable for the C library's version)."""
from __future__ import annotations

import os
import platform
import re
import sys


def installed_versions(names) -> dict[str, str]:
    """{name: version, or "not installed"} for the distributions ``names``, as
    ``importlib.metadata.version`` gives them: the first ``NAME-VERSION.dist-info`` directory
    on sys.path (its name is the wheel standard's), else the metadata (e.g. an egg)."""
    found = _dist_info_versions(names)
    out = {}
    for dist in names:
        if dist not in found:
            from importlib.metadata import PackageNotFoundError, version
            try:
                found[dist] = version(dist)
            except PackageNotFoundError:
                found[dist] = "not installed"
        out[dist] = found[dist]
    return out


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "_", name).lower()


def _dist_info_versions(names) -> dict[str, str]:
    """{name: version} of those ``names`` found as ``NAME-VERSION.dist-info`` directories on
    sys.path (the first in path order, as importlib.metadata finds them)."""
    wanted, found = {_norm(n): n for n in names}, {}
    for entry in sys.path:
        try:
            listing = os.listdir(entry or ".")
        except OSError:
            continue
        for item in listing:
            stem = item[:-len(".dist-info")] if item.endswith(".dist-info") else ""
            if stem.count("-") == 1:
                name, version = stem.split("-")
                dist = wanted.get(_norm(name))
                if dist is not None and dist not in found:
                    found[dist] = version
    return found


def platform_name() -> str:
    """``platform.platform()``'s text; on Linux with glibc built from ``os.uname`` and
    ``os.confstr`` the way it builds it, without its scan of the executable."""
    libc = os.confstr("CS_GNU_LIBC_VERSION") if "CS_GNU_LIBC_VERSION" in getattr(os, "confstr_names", {}) else None
    u = os.uname()
    if u.sysname != "Linux" or not libc or not libc.startswith("glibc "):
        return platform.platform()
    return "-".join(part.replace(" ", "_") for part in (u.sysname, u.release, u.machine, "with",
                                                          libc.replace(" ", "")))
