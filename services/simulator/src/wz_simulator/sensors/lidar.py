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
vehicles only, and keeps per ray the nearer of the static and the vehicle hit.

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

Physics of one return
---------------------
For a first hit at range ``r`` [m] on a surface of material ``m`` at incidence ``theta``:

1. Apparent reflectivity, reported as the point's intensity (0..1, range-compensated like the
   calibrated reflectivity channel of common sensors)::

       intensity = rho_m * cos(theta)^k_m * exp(-2 alpha r)

   with ``rho_m`` the material's diffuse reflectivity at 905 nm and ``k_m`` its angular exponent
   (:data:`MATERIAL_RESPONSE`: 1 for Lambertian surfaces; close to 0 for retroreflective
   marking paint, drums and signs, which send light back towards the source at any incidence).
   ``exp(-2 alpha r)`` is the two-way transmission through fog and rain, which the sensor
   cannot compensate.
2. Detection: the received power follows the LiDAR equation for an extended target,
   ``P ~ intensity / r^2``. Sensors are specified by the range at which a target of a given
   reflectivity is just detected (datasheet convention: 80 % at ``max_range_m``), so a return is
   detected when ``intensity * (max_range / r)^2 >= range_spec_reflectivity``, and when
   ``min_range_m <= r <= max_range_m``. In clear weather a 10 % target is thus seen to about
   ``max_range / sqrt(8)`` (71 m at 200 m), a grazing road surface much less far.
3. Dropouts: a detected return is lost with probability ``dropout_probability`` + a grazing
   term rising linearly in ``cos(theta)`` from 0 at ``grazing_onset_deg`` to
   ``grazing_dropout_probability`` at 90 deg incidence + the material's extra (glass transmits
   or mirrors most of the beam).
4. Range noise: Gaussian, ``range_noise_std_m`` of the intrinsics, along the beam (Box-Muller
   on float32 uniforms, exact to 5.8 standard deviations).

Weather (``alpha`` [1/m], the sum of both terms):

- Fog: Koschmieder, ``alpha = 3.912 / V * (lambda / 550 nm)^-q`` for visibility V, with the
  size-distribution exponent q of Kim et al. (2001): q = 1.6 (V > 50 km), 1.3 (6-50 km),
  0.16 V + 0.34 (1-6 km), V - 0.5 (0.5-1 km), 0 below 0.5 km (fog droplets scatter all
  wavelengths alike). At 100 m visibility alpha = 0.039 /m: a 35 % target (concrete) at
  normal incidence is lost beyond 34 m.
- Rain: the empirical rain attenuation of free-space-optics link budgets, ``gamma = 1.076
  R^0.67`` dB/km for rain rate R [mm/h] (as commonly cited from Carbonneau and Wisely, 1998),
  ``alpha = gamma / 4343``: 1.0e-3 /m at 8 mm/h, where an 80 % target is seen to 169 m
  instead of 200 and a 10 % one to 66 m instead of 71: rain hurts a LiDAR far less than fog.
  The coefficients are settings (power laws such as ``0.01 R^0.6`` are used elsewhere, with
  various units). Raindrops close to the sensor also return light: a Poisson number of spurious
  points per frame, mean ``rain_clutter_per_mm_h * R``, on uniformly drawn beams at ranges
  uniform in ``[rain_clutter_min_range_m, rain_clutter_max_range_m]``, weak (intensity uniform
  in 0.01-0.1), labelled 0; each replaces its beam's return when nearer.

Randomness: every frame draws from ``numpy.random.default_rng((seed, frame_index))``, so a frame
depends only on the seed, its index and its inputs, never on the frames before it (a replay or a
rebuilt model reproduces it). Draw order: dropouts, range noise, rain clutter.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Protocol

import numpy as np
import numpy.typing as npt
import open3d as o3d

from wz_shared.messages import LidarFrameMeta, VehicleTruth
from wz_shared.site import LidarIntrinsics, SensorMount
from wz_simulator.sensors.scene import (
    BOX_CORNER_SIGNS,
    BOX_FACES,
    STATIC_LABEL,
    Box,
    GroundPolygon,
    Material,
    Weather,
)

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
IntArray = npt.NDArray[np.intp]
Int32Array = npt.NDArray[np.int32]
BoolArray = npt.NDArray[np.bool_]

#: ``boxes_for(vehicles, dt_s)``: the vehicles' bodies as boxes moved ``dt_s`` seconds from the
#: truth's stamp, each labelled with the 1-based index of its vehicle (``scene.vehicle_boxes``).
BoxesFor = Callable[[Sequence[VehicleTruth], float], list[Box]]


