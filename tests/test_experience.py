"""The first-day experience (issue 19): --version, the compile note, sweep figures' labels."""
from __future__ import annotations

import importlib.metadata
import os
import subprocess
import sys

import pandas as pd
from typer.testing import CliRunner

from analysis.figures.sweep_figures import metric_figure
from analysis.report.sweep_report import swept_labels
from formation_traci.cli import app


def test_version_flag_prints_the_installed_version():
    res = CliRunner().invoke(app, ["--version"])
    assert res.exit_code == 0
    assert res.output.strip() == f"formation-traci {importlib.metadata.version('formation-traci')}"


def test_compiling_is_announced_once_on_a_cold_cache_and_not_on_a_warm_one(tmp_path):
    """kernels.py's one-line notice: printed once when kernels compile (empty numba cache),
    silent when they come from the cache."""
    from formation_traci.core.kernels import _NOTICE

    code = ("from formation_traci.control.schedule import p_law, scheduled_gain\n"
            "p_law(1.0, 0.0, 0.2, 8.0, 1.0); scheduled_gain(0.5, 0.2, 8.0, 1.0)\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("NUMBA_DISABLE_JIT", None)
    cold = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=300)
    warm = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=300)
    assert cold.returncode == 0 and warm.returncode == 0, cold.stderr + warm.stderr
    assert cold.stderr.count(_NOTICE) == 1
    assert _NOTICE not in warm.stderr


def test_sweep_figures_name_the_swept_fields_by_their_labels():
    meta = {"swept": ["traffic.flows.0.veh_per_hour_per_lane", "controller.k"],
            "sweep": {"labels": {"traffic.flows.0.veh_per_hour_per_lane": "vph"}}}
    labels = swept_labels(meta)
    assert labels == {"traffic.flows.0.veh_per_hour_per_lane": "vph", "controller.k": "k"}
    done = pd.DataFrame({"traffic.flows.0.veh_per_hour_per_lane": [800, 800, 1600, 1600],
                         "controller.k": [1.0, 2.0, 1.0, 2.0], "e_rms_m": [0.1, 0.2, 0.3, 0.4]})
    fig = metric_figure(done, meta["swept"], meta["swept"], "e_rms_m", "m", labels=labels)
    ax_vph, ax_k = fig.axes[:2]
    assert ax_vph.get_xlabel() == "vph" and ax_k.get_xlabel() == "k"
    legend = [t.get_text() for t in ax_vph.get_legend().get_texts()]
    assert legend == ["k=1.0", "k=2.0"]
    assert [t.get_text() for t in ax_k.get_legend().get_texts()] == ["vph=800", "vph=1600"]


# --- the report read top-down (item 4) -----------------------------------------------------

import re  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from analysis.load.run_data import describe_issues  # noqa: E402
from analysis.metrics.propagation import propagation  # noqa: E402
from analysis.report.headline import verdicts  # noqa: E402
from formation_traci.scenario import load_scenario  # noqa: E402
from formation_traci.runner import run_scenario  # noqa: E402

THESIS = "scenarios/thesis/dynamic_case4_straight.toml"


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    out = tmp_path_factory.mktemp("rep") / "run"
    sc = load_scenario(THESIS, **{"run.duration": 12.0})
    run_scenario(sc, out, progress=False)
    res = CliRunner().invoke(app, ["analyze", str(out)])
    assert res.exit_code == 0, res.output
    return out, res.output


def test_report_reads_top_down_summary_figures_then_collapsed_tables(analysed):
    out, cli = analysed
    page = (out / "report.html").read_text()
    first_table = page.index("<table")
    assert page.index('id="summary"') < page.index("<img") < first_table
    assert page.rindex("<img") < first_table  # every figure before any table
    # every table sits in a collapsed <details> (open only when data errors are listed)
    assert page.count("<details>") >= 5 and page.count("<table") == page[first_table:].count("<table")
    body = page[page.index("<h2>Tables</h2>"):]
    assert body.count("<details") == body.count("</details>")
    assert "version numpy" not in page[:first_table]
    # the data issues are counted the same way in the CLI and in the report's summary
    line = re.search(r"(\d+ data issue\(s\): [^<;]*)", cli).group(1)
    summary = page[page.index('id="summary"'):page.index("</div>", page.index('id="summary"'))]
    assert line in summary
    assert "comfortable band" in summary and "worst formation error per member" in summary


def test_iso2631_is_there_by_default_from_the_control_rate_table(analysed):
    import json

    out, _ = analysed
    doc = json.loads((out / "metrics.json").read_text())
    assert len(doc["members"]) == 3  # the loop below checks every member, not none
    for m in doc["members"]:
        assert m["aw_lat_mps2"] is not None and m["aw_lon_mps2"] is not None, m["id"]
    assert doc["tables"]["comfort"]["rows"] == 3 * (1200 + 1)  # 3 members, 100 Hz, 12 s
    assert "100 Hz" in doc["run"]["iso2631_note"]


def test_headline_names_a_member_falling_back():
    import pandas as pd

    members = pd.DataFrame({"e_max_m": [0.2, 0.25, 4.0], "duration_s": [10.0] * 3},
                           index=["a", "b", "c"])
    text, ok = [v for v in verdicts(members, {}, []) if "formation error" in v[0]][0]
    assert ok is False and "c is 16.0 x the median" in text and "a 0.2 m" in text
    members["e_max_m"] = [0.2, 0.25, 0.3]
    text, ok = [v for v in verdicts(members, {}, []) if "formation error" in v[0]][0]
    assert ok is True and "fell back" not in text
    assert describe_issues([{"severity": "error"}, {"severity": "info"}]) == \
        "2 data issue(s): 1 error(s), 0 warning(s), 1 note(s)"


def test_propagation_ratios_along_columns_and_rows():
    off = {"f": (10.0, 0.0), "m": (0.0, 0.0), "b": (-10.0, 0.0), "l": (0.0, 3.5), "r": (0.0, -3.5)}
    peak = {"f": 0.1, "m": 0.4, "b": 0.2, "l": 0.1, "r": 0.8}
    rms = {k: v / 2 for k, v in peak.items()}
    df = propagation(off, peak, rms)
    col = df[df.direction == "column"]
    assert list(zip(col.source, col.target)) == [("f", "m"), ("m", "b")]
    np.testing.assert_allclose(col.peak_ratio, [4.0, 0.5])
    assert list(col.grows) == [True, False]
    row = df[df.direction == "row"]  # outwards from r, the most disturbed member of the row
    assert list(zip(row.source, row.target)) == [("r", "m"), ("m", "l")]
    np.testing.assert_allclose(row.peak_ratio, [0.5, 0.25])
