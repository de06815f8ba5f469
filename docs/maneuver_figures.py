"""Regenerate the maneuver figures of docs/maneuvers.md from real runs of the bundled
scenarios (scenarios/maneuvers/): one figure per maneuver, drawn by the analysis.

    python docs/maneuver_figures.py            # all figures into docs/img/
    python docs/maneuver_figures.py join leave # only these

Each scenario runs at full length into a temporary directory (SUMO through libsumo, about
a minute in all); the run-level figures come from ``formation-traci analyze``
(analysis/api.py ``analyze_run``), the hand-over figures from analysis/figures/handover_figures.py.
"""
from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"

FIGURES = {  # scenario -> (figure, file in docs/img); figure: an analyze figure or handover:<member>
    "lanedrop_reshape": ("paths", "maneuver_reshape_paths.png"),
    "lane_change_blocked": ("comfort", "maneuver_lane_change_comfort.png"),
    "leave": ("handover:right", "maneuver_leave_handover.png"),
    "exit_leave": ("handover:exiting", "maneuver_exit_leave_handover.png"),
    "join": ("handover:newcomer", "maneuver_join.png"),
    "mixed_truck": ("errors", "maneuver_mixed_truck_errors.png"),
}


def draw(name: str, work: Path) -> Path:
    """Run scenario ``name`` and write its figure into docs/img; returns the file."""
    from analysis.api import analyze_run
    from analysis.figures.handover_figures import handover_figure
    from formation_traci.scenario import load_scenario
    from formation_traci.runner import run_scenario

    path = ROOT / "scenarios" / "maneuvers" / f"{name}.toml"
    out = work / name
    res = run_scenario(load_scenario(path), out, scenario_path=path, progress=False, force=True)
    if res.status != "completed":
        raise RuntimeError(f"{name}: {res.reason}")
    figure, target = FIGURES[name]
    if figure.startswith("handover:"):
        return handover_figure(out, figure.split(":", 1)[1], IMG / target)
    analyze_run(out, figures=True)
    return Path(shutil.copyfile(out / "figures" / f"{figure}.png", IMG / target))


def main(argv: list[str]) -> int:
    names = argv or list(FIGURES)
    unknown = sorted(set(names) - set(FIGURES))
    if unknown:
        print(f"unknown: {unknown}; known: {sorted(FIGURES)}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            print(draw(name, Path(tmp)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