@dataclass(frozen=True)
class SurfaceResponse:
    """How a material returns a 905 nm beam.

    Attributes
    ----------
    reflectivity
        Diffuse reflectivity at normal incidence, 0..1 (retroreflectors are given 1).
    angular_exponent
        The return scales as ``cos(incidence) ** angular_exponent``: 1 for a Lambertian surface,
        near 0 for a retroreflector.
    extra_dropout_probability
        Added to the dropout probability of every return from this material.
    """

    reflectivity: float
    angular_exponent: float = 1.0
    extra_dropout_probability: float = 0.0


#: Response per material: typical NIR reflectivities (asphalt 5-15 %, paint 20-50 %, vegetation
#: and grass 30-50 %, retroreflective sheeting and beads far above any diffuse surface).
MATERIAL_RESPONSE: Mapping[Material, SurfaceResponse] = MappingProxyType(
    {
        Material.ASPHALT: SurfaceResponse(0.08),
        Material.MARKING: SurfaceResponse(0.7, angular_exponent=0.1),
        Material.GRASS: SurfaceResponse(0.35),
        Material.CAR_PAINT: SurfaceResponse(0.3),
        Material.GLASS: SurfaceResponse(0.05, extra_dropout_probability=0.5),
        Material.TIRE: SurfaceResponse(0.03),
        Material.TRUCK_BODY: SurfaceResponse(0.45),
        Material.LIGHT: SurfaceResponse(0.6, angular_exponent=0.3),
        Material.DRUM: SurfaceResponse(0.9, angular_exponent=0.2),
        Material.CONCRETE: SurfaceResponse(0.35),
        Material.SIGN: SurfaceResponse(1.0, angular_exponent=0.2),
        Material.METAL: SurfaceResponse(0.4),
        Material.VEGETATION: SurfaceResponse(0.45),
    }
)

#: Koschmieder's constant: visibility is where contrast falls to 2 % (-ln 0.02).
KOSCHMIEDER = 3.912
#: dB per neper-ish: ``gamma [dB/km] / (10 log10 e) / 1000 = alpha [1/m]``.
_DB_PER_KM_TO_PER_M = 1.0 / (10.0 * math.log10(math.e) * 1000.0)

#: Corner indices of the 6 faces of a box (``BOX_FACES``), shape (6, 4).
_BOX_FACE_CORNERS = np.array(BOX_FACES, dtype=np.intp)
#: The 12 triangles of a box (two per face of ``BOX_FACES``, in face order), as corner indices.
BOX_TRIANGLES = np.array(
    [tri for a, b, c, d in BOX_FACES for tri in ((a, b, c), (a, c, d))], dtype=np.uint32
)
_TRIANGLES_PER_BOX = len(BOX_TRIANGLES)
#: The 12 edges of a box as pairs of corner indices (:meth:`Box.corners` order).
_BOX_EDGES = np.array(
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]]
)
#: Edges of the volume a box sweeps along a segment (corners 0-7 at the start, 8-15 at the end):
#: every edge of its convex hull is an edge of either box or joins a corner to its copy.
_SWEPT_BOX_EDGES = np.concatenate(
    [_BOX_EDGES, _BOX_EDGES + 8, np.column_stack([np.arange(8), np.arange(8) + 8])]
)
#: Slack on interval ends (columns, radians) against float round-off in the ray culling.
_COLUMN_SLACK = 0.01
_ELEVATION_SLACK_RAD = 1e-4


