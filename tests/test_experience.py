"""The first-day experience (issue 19): --version, the compile note, sweep figures' labels."""
from __future__ import annotations

import importlib.metadata

import pandas as pd
from typer.testing import CliRunner

from formation_traci.cli import app
from formation_traci.sweep.figures import metric_figure
from formation_traci.sweep.report import swept_labels


def test_version_flag_prints_the_installed_version():
    res = CliRunner().invoke(app, ["--version"])
    assert res.exit_code == 0
    assert res.output.strip() == f"formation-traci {importlib.metadata.version('formation-traci')}"


def test_needs_compile_is_false_once_the_kernels_are_compiled():
    from formation_traci.sim import fast

    fast.warmup()
    assert fast.needs_compile() is False


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
