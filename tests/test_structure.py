"""Layout rules (GUIDE, issue 14): no import circle in formation_traci, analysis or
run_contract, no module over 400 lines, no function over 80 lines, exactly one module imports
libsumo/traci, no two folders (the packages among them) import each other, no module reads
another object's private attribute.

``DEBT`` names the modules and functions that were over the limits when the rule came in and
have not been split yet; the test fails for any other violation and for a listed one that
is fixed (so the list only shrinks); ``FOLDER_DEBT`` and ``PRIVATE_READERS`` likewise. The test walks the source with ``ast`` (imports inside
functions count too), like /work/shared/tools/structure_check.py.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("formation_traci", "analysis", "run_contract")
MAX_MODULE_LINES = 400
MAX_FUNCTION_LINES = 80
DEBT: set[str] = set()
FOLDER_DEBT: set[tuple[str, str]] = set()


def modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for p in sorted((ROOT / pkg).rglob("*.py")):
            rel = p.relative_to(ROOT).with_suffix("")
            out[".".join(rel.parts).removesuffix(".__init__")] = p
    return out


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Modules of the two packages that ``name`` imports (relative imports resolved)."""
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    deps = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            deps.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = pkg.split(".")
                base = ".".join(parts[:len(parts) - (node.level - 1)] + ([base] if base else []))
            deps.add(base)
            deps.update(f"{base}.{a.name}" for a in node.names)
    return {d for d in deps if d in known and d != name}


def test_no_import_circles():
    mods = modules()
    inits = {m for m, p in mods.items() if p.name == "__init__.py"}
    graph = {m: imports(m, p, set(mods)) - inits for m, p in mods.items() if m not in inits}
    state: dict[str, int] = {}
    circles = []

    def visit(u, stack):
        state[u] = 1
        stack.append(u)
        for v in sorted(graph.get(u, ())):
            if state.get(v) == 1:
                circles.append(" -> ".join(stack[stack.index(v):] + [v]))
            elif not state.get(v):
                visit(v, stack)
        stack.pop()
        state[u] = 2

    for m in sorted(graph):
        if not state.get(m):
            visit(m, [])
    assert not circles, circles


def folder(module: str) -> str:
    """The folder a module is in: formation_traci.<sub> or analysis.<sub> (load, metrics, runs,
    figures, report); the package itself for the modules at its top (formation_traci's cli,
    runner, kernels, states, versions, interrupt, ...; analysis' api; run_contract's modules)."""
    parts = module.split(".")
    if len(parts) >= 2 and (ROOT / parts[0] / parts[1]).is_dir():
        return ".".join(parts[:2])
    return parts[0]


def folder_edges() -> dict[str, set[str]]:
    """Folder -> the other folders its modules import. A package is a folder too: an import
    across packages (analysis.load -> formation_traci.record) is also an edge between the two
    packages (analysis -> formation_traci)."""
    mods = modules()
    edges: dict[str, set[str]] = {}
    for m, p in mods.items():
        for d in imports(m, p, set(mods)):
            for src, dst in ((folder(m), folder(d)), (m.split(".")[0], d.split(".")[0])):
                if dst != src:
                    edges.setdefault(src, set()).add(dst)
    return edges


def mutual_pairs(edges: dict[str, set[str]]) -> set[tuple[str, str]]:
    """The pairs of folders that import each other."""
    return {tuple(sorted((a, b))) for a, bs in edges.items() for b in bs if a in edges.get(b, ())}


def test_the_analysis_metrics_import_no_other_part_of_the_analysis():
    """analysis/metrics/ holds the definitions: pure functions that read no file, so none of
    its modules imports the loading, the per-run drivers, the figures or the report."""
    assert folder_edges().get("analysis.metrics", set()) <= {"run_contract"}


def test_no_two_folders_import_each_other():
    """Folders import one way: road never imports control and control road, comm neither sim
    nor the scenario, analysis not sweep and sweep analysis (issue 26); within the analysis
    load -> metrics, runs -> load and metrics, figures -> runs, report -> figures and runs.
    The packages too: formation_traci -> analysis (the command line runs the analysis), both
    -> run_contract, never back. ``FOLDER_DEBT`` names the pairs with formation_traci's
    top-level modules that are not untangled yet; the list only shrinks."""
    pairs = mutual_pairs(folder_edges())
    assert not pairs - FOLDER_DEBT, f"folders importing each other: {sorted(pairs - FOLDER_DEBT)}"
    assert not FOLDER_DEBT - pairs, f"untangled, remove from FOLDER_DEBT: {sorted(FOLDER_DEBT - pairs)}"


