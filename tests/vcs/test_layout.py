"""Layout of the vcs package: the import graph (static, with ``ast``) has no cycle, and the atlas
statistics never reach plotting.

Every import statement counts, at module level and inside functions (lazy imports), including
``if TYPE_CHECKING:`` blocks. Self-contained: needs only the source tree, imports nothing of vcs.
"""

from __future__ import annotations

import ast
from collections import deque
from collections.abc import Callable
from pathlib import Path

VCS_DIR = Path(__file__).resolve().parents[2] / "vcs"

# the atlas computation (statistics) modules: pure numpy/scipy, never plotting
ATLAS_STATISTICS = ("vcs.atlas.procrustes", "vcs.atlas.pca", "vcs.atlas.regression", "vcs.atlas.cohort")
PLOTTING_PACKAGES = ("matplotlib", "pyvista")
PLOTTING_MODULES = ("vcs.atlas.plots",)
# (vcs module, third-party package) pairs the statistics may reach: the mesh readers of vcs.io and
# the VTP writers of vcs.mesh use pyvista (imported inside those functions), and both are imported
# by vcs.vessel / vcs.model, whose VesselModel the statistics build. Not plotting.
TOLERATED = {("vcs.io", "pyvista"), ("vcs.mesh", "pyvista")}


def vcs_modules(root: Path = VCS_DIR) -> dict[str, Path]:
    """The modules of a package directory.

    Parameters
    ----------
    root : Path
        Package directory (default: the vcs package next to tests/).

    Returns
    -------
    dict
        Dotted module name -> file, for every .py file under ``root`` (``pkg/__init__.py`` is
        ``pkg``, ``pkg/a/b.py`` is ``pkg.a.b``).
    """
    modules = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        modules[".".join(parts)] = path
    return modules


def _is_package(path: Path) -> bool:
    return path.name == "__init__.py"


def _statements(path: Path) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement of a file, at any depth (functions, classes, if/try blocks)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    return [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))]


