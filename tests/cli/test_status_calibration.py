"""`wz status`'s CALIBRATION table, as processes on a real bus: `wz router`, a camera detector
on the real runtime (:mod:`tests.cli.stall_node` named ``camera-detector``: its liveliness
token and status), this test publishing the calibration of the camera and the radar (and of
a sensor the site file does not list), and `wz status` as a command. The default site's LiDAR,
whose detector is not running, and then the radar, whose detector runs but sends nothing, are
shown without data and said why, as the services table does for a service that did not
report."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from tests.cli.procs import ROOT, run_wz, stop_process, wait_for, wz_env
from wz_shared.bus import Bus
from wz_shared.messages import CalibrationState, PoseCorrection, SensorCalibration
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, load_site

SITE = load_site(DEFAULT_SITE_PATH)
DETECTOR = "camera-detector"


def calibration(
    sensor_id: str, kind: str, state: CalibrationState, **values: object
) -> SensorCalibration:
    return SensorCalibration.model_validate(
        {
            "site": SITE.site_id,
            "source_id": sensor_id,
            "stamp": 100.0,
            "sensor_kind": kind,
            "state": state,
            **values,
        }
    )


CAMERA = calibration(
    "camera-mast",
    "camera",
    CalibrationState.BUMPED,
    state_since_s=60.0,
    correction=PoseCorrection(yaw_deg=0.8, pitch_deg=-0.2, yaw_std_deg=0.4),
    clock_offset_s=0.085,
    clock_offset_std_s=0.004,
    samples=42,
    detail="its boxes stand 2.1 deg off the LiDAR's",
)
RADAR = calibration(
    "radar-mast",
    "radar",
    CalibrationState.CALIBRATED,
    state_since_s=25.0,
    correction=PoseCorrection(yaw_deg=-0.35, yaw_std_deg=0.08),
    clock_offset_s=0.021,
    samples=310,
)
#: A sensor the site file does not list: shown after the site's.
ROOF = calibration("lidar-roof", "lidar", CalibrationState.LEARNING, state_since_s=95.0)


@contextmanager
def publishing(
    endpoint: str, sensors: dict[str, SensorCalibration]
) -> Iterator[Callable[[], None]]:
    """Publish each calibration of ``sensors`` (which the test may change meanwhile) twice a
    second, as a detector does every 5 s, until the block ends; yields a call that waits
    until a whole round began after it was called."""
    stop = threading.Event()
    rounds = threading.Condition()
    done = [0]
    settings = BusSettings(mode="peer", connect_endpoints=[endpoint], listen_endpoints=[])
    with Bus.open(settings, site=SITE.site_id, service="calibration-publisher") as bus:
        publishers = {
            sensor_id: bus.publisher(bus.keys.calibration(sensor_id), SensorCalibration)
            for sensor_id in sensors
        }

        def loop() -> None:
            while not stop.wait(0.5):
                for sensor_id, message in list(sensors.items()):
                    publishers[sensor_id].put(message)
                with rounds:
                    done[0] += 1
                    rounds.notify_all()

        def next_round() -> None:
            with rounds:
                after = done[0] + 1  # the round under way may have read the old sensors
                assert rounds.wait_for(lambda: done[0] > after, 10.0)

        thread = threading.Thread(target=loop, name="calibrations", daemon=True)
        thread.start()
        try:
            yield next_round
        finally:
            stop.set()
            thread.join(5.0)


def status(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return run_wz("status", "--connect", endpoint, "--expect", DETECTOR, *args)


def test_wz_status_shows_each_sensors_calibration_and_what_is_missing(
    router: str, tmp_path: Path
) -> None:
    detector = subprocess.Popen(
        [sys.executable, "-m", "tests.cli.stall_node", DETECTOR, str(tmp_path / "never")],
        cwd=ROOT,
        env=wz_env(WZ_BUS_CONNECT_ENDPOINTS=router, WZ_STATUS_PERIOD_S="0.5"),
    )
    sensors = {"camera-mast": CAMERA, "radar-mast": RADAR, "lidar-roof": ROOF}
    try:
        with publishing(router, sensors) as next_round:
            wait_for(
                lambda: status(router, "--timeout", "2").returncode == 0, 60.0, "the detector up"
            )
            # Every sensor whose detector is alive reported: it returns at once, not after 20 s.
            started = time.monotonic()
            result = status(router, "--json", "--timeout", "20")
            assert time.monotonic() - started < 10.0
            assert result.returncode == 0, result.stderr
            report = json.loads(result.stdout)
            rows = {row["sensor"]: row for row in report["calibration"]}
            # The site file's first; one it does not list is not waited for (it may be there).
            assert list(rows)[:3] == ["lidar-mast", "camera-mast", "radar-mast"]
            assert SensorCalibration.model_validate(rows["camera-mast"]["calibration"]) == CAMERA
            assert rows["camera-mast"]["detector_alive"] is True
            assert rows["camera-mast"]["age_s"] < 2.0
            assert rows["lidar-mast"] == {
                "sensor": "lidar-mast",
                "kind": "lidar",
                "expected": True,
                "detector_alive": False,
                "calibration": None,
                "age_s": None,
            }
            assert report["problems"] == [] and report["ok"] is True
            assert report["calibration_notes"] == [
                "lidar-mast: no calibration (lidar-detector is not running)",
                "camera-mast: bumped 40.0s ago (its boxes stand 2.1 deg off the LiDAR's): its "
                "pose is being learned again, its detections weigh less",
            ]

            table = status(router, "--timeout", "20")
            assert table.returncode == 0, table.stderr
            lines = table.stdout.splitlines()
            start = lines.index("CALIBRATION")
            assert lines[start + 1].split() == [
                "SENSOR",
                "KIND",
                "STATE",
                "DYAW",
                "DEG",
                "DPITCH",
                "DEG",
                "DROLL",
                "DEG",
                "CLOCK",
                "MS",
                "SAMPLES",
                "SINCE",
            ]
            cells = [line.split() for line in lines[start + 2 : start + 5]]
            assert cells == [
                ["lidar-mast", "lidar", "-", "-", "-", "-", "-", "-", "-"],
                [
                    "camera-mast",
                    "camera",
                    "bumped",
                    "+0.80",
                    "-0.20",
                    "+0.00",
                    "+85",
                    "42",
                    "40.0s",
                ],
                [
                    "radar-mast",
                    "radar",
                    "calibrated",
                    "-0.35",
                    "+0.00",
                    "+0.00",
                    "+21",
                    "310",
                    "1m15s",
                ],
            ]
            assert lines[-2:] == report["calibration_notes"]

            # The radar's calibration stops while its detector lives: shown without data after
            # the whole timeout, and said so.
            del sensors["radar-mast"]
            next_round()
            started = time.monotonic()
            result = status(router, "--json", "--timeout", "2")
            assert time.monotonic() - started >= 2.0
            report = json.loads(result.stdout)
            rows = {row["sensor"]: row for row in report["calibration"]}
            assert list(rows) == ["lidar-mast", "camera-mast", "radar-mast", "lidar-roof"]
            assert rows["lidar-roof"]["expected"] is False
            assert rows["lidar-roof"]["calibration"]["state"] == "learning"
            radar = rows["radar-mast"]
            assert radar["calibration"] is None and radar["detector_alive"] is True
            assert any(
                note.startswith(
                    "radar-mast: no calibration heard in 2.0 s (camera-detector is alive"
                )
                for note in report["calibration_notes"]
            ), report["calibration_notes"]
            assert result.returncode == 0  # a sensor's calibration never fails the command
            table = status(router, "--timeout", "2").stdout.splitlines()
            roof = table[table.index("CALIBRATION") + 5].split()
            assert roof == ["lidar-roof", "lidar", "learning", *("+0.00",) * 3, "+0", "0", "5.0s"]
    finally:
        assert stop_process(detector) == 0
