"""The LiDAR detector node: sensor-to-site transforms, the per-frame logic, and the node as a
real process over Zenoh (learning, detections with the frames' stamps, bad input counted).

Frames are synthetic: an organized 32 x 1024 sweep of a sensor 6 m above a flat road (the
default site's mast), with a 4.5 x 1.8 x 1.5 m box standing on the road, ray-cast in numpy.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from wz_lidar_detector.detection import BoxDetection, PointFrame
from wz_lidar_detector.node import ColumnClock, LidarDetector
from wz_lidar_detector.settings import LidarDetectorSettings, lidar_mount
from wz_lidar_detector.transform import box_to_site, detections_in_site, to_detection, wrap_angle
from wz_shared.bus import Bus, Subscription
from wz_shared.codec import encode_lidar_frame
from wz_shared.messages import (
    CalibrationState,
    DetectionBatch,
    LidarFrameMeta,
    SensorCalibration,
    ServiceState,
    ServiceStatus,
    VehicleClass,
)
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, Pose, load_site

ROOT = Path(__file__).resolve().parents[2]
SITE = load_site(DEFAULT_SITE_PATH)
MOUNT = SITE.sensor("lidar-mast")  # x 7.5, y 980, z 6 m, yaw -90 deg: looking south
ROWS, COLUMNS = 32, 1024
CAR_LWH_M = (4.5, 1.8, 1.5)
RATE_HZ = 20.0


def synthetic_points(
    box_xy_m: tuple[float, float] | None,
    *,
    rows: int = ROWS,
    columns: int = COLUMNS,
    seed: int = 0,
    height_m: float = 6.0,
    max_range_m: float = 60.0,
) -> npt.NDArray[np.float32]:
    """An organized sweep (row-major by beam) of a flat road and an optional axis-aligned car.

    Beams from -25 to -5 deg elevation, 360 deg of azimuth; returns beyond ``max_range_m`` are
    no-return slots (NaN); 1 cm range noise.
    """
    elevation = np.radians(np.linspace(-25.0, -5.0, rows))[:, None]
    azimuth = np.linspace(-math.pi, math.pi, columns, endpoint=False)[None, :]
    directions = np.stack(
        np.broadcast_arrays(
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation) * np.ones_like(azimuth),
        ),
        axis=-1,
    ).reshape(-1, 3)
    ranges = -height_m / directions[:, 2]  # the road, z = -height_m
    if box_xy_m is not None:
        length, width, height = CAR_LWH_M
        low = np.array([box_xy_m[0] - length / 2, box_xy_m[1] - width / 2, -height_m])
        high = np.array([box_xy_m[0] + length / 2, box_xy_m[1] + width / 2, -height_m + height])
        with np.errstate(divide="ignore", invalid="ignore"):  # slab method
            t1, t2 = low / directions, high / directions
        near = np.nanmax(np.minimum(t1, t2), axis=1)
        far = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (far >= near) & (near > 0) & (near < ranges)
        ranges = np.where(hit, near, ranges)
    ranges = ranges + np.random.default_rng(seed).normal(0.0, 0.01, ranges.shape)
    points = np.empty((len(ranges), 4), dtype=np.float32)
    points[:, :3] = directions * ranges[:, None]
    points[:, 3] = 0.3
    points[ranges > max_range_m] = np.nan
    return points


def frame_meta(
    index: int,
    num_points: int = ROWS * COLUMNS,
    *,
    rows: int = ROWS,
    columns: int = COLUMNS,
    organized: bool = True,
    source_id: str = "lidar-mast",
) -> LidarFrameMeta:
    return LidarFrameMeta(
        site=SITE.site_id,
        source_id=source_id,
        stamp=index / RATE_HZ,
        frame_index=index,
        rows=rows,
        columns=columns,
        num_points=num_points,
        organized=organized,
    )


def site_of_sensor_xy(x_m: float, y_m: float) -> tuple[float, float]:
    """Closed form for the default mast (yaw -90 deg, level): sensor x points south."""
    return MOUNT.pose.x_m + y_m, MOUNT.pose.y_m - x_m


def assert_car_at(batch: DetectionBatch, sensor_xy: tuple[float, float]) -> None:
    expected = site_of_sensor_xy(*sensor_xy)
    near = [d for d in batch.detections if math.dist((d.x_m, d.y_m), expected) < 1.5]
    assert len(near) == 1, f"no single detection near {expected}: {batch.detections}"
    car = near[0]
    assert car.object_class == VehicleClass.CAR
    assert car.heading_rad is not None and abs(math.cos(car.heading_rad)) < 0.2  # along y (N-S)
    covariance = np.array(car.covariance_m2).reshape(2, 2)
    np.testing.assert_allclose(covariance, covariance.T)
    assert np.linalg.eigvalsh(covariance).min() > 0


# --- transforms -----------------------------------------------------------------------------


def box(
    center: tuple[float, float, float],
    heading_rad: float,
    covariance: tuple[tuple[float, float], tuple[float, float]] = ((0.04, 0.0), (0.0, 0.01)),
) -> BoxDetection:
    return BoxDetection(
        center_xyz_m=center,
        size_lwh_m=CAR_LWH_M,
        heading_rad=heading_rad,
        object_class=VehicleClass.CAR,
        num_points=100,
        covariance_xy_m2=covariance,
        score=0.9,
    )


def test_level_mount_closed_form() -> None:
    # The default mast: yaw -90 deg. Sensor (20, 6, -5.25) -> site (7.5 + 6, 980 - 20, 0.75).
    moved = box_to_site(box((20.0, 6.0, -5.25), 0.3), MOUNT.pose)
    assert moved.center_xyz_m == pytest.approx((13.5, 960.0, 0.75), abs=1e-9)
    assert moved.heading_rad == pytest.approx(0.3 - math.pi / 2)
    # Var along the sensor's x (0.04) becomes var along site y; along sensor y (0.01), site x.
    np.testing.assert_allclose(moved.covariance_xy_m2, [[0.01, 0.0], [0.0, 0.04]], atol=1e-12)
    assert moved.size_lwh_m == CAR_LWH_M and moved.num_points == 100
    # Any yaw: heading adds, position rotates.
    pose = Pose(x_m=1.0, y_m=2.0, z_m=3.0, yaw_deg=30.0)
    moved = box_to_site(box((10.0, 0.0, 0.0), 3.0), pose)
    assert moved.center_xyz_m == pytest.approx(
        (1.0 + 10 * math.cos(math.radians(30)), 2.0 + 10 * math.sin(math.radians(30)), 3.0)
    )
    assert moved.heading_rad == pytest.approx(wrap_angle(3.0 + math.radians(30)))
    assert -math.pi < moved.heading_rad <= math.pi


def test_tilted_mount_uses_the_rotated_heading_vector() -> None:
    rng = np.random.default_rng(11)
    for _ in range(50):
        pose = Pose(
            x_m=0.0,
            y_m=0.0,
            z_m=5.0,
            yaw_deg=float(rng.uniform(-180, 180)),
            pitch_deg=float(rng.uniform(-20, 20)),
            roll_deg=float(rng.uniform(-10, 10)),
        )
        heading = float(rng.uniform(-math.pi, math.pi))
        a, b = rng.normal(size=(2, 2))
        c = np.array([[a @ a, a @ b], [a @ b, b @ b]])  # symmetric positive definite
        moved = box_to_site(box((15.0, -3.0, -5.0), heading, (tuple(c[0]), tuple(c[1]))), pose)
        rotation = pose.rotation()
        forward = rotation @ [math.cos(heading), math.sin(heading), 0.0]
        assert moved.heading_rad == pytest.approx(math.atan2(forward[1], forward[0]))
        expected = rotation[:2, :2] @ c @ rotation[:2, :2].T
        np.testing.assert_allclose(moved.covariance_xy_m2, expected, atol=1e-12)
        np.testing.assert_array_equal(moved.covariance_xy_m2, np.transpose(moved.covariance_xy_m2))
        assert np.linalg.eigvalsh(np.array(moved.covariance_xy_m2)).min() >= -1e-12
        np.testing.assert_allclose(
            moved.center_xyz_m, rotation @ [15.0, -3.0, -5.0] + pose.position_m
        )


def test_detection_message_fields() -> None:
    detection = to_detection(box((3.0, 4.0, 1.0), 7.0))
    assert (detection.x_m, detection.y_m) == (3.0, 4.0)
    assert detection.covariance_m2 == [0.04, 0.0, 0.0, 0.01]
    assert (detection.length_m, detection.width_m, detection.height_m) == CAR_LWH_M
    assert detection.heading_rad == pytest.approx(7.0 - 2 * math.pi)
    assert (detection.object_class, detection.score) == (VehicleClass.CAR, 0.9)
    assert detections_in_site([box((1.0, 0.0, 0.0), 0.0)], Pose(x_m=0, y_m=0, z_m=0)) == [
        to_detection(box((1.0, 0.0, 0.0), 0.0))
    ]


# --- the per-frame logic, in process --------------------------------------------------------


def detector(path: str = "fast", **settings: Any) -> tuple[LidarDetector, list[tuple[str, str]]]:
    reports: list[tuple[str, str]] = []
    node = LidarDetector(
        SITE.site_id,
        MOUNT,
        LidarDetectorSettings(path=path, learn_frames=3, **settings),
        report=lambda reason, detail: reports.append((reason, detail)),
    )
    return node, reports


def handle(
    node: LidarDetector, index: int, points: npt.NDArray[np.float32], **meta: Any
) -> DetectionBatch | None:
    return node.handle(frame_meta(index, len(points), **meta), points, time.monotonic())


def test_settings_pick_the_first_lidar() -> None:
    assert lidar_mount(SITE, None).sensor_id == "lidar-mast"
    with pytest.raises(ValueError, match="is a camera, not a LiDAR"):
        lidar_mount(SITE, "camera-mast")
    with pytest.raises(ValueError, match=r"no sensor 'nope'.*lidar-mast"):
        lidar_mount(SITE, "nope")
    settings = LidarDetectorSettings.model_validate({})
    assert (settings.path, settings.sensor_id) == ("fast", None)


def test_reference_path_detects_from_the_first_frame() -> None:
    node, reports = detector("reference")
    assert node.state == ServiceState.RUNNING
    batch = handle(node, 7, synthetic_points((20.0, 6.0)))
    assert batch is not None and reports == []
    assert (batch.stamp, batch.frame_index, batch.source_id) == (7 / RATE_HZ, 7, "lidar-mast")
    assert batch.latency_s > 0
    assert_car_at(batch, (20.0, 6.0))


def test_the_quick_background_is_refined_over_the_refine_span(tmp_path: Path) -> None:
    """A car parked through the quick learning (3 frames) is learned as background; the
    refinement, 10 frames spread over the next second of an empty road, replaces it (and the
    saved file), so a car there is found again: long before ``reveal_frames`` (100) would."""
    saved = tmp_path / "background.npz"
    node, _ = detector("fast", refine_span_s=1.0, refine_frames=10, background_file=saved)
    parked = (20.0, 6.0)
    for index in range(3):
        assert handle(node, index, synthetic_points(parked, seed=index)) is None
    quick = saved.read_bytes()
    batch = handle(node, 3, synthetic_points(parked, seed=3))
    assert batch is not None and batch.detections == []  # part of the quick background
    index = 4
    while index < 4 + 20:  # one second at 20 Hz: the refinement takes every other frame
        handle(node, index, synthetic_points(None, seed=index))
        index += 1
    assert saved.read_bytes() != quick
    batch = handle(node, index, synthetic_points(parked, seed=index))
    assert batch is not None
    assert_car_at(batch, parked)


def test_fast_path_learns_then_detects_and_keeps_layouts(tmp_path: Path) -> None:
    saved = tmp_path / "background.npz"
    node, reports = detector("fast", background_file=saved)
    assert node.state == ServiceState.STARTING
    for index in range(3):  # learning: nothing published
        assert handle(node, index, synthetic_points(None, seed=index)) is None
    assert node.state == ServiceState.RUNNING and saved.is_file()
    batch = handle(node, 3, synthetic_points((20.0, 6.0), seed=3))
    assert batch is not None and batch.stamp == 3 / RATE_HZ
    assert_car_at(batch, (20.0, 6.0))
    # Another layout: counted, learned anew (degraded meanwhile); the first layout is kept.
    small = synthetic_points(None, rows=16, columns=512)
    assert handle(node, 4, small, rows=16, columns=512) is None
    assert [reason for reason, _ in reports] == ["shape_change"]
    assert node.state == ServiceState.DEGRADED
    batch = handle(node, 5, synthetic_points((25.0, -4.0), seed=5))
    assert batch is not None and node.state == ServiceState.RUNNING
    assert_car_at(batch, (25.0, -4.0))
    # A node started later loads the saved background and detects on its first frame.
    loaded, _ = detector("fast", background_file=saved)
    assert loaded.backgrounds.load(saved) and loaded.state == ServiceState.RUNNING
    batch = handle(loaded, 0, synthetic_points((20.0, 6.0), seed=9))
    assert batch is not None
    assert_car_at(batch, (20.0, 6.0))


def test_bad_frames_are_reported_and_the_rest_goes_on() -> None:
    node, reports = detector("reference")
    nan = np.full((ROWS * COLUMNS, 4), np.nan, dtype=np.float32)
    assert handle(node, 0, nan) is None
    absurd = synthetic_points((20.0, 6.0))
    absurd[:50, :3] = 1e6
    absurd[50, 1] = np.inf
    batch = handle(node, 1, absurd)
    assert batch is not None
    assert_car_at(batch, (20.0, 6.0))
    points = synthetic_points(None)[:21]
    assert handle(node, 2, points, rows=7, columns=4, organized=False) is not None
    assert handle(node, 3, points, source_id="other-lidar") is None
    reasons = [reason for reason, _ in reports]
    assert reasons == [
        "no_returns",
        "absurd_coordinates",
        "wrong_shape",
        "shape_change",
        "wrong_sensor",
    ]
    assert "51 points beyond 10000 m" in reports[1][1]

    class Failing:
        def detect(self, frame: PointFrame) -> None:
            raise RuntimeError("core bug")

    node.reference = Failing()  # type: ignore[assignment]
    assert handle(node, 4, synthetic_points(None)) is None
    assert reports[-1] == ("detector_error", "RuntimeError('core bug')")


# --- the node as a process ------------------------------------------------------------------


def wait_status(
    status: Subscription[ServiceStatus],
    condition: Callable[[ServiceStatus], bool],
    what: str,
    timeout_s: float = 15.0,
) -> ServiceStatus:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        message = status.recv(0.5)
        if message is not None and condition(message):
            return message
    pytest.fail(f"timed out waiting for the node's status to show {what}")


def wait_batch(
    detections: Subscription[DetectionBatch], frame_index: int, timeout_s: float = 15.0
) -> DetectionBatch:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        batch = detections.recv(0.5)
        if batch is not None and batch.frame_index == frame_index:
            return batch
    pytest.fail(f"no detection batch for frame {frame_index} within {timeout_s} s")


def test_node_process_learns_detects_and_survives_bad_frames(port: int) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_LIDAR_PATH="fast",
        WZ_LIDAR_LEARN_FRAMES="3",
        WZ_STATUS_PERIOD_S="0.2",
        WZ_LOG_FORMAT="json",
    )
    with Bus.open(settings, site=SITE.site_id, service="node-test") as bus:
        raw_key = bus.keys.raw_lidar("lidar-mast")
        detections = bus.subscribe(bus.keys.detections("lidar-mast"), DetectionBatch)
        status = bus.subscribe(
            bus.keys.status("lidar-detector"), ServiceStatus, mode="ring", capacity=1
        )
        calibrations = bus.subscribe(bus.keys.calibration("lidar-mast"), SensorCalibration)
        raw = bus.publisher(raw_key, LidarFrameMeta, block=True)
        node = subprocess.Popen([sys.executable, "-m", "wz_lidar_detector.node"], cwd=ROOT, env=env)
        try:
            assert raw.wait_for_subscribers(30.0), "the node never subscribed"

            def send(index: int, points: npt.NDArray[np.float32], **meta: Any) -> None:
                raw.put_bytes(encode_lidar_frame(frame_meta(index, len(points), **meta), points))

            # Learning: empty road until the first (empty) batch comes back. The ring keeps
            # only the newest frame, so send one at a time.
            index, first = 0, None
            deadline = time.monotonic() + 30.0
            while first is None and time.monotonic() < deadline:
                send(index, synthetic_points(None, seed=index))
                first = detections.recv(0.3)
                index += 1
            assert first is not None, "the node never finished learning"
            assert first.detections == [] and first.stamp == first.frame_index / RATE_HZ
            assert first.source_id == "lidar-mast" and first.site == SITE.site_id
            # A car driving along the sensor's x axis: one batch per frame, stamped as the frame.
            for step in range(3):
                index += 1
                position = (15.0 + 2.0 * step, 6.0)
                send(index, synthetic_points(position, seed=index))
                batch = wait_batch(detections, index)
                assert batch.stamp == index / RATE_HZ and batch.latency_s > 0
                assert_car_at(batch, position)

            # Bad input, one kind at a time, each counted before the next is sent.
            good = encode_lidar_frame(frame_meta(0), synthetic_points(None))

            def counted(reason: str) -> ServiceStatus:
                key = f"{raw_key}|{reason}"
                return wait_status(status, lambda s: s.invalid_counts.get(key, 0) >= 1, key)

            raw.put_bytes(b"\x00 garbage, not a frame")
            counted("bad_magic")
            raw.put_bytes(good[:-160])  # payload shorter than num_points says
            counted("truncated")
            raw.put_bytes(good + b"\x00" * 16)
            counted("size_mismatch")
            index += 1
            send(index, np.full((ROWS * COLUMNS, 4), np.nan, dtype=np.float32))
            counted("no_returns")
            index += 1
            send(index, synthetic_points(None)[:21], rows=7, columns=4, organized=False)
            counted("wrong_shape")
            counted("shape_change")
            index += 1
            absurd = synthetic_points((20.0, 6.0), seed=index)
            absurd[::97, :3] = -3e7
            send(index, absurd)  # back to the learned layout: detected at once
            assert_car_at(wait_batch(detections, index), (20.0, 6.0))
            counted("absurd_coordinates")

            # A burst faster than the node: the ring drops, the newest frame is processed.
            burst = [synthetic_points((22.0, 6.0), seed=i) for i in range(12)]
            for points in burst:
                index += 1
                send(index, points)
            assert_car_at(wait_batch(detections, index), (22.0, 6.0))
            health = wait_status(
                status, lambda s: s.dropped_counts.get(raw_key, 0) >= 1, "dropped frames"
            )
            assert health.state == ServiceState.RUNNING and health.pid == node.pid
            assert 0 < health.stamp <= index / RATE_HZ  # the newest frame's time, not wall time
            assert node.poll() is None
            # The sensor's self-calibration went out on its key: the synthetic road is level
            # 6 m under the sensor, as the site file says, so nothing is corrected.
            learned = list(iter(lambda: calibrations.recv(0.5), None))
            assert learned, "no calibration message from the node"
            assert {m.source_id for m in learned} == {"lidar-mast"}
            assert learned[0].sensor_kind == "lidar"
            assert learned[-1].state in (CalibrationState.PRIOR, CalibrationState.LEARNING)
            assert abs(learned[-1].correction.pitch_deg) < 0.05
            assert abs(learned[-1].correction.z_m) < 0.02
        finally:
            node.send_signal(signal.SIGTERM)
            assert node.wait(15.0) == 0


def test_column_clock_times_each_detection_by_its_azimuth() -> None:
    """Columns fire across the sweep; the clock reads each column's azimuth from the returns
    (here the simulator's convention: column j looks at pi - 2 pi j / N) and gives a point
    the time of the column nearest its azimuth."""
    rows, columns, sweep_s = 4, 360, 0.05
    azimuth = math.pi - 2.0 * math.pi * np.arange(columns) / columns
    image = np.full((rows, columns, 4), np.nan, dtype=np.float32)
    image[:, :, 0] = 10.0 * np.cos(azimuth)
    image[:, :, 1] = 10.0 * np.sin(azimuth)
    image[:, :, 2] = -1.0
    image[:, :, 3] = 1.0
    image[0, 7, :3] = np.nan  # a column with a missing return still has its azimuth
    frame = PointFrame(points=image.reshape(-1, 4), rows=rows, columns=columns, stamp_s=0.0)
    clock = ColumnClock(frame, sweep_s)
    # Straight ahead (+x) is the middle column; behind, just left of the seam, the first ones.
    ahead, left, behind = clock.offsets_s([5.0, 0.0, -5.0], [0.0, 5.0, 0.1])
    assert ahead == pytest.approx(0.5 * sweep_s)
    assert left == pytest.approx(0.25 * sweep_s)
    assert behind == pytest.approx(1 / columns * sweep_s, abs=1.5 / columns * sweep_s)


def test_a_knocked_sensor_makes_the_node_degraded_and_relearns_its_background() -> None:
    node, _ = detector("fast")
    node.calibration.site = SITE  # the site's road: the detector learns its pose from it
    for index in range(3):
        handle(node, index, synthetic_points(None, seed=index))
    assert node.state == ServiceState.RUNNING
    node.calibration.log.enter(CalibrationState.BUMPED, 1.0, "test: turned 2 deg")
    assert node.state == ServiceState.DEGRADED
    node._relearn_background("test")
    assert not node.backgrounds.has_background  # learned again from the next frames
