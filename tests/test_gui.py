"""sumo-gui (issue 19 item 3): ``run --gui`` under Xvfb, following the formation; a SUMO that
fails to start ends the run with SUMO's own message within 30 s. Needs Xvfb: the README's test command (tests/system_deps.sh) installs it."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from formation_traci.scenario import load_scenario
from formation_traci.runner import run_scenario
from formation_traci.sumo.adapter import GUI_VIEW

ROOT = Path(__file__).resolve().parents[1]
LIGHT = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"
SHORT = {"run.duration": 2.0, "traffic.warmup": 5.0, "sumo.ssm": False}


@pytest.fixture(scope="module")
def display():
    exe = shutil.which("Xvfb")
    assert exe, "Xvfb is needed for the sumo-gui tests: bash tests/system_deps.sh installs it"
    num = 90 + os.getpid() % 100
    proc = subprocess.Popen([exe, f":{num}", "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)
    assert proc.poll() is None, "Xvfb did not start"
    old = os.environ.get("DISPLAY")
    os.environ["DISPLAY"] = f":{num}"
    yield f":{num}"
    if old is None:
        os.environ.pop("DISPLAY", None)
    else:
        os.environ["DISPLAY"] = old
    proc.terminate()
    proc.wait(10)


def test_gui_run_starts_follows_a_member_and_closes(display, tmp_path):
    out = tmp_path / "gui"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    tracked = []
    sc = load_scenario(LIGHT, **SHORT, **{"sumo.backend": "traci", "sumo.gui": True})

    def hook(k, t, adapter):
        if k in (2, 20):
            tracked.append((adapter.api.gui.getTrackedVehicle(GUI_VIEW), adapter.api.gui.getZoom(GUI_VIEW)))

    res = run_scenario(sc, out, scenario_path=LIGHT, progress=False, step_hook=hook)
    assert res.status == "completed", res.reason
    assert [v for v, _ in tracked] == ["centre", "centre"]  # the middle member, all along
    assert all(z > 200 for _, z in tracked)  # zoomed in on the formation, not the 6 km road
    meta = json.loads((out / "run.json").read_text())
    assert "--start" in meta["sumo"]["args"] and "--quit-on-end" in meta["sumo"]["args"]
    # the CLI flag: sumo-gui opens, runs by itself and closes at the end (no hang)
    short = tmp_path / "light_short.toml"
    text = LIGHT.read_text().replace("warmup = 200.0", "warmup = 5.0")
    short.write_text(text)
    t0 = time.monotonic()
    cli = subprocess.run([sys.executable, "-m", "formation_traci.cli", "run", str(short), "--out",
                          str(tmp_path / "cli"), "--duration", "1", "--no-progress", "--gui"],
                         env=env, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert cli.returncode == 0, cli.stderr
    cli_meta = json.loads((tmp_path / "cli" / "run.json").read_text())
    assert cli_meta["scenario"]["sumo"]["gui"] is True
    assert "--start" in cli_meta["sumo"]["args"] and "--quit-on-end" in cli_meta["sumo"]["args"]
    assert time.monotonic() - t0 < 120


@pytest.mark.parametrize("gui", [True, False], ids=["sumo-gui", "sumo"])
def test_sumo_that_fails_to_start_ends_the_run_within_30_s(display, tmp_path, gui):
    sc = load_scenario(LIGHT, **SHORT, **{"sumo.backend": "traci", "sumo.gui": gui,
                                          # passes our option check (a known option, an integer); SUMO
                                          # refuses it, beyond its 32-bit range
                                          "sumo.options": ["--aggregate-warnings", "99999999999999"]})
    t0 = time.monotonic()
    res = run_scenario(sc, tmp_path / "run", scenario_path=LIGHT, progress=False)
    assert time.monotonic() - t0 < 30
    assert res.status == "failed"
    assert "SUMO did not start" in res.reason and (gui or "99999999999999" in res.reason)
    # SUMO's words: sumo prints the refused value on stderr; sumo-gui shows it in its own
    # message window (stderr has only font warnings), so only the failure is checked there
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    assert meta["status"] == "failed" and meta["reason"] == res.reason
