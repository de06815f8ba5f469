"""Every bundled scenario against its trajectories recorded before the step was restructured
(issue 14): tests/golden/*.npz, written by tests/golden/make_golden.py.

Free space (scenarios/thesis, bundled durations): positions within 1e-9 m. The SUMO scenarios
(scenarios/highway, shortened to make_golden.HIGHWAY_OVERRIDES) are compared inside
tests/test_sumo_runs.py's run of each bundled scenario (one SUMO run serves both tests).
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("make_golden", HERE / "golden" / "make_golden.py")
golden = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(golden)

FREE_SPACE_TOL_M = 1e-9
SUMO_TOL_M = 1e-6
VELOCITY_TOL = {"free": 1e-9, "sumo": 1e-6}  # [m/s]
HEADING_TOL = {"free": 1e-9, "sumo": 1e-6}  # [rad]


def compare(kind: str, stem: str, df, tol_m: float) -> None:
    """df (trajectories of the run) against the stored rows of ``stem``: same rows in the
    same order, x and y within tol_m, heading and v within the set's tolerances."""
    ids, ref = golden.load_set(kind)[stem]
    got = df[["vehicle_id", *golden.COLUMNS]].sort_values(["t", "vehicle_id"], kind="stable")
    assert len(got) == len(ref), f"{stem}: {len(got)} rows, golden {len(ref)}"
    assert (got.vehicle_id.astype(str).to_numpy() == ids).all(), f"{stem}: rows differ"
    vals = got[list(golden.COLUMNS)].to_numpy(np.float64)
    key = "free" if kind == "thesis" else "sumo"
    np.testing.assert_array_equal(vals[:, 0], ref[:, 0], err_msg=f"{stem}: times differ")
    for j, name in enumerate(golden.COLUMNS[1:], start=1):
        tol = {"x": tol_m, "y": tol_m, "heading": HEADING_TOL[key], "v": VELOCITY_TOL[key]}[name]
        err = np.nanmax(np.abs(vals[:, j] - ref[:, j])) if len(ref) else 0.0
        assert np.array_equal(np.isnan(vals[:, j]), np.isnan(ref[:, j])), f"{stem}: NaN of {name}"
        assert err <= tol, f"{stem}: {name} differs from the golden run by {err:.3g} (> {tol:g})"


@pytest.mark.jit_off
@pytest.mark.parametrize("path", golden.SETS["thesis"], ids=lambda p: p.stem)
def test_thesis_scenario_matches_its_golden_trajectories(tmp_path, path):
    """Free space, bundled duration: every member and the virtual car within 1e-9 m."""
    df = golden.trajectory(path, "thesis", tmp_path / "run")
    compare("thesis", path.stem, df, FREE_SPACE_TOL_M)


def test_golden_sets_cover_every_bundled_scenario():
    """A scenario added to scenarios/ without a golden trajectory fails here; only the scenarios
    named in make_golden.NOT_GOLDEN (with the reason) are left out, and they exist."""
    for kind, paths in golden.SETS.items():
        assert sorted(golden.load_set(kind)) == sorted(p.stem for p in paths), kind
    bundled = {p.stem for p in (golden.ROOT / "scenarios" / "highway").glob("*.toml")}
    assert set(golden.NOT_GOLDEN) <= bundled
    assert bundled - set(golden.NOT_GOLDEN) == {p.stem for p in golden.SETS["highway"]}
