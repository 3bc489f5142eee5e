"""The simulator node as a real process: truth over Zenoh, site queryable, health, shutdown."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from wz_shared.bus import Bus
from wz_shared.messages import (
    CameraFrameMeta,
    GroundTruth,
    LidarFrameMeta,
    PointSensorReading,
    RadarScan,
    ServiceStatus,
)
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, Site, load_site

ROOT = Path(__file__).resolve().parents[2]


def test_simulator_node_publishes_truth_and_serves_site(port: int, tmp_path: Path) -> None:
    site = load_site(DEFAULT_SITE_PATH)
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    with Bus.open(settings, site=site.site_id, service="node-test") as bus:
        truth = bus.subscribe(bus.keys.truth, GroundTruth)
        status = bus.subscribe(bus.keys.status("simulator"), ServiceStatus)
        env = {
            **os.environ,
            "WZ_BUS_CONNECT_ENDPOINTS": f"tcp/127.0.0.1:{port}",
            "WZ_BUS_LISTEN_ENDPOINTS": "",
            "WZ_SIM_REALTIME_FACTOR": "4",
            "WZ_SIM_WORK_DIR": str(tmp_path),
            "WZ_STATUS_PERIOD_S": "0.5",
            "WZ_SIM_SENSORS_ENABLED": "false",
        }
        node = subprocess.Popen([sys.executable, "-m", "wz_simulator.node"], cwd=ROOT, env=env)
        try:
            messages: list[GroundTruth] = []
            deadline = time.monotonic() + 60.0
            while time.monotonic() < deadline and not any(m.vehicles for m in messages[-1:]):
                # The first waits for the node's start (its imports: seconds on a loaded box).
                message = truth.recv(5.0 if messages else 30.0)
                assert message is not None, "no truth from the simulator"
                messages.append(message)
            assert messages[-1].vehicles, "no vehicle appeared within 60 s"
            steps = [m.step_index for m in messages]
            assert steps == list(range(steps[0], steps[0] + len(steps)))  # FIFO: none lost
            stamps = [m.stamp for m in messages]
            assert all(abs((b - a) - 0.05) < 1e-6 for a, b in itertools.pairwise(stamps))
            vehicle = messages[-1].vehicles[0]
            assert vehicle.station_m < 300 and vehicle.speed_mps > 10
            health = status.recv(10.0)
            assert health is not None and health.pid == node.pid
            assert bus.alive() == [bus.keys.status("simulator")]
            served = bus.query_bytes(bus.keys.config_site, timeout_s=5.0)
            assert len(served) == 1 and Site.model_validate_json(served[0]) == site
        finally:
            node.send_signal(signal.SIGTERM)
            assert node.wait(15.0) == 0
        # Gone from liveliness once stopped.
        deadline = time.monotonic() + 5.0
        while bus.alive() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert bus.alive() == []


def run_node_to_the_end(env: dict[str, str]) -> None:
    """Run the simulator node with ``env`` until it exits by itself (its duration), successfully."""
    node = subprocess.Popen([sys.executable, "-m", "wz_simulator.node"], cwd=ROOT, env=env)
    try:
        assert node.wait(120.0) == 0
    finally:
        if node.poll() is None:
            node.kill()


def test_simulator_node_publishes_every_sensor_at_its_rate(port: int, tmp_path: Path) -> None:
    """Truth at 20 Hz, LiDAR 20 Hz, camera 10 Hz, radar 15 Hz, all on simulation time."""
    site = load_site(DEFAULT_SITE_PATH)
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    with Bus.open(settings, site=site.site_id, service="node-test") as bus:
        keys = bus.keys
        lidar = bus.subscribe_frames(
            keys.raw_lidar("lidar-mast"), LidarFrameMeta, mode="fifo", capacity=64
        )
        camera = bus.subscribe_frames(
            keys.raw_camera("camera-mast"), CameraFrameMeta, mode="fifo", capacity=64
        )
        radar = bus.subscribe(keys.raw_radar("radar-mast"), RadarScan)
        truth = bus.subscribe(keys.truth, GroundTruth)
        env = {
            **os.environ,
            "WZ_BUS_CONNECT_ENDPOINTS": f"tcp/127.0.0.1:{port}",
            "WZ_BUS_LISTEN_ENDPOINTS": "",
            "WZ_SIM_REALTIME_FACTOR": "1",
            "WZ_SIM_DURATION_S": "4",
            "WZ_SIM_WORK_DIR": str(tmp_path),
        }
        run_node_to_the_end(env)
        lidar_frames = lidar.drain()
        camera_frames = camera.drain()
        radar_scans = radar.drain()
        truths = truth.drain()
    # Subscribers were declared first, but the node's publishers need a moment to match: the
    # first frames may be missed. After that, frames arrive in order, at their own stamps;
    # sensor frames are published with congestion control "drop" (a stale frame is worthless,
    # `Bus.publisher`), so on a loaded machine one may go missing (CI lost LiDAR frame 1 of
    # 80 once), but hardly any. Radar scans and truth are never dropped.
    assert len(truths) >= 70
    for frames, rate_hz in ((lidar_frames, 20.0), (camera_frames, 10.0)):
        indices = [frame.meta.frame_index for frame in frames]
        assert len(indices) >= 0.8 * 4 * rate_hz
        assert indices == sorted(set(indices))
        assert len(indices) >= 0.9 * (indices[-1] - indices[0] + 1)
        for frame in frames:
            assert abs(frame.meta.stamp - frame.meta.frame_index / rate_hz) < 1e-9
    scans = [scan.scan_index for scan in radar_scans]
    assert len(scans) >= 0.8 * 4 * 15 and scans == list(range(scans[0], scans[0] + len(scans)))
    assert all(abs(s.stamp - s.scan_index / 15.0) < 1e-9 for s in radar_scans)
    points = lidar_frames[-1].points()
    assert points.shape == (64 * 2048, 4)
    assert np.isfinite(points[:, 0]).mean() > 0.5  # ground and roadside return
    jpeg = bytes(camera_frames[-1].payload)
    image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (1200, 1200, 3)
    assert any(scan.targets for scan in radar_scans)


def test_simulator_node_warms_up_before_it_publishes(port: int, tmp_path: Path) -> None:
    """With a warm-up, the node simulates traffic first, publishing nothing ("starting"): the
    first truth and frames come after it, on a road with vehicles as far as the sensors, each
    sensor's frames numbered on simulation time as without one."""
    site = load_site(DEFAULT_SITE_PATH)
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    with Bus.open(settings, site=site.site_id, service="node-test") as bus:
        keys = bus.keys
        lidar = bus.subscribe_frames(
            keys.raw_lidar("lidar-mast"), LidarFrameMeta, mode="fifo", capacity=64
        )
        truth = bus.subscribe(keys.truth, GroundTruth)
        status = bus.subscribe(keys.status("simulator"), ServiceStatus)
        env = {
            **os.environ,
            "WZ_BUS_CONNECT_ENDPOINTS": f"tcp/127.0.0.1:{port}",
            "WZ_BUS_LISTEN_ENDPOINTS": "",
            "WZ_SIM_REALTIME_FACTOR": "1",
            "WZ_SIM_WARMUP_S": "45",
            "WZ_SIM_DURATION_S": "47",  # the warm-up counts: 2 s published
            "WZ_SIM_SEED": "3",
            "WZ_SIM_WORK_DIR": str(tmp_path),
            "WZ_STATUS_PERIOD_S": "0.2",
        }
        run_node_to_the_end(env)
        truths = truth.drain()
        frames = lidar.drain()
        states = [s.state.value for s in status.drain()]
    assert truths and frames
    assert all(45.0 < t.stamp <= 47.0 + 1e-9 for t in truths)
    assert truths[0].step_index > 45.0 / 0.05 - 1  # the warm-up's steps count
    # Traffic all along the road, within the LiDAR's range (the mast is at station 980) too.
    stations = [v.station_m for v in truths[0].vehicles]
    assert len(stations) >= 5 and max(stations) > 850.0, stations
    assert all(f.meta.stamp > 45.0 for f in frames)
    assert all(abs(f.meta.stamp - f.meta.frame_index / 20.0) < 1e-9 for f in frames)
    assert states[0] == "starting" and "running" in states


