"""deploy/containers/stack.py (``make containers``) against the compose file and the Makefile.

The script itself builds and runs the stack with Podman at the end of ``make test``; these
checks keep it in step with the files it reads, without Podman."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _stack() -> ModuleType:
    spec = importlib.util.spec_from_file_location("stack", ROOT / "deploy/containers/stack.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_image_of_the_compose_file_has_a_size_ceiling() -> None:
    stack = _stack()
    images = stack.compose_images()
    assert set(images) == set(stack.CEILINGS_MB)
    assert all(ceiling > 0 for ceiling in stack.CEILINGS_MB.values())
    # Each image is built from one workspace member with a command, as the Dockerfile asks.
    assert all(args.get("PACKAGE") and args.get("COMMAND") for args in images.values())


def test_no_runtime_image_carries_open3d_but_the_simulator() -> None:
    """The LiDAR detector's image runs the fast path: open3d is its optional extra only."""
    stack = _stack()
    for image, args in stack.compose_images().items():
        assert "reference" not in args.get("SYNC_FLAGS", ""), image
    lidar = (ROOT / "services/lidar_detector/pyproject.toml").read_text(encoding="utf-8")
    dependencies = lidar.split("dependencies = [", 1)[1].split("]", 1)[0]
    assert "open3d" not in dependencies
    assert re.search(r'^reference = \["open3d', lidar, re.MULTILINE)


def test_a_size_over_its_ceiling_is_reported() -> None:
    stack = _stack()
    image, ceiling = next(iter(stack.CEILINGS_MB.items()))
    assert stack.check_sizes({image: ceiling - 1.0}) == []
    (line,) = stack.check_sizes({image: ceiling + 1.0})
    assert image in line and str(ceiling) in line


def test_make_test_ends_with_the_containers_check() -> None:
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    (test_line,) = [line for line in makefile.splitlines() if line.startswith("test:")]
    assert test_line.split()[-1] == "containers-check"
    assert "stack.py check --down-after" in makefile


@pytest.mark.parametrize("argv", [[], ["launch"], ["check", "--bogus"]])
def test_bad_arguments_are_a_usage_error(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exited:
        _stack().main(argv)
    assert exited.value.code == 2
    assert "usage:" in capsys.readouterr().err


def test_the_container_networks_dns_is_installed_and_its_backend_pinned() -> None:
    """A fresh machine got podman without its recommends, so no DNS on the compose network and
    no service found `router` (issue 37): the plugin is installed with podman, the backend that
    uses it is pinned, and the check resolves one container from another before the stack."""
    stack = _stack()
    assert stack.DEBIAN_PACKAGES["golang-github-containernetworking-plugin-dnsname"] == (
        "/usr/lib/cni/dnsname"
    )
    assert {"podman", "runc", "debootstrap", "containernetworking-plugins"} <= set(
        stack.DEBIAN_PACKAGES
    )
    conf = (ROOT / "deploy/containers/containers.conf").read_text(encoding="utf-8")
    assert re.search(r'^\[network\]\s*\n(?:#.*\n)*network_backend = "cni"', conf, re.MULTILINE)
    source = (ROOT / "deploy/containers/stack.py").read_text(encoding="utf-8")
    check_body = source.split("def _check(", 1)[1]
    assert check_body.index("check_network_dns(") < check_body.index('compose("up"')
