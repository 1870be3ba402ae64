"""The package's imports point down its floors and never run in a circle (issue 31).

Every ``import`` / ``from ... import`` of a spacefit module anywhere in a module's source counts,
those inside functions and under ``if TYPE_CHECKING:`` too. The floors, low to high, are
:data:`FLOORS`; an import may reach its own floor or a lower one, and the modules of one floor may
not import each other in a circle. A function-local import of a spacefit module is allowed only to
load a heavy dependency late, with its reason on that line or the line above.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "spacefit"

# Low to high: each module's floor is that of the longest prefix listed.
FLOORS: tuple[tuple[str, ...], ...] = (
    ("spacefit.errors", "spacefit.units", "spacefit.precision", "spacefit.interrupts", "spacefit.progress",
     "spacefit.versions", "spacefit.locks", "spacefit.output", "spacefit.digests", "spacefit.executors",
     "spacefit.timescales", "spacefit.html_tables", "spacefit.programs"),
    ("spacefit.geometry",),
    ("spacefit.materials",),
    ("spacefit.scene",),
    ("spacefit.display", "spacefit.plotting"),  # in the registry's words: above the scene (a Scene shows itself)
    ("spacefit.sensor", "spacefit.detector", "spacefit.psf", "spacefit.formation"),
    ("spacefit.rendering",),
    ("spacefit.imageio", "spacefit.cases"),
    ("spacefit.fitting",),
    ("spacefit.studies",),
    ("spacefit.render_job", "spacefit.pipeline", "spacefit.cli_parser", "spacefit.cli", "spacefit"),
)


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def floor(module: str) -> int:
    best, level = -1, -1
    for k, names in enumerate(FLOORS):
        for name in names:
            if (module == name or module.startswith(name + ".")) and len(name) > best:
                best, level = len(name), k
    return level


def resolve(name: str) -> str:
    """The spacefit module an imported name lives in (``spacefit.scene.schema.Scene`` -> its module)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name


def imports(module: str) -> list[tuple[str, int, bool]]:
    """(imported spacefit module, line, inside a function) for every import in ``module``'s source."""
    tree = ast.parse(MODULES[module].read_text())
    out = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
            if isinstance(child, ast.ImportFrom) and child.module and child.module.startswith("spacefit"):
                targets = {resolve(f"{child.module}.{a.name}") for a in child.names}
            elif isinstance(child, ast.Import):
                targets = {resolve(a.name) for a in child.names if a.name.startswith("spacefit")}
            else:
                visit(child, inner)
                continue
            out.extend((t, child.lineno, in_function) for t in targets if t not in ("", module, "spacefit"))

    visit(tree, False)
    return out


GRAPH = {m: imports(m) for m in MODULES}


def test_every_module_has_a_floor():
    assert [m for m in MODULES if floor(m) < 0] == []


def test_no_import_runs_up_a_floor():
    upward = [f"{m}:{line} -> {t}" for m, edges in GRAPH.items() for t, line, _ in edges if floor(t) > floor(m)]
    assert upward == []


def test_no_import_cycle():
    edges = {m: {t for t, _, _ in e} for m, e in GRAPH.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def connect(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in edges[v]:
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in edges:
        if v not in index:
            connect(v)
    assert cycles == []


def explained(lines: list[str], line: int) -> bool:
    """Whether the import at ``line`` (from 1) gives its reason: a comment on it, on an import of the
    block of imports it stands in, or on the line above that block."""
    k = line - 1
    while k > 0 and (lines[k - 1].strip().startswith(("from ", "import ")) or not lines[k - 1].strip()):
        k -= 1
    block = lines[k:line]
    return any("#" in text for text in block) or (k > 0 and "#" in lines[k - 1])


def test_a_function_local_import_says_why():
    unexplained = []
    for m, edges in GRAPH.items():
        lines = MODULES[m].read_text().splitlines()
        unexplained += [f"{m}:{line}: {lines[line - 1].strip()}" for _, line, in_function in edges
                        if in_function and not explained(lines, line)]
    assert sorted(set(unexplained)) == []


@pytest.mark.parametrize("planted", ["upward", "cycle"])
def test_the_checks_find_a_planted_fault(planted):
    """The walk itself: an upward import and a circle added to a copy of the graph are found."""
    edges = defaultdict(set, {m: {t for t, _, _ in e} for m, e in GRAPH.items()})
    if planted == "upward":
        edges["spacefit.geometry.wm"].add("spacefit.fitting.loop")
        assert any(floor(t) > floor(m) for m, ts in edges.items() for t in ts)
    else:
        edges["spacefit.scene.sections"].add("spacefit.scene.schema")
        seen, todo = set(), ["spacefit.scene.schema"]
        while todo:
            v = todo.pop()
            for w in edges[v] - seen:
                seen.add(w)
                todo.append(w)
        assert "spacefit.scene.schema" in seen
