"""The repository's shape, checked: what a newcomer relies on when finding their way.

- no import cycle between first-party modules (module-level imports, ``TYPE_CHECKING`` ones
  included: a cycle of types is still two rooms that cannot be read apart);
- no source module over 1,000 lines;
- every service has its settings in ``settings.py`` and a README.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCE_ROOTS = [
    ROOT / "shared" / "src",
    ROOT / "cli" / "src",
    ROOT / "eval" / "src",
    *sorted((ROOT / "services").glob("*/src")),
]
SERVICES = sorted(p.parent for p in (ROOT / "services").glob("*/pyproject.toml"))
MAX_MODULE_LINES = 1000


def _modules() -> dict[str, Path]:
    """Dotted module name -> file, for every first-party module."""
    modules = {}
    for source in SOURCE_ROOTS:
        for path in source.rglob("*.py"):
            parts = path.relative_to(source).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """First-party modules that ``name`` imports at module level (``if`` blocks included)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        for statement in [node, *(node.body if isinstance(node, ast.If) else [])]:
            if isinstance(statement, ast.Import):
                found.update(alias.name for alias in statement.names)
            elif isinstance(statement, ast.ImportFrom):
                base = statement.module or ""
                if statement.level:
                    parts = package.split(".")[: len(package.split(".")) - statement.level + 1]
                    base = ".".join([*parts, base] if base else parts)
                found.add(base)
                found.update(f"{base}.{alias.name}" for alias in statement.names)
    return {module for module in found if module in known and module != name}


def import_cycles(modules: dict[str, Path]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan's algorithm, iterative)."""
    graph = {name: sorted(_imports(name, path, set(modules))) for name, path in modules.items()}
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
    return cycles


def test_the_cycle_finder_finds_a_cycle(tmp_path: Path) -> None:
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "a.py").write_text("from pkg.b import thing\n")
    (tmp_path / "pkg" / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg import a\n"
    )
    (tmp_path / "pkg" / "c.py").write_text("from . import a\n")
    modules = {
        "pkg": tmp_path / "pkg" / "__init__.py",
        **{f"pkg.{m}": tmp_path / "pkg" / f"{m}.py" for m in "abc"},
    }
    assert import_cycles(modules) == [["pkg.a", "pkg.b"]]


def test_no_import_cycle_between_first_party_modules() -> None:
    assert import_cycles(_modules()) == []


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