def test_the_run_contract_is_below_both_packages():
    """The analysis imports nothing of formation_traci; run_contract (the recorded run's
    contract) imports neither of them."""
    edges = folder_edges()
    assert "formation_traci" not in edges.get("analysis", set())
    assert not edges.get("run_contract", set()) & {"formation_traci", "analysis"}
    assert "run_contract" in edges["analysis"] and "run_contract" in edges["formation_traci"]


def test_the_checker_finds_two_packages_importing_each_other(tmp_path, monkeypatch):
    """Two packages import each other even when no two of their folders do: the sweep imports
    the analysis' top and the analysis' loading the record's columns."""
    for pkg in ("formation_traci", "formation_traci/sweep", "formation_traci/record", "analysis",
                "analysis/load"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "formation_traci" / "sweep" / "run.py").write_text("def f():\n    from analysis.api import g\n")
    (tmp_path / "formation_traci" / "record" / "columns.py").write_text("VC = 'vc'\n")
    (tmp_path / "analysis" / "api.py").write_text("def g():\n    pass\n")
    (tmp_path / "analysis" / "load" / "x.py").write_text("from formation_traci.record.columns import VC\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", tmp_path)
    monkeypatch.setattr(__import__(__name__), "PACKAGES", ("formation_traci", "analysis"))
    assert mutual_pairs(folder_edges()) == {("analysis", "formation_traci")}


def test_the_generic_loop_is_apart_from_sumo():
    """sim/ (the loop, World, fleet, recorder) imports nothing of sumo/ and sumo/ builds on
    sim/ (issue 26 item 5); only the top-level runner.py chooses between them."""
    edges = folder_edges()
    assert "formation_traci.sumo" not in edges.get("formation_traci.sim", set())
    assert "formation_traci.sim" in edges.get("formation_traci.sumo", set())
    sumo_users = {f for f, dst in edges.items() if "formation_traci.sumo" in dst}
    assert "formation_traci.sim" not in sumo_users, sumo_users


def violations() -> set[str]:
    found = set()
    for p in modules().values():
        rel = p.relative_to(ROOT).as_posix()
        src = p.read_text()
        if len(src.splitlines()) > MAX_MODULE_LINES:
            found.add(f"module {rel}")
        for node in ast.walk(ast.parse(src)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES:
                    found.add(f"function {rel}:{node.name}")
    return found


MAX_PARAMETERS = 12


def wide_functions(package: str = "formation_traci") -> list[str]:
    """Functions of ``package`` with more than MAX_PARAMETERS parameters (positional-only,
    positional and keyword-only but self and cls, *args and **kwargs each count one; as
    structure_check.py)."""
    found = []
    for p in sorted((ROOT / package).rglob("*.py")):
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                k = len([x for x in a.posonlyargs + a.args + a.kwonlyargs if x.arg not in ("self", "cls")])
                k += bool(a.vararg) + bool(a.kwarg)
                if k > MAX_PARAMETERS:
                    found.append(f"{p.relative_to(ROOT).as_posix()}:{node.name} ({k})")
    return found


def test_no_function_of_formation_traci_takes_more_than_12_parameters():
    """Kernels and functions take a few records (named tuples of arrays, structrefs), never
    long positional lists."""
    assert not wide_functions(), wide_functions()


def test_the_parameter_count_sees_a_wide_function(tmp_path, monkeypatch):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "m.py").write_text("def f(a, b, c, d, e, f, g, h, i, j, k, l, m):\n    pass\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", tmp_path)
    assert wide_functions("pkg") == ["pkg/m.py:f (13)"]


def test_module_and_function_sizes():
    found = violations()
    assert not found - DEBT, f"over the limits: {sorted(found - DEBT)}"
    assert not DEBT - found, f"fixed, remove from DEBT: {sorted(DEBT - found)}"