def test_simulator_node_publishes_the_point_sensors_each_interval(
    port: int, tmp_path: Path
) -> None:
    """The default site's two upstream point speed sensors (every 30 s): a reading each at 30
    and 60 s of simulation, per lane, at the site file's stations."""
    site = load_site(DEFAULT_SITE_PATH)
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    with Bus.open(settings, site=site.site_id, service="node-test") as bus:
        points = bus.subscribe(bus.keys.point_sensors_all, PointSensorReading)
        env = {
            **os.environ,
            "WZ_BUS_CONNECT_ENDPOINTS": f"tcp/127.0.0.1:{port}",
            "WZ_BUS_LISTEN_ENDPOINTS": "",
            "WZ_SIM_REALTIME_FACTOR": "0",
            "WZ_SIM_DURATION_S": "61",
            "WZ_SIM_SENSORS_ENABLED": "false",
            "WZ_SIM_WORK_DIR": str(tmp_path),
        }
        run_node_to_the_end(env)
        readings = points.drain()
    stations = {p.sensor_id: p.station_m for p in site.point_sensors}
    # The node's publishers need a moment to match the subscriber: the first may be missed.
    got = {(r.source_id, r.stamp) for r in readings}
    assert {("speed-1", 60.0), ("speed-2", 60.0)} <= got
    assert got <= {(name, stamp) for name in stations for stamp in (30.0, 60.0)}
    for r in readings:
        assert r.station_m == stations[r.source_id] and len(r.lanes) == 2
    # by 60 s the first vehicles have passed both (the road starts empty)
    assert all(sum(lane.vehicle_count for lane in r.lanes) > 0 for r in readings if r.stamp == 60.0)
