"""Package rules: imports (STYLE 7, 12), numpydoc parameters (STYLE 11), doctests."""
from __future__ import annotations

import ast
import doctest
import importlib
import inspect
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "analysis"
SOURCES = sorted(PKG.rglob("*.py"))
MODULES = sorted(".".join(p.relative_to(PKG).with_suffix("").parts) for p in SOURCES
                 if p.stem != "__init__")  # e.g. "metrics.comfort"
FORBIDDEN = {"libsumo", "traci", "sumolib"}


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
    return out


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: p.relative_to(PKG).as_posix())
def test_import_rules(path):
    mods = imported_modules(path)
    tops = {m.split(".")[0] for m in mods}
    assert not tops & FORBIDDEN, f"{path.name} imports the simulator"
    # the simulator never: the record's contract (run_contract: its columns, its directory rules,
    # the sweep's error type) is a package of its own
    assert not {m for m in mods if m.split(".")[0] == "formation_traci"}, (
        f"{path.name} imports formation_traci")
    allowed = {"run_contract.columns", "run_contract.rundir"}
    if path.name == "sweep_report.py":  # the sweep's error type (the metric table and the paired
        # statistics over seeds are the analysis' own: sweep_metrics.py, effects.py)
        allowed |= {"run_contract.errors"}
    assert {m for m in mods if m.split(".")[0] == "run_contract"} <= allowed, (
        f"{path.name} imports run_contract beyond {sorted(allowed)}")
    # the figure modules (analysis/figures/: run, compare, traffic, hand-over and sweep figures
    # and their shared drawing helpers)
    if path.parent.name != "figures":
        assert "matplotlib" not in tops, f"{path.name} imports matplotlib"
    if not (path.parent.name == "report" and path.name.endswith("_report.py")):  # the HTML reports
        assert "html" not in tops and "<html" not in path.read_text().lower()


def test_importing_analysis_pulls_neither_simulator_nor_matplotlib():
    code = ("import sys, analysis, analysis.api, analysis.runs.summary, analysis.metrics.iso2631; "
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
            "{'libsumo', 'traci', 'sumolib', 'matplotlib'}); print(bad)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == "[]"


def public_callables():
    for name in MODULES:
        mod = importlib.import_module(f"analysis.{name}")
        for attr in getattr(mod, "__all__", []):
            obj = getattr(mod, attr)
            if inspect.isfunction(obj):
                yield f"{name}.{attr}", obj
            elif inspect.isclass(obj):
                for mname, meth in vars(obj).items():
                    if inspect.isfunction(meth) and not mname.startswith("_"):
                        yield f"{name}.{attr}.{mname}", meth


@pytest.mark.parametrize("qualname, fn", list(public_callables()), ids=lambda x: x
                         if isinstance(x, str) else "")
def test_public_functions_document_every_parameter(qualname, fn):
    doc = inspect.getdoc(fn) or ""
    params = [p for p in inspect.signature(fn).parameters if p not in ("self", "cls")]
    if params:
        assert "Parameters\n----------" in doc, f"{qualname} has no Parameters section"
        section = doc.split("Parameters\n----------", 1)[1]
        section = re.split(r"\n(Returns|Raises|Notes|Examples|See Also)\n-+", section)[0]
        documented = set(re.findall(r"^(\w+) :", section, flags=re.M))
        assert set(params) <= documented, f"{qualname}: undocumented {set(params) - documented}"
    assert "Returns\n-------" in doc, f"{qualname} has no Returns section"


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    mod = importlib.import_module(f"analysis.{name}")
    res = doctest.testmod(mod, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert res.failed == 0
