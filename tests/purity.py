"""Pure cores import no I/O library: a helper for the tests that enforce it."""

from __future__ import annotations

import ast
import inspect
from types import ModuleType


def top_level_imports(module: ModuleType) -> set[str]:
    """The top-level package names a module imports (``numpy`` for ``numpy.typing``)."""
    tree = ast.parse(inspect.getsource(module))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module.split(".")[0])
    return names


def imported_modules(module: ModuleType) -> set[str]:
    """The full dotted names of the modules a module imports from (``numpy.typing``)."""
    tree = ast.parse(inspect.getsource(module))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names
