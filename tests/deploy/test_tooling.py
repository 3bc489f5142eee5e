"""The Makefile and .pre-commit-config.yaml run the same checks, with nothing to download."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]


def makefile_variable(name: str) -> list[str]:
    """The words of a ``NAME := ...`` or ``NAME ?= ...`` assignment (continuations joined)."""
    text = (ROOT / "Makefile").read_text(encoding="utf-8").replace("\\\n", " ")
    match = re.search(rf"^{name}\s*[:?]?=\s*(.*)$", text, re.MULTILINE)
    assert match, f"Makefile sets no {name}"
    return shlex.split(match.group(1))


def makefile_recipe(target: str) -> list[str]:
    """The command lines of ``target`` (a line ending in a backslash joined to the next)."""
    lines = (ROOT / "Makefile").read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"{target}:"))
    recipe: list[str] = []
    continued = False
    for line in lines[start + 1 :]:
        if not line.startswith("\t"):
            break
        text = line.strip()
        if continued:
            recipe[-1] = recipe[-1].removesuffix("\\").rstrip() + " " + text
        else:
            recipe.append(text)
        continued = text.endswith("\\")
    return recipe


def hooks() -> dict[str, dict[str, object]]:
    config = yaml.safe_load((ROOT / ".pre-commit-config.yaml").read_text(encoding="utf-8"))
    (repo,) = config["repos"]
    assert repo["repo"] == "local", "local hooks only: nothing downloaded"
    return {hook["id"]: hook for hook in repo["hooks"]}


def test_hooks_run_the_workspace_tools() -> None:
    for hook_id, hook in hooks().items():
        assert hook["language"] == "system", hook_id
        assert str(hook["entry"]).startswith(".venv/bin/"), hook_id


def test_mypy_hook_checks_the_makefile_folders() -> None:
    typed = makefile_variable("TYPED")
    assert all((ROOT / folder).is_dir() for folder in typed), typed
    assert any("mypy $(TYPED)" in line for line in makefile_recipe("typecheck"))
    mypy = hooks()["mypy"]
    assert mypy["args"] == typed
    assert mypy["pass_filenames"] is False


def test_lint_checks_format_as_the_hooks_do() -> None:
    recipe = makefile_recipe("lint")
    assert any(line.endswith("ruff check .") for line in recipe)
    assert any(line.endswith("ruff format --check .") for line in recipe)
    entries = {str(hook["entry"]).removeprefix(".venv/bin/") for hook in hooks().values()}
    assert {"ruff check", "ruff format --check"} <= entries


def test_pytest_measures_coverage_against_the_floor() -> None:
    floor = makefile_variable("COV_FLOOR")
    assert len(floor) == 1 and 80 <= float(floor[0]) <= 100  # measured 86 %
    parallel, serial = (shlex.split(command) for command in makefile_recipe("pytest"))
    # First on every core (the tests that run `wz up` kept on one worker), then the serial
    # tests alone; coverage measured over both, the floor checked at the end; the slowest listed.
    assert parallel[parallel.index("-n") + 1] == "$(PYTEST_WORKERS)"
    assert parallel[parallel.index("--dist") + 1] == "loadgroup"
    assert parallel[parallel.index("-m") + 1] == "not serial"
    assert serial[serial.index("-m") + 1] == "serial" and "-n" not in serial
    assert "--cov" in parallel and {"--cov", "--cov-append"} <= set(serial)
    assert "--cov-fail-under=$(COV_FLOOR)" in serial
    assert all(any(w.startswith("--durations=") for w in run) for run in (parallel, serial))


def test_vendored_wzdx_schemas_are_the_recorded_files() -> None:
    """Each vendored WZDx file is the one its README records (name and sha256), so an edit or
    a file added without its source and licence stated shows here."""
    import hashlib

    folder = ROOT / "deploy" / "schemas" / "wzdx-4.2"
    readme = (folder / "README.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| `([^`]+)`[^|]* \| `([0-9a-f]{64})` \|$", readme, re.MULTILINE)
    recorded = dict(rows)
    present = {
        str(path.relative_to(folder)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in folder.rglob("*")
        if path.suffix in {".json", ".geojson"}
    }
    assert present == recorded
    licence = (folder / "LICENSE-CC0.txt").read_text(encoding="utf-8")
    assert licence.startswith("Creative Commons Legal Code")
