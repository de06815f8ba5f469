"""SUMO's SSM device keeps every step of an open encounter, and a formation's members keep
theirs with one another open for the whole run (docs/sumo.md; measured in benchmarks/RESULTS.md,
issue 33's seventh session): a run whose members' encounters would keep more than a GB is warned
about before it starts, on the terminal."""
from pathlib import Path

import numpy as np
import pytest

from formation_traci.sumo.ssm import (SSM_ENCOUNTER_BYTES, SSM_RANGE_M, member_encounter_bytes,
                                      memory_note)
from run_helpers import spawn

ROOT = Path(__file__).resolve().parents[1]

WEDGE = np.array([[0.0, 0.0], [-20.0, 3.2], [-20.0, -3.2], [-40.0, 6.4], [-40.0, -6.4]])
"""Five members in rows 20 m apart: the farthest two (40 m along, 6.4 m across) are 40.5 m
apart, within the device's 50 m, so each member has the four others as foes: 20 ordered pairs."""
COLUMN = np.array([[0.0, 0.0], [-60.0, 0.0], [-120.0, 0.0]])
"""Three members 60 m apart: none within range of another."""


def test_the_members_encounters_are_the_ordered_pairs_within_range_every_step():
    """20 ordered pairs of the wedge for 72,000 steps (3600 s at 0.05 s) at the measured bytes
    per encounter and step; the column adds none, formations are counted apart (two wedges
    at the same place are 40 pairs, not 90), and none with the device off."""
    assert SSM_RANGE_M == 50.0
    assert member_encounter_bytes("members", [WEDGE], 3600.0, 0.05) == (20, SSM_ENCOUNTER_BYTES * 20 * 72_000)
    assert member_encounter_bytes("members", [COLUMN], 3600.0, 0.05) == (0, 0.0)
    assert member_encounter_bytes("all", [WEDGE, WEDGE, COLUMN], 60.0, 0.05)[0] == 40
    assert member_encounter_bytes("off", [WEDGE], 3600.0, 0.05) == (0, 0.0)


def test_the_note_names_the_pairs_and_the_memory_only_past_a_gb():
    """The wedge keeps 0.58 GB in an hour (no note) and 1.15 GB in two (the note, with the
    pairs, the estimate and the way out); the column never."""
    assert memory_note("members", [WEDGE], 3600.0, 0.05) is None
    note = memory_note("members", [WEDGE], 7200.0, 0.05)
    assert note is not None
    assert "20 ordered member pairs within 50 m" in note and "~1.2 GB" in note
    assert 'sumo.ssm = "off"' in note and "docs/sumo.md" in note
    assert memory_note("members", [COLUMN], 100_000.0, 0.05) is None


@pytest.mark.parametrize("duration, warned", [(7200, True), (3000, False)])
def test_the_terminal_warns_before_the_run(tmp_path, duration, warned):
    """The bundled five-member wedge for two hours: the warning is on the terminal before
    anything runs (the run is then refused for its output directory: exit 2, nothing
    created); for 3000 s there is none."""
    out = tmp_path / "a,b"
    proc = spawn("run", ROOT / "scenarios" / "highway" / "straight_wedge5_heavy.toml",
                 "--duration", duration, "--out", out, "--no-progress")
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 2, err
    assert not out.exists()
    lines = [ln for ln in err.splitlines() if ln.startswith("warning: sumo.ssm = 'members'")]
    assert len(lines) == (1 if warned else 0), err
