"""The sensor rig: every sensor of the site, each firing at its own rate on simulation time.

The traffic world gives truth every step (0.05 s); sensors run at their own rates (LiDAR 20 Hz,
camera 10 Hz, radar 15 Hz in the default site), so a sensor's firing time rarely equals a step's
time. :meth:`SensorRig.fire` takes the truth of a step and produces every frame due up to that
step's time, each at its exact firing time: vehicles are moved from the truth's time to the
firing time along their heading at their speed (|dt| < one step). Frames are numbered per sensor
from 0, and the n-th firing happens at ``n / rate_hz`` exactly (no drift).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wz_shared.messages import CameraFrameMeta, VehicleTruth
from wz_shared.site import SensorMount, Site
from wz_simulator.sensors.camera import CameraFrame, CameraModel, encode_jpeg
from wz_simulator.sensors.lidar import LidarModel, LidarScan
from wz_simulator.sensors.radar import RadarModel, RadarScanResult
from wz_simulator.sensors.scene import StaticScene, Weather, static_scene, vehicle_boxes

#: Vehicles farther than this along the road from a camera are not drawn [m] (sub-pixel).
CAMERA_CULL_STATION_M = 600.0
#: Vehicles this much beyond a LiDAR's maximum range are not cast [m] (a truck is 16.5 m).
LIDAR_CULL_MARGIN_M = 30.0


@dataclass(frozen=True)
class LidarOutput:
    sensor_id: str
    scan: LidarScan


@dataclass(frozen=True)
class CameraOutput:
    sensor_id: str
    meta: CameraFrameMeta
    frame: CameraFrame
    jpeg: bytes


@dataclass(frozen=True)
class RadarOutput:
    sensor_id: str
    result: RadarScanResult


SensorOutput = LidarOutput | CameraOutput | RadarOutput


def moved(vehicles: Sequence[VehicleTruth], dt_s: float) -> list[VehicleTruth]:
    """The vehicles ``dt_s`` seconds later, at constant speed along their heading."""
    if dt_s == 0.0:
        return list(vehicles)
    return [
        vehicle.model_copy(
            update={
                "x_m": vehicle.x_m + vehicle.speed_mps * dt_s * math.cos(vehicle.heading_rad),
                "y_m": vehicle.y_m + vehicle.speed_mps * dt_s * math.sin(vehicle.heading_rad),
                "station_m": vehicle.station_m + vehicle.speed_mps * dt_s,
            }
        )
        for vehicle in vehicles
    ]


class _Schedule:
    """Firing times ``n / rate_hz`` of one sensor."""

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.next_index = 0

    @property
    def next_time_s(self) -> float:
        return self.next_index / self.rate_hz


class SensorRig:
    """The site's sensors (or the ones named), built once on the static scene.

    Parameters
    ----------
    site
        Sensor mounts and the work zone the static scene is built from.
    weather
        Conditions for every model.
    seed
        Base seed; each sensor draws from its own stream (seed + its position in the site).
    sensor_ids
        Sensors to simulate (default: all of the site's).
    jpeg_quality
        Camera JPEG quality (1-100).
    """

    def __init__(
        self,
        site: Site,
        weather: Weather,
        seed: int,
        *,
        sensor_ids: Sequence[str] | None = None,
        jpeg_quality: int = 90,
        scene: StaticScene | None = None,
    ) -> None:
        self.site = site
        self.weather = weather
        self.jpeg_quality = jpeg_quality
        self.scene = scene if scene is not None else static_scene(site)
        wanted = set(sensor_ids) if sensor_ids is not None else None
        self.mounts: list[SensorMount] = [
            mount for mount in site.sensors if wanted is None or mount.sensor_id in wanted
        ]
        if wanted is not None and wanted - {mount.sensor_id for mount in self.mounts}:
            missing = sorted(wanted - {mount.sensor_id for mount in self.mounts})
            raise ValueError(f"site {site.site_id} has no sensor {missing}")
        self._lidars: dict[str, LidarModel] = {}
        self._cameras: dict[str, CameraModel] = {}
        self._radars: dict[str, RadarModel] = {}
        self._camera_station_m: dict[str, float] = {}
        self._camera_forward_xy: dict[str, tuple[float, float]] = {}
        self._schedules: dict[str, _Schedule] = {}
        for position, mount in enumerate(site.sensors):
            if mount not in self.mounts:
                continue
            sensor_seed = seed * 1000 + position
            if mount.kind == "lidar":
                self._lidars[mount.sensor_id] = LidarModel.from_scene(
                    mount,
                    self.scene,
                    weather,
                    sensor_seed,
                    boxes_for=vehicle_boxes,
                    site_id=site.site_id,
                )
            elif mount.kind == "camera":
                self._cameras[mount.sensor_id] = CameraModel.from_scene(
                    mount, self.scene, weather, sensor_seed
                )
                station, _ = site.road_frame.to_road(mount.pose.x_m, mount.pose.y_m)
                self._camera_station_m[mount.sensor_id] = float(station)
                forward = mount.pose.rotation()[:, 0]
                norm = float(np.hypot(forward[0], forward[1])) or 1.0
                self._camera_forward_xy[mount.sensor_id] = (forward[0] / norm, forward[1] / norm)
            else:
                self._radars[mount.sensor_id] = RadarModel(
                    mount, weather, sensor_seed, site_id=site.site_id
                )
            self._schedules[mount.sensor_id] = _Schedule(mount.rate_hz)

    def skip_until(self, t_s: float) -> None:
        """Leave out every firing at or before ``t_s`` (the simulation ran without sensors
        until then: a warm-up); frame indices stay ``round(fire time * rate)``."""
        for schedule in self._schedules.values():
            first = math.floor(t_s * schedule.rate_hz + 1e-9) + 1
            schedule.next_index = max(schedule.next_index, first)

    def due(self, until_s: float) -> list[tuple[str, int, float]]:
        """Firings due up to ``until_s``: (sensor id, frame index, time), in time order."""
        firings = []
        for sensor_id, schedule in self._schedules.items():
            index = schedule.next_index
            while index / schedule.rate_hz <= until_s + 1e-9:
                firings.append((sensor_id, index, index / schedule.rate_hz))
                index += 1
        return sorted(firings, key=lambda firing: (firing[2], firing[0]))

    def fire(
        self, vehicles: Sequence[VehicleTruth], truth_stamp_s: float, until_s: float | None = None
    ) -> list[SensorOutput]:
        """Every frame due up to ``until_s`` (default: the truth's time), in time order."""
        outputs: list[SensorOutput] = []
        for sensor_id, index, fire_s in self.due(truth_stamp_s if until_s is None else until_s):
            outputs.append(self.capture(sensor_id, index, fire_s, vehicles, truth_stamp_s))
            self._schedules[sensor_id].next_index = index + 1
        return outputs

    def capture(
        self,
        sensor_id: str,
        index: int,
        fire_s: float,
        vehicles: Sequence[VehicleTruth],
        truth_stamp_s: float,
    ) -> SensorOutput:
        """One frame of one sensor at ``fire_s``, outside the schedule (datasets, pictures)."""
        if sensor_id in self._lidars:
            lidar = self._lidars[sensor_id]
            # Vehicles the beams cannot reach are left out: labels index the vehicles passed.
            reach_m = lidar.max_range_m + LIDAR_CULL_MARGIN_M
            x0, y0 = float(lidar.position_m[0]), float(lidar.position_m[1])
            near = [v for v in vehicles if math.hypot(v.x_m - x0, v.y_m - y0) < reach_m]
            scan = lidar.scan(near, fire_s, index, truth_stamp_s=truth_stamp_s)
            return LidarOutput(sensor_id, scan)
        now = moved(vehicles, fire_s - truth_stamp_s)
        if sensor_id in self._cameras:
            camera = self._cameras[sensor_id]
            station = self._camera_station_m[sensor_id]
            fx, fy = self._camera_forward_xy[sensor_id]
            cx, cy = camera.camera.position_m[0], camera.camera.position_m[1]
            # In front of the camera (a vehicle's length of slack) and not beyond sight.
            seen = [
                v
                for v in now
                if abs(v.station_m - station) < CAMERA_CULL_STATION_M
                and (v.x_m - cx) * fx + (v.y_m - cy) * fy > -v.length_m
            ]
            frame = camera.render(
                vehicle_boxes(seen),
                [v.vehicle_id for v in seen],
                fire_s,
                [v.vehicle_class for v in seen],
            )
            height, width = frame.image.shape[:2]
            meta = CameraFrameMeta(
                site=self.site.site_id,
                source_id=sensor_id,
                stamp=fire_s,
                frame_index=index,
                width_px=width,
                height_px=height,
                rendered=True,
            )
            return CameraOutput(sensor_id, meta, frame, encode_jpeg(frame.image, self.jpeg_quality))
        result = self._radars[sensor_id].scan(now, fire_s, index)
        return RadarOutput(sensor_id, result)
