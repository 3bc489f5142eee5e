"""Where a site's sensors can see a car: the region a tracker can be held to.

A spot on the road is *covered* when at least one of the site's sensors would detect a
passenger car standing there, other vehicles aside (hiding behind another vehicle is the
tracker's to bridge, not a hole in the coverage). Everything follows from the site file's
sensor geometry and the weather; nothing is fitted:

- **LiDAR**: the spot is within the range at which a car's paint still returns, and the
  beams are dense enough there that at least one is sure to cross the car. The range follows
  the datasheet convention (an 80 % target is detected at ``max_range_m``): paint of
  :data:`CAR_REFLECTIVITY` at normal incidence is detected while
  ``rho exp(-2 alpha r) (max_range / r)^2 >= 0.8``, ``alpha`` the weather's extinction (fog,
  rain; 0 in clear air). Clear: 0.61 ``max_range_m`` (122 m for a 200 m sensor); in fog of
  150 m visibility (``alpha`` 0.026 /m), about 45 m. The beams: a car of height
  :data:`CAR_HEIGHT_M` at ground range ``r`` from a LiDAR ``h`` above the road spans the
  elevations ``[atan(-h / r), atan((CAR_HEIGHT_M - h) / r)]``; one beam is sure to fall in it
  when that span is at least the beam spacing ``(vertical_max - vertical_min) / (beams - 1)``
  and lies inside the beams' fan. A 32-beam LiDAR over 40 degrees (1.3 degrees apart) 5 m up
  has a beam on a car to about 66 m; a 64-beam one over 41 degrees, to about 130 m. Beyond, a
  car falls between two beams, and a tracker downstream of the mast sees nothing there.
- **camera**: the car's middle (half its height above the road) is in front of the camera,
  inside the image and within ``camera_range_m`` (the camera detector publishes nothing
  beyond its ``max_range_m``, 200 m by default); in fog, no farther than where the car's
  contrast falls to :data:`CAMERA_MIN_CONTRAST` (Koschmieder: ``exp(-3.912 r / V)``; 0.77 V).
- **radar**: within ``max_range_m`` and half the horizontal field of view of the boresight.

:class:`SiteCoverage` answers for points; ``wz eval`` scores the tracks inside the 150 m circle
*and* the covered road (and reports the whole circle alongside); ``wz site show`` draws what
each sensor covers.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from wz_shared.camera_geometry import PinholeCamera
from wz_shared.occlusion import Boxes, hidden
from wz_shared.site import CameraIntrinsics, LidarIntrinsics, RadarIntrinsics, SensorMount, Site

F64 = npt.NDArray[np.float64]
Bool = npt.NDArray[np.bool_]

#: The vehicle a sensor must be able to see for a spot to count as covered: a passenger car's
#: height [m] (trucks, taller, are seen further).
CAR_HEIGHT_M = 1.5
#: The camera detector's default range [m] (``CameraDetectorSettings.max_range_m``).
CAMERA_RANGE_M = 200.0
#: Diffuse reflectivity of car paint in the near infrared (the simulator's, and a mid value of
#: the 0.05-0.8 that paints span).
CAR_REFLECTIVITY = 0.3
#: Datasheet convention: a target of this reflectivity is just detected at ``max_range_m``.
SPEC_REFLECTIVITY = 0.8
#: The least contrast at which a camera still finds a car in fog (5 %, against the 2 % that
#: defines meteorological visibility).
CAMERA_MIN_CONTRAST = 0.05
#: Koschmieder's constant: visibility is where contrast falls to 2 % (-ln 0.02).
KOSCHMIEDER = 3.912


def lidar_detection_range_m(
    max_range_m: float, extinction_per_m: float = 0.0, reflectivity: float = CAR_REFLECTIVITY
) -> float:
    """The farthest range [m] a target of ``reflectivity`` at normal incidence returns
    (module docstring): ``rho exp(-2 alpha r) (max_range / r)^2 >= SPEC_REFLECTIVITY``."""
    clear = max_range_m * math.sqrt(min(1.0, reflectivity / SPEC_REFLECTIVITY))
    if extinction_per_m <= 0.0:
        return clear
    lo, hi = 0.0, clear  # the left side falls with r: bisect its crossing
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        seen = reflectivity * math.exp(-2.0 * extinction_per_m * mid) * (max_range_m / mid) ** 2
        lo, hi = (mid, hi) if seen >= SPEC_REFLECTIVITY else (lo, mid)
    return lo


def camera_fog_range_m(visibility_m: float) -> float:
    """How far a camera still finds a car in fog of ``visibility_m`` (inf when clear)."""
    if not math.isfinite(visibility_m):
        return math.inf
    return -math.log(CAMERA_MIN_CONTRAST) / KOSCHMIEDER * visibility_m


def lidar_beam_rows(
    mount: SensorMount, x_m: npt.ArrayLike, y_m: npt.ArrayLike, extinction_per_m: float = 0.0
) -> F64:
    """How many of a LiDAR's beam rows cross a car standing at each point: the car's span of
    elevations (module docstring), clipped to the beams' fan, over the beam spacing; 0 where
    its paint does not return (beyond the reach) or the span is outside the fan. At least 1:
    a beam is sure to cross the car; a single-beam sensor gives 1 where its beam falls on it.
    """
    intrinsics = mount.intrinsics
    assert isinstance(intrinsics, LidarIntrinsics)
    r = np.hypot(np.asarray(x_m, float) - mount.pose.x_m, np.asarray(y_m, float) - mount.pose.y_m)
    r = np.maximum(r, 1e-3)
    low = np.degrees(np.arctan2(-mount.pose.z_m, r))
    high = np.degrees(np.arctan2(CAR_HEIGHT_M - mount.pose.z_m, r))
    lo = np.maximum(low, intrinsics.vertical_min_deg)
    hi = np.minimum(high, intrinsics.vertical_max_deg)
    if intrinsics.beams > 1:
        spacing = (intrinsics.vertical_max_deg - intrinsics.vertical_min_deg) / (
            intrinsics.beams - 1
        )
        rows = np.maximum(hi - lo, 0.0) / spacing
    else:
        rows = ((lo <= intrinsics.vertical_min_deg) & (hi >= intrinsics.vertical_min_deg)) * 1.0
    reach = lidar_detection_range_m(intrinsics.max_range_m, extinction_per_m)
    result: F64 = np.where((r <= reach) & (hi > lo), rows, 0.0)
    return result


def lidar_covers(
    mount: SensorMount, x_m: npt.ArrayLike, y_m: npt.ArrayLike, extinction_per_m: float = 0.0
) -> Bool:
    """Whether a LiDAR sees a car at each point: its paint returns from there and a beam is
    sure to cross it (module docstring; :func:`lidar_beam_rows` at least 1)."""
    result: Bool = lidar_beam_rows(mount, x_m, y_m, extinction_per_m) >= 1.0
    return result


def lidar_car_ranges_m(
    mount: SensorMount, step_m: float = 0.5, extinction_per_m: float = 0.0
) -> tuple[float, float] | None:
    """The nearest and farthest ground range [m] at which :func:`lidar_covers` holds (the
    blind cone under the sensor inside, beams too sparse for a car beyond); None if nowhere."""
    intrinsics = mount.intrinsics
    assert isinstance(intrinsics, LidarIntrinsics)
    r = np.arange(step_m, intrinsics.max_range_m + step_m / 2.0, step_m)
    hit = lidar_covers(mount, mount.pose.x_m + r, np.full_like(r, mount.pose.y_m), extinction_per_m)
    if not hit.any():
        return None
    return float(r[hit].min()), float(r[hit].max())


def camera_covers(
    mount: SensorMount,
    x_m: npt.ArrayLike,
    y_m: npt.ArrayLike,
    range_m: float = CAMERA_RANGE_M,
    camera: PinholeCamera | None = None,
) -> Bool:
    """Whether a car at each point is in the camera's picture and range (module docstring);
    ``camera``: the mount's :class:`PinholeCamera`, when the caller keeps one."""
    intrinsics = mount.intrinsics
    assert isinstance(intrinsics, CameraIntrinsics)
    x = np.atleast_1d(np.asarray(x_m, float))
    y = np.atleast_1d(np.asarray(y_m, float))
    camera = camera if camera is not None else PinholeCamera(mount)
    points = np.column_stack([x, y, np.full_like(x, CAR_HEIGHT_M / 2.0)])
    uv, depth = camera.project(points)
    with np.errstate(invalid="ignore"):
        inside = (
            (depth > 0.0)
            & (uv[:, 0] >= 0.0)
            & (uv[:, 0] < intrinsics.width_px)
            & (uv[:, 1] >= 0.0)
            & (uv[:, 1] < intrinsics.height_px)
        )
    near = np.hypot(x - mount.pose.x_m, y - mount.pose.y_m) <= range_m
    result: Bool = inside & near
    return result


