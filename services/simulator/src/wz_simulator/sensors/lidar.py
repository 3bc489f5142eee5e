"""A spinning multi-beam LiDAR by ray casting (open3d ``RaycastingScene``), as a pure core.

The model stands in for the mast LiDAR of the paper (a 64-beam spinning unit, -30 to +11 deg,
200 m, 20 Hz; an Ouster in the field). Each sweep it returns an *organized* frame: one cell per
beam and azimuth step, NaN where the beam got no return, with truth labels and truth boxes for
evaluation.

Geometry
--------
- Sensor frame: x forward, y left, z up. Site frame: ENU metres. ``p_site = R @ p_sensor +
  position`` with ``R = Rz(yaw) Ry(-pitch) Rx(roll)`` (right-handed elementary rotations; the
  minus makes positive pitch raise the x axis, as the :class:`~wz_shared.site.Pose` docstring
  and the radar model read it).
- Beams (rows): ``beams`` elevations evenly spaced, row 0 the *highest* (``vertical_max_deg``)
  down to row ``beams - 1`` at ``vertical_min_deg`` (image order: the organized frame displays
  upright).
- Columns: column ``j`` points at azimuth ``pi - 2 pi j / azimuth_steps`` (counter-clockwise
  from the sensor's x axis): column 0 looks backwards, the middle column forwards, and the head
  spins clockwise seen from above, as common spinning sensors do. The seam (where a sweep's end
  meets its start) is thus behind the sensor, away from the traffic it faces.
- Point order: row-major, beam then column: point ``i * azimuth_steps + j`` is beam ``i``,
  column ``j``; ``points.reshape(beams, azimuth_steps, 4)`` is the range image.
- Timing: column ``j`` fires at ``sweep_start + j / azimuth_steps / rate_hz`` (as in
  :class:`~wz_shared.messages.LidarFrameMeta`).

Scene and ray casting
---------------------
The static scene (boxes, ground polygons triangulated by ear clipping at their layer height
``z_m``, and a large base ground plane at z = 0 so that every downward beam meets the ground) is
cast once, at construction, with every ray; the distance, surface and incidence of each ray's
first static hit are cached. Each frame casts only rays that can meet a vehicle, against
vehicles only, and keeps per ray the nearer of the static and the vehicle hit. A head that
turns (:meth:`LidarModel.turn_to`: a real mast's sway, settling or a bump, see
:mod:`~wz_simulator.sensors.mast`) casts the static scene again with its new rays.

Vehicles move during a sweep, and each column sees them where they are when it fires: the
boxes of ``boxes_for(vehicles, dt)`` (called once per frame, at the sweep start) move with the
truth velocity ``v (cos h, sin h, 0)``, so a ray of column j meets vehicle k at its position at
``t_j``. Rather than moving the vehicles, the model moves the rays: each vehicle stands once, at
its sweep-start position, in its own "universe" (space translated by more than twice the maximum
range from the others), and a ray that may meet vehicle k is cast in k's universe from
``origin - v_k t_j``, where the relative geometry is the same. One small scene, one build and one
cast per frame, with exact column timing; a ray that may meet several vehicles is cast once per
vehicle and the nearest hit wins (so vehicles occlude one another). Only the faces of a box that
turn towards the sensor somewhere in the sweep enter the scene (a ray from outside meets a front
face first), which halves the build.

Which rays may meet vehicle k is decided per sector (``sectors`` equal runs of columns, default
32) from the volume its body's box sweeps during the sector: the exact azimuth interval of that
volume (from its corners) gives the columns, and the exact elevation interval of the volume it
sweeps during the whole sweep (corners and the apexes of its edges' great-circle arcs) gives the
beams. On a work-zone approach this casts about 1.6 rays per vehicle return.

Rooms
-----
- :mod:`~wz_simulator.sensors.lidar_geometry`: box triangles, ground polygons (ear clipping),
  the static mesh, and the exact azimuth/elevation extents behind the ray culling.
- :mod:`~wz_simulator.sensors.lidar_physics`: the physics of one return (material response,
  fog and rain extinction, detection threshold, dropouts, range noise) and the settings
  (:class:`LidarPhysics`).
- :mod:`~wz_simulator.sensors.lidar_frame`: what a sweep hands on (:class:`LidarScan`, truth
  boxes).
- here, :class:`LidarModel`: the beam pattern (rows, columns, timing, sectors), the static cast
  once, and each sweep: vehicle bodies, culled rays cast in per-vehicle universes, dropouts,
  noise, rain clutter, the organized frame.

Randomness: every frame draws from ``numpy.random.default_rng((seed, frame_index))``, so a frame
depends only on the seed, its index and its inputs, never on the frames before it (a replay or a
rebuilt model reproduces it). Draw order: dropouts, range noise, rain clutter.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import open3d as o3d

from wz_shared.arrays import F32, F64, I32, IntP
from wz_shared.messages import LidarFrameMeta, VehicleTruth
from wz_shared.sensor_mounts import intrinsics_of
from wz_shared.site import LidarIntrinsics, SensorMount

# Re-exported (``X as X``): these moved to the lidar_* rooms, their names stay here.
from wz_simulator.sensors.lidar_frame import LidarScan as LidarScan
from wz_simulator.sensors.lidar_frame import LidarTruthBox as LidarTruthBox
from wz_simulator.sensors.lidar_geometry import (
    BOX_FACE_CORNERS,
    SWEPT_BOX_EDGES,
    azimuth_extent,
    centred_grid,
    elevation_extent,
    static_mesh,
)
from wz_simulator.sensors.lidar_geometry import BOX_TRIANGLES as BOX_TRIANGLES
from wz_simulator.sensors.lidar_geometry import box_corners as box_corners
from wz_simulator.sensors.lidar_geometry import triangulate_polygon as triangulate_polygon
from wz_simulator.sensors.lidar_physics import KOSCHMIEDER as KOSCHMIEDER
from wz_simulator.sensors.lidar_physics import MATERIAL_RESPONSE as MATERIAL_RESPONSE
from wz_simulator.sensors.lidar_physics import LidarPhysics as LidarPhysics
from wz_simulator.sensors.lidar_physics import (
    ReturnPhysics,
    Returns,
    empty_returns,
    incidence_cosine,
    standard_normal,
)
from wz_simulator.sensors.lidar_physics import SurfaceResponse as SurfaceResponse
from wz_simulator.sensors.lidar_physics import fog_extinction_per_m as fog_extinction_per_m
from wz_simulator.sensors.lidar_physics import rain_extinction_per_m as rain_extinction_per_m
from wz_simulator.sensors.scene import STATIC_LABEL, Box, GroundPolygon, Weather

#: ``boxes_for(vehicles, dt_s)``: the vehicles' bodies as boxes moved ``dt_s`` seconds from the
#: truth's stamp, each labelled with the 1-based index of its vehicle (``scene.vehicle_boxes``).
BoxesFor = Callable[[Sequence[VehicleTruth], float], list[Box]]

#: Slack on interval ends (columns, radians) against float round-off in the ray culling.
_COLUMN_SLACK = 0.01
_ELEVATION_SLACK_RAD = 1e-4


class StaticSceneLike(Protocol):
    """What the model needs of a static scene (``scene.StaticScene`` fits)."""

    @property
    def boxes(self) -> Sequence[Box]: ...

    @property
    def ground(self) -> Sequence[GroundPolygon]: ...


@dataclass(frozen=True)
class _VehicleBodies:
    """One frame's vehicle boxes at the sweep start, sorted by label (sensor-centred site frame).

    ``m`` vehicles have a body; vehicle ``j`` of them owns boxes ``start[j] : start[j] +
    count[j]``.
    """

    corners_m: F64  # (nb, 8, 3)
    labels: IntP  # (nb,)
    materials: IntP  # (nb,)
    vehicle_index: IntP  # (m,) 0-based index into the frame's truth
    start: IntP  # (m,)
    count: IntP  # (m,)
    hull_center_m: F64  # (m, 3) heading-aligned bounding box of the body
    hull_size_m: F64  # (m, 3)
    heading_rad: F64  # (m,)
    velocity_mps: F64  # (m, 3)


class LidarModel:
    """Simulated spinning LiDAR: static scene once, vehicle truth per sweep, organized frames.

    Parameters
    ----------
    mount : SensorMount
        Sensor id, pose and :class:`LidarIntrinsics` (beams, vertical span, azimuth steps,
        maximum range, range noise); ``rate_hz`` is the spin rate.
    static_boxes : sequence of Box
        What does not move (labels ignored: static points are labelled 0).
    static_ground : sequence of GroundPolygon
        Ground polygons, each at its layer height ``z_m``. A base ground plane is added at
        z = 0 (or 1 cm below the lowest polygon, if any lies at or below 0).
    weather : Weather
        Fog and rain (extinction, rain clutter); light is ignored.
    seed : int
        Seed of the frame generators (frame ``i`` draws from ``(seed, i)``).
    boxes_for : callable
        ``boxes_for(vehicles, dt_s) -> list[Box]``: the vehicles' bodies ``dt_s`` seconds after
        the truth's stamp, labelled 1..len(vehicles) (``scene.vehicle_boxes``).
    site_id : str
        Site of the frame metadata.
    physics : LidarPhysics
        Model settings.
    """

    def __init__(
        self,
        mount: SensorMount,
        static_boxes: Sequence[Box],
        static_ground: Sequence[GroundPolygon],
        weather: Weather,
        seed: int,
        *,
        boxes_for: BoxesFor,
        site_id: str = "sim",
        physics: LidarPhysics | None = None,
    ) -> None:
        intrinsics = intrinsics_of(mount, LidarIntrinsics, "LidarModel needs lidar intrinsics")
        self.physics = physics if physics is not None else LidarPhysics()
        self.physics.validate(intrinsics)
        self.mount = mount
        self.intrinsics = intrinsics
        self.weather = weather
        self.seed = seed
        self.site_id = site_id
        self.boxes_for = boxes_for

        intrinsics, physics = self.intrinsics, self.physics
        self.rows = intrinsics.beams
        self.columns = intrinsics.azimuth_steps
        self.num_rays = self.rows * self.columns
        self.sweep_duration_s = 1.0 / mount.rate_hz
        self.max_range_m = intrinsics.max_range_m
        pose = mount.pose
        self.position_m: F64 = np.array([pose.x_m, pose.y_m, pose.z_m])
        self.rotation: F64 = pose.rotation()
        self.extinction_per_m = fog_extinction_per_m(
            weather.fog_visibility_m, physics.wavelength_nm
        ) + rain_extinction_per_m(
            weather.rain_mm_per_h,
            physics.rain_attenuation_db_per_km,
            physics.rain_attenuation_exponent,
        )

        # --- rays ---------------------------------------------------------------------------
        #: Beam elevations [rad], row 0 the highest, shape (rows,).
        self.elevations_rad: F64 = np.radians(
            np.linspace(intrinsics.vertical_max_deg, intrinsics.vertical_min_deg, self.rows)
        )
        self._elevations_ascending = self.elevations_rad[::-1].copy()
        #: Column azimuths [rad] in the sensor frame, shape (columns,).
        self.azimuths_rad: F64 = np.pi - 2.0 * np.pi * np.arange(self.columns) / self.columns
        cos_el = np.cos(self.elevations_rad)[:, None]
        directions = np.stack(
            np.broadcast_arrays(
                cos_el * np.cos(self.azimuths_rad)[None, :],
                cos_el * np.sin(self.azimuths_rad)[None, :],
                np.sin(self.elevations_rad)[:, None],
            ),
            axis=-1,
        ).reshape(-1, 3)
        #: Unit ray directions in the sensor frame, (rows * columns, 3), point order.
        self.ray_directions_sensor: F64 = directions
        self._rays = np.empty((self.num_rays, 6), dtype=np.float32)
        self._aim_rays(directions @ self.rotation.T)
        # Sensor-frame directions by axis, (3, rows * columns): points = direction * range.
        self._directions_by_axis = np.ascontiguousarray(directions.T, dtype=np.float32)

        # --- timing and sectors -------------------------------------------------------------
        column = np.arange(self.columns)
        #: Firing time of each column after the sweep start [s], shape (columns,).
        self.column_time_offsets_s: F64 = column * self.sweep_duration_s / self.columns
        self._column_time_s = self.column_time_offsets_s.astype(np.float32)
        #: Sector of each column (the unit of ray culling), shape (columns,).
        self.sector_of_column: IntP = (column * physics.sectors) // self.columns
        first = np.searchsorted(self.sector_of_column, np.arange(physics.sectors), side="left")
        last = np.searchsorted(self.sector_of_column, np.arange(physics.sectors), side="right") - 1
        self._sector_first_column: IntP = first
        self._sector_last_column: IntP = last

        # --- static scene, cast once (and again when the head turns: turn_to) ----------------
        self._return_physics = ReturnPhysics(physics, self.extinction_per_m, self.max_range_m)
        vertices, triangles, triangle_material = static_mesh(
            static_boxes,
            static_ground,
            self.position_m,
            self.max_range_m,
            physics.base_ground_material,
        )
        self._static_scene = o3d.t.geometry.RaycastingScene()
        self._static_scene.add_triangles(
            o3d.core.Tensor.from_numpy(vertices), o3d.core.Tensor.from_numpy(triangles)
        )
        self._static_material = triangle_material
        self._cast_static()

    def _aim_rays(self, directions_site: F64) -> None:
        """Aim the rays along ``directions_site``, (rows * columns, 3), the sensor's beams in the
        site frame (``ray_directions_sensor @ rotation.T``)."""
        #: Unit ray directions in the site frame, (rows * columns, 3).
        self.ray_directions_site: F64 = directions_site
        # Rays for open3d in the sensor-centred site frame (small coordinates keep float32
        # precise): origin at the blind-zone distance along the direction, then the direction.
        self._rays[:, :3] = self.ray_directions_site * self.physics.min_range_m
        self._rays[:, 3:] = self.ray_directions_site

    def _cast_static(self) -> None:
        """Every ray against the static scene: each ray's first static hit and its return."""
        physics = self.physics
        hits = self._static_scene.cast_rays(
            o3d.core.Tensor.from_numpy(self._rays), nthreads=physics.raycast_threads
        )
        t_hit = hits["t_hit"].numpy()
        hit = np.isfinite(t_hit)
        primitive = np.where(hit, hits["primitive_ids"].numpy(), 0).astype(np.intp)
        #: First static hit along each ray [m] (inf: none), whether detectable or not.
        self.static_range_m: F32 = np.where(
            hit, t_hit + np.float32(physics.min_range_m), np.float32(np.inf)
        ).astype(np.float32)
        cos_incidence = incidence_cosine(self._rays[:, 3:], hits["primitive_normals"].numpy())
        response = self._return_physics.response(
            np.where(hit, self.static_range_m, np.float32(0.0)),
            cos_incidence,
            self._static_material[primitive],
        )
        detected = hit & response.detected
        self._static_return_m = np.where(detected, self.static_range_m, np.float32(np.nan))
        self._static_intensity = np.where(detected, response.intensity, np.float32(np.nan))
        self._static_dropout = np.where(detected, response.dropout_probability, np.float32(0.0))

    def turn_to(self, rotation: F64) -> None:
        """Turn the head to ``rotation`` (sensor to site, (3, 3)), its position kept.

        The beams then point anew and the static scene is cast again with them: exact, at the
        cost of one static cast per turn (10-35 ms for 131,072 rays on two busy cores). The
        mast model (:mod:`~wz_simulator.sensors.mast`) turns the head every sweep; nothing
        happens when ``rotation`` is the head's already.
        """
        if np.array_equal(rotation, self.rotation):
            return
        self.rotation = np.array(rotation, dtype=np.float64)
        # einsum, not a matmul: numpy hands a tall (N, 3) @ (3, 3) to multithreaded BLAS, which
        # took 55 ms on a busy two-core machine against 2-9 ms (the build keeps its matmul, so
        # that a model that never turns draws the very frames it drew before it could turn).
        self._aim_rays(np.einsum("ij,kj->ik", self.ray_directions_sensor, self.rotation))
        self._cast_static()

    @classmethod
    def from_scene(
        cls,
        mount: SensorMount,
        scene: StaticSceneLike,
        weather: Weather,
        seed: int,
        *,
        boxes_for: BoxesFor,
        site_id: str = "sim",
        physics: LidarPhysics | None = None,
    ) -> LidarModel:
        """Build from a static scene (``scene.static_scene(site)``)."""
        return cls(
            mount,
            scene.boxes,
            scene.ground,
            weather,
            seed,
            boxes_for=boxes_for,
            site_id=site_id,
            physics=physics,
        )

    def scan(
        self,
        vehicles: Sequence[VehicleTruth],
        sweep_start_s: float,
        frame_index: int,
        *,
        truth_stamp_s: float | None = None,
    ) -> LidarScan:
        """Simulate one sweep.

        Parameters
        ----------
        vehicles : sequence of VehicleTruth
            Ground truth; vehicle k (1-based) gets label k.
        sweep_start_s : float
            Firing time of column 0 [s] (the frame's stamp, >= 0).
        frame_index : int
            Index of the frame (>= 0); with the seed, it selects the random draws.
        truth_stamp_s : float, optional
            Time of the truth [s]; the sweep start when omitted. Vehicles are moved from it
            with their speed and heading.

        Returns
        -------
        LidarScan
            Organized points (sensor frame), labels, truth boxes and metadata.
        """
        rng = np.random.default_rng((self.seed, frame_index))
        truth_stamp = sweep_start_s if truth_stamp_s is None else truth_stamp_s
        range_m = self._static_return_m.copy()
        intensity = self._static_intensity.copy()
        dropout = self._static_dropout.copy()
        labels = np.zeros(self.num_rays, dtype=np.int32)

        bodies = self._bodies(vehicles, sweep_start_s - truth_stamp)
        returns = None if bodies is None else self._vehicle_returns(bodies)
        if returns is not None:
            index = returns.ray_index
            nan = np.float32(np.nan)
            np.put(range_m, index, np.where(returns.detected, returns.range_m, nan))
            np.put(intensity, index, np.where(returns.detected, returns.intensity, nan))
            np.put(dropout, index, np.where(returns.detected, returns.dropout_probability, 0.0))

        dropped = rng.random(self.num_rays, dtype=np.float32) < dropout
        np.copyto(range_m, np.float32(np.nan), where=dropped)
        np.copyto(intensity, np.float32(np.nan), where=dropped)
        if returns is not None:
            index = returns.ray_index
            np.put(labels, index, np.where(np.take(dropped, index), STATIC_LABEL, returns.labels))
        noise_std = self.intrinsics.range_noise_std_m
        if noise_std > 0:
            range_m += np.float32(noise_std) * standard_normal(rng, self.num_rays)
        self._rain_clutter(rng, range_m, intensity, labels)

        # Range and intensity are NaN together (no return): so are the point's coordinates.
        points = np.empty((self.num_rays, 4), dtype=np.float32)
        for axis in range(3):
            np.multiply(self._directions_by_axis[axis], range_m, out=points[:, axis])
        points[:, 3] = intensity

        boxes = () if bodies is None else self._truth_boxes(vehicles, bodies, labels, sweep_start_s)
        meta = LidarFrameMeta(
            site=self.site_id,
            source_id=self.mount.sensor_id,
            stamp=sweep_start_s,
            frame_index=frame_index,
            rows=self.rows,
            columns=self.columns,
            num_points=self.num_rays,
            sweep_duration_s=self.sweep_duration_s,
            organized=True,
        )
        return LidarScan(
            points=points,
            labels=labels,
            vehicle_ids=tuple(vehicle.vehicle_id for vehicle in vehicles),
            boxes=boxes,
            meta=meta,
        )

    def _rain_clutter(
        self,
        rng: np.random.Generator,
        range_m: F32,
        intensity: F32,
        labels: I32,
    ) -> None:
        """Spurious raindrop returns (in place): nearer than a beam's return, they replace it."""
        physics = self.physics
        mean = physics.rain_clutter_per_mm_h * max(self.weather.rain_mm_per_h, 0.0)
        count = int(rng.poisson(mean)) if mean > 0 else 0
        if count == 0:
            return
        index = rng.integers(0, self.num_rays, count)
        drop_range = rng.uniform(
            physics.rain_clutter_min_range_m, physics.rain_clutter_max_range_m, count
        ).astype(np.float32)
        drop_intensity = rng.uniform(0.01, 0.1, count).astype(np.float32)
        nearer = ~(range_m[index] <= drop_range)  # NaN (no return) counts as farther
        index, drop_range, drop_intensity = (
            index[nearer],
            drop_range[nearer],
            drop_intensity[nearer],
        )
        range_m[index] = drop_range
        intensity[index] = drop_intensity
        labels[index] = STATIC_LABEL

    def _bodies(self, vehicles: Sequence[VehicleTruth], dt_s: float) -> _VehicleBodies | None:
        """The vehicles' boxes at the sweep start, sorted by label, and their bodies' hulls."""
        if not vehicles:
            return None
        boxes = self.boxes_for(vehicles, dt_s)
        if not boxes:
            return None
        labels = np.fromiter((box.label for box in boxes), dtype=np.intp, count=len(boxes))
        if labels.min() < 1 or labels.max() > len(vehicles):
            raise ValueError(
                f"boxes_for gave labels {labels.min()}..{labels.max()}, "
                f"expected 1..{len(vehicles)} (1-based vehicle indices)"
            )
        order = np.argsort(labels, kind="stable")
        labels = labels[order]
        centers = np.array([box.center_xyz_m for box in boxes], dtype=np.float64)[order]
        sizes = np.array([box.size_lwh_m for box in boxes], dtype=np.float64)[order]
        yaws = np.array([box.yaw_rad for box in boxes], dtype=np.float64)[order]
        materials = np.array([int(box.material) for box in boxes], dtype=np.intp)[order]
        corners = box_corners(centers - self.position_m, sizes, yaws)

        heading_all = np.array([vehicle.heading_rad for vehicle in vehicles], dtype=np.float64)
        speed_all = np.array([vehicle.speed_mps for vehicle in vehicles], dtype=np.float64)
        velocity_all = np.column_stack(
            [
                speed_all * np.cos(heading_all),
                speed_all * np.sin(heading_all),
                np.zeros(len(vehicles)),
            ]
        )
        owners, start, count = np.unique(labels, return_index=True, return_counts=True)
        vehicle_index = owners - 1
        # Body hull: bounds of the vehicle's corners along and across its heading, and in z.
        heading = heading_all[vehicle_index]
        cos_h = np.repeat(np.cos(heading), count)[:, None]
        sin_h = np.repeat(np.sin(heading), count)[:, None]
        along = corners[..., 0] * cos_h + corners[..., 1] * sin_h
        across = -corners[..., 0] * sin_h + corners[..., 1] * cos_h
        bounds_start = start * 8
        low = np.stack(
            [
                np.minimum.reduceat(c.reshape(-1), bounds_start)
                for c in (along, across, corners[..., 2])
            ],
            axis=1,
        )
        high = np.stack(
            [
                np.maximum.reduceat(c.reshape(-1), bounds_start)
                for c in (along, across, corners[..., 2])
            ],
            axis=1,
        )
        mid = 0.5 * (low + high)
        hull_center = np.column_stack(
            [
                mid[:, 0] * np.cos(heading) - mid[:, 1] * np.sin(heading),
                mid[:, 0] * np.sin(heading) + mid[:, 1] * np.cos(heading),
                mid[:, 2],
            ]
        )
        return _VehicleBodies(
            corners_m=corners,
            labels=labels,
            materials=materials,
            vehicle_index=vehicle_index,
            start=start,
            count=count,
            hull_center_m=hull_center,
            hull_size_m=high - low,
            heading_rad=heading,
            velocity_mps=velocity_all[vehicle_index],
        )

    def _vehicle_returns(self, bodies: _VehicleBodies) -> Returns:
        """Cast the rays that may meet a vehicle; keep hits nearer than the static scene.

        Each vehicle stands once, at its sweep-start position, in its own universe. A ray that
        may meet vehicle j is cast in j's universe from ``origin - v_j t``, t the firing time of
        its column: relative to the ray, the vehicle is where it is when the column fires. A
        ray that may meet several vehicles is cast once per vehicle; the nearest hit wins.
        """
        physics = self.physics
        columns = self.columns
        velocity = bodies.velocity_mps
        # Which rays may meet which vehicle. Rows: the elevations of the volume its hull
        # sweeps during the sweep (the hull of its first and last positions). Columns: per
        # sector, the azimuths of the volume it sweeps during the sector.
        hull = box_corners(bodies.hull_center_m, bodies.hull_size_m, bodies.heading_rad)
        sweep_end = self.column_time_offsets_s[-1]
        whole = np.concatenate([hull, hull + velocity[:, None, :] * sweep_end], axis=1)
        whole = whole @ self.rotation  # (m, 16, 3) in the sensor frame
        center = whole.mean(axis=1)
        radius = np.linalg.norm(whole - center[:, None, :], axis=-1).max(axis=-1)
        in_range = np.linalg.norm(center, axis=-1) - radius <= self.max_range_m
        top, bottom = elevation_extent(whole, SWEPT_BOX_EDGES)
        t_first = self.column_time_offsets_s[self._sector_first_column]
        t_last = self.column_time_offsets_s[self._sector_last_column]
        xy_rotation = self.rotation[:, :2]
        swept_xy = np.concatenate(
            [
                (hull @ xy_rotation)[None, :, :, :]
                + (velocity @ xy_rotation)[None, :, None, :] * t[:, None, None, None]
                for t in (t_first, t_last)
            ],
            axis=2,
        )  # (S, m, 16, 2)
        az_start, az_span, around = azimuth_extent(swept_xy[..., 0], swept_xy[..., 1])
        # Around the vertical axis: the nadir (zenith) is met too.
        encircles = around.any(axis=0)
        top = np.where(encircles & (whole[..., 2].max(axis=-1) > 0), 0.5 * np.pi, top)
        bottom = np.where(encircles & (whole[..., 2].min(axis=-1) < 0), -0.5 * np.pi, bottom)
        ascending = self._elevations_ascending
        row_first = np.broadcast_to(
            self.rows - np.searchsorted(ascending, top + _ELEVATION_SLACK_RAD, "right"),
            around.shape,
        )
        row_last = np.broadcast_to(
            self.rows - 1 - np.searchsorted(ascending, bottom - _ELEVATION_SLACK_RAD, "left"),
            around.shape,
        )
        # Azimuth interval [az_start, az_start + az_span] -> columns (azimuth falls as the column
        # index grows): u(az) = (pi - az) columns / 2 pi, column j fires at u = j.
        per_radian = columns / (2.0 * np.pi)
        col_low = np.ceil((np.pi - az_start - az_span) * per_radian - _COLUMN_SLACK)
        col_high = np.floor((np.pi - az_start) * per_radian + _COLUMN_SLACK)
        around |= col_high - col_low + 1 >= columns
        col_low = np.where(around, 0, col_low).astype(np.intp)
        col_high = np.where(around, columns - 1, col_high).astype(np.intp)
        shift = (col_low // columns) * columns
        col_low, col_high = col_low - shift, col_high - shift  # col_low in [0, columns)
        first = self._sector_first_column[:, None]
        last = self._sector_last_column[:, None]
        useful = in_range[None, :] & (row_first <= row_last)
        windows: list[tuple[IntP, ...]] = []
        for wrap in (0, columns):  # the interval, then its part past the seam
            low = np.maximum(col_low - wrap, first)
            high = np.minimum(col_high - wrap, last)
            sector, vehicle = np.nonzero(useful & (low <= high))
            windows.append(
                (
                    row_first[sector, vehicle],
                    row_last[sector, vehicle],
                    low[sector, vehicle],
                    high[sector, vehicle],
                    vehicle,
                )
            )
        row0, row1, col0, col1, window_vehicle = (
            np.concatenate(part) for part in zip(*windows, strict=True)
        )
        if len(row0) == 0:
            return empty_returns()
        # Every (ray, vehicle) candidate of the windows, without a Python loop.
        widths = col1 - col0 + 1
        sizes = (row1 - row0 + 1) * widths
        window = np.repeat(np.arange(len(sizes)), sizes)
        local = np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)
        column = col0[window] + local % widths[window]
        ray = (row0[window] + local // widths[window]) * columns + column
        vehicle = window_vehicle[window]

        # The scene: each vehicle seen by some window once, in its own universe, far enough
        # from the others that a ray cannot reach a foreign vehicle within the maximum range.
        seen = np.zeros(len(velocity), dtype=bool)
        seen[window_vehicle] = True
        speed_max = float(np.linalg.norm(velocity, axis=1).max())
        spacing = 2.0 * (
            self.max_range_m + float(radius.max()) + speed_max * self.sweep_duration_s
        ) + (physics.min_range_m + 10.0)
        slot = np.cumsum(seen) - 1  # universes only for the vehicles seen: a compact grid
        universe = centred_grid(int(seen.sum()))[np.maximum(slot, 0)] * spacing  # (m, 3)
        box_vehicle = np.repeat(np.arange(len(velocity)), bodies.count)
        scene_box = np.flatnonzero(seen[box_vehicle])
        corners = bodies.corners_m[scene_box]  # (nb, 8, 3), sensor at the origin
        # Front faces only: a ray from outside a box meets a front face first. A face turned
        # away from the sensor at the sweep's start and end is turned away in between (the
        # sensor moves along a segment relative to the vehicle), so it is left out: half the
        # triangles, a faster scene build.
        quads = corners[:, BOX_FACE_CORNERS, :]  # (nb, 6, 4, 3)
        outward = np.cross(quads[:, :, 1] - quads[:, :, 0], quads[:, :, 3] - quads[:, :, 0])
        face_center = quads.mean(axis=2)
        sweep_motion = velocity[box_vehicle[scene_box]] * self.sweep_duration_s
        facing = (np.einsum("bfi,bfi->bf", outward, face_center) < 0) | (
            np.einsum("bfi,bfi->bf", outward, face_center + sweep_motion[:, None, :]) < 0
        )
        face_box, face = np.nonzero(facing)
        triangle_box = np.repeat(face_box, 2)
        triangles = np.ascontiguousarray(
            BOX_TRIANGLES[(2 * face[:, None] + np.arange(2)).reshape(-1)]
            + np.uint32(8) * triangle_box[:, None].astype(np.uint32)
        )
        vertices = np.ascontiguousarray(
            (corners + universe[box_vehicle[scene_box]][:, None, :]).reshape(-1, 3),
            dtype=np.float32,
        )
        rays = np.take(self._rays, ray, axis=0)
        origin_shift = np.take(universe.astype(np.float32), vehicle, axis=0)
        origin_shift -= (
            np.take(velocity.astype(np.float32), vehicle, axis=0)
            * np.take(self._column_time_s, column)[:, None]
        )
        rays[:, :3] += origin_shift
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor.from_numpy(vertices), o3d.core.Tensor.from_numpy(triangles)
        )
        hits = scene.cast_rays(o3d.core.Tensor.from_numpy(rays), nthreads=physics.raycast_threads)
        t_hit = hits["t_hit"].numpy() + np.float32(physics.min_range_m)
        # Hits nearer than the static scene (inf, no hit, never is); then per ray the nearest
        # candidate: a key of the range's bits (positive floats order as integers) and the
        # candidate's index is unique, so the winner is too.
        candidate = np.flatnonzero(t_hit < np.take(self.static_range_m, ray))
        candidate_ray = np.take(ray, candidate)
        key = (np.take(t_hit, candidate).view(np.uint32).astype(np.int64) << 32) | candidate
        best = np.full(self.num_rays, np.iinfo(np.int64).max, dtype=np.int64)
        np.minimum.at(best, candidate_ray, key)
        winner = np.take(candidate, np.flatnonzero(key == np.take(best, candidate_ray)))
        triangle = np.take(hits["primitive_ids"].numpy(), winner).astype(np.intp)
        box = np.take(scene_box, np.take(triangle_box, triangle))
        cos_incidence = incidence_cosine(
            np.take(rays, winner, axis=0)[:, 3:],
            np.take(hits["primitive_normals"].numpy(), winner, axis=0),
        )
        response = self._return_physics.response(
            np.take(t_hit, winner), cos_incidence, np.take(bodies.materials, box)
        )
        return Returns(
            ray_index=np.take(ray, winner),
            range_m=response.range_m,
            intensity=response.intensity,
            detected=response.detected,
            dropout_probability=response.dropout_probability,
            labels=np.where(response.detected, np.take(bodies.labels, box), STATIC_LABEL).astype(
                np.int32
            ),
        )

    def _truth_boxes(
        self,
        vehicles: Sequence[VehicleTruth],
        bodies: _VehicleBodies,
        labels: I32,
        sweep_start_s: float,
    ) -> tuple[LidarTruthBox, ...]:
        """Each body's box when the sweep's beam points at its centre."""
        per_radian = self.columns / (2.0 * np.pi)
        fraction = np.full(len(bodies.vehicle_index), 0.5)
        for _ in range(3):  # fixed point: the column time depends on where the vehicle is
            center = (
                bodies.hull_center_m
                + bodies.velocity_mps * (fraction * self.sweep_duration_s)[:, None]
            )
            sensor = center @ self.rotation
            azimuth = np.arctan2(sensor[:, 1], sensor[:, 0])
            fraction = ((np.pi - azimuth) * per_radian % self.columns) / self.columns
        offset_s = fraction * self.sweep_duration_s
        center = bodies.hull_center_m + bodies.velocity_mps * offset_s[:, None]
        center_sensor = center @ self.rotation
        heading_sensor = (
            np.column_stack(
                [np.cos(bodies.heading_rad), np.sin(bodies.heading_rad), np.zeros(len(center))]
            )
            @ self.rotation
        )
        yaw_sensor = np.arctan2(heading_sensor[:, 1], heading_sensor[:, 0])
        center_site = center + self.position_m
        num_points = np.bincount(labels, minlength=len(vehicles) + 1)
        boxes = []
        for j, index in enumerate(bodies.vehicle_index.tolist()):
            boxes.append(
                LidarTruthBox(
                    label=index + 1,
                    vehicle_id=vehicles[index].vehicle_id,
                    stamp_s=sweep_start_s + float(offset_s[j]),
                    center_site_m=_triple(center_site[j]),
                    yaw_site_rad=float(bodies.heading_rad[j]),
                    center_sensor_m=_triple(center_sensor[j]),
                    yaw_sensor_rad=float(yaw_sensor[j]),
                    size_lwh_m=_triple(bodies.hull_size_m[j]),
                    num_points=int(num_points[index + 1]),
                )
            )
        return tuple(boxes)


def _triple(values: F64) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))
