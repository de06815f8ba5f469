"""Versions of installed distributions and the platform's name, for run.json, sweep summaries
and cache keys, read without the start-up cost of ``importlib.metadata`` (a run's
start within about 1 s): parsing nine METADATA files took ~20 ms, ``platform.platform()`` ~15 ms (it
runs ``uname -p`` in a subprocess for the processor field)."""
from __future__ import annotations

import os
import platform
import re
import sys


def installed_versions(names) -> dict[str, str]:
    """{name: version, or "not installed"} for the distributions ``names``, as
    ``importlib.metadata.version`` gives them: the first ``NAME-VERSION.dist-info`` directory
    on sys.path (its name is the wheel standard's), else (an ``.egg-info`` comes first, or
    nothing was found) the metadata itself."""
    found = _dist_info_versions(names)
    out = {}
    for dist in names:
        if found.get(dist) is None:
            from importlib.metadata import PackageNotFoundError, version
            try:
                found[dist] = version(dist)
            except PackageNotFoundError:
                found[dist] = "not installed"
        out[dist] = found[dist]
    return out


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "_", name).lower()


def _dist_info_versions(names) -> dict[str, str | None]:
    """{name: version} of those ``names`` whose first metadata directory on sys.path (in path
    order, as importlib.metadata finds them) is ``NAME-VERSION.dist-info``; None for those
    whose first is an ``.egg-info`` (its version is inside)."""
    wanted, found = {_norm(n): n for n in names}, {}
    for entry in sys.path:
        try:
            listing = os.listdir(entry or ".")
        except OSError:
            continue
        for item in listing:
            if item.endswith(".dist-info"):
                stem, egg = item[:-len(".dist-info")], False
            elif item.endswith(".egg-info"):
                stem, egg = item[:-len(".egg-info")], True
            else:
                continue
            name, _, version = stem.partition("-")
            dist = wanted.get(_norm(name))
            if dist is None or dist in found:
                continue
            found[dist] = None if egg or not version or "-" in version else version
    return found


def platform_name() -> str:
    """``platform.platform()``'s text without the processor field (``uname -p``, which Linux
    distributions report as "unknown" or as the machine, in which cases the texts are equal);
    other systems than Linux get ``platform.platform()`` itself."""
    u = os.uname()
    join = getattr(platform, "_platform", None)  # platform.platform()'s joining and cleaning
    if u.sysname != "Linux" or join is None:
        return platform.platform()
    libc, version = platform.libc_ver()  # os.confstr: no scan of the executable
    return join(u.sysname, u.release, u.machine, "with", libc + version)
