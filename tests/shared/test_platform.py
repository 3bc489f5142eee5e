"""Bus callbacks, shutdown, key registry, logging and time helpers."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.shared.samples import json_samples
from wz_shared.bus import Bus
from wz_shared.keys import Keys, site_of_key
from wz_shared.logs import JsonFormatter, configure_logging
from wz_shared.messages import Alert
from wz_shared.settings import BusSettings
from wz_shared.timebase import NEW_RUN_STEP_BACK_S, Pacer, RunWatch, SimClock, stamp_went_back

ROOT = Path(__file__).resolve().parents[2]
ALERT = next(m for m in json_samples() if isinstance(m, Alert))


@pytest.fixture
def two_buses(port: int) -> Iterator[tuple[Bus, Bus]]:
    listen = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    connect = BusSettings(listen_endpoints=[], connect_endpoints=[f"tcp/127.0.0.1:{port}"])
    with (
        Bus.open(listen, site="test-site", service="a") as a,
        Bus.open(connect, site="test-site", service="b") as b,
    ):
        yield a, b


def test_callback_that_raises_is_counted_and_the_subscription_goes_on(
    two_buses: tuple[Bus, Bus],
) -> None:
    a, b = two_buses
    got: list[str] = []
    done = threading.Event()

    def on_alert(key: str, alert: Alert) -> None:
        if alert.alert_id == "boom":
            raise RuntimeError("a bug in a service's callback")
        got.append(alert.alert_id)
        if len(got) == 2:
            done.set()

    b.on(b.keys.alerts_all, Alert, on_alert)
    publisher = a.publisher(a.keys.alerts("speeding"), Alert)
    assert publisher.wait_for_subscribers(10.0)
    for alert_id in ("first", "boom", "second"):
        publisher.put(ALERT.model_copy(update={"alert_id": alert_id}))
    publisher.put_bytes(b"not json")
    assert done.wait(10.0)
    assert got == ["first", "second"]
    deadline = time.monotonic() + 5.0
    while sum(b.stats.invalid.values()) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    reasons = {reason: n for (_, reason), n in b.stats.invalid.items()}
    assert reasons == {"callback_error": 1, "bad_json": 1}


def test_queryable_and_liveliness(two_buses: tuple[Bus, Bus]) -> None:
    a, b = two_buses
    a.serve(a.keys.config_site, lambda: b'{"site": "test-site"}')
    a.declare_alive()
    deadline = time.monotonic() + 5.0
    while not b.alive() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert b.alive() == ["wz/test-site/status/a"]
    assert b.query_bytes(b.keys.config_site, timeout_s=5.0) == [b'{"site": "test-site"}']


CALLBACK_PROCESS = """
import sys
from wz_shared.bus import Bus
from wz_shared.messages import Alert
from wz_shared.settings import BusSettings
with Bus.open(BusSettings(listen_endpoints=[], connect_endpoints=[]), site="s", service="x") as bus:
    bus.on(bus.keys.alerts_all, Alert, lambda key, alert: None)
    bus.subscribe(bus.keys.tracks, Alert)
