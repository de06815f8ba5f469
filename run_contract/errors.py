"""The error of a sweep file or sweep directory that cannot be used, raised by the sweep
(formation_traci/sweep) and by the sweep's analysis (analysis/report/sweep_report.py); the
command line turns it into exit 2."""
from __future__ import annotations

from pathlib import Path


class SweepError(ValueError):
    """A sweep file (or sweep directory) that cannot be used; ``problems``: (field, message)."""

    def __init__(self, path: str | Path, problems: list[tuple[str, str]]):
        self.path = str(path)
        self.problems = problems
        lines = [f"{self.path}: {field}: {msg}" for field, msg in problems[:20]]
        if len(problems) > 20:
            lines.append(f"... and {len(problems) - 20} more")
        super().__init__(f"invalid sweep ({len(problems)} problem"
                         f"{'s' if len(problems) != 1 else ''}):\n  " + "\n  ".join(lines))
