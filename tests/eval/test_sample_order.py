"""``evaluate`` on a record whose camera stamps step back: the camera's learned clock offset grew
between two frames (seen on a generated site: 0 to 68 ms at once), so a frame's stamp lies
before one already taken. The tracks are not sampled back in time: the sample is counted and
skipped, and the run is scored (it used to stop with the tracker's ValueError)."""

from __future__ import annotations

import math

import numpy as np

from wz_eval.fusion import EvalOptions, evaluate, lidar_mount
from wz_eval.pipeline import PipelineOptions, PipelineRecord, SourcePoint
from wz_shared.messages import Detection, DetectionBatch, VehicleClass, VehicleTruth
from wz_shared.site import DEFAULT_SITE_PATH, load_site


def test_a_camera_stamp_that_steps_back_is_counted_not_fatal() -> None:
    site = load_site(DEFAULT_SITE_PATH)
    lidar = lidar_mount(site, None)
    road = site.road_frame
    mast_station = float(road.to_road(lidar.pose.x_m, lidar.pose.y_m)[0])
    camera_id = next(m.sensor_id for m in site.sensors if "camera" in m.sensor_id)
    speed = 25.0
    record = PipelineRecord(site=site, options=PipelineOptions(duration_s=4.0, warmup_s=0.0))

    def car_at(t_s: float) -> tuple[float, float, float, VehicleTruth]:
        station = mast_station - 80.0 + speed * t_s
        x, y = (float(v) for v in road.to_site(station, -1.8))
        heading = float(road.heading_at(station))
        truth = VehicleTruth(
            vehicle_id="v1",
            vehicle_class=VehicleClass.CAR,
            x_m=x,
            y_m=y,
            z_m=0.75,
            heading_rad=heading,
            speed_mps=speed,
            accel_mps2=0.0,
            length_m=4.5,
            width_m=1.8,
            height_m=1.5,
            lane_index=0,
            station_m=station,
            offset_m=-1.8,
            driver_profile="normal",
        )
        return x, y, heading, truth

    for k in range(80):  # 4 s: truth at 20 Hz, the LiDAR at 20 Hz
        t = 0.05 * k
        x, y, heading, truth = car_at(t)
        record.truth.append((t, [truth]))
        box = Detection(
            x_m=x,
            y_m=y,
            covariance_m2=[0.01, 0.0, 0.0, 0.01],
            object_class=VehicleClass.CAR,
            length_m=4.5,
            width_m=1.8,
            heading_rad=heading,
        )
        record.batches.append(
            DetectionBatch(
                site=site.site_id,
                source_id=lidar.sensor_id,
                stamp=t,
                frame_index=k,
                detections=[box],
            )
        )
    # The camera at 10 Hz; from frame 20 on its stamps are 120 ms earlier (its offset learned):
    # frame 20 lies 20 ms before frame 19.
    stamps = [0.1 * k for k in range(20)] + [0.1 * k - 0.12 for k in range(20, 40)]
    for k, stamp in enumerate(stamps):
        x, y, _, _ = car_at(stamp)
        record.camera_only.append((stamp, [SourcePoint(x, y)]))
        record.batches.append(
            DetectionBatch(
                site=site.site_id, source_id=camera_id, stamp=stamp, frame_index=k, detections=[]
            )
        )
    record.batches.sort(key=lambda b: b.stamp)
    report = evaluate(site, EvalOptions(duration_s=4.0, warmup_s=0.0), record)
    assert report["samples_out_of_order"] == 1
    assert report["mota"] > 0.5 and math.isfinite(report["mota"])
    assert np.isfinite(report["sources"]["fused"]["rmse_longitudinal_m"])
