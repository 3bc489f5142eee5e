"""One valid example of every message type, for bus and codec tests."""

from __future__ import annotations

import numpy as np

from wz_shared import codec
from wz_shared.messages import (
    ActiveAlerts,
    Alert,
    CameraFrameMeta,
    Detection,
    DetectionBatch,
    GroundTruth,
    LidarFrameMeta,
    Message,
    PoseCorrection,
    RadarScan,
    RadarTarget,
    RoadsideDeviceState,
    SensorCalibration,
    ServiceState,
    ServiceStatus,
    Track,
    TrackBatch,
    VehicleTruth,
)

SITE = "test-site"
# The smallest valid JPEG: SOI, EOI (the codec checks the SOI marker only).
TINY_JPEG = b"\xff\xd8\xff\xd9"


def json_samples(i: int = 0) -> list[Message]:
    """One message of every JSON type, numbered ``i``."""
    stamp = 10.0 + 0.05 * i
    vehicle = VehicleTruth(
        vehicle_id=f"veh{i}",
        vehicle_class="car",
        x_m=1.0,
        y_m=2.0,
        heading_rad=1.57,
        speed_mps=30.0,
        accel_mps2=-0.5,
        length_m=4.6,
        width_m=1.8,
        height_m=1.5,
        lane_index=0,
        station_m=500.0,
        offset_m=-1.83,
        driver_profile="normal",
    )
    detection = Detection(x_m=1.0, y_m=2.0, covariance_m2=[0.5, 0.0, 0.0, 0.5], score=0.9)
    track = Track(
        track_id=i,
        x_m=1.0,
        y_m=2.0,
        vx_mps=0.0,
        vy_mps=30.0,
        covariance=[0.0] * 16,
        station_m=500.0,
        offset_m=-1.8,
        speed_mps=30.0,
        heading_rad=1.57,
        lane_index=0,
        age_s=1.0,
        hits=3,
        confirmed=True,
        sources=["lidar-mast"],
    )
    alert = Alert(
        site=SITE,
        source_id="alert-service",
        stamp=stamp,
        alert_id=f"al{i}",
        alert_type="speeding",
        severity="warning",
        track_id=i,
        station_m=500.0,
        offset_m=-1.8,
        speed_mps=33.0,
        measured_value=33.0,
        threshold_value=29.0,
        description="speeding 74 mph in a 55 mph zone",
        phase="start",
        episode_id=f"speeding-{i}-1",
        onset_stamp=stamp - 1.0,
        value_unit="m/s",
        evidence={"speed_limit_mps": 24.5872, "excess_mps": 8.4128},
        track=track,
    )
    devices = RoadsideDeviceState(
        site=SITE,
        source_id="alert-service",
        stamp=stamp,
        beacon_on=True,
        sign_text="SLOW DOWN",
        cause="speeding",
    )
    return [
        RadarScan(
            site=SITE,
            source_id="radar-mast",
            stamp=stamp,
            scan_index=i,
            targets=[
                RadarTarget(range_m=50.0, azimuth_rad=0.1, radial_speed_mps=-30.0, rcs_dbsm=10.0)
            ],
        ),
        GroundTruth(
            site=SITE, source_id="simulator", stamp=stamp, step_index=i, vehicles=[vehicle]
        ),
        DetectionBatch(
            site=SITE, source_id="lidar-mast", stamp=stamp, frame_index=i, detections=[detection]
        ),
        TrackBatch(
            site=SITE, source_id="fusion-tracker", stamp=stamp, cycle_index=i, tracks=[track]
        ),
        alert,
        devices,
        ActiveAlerts(
            site=SITE, source_id="alert-service", stamp=stamp, alerts=[alert], devices=devices
        ),
        ServiceStatus(
            site=SITE,
            source_id="fusion-tracker",
            stamp=stamp,
            service="fusion-tracker",
            state=ServiceState.RUNNING,
            uptime_s=1.0,
            pid=1,
        ),
        SensorCalibration(
            site=SITE,
            source_id="cam-1",
            stamp=stamp,
            sensor_kind="camera",
            state="calibrated",
            state_since_s=1.0,
            correction=PoseCorrection(yaw_deg=0.8, yaw_std_deg=0.05, pitch_deg=-0.3),
            clock_offset_s=0.08,
            clock_offset_std_s=0.004,
            samples=120 + i,
        ),
    ]


def lidar_frame(i: int, num_points: int = 1024, seed: int = 0) -> tuple[LidarFrameMeta, np.ndarray]:
    rng = np.random.default_rng(seed + i)
    points = rng.normal(size=(num_points, 4)).astype(np.float32)
    meta = LidarFrameMeta(
        site=SITE,
        source_id="lidar-mast",
        stamp=0.05 * i,
        frame_index=i,
        rows=1,
        columns=num_points,
        num_points=num_points,
        organized=False,
    )
    return meta, points


def camera_frame(i: int) -> tuple[CameraFrameMeta, bytes]:
    meta = CameraFrameMeta(
        site=SITE,
        source_id="camera-mast",
        stamp=0.1 * i,
        frame_index=i,
        width_px=1200,
        height_px=1200,
    )
    return meta, TINY_JPEG


def encoded_lidar(i: int, num_points: int = 1024) -> bytes:
    meta, points = lidar_frame(i, num_points)
    return codec.encode_lidar_frame(meta, points)
