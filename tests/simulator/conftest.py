"""Fixtures of the simulator tests: the default site and one network cache per session."""

from __future__ import annotations

from pathlib import Path

import pytest

from wz_shared.site import DEFAULT_SITE_PATH, Site, load_site


@pytest.fixture(scope="session")
def site() -> Site:
    return load_site(DEFAULT_SITE_PATH)


@pytest.fixture(scope="session")
def sim_work_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A work folder shared by the session, so the network is built once."""
    return tmp_path_factory.mktemp("wz-sim")
