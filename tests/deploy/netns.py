"""Hosts for the multi-site tests: Linux network namespaces joined by veth pairs (as root).

Each :class:`Host` is a namespace with its own loopback and interfaces, so a process in it
binds 127.0.0.1 and port 7447 as on its own box; a "cable" is a veth pair, cut and healed by
setting one end down and up (what a lost cellular link looks like to TCP: silence, no reset).
"""

from __future__ import annotations

import itertools
import os
import shutil
import subprocess
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pytest


def _ip(*args: str) -> None:
    result = subprocess.run(["ip", *args], capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {result.stderr.strip()}")


def require_namespaces() -> None:
    """Fail (not skip) where namespaces cannot be made: the deployment's must-show needs them,
    and the bootstrap (root, iproute2) provides them."""
    if shutil.which("ip") is None:
        pytest.fail("the `ip` tool is missing: install iproute2 (deploy/host/bootstrap.sh does)")
    if os.geteuid() != 0:
        pytest.fail("network namespaces need root: run the tests as root, as CI does")


@dataclass
class Host:
    """One namespace; ``address`` is its address on its first cable."""

    name: str
    addresses: list[str] = field(default_factory=list)

    def argv(self, argv: Sequence[str]) -> list[str]:
        return ["ip", "netns", "exec", self.name, *argv]

    def popen(
        self, argv: Sequence[str], *, env: Mapping[str, str], cwd: Path, log: Path
    ) -> subprocess.Popen[bytes]:
        """Start ``argv`` in this namespace, stdout and stderr to ``log`` (appended)."""
        with log.open("ab") as out:
            return subprocess.Popen(
                self.argv(argv), env=dict(env), cwd=cwd, stdout=out, stderr=subprocess.STDOUT
            )


@dataclass
class Cable:
    """A veth pair between two hosts; ``cut`` and ``heal`` act on the ``far`` host's end."""

    near: Host
    far: Host
    near_if: str
    far_if: str

    def cut(self) -> None:
        _ip("-n", self.far.name, "link", "set", self.far_if, "down")

    def heal(self) -> None:
        _ip("-n", self.far.name, "link", "set", self.far_if, "up")


def _worker_octet() -> int:
    """The second octet of this test process's cables: 231 alone, 231 + N for pytest-xdist's
    worker gwN. A root cable puts its near address in the test's own (shared) namespace, so two
    workers must not both take 10.231.1.1."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    return 231 + (int(worker[2:]) + 1 if worker.startswith("gw") and worker[2:].isdigit() else 0)


#: Numbers the networks of this process: each one's interfaces are named apart.
_NETWORKS = itertools.count()


class Network:
    """Namespaces and cables, all removed by :meth:`close` (processes must be stopped first)."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix
        self.hosts: list[Host] = []
        self._subnet = 0
        self._octet = _worker_octet()
        # Interface names (15 characters at most), unique to this process and network: the
        # prefix's first characters would be alike for two workers' pids (wzt3422, wzt3425).
        self._ifbase = f"v{os.getpid() % 1_000_000:06d}{next(_NETWORKS) % 100:02d}"
        self._root_ifs: list[str] = []  # veth ends in this test's own namespace

    def host(self, name: str) -> Host:
        host = Host(f"{self.prefix}-{name}")
        subprocess.run(["ip", "netns", "del", host.name], capture_output=True, check=False)
        _ip("netns", "add", host.name)
        _ip("-n", host.name, "link", "set", "lo", "up")
        self.hosts.append(host)
        return host

    def cable(self, near: Host, far: Host) -> Cable:
        """A /30 between ``near`` (.1) and ``far`` (.2), in 10.<octet>.<n>.0."""
        self._subnet += 1
        n = self._subnet
        near_if, far_if = f"{self._ifbase}{n}a", f"{self._ifbase}{n}b"
        _ip("link", "add", near_if, "type", "veth", "peer", "name", far_if)
        for host, ifname, last in ((near, near_if, 1), (far, far_if, 2)):
            _ip("link", "set", ifname, "netns", host.name)
            address = f"10.{self._octet}.{n}.{last}"
            _ip("-n", host.name, "addr", "add", f"{address}/30", "dev", ifname)
            _ip("-n", host.name, "link", "set", ifname, "up")
            host.addresses.append(address)
        return Cable(near, far, near_if, far_if)

    def root_cable(self, far: Host) -> str:
        """A veth between this test's own namespace and ``far``; ``far``'s address."""
        self._subnet += 1
        n = self._subnet
        near_if, far_if = f"{self._ifbase}{n}a", f"{self._ifbase}{n}b"
        _ip("link", "add", near_if, "type", "veth", "peer", "name", far_if)
        _ip("link", "set", far_if, "netns", far.name)
        _ip("addr", "add", f"10.{self._octet}.{n}.1/30", "dev", near_if)
        _ip("link", "set", near_if, "up")
        _ip("-n", far.name, "addr", "add", f"10.{self._octet}.{n}.2/30", "dev", far_if)
        _ip("-n", far.name, "link", "set", far_if, "up")
        self._root_ifs.append(near_if)
        return f"10.{self._octet}.{n}.2"

    def close(self) -> None:
        for ifname in self._root_ifs:
            subprocess.run(["ip", "link", "del", ifname], capture_output=True, check=False)
        for host in self.hosts:  # deleting a namespace deletes its veth ends (and the peers)
            subprocess.run(["ip", "netns", "del", host.name], capture_output=True, check=False)