PRIVATE_READERS = {
    "formation_traci/core/kernel_load.py",  # extends numba's cache (the one module that does)
}
"""The modules allowed to read another object's private attribute; the list only shrinks."""


def private_reads() -> dict[str, list[str]]:
    """Module path -> its reads ``obj._name`` (line and name) where ``obj`` is not ``self`` or
    ``cls``: the rule of /work/shared/tools/structure_check.py (dunder names are not private;
    ``getattr(obj, "_name")`` is not seen)."""
    found: dict[str, list[str]] = {}
    for p in modules().values():
        for node in ast.walk(ast.parse(p.read_text())):
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                    and not node.attr.startswith("__")
                    and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))):
                found.setdefault(p.relative_to(ROOT).as_posix(), []).append(f"{node.lineno} .{node.attr}")
    return found


def test_no_module_reads_another_objects_private_attribute():
    """A module uses what another object offers publicly (a property, a method, a public
    attribute for shared state), never its ``_name``; only ``PRIVATE_READERS`` still do."""
    found = private_reads()
    extra = {f: rows for f, rows in found.items() if f not in PRIVATE_READERS}
    assert not extra, f"private attributes of another object: {extra}"
    assert not PRIVATE_READERS - set(found), (
        f"no private read left, remove from PRIVATE_READERS: {sorted(PRIVATE_READERS - set(found))}")


def test_the_private_read_check_sees_a_read(tmp_path, monkeypatch):
    (tmp_path / "formation_traci").mkdir()
    (tmp_path / "formation_traci" / "a.py").write_text(
        "class A:\n    def f(self, other):\n        return self._x, other._y, other.__dict__, cls_._z\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", tmp_path)
    monkeypatch.setattr(__import__(__name__), "PACKAGES", ("formation_traci",))
    assert private_reads() == {"formation_traci/a.py": ["3 ._y", "3 ._z"]}


def test_one_module_imports_libsumo():
    users = set()
    for name, p in modules().items():
        for node in ast.walk(ast.parse(p.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            if any(n.split(".")[0] in ("libsumo", "traci") for n in names):
                users.add(name)
    assert users == {"formation_traci.sumo.adapter"}, users


def test_the_checker_finds_a_circle(tmp_path, monkeypatch):
    """The walk sees a circle made of relative imports inside functions."""
    pkg = tmp_path / "formation_traci"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from . import b\n")
    (pkg / "b.py").write_text("from .a import f\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", tmp_path)
    monkeypatch.setattr(__import__(__name__), "PACKAGES", ("formation_traci",))
    try:
        test_no_import_circles()
    except AssertionError as e:
        assert "formation_traci.a -> formation_traci.b -> formation_traci.a" in str(e)
    else:
        raise AssertionError("the circle a <-> b was not found")


def test_ci_runs_the_readme_test_command_verbatim():
    """Issue 30: the README says its test command is exactly what .ci/run does; the command
    (the bash block after "Run the tests") is a line of .ci/run, and it installs the system
    packages the sumo-gui tests need (tests/system_deps.sh) before the tests."""
    readme = (ROOT / "README.md").read_text()
    block = readme[readme.index("Run the tests"):]
    cmd = block[block.index("```bash\n") + 8:].split("\n", 1)[0]
    assert cmd.startswith("bash tests/system_deps.sh && "), cmd
    assert "python -m pytest -q" in cmd
    assert cmd in (ROOT / ".ci" / "run").read_text().splitlines()


def test_readme_is_short_and_docs_carry_no_development_history():
    """The README speaks to users in at most 150 lines, and neither it, the docs, the code's
    comments nor the schema's descriptions name issues (development history lives in git and
    benchmarks/RESULTS.md)."""
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 150, len(readme.splitlines())
    pattern = re.compile(r"issues? [0-9]+", re.IGNORECASE)
    found = []
    for base in ("README.md", "docs", "formation_traci", "analysis"):
        path = ROOT / base
        files = [path] if path.is_file() else [p for p in path.rglob("*") if p.suffix in (".py", ".md", ".cpp")]
        for f in files:
            for i, line in enumerate(f.read_text(errors="replace").splitlines(), 1):
                if pattern.search(line):
                    found.append(f"{f.relative_to(ROOT)}:{i}")
    assert not found, found
