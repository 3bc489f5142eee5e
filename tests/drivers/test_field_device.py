"""The device worker's resilience (``wz_drivers.field_device.DeviceWorker``), with a device in
memory: a driver that cannot be built, or one that fails in a way its protocol did not
foresee, is reported unreachable with the reason; the thread goes on and drives the device
once it works."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from wz_drivers.field_device import DeviceWorker, FieldDevice
from wz_shared.messages import DeviceLink


class Lamp(FieldDevice[bool]):
    """A device in memory whose ``_put`` fails with a plain error while ``broken``."""

    def __init__(self) -> None:
        super().__init__("memory lamp", retry_s=0.05, check_s=60.0)
        self.lit = False
        self.broken = True

    def _put(self, value: bool) -> bool:
        if self.broken:
            raise ZeroDivisionError("a bug")
        self.lit = value
        return value

    def _get(self) -> bool:
        return self.lit


def link_when(
    worker: DeviceWorker[bool], condition: Callable[[DeviceLink], bool], what: str
) -> DeviceLink:
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        link = worker.link(time.monotonic())
        if condition(link):
            return link
        time.sleep(0.01)
    pytest.fail(f"timed out waiting for {what}")


def test_a_driver_that_cannot_be_built_is_reported_unreachable() -> None:
    def make() -> FieldDevice[bool]:
        raise OSError("no such interface")

    stop = threading.Event()
    worker = DeviceWorker("lamp", "memory lamp", make, stop)
    assert worker.link(0.0).reachable is None  # before the thread ran
    worker.start()
    link = link_when(worker, lambda link: link.reachable is False, "the failure reported")
    assert link.detail == "cannot drive it: OSError('no such interface')"
    stop.set()
    worker.join(1.0)


def test_a_driver_that_fails_unexpectedly_is_unreachable_and_retried() -> None:
    lamp = Lamp()
    stop = threading.Event()
    worker = DeviceWorker("lamp", lamp.address, lambda: lamp, stop)
    worker.start()
    try:
        worker.want(True)
        link = link_when(worker, lambda link: link.reachable is False, "the failure reported")
        assert link.detail == "driver error: ZeroDivisionError('a bug')"
        lamp.broken = False  # mended: the next try (retry_s on) puts the wish on
        link_when(worker, lambda link: link.shows == "True", "the lamp lit")
        assert lamp.lit and worker.changes == 1
    finally:
        stop.set()
        worker.join(1.0)