sys.stdout.write("closed\\n")
"""


def test_process_with_callback_subscriber_exits_after_close() -> None:
    """Zenoh hangs interpreter exit while a Python callback stays declared: close() undeclares."""
    result = subprocess.run(
        [sys.executable, "-c", CALLBACK_PROCESS], cwd=ROOT, capture_output=True, timeout=30
    )
    assert result.returncode == 0, result.stderr.decode()
    assert result.stdout == b"closed\n"


def test_closed_bus_refuses_new_declarations(port: int) -> None:
    bus = Bus.open(BusSettings(listen_endpoints=[], connect_endpoints=[]), site="s", service="x")
    bus.close()
    bus.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        bus.subscribe(bus.keys.tracks, Alert)


def test_keys_follow_the_architecture() -> None:
    keys = Keys("us75-lincoln")
    assert keys.raw_lidar("lidar-mast") == "wz/us75-lincoln/raw/lidar/lidar-mast"
    assert keys.raw_camera("cam") == "wz/us75-lincoln/raw/camera/cam"
    assert keys.raw_radar("radar") == "wz/us75-lincoln/raw/radar/radar"
    assert keys.truth == "wz/us75-lincoln/truth/vehicles"
    assert keys.detections("lidar-mast") == "wz/us75-lincoln/detections/lidar-mast"
    assert keys.tracks == "wz/us75-lincoln/tracks"
    assert keys.tracks_latest == "wz/us75-lincoln/tracks/latest"
    assert keys.alerts("late_merge") == "wz/us75-lincoln/alerts/late_merge"
    assert keys.alerts_active == "wz/us75-lincoln/alerts/active"
    assert keys.devices_state == "wz/us75-lincoln/devices/state"
    assert keys.status("simulator") == "wz/us75-lincoln/status/simulator"
    assert keys.config_site == "wz/us75-lincoln/config/site"
    assert Keys.all_sites("alerts/*") == "wz/*/alerts/*"
    assert site_of_key("wz/us75-lincoln/tracks") == "us75-lincoln"
    assert site_of_key("other/thing") is None


@pytest.mark.parametrize("bad", ["", "a/b", "*", "**", "a$b", "Upper", "a b", "x?y"])
def test_keys_refuse_chunks_that_would_change_the_expression(bad: str) -> None:
    with pytest.raises(ValueError, match="key expression"):
        Keys(bad)
    with pytest.raises(ValueError, match="key expression"):
        Keys("site").raw_lidar(bad)


def test_json_logs_carry_site_service_sensor(capsys: pytest.CaptureFixture[str]) -> None:
    configure_logging(service="lidar-detector", site="us75-lincoln", sensor="lidar-mast")
    handler = logging.getLogger().handlers[0]
    handler.setFormatter(JsonFormatter())
    logging.getLogger("wz.test").warning("frame %d dropped", 7, extra={"reason": "truncated"})
    line = capsys.readouterr().err.strip().splitlines()[-1]
    entry = json.loads(line)
    assert entry["msg"] == "frame 7 dropped"
    assert entry["level"] == "warning"
    assert (entry["site"], entry["service"], entry["sensor"]) == (
        "us75-lincoln",
        "lidar-detector",
        "lidar-mast",
    )
    assert entry["reason"] == "truncated"
    logging.getLogger().handlers.clear()


def test_sim_clock_never_goes_back() -> None:
    clock = SimClock()
    clock.advance_to(1.5)
    assert clock.now() == 1.5
    with pytest.raises(ValueError, match="back"):
        clock.advance_to(1.0)
    clock.restart(0.2)  # a new run only
    assert clock.now() == 0.2
    clock.advance_to(0.3)
    assert clock.now() == 0.3


def test_run_watch_tells_a_new_run_from_a_stray_late_message() -> None:
    watch = RunWatch(step_back_s=1.0, confirm=3)
    assert [watch.observe(t) for t in (10.0, 10.1, 9.5, 10.2)] == ["run"] * 4  # within 1 s
    assert watch.newest_s == 10.2
    # One stray old message, then the run goes on: late, not a new run.
    assert [watch.observe(t) for t in (3.0, 10.3)] == ["behind", "run"]
    # Stamps going back and on for three messages: a restarted stream.
    assert [watch.observe(t) for t in (0.05, 0.10, 0.15, 0.20)] == [
        "behind",
        "behind",
        "new_run",
        "run",
    ]
    assert watch.newest_s == 0.20
    # Far back but not going on from there (not increasing): no new run.
    watch = RunWatch(step_back_s=1.0, confirm=3)
    watch.observe(50.0)
    assert [watch.observe(t) for t in (5.0, 4.0, 3.0, 2.0)] == ["behind"] * 4
    assert watch.newest_s == 50.0


def test_stamp_went_back_is_runwatchs_step_back() -> None:
    """One test of "the stamps went back", the gateway's (one stamp) and RunWatch's alike."""
    assert not stamp_went_back(None, 0.0)  # nothing yet
    assert not stamp_went_back(10.0, 10.0 - NEW_RUN_STEP_BACK_S)  # at the step: late only
    assert stamp_went_back(10.0, 8.9)
    assert not stamp_went_back(10.0, 11.0)
    assert stamp_went_back(10.0, 9.4, step_back_s=0.5)
    for stamp in (9.0, 8.99):
        watch = RunWatch(confirm=1)
        watch.observe(10.0)
        assert (watch.observe(stamp) == "new_run") == stamp_went_back(10.0, stamp)


def test_pacer_holds_simulation_to_a_multiple_of_real_time() -> None:
    pacer = Pacer(realtime_factor=10.0)
    start = time.monotonic()
    for step in range(21):
        pacer.wait_until(step * 0.05)  # 1 simulated second at 10x: 0.1 s of wall time
    elapsed = time.monotonic() - start
    assert 0.09 <= elapsed < 0.5
    fast = Pacer(realtime_factor=0.0)
    start = time.monotonic()
    for step in range(1000):
        fast.wait_until(step * 0.05)
    assert time.monotonic() - start < 0.05
