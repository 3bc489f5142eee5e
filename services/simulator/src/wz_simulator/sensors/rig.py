"""The sensor rig: every sensor of the site, each firing at its own rate on simulation time.

The traffic world gives truth every step (0.05 s); sensors run at their own rates (LiDAR 20 Hz,
camera 10 Hz, radar 15 Hz in the default site), so a sensor's firing time rarely equals a step's
time. :meth:`SensorRig.fire` takes the truth of a step and produces every frame due up to that
step's time, each at its exact firing time: vehicles are moved from the truth's time to the
firing time along their heading at their speed (|dt| < one step). Frames are numbered per sensor
from 0, and the n-th firing happens at ``n / rate_hz`` exactly (no drift).

A real mast (``mast``: :class:`~wz_simulator.sensors.mast.MastModel`, off by default). Each
model is built on its sensor's mount as it really stands (the site file's pose plus the set-up
error), and every capture renders from the sensor's true orientation at that instant: the LiDAR
turns its head (:meth:`LidarModel.turn_to`, the static scene cast again) to its orientation
half-way through the sweep, the radar turns (:meth:`RadarModel.turn_to`), the camera's frame is
turned by the homography of its sway and settling (:meth:`CameraModel.render`'s ``rotation``;
a bumped camera has a second model, built on its bumped mount, for the frames after the bump).
Stamps stay on the schedule: frame n is still stamped ``n / rate_hz`` and fires then, but it
was captured ``clock_offset_s`` earlier (vehicles moved back to that instant, at most one step
plus 150 ms, along their heading at their speed): a frame captured at ``t`` carries ``t +
offset``, and arrives no earlier than its stamp, as a late-stamping sensor's does. Everything
published stays nominal: the metadata carries no pose and :attr:`SensorRig.site` is the site
given. Without a mast every frame is the same, bit for bit, as before the model existed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from wz_shared.messages import CameraFrameMeta, VehicleTruth
from wz_shared.site import SensorMount, Site
from wz_simulator.sensors.camera import CameraFrame, CameraModel, encode_jpeg
from wz_simulator.sensors.lidar import LidarModel, LidarScan
from wz_simulator.sensors.mast import MastModel
from wz_simulator.sensors.radar import RadarModel, RadarScanResult
from wz_simulator.sensors.scene import StaticScene, Weather, static_scene, vehicle_boxes

#: Vehicles farther than this along the road from a camera are not drawn [m] (sub-pixel).
CAMERA_CULL_STATION_M = 600.0
#: Vehicles this much beyond a LiDAR's maximum range are not cast [m] (a truck is 16.5 m).
LIDAR_CULL_MARGIN_M = 30.0


# Each output's ``capture_s`` is the true time the frame shows [s]: its stamp less the sensor's
# clock offset (the stamp itself without a mast model). It is not published.


@dataclass(frozen=True)
class LidarOutput:
    sensor_id: str
    scan: LidarScan
    capture_s: float


@dataclass(frozen=True)
class CameraOutput:
    sensor_id: str
    meta: CameraFrameMeta
    frame: CameraFrame
    jpeg: bytes
    capture_s: float


@dataclass(frozen=True)
class RadarOutput:
    sensor_id: str
    result: RadarScanResult
    capture_s: float


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
    scene
        The static scene (default: ``static_scene(site)``).
    mast
        A real mast's errors, clocks and motion (see the module docstring); None: every sensor
        exactly at its site pose, with a perfect clock.
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
        mast: MastModel | None = None,
    ) -> None:
        self.site = site
        self.mast = mast
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
        self._mount_of = {mount.sensor_id: mount for mount in self.mounts}
        self._lidars: dict[str, LidarModel] = {}
        self._cameras: dict[str, CameraModel] = {}
        #: A bumped camera's model on its bumped mount, and the bump's time.
        self._bumped_cameras: dict[str, tuple[float, CameraModel]] = {}
        self._radars: dict[str, RadarModel] = {}
        self._camera_station_m: dict[str, float] = {}
        self._camera_forward_xy: dict[str, tuple[float, float]] = {}
        self._schedules: dict[str, _Schedule] = {}
        for position, site_mount in enumerate(site.sensors):
            if site_mount not in self.mounts:
                continue
            # Where the sensor really stands: its model draws from there.
            mount = site_mount if mast is None else mast.mounted(site_mount)
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
                bump = None if mast is None else mast.bump
                if mast is not None and bump is not None and bump.sensor_id == mount.sensor_id:
                    # Built now, not at the bump: a background takes up to a second to draw.
                    bumped_mount = mast.mounted(site_mount, bump.at_s)
                    self._bumped_cameras[mount.sensor_id] = (
                        bump.at_s,
                        CameraModel.from_scene(bumped_mount, self.scene, weather, sensor_seed),
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
        """One frame of one sensor stamped ``fire_s``, outside the schedule (datasets, pictures).

        It shows the road at ``fire_s`` less the sensor's clock offset (none without a mast
        model; at 0 when that is negative), seen from the sensor's true pose then (see the
        module docstring).
        """
        mast = self.mast
        # A late clock's first frames (stamped before its offset) show the road at 0: there is
        # no road before the simulation starts.
        capture_s = fire_s if mast is None else max(0.0, fire_s - mast.clock_offset_s(sensor_id))
        mount = self._mount_of[sensor_id]
        if sensor_id in self._lidars:
            lidar = self._lidars[sensor_id]
            if mast is not None:
                # The head's orientation half-way through the sweep (the sway turns it by at
                # most a few hundredths of a degree in one).
                mid_sweep_s = capture_s + 0.5 * lidar.sweep_duration_s
                lidar.turn_to(mast.rotation_at(mount, mid_sweep_s))
            # Vehicles the beams cannot reach are left out: labels index the vehicles passed.
            reach_m = lidar.max_range_m + LIDAR_CULL_MARGIN_M
            x0, y0 = float(lidar.position_m[0]), float(lidar.position_m[1])
            near = [v for v in vehicles if math.hypot(v.x_m - x0, v.y_m - y0) < reach_m]
            scan = lidar.scan(near, capture_s, index, truth_stamp_s=truth_stamp_s)
            if capture_s != fire_s:
                scan = replace(scan, meta=scan.meta.model_copy(update={"stamp": fire_s}))
            return LidarOutput(sensor_id, scan, capture_s)
        now = moved(vehicles, capture_s - truth_stamp_s)
        if sensor_id in self._cameras:
            camera = self._cameras[sensor_id]
            bumped = self._bumped_cameras.get(sensor_id)
            if bumped is not None and capture_s >= bumped[0]:
                camera = bumped[1]
            rotation = None
            if mast is not None:
                rotation = mast.rotation_at(mount, capture_s)
                if np.array_equal(rotation, camera.rotation):
                    rotation = None  # as the model was drawn: nothing to turn
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
                capture_s,
                [v.vehicle_class for v in seen],
                rotation=rotation,
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
            jpeg = encode_jpeg(frame.image, self.jpeg_quality)
            return CameraOutput(sensor_id, meta, frame, jpeg, capture_s)
        radar = self._radars[sensor_id]
        if mast is not None:
            radar.turn_to(mast.rotation_at(mount, capture_s))
        result = radar.scan(now, capture_s, index)
        if capture_s != fire_s:
            stamped = result.scan.model_copy(update={"stamp": fire_s})
            result = RadarScanResult(scan=stamped, target_vehicle_ids=result.target_vehicle_ids)
        return RadarOutput(sensor_id, result, capture_s)
