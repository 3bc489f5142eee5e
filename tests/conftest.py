"""Fixtures shared by every test: free loopback ports, bus settings, sample messages."""

from __future__ import annotations

import os
import socket
from collections.abc import Iterator

import pytest
from hypothesis import settings

from wz_shared.settings import BusSettings

# Property tests draw the same examples on every run (a CI result is reproducible); set
# HYPOTHESIS_PROFILE=explore to draw new ones when hunting for counter-examples.
settings.register_profile("reproducible", derandomize=True)
settings.register_profile("explore", derandomize=False, max_examples=2000)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "reproducible"))


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Under pytest-xdist (``--dist loadgroup``), a module's tests run on one worker: its
    module-scoped fixtures (a test network of namespaces, a PostgreSQL cluster, routers) are
    made once, not again each time the worker comes back to the module. Tests that name a
    group of their own (``xdist_group("stack")``: they run `wz up`) keep it. Before xdist's
    own hook, which reads the marks."""
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::", 1)[0]))


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture
def port() -> int:
    return free_port()


@pytest.fixture
def listening_bus_settings(port: int) -> Iterator[BusSettings]:
    """A peer that listens on a free loopback port and connects nowhere."""
    yield BusSettings(mode="peer", listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
