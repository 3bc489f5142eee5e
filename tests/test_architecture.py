"""The repository's shape, checked: what a newcomer relies on when finding their way.

- no import cycle between first-party modules, counting every ``import`` and ``from ...
  import`` anywhere in a module (``ast.walk``): at module level, inside functions and methods
  (a function-level import is a runtime cycle put off until the call, not a way out of one),
  and under ``if TYPE_CHECKING:`` (not a runtime cycle, but a cycle of types is still two
  rooms that cannot be read apart: move the shared types to a module both import);
- no source module over 1,000 lines;
- every service has its settings in ``settings.py`` and a README.
"""

from __future__ import annotations

import ast
from collections import deque
from pathlib import Path
from typing import NamedTuple

import pytest

ROOT = Path(__file__).resolve().parents[1]
SERVICES = sorted(p.parent for p in (ROOT / "services").glob("*/pyproject.toml"))
MAX_MODULE_LINES = 1000


def source_roots(root: Path) -> list[Path]:
    """The folders holding the first-party packages of the repository at ``root``."""
    return [
        root / "shared" / "src",
        root / "cli" / "src",
        root / "eval" / "src",
        *sorted((root / "services").glob("*/src")),
    ]


def _modules(root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name -> file, for every first-party module under ``root``."""
    modules = {}
    for source in source_roots(root):
        for path in source.rglob("*.py"):
            parts = path.relative_to(source).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


class Import(NamedTuple):
    """Where one module imports another: the line and what holds the statement."""

    line: int
    place: str  # "module level", "in function NAME", "under TYPE_CHECKING"

    def __str__(self) -> str:
        return f"line {self.line}, {self.place}"


def _places(tree: ast.Module) -> dict[int, str]:
    """For each import statement (by ``id``): what holds it (:class:`Import`'s ``place``)."""
    places: dict[int, str] = {}

    def visit(node: ast.AST, place: str) -> None:
        for child in ast.iter_child_nodes(node):
            here = place
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                here = f"in function {child.name}" if place == "module level" else place
            elif isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                here = "under TYPE_CHECKING" if place == "module level" else place
            if isinstance(child, ast.Import | ast.ImportFrom):
                places[id(child)] = here
            visit(child, here)

    visit(tree, "module level")
    return places


def _imports(name: str, path: Path, known: set[str]) -> dict[str, list[Import]]:
    """First-party modules that ``name`` imports anywhere in its file, each with where."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    places = _places(tree)
    found: dict[str, list[Import]] = {}
    for statement in ast.walk(tree):
        targets: list[str] = []
        if isinstance(statement, ast.Import):
            targets = [alias.name for alias in statement.names]
        elif isinstance(statement, ast.ImportFrom):
            base = statement.module or ""
            if statement.level:
                parts = package.split(".")[: len(package.split(".")) - statement.level + 1]
                base = ".".join([*parts, base] if base else parts)
            targets = [base, *(f"{base}.{alias.name}" for alias in statement.names)]
        for target in targets:
            if target in known and target != name:
                where = Import(statement.lineno, places[id(statement)])
                found.setdefault(target, []).append(where)
    return found


def import_graph(modules: dict[str, Path]) -> dict[str, dict[str, list[Import]]]:
    """Module -> the first-party modules it imports -> where."""
    return {name: _imports(name, path, set(modules)) for name, path in modules.items()}


def import_cycles(modules: dict[str, Path]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan's algorithm, iterative)."""
    graph = {name: sorted(edges) for name, edges in import_graph(modules).items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    for start in graph:
        if start in index:
            continue
        work = [(start, 0)]
        while work:
            node, child = work.pop()
            if child == 0:
                index[node] = low[node] = len(index)
                stack.append(node)
                on_stack.add(node)
            if child < len(graph[node]):
                work.append((node, child + 1))
                successor = graph[node][child]
                if successor not in index:
                    work.append((successor, 0))
                elif successor in on_stack:
                    low[node] = min(low[node], index[successor])
                continue
            if low[node] == index[node]:
                group = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.append(member)
                    if member == node:
                        break
                if len(group) > 1:
                    cycles.append(sorted(group))
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
    return sorted(cycles)


def _shortest_cycle(
    first: str, group: list[str], graph: dict[str, dict[str, list[Import]]]
) -> list[str]:
    """The shortest path inside ``group`` from ``first`` back to itself."""
    members = set(group)
    came_from: dict[str, str] = {}
    queue = deque([first])
    while queue:
        node = queue.popleft()
        for successor in sorted(graph[node]):
            if successor not in members:
                continue
            if successor == first:
                path = [node]
                while path[-1] != first:
                    path.append(came_from[path[-1]])
                return [first, *reversed(path[:-1]), first]
            if successor not in came_from:
                came_from[successor] = node
                queue.append(successor)
    return [first]


def cycle_report(root: Path = ROOT) -> list[str]:
    """Each import cycle among the first-party modules under ``root``, as text: its modules,
    every import between them (line and where), and one cycle through them."""
    modules = _modules(root)
    graph = import_graph(modules)
    report = []
    for group in import_cycles(modules):
        lines = [f"import cycle among {', '.join(group)}:"]
        for importer in group:
            for imported, places in sorted(graph[importer].items()):
                if imported in group:
                    where = "; ".join(map(str, places))
                    relative = modules[importer].relative_to(root)
                    lines.append(f"  {importer} -> {imported} ({relative}: {where})")
        lines.append("  e.g. " + " -> ".join(_shortest_cycle(group[0], group, graph)))
        report.append("\n".join(lines))
    return report


def _package(root: Path, files: dict[str, str]) -> dict[str, Path]:
    """A package ``pkg`` of ``files`` (module name -> text) in ``root``'s ``shared/src``."""
    folder = root / "shared" / "src" / "pkg"
    folder.mkdir(parents=True)
    (folder / "__init__.py").write_text("")
    for module, text in files.items():
        (folder / f"{module}.py").write_text(text)
    return _modules(root)


def test_the_cycle_finder_finds_a_cycle_of_types(tmp_path: Path) -> None:
    modules = _package(
        tmp_path,
        {
            "a": "from pkg.b import thing\n",
            "b": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg import a\n",
            "c": "from . import a\n",
        },
    )
    assert import_cycles(modules) == [["pkg.a", "pkg.b"]]
    graph = import_graph(modules)
    assert graph["pkg.b"]["pkg.a"] == [Import(3, "under TYPE_CHECKING")]


def test_the_cycle_finder_counts_imports_inside_functions(tmp_path: Path) -> None:
    """A cycle closed by an import inside a function or a method (``wz_eval.fusion``'s
    ``main`` importing ``sites``, which imported ``fusion`` inside its own functions), and a
    relative one inside a function; a one-way function-level import is no cycle."""
    modules = _package(
        tmp_path,
        {
            "a": "def main():\n    from pkg.b import run\n    return run()\n",
            "b": "def run():\n    from pkg.a import helper\n",
            "c": "class C:\n    def go(self):\n        import pkg.d\n",
            "d": "from . import c\n",
            "e": "def f():\n    from .f import g\n",
            "f": "def g():\n    from .e import f\n",
            "g": "def one_way():\n    from pkg.a import main\n",
        },
    )
    assert import_cycles(modules) == [["pkg.a", "pkg.b"], ["pkg.c", "pkg.d"], ["pkg.e", "pkg.f"]]
    graph = import_graph(modules)
    assert graph["pkg.c"]["pkg.d"] == [Import(3, "in function go")]
    report = cycle_report(tmp_path)
    assert report[0] == (
        "import cycle among pkg.a, pkg.b:\n"
        "  pkg.a -> pkg.b (shared/src/pkg/a.py: line 2, in function main)\n"
        "  pkg.b -> pkg.a (shared/src/pkg/b.py: line 2, in function run)\n"
        "  e.g. pkg.a -> pkg.b -> pkg.a"
    )


def test_no_import_cycle_between_first_party_modules() -> None:
    report = cycle_report()
    assert not report, "\n".join(report)


def test_no_source_module_is_over_a_thousand_lines() -> None:
    files = [*_modules().values(), *(ROOT / "benchmarks").glob("*.py")]
    long = {
        str(p.relative_to(ROOT)): n
        for p in files
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert long == {}


@pytest.mark.parametrize("service", SERVICES, ids=lambda p: p.name)
def test_each_service_has_its_settings_module_and_a_readme(service: Path) -> None:
    assert (service / "README.md").is_file()
    packages = [p for p in (service / "src").iterdir() if (p / "__init__.py").is_file()]
    assert len(packages) == 1
    assert (packages[0] / "settings.py").is_file()