@dataclass(frozen=True)
class LidarPhysics:
    """Settings of the LiDAR model (units in the names).

    Attributes
    ----------
    sectors
        Equal runs of columns over which the rays that may meet each vehicle are chosen
        (1..azimuth_steps): more sectors give tighter windows, and more of them.
    min_range_m
        Blind zone: geometry nearer than this is not seen (rays start there).
    dropout_probability
        Chance that any detected return is lost.
    grazing_dropout_probability
        Extra chance of loss at 90 deg incidence, falling linearly in cos(incidence) to 0 at
        ``grazing_onset_deg``.
    grazing_onset_deg
        Incidence angle where the grazing dropout starts [deg].
    range_spec_reflectivity
        Reflectivity detected just at ``max_range_m`` (datasheet convention, 0.8); 0 turns the
        detection threshold off (every hit within range returns).
    wavelength_nm
        Laser wavelength (fog extinction depends on it above 0.5 km visibility).
    rain_attenuation_db_per_km
        ``a`` of the rain attenuation ``gamma = a R^b`` [dB/km], R in mm/h.
    rain_attenuation_exponent
        ``b`` of the same.
    rain_clutter_per_mm_h
        Mean spurious raindrop returns per frame per mm/h of rain.
    rain_clutter_min_range_m, rain_clutter_max_range_m
        Range interval of the spurious returns [m].
    raycast_threads
        Threads open3d may use per cast (0: all cores).
    base_ground_material
        Material of the base ground plane (seen where no ground polygon lies).
    """

    sectors: int = 32
    min_range_m: float = 0.5
    dropout_probability: float = 0.001
    grazing_dropout_probability: float = 0.5
    grazing_onset_deg: float = 75.0
    range_spec_reflectivity: float = 0.8
    wavelength_nm: float = 905.0
    rain_attenuation_db_per_km: float = 1.076
    rain_attenuation_exponent: float = 0.67
    rain_clutter_per_mm_h: float = 1.0
    rain_clutter_min_range_m: float = 5.0
    rain_clutter_max_range_m: float = 15.0
    raycast_threads: int = 0
    base_ground_material: Material = Material.GRASS

    @classmethod
    def ideal(cls, sectors: int = 32) -> LidarPhysics:
        """Geometry only: no dropouts, no detection threshold, no rain clutter.

        Weather extinction still scales the intensity; range noise comes from the intrinsics.
        """
        return cls(
            sectors=sectors,
            dropout_probability=0.0,
            grazing_dropout_probability=0.0,
            range_spec_reflectivity=0.0,
            rain_clutter_per_mm_h=0.0,
        )

    def validate(self, intrinsics: LidarIntrinsics) -> None:
        """Raise ValueError naming the first setting that does not fit these intrinsics."""
        if not 1 <= self.sectors <= intrinsics.azimuth_steps:
            raise ValueError(f"sectors must lie in [1, {intrinsics.azimuth_steps}]")
        if not 0.0 <= self.min_range_m < intrinsics.max_range_m:
            raise ValueError("min_range_m must lie in [0, max_range_m)")
        for name in ("dropout_probability", "grazing_dropout_probability"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1]")
        if not 0.0 <= self.grazing_onset_deg < 90.0:
            raise ValueError("grazing_onset_deg must lie in [0, 90)")
        if self.range_spec_reflectivity < 0 or self.rain_clutter_per_mm_h < 0:
            raise ValueError("range_spec_reflectivity and rain_clutter_per_mm_h must be >= 0")
        if not 0.0 <= self.rain_clutter_min_range_m <= self.rain_clutter_max_range_m:
            raise ValueError("rain clutter ranges must satisfy 0 <= min <= max")


class StaticSceneLike(Protocol):
    """What the model needs of a static scene (``scene.StaticScene`` fits)."""

    @property
    def boxes(self) -> Sequence[Box]: ...

    @property
    def ground(self) -> Sequence[GroundPolygon]: ...


@dataclass(frozen=True)
class LidarTruthBox:
    """A vehicle's true 3D box for one sweep, when the sweep's beam crossed its centre.

    The box is the vehicle's body (the union of its ``boxes_for`` boxes) aligned with its
    heading; ``stamp_s`` is the firing time of the column that points at its centre.

    Attributes
    ----------
    label
        1-based index of the vehicle in the frame's truth (its points' label).
    vehicle_id
        The vehicle's id.
    stamp_s
        Time the box is given at [s].
    center_site_m, yaw_site_rad
        Centre [m] and heading (CCW from east) [rad] in the site frame.
    center_sensor_m, yaw_sensor_rad
        Centre [m] and heading (CCW from the sensor's x axis, about its z axis) [rad] in the
        sensor frame.
    size_lwh_m
        Length (along the heading), width, height [m].
    num_points
        Points of the frame labelled with this vehicle.
    """

    label: int
    vehicle_id: str
    stamp_s: float
    center_site_m: tuple[float, float, float]
    yaw_site_rad: float
    center_sensor_m: tuple[float, float, float]
    yaw_sensor_rad: float
    size_lwh_m: tuple[float, float, float]
    num_points: int


@dataclass(frozen=True)
class LidarScan:
    """One simulated sweep.

    Attributes
    ----------
    points
        ``(rows * columns, 4)`` float32: x, y, z [m] in the sensor frame and intensity (0..1);
        organized, row-major by beam then column (see the module docstring); NaN rows where the
        beam got no return.
    labels
        ``(rows * columns,)`` int32: 0 for the static scene, rain clutter and no return; k for
        vehicle k (1-based index into the frame's truth).
    vehicle_ids
        ``vehicle_ids[k - 1]`` is the id of the vehicle labelled k.
    boxes
        Truth boxes of the vehicles that have a body, in label order.
    meta
        The frame's metadata message (stamp: the sweep start).
    """

    points: Float32Array
    labels: Int32Array
    vehicle_ids: tuple[str, ...]
    boxes: tuple[LidarTruthBox, ...]
    meta: LidarFrameMeta

    @property
    def range_image(self) -> Float32Array:
        """The points as a ``(rows, columns, 4)`` view."""
        image: Float32Array = self.points.reshape(self.meta.rows, self.meta.columns, 4)
        return image


