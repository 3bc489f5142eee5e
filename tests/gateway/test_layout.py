"""The gateway package's layout: no module imports, at module level, a module that imports it
back (directly or around a loop). A cycle means two rooms that cannot be read, tested or moved
one without the other (as ``app.py`` and ``webhook_routes.py`` once were). Imports under
``if TYPE_CHECKING:`` count: the type checker follows them, and so does a reader."""

from __future__ import annotations

import ast
from pathlib import Path

import wz_gateway

PACKAGE = "wz_gateway"
ROOT = Path(wz_gateway.__file__).resolve().parent


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = [PACKAGE, *path.relative_to(root).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _module_level(tree: ast.Module) -> list[ast.Import | ast.ImportFrom]:
    """The imports of the module's top level and of its ``if``/``try`` blocks (``if
    TYPE_CHECKING:`` too), not those in function bodies (run later, if ever)."""
    found: list[ast.Import | ast.ImportFrom] = []
    pending: list[ast.stmt] = list(tree.body)
    while pending:
        node = pending.pop(0)
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.append(node)
        elif isinstance(node, ast.If):
            pending += [*node.body, *node.orelse]
        elif isinstance(node, ast.Try):
            pending += [*node.body, *node.orelse, *node.finalbody]
            pending += [stmt for handler in node.handlers for stmt in handler.body]
    return found


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Each module of the package -> the modules of the package it imports at module level
    (``from wz_gateway.api.routes import tracks`` counts as importing the module ``tracks``)."""
    modules = {module_name(path, root): path for path in sorted(root.rglob("*.py"))}
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in _module_level(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                base = node.module or ""
                if node.level:  # relative: up from this module's package
                    anchor = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                    base = f"{anchor}.{base}" if base else anchor
                targets = [base, *(f"{base}.{alias.name}" for alias in node.names)]
            graph[name] |= {t for t in targets if t in modules and t != name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph (its modules, the first repeated at the end), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for target in sorted(graph[node]):
            if state.get(target) == 1:
                return [*path[path.index(target):], target]
            if target not in state:
                cycle = visit(target)
                if cycle is not None:
                    return cycle
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state:
            cycle = visit(start)
            if cycle is not None:
                return cycle
    return None


def test_the_package_has_no_import_cycle() -> None:
    graph = import_graph()
    assert "wz_gateway.storage" in graph["wz_gateway.app"]  # the graph is read at all
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_the_cycle_finder_finds_the_old_app_and_webhook_routes_loop(tmp_path: Path) -> None:
    """The shape the package had: app.py imported webhook_routes.py, which imported app.py
    back under ``if TYPE_CHECKING:``; an import inside a function does not count."""
    (tmp_path / "__init__.py").write_text("")
    (tmp_path / "app.py").write_text("from wz_gateway.webhook_routes import webhook_router\n")
    (tmp_path / "webhook_routes.py").write_text("from . import storage\n")
    (tmp_path / "storage.py").write_text("def f():\n    from wz_gateway import app\n")
    assert find_cycle(import_graph(tmp_path)) is None
    (tmp_path / "webhook_routes.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from wz_gateway.app import GatewayContext\n"
    )
    assert find_cycle(import_graph(tmp_path)) == [
        "wz_gateway.app", "wz_gateway.webhook_routes", "wz_gateway.app"]  # fmt: skip
