"""What the gateway's tests share: keys, settings, sample data and a live uvicorn server."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import httpx
import pytest
import uvicorn

from tests.alert_service.helpers import SITE, batch, make_track
from tests.conftest import free_port
from wz_gateway.app import create_app
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.node import prepare_keys
from wz_gateway.settings import GatewaySettings
from wz_gateway.sites import Sites
from wz_gateway.storage import Storage
from wz_shared.messages import (
    Alert,
    AlertPhase,
    AlertSeverity,
    AlertType,
    RoadsideDeviceState,
    ServiceState,
    ServiceStatus,
    Track,
    TrackBatch,
)
from wz_shared.site import Site

__all__ = ["SITE", "batch", "make_track"]

READ_KEY = "rk-4f9Qz7Lm2Xv8Tb3Nc6Wd1Ys5"
ADMIN_KEY = "ak-8Hj2Kp5Rt9Uw3Ye6Za1Bc4Dq7"
#: The WZDx 4.2 schemas (CC0), vendored: deploy/schemas/wzdx-4.2/README.md.
SPEC_DIR = Path(__file__).resolve().parents[2] / "deploy" / "schemas" / "wzdx-4.2"


def gateway_settings(tmp_path: Path, **overrides: Any) -> GatewaySettings:
    """Settings on a database under ``tmp_path`` with one read and one admin key."""
    values: dict[str, Any] = {
        "data_dir": tmp_path / "data",
        "api_keys": [f"read:{READ_KEY}", f"admin:{ADMIN_KEY}"],
        "port": 0,
        **overrides,
    }
    return GatewaySettings(**values)


def open_storage(settings: GatewaySettings) -> Storage:
    storage = Storage.open(settings.resolved_database_url())
    prepare_keys(storage, settings, time.time())
    return storage


def car_batches(
    track_id: int,
    station0_m: float,
    speed_mps: float,
    start_s: float,
    count: int,
    *,
    offset_m: float = -1.83,
    period_s: float = 0.1,
    first_cycle: int = 0,
) -> list[TrackBatch]:
    """One car driving at a constant speed: a batch every ``period_s``."""
    return [
        batch(
            start_s + k * period_s,
            [
                make_track(
                    track_id, station0_m + speed_mps * k * period_s, speed_mps, offset_m=offset_m
                )
            ],
            first_cycle + k,
        )
        for k in range(count)
    ]


def sample_alert(
    alert_id: str,
    stamp: float,
    *,
    alert_type: AlertType = AlertType.SPEEDING,
    severity: AlertSeverity = AlertSeverity.WARNING,
    phase: AlertPhase = "start",
    track: Track | None = None,
    track_id: int | None = 1,
) -> Alert:
    return Alert(
        site=SITE.site_id,
        source_id="alert-service",
        stamp=stamp,
        alert_id=alert_id,
        alert_type=alert_type,
        severity=severity,
        track_id=track_id,
        station_m=700.0,
        offset_m=-1.83,
        speed_mps=29.0,
        measured_value=29.0,
        threshold_value=26.8,
        description="speeding: 65 mph in the 55 mph zone",
        phase=phase,
        episode_id=f"ep-{alert_id}",
        onset_stamp=max(0.0, stamp - 1.0),
        value_unit="m/s",
        evidence={"speed_limit_mps": 24.587},
        track=track,
    )


def devices_state(
    stamp: float, *, beacon_on: bool, sign_text: str, cause: AlertType | None
) -> RoadsideDeviceState:
    return RoadsideDeviceState(
        site=SITE.site_id,
        source_id="alert-service",
        stamp=stamp,
        beacon_on=beacon_on,
        sign_text=sign_text,
        cause=cause,
    )


def service_status(service: str, stamp: float, received_hz: dict[str, float]) -> ServiceStatus:
    return ServiceStatus(
        site=SITE.site_id,
        source_id=service,
        stamp=stamp,
        service=service,
        state=ServiceState.RUNNING,
        uptime_s=10.0,
        pid=1234,
        received_hz=received_hz,
    )


@contextmanager
def live_server(
    settings: GatewaySettings,
    storage: Storage,
    metrics: GatewayMetrics | None = None,
    *,
    site: Site | Sites = SITE,
    clock: Callable[[], float] = time.time,
) -> Iterator[str]:
    """The app on uvicorn on a free loopback port, in a thread; yields its base URL."""
    port = free_port()
    app = create_app(settings, storage, site=site, metrics=metrics, clock=clock)
    server = uvicorn.Server(
        uvicorn.Config(
            app, host="127.0.0.1", port=port, log_config=None, access_log=False, lifespan="off"
        )
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10.0
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("uvicorn did not start")
        time.sleep(0.01)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(10.0)


ROOT = Path(__file__).resolve().parents[2]


@contextmanager
def gateway_process(
    bus_port: int, http_port: int, data_dir: Path, *, keys: bool = True, **settings: str
) -> Iterator[subprocess.Popen[bytes]]:
    """The gateway node as its own process, a client of the bus at ``bus_port``, serving HTTP
    on ``http_port`` and storing in ``data_dir``; ``keys``: the read and admin keys of these
    tests configured; ``settings``: more ``WZ_GATEWAY_<NAME>`` values (``dev_mode="true"``).
    Stopped with SIGTERM, and it must then exit cleanly; one a test killed is left as is."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{bus_port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_STATUS_PERIOD_S="0.2",
        WZ_LOG_FORMAT="json",
        WZ_GATEWAY_PORT=str(http_port),
        WZ_GATEWAY_DATA_DIR=str(data_dir),
    )
    if keys:
        env["WZ_GATEWAY_API_KEYS"] = f"read:{READ_KEY},admin:{ADMIN_KEY}"
    env.update({f"WZ_GATEWAY_{name.upper()}": value for name, value in settings.items()})
    node = subprocess.Popen([sys.executable, "-m", "wz_gateway.node"], cwd=ROOT, env=env)
    try:
        yield node
    finally:
        if node.poll() is None:
            node.send_signal(signal.SIGTERM)
            assert node.wait(20.0) == 0
        else:  # it stopped by itself: only a kill by the test is fine
            assert node.returncode in (0, -signal.SIGKILL), node.returncode


_T = TypeVar("_T")


def eventually(probe: Callable[[], _T | None], what: str, timeout_s: float = 20.0) -> _T:
    """Ask ``probe`` until it returns something (the HTTP side has no event to wait on)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            value = probe()
        except httpx.TransportError:  # the server is not listening yet
            value = None
        if value is not None:
            return value
        time.sleep(0.05)
    pytest.fail(f"timed out after {timeout_s:.0f} s waiting for {what}")


def mint_concurrently(url: str, headers: dict[str, str], count: int) -> list[int]:
    """``count`` POST /v1/admin/api-keys at once (a thread each, released together); their
    status codes."""
    import threading

    gate = threading.Barrier(count)
    codes: list[int] = []
    lock = threading.Lock()

    def one() -> None:
        with httpx.Client(timeout=60.0) as client:
            gate.wait()
            reply = client.post(
                f"{url}/v1/admin/api-keys", headers=headers, json={"scope": "read", "name": "n"}
            )
        with lock:
            codes.append(reply.status_code)

    threads = [threading.Thread(target=one) for _ in range(count)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(120.0)
    return codes