def fog_extinction_per_m(visibility_m: float, wavelength_nm: float = 905.0) -> float:
    """Fog extinction coefficient [1/m] from the meteorological visibility [m].

    Koschmieder with Kim et al.'s (2001) wavelength exponent q(V); 0 for infinite visibility.
    """
    if not math.isfinite(visibility_m):
        return 0.0
    if visibility_m <= 0:
        raise ValueError("fog visibility must be positive")
    v_km = visibility_m / 1000.0
    if v_km > 50.0:
        q = 1.6
    elif v_km > 6.0:
        q = 1.3
    elif v_km > 1.0:
        q = 0.16 * v_km + 0.34
    elif v_km > 0.5:
        q = v_km - 0.5
    else:
        q = 0.0
    return float(KOSCHMIEDER / visibility_m * (wavelength_nm / 550.0) ** -q)


def rain_extinction_per_m(
    rain_mm_per_h: float, coefficient_db_per_km: float = 1.076, exponent: float = 0.67
) -> float:
    """Rain extinction coefficient [1/m]: ``gamma = a R^b`` [dB/km] converted to nepers per m."""
    if rain_mm_per_h <= 0:
        return 0.0
    return float(coefficient_db_per_km * rain_mm_per_h**exponent * _DB_PER_KM_TO_PER_M)


def box_corners(centers_m: FloatArray, sizes_lwh_m: FloatArray, yaws_rad: FloatArray) -> FloatArray:
    """Corners of many boxes at once, in :meth:`Box.corners` order.

    Parameters
    ----------
    centers_m : ndarray, shape (n, 3)
        Box centres [m].
    sizes_lwh_m : ndarray, shape (n, 3)
        Length (along the yaw), width, height [m].
    yaws_rad : ndarray, shape (n,)
        Yaw, counter-clockwise about z [rad].

    Returns
    -------
    ndarray, shape (n, 8, 3)
    """
    local = 0.5 * sizes_lwh_m[:, None, :] * BOX_CORNER_SIGNS[None, :, :]
    cos_yaw, sin_yaw = np.cos(yaws_rad)[:, None], np.sin(yaws_rad)[:, None]
    corners = np.empty_like(local)
    corners[..., 0] = cos_yaw * local[..., 0] - sin_yaw * local[..., 1]
    corners[..., 1] = sin_yaw * local[..., 0] + cos_yaw * local[..., 1]
    corners[..., 2] = local[..., 2]
    corners += centers_m[:, None, :]
    return corners


def triangulate_polygon(vertices_xy: npt.ArrayLike) -> npt.NDArray[np.uint32]:
    """Triangulate a simple polygon by ear clipping.

    Parameters
    ----------
    vertices_xy : array_like, shape (n, 2)
        Vertices in order (either orientation; a repeated closing vertex is dropped).

    Returns
    -------
    ndarray of uint32, shape (m, 3)
        Triangles as vertex indices, counter-clockwise; collinear vertices yield no triangle.

    Raises
    ------
    ValueError
        Fewer than 3 vertices, or no ear found (a self-intersecting polygon).
    """
    points = np.asarray(vertices_xy, dtype=np.float64)
    count = len(points)
    if count >= 2 and np.allclose(points[0], points[-1]):
        count -= 1
    if count < 3:
        raise ValueError(f"a ground polygon needs at least 3 vertices, got {count}")
    x, y = points[:count, 0], points[:count, 1]
    twice_area = float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    remaining = list(range(count)) if twice_area >= 0 else list(range(count - 1, -1, -1))
    scale = float(np.ptp(points[:count], axis=0).max()) or 1.0
    eps = 1e-12 * scale * scale
    triangles: list[tuple[int, int, int]] = []
    while len(remaining) > 3:
        ring = np.asarray(remaining)
        prev_pts, cur_pts, next_pts = (
            points[np.roll(ring, 1)],
            points[ring],
            points[np.roll(ring, -1)],
        )
        edge_a, edge_b = cur_pts - prev_pts, next_pts - cur_pts
        cross = edge_a[:, 0] * edge_b[:, 1] - edge_a[:, 1] * edge_b[:, 0]
        collinear = np.flatnonzero(np.abs(cross) <= eps)
        if len(collinear):
            remaining.pop(int(collinear[0]))
            continue
        for i in np.flatnonzero(cross > eps).tolist():
            a, b, c = prev_pts[i], cur_pts[i], next_pts[i]
            others = points[np.delete(ring, [(i - 1) % len(ring), i, (i + 1) % len(ring)])]
            # Inside (or on the edge of) triangle abc: all three edge cross products >= 0.
            inside = np.ones(len(others), dtype=bool)
            for p, q in ((a, b), (b, c), (c, a)):
                inside &= (q[0] - p[0]) * (others[:, 1] - p[1]) - (q[1] - p[1]) * (
                    others[:, 0] - p[0]
                ) >= -eps
            if not inside.any():
                m = len(remaining)
                triangles.append((remaining[(i - 1) % m], remaining[i], remaining[(i + 1) % m]))
                remaining.pop(i)
                break
        else:
            raise ValueError("ground polygon has no ear: is it self-intersecting?")
    if len(remaining) == 3:
        triangles.append((remaining[0], remaining[1], remaining[2]))
    return np.asarray(triangles, dtype=np.uint32).reshape(-1, 3)


