"""The tracker's history smoothing does no I/O (the smoother itself, and its comparisons with
filterpy: tests/shared/test_motion.py; a history's runs: test_tracker.py)."""

from __future__ import annotations

from tests.purity import top_level_imports
from wz_fusion_tracker import smoothing


def test_core_imports_no_io_library() -> None:
    assert top_level_imports(smoothing).isdisjoint({"zenoh", "fastapi", "requests", "io"})