def _imported_names(module: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Absolute dotted names a file imports: ``import a.b`` -> a.b; ``from a.b import c`` -> a.b.c
    when that is a module of ``modules``, else a.b; relative imports resolved against ``module``."""
    names: set[str] = set()
    for node in _statements(path):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
            continue
        base = node.module or ""
        if node.level:
            package = module.split(".") if _is_package(path) else module.split(".")[:-1]
            package = package[: len(package) - (node.level - 1)]
            base = ".".join(package + ([node.module] if node.module else []))
        for alias in node.names:
            sub = f"{base}.{alias.name}"
            names.add(sub if sub in modules else base)
    return names


def import_graph(root: Path = VCS_DIR) -> dict[str, set[str]]:
    """The static import graph of a package, every import statement at any depth.

    ``import a.b`` is an edge to a.b; ``from a.b import c`` to a.b.c when that is a module
    (file or package), else to a.b; relative imports are resolved. Only edges to modules of the
    package are kept.

    Parameters
    ----------
    root : Path
        Package directory (default: the vcs package next to tests/).

    Returns
    -------
    dict
        Module -> set of the package's modules it imports. Every .py file under ``root`` is a
        key; an import of a name inside the package that is no module file (a stale import) is
        kept as an edge to that name.
    """
    modules = vcs_modules(root)
    top = root.name
    return {
        m: {n for n in _imported_names(m, p, modules) if n == top or n.startswith(top + ".")}
        for m, p in modules.items()
    }


def external_imports(root: Path = VCS_DIR) -> dict[str, set[str]]:
    """What each module of a package imports from outside it (standard library included).

    Parameters
    ----------
    root : Path
        Package directory (default: the vcs package next to tests/).

    Returns
    -------
    dict
        Module -> top-level names of the outside packages it imports, at any depth.
    """
    modules = vcs_modules(root)
    top = root.name
    return {
        m: {n.split(".")[0] for n in _imported_names(m, p, modules) if n.split(".")[0] != top}
        for m, p in modules.items()
    }


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import cycles of a graph, one per strongly connected component (Tarjan's algorithm).

    Parameters
    ----------
    graph : dict
        Module -> set of imported modules (:func:`import_graph`).

    Returns
    -------
    list of list of str
        For every component with more than one module (or a module importing itself) a
        shortest cycle ``[a, b, ..., a]`` through its alphabetically first module; empty when
        the graph is acyclic.
    """
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    sccs: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            scc = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                scc.add(w)
                if w == v:
                    break
            if len(scc) > 1 or v in graph.get(v, ()):
                sccs.append(scc)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    out = []
    for scc in sccs:
        start = min(scc)

        def closes_cycle(n: str, start: str = start) -> bool:
            return start in graph.get(n, ())

        path = _path(graph, start, closes_cycle, within=scc)
        assert path is not None  # a strongly connected component has a cycle through each member
        out.append(path + [start])
    return out


def _path(
    graph: dict[str, set[str]], start: str, goal: Callable[[str], bool], within: set[str] | None = None
) -> list[str] | None:
    """Shortest import chain start -> ... -> n with ``goal(n)`` (breadth first), or None."""
    prev: dict[str, str | None] = {start: None}
    queue = deque([start])
    while queue:
        n = queue.popleft()
        if goal(n):
            chain = [n]
            while (p := prev[chain[-1]]) is not None:
                chain.append(p)
            return chain[::-1]
        for w in sorted(graph.get(n, ())):
            if w not in prev and (within is None or w in within):
                prev[w] = n
                queue.append(w)
    return None


def test_import_graph_sees_lazy_and_relative_imports(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from pkg.a import f\n")
    (pkg / "a.py").write_text("def f():\n    from pkg.sub import b\n    import numpy\n")
    (pkg / "sub" / "__init__.py").write_text("from . import b\nfrom .. import a\n")
    (pkg / "sub" / "b.py").write_text("from ..a import f\nif False:\n    from . import c\n")
    g = import_graph(pkg)
    assert g == {
        "pkg": {"pkg.a"},
        "pkg.a": {"pkg.sub.b"},
        "pkg.sub": {"pkg.sub.b", "pkg.a"},
        "pkg.sub.b": {"pkg.a", "pkg.sub"},
    }
    assert external_imports(pkg)["pkg.a"] == {"numpy"}
    assert cycles(g) == [["pkg.a", "pkg.sub.b", "pkg.a"]]


def test_vcs_import_graph_is_acyclic():
    found = cycles(import_graph())
    assert not found, "import cycles in vcs: " + "; ".join(" -> ".join(c) for c in found)


def test_every_vcs_import_names_a_module():
    modules = vcs_modules()
    stale = sorted(f"{m} imports {n}" for m, targets in import_graph().items() for n in targets if n not in modules)
    assert not stale, "imports of vcs modules that do not exist: " + "; ".join(stale)


def test_atlas_statistics_never_reach_plotting():
    graph = import_graph()
    external = external_imports()
    assert set(ATLAS_STATISTICS) <= set(graph), "update ATLAS_STATISTICS to the statistics modules of vcs.atlas"
    problems = []
    for start in ATLAS_STATISTICS:
        for bad in PLOTTING_MODULES:
            chain = _path(graph, start, lambda n, bad=bad: n == bad)
            if chain:
                problems.append(" -> ".join(chain))
        for pkg in PLOTTING_PACKAGES:
            chain = _path(graph, start, lambda n, pkg=pkg: pkg in external.get(n, ()) and (n, pkg) not in TOLERATED)
            if chain:
                problems.append(" -> ".join(chain + [pkg]))
    assert not problems, "atlas statistics import plotting: " + "; ".join(problems)


def test_subpackages_import_their_modules_not_themselves():
    """Inside every subpackage (vcs.atlas, vcs.cfd, vcs.cli, vcs.phantoms), imports name full module
    paths (vcs.atlas.pca), never the package (whose __init__ imports everything), and the command
    modules of vcs.cli import vcs.cli._args and the library only, never the parser (vcs.cli.main)
    or each other."""
    graph = import_graph()
    packages = sorted(m for m, path in vcs_modules().items() if _is_package(path) and m != "vcs")
    assert {"vcs.atlas", "vcs.cfd", "vcs.cli", "vcs.phantoms"} <= set(packages)
    bad = []
    for package in packages:
        for m in sorted(graph):
            if m.startswith(package + ".") and package in graph[m]:
                bad.append(f"{m} imports {package}")
    commands = [m for m in graph if m.startswith("vcs.cli.") and m not in ("vcs.cli.main", "vcs.cli.__main__")]
    for m in sorted(commands):
        for n in sorted(graph[m]):
            if n.startswith("vcs.cli") and n != "vcs.cli._args":
                bad.append(f"{m} imports {n}")
    assert not bad, "; ".join(bad)


def test_dependency_direction():
    """workflow/ -> vcs/ -> numpy/scipy: vcs never imports snakemake or workflow code; jinja2 (the
    OpenFOAM templates) only inside vcs.cfd; no module outside vcs.cfd imports vcs.cfd except the
    top layers that use everything: the CLI and vcs.qc (a patient's QC sheet: its fit and its CFD)."""
    external = external_imports()
    bad = [
        f"{m} imports {pkg}"
        for m, pkgs in external.items()
        for pkg in pkgs
        if pkg in ("snakemake", "workflow", "vcsflow") or (pkg == "jinja2" and not m.startswith("vcs.cfd"))
    ]
    graph = import_graph()
    bad += [
        f"{m} imports {n}"
        for m, targets in graph.items()
        for n in targets
        if n.startswith("vcs.cfd") and not m.startswith(("vcs.cfd", "vcs.cli", "vcs.qc"))
    ]
    assert not bad, "; ".join(bad)


def test_workflow_holds_snakemake_files_only():
    """workflow/: rules, schemas, envs and thin scripts; Python only in workflow/scripts/."""
    workflow = VCS_DIR.parent / "workflow"
    stray = sorted(
        str(p.relative_to(workflow))
        for p in workflow.rglob("*.py")
        if p.parent != workflow / "scripts" and "__pycache__" not in p.parts
    )
    assert not stray, f"Python outside workflow/scripts/: {stray}"


def test_every_package_is_in_the_wheel_list():
    """pyproject's explicit package list names every package under vcs/ (a missing one would be
    left out of a non-editable install)."""
    import tomllib

    pyproject = tomllib.loads((VCS_DIR.parent / "pyproject.toml").read_text())
    listed = set(pyproject["tool"]["setuptools"]["packages"])
    packages = {m for m, path in vcs_modules().items() if _is_package(path)}
    assert listed == packages, f"pyproject packages {sorted(listed)} vs vcs/ packages {sorted(packages)}"
