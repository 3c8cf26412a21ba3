"""The import graph's rules: the layer contracts in pyproject.toml, and no cycles anywhere."""

from __future__ import annotations

import subprocess
import sys

import grimp

from tests.conftest import ROOT


def test_the_layer_contracts_hold():
    """``lint-imports`` (import-linter) with the contracts of pyproject.toml: the core imports nothing above it
    (rehab, sweep, workspace, …) and no plugin; every layer imports only downwards."""
    code = "import sys; from importlinter.cli import lint_imports; sys.exit(lint_imports(no_cache=True))"
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "0 broken" in done.stdout


def _cycles(graph) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph.modules):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.find_modules_directly_imported_by(root))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph.find_modules_directly_imported_by(w)))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        found.append(sorted(comp))
    return found


def test_no_import_cycles_anywhere():
    """Not between packages, nor between two modules, counting imports made only for type checking."""
    graph = grimp.build_graph("rehabkit", "rehabkit_plugins", cache_dir=None)
    assert _cycles(graph) == []


class _Folders:
    """The import graph between the core's folders (its stages: kinds, plugins, scenario, safety, setup, run,
    results, log): an edge where any module of one imports any module of the other."""

    def __init__(self, graph):
        def stage(module: str) -> str | None:
            parts = module.split(".")
            return ".".join(parts[:3]) if len(parts) > 3 and parts[1] == "core" else None

        self.edges: dict[str, set[str]] = {}
        for m in graph.modules:
            if (a := stage(m)) is None:
                continue
            self.edges.setdefault(a, set())
            for n in graph.find_modules_directly_imported_by(m):
                if (b := stage(n)) is not None and b != a:
                    self.edges[a].add(b)
                    self.edges.setdefault(b, set())
        self.modules = set(self.edges)

    def find_modules_directly_imported_by(self, folder: str) -> set[str]:
        return self.edges[folder]


def test_the_cores_stages_import_in_one_direction():
    """No cycle between the core's folders either (setup and safety, scenario and safety, plugins and results each
    imported the other: a shared type moved below both)."""
    graph = grimp.build_graph("rehabkit", cache_dir=None)
    assert _cycles(_Folders(graph)) == []


def test_the_cycle_finder_finds_a_cycle():
    class Graph:
        modules = {"a", "b", "c", "d"}
        edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}

        def find_modules_directly_imported_by(self, m):
            return self.edges[m]

    assert _cycles(Graph()) == [["a", "b", "c"]]


def test_each_folder_of_the_package_is_one_stage_of_a_dozen_modules_at_most():
    """The core grouped by stage, every folder small enough to take in at once (``__init__`` not counted)."""
    package = ROOT / "rehabkit"
    sizes = {str(d.relative_to(ROOT)): len([p for p in d.glob("*.py") if not p.name.startswith("__")])
             for d in [package, *package.rglob("*")] if d.is_dir() and d.name != "__pycache__"}
    assert {d: n for d, n in sizes.items() if n > 12} == {}
    stages = {"kinds", "plugins", "scenario", "setup", "run", "safety", "results", "log"}
    core = package / "core"
    assert stages <= {d.name for d in core.iterdir() if d.is_dir()}
    assert sorted(p.name for p in core.glob("*.py")) == ["__init__.py", "io.py", "version.py"]


def test_every_package_is_in_the_distribution():
    """A package missing from pyproject's list works in an editable install and is gone from a wheel."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "rehabkit").rglob("__init__.py")}
    found |= {".".join(("rehabkit_plugins", *p.parent.relative_to(ROOT / "plugins").parts))
              for p in (ROOT / "plugins").rglob("__init__.py")}
    assert found - listed == set()


def test_no_secret_is_tracked():
    """No file git tracks is a link key (by name or by its header): one was committed once (keys/arm4.key)."""
    files = subprocess.run(["git", "ls-files", "-z"], capture_output=True, cwd=ROOT, check=True).stdout.split(b"\0")
    keys = [f for f in (f.decode() for f in files if f) if f.endswith(".key") or f.startswith("keys/") or
            (ROOT / f).is_file() and (ROOT / f).read_bytes()[:40].startswith(b"# rehabkit link key")]
    assert keys == []
    for path in ("keys/hit-1.key", "robots/lab/arm.key"):  # (the README's `keys new ... --out keys/hit-1.key`)
        assert subprocess.run(["git", "check-ignore", "-q", path], cwd=ROOT).returncode == 0, path


def test_the_public_api_imports_no_simulator_robotics_library_or_viewer():
    """A third party's plugin module imports rehabkit.plugin: it must not pull in MuJoCo (it did, through the DH
    description's MJCF builder: 0.48 s), Pinocchio, Rerun or the planners' libraries."""
    heavy = ("mujoco", "pinocchio", "rerun", "pink", "ompl", "cv2", "ray", "pyarrow", "scipy")
    code = f"import sys, rehabkit.plugin; print(','.join(m for m in {heavy!r} if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert done.stdout.strip() == ""


def test_built_in_plugins_import_only_the_public_api():
    """A built-in plugin imports from rehabkit only what a third party may: ``rehabkit.plugin`` and the public helper
    modules (``rehabkit.plugin.PUBLIC_MODULES``), never an internal module, a backend or a layer; and every name
    each public module lists in ``__all__`` exists."""
    import ast
    import importlib.util
    from pathlib import Path

    from rehabkit.plugin import PUBLIC_MODULES

    forbidden = ("rehabkit.core", "rehabkit.sim", "rehabkit.hardware", "rehabkit.canopen", "rehabkit.rehab",
                 "rehabkit.ros", "rehabkit.sweep", "rehabkit.gym", "rehabkit.learning", "rehabkit.safety_report",
                 "rehabkit.cli", "rehabkit.api", "rehabkit.testing")
    assert not [m for m in PUBLIC_MODULES if m.startswith(forbidden)]
    bad = []
    for path in sorted((ROOT / "plugins").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            bad += [f"{path.relative_to(ROOT)}:{node.lineno}: {m}" for m in names
                    if (m == "rehabkit" or m.startswith("rehabkit.")) and m not in PUBLIC_MODULES]
    assert bad == []
    # each name resolved where the module says it comes from (a helper module loads a name's module on first use:
    # read, not imported, to keep this cheap — importing them all pulls in MuJoCo, Pinocchio, SciPy, OMPL)
    defined: dict[str, set[str]] = {}

    def top_level(module: str) -> set[str]:
        if module not in defined:
            tree = ast.parse(Path(importlib.util.find_spec(module).origin).read_text())
            names = set()
            for node in tree.body:
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    names.add(node.name)
                elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                    for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                        names |= {n.id for n in ast.walk(target) if isinstance(n, ast.Name)}
                elif isinstance(node, (ast.Import, ast.ImportFrom)):
                    names |= {(a.asname or a.name).split(".")[0] for a in node.names}
            defined[module] = names
        return defined[module]

    for name in PUBLIC_MODULES:
        module = importlib.import_module(name)
        assert module.__doc__ and module.__all__, name
        sources = {attr: where for where, attrs in getattr(module, "_FROM", {}).items() for attr in attrs}
        missing = [attr for attr in module.__all__ if attr not in vars(module) and
                   (attr not in sources or attr not in top_level(sources[attr]))]
        assert missing == [], name
