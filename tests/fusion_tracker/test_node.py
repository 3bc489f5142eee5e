"""The fusion tracker node as its own process on real Zenoh: detections of two asynchronous
sensors in, one confirmed track per vehicle out at 10 Hz, the latest batch on query, bad input
counted and the node alive."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from wz_fusion_tracker.node import FusionCore, process_noise
from wz_fusion_tracker.settings import FusionTrackerSettings, TrackerSettings
from wz_shared.bus import Bus
from wz_shared.messages import (
    Detection,
    DetectionBatch,
    ServiceStatus,
    TrackBatch,
    TrackStatus,
)
from wz_shared.motion import ProcessNoise
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, load_site

ROOT = Path(__file__).resolve().parents[2]
SITE = load_site(DEFAULT_SITE_PATH)
# Two northbound vehicles upstream of the mast (7.5, 980), one per lane, at 25 and 30 m/s.
VEHICLES = ((-1.83, 880.0, 25.0), (1.83, 860.0, 30.0))


def truth_at(t: float) -> list[tuple[float, float]]:
    return [(x, y + v * t) for x, y, v in VEHICLES]


def batch(
    sensor: str,
    index: int,
    t: float,
    rng: np.random.Generator,
    std: float,
    covariance: list[float] | None = None,
    site: str | None = None,
) -> DetectionBatch:
    detections = [
        Detection(
            x_m=x + rng.normal(0, std),
            y_m=y + rng.normal(0, std),
            covariance_m2=covariance or [std**2, 0.0, 0.0, std**2],
            object_class="car",
            length_m=4.6,
            width_m=1.8,
        )
        for x, y in truth_at(t)
    ]
    return DetectionBatch(
        site=site or SITE.site_id,
        source_id=sensor,
        stamp=t,
        frame_index=index,
        detections=detections,
    )


def test_core_publishes_a_batch_per_output_period_with_road_coordinates() -> None:
    rng = np.random.default_rng(2)
    core = FusionCore(SITE, FusionTrackerSettings(), report=lambda r, d: None)
    outputs: list[TrackBatch] = []
    for k in range(60):  # 3 s of LiDAR at 20 Hz
        outputs += core.add(batch("lidar-mast", k, 0.05 * k, rng, 0.2))
    stamps = [b.stamp for b in outputs]
    assert np.allclose(np.diff(stamps), 0.1, atol=0.051)  # on the 10 Hz grid, by a batch
    assert [b.cycle_index for b in outputs] == list(range(len(outputs)))
    last = outputs[-1]
    assert len(last.tracks) == 2
    for track, (x, y) in zip(
        sorted(last.tracks, key=lambda t: t.x_m), truth_at(last.stamp), strict=True
    ):
        assert math.hypot(track.x_m - x, track.y_m - y) < 0.5
        station, offset = SITE.road_frame.to_road(x, y)
        assert track.station_m == pytest.approx(float(station), abs=0.5)
        assert track.offset_m == pytest.approx(float(offset), abs=0.5)
        assert track.lane_index == (0 if offset < 0 else 1)
        assert track.status == TrackStatus.CONFIRMED and track.sources == ["lidar-mast"]


def test_track_batches_carry_the_process_noise_of_the_trackers_settings() -> None:
    """The gateway smooths with what the batches carry: the tracker's settings, which are the
    motion model's defaults unless changed."""
    assert process_noise(TrackerSettings()) == ProcessNoise()
    tracker = TrackerSettings(
        sigma_along_mps2=2.5, sigma_across_mps2=1.5, heading_min_speed_mps=1.0
    )
    core = FusionCore(SITE, FusionTrackerSettings(tracker=tracker), report=lambda r, d: None)
    rng = np.random.default_rng(3)
    outputs: list[TrackBatch] = []
    for k in range(20):
        outputs += core.add(batch("lidar-mast", k, 0.05 * k, rng, 0.2))
    assert outputs and all(b.process_noise == ProcessNoise(2.5, 1.5, 1.0) for b in outputs)
    decoded = TrackBatch.model_validate_json(outputs[-1].model_dump_json())
    assert decoded.process_noise == ProcessNoise(2.5, 1.5, 1.0)


