"""A service's Prometheus metrics (``WZ_METRICS_PORT``) in this process: a runtime with a
queue on the bus, messages taken and processed, the port scraped over HTTP. Processing time
is observed once per input, from its arrival; a field device that does not answer shows as 0
and turns the state ``degraded``; the port is free again once the runtime stops; a taken port
leaves the service running without metrics."""

from __future__ import annotations

import re
import socket
import time

import httpx

from tests.conftest import free_port
from wz_shared.messages import DeviceLink, ServiceStatus
from wz_shared.service import ServiceRuntime
from wz_shared.settings import BusSettings

BUS = BusSettings(mode="peer", listen_endpoints=[], connect_endpoints=[])


def sample(text: str, name: str, **labels: str) -> float:
    for line in text.splitlines():
        if line.startswith(name + "{") and all(f'{k}="{v}"' in line for k, v in labels.items()):
            return float(line.rsplit(" ", 1)[1])
    raise AssertionError(f"no {name} {labels} in the scrape")


def test_a_runtime_serves_its_metrics_and_frees_the_port_on_stop() -> None:
    port = free_port()
    with ServiceRuntime("metrics-test", "s", BUS, status_period_s=0.05, metrics_port=port) as rt:
        key = rt.bus.keys.status("metrics-test")
        inbox = rt.bus.subscribe(key, ServiceStatus, capacity=8)
        taken = 0
        deadline = time.monotonic() + 10.0
        while taken < 3 and time.monotonic() < deadline:
            if inbox.recv(0.5) is not None:  # the runtime's own status messages as input
                taken += 1
                rt.beat(processed=True)
                rt.beat(processed=True)  # the same input: observed once
        assert taken == 3
        rt.devices = {"dynamic-message-sign": DeviceLink(address="udp x:161", reachable=False)}
        text = httpx.get(f"http://127.0.0.1:{port}/metrics", timeout=5.0).text
        assert sample(text, "wz_processing_seconds_count", service="metrics-test") == 3.0
        assert sample(text, "wz_bus_received_total", key=key) >= 3.0
        assert sample(text, "wz_bus_published_total", key=key) >= 3.0
        assert sample(text, "wz_queue_capacity", key=key) == 8.0
        assert sample(text, "wz_service_state", state="degraded") == 1.0
        assert sample(text, "wz_service_state", state="running") == 0.0
        assert sample(text, "wz_device_reachable", device="dynamic-message-sign") == 0.0
        assert 0.0 <= sample(text, "wz_loop_age_seconds") < 5.0
        assert re.search(r'wz_input_age_seconds\{service="metrics-test",site="s"\} [0-9.e-]+', text)
    with socket.socket() as probe:
        assert probe.connect_ex(("127.0.0.1", port)) != 0, "the metrics port is still open"


def test_a_taken_port_leaves_the_service_running_without_metrics() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with ServiceRuntime("metrics-test", "s", BUS, metrics_port=port) as runtime:
            assert runtime.metrics is not None and runtime.bus is not None
            runtime.beat(processed=True)  # no input taken yet: nothing observed, no error