@dataclass(frozen=True)
class _VehicleBodies:
    """One frame's vehicle boxes at the sweep start, sorted by label (sensor-centred site frame).

    ``m`` vehicles have a body; vehicle ``j`` of them owns boxes ``start[j] : start[j] +
    count[j]``.
    """

    corners_m: FloatArray  # (nb, 8, 3)
    labels: IntArray  # (nb,)
    materials: IntArray  # (nb,)
    vehicle_index: IntArray  # (m,) 0-based index into the frame's truth
    start: IntArray  # (m,)
    count: IntArray  # (m,)
    hull_center_m: FloatArray  # (m, 3) heading-aligned bounding box of the body
    hull_size_m: FloatArray  # (m, 3)
    heading_rad: FloatArray  # (m,)
    velocity_mps: FloatArray  # (m, 3)


@dataclass(frozen=True)
class _Returns:
    """Returns of a subset of rays: indices into the frame and their physics."""

    ray_index: IntArray
    range_m: Float32Array
    intensity: Float32Array
    detected: BoolArray
    dropout_probability: Float32Array
    labels: Int32Array


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
        if not isinstance(mount.intrinsics, LidarIntrinsics):
            raise ValueError(
                f"sensor {mount.sensor_id!r} is a {mount.kind}, not a lidar: "
                "LidarModel needs lidar intrinsics"
            )
        self.physics = physics if physics is not None else LidarPhysics()
        self.physics.validate(mount.intrinsics)
        self.mount = mount
        self.intrinsics: LidarIntrinsics = mount.intrinsics
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
        self.position_m: FloatArray = np.array([pose.x_m, pose.y_m, pose.z_m])
        self.rotation: FloatArray = pose.rotation()
        self.extinction_per_m = fog_extinction_per_m(
            weather.fog_visibility_m, physics.wavelength_nm
        ) + rain_extinction_per_m(
            weather.rain_mm_per_h,
            physics.rain_attenuation_db_per_km,
            physics.rain_attenuation_exponent,
        )

        # --- rays ---------------------------------------------------------------------------
        #: Beam elevations [rad], row 0 the highest, shape (rows,).
        self.elevations_rad: FloatArray = np.radians(
            np.linspace(intrinsics.vertical_max_deg, intrinsics.vertical_min_deg, self.rows)
        )
        self._elevations_ascending = self.elevations_rad[::-1].copy()
        #: Column azimuths [rad] in the sensor frame, shape (columns,).
        self.azimuths_rad: FloatArray = np.pi - 2.0 * np.pi * np.arange(self.columns) / self.columns
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
        self.ray_directions_sensor: FloatArray = directions
        #: Unit ray directions in the site frame, (rows * columns, 3).
        self.ray_directions_site: FloatArray = directions @ self.rotation.T
        # Rays for open3d in the sensor-centred site frame (small coordinates keep float32
        # precise): origin at the blind-zone distance along the direction, then the direction.
        self._rays = np.empty((self.num_rays, 6), dtype=np.float32)
        self._rays[:, :3] = self.ray_directions_site * physics.min_range_m
        self._rays[:, 3:] = self.ray_directions_site
        # Sensor-frame directions by axis, (3, rows * columns): points = direction * range.
        self._directions_by_axis = np.ascontiguousarray(directions.T, dtype=np.float32)

        # --- timing and sectors -------------------------------------------------------------
        column = np.arange(self.columns)
        #: Firing time of each column after the sweep start [s], shape (columns,).
        self.column_time_offsets_s: FloatArray = column * self.sweep_duration_s / self.columns
        self._column_time_s = self.column_time_offsets_s.astype(np.float32)
        #: Sector of each column (the unit of ray culling), shape (columns,).
        self.sector_of_column: IntArray = (column * physics.sectors) // self.columns
        first = np.searchsorted(self.sector_of_column, np.arange(physics.sectors), side="left")
        last = np.searchsorted(self.sector_of_column, np.arange(physics.sectors), side="right") - 1
        self._sector_first_column: IntArray = first
        self._sector_last_column: IntArray = last

        # --- static scene, cast once ----------------------------------------------------------
        self._material_reflectivity = np.array(
            [MATERIAL_RESPONSE[m].reflectivity for m in Material], dtype=np.float32
        )
        self._material_exponent = np.array(
            [MATERIAL_RESPONSE[m].angular_exponent for m in Material], dtype=np.float32
        )
        self._material_dropout = np.array(
            [MATERIAL_RESPONSE[m].extra_dropout_probability for m in Material], dtype=np.float32
        )
        self._grazing_onset_cos = math.cos(math.radians(physics.grazing_onset_deg))
        vertices, triangles, triangle_material = self._static_mesh(static_boxes, static_ground)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor.from_numpy(vertices), o3d.core.Tensor.from_numpy(triangles)
        )
        hits = scene.cast_rays(
            o3d.core.Tensor.from_numpy(self._rays), nthreads=physics.raycast_threads
        )
        t_hit = hits["t_hit"].numpy()
        hit = np.isfinite(t_hit)
        primitive = np.where(hit, hits["primitive_ids"].numpy(), 0).astype(np.intp)
        #: First static hit along each ray [m] (inf: none), whether detectable or not.
        self.static_range_m: Float32Array = np.where(
            hit, t_hit + np.float32(physics.min_range_m), np.float32(np.inf)
        ).astype(np.float32)
        cos_incidence = _cos_incidence(self._rays[:, 3:], hits["primitive_normals"].numpy())
        response = self._response(
            np.where(hit, self.static_range_m, np.float32(0.0)),
            cos_incidence,
            triangle_material[primitive],
        )
        detected = hit & response.detected
        self._static_return_m = np.where(detected, self.static_range_m, np.float32(np.nan))
        self._static_intensity = np.where(detected, response.intensity, np.float32(np.nan))
        self._static_dropout = np.where(detected, response.dropout_probability, np.float32(0.0))

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

    # --- physics ------------------------------------------------------------------------

    def _response(
        self, range_m: Float32Array, cos_incidence: Float32Array, material: IntArray
    ) -> _Returns:
        """Intensity, detection and dropout probability of hits (see the module docstring).

        ``range_m``, ``cos_incidence`` and ``material`` are parallel, shape (n,); the returned
        ``ray_index`` and ``labels`` are left empty.
        """
        physics = self.physics
        intensity = np.take(self._material_reflectivity, material) * np.power(
            cos_incidence, np.take(self._material_exponent, material)
        )
        if self.extinction_per_m > 0:
            intensity *= np.exp(np.float32(-2.0 * self.extinction_per_m) * range_m)
        detected = (range_m >= physics.min_range_m) & (range_m <= self.max_range_m)
        if physics.range_spec_reflectivity > 0:
            # intensity (R_max / r)^2 >= rho_spec, without dividing by r.
            detected &= intensity * np.float32(self.max_range_m**2) >= np.float32(
                physics.range_spec_reflectivity
            ) * np.square(range_m)
        grazing = np.clip(1.0 - cos_incidence / np.float32(self._grazing_onset_cos), 0.0, 1.0)
        dropout = np.minimum(
            np.float32(physics.dropout_probability)
            + np.float32(physics.grazing_dropout_probability) * grazing
            + np.take(self._material_dropout, material),
            np.float32(1.0),
        )
        empty = np.empty(0, dtype=np.intp)
        return _Returns(empty, range_m, intensity, detected, dropout, np.empty(0, dtype=np.int32))

    def _static_mesh(
        self, boxes: Sequence[Box], ground: Sequence[GroundPolygon]
    ) -> tuple[Float32Array, npt.NDArray[np.uint32], IntArray]:
        """Vertices (sensor-centred), triangles and per-triangle material of the static scene."""
        vertex_blocks: list[FloatArray] = []
        triangle_blocks: list[npt.NDArray[np.uint32]] = []
        material_blocks: list[IntArray] = []
        offset = 0

        def add(
            vertices: FloatArray, triangles: npt.NDArray[np.uint32], material: IntArray
        ) -> None:
            nonlocal offset
            vertex_blocks.append(vertices - self.position_m)
            triangle_blocks.append(triangles + np.uint32(offset))
            material_blocks.append(material)
            offset += len(vertices)

        if boxes:
            centers = np.array([box.center_xyz_m for box in boxes], dtype=np.float64)
            sizes = np.array([box.size_lwh_m for box in boxes], dtype=np.float64)
            yaws = np.array([box.yaw_rad for box in boxes], dtype=np.float64)
            corners = box_corners(centers, sizes, yaws).reshape(-1, 3)
            count = len(boxes)
            triangles = (
                BOX_TRIANGLES[None, :, :]
                + np.uint32(8) * np.arange(count, dtype=np.uint32)[:, None, None]
            ).reshape(-1, 3)
            materials = np.repeat(
                np.array([int(box.material) for box in boxes], dtype=np.intp), _TRIANGLES_PER_BOX
            )
            add(corners, triangles, materials)
        lowest = 0.0
        for polygon in ground:
            xy = np.asarray(polygon.vertices_xy_m, dtype=np.float64)
            triangles = triangulate_polygon(xy)
            vertices = np.column_stack([xy, np.full(len(xy), polygon.z_m)])
            add(vertices, triangles, np.full(len(triangles), int(polygon.material), np.intp))
            lowest = min(lowest, polygon.z_m - 0.01)
        # Base plane under everything, wide enough for every downward beam within range.
        half = self.max_range_m + 100.0
        px, py = self.position_m[0], self.position_m[1]
        plane = np.array(
            [
                [px - half, py - half, lowest],
                [px + half, py - half, lowest],
                [px + half, py + half, lowest],
                [px - half, py + half, lowest],
            ]
        )
        add(
            plane,
            np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32),
            np.full(2, int(self.physics.base_ground_material), np.intp),
        )
        return (
            np.ascontiguousarray(np.concatenate(vertex_blocks), dtype=np.float32),
            np.ascontiguousarray(np.concatenate(triangle_blocks), dtype=np.uint32),
            np.concatenate(material_blocks),
        )

    # --- one sweep ----------------------------------------------------------------------

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
            range_m += np.float32(noise_std) * _standard_normal(rng, self.num_rays)
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
        range_m: Float32Array,
        intensity: Float32Array,
        labels: Int32Array,
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

    def _vehicle_returns(self, bodies: _VehicleBodies) -> _Returns:
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
        top, bottom = _elevation_extent(whole, _SWEPT_BOX_EDGES)
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
        az_start, az_span, around = _azimuth_extent(swept_xy[..., 0], swept_xy[..., 1])
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
        windows: list[tuple[IntArray, ...]] = []
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
            return _empty_returns()
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
        universe = _centred_grid(int(seen.sum()))[np.maximum(slot, 0)] * spacing  # (m, 3)
        box_vehicle = np.repeat(np.arange(len(velocity)), bodies.count)
        scene_box = np.flatnonzero(seen[box_vehicle])
        corners = bodies.corners_m[scene_box]  # (nb, 8, 3), sensor at the origin
        # Front faces only: a ray from outside a box meets a front face first. A face turned
        # away from the sensor at the sweep's start and end is turned away in between (the
        # sensor moves along a segment relative to the vehicle), so it is left out: half the
        # triangles, a faster scene build.
        quads = corners[:, _BOX_FACE_CORNERS, :]  # (nb, 6, 4, 3)
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
        cos_incidence = _cos_incidence(
            np.take(rays, winner, axis=0)[:, 3:],
            np.take(hits["primitive_normals"].numpy(), winner, axis=0),
        )
        response = self._response(
            np.take(t_hit, winner), cos_incidence, np.take(bodies.materials, box)
        )
        return _Returns(
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
        labels: Int32Array,
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


def _elevation_extent(corners: FloatArray, edges: IntArray) -> tuple[FloatArray, FloatArray]:
    """Highest and lowest elevation [rad] of any point of convex bodies, seen from the origin.

    Exact: the extremes of a body's projection on the unit sphere lie on the projections of its
    edges, great-circle arcs whose highest (lowest) point is an end or the apex (antipode) of
    their circle, when the apex lies on the arc. (A body around the vertical axis also
    covers the nadir or zenith: see :func:`_azimuth_extent`.)

    Parameters
    ----------
    corners : ndarray, shape (..., n, 3)
        Corners of the bodies [m], none containing the origin.
    edges : ndarray of int, shape (e, 2)
        Pairs of corner indices, including every edge of the bodies' convex hulls.

    Returns
    -------
    top, bottom : ndarray, shape (...)
    """
    x, y, z = corners[..., 0], corners[..., 1], corners[..., 2]
    elevation = np.arctan2(z, np.hypot(x, y))
    top, bottom = elevation.max(axis=-1), elevation.min(axis=-1)
    ax, ay, az = (corners[..., edges[:, 0], i] for i in range(3))
    bx, by, bz = (corners[..., edges[:, 1], i] for i in range(3))
    # n = a x b, normal of the arc's great circle; its apex p = (-nx nz, -ny nz, nx^2 + ny^2)
    # (z projected on the circle's plane) lies on the arc a -> b iff p.(n x a) >= 0 and
    # p.(b x n) >= 0; the antipode -p iff both are <= 0.
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    horizontal2 = nx * nx + ny * ny
    px, py = -nx * nz, -ny * nz
    from_a = px * (ny * az - nz * ay) + py * (nz * ax - nx * az) + horizontal2 * (nx * ay - ny * ax)
    to_b = px * (by * nz - bz * ny) + py * (bz * nx - bx * nz) + horizontal2 * (bx * ny - by * nx)
    tilted = horizontal2 > 1e-12 * (horizontal2 + nz * nz)  # else the circle is the horizon
    apex_elevation = np.arctan2(np.sqrt(horizontal2), np.abs(nz))
    high = tilted & (from_a >= 0) & (to_b >= 0)
    low = tilted & (from_a <= 0) & (to_b <= 0)
    top = np.maximum(top, np.where(high, apex_elevation, -np.inf).max(axis=-1))
    bottom = np.minimum(bottom, np.where(low, -apex_elevation, np.inf).min(axis=-1))
    return top, bottom


def _azimuth_extent(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Azimuths [rad] met by convex bodies, from their corners' x and y, shape (..., n).

    Returns
    -------
    start, span : ndarray, shape (...)
        The azimuths met are ``[start, start + span]`` (exact: the corners' azimuths less the
        widest gap between them).
    around : ndarray of bool, shape (...)
        The body surrounds the vertical axis (no gap wider than pi): every azimuth is met.
    """
    azimuth = np.sort(np.arctan2(y, x), axis=-1)
    gaps = np.diff(azimuth, axis=-1, append=azimuth[..., :1] + 2.0 * np.pi)
    widest = gaps.argmax(axis=-1)[..., None]
    widest_gap = np.take_along_axis(gaps, widest, axis=-1)[..., 0]
    start = np.take_along_axis(azimuth, (widest + 1) % x.shape[-1], axis=-1)[..., 0]
    return start, 2.0 * np.pi - widest_gap, widest_gap <= np.pi


def _triple(values: FloatArray) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))


def _cos_incidence(directions: Float32Array, normals: Float32Array) -> Float32Array:
    """|cos| of the angle between unit ray directions and unit normals, both (n, 3); (n,)."""
    cosine: Float32Array = np.minimum(
        np.abs(np.einsum("ij,ij->i", directions, normals)), np.float32(1.0)
    )
    return cosine


def _standard_normal(rng: np.random.Generator, count: int) -> Float32Array:
    """``count`` standard normal float32 draws by Box-Muller on float32 uniforms.

    Exact in distribution up to 5.8 sigma (the largest ``sqrt(-2 ln u)`` of a float32 u);
    about twice as fast as numpy's float32 ziggurat on this kind of machine.
    """
    half = (count + 1) // 2
    uniform = rng.random(2 * half, dtype=np.float32)
    radius = np.sqrt(np.float32(-2.0) * np.log1p(-uniform[:half]))  # 1 - u lies in (0, 1]
    angle = np.float32(2.0 * np.pi) * uniform[half:]
    normal = np.empty(2 * half, dtype=np.float32)
    np.multiply(radius, np.cos(angle), out=normal[:half])
    np.multiply(radius, np.sin(angle), out=normal[half:])
    return normal[:count]


def _centred_grid(count: int) -> FloatArray:
    """``count`` points of a unit-spaced 3D grid, as compact as possible, centred on 0, (n, 3)."""
    side = max(1, math.ceil(count ** (1.0 / 3.0) - 1e-9))
    index = np.arange(count)
    grid = np.column_stack([index % side, (index // side) % side, index // (side * side)])
    centred: FloatArray = grid - 0.5 * (grid.max(axis=0) + grid.min(axis=0))
    return centred.astype(np.float64)


def _empty_returns() -> _Returns:
    return _Returns(
        ray_index=np.empty(0, dtype=np.intp),
        range_m=np.empty(0, dtype=np.float32),
        intensity=np.empty(0, dtype=np.float32),
        detected=np.empty(0, dtype=bool),
        dropout_probability=np.empty(0, dtype=np.float32),
        labels=np.empty(0, dtype=np.int32),
    )