def test_the_imm_motion_model_is_chosen_from_the_environment_and_tracks(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("WZ_FUSION_TRACKER__MOTION_MODEL", "imm")
    settings = FusionTrackerSettings()
    assert settings.tracker.motion_model == "imm"
    rng = np.random.default_rng(2)
    core = FusionCore(SITE, settings, report=lambda r, d: None)
    outputs: list[TrackBatch] = []
    for k in range(60):
        outputs += core.add(batch("lidar-mast", k, 0.05 * k, rng, 0.2))
    last = outputs[-1]
    assert len(last.tracks) == 2
    for track, (x, y) in zip(
        sorted(last.tracks, key=lambda t: t.x_m), truth_at(last.stamp), strict=True
    ):
        assert math.hypot(track.x_m - x, track.y_m - y) < 0.5
    monkeypatch.setenv("WZ_FUSION_TRACKER__MOTION_MODEL", "kalman")
    with pytest.raises(ValueError, match="motion_model"):
        FusionTrackerSettings()


def test_core_starts_a_new_run_when_a_sensor_starts_again() -> None:
    """A restarted simulation counts from its start again: the sensors' stamps go back. The
    first batches of the new run are late; from the third, a new run: tracks again, their ids
    after the old ones, the output grid on the new stamps."""
    rng = np.random.default_rng(4)
    reports: list[str] = []
    core = FusionCore(SITE, FusionTrackerSettings(), report=lambda r, d: reports.append(r))
    first: list[TrackBatch] = []
    for k in range(60):  # 3 s
        first += core.add(batch("lidar-mast", k, 0.05 * k, rng, 0.2))
    old_ids = {t.track_id for t in first[-1].tracks}
    assert len(old_ids) == 2 and core.runs == 1
    second: list[TrackBatch] = []
    for k in range(60):  # the same 3 s again, from 0
        second += core.add(batch("lidar-mast", 100 + k, 0.05 * k, rng, 0.2))
    assert core.runs == 2
    assert reports == ["late", "late"]  # the two batches before the new run was certain
    assert second and second[0].stamp < 0.5 and second[-1].stamp > 2.5
    assert np.allclose(np.diff([b.stamp for b in second]), 0.1, atol=0.051)
    assert [b.cycle_index for b in second] == list(range(len(first), len(first) + len(second)))
    new_ids = {t.track_id for t in second[-1].tracks}
    assert len(new_ids) == 2 and min(new_ids) > max(old_ids)  # never reused
    for track, (x, y) in zip(
        sorted(second[-1].tracks, key=lambda t: t.x_m), truth_at(second[-1].stamp), strict=True
    ):
        assert math.hypot(track.x_m - x, track.y_m - y) < 0.5


def test_node_process_tracks_two_sensors_and_survives_bad_input(port: int) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_STATUS_PERIOD_S="0.2",
        WZ_LOG_FORMAT="json",
    )
    rng = np.random.default_rng(5)
    with Bus.open(settings, site=SITE.site_id, service="node-test") as bus:
        lidar = bus.publisher(bus.keys.detections("lidar-mast"), DetectionBatch, block=True)
        camera = bus.publisher(bus.keys.detections("camera-mast"), DetectionBatch, block=True)
        tracks = bus.subscribe(bus.keys.tracks, TrackBatch)
        status = bus.subscribe(
            bus.keys.status("fusion-tracker"), ServiceStatus, mode="ring", capacity=1
        )
        node = subprocess.Popen([sys.executable, "-m", "wz_fusion_tracker.node"], cwd=ROOT, env=env)
        try:
            assert lidar.wait_for_subscribers(30.0), "the node never subscribed"
            assert camera.wait_for_subscribers(10.0)
            # 3 s of data at about 4x real time: LiDAR at 20 Hz, camera at 10 Hz, offset.
            for k in range(60):
                t = 0.05 * k
                lidar.put(batch("lidar-mast", k, t, rng, 0.2))
                if k % 2 == 1:
                    camera.put(batch("camera-mast", k // 2, t + 0.013, rng, 0.8))
                time.sleep(0.0125)
            received: list[TrackBatch] = []
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline and (not received or received[-1].stamp < 2.8):
                message = tracks.recv(0.5)
                if message is not None:
                    received.append(message)
            assert received and received[-1].stamp >= 2.8
            last = received[-1]
            assert len(last.tracks) == 2
            assert {tuple(t.sources) for t in last.tracks} == {("camera-mast", "lidar-mast")}
            ids = {t.track_id for t in last.tracks}
            assert all({t.track_id for t in b.tracks} == ids for b in received if b.stamp > 1.0)
            for track in last.tracks:
                error = min(
                    math.hypot(track.x_m - x, track.y_m - y) for x, y in truth_at(last.stamp)
                )
                assert error < 0.5
                assert track.speed_mps == pytest.approx(25.0 if track.x_m < 0 else 30.0, abs=1.0)
            (latest,) = bus.query(bus.keys.tracks_latest, TrackBatch)
            assert latest.stamp >= last.stamp

            def counted(reason: str, times: int = 1) -> None:
                name = f"{bus.keys.detections_all}|{reason}"
                deadline = time.monotonic() + 20.0
                while time.monotonic() < deadline:
                    message = status.recv(0.5)
                    if message is not None and message.invalid_counts.get(name, 0) >= times:
                        return
                pytest.fail(f"{name} never counted")

            # A covariance that is not one: the bus refuses the batch (Covariance2 checks it).
            bad = batch("lidar-mast", 100, 3.05, rng, 0.2).model_dump(mode="json")
            bad["detections"][0]["covariance_m2"] = [1.0, 0.0, 0.0, -1.0]
            lidar.put_bytes(json.dumps(bad).encode())
            counted("invalid")
            lidar.put(batch("lidar-mast", 101, 3.1, rng, 0.2, site="elsewhere"))
            counted("wrong_site")
            lidar.put(batch("lidar-mast", 5, 0.25, rng, 0.2))  # long past the reorder window
            counted("late")
            lidar.put_bytes(b'{"kind": "detection_batch", "detections": "garbage"}')
            counted("invalid", times=2)
            # Still tracking. The wall time spent above moved the tracker's clock on (no
            # detections came): within max_outage_coast_s of data time the tracks coasted
            # through the silence and keep their ids; beyond it they ended and the vehicles get
            # new tracks, with ids never reused.
            for k in range(102, 116):
                lidar.put(batch("lidar-mast", k, 0.05 * k, rng, 0.2))
            message = None
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline:
                message = tracks.recv(0.5)
                if message is not None and message.stamp >= 5.6:
                    break
            assert message is not None and message.stamp >= 5.6
            assert len(message.tracks) == 2
            now_ids = {t.track_id for t in message.tracks}
            assert now_ids == ids or min(now_ids) > max(ids), (now_ids, ids)
            assert node.poll() is None
        finally:
            node.send_signal(signal.SIGTERM)
            assert node.wait(15.0) == 0
