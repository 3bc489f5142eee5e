"""The perception pipeline on the simulated work zone, in one process, on simulation time.

:func:`run_pipeline` steps SUMO (:class:`TrafficWorld`), fires the site's sensors at their own
rates (:class:`SensorRig`: LiDAR 20 Hz, camera 10 Hz, radar 15 Hz on the default site) and runs
the detectors' own per-frame code on every frame: :class:`LidarDetector.handle` (fast path,
learning its background during the warm-up) and :meth:`CameraDetector.process_frame` (YOLO where due, flow between,
image tracking, ranging, radar fusion). It records, in time order:

- the truth of every step (20 Hz);
- each detector's :class:`DetectionBatch` as the node would publish it (site frame); the camera
  channel's detections are its fused camera+radar objects, as on the bus;
- per camera frame, the camera-only positions (calibrated pinhole, before radar fusion);
- per radar scan, the targets converted to the site frame (echo points, no camera).

The last two exist only for evaluation ("camera alone", "radar alone"). With
``PipelineOptions.mount_errors`` the sensors are a real mast's (:mod:`wz_simulator.sensors.mast`:
set-up errors, late clocks, sway, settling and an optional bump, drawn from the seed): the
frames come from the true poses while both detectors keep the site file's, as in the field;
the drawn model is kept in :attr:`PipelineRecord.mast` for the report. No bus is involved:
the same code as the nodes, without serialisation, deterministic for a seed. Processes and
Zenoh are tested elsewhere (``tests/*/test_node*.py``, ``tests/integration``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wz_camera_detector.association import (
    AssociationSettings,
    radar_targets_to_site,
    to_detection,
)
from wz_camera_detector.calibration import CameraSelfCalibration
from wz_camera_detector.node import CameraDetector
from wz_camera_detector.radar_calibration import RadarSelfCalibration
from wz_camera_detector.settings import CameraDetectorSettings, camera_mount, radar_mount
from wz_lidar_detector.calibration import LidarSelfCalibration
from wz_lidar_detector.node import LidarDetector
from wz_lidar_detector.settings import LidarDetectorSettings, lidar_mount
from wz_shared.capacity import closure_capacity_vph
from wz_shared.messages import (
    Detection,
    DetectionBatch,
    PointSensorReading,
    SensorCalibration,
    VehicleTruth,
)
from wz_shared.site import Site
from wz_simulator.sensors.mast import Bump, MastModel
from wz_simulator.sensors.rig import CameraOutput, LidarOutput, RadarOutput, SensorRig
from wz_simulator.sensors.scene import WEATHER_PRESETS
from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.world import TrafficWorld

log = logging.getLogger("wz_eval.pipeline")

#: The detectors start this many simulated seconds into the run at the latest [s]: traffic is
#: on the road by then, and the rest of the warm-up is the sensors' self-calibration.
DETECT_FROM_S = 30.0


def ramp_settings(warmup_s: float, duration_s: float) -> dict[str, float]:
    """A ramp inside the scored window: free flow (0.6 of capacity) through the warm-up, the
    flow rising over the first tenth of the scored time, held for half of it, falling over a
    tenth and free flow for the last three tenths, in which the queue dissolves."""
    return {
        "ramp_base_ratio": 0.6,
        "ramp_start_s": warmup_s,
        "ramp_rise_s": 0.1 * duration_s,
        "ramp_hold_s": 0.5 * duration_s,
        "ramp_fall_s": 0.1 * duration_s,
    }


def demand_conditions(site: Site, options: PipelineOptions) -> dict[str, Any]:
    """The run's demand for its report: the flow (the ramp's peak), the ratio asked (None: a
    flow was asked), the flow's share of the closure's capacity, the capacity and the profile."""
    capacity_vph = closure_capacity_vph(site, options.truck_share)
    flow_vph = options.vehicles_per_hour
    if options.demand_ratio is not None:
        flow_vph = options.demand_ratio * capacity_vph
    return {
        "vehicles_per_hour": round(flow_vph, 1) if options.demand_ratio is not None else flow_vph,
        "demand_ratio": options.demand_ratio,
        "share_of_capacity": round(flow_vph / capacity_vph, 3),
        "capacity_vph": round(capacity_vph, 1),
        "demand_profile": options.demand_profile,
        "work_zone_headways": options.demand_ratio is not None,
    }


@dataclass(frozen=True)
class PipelineOptions:
    """What to simulate. Times in simulated seconds."""

    seed: int = 7
    duration_s: float = 600.0
    #: Simulated before scoring starts: traffic fills the road, the LiDAR learns its background.
    warmup_s: float = 60.0
    weather: str = "day"
    vehicles_per_hour: float = 1400.0
    #: Demand as a share of the closure's capacity (replaces ``vehicles_per_hour``); None: off.
    demand_ratio: float | None = None
    #: ``steady``, or ``ramp``: a queue forms and dissolves in the scored window
    #: (:func:`ramp_settings`).
    demand_profile: str = "steady"
    truck_share: float = 0.15
    aggressive_share: float = 0.2
    camera_model: Path | None = None
    work_dir: Path | None = None
    #: A real mast's sensors (:mod:`wz_simulator.sensors.mast`); False: exactly at the site's.
    mount_errors: bool = False
    #: A sensor knocked round at a simulation time (needs ``mount_errors``).
    bump: Bump | None = None
    #: The sensors learn their poses and clocks (the detectors' self-calibration, on by
    #: default as in the services); False: the site file's poses and the stamps as they come.
    self_calibration: bool = True


@dataclass(frozen=True)
class SourcePoint:
    """A position from one sensor alone (camera-only or radar echo), for evaluation."""

    x_m: float
    y_m: float
    speed_mps: float | None = None


@dataclass
class PipelineRecord:
    """Everything :func:`run_pipeline` saw, in time order per list."""

    site: Site
    options: PipelineOptions
    truth: list[tuple[float, list[VehicleTruth]]] = field(default_factory=list)
    batches: list[DetectionBatch] = field(default_factory=list)
    camera_only: list[tuple[float, list[SourcePoint]]] = field(default_factory=list)
    radar_only: list[tuple[float, list[SourcePoint]]] = field(default_factory=list)
    #: The site's upstream point sensors' readings (warm-up included), in time order.
    point_readings: list[PointSensorReading] = field(default_factory=list)
    problems: dict[str, int] = field(default_factory=dict)
    wall_s: float = 0.0
    #: The mast model the sensors were rendered with (None: the nominal poses).
    mast: MastModel | None = None
    #: Each sensor's self-calibration at the end of the run, by sensor id.
    calibrations: dict[str, SensorCalibration] = field(default_factory=dict)
    #: Each sensor's changes of calibration state: (stamp, state, detail), by sensor id.
    calibration_history: dict[str, list[tuple[float, str, str]]] = field(default_factory=dict)

    def sensor_ids(self) -> list[str]:
        return sorted({batch.source_id for batch in self.batches})


def run_pipeline(
    site: Site,
    options: PipelineOptions,
    progress: Callable[[float, float], None] | None = None,
) -> PipelineRecord:
    """Simulate and detect; ``progress(sim_s, total_s)`` is called about once a simulated second.

    Raises
    ------
    ValueError
        When a bump is asked for without ``mount_errors``, or names a sensor the site lacks.
    """
    started = time.perf_counter()
    if options.bump is not None and not options.mount_errors:
        raise ValueError("a bump needs mount_errors (the mast model it is part of)")
    mast = MastModel.draw(site, options.seed, options.bump) if options.mount_errors else None
    record = PipelineRecord(site=site, options=options, mast=mast)

    def report(reason: str, detail: str) -> None:
        record.problems[reason] = record.problems.get(reason, 0) + 1

    lidar = lidar_mount(site, None)
    camera = camera_mount(site, None)
    radar = radar_mount(site, None)
    lidar_settings = LidarDetectorSettings.model_validate(
        {
            "path": "fast",
            "learn_frames": 40,
            "calibration": {"enabled": options.self_calibration},
        }
    )
    lidar_detector = LidarDetector(site.site_id, lidar, lidar_settings, report, site=site)
    camera_kwargs: dict[str, object] = {
        "backend": "yolo",
        "calibration": {"enabled": options.self_calibration},
        "radar_id": radar.sensor_id if radar is not None else "none",
    }
    if options.camera_model is not None:
        camera_kwargs["model_path"] = options.camera_model
    camera_settings = CameraDetectorSettings.model_validate(camera_kwargs)
    camera_detector = CameraDetector(site, camera, radar, camera_settings, report, rendered=True)
    association = AssociationSettings()
    sensor_ids = [lidar.sensor_id, camera.sensor_id] + ([radar.sensor_id] if radar else [])
    rig = SensorRig(
        site, WEATHER_PRESETS[options.weather], options.seed, sensor_ids=sensor_ids, mast=mast
    )
    total_s = options.warmup_s + options.duration_s
    sim_settings: dict[str, object] = {
        "seed": options.seed,
        "realtime_factor": 0.0,
        "sensors_enabled": False,
        "vehicles_per_hour": options.vehicles_per_hour,
        "demand_ratio": options.demand_ratio,
        "demand_profile": options.demand_profile,
        # Demand stated against HCM's capacity needs a closure that carries it.
        "work_zone_headways": options.demand_ratio is not None,
        **(
            ramp_settings(options.warmup_s, options.duration_s)
            if options.demand_profile == "ramp"
            else {}
        ),
        "truck_share": options.truck_share,
        "aggressive_share": options.aggressive_share,
        "duration_s": total_s,
    }
    if options.work_dir is not None:
        sim_settings["work_dir"] = options.work_dir
    # The detectors start before the scoring: the LiDAR learns its background from the first
    # frames with traffic on the road, and every sensor learns its pose and clock from the
    # warm-up's traffic (the self-calibration, on as in the services).
    detect_from_s = max(0.0, min(options.warmup_s - 10.0, DETECT_FROM_S))
    next_progress_s = 0.0
    with TrafficWorld(site, SimulatorSettings.model_validate(sim_settings)) as world:
        while not world.finished:
            vehicles = world.step()
            now_s = world.sim_time_s
            if now_s >= options.warmup_s:
                record.truth.append((now_s, vehicles))
            record.point_readings += world.point_readings()
            if progress is not None and now_s >= next_progress_s:
                progress(now_s, total_s)
                next_progress_s += 1.0
            for output in rig.fire(vehicles, now_s):
                if isinstance(output, LidarOutput):
                    if output.scan.meta.stamp < detect_from_s:
                        continue
                    batch = lidar_detector.handle(
                        output.scan.meta, output.scan.points, time.monotonic()
                    )
                    if batch is None:
                        continue
                    camera_detector.lidar_batch(batch)
                    if batch.stamp >= options.warmup_s:
                        record.batches.append(batch)
                elif isinstance(output, RadarOutput):
                    scan = output.result.scan
                    camera_detector.radar_scan(scan)
                    own = camera_detector.radar_calibration
                    stamp_s = scan.stamp - (own.clock_offset_s if own is not None else 0.0)
                    if stamp_s >= options.warmup_s and camera_detector.radar_mount is not None:
                        points = radar_targets_to_site(
                            scan.targets, camera_detector.radar_mount, association
                        )
                        record.radar_only.append(
                            (stamp_s, [SourcePoint(p.x_m, p.y_m) for p in points])
                        )
                elif isinstance(output, CameraOutput):
                    if output.meta.stamp < detect_from_s:
                        continue
                    result = camera_detector.process_frame(
                        output.jpeg, output.meta.stamp, output.meta.frame_index
                    )
                    if result is None or result.stamp_s < options.warmup_s:
                        continue
                    stamp_s = result.stamp_s
                    record.camera_only.append(
                        (stamp_s, [SourcePoint(o.x_m, o.y_m) for o in result.camera_objects])
                    )
                    detections: list[Detection] = []
                    for fused in result.fused:
                        try:
                            detections.append(to_detection(fused))
                        except ValueError:
                            report("bad_detection", str(fused))
                    record.batches.append(
                        DetectionBatch(
                            site=site.site_id,
                            source_id=camera.sensor_id,
                            stamp=stamp_s,
                            frame_index=output.meta.frame_index,
                            detections=detections,
                        )
                    )
    owners: list[LidarSelfCalibration | CameraSelfCalibration | RadarSelfCalibration] = [
        lidar_detector.calibration,
        camera_detector.calibration,
    ]
    if camera_detector.radar_calibration is not None:
        owners.append(camera_detector.radar_calibration)
    for owner in owners:
        message = owner.message()
        record.calibrations[message.source_id] = message
        record.calibration_history[message.source_id] = [
            (stamp, str(state), detail) for stamp, state, detail in owner.log.history
        ]
    record.batches.sort(key=lambda b: (b.stamp, b.source_id))
    record.wall_s = time.perf_counter() - started
    return record
