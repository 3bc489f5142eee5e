"""`wz tap` as a process: a router, a publisher process, and the tap printing what passes."""

from __future__ import annotations

from tests.cli.bus_tools import JUNK_KEY, tap_mix
from tests.cli.procs import (
    communicate_while_publishing,
    free_port,
    run_wz,
    running,
    start_wz,
)


def test_tap_shows_messages_frames_and_invalid_payloads(router: str) -> None:
    expected = len(tap_mix())
    tapping = ("tap", "wz/test-site/**", "--count", str(expected), "--timeout", "60")
    # The publisher waits until its publishers match the tap's subscription.
    with running(start_wz(*tapping, "--connect", router)) as tap:
        out, err = communicate_while_publishing(tap, router, "tap")
    assert tap.returncode == 0, err
    lines = out.splitlines()
    assert len(lines) == expected, out
    assert lines[0] == (
        "wz/test-site/truth/vehicles  ground_truth  "
        "stamp=10.150 step=3 vehicles=1 first=veh3 30.0 m/s"
    )
    assert lines[1].startswith("wz/test-site/raw/lidar/lidar-mast  lidar_frame  #4 ")
    assert "points=32" in lines[1]
    assert lines[2].startswith("wz/test-site/raw/camera/camera-mast  camera_frame  #5 ")
    assert lines[3].startswith('wz/test-site/alerts/speeding  alert  {"schema_version":1')
    assert "<invalid: schema_version" in lines[4]
    assert lines[5].startswith(f"{JUNK_KEY}  ?  <invalid: bad_json")
    assert "lidar_frame  <invalid: truncated" in lines[6]


def test_tap_times_out_with_exit_1_when_nothing_comes(router: str) -> None:
    result = run_wz("tap", "wz/nobody/**", "--count", "1", "--timeout", "0.5", "--connect", router)
    assert result.returncode == 1
    assert result.stdout == ""
    assert "only 0 of 1 message(s)" in result.stderr


def test_status_without_a_router_says_so_and_exits_1() -> None:
    port = free_port()
    result = run_wz("status", "--connect", f"tcp/127.0.0.1:{port}", "--timeout", "0.5")
    assert result.returncode == 1
    assert result.stdout == ""
    assert f"cannot reach the bus at tcp/127.0.0.1:{port}: is the stack running" in result.stderr


def test_status_with_no_service_alive_exits_1(router: str) -> None:
    """Every service `wz up` runs is expected: each is listed as down."""
    result = run_wz("status", "--connect", router, "--timeout", "0.5")
    assert result.returncode == 1
    assert "site us75-lincoln: 0 of 6 service(s) up" in result.stdout
    for name in ("simulator", "fusion-tracker", "alert-service", "gateway"):
        assert f"{name}: down (not running)" in result.stdout
    result = run_wz("status", "--connect", router, "--timeout", "0.5", "--expect", "")
    assert result.returncode == 1
    assert "0 of 0 service(s) up" in result.stdout