def radar_covers(mount: SensorMount, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> Bool:
    """Whether each point is inside the radar's range and field of view."""
    intrinsics = mount.intrinsics
    assert isinstance(intrinsics, RadarIntrinsics)
    dx = np.asarray(x_m, float) - mount.pose.x_m
    dy = np.asarray(y_m, float) - mount.pose.y_m
    azimuth = np.arctan2(dy, dx) - mount.pose.ground_heading_rad()
    azimuth = (azimuth + math.pi) % (2.0 * math.pi) - math.pi
    result: Bool = (np.hypot(dx, dy) <= intrinsics.max_range_m) & (
        np.abs(azimuth) <= math.radians(intrinsics.horizontal_fov_deg) / 2.0
    )
    return result


class SiteCoverage:
    """What a site's sensors cover (:func:`covered`), the cameras' models built once.

    ``lidar_extinction_per_m`` and ``visibility_m``: the weather (clear by default): the
    LiDAR's extinction coefficient [1/m] (fog and rain) and the meteorological visibility [m]
    that limits the camera in fog. The radar is taken to see through both.
    """

    def __init__(
        self, site: Site, lidar_extinction_per_m: float = 0.0, visibility_m: float = math.inf
    ) -> None:
        self.site = site
        self.lidar_extinction_per_m = lidar_extinction_per_m
        self.camera_range_m = min(CAMERA_RANGE_M, camera_fog_range_m(visibility_m))
        self._cameras = {m.sensor_id: PinholeCamera(m) for m in site.sensors if m.kind == "camera"}

    def sensor(self, mount: SensorMount, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> Bool:
        """Whether ``mount`` can see a car at each point (dispatch on its kind)."""
        if mount.kind == "lidar":
            return lidar_covers(mount, x_m, y_m, self.lidar_extinction_per_m)
        if mount.kind == "camera":
            return camera_covers(
                mount, x_m, y_m, self.camera_range_m, camera=self._cameras[mount.sensor_id]
            )
        return radar_covers(mount, x_m, y_m)

    def __call__(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> Bool:
        """Whether at least one of the site's sensors can see a car at each point."""
        x = np.atleast_1d(np.asarray(x_m, float))
        y = np.atleast_1d(np.asarray(y_m, float))
        out = np.zeros(x.shape, dtype=bool)
        for mount in self.site.sensors:
            out |= self.sensor(mount, x, y)
        return out


class SiteSight:
    """Whether other vehicles hide points from every one of a site's sensors that covers them
    (:class:`SiteCoverage`: range, field of view, beams; clear weather
    unless ``coverage`` says otherwise)."""

    def __init__(self, site: Site, coverage: SiteCoverage | None = None) -> None:
        self._coverage = SiteCoverage(site) if coverage is None else coverage
        self._mounts = list(site.sensors)

    def covers(self, targets_m: npt.ArrayLike) -> Bool:
        """Which sensor covers which target (M, 3) [m]: shape (S, M), the site's sensors in
        order. Fixed points (a lane's loop spot) take it once for every :meth:`hidden`."""
        targets = np.asarray(targets_m, dtype=np.float64).reshape(-1, 3)
        rows = [self._coverage.sensor(m, targets[:, 0], targets[:, 1]) for m in self._mounts]
        return np.array(rows, dtype=bool).reshape(len(self._mounts), targets.shape[0])

    def hidden(self, targets_m: npt.ArrayLike, boxes: Boxes, covers: Bool | None = None) -> Bool:
        """Whether every sensor that covers each target (M, 3) [m] has a box in its sight line;
        False where none covers it. ``covers``: :meth:`covers` of these targets, if known."""
        targets = np.asarray(targets_m, dtype=np.float64).reshape(-1, 3)
        covers = self.covers(targets) if covers is None else covers
        seen = np.zeros(targets.shape[0], dtype=bool)
        for mount, row in zip(self._mounts, covers, strict=True):
            if row.any():
                seen |= row & ~hidden(mount.pose.position_m, targets, boxes)
        result: Bool = covers.any(axis=0) & ~seen
        return result


#: The longest stretch no sensor sees that a tracker bridges by coasting [m]: the blind cone
#: under a mast (a 64-beam LiDAR 8 m up sees the road from about 20 m out) with the stretch
#: where the cameras and radars facing upstream have already lost a vehicle.
MAX_SENSOR_GAP_M = 80.0


class SensorGaps:
    """The stretches of each lane that no sensor sees but that seen road bounds on both sides:
    where a vehicle is only out of sight for a moment, and a tracker coasts its track across
    instead of ending it (a vehicle passing under the mast, from the upstream-facing camera and
    radar to the LiDAR beyond its blind cone).

    Built once from the site file (:class:`SiteCoverage`, clear weather unless ``coverage``
    says otherwise): along each lane's centre line every ``step_m``, the uncovered runs of at
    most ``max_gap_m`` with covered road before and after. A point belongs to the lane whose
    centre is nearest its offset (within half a lane width and a metre).
    """

    def __init__(
        self,
        site: Site,
        *,
        max_gap_m: float = MAX_SENSOR_GAP_M,
        step_m: float = 1.0,
        coverage: SiteCoverage | None = None,
    ) -> None:
        coverage = SiteCoverage(site) if coverage is None else coverage
        self.site = site
        self.step_m = step_m
        frame = site.road_frame
        self._stations = np.arange(0.0, frame.length_m, step_m)
        self._offsets = np.array([lane.center_offset_m for lane in site.lanes])
        self._half_widths = np.array([0.5 * lane.width_m + 1.0 for lane in site.lanes])
        self.gaps = np.zeros((len(site.lanes), self._stations.size), dtype=bool)
        for row, offset in enumerate(self._offsets):
            x, y = frame.to_site(self._stations, np.full(self._stations.shape, offset))
            seen = coverage(x, y)
            self.gaps[row] = _bounded_runs(~seen, int(max_gap_m / step_m))

    def spans_m(self, lane_row: int) -> list[tuple[float, float]]:
        """The gaps of the ``lane_row``-th lane of the site file, as station spans [m]."""
        mask = self.gaps[lane_row]
        edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
        return [
            (float(self._stations[a]), float(self._stations[b - 1]))
            for a, b in zip(edges[::2], edges[1::2], strict=True)
        ]

    def __call__(self, x_m: float, y_m: float) -> bool:
        """Whether a site point lies in a lane's gap."""
        station, offset = self.site.road_frame.to_road(x_m, y_m)
        d = np.abs(self._offsets - float(offset))
        row = int(np.argmin(d))
        if d[row] > self._half_widths[row]:
            return False
        k = round(float(station) / self.step_m)
        return 0 <= k < self._stations.size and bool(self.gaps[row, k])


def _bounded_runs(unseen: Bool, max_len: int) -> Bool:
    """The runs of True in ``unseen`` of at most ``max_len`` with False on both sides."""
    out = np.zeros_like(unseen)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], unseen.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if a > 0 and b < unseen.size and b - a <= max_len:
            out[a:b] = True
    return out
