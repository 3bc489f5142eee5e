"""Fixtures of the `wz` tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.cli.procs import start_router, stop_process


@pytest.fixture
def router() -> Iterator[str]:
    """A `wz router` on a free loopback port; yields its endpoint, then stops it (must exit 0)."""
    endpoint, process = start_router()
    try:
        yield endpoint
    finally:
        code = stop_process(process)
        if process.stderr is not None:
            process.stderr.close()
        assert code == 0
