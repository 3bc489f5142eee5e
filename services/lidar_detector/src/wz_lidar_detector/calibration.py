"""The LiDAR learns its own pose from the road and the traffic on it (issue 39).

No LiDAR stands exactly where its site file says: a technician's level, tape and compass leave
about a degree of yaw, half a degree of pitch and roll and a couple of decimetres of position,
and a degree of yaw alone moves a vehicle 1.7 m across the road at 100 m. Two things the
LiDAR sees fix most of its pose without any survey:

**The road surface** gives pitch, roll and height. The ground is the plane ``z = 0`` of the
site frame (the site's flat road). Its unit normal seen from the sensor is ``n = R^T e_z``;
with ``R = Rz(yaw) Ry(-pitch) Rx(roll)`` (:meth:`wz_shared.site.Pose.rotation`)::

    n = (sin pitch, sin roll cos pitch, cos roll cos pitch)

so ``pitch = asin(n_x)``, ``roll = atan2(n_y, n_z)``, and the sensor's height is its distance
to the plane (yaw does not change ``n``). :func:`fit_ground` fits the plane to the returns
within a band of the road's height under the current pose (least squares, narrowed to a
15 cm band and refitted until the returns in it settle), once a second, over the ranges where
the sensor's beams meet the road (:func:`ground_range`); the estimate is the median of the
last fits.

**The vehicles on their lanes** give yaw and the position across the road. Vehicles drive on
their lanes' centres, on average: a detected centre's offset from the nearest lane centre is,
for a sensor turned by ``dpsi`` and shifted by ``dn`` along the road's normal at the sensor,::

    residual_i = d_i + dpsi (n_i . J (q_i - c)) + dn (n_i . n_c) - lane centre

(``q_i`` the centre placed by the site file's yaw, ``c`` the sensor, ``J`` a quarter turn,
``n`` the road's left normal). A yaw moves far vehicles more than near ones; a shift moves
all alike: the two are told apart by the spread of ranges. :func:`fit_lane_alignment` finds
the pair by a vote over a grid (robust to the 3 deg, 5 m-at-100 m, that would send a vehicle to
the wrong lane) and refines it by trimmed least squares. The position *along* the road is
left at the site file's: on a straight road nothing in traffic tells it (it only shifts
every track a few decimetres along the road; speeds, gaps and the alerts do not change).

**A bump** (a sensor knocked round) shows as the yaw fitted to the last few seconds standing
away from the learned one (or the ground's tilt moving): twice in a row past its threshold and
the sensor is ``bumped``: the window is cleared, the pose is learned again from new vehicles,
and meanwhile every detection carries the yaw's uncertainty in its covariance
(:func:`wz_shared.self_calibration.angular_covariance`), so the tracker leans on the other
sensors.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from wz_shared.arrays import F64
from wz_shared.messages import CalibrationState, PoseCorrection, SensorCalibration
from wz_shared.self_calibration import (
    CalibrationLog,
    bounded,
    bounded_correction,
    corrected_pose,
    robust_std,
)
from wz_shared.site import LidarIntrinsics, Pose, SensorMount, Site


class LidarCalibrationSettings(BaseModel):
    """How the LiDAR learns its pose (``WZ_LIDAR_CALIBRATION__*``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    #: Learn and apply the pose; False: the site file's pose, as surveyed.
    enabled: bool = True
    #: A ground fit every this many seconds of sensor time [s].
    ground_every_s: float = Field(default=1.0, gt=0.0)
    #: Ground fits the pitch, roll and height are the median of.
    ground_fits: int = Field(default=15, ge=1, le=600)
    #: Returns within this horizontal range are the ground fit's [m]: near enough for the beams
    #: to be dense, far from the mast's own trailer. A LiDAR whose lowest beam meets the road
    #: farther out gets the range its beams see (:func:`ground_range`).
    ground_range_m: tuple[float, float] = (4.0, 40.0)
    #: A fit's band around the ground under the current pose [m], the first and the last.
    ground_band_m: tuple[float, float] = (1.5, 0.15)
    #: Box centres within this horizontal range feed the lane alignment [m].
    lane_range_m: tuple[float, float] = (8.0, 150.0)
    #: Seconds of box centres the lane alignment is fitted to [s].
    lane_window_s: float = Field(default=90.0, gt=0.0)
    #: Box centres before a yaw and shift are applied.
    lane_min_samples: int = Field(default=300, ge=10)
    #: Seconds between lane fits while learning, and once calibrated [s] (the bump check
    #: runs every ``lane_every_s``).
    lane_every_s: float = Field(default=1.0, gt=0.0)
    calibrated_lane_every_s: float = Field(default=10.0, gt=0.0)
    #: A residual beyond this is not on its lane (a lane change, a false box) [m].
    lane_trim_m: float = Field(default=0.8, gt=0.0)
    #: Box centres of one vehicle seen frame after frame are not independent: the formal
    #: standard deviations are multiplied by the square root of this.
    frames_per_vehicle: float = Field(default=30.0, ge=1.0)
    #: The bump check: the yaw of the last seconds [s] against the learned one [deg], and the
    #: ground's tilt [deg].
    bump_window_s: float = Field(default=4.0, gt=0.0)
    bump_yaw_deg: float = Field(default=0.6, gt=0.0)
    bump_tilt_deg: float = Field(default=0.6, gt=0.0)
    bump_min_samples: int = Field(default=40, ge=5)
    #: The bump check votes afresh when fewer of the recent centres than this share lie on a
    #: lane under the learned pose (a lane change or a false box leaves most on).
    bump_on_lane_share: float = Field(default=0.8, gt=0.0, le=1.0)
    #: Ground fits once calibrated: every this many seconds [s].
    calibrated_ground_every_s: float = Field(default=5.0, gt=0.0)
    #: Yaw std [deg] below which (with the ground fits done) the sensor is ``calibrated``.
    calibrated_yaw_std_deg: float = Field(default=0.1, gt=0.0)


@dataclass(frozen=True)
class GroundFit:
    """One frame's ground plane seen from the sensor."""

    pitch_deg: float
    roll_deg: float
    height_m: float
    points: int
    rms_m: float


def tilt_from_normal(normal: F64) -> tuple[float, float]:
    """(pitch, roll) [deg] of a sensor that sees the site's up direction as ``normal``."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    if n[2] < 0:
        n = -n
    pitch = math.degrees(math.asin(float(np.clip(n[0], -1.0, 1.0))))
    roll = math.degrees(math.atan2(float(n[1]), float(n[2])))
    return pitch, roll


def ground_range(mount: SensorMount, range_m: tuple[float, float]) -> tuple[float, float]:
    """The horizontal range [m] whose ground the LiDAR on ``mount`` sees, from ``range_m`` on.

    A sensor ``h`` above the road whose lowest beam points ``d`` below the horizon first
    meets the road at ``h / tan d``; nearer, its returns are the mast's trailer and nothing of
    the road. A narrow-field LiDAR high on a mast (a 64-beam unit of +-11 deg at 7.6 m meets
    the road at 38 m) would leave ``range_m``'s 40 m a sliver of its lowest ring, where a
    plane is barely conditioned: the range becomes from 0.9 of that distance to twice it (the
    lower half of its beams' depression). The sensor's own tilt can lower or raise the beam
    by up to ``hypot(pitch, roll)``; the near edge takes the steepest.
    """
    intrinsics = mount.intrinsics
    if not isinstance(intrinsics, LidarIntrinsics) or mount.pose.z_m <= 0.0:
        return range_m
    tilt = math.hypot(mount.pose.pitch_deg, mount.pose.roll_deg)
    steepest = -intrinsics.vertical_min_deg + tilt
    if steepest <= 1.0 or steepest >= 89.0:
        return range_m
    first = mount.pose.z_m / math.tan(math.radians(steepest))
    low, high = range_m
    return max(low, 0.9 * first), max(high, 2.0 * first)


def fit_ground(
    xyz_sensor: npt.NDArray[np.floating],
    pose: Pose,
    ground_z_m: float = 0.0,
    range_m: tuple[float, float] = (4.0, 40.0),
    band_m: tuple[float, float] = (1.5, 0.15),
    max_points: int = 20_000,
) -> GroundFit | None:
    """The ground plane under a LiDAR from one frame's returns (sensor frame, finite).

    Returns within ``range_m`` (horizontal) whose height under ``pose`` is within the first of
    ``band_m`` of ``ground_z_m`` are fitted by least squares; the fit is repeated with the
    returns within narrower bands of the plane found, down to the last of ``band_m``, until
    they stop changing (a vehicle's roof or a drum leaves it); None when fewer than 200
    returns remain.
    """
    xyz = np.asarray(xyz_sensor).reshape(-1, 3)
    if len(xyz) > 4 * max_points:  # a sweep's 100 000+ returns: every k-th is plenty
        xyz = xyz[:: len(xyz) // (2 * max_points)]
    xyz = np.asarray(xyz, dtype=np.float64)
    horizontal = np.hypot(xyz[:, 0], xyz[:, 1])
    near = (horizontal >= range_m[0]) & (horizontal <= range_m[1])
    xyz = xyz[near]
    if len(xyz) > max_points:
        xyz = xyz[:: math.ceil(len(xyz) / max_points)]
    site_z = xyz @ pose.rotation()[2] + pose.z_m
    chosen = xyz[np.abs(site_z - ground_z_m) <= band_m[0]]
    if len(chosen) < 200:
        return None

    def plane(points: F64) -> tuple[F64, float]:
        centroid = points.mean(axis=0)
        _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
        normal = vt[2] if vt[2][2] >= 0 else -vt[2]
        return normal, -float(normal @ centroid)

    def settle(normal: F64, offset: float, bands: list[float]) -> tuple[F64, float, F64]:
        """Narrowed to the last band, then refitted until the returns within it stop
        changing: (normal, offset, the returns fitted)."""
        chosen = np.zeros((0, 3))
        inside = np.zeros(len(xyz), dtype=bool)
        for band in (*bands, *[band_m[1]] * 8):
            keep = np.abs(xyz @ normal + offset) <= band
            if keep.sum() < 200:
                break
            if band == band_m[1] and np.array_equal(keep, inside):
                break
            inside = keep
            chosen = xyz[keep]
            normal, offset = plane(chosen)
        return normal, offset, chosen

    # Two starts, and the plane more returns lie on wins (the road is the largest surface):
    # the fit to the wide band's returns leans towards what stands on the road (drums,
    # barriers, a trailer, a truck's roof in traffic) and a tilted sensor's road leaves the
    # band at the range's far end until the plane has turned; the plane the pose gives
    # starts on the road, if the pose is near.
    wide = settle(*plane(chosen), list(np.geomspace(band_m[0], band_m[1], 3)[1:]))
    up = pose.rotation()[2]  # the site's up in the sensor frame
    posed = settle(up, pose.z_m - ground_z_m, [float(np.sqrt(band_m[0] * band_m[1]))])
    normal, offset, chosen = max((wide, posed), key=lambda fit: len(fit[2]))
    if len(chosen) < 200:
        return None
    residual = chosen @ normal + offset
    pitch, roll = tilt_from_normal(normal)
    return GroundFit(
        pitch_deg=pitch,
        roll_deg=roll,
        height_m=offset + ground_z_m,  # the sensor's distance above the plane, plus its height
        points=len(chosen),
        rms_m=float(np.sqrt(np.mean(residual**2))),
    )


@dataclass(frozen=True)
class LaneFit:
    """Yaw and cross-road shift of a sensor from its vehicles on the lanes."""

    yaw_rad: float
    shift_m: float
    yaw_std_rad: float
    shift_std_m: float
    inliers: int
    rms_m: float


def _lane_terms(
    site: Site, centres_xy_m: F64, sensor_xy_m: tuple[float, float]
) -> tuple[F64, F64, F64, F64]:
    """Per centre: its offset ``d``, its yaw lever ``a``, its shift lever ``b``; the normal."""
    road = site.road_frame
    stations, offsets = road.to_road(centres_xy_m[:, 0], centres_xy_m[:, 1])
    normals = np.asarray(road.normal_at(stations), dtype=np.float64).reshape(-1, 2)
    sensor_station, _ = road.to_road(sensor_xy_m[0], sensor_xy_m[1])
    sensor_normal = np.asarray(road.normal_at(sensor_station), dtype=np.float64).reshape(2)
    rel = centres_xy_m - np.asarray(sensor_xy_m)
    turned = np.stack([-rel[:, 1], rel[:, 0]], axis=1)  # J (q - c)
    lever_yaw = np.einsum("ij,ij->i", normals, turned)
    lever_shift = normals @ sensor_normal
    return np.asarray(offsets, dtype=np.float64).reshape(-1), lever_yaw, lever_shift, sensor_normal


def _nearest_lane(offsets_m: F64, lanes_m: F64) -> F64:
    """Each offset minus the nearest lane centre."""
    diff = offsets_m[:, None] - lanes_m[None, :]
    return np.asarray(diff[np.arange(len(diff)), np.abs(diff).argmin(axis=1)], dtype=np.float64)


def _vote(
    offsets: F64,
    lever_yaw: F64,
    lever_shift: F64,
    lanes: F64,
    yaws: F64,
    shifts: F64,
    width_m: float,
) -> tuple[float, float]:
    """The (yaw, shift) of the grid that puts most centres near a lane centre (a soft count:
    a Gaussian of ``width_m`` of each centre's distance to its nearest lane)."""
    best = (-1.0, 0.0, 0.0)
    for shift in shifts:
        moved = offsets[None, :] + yaws[:, None] * lever_yaw[None, :] + shift * lever_shift[None, :]
        gap = np.min(np.abs(moved[:, :, None] - lanes[None, None, :]), axis=2)
        score = np.exp(-0.5 * (gap / width_m) ** 2).sum(axis=1)
        index = int(score.argmax())
        if score[index] > best[0]:
            best = (float(score[index]), float(yaws[index]), float(shift))
    return best[1], best[2]


def fit_lane_alignment(
    site: Site,
    centres_xy_m: F64,
    sensor_xy_m: tuple[float, float],
    start: tuple[float, float] | None = None,
    trim_m: float = 0.8,
    search_yaw_deg: float = 6.0,
    search_shift_m: float = 1.0,
    frames_per_vehicle: float = 30.0,
    hold_shift_m: float | None = None,
) -> LaneFit | None:
    """Yaw [rad] and cross-road shift [m] that put ``centres_xy_m`` (site frame, placed with
    the pose to correct) on the site's lane centres; None with under 10 centres on a lane.

    ``start`` None: a vote over the whole search grid first (robust to large errors); else
    refine from ``start`` (yaw, shift). ``hold_shift_m``: the shift is known (a knock turns a
    sensor on its mast, it does not move it sideways), only the yaw is fitted; with few
    vehicles in few lanes a free yaw and shift together can carry one lane onto the next.
    """
    centres = np.asarray(centres_xy_m, dtype=np.float64).reshape(-1, 2)
    if len(centres) < 10:
        return None
    lanes = np.array([lane.center_offset_m for lane in site.lanes], dtype=np.float64)
    offsets, lever_yaw, lever_shift, _ = _lane_terms(site, centres, sensor_xy_m)
    if start is None:
        sample = np.arange(len(centres))
        if len(sample) > 800:
            sample = np.linspace(0, len(centres) - 1, 800).astype(int)
        d, a, b = offsets[sample], lever_yaw[sample], lever_shift[sample]
        # Coarse to fine: 0.2 deg x 0.1 m over the whole search, then 0.02 deg x 0.02 m.
        coarse_yaws = np.radians(np.arange(-search_yaw_deg, search_yaw_deg + 1e-9, 0.2))
        coarse_shifts = np.arange(-search_shift_m, search_shift_m + 1e-9, 0.1)
        if hold_shift_m is not None:
            coarse_shifts = np.array([hold_shift_m])
        yaw, shift = _vote(d, a, b, lanes, coarse_yaws, coarse_shifts, 0.35)
        fine_yaws = yaw + np.radians(np.arange(-0.2, 0.2 + 1e-9, 0.02))
        fine_shifts = shift + np.arange(-0.1, 0.1 + 1e-9, 0.02)
        if hold_shift_m is not None:
            fine_shifts = coarse_shifts
        yaw, shift = _vote(d, a, b, lanes, fine_yaws, fine_shifts, 0.2)
    else:
        yaw, shift = start
    if hold_shift_m is not None:
        shift = hold_shift_m
    design = np.stack([lever_yaw, lever_shift], axis=1)
    fitted = 1 if hold_shift_m is not None else 2
    inliers = np.zeros(len(centres), dtype=bool)
    residual = np.zeros(len(centres))
    for _ in range(6):
        residual = _nearest_lane(offsets + yaw * lever_yaw + shift * lever_shift, lanes)
        inliers = np.abs(residual) <= trim_m
        if inliers.sum() < 10:
            return None
        step, *_ = np.linalg.lstsq(design[inliers, :fitted], -residual[inliers], rcond=None)
        yaw += float(step[0])
        shift += float(step[1]) if fitted == 2 else 0.0
        if abs(step[0]) < 1e-6 and (fitted == 1 or abs(step[1]) < 1e-4):
            break
    residual = _nearest_lane(offsets + yaw * lever_yaw + shift * lever_shift, lanes)
    inliers = np.abs(residual) <= trim_m
    sigma = max(robust_std(residual[inliers]), 0.02)
    normal = design[inliers, :fitted].T @ design[inliers, :fitted]
    try:
        covariance = np.linalg.inv(normal) * sigma**2 * frames_per_vehicle
    except np.linalg.LinAlgError:
        return None
    if fitted == 1:
        covariance = np.diag([covariance[0, 0], 0.0])
    return LaneFit(
        yaw_rad=yaw,
        shift_m=shift,
        yaw_std_rad=float(math.sqrt(max(covariance[0, 0], 0.0))),
        shift_std_m=float(math.sqrt(max(covariance[1, 1], 0.0))),
        inliers=int(inliers.sum()),
        rms_m=float(np.sqrt(np.mean(residual[inliers] ** 2))),
    )


class LidarSelfCalibration:
    """One LiDAR's pose, learned online from its frames and its boxes (module docstring).

    Feed it every frame's finite returns (:meth:`observe_frame`, sensor frame) and every
    frame's box centres (:meth:`observe_boxes`, sensor frame); read :attr:`pose` (what the
    detector places boxes with), :attr:`yaw_std_rad` (what it adds to their covariance) and
    :meth:`message` (what the node publishes).
    """

    def __init__(
        self,
        site_id: str,
        mount: SensorMount,
        settings: LidarCalibrationSettings,
        site: Site | None,
    ) -> None:
        self.site = site
        self.nominal = mount.pose
        self.settings = (
            settings if site is not None else settings.model_copy(update={"enabled": False})
        )
        self.log = CalibrationLog(site_id, mount.sensor_id, "lidar")
        self.ground_range_m = ground_range(mount, settings.ground_range_m)
        self._ground: deque[GroundFit] = deque(maxlen=settings.ground_fits)
        self._next_ground_s = -math.inf
        self._next_lane_s = -math.inf
        #: Box centres in the sensor frame with their stamps.
        self._boxes: deque[tuple[float, F64]] = deque()
        self._lane: LaneFit | None = None
        self._next_full_fit_s = -math.inf
        self._bump_votes = 0
        self._bump_yaw_rad = 0.0  # the yaw the last vote found
        self._last_stamp_s = 0.0
        self.correction = PoseCorrection()
        self.pose = mount.pose

    # -- evidence ----------------------------------------------------------------------------

    def observe_frame(self, xyz_sensor: npt.NDArray[np.floating], stamp_s: float) -> None:
        """A frame's returns (sensor frame; no-return rows NaN): a ground fit when one is due
        (the frame is only read then)."""
        self._last_stamp_s = max(self._last_stamp_s, stamp_s)
        if not self.settings.enabled or stamp_s < self._next_ground_s:
            return
        every = self.settings.ground_every_s
        if self.log.state == CalibrationState.CALIBRATED:
            every = self.settings.calibrated_ground_every_s
        self._next_ground_s = stamp_s + every
        fit = fit_ground(
            xyz_sensor[np.isfinite(xyz_sensor).all(axis=1)],
            self.pose,
            range_m=self.ground_range_m,
            band_m=self.settings.ground_band_m,
        )
        if fit is None:
            return
        if len(self._ground) >= 3:
            pitch = float(np.median([g.pitch_deg for g in self._ground]))
            roll = float(np.median([g.roll_deg for g in self._ground]))
            moved = max(abs(fit.pitch_deg - pitch), abs(fit.roll_deg - roll))
            if moved > self.settings.bump_tilt_deg and self.log.state != CalibrationState.BUMPED:
                self._bumped(stamp_s, f"the ground tilted {moved:.2f} deg in one fit")
                self._ground.clear()
        self._ground.append(fit)
        self._update(stamp_s)

    def observe_boxes(self, centres_sensor_m: F64, stamp_s: float) -> None:
        """A frame's box centres (sensor frame, shape (K, 3)): a lane fit when one is due."""
        self._last_stamp_s = max(self._last_stamp_s, stamp_s)
        if not self.settings.enabled:
            return
        centres = np.asarray(centres_sensor_m, dtype=np.float64).reshape(-1, 3)
        horizontal = np.hypot(centres[:, 0], centres[:, 1])
        low, high = self.settings.lane_range_m
        centres = centres[(horizontal >= low) & (horizontal <= high)]
        if len(centres):
            self._boxes.append((stamp_s, centres))
        while self._boxes and self._boxes[0][0] < stamp_s - self.settings.lane_window_s:
            self._boxes.popleft()
        if stamp_s >= self._next_lane_s:
            self._next_lane_s = stamp_s + self.settings.lane_every_s
            self._fit_lanes(stamp_s)

    # -- state ------------------------------------------------------------------------------

    @property
    def yaw_std_rad(self) -> float:
        """The yaw's uncertainty the detections carry now [rad]: 1 deg (the site file's)
        until learned and while bumped, the fit's while learning, none once calibrated."""
        state = self.log.state
        if self._lane is None or state in (CalibrationState.PRIOR, CalibrationState.BUMPED):
            return math.radians(1.0)
        if state == CalibrationState.CALIBRATED:
            return 0.0
        return self._lane.yaw_std_rad

    def message(self) -> SensorCalibration:
        samples = sum(len(c) for _, c in self._boxes) + sum(g.points for g in self._ground)
        return self.log.message(self._last_stamp_s, self.correction, 0.0, None, samples)

    def _bumped(self, stamp_s: float, detail: str) -> None:
        self.log.enter(CalibrationState.BUMPED, stamp_s, detail)
        self._bump_votes = 0

    def _tilt_pose(self) -> Pose:
        """The pose with the ground's pitch, roll and height and the site file's yaw and xy."""
        c = self.correction
        return corrected_pose(
            self.nominal, PoseCorrection(pitch_deg=c.pitch_deg, roll_deg=c.roll_deg, z_m=c.z_m)
        )

    def _site_centres(self, centres_sensor: F64) -> F64:
        pose = self._tilt_pose()
        site = centres_sensor @ pose.rotation().T + pose.position_m
        return np.asarray(site[:, :2], dtype=np.float64)

    def _fit_lanes(self, stamp_s: float) -> None:
        samples = sum(len(c) for _, c in self._boxes)
        if self.site is None or samples < self.settings.lane_min_samples // 3:
            return
        sensor_xy = (self.nominal.x_m, self.nominal.y_m)
        calibrated = self._lane is not None and self.log.state == CalibrationState.CALIBRATED
        if calibrated and self._bump_check(stamp_s, sensor_xy):
            return
        if calibrated and stamp_s < self._next_full_fit_s:
            return  # learned: the whole window is fitted again only now and then
        self._next_full_fit_s = stamp_s + self.settings.calibrated_lane_every_s
        start = None
        if self._lane is not None and self.log.state != CalibrationState.BUMPED:
            start = (self._lane.yaw_rad, self._lane.shift_m)
        fit = fit_lane_alignment(
            self.site,
            self._site_centres(np.concatenate([c for _, c in self._boxes])),
            sensor_xy,
            start,
            trim_m=self.settings.lane_trim_m,
            frames_per_vehicle=self.settings.frames_per_vehicle,
        )
        if fit is None:
            return
        if samples >= self.settings.lane_min_samples or self.log.state == CalibrationState.BUMPED:
            self._lane = fit
        self._update(stamp_s)

    def _bump_check(self, stamp_s: float, sensor_xy: tuple[float, float]) -> bool:
        """Whether the last seconds' vehicles say the sensor was turned (then it is
        ``bumped`` and learns again from them). A cheap screen first: the share of recent
        centres on a lane under the learned pose; only when it falls is the yaw voted afresh
        (a knock of degrees sends far vehicles lanes away)."""
        assert self._lane is not None and self.site is not None
        recent = [c for t, c in self._boxes if t >= stamp_s - self.settings.bump_window_s]
        if not recent or sum(len(c) for c in recent) < self.settings.bump_min_samples:
            return False
        centres = self._site_centres(np.concatenate(recent))
        lanes = np.array([lane.center_offset_m for lane in self.site.lanes], dtype=np.float64)
        offsets, lever_yaw, lever_shift, _ = _lane_terms(self.site, centres, sensor_xy)
        residual = _nearest_lane(
            offsets + self._lane.yaw_rad * lever_yaw + self._lane.shift_m * lever_shift, lanes
        )
        on_lane = float(np.mean(np.abs(residual) <= self.settings.lane_trim_m))
        moved = 0.0
        short = None
        if on_lane < self.settings.bump_on_lane_share:
            # A knock turns the sensor: the yaw alone, at the learned shift, must put the
            # recent vehicles back on their lanes.
            short = fit_lane_alignment(
                self.site,
                centres,
                sensor_xy,
                None,
                trim_m=self.settings.lane_trim_m,
                hold_shift_m=self._lane.shift_m,
            )
            if short is not None:
                turned = _nearest_lane(
                    offsets + short.yaw_rad * lever_yaw + short.shift_m * lever_shift, lanes
                )
                explains = np.mean(np.abs(turned) <= self.settings.lane_trim_m)
                if explains >= self.settings.bump_on_lane_share:
                    moved = abs(math.degrees(short.yaw_rad - self._lane.yaw_rad))
        # Two checks in a row must find the same turn: a knock stays; a few vehicles that a
        # wrong yaw happens to fit (one lane carried onto the next) give another yaw a second on.
        if moved > self.settings.bump_yaw_deg and short is not None:
            agrees = (
                self._bump_votes > 0
                and abs(math.degrees(short.yaw_rad - self._bump_yaw_rad))
                <= 0.5 * self.settings.bump_yaw_deg
            )
            self._bump_votes = self._bump_votes + 1 if agrees else 1
            self._bump_yaw_rad = short.yaw_rad
        else:
            self._bump_votes = 0
        if self._bump_votes < 2 or short is None:
            return False
        self._bumped(stamp_s, f"its yaw moved {moved:.2f} deg in {self.settings.bump_window_s:g} s")
        # Learn again from the vehicles seen since the bump only.
        while self._boxes and self._boxes[0][0] < stamp_s - self.settings.bump_window_s:
            self._boxes.popleft()
        self._lane = replace(short, shift_std_m=self._lane.shift_std_m)  # the shift held
        self._update(stamp_s)
        return True

    def _update(self, stamp_s: float) -> None:
        correction = PoseCorrection()
        ground_known = len(self._ground) >= 3
        if ground_known:
            pitches = np.array([g.pitch_deg for g in self._ground])
            rolls = np.array([g.roll_deg for g in self._ground])
            heights = np.array([g.height_m for g in self._ground])
            spread = math.sqrt(len(self._ground))
            correction = bounded_correction(
                pitch_deg=float(np.median(pitches)) - self.nominal.pitch_deg,
                roll_deg=float(np.median(rolls)) - self.nominal.roll_deg,
                z_m=float(np.median(heights)) - self.nominal.z_m,
                pitch_std_deg=max(robust_std(pitches) / spread, 0.01),
                roll_std_deg=max(robust_std(rolls) / spread, 0.01),
                z_std_m=max(robust_std(heights) / spread, 0.005),
            )
        lane = self._lane
        if lane is not None and self.site is not None:
            road = self.site.road_frame
            station, _ = road.to_road(self.nominal.x_m, self.nominal.y_m)
            normal = np.asarray(road.normal_at(station), dtype=np.float64).reshape(2)
            shift_std = lane.shift_std_m
            correction = correction.model_copy(
                update={
                    "yaw_deg": math.degrees(lane.yaw_rad),
                    "yaw_std_deg": math.degrees(lane.yaw_std_rad),
                    "x_m": lane.shift_m * float(normal[0]),
                    "y_m": lane.shift_m * float(normal[1]),
                    # Only the cross-road part is observed: a std along the normal's axes.
                    "x_std_m": shift_std * abs(float(normal[0])) or None,
                    "y_std_m": shift_std * abs(float(normal[1])) or None,
                }
            )
        self.correction = bounded(correction)
        self.pose = corrected_pose(self.nominal, self.correction)
        state = self.log.state
        if state == CalibrationState.PRIOR and (ground_known or lane is not None):
            self.log.enter(CalibrationState.LEARNING, stamp_s, "learning from the road")
        samples = sum(len(c) for _, c in self._boxes)
        calibrated = (
            ground_known
            and lane is not None
            and samples >= self.settings.lane_min_samples
            and math.degrees(lane.yaw_std_rad) <= self.settings.calibrated_yaw_std_deg
        )
        if calibrated and self.log.state in (CalibrationState.LEARNING, CalibrationState.BUMPED):
            self.log.enter(
                CalibrationState.CALIBRATED,
                stamp_s,
                f"yaw {self.correction.yaw_deg:+.2f} deg, pitch {self.correction.pitch_deg:+.2f} "
                f"deg, roll {self.correction.roll_deg:+.2f} deg from the road and "
                f"{lane.inliers if lane else 0} vehicle positions",
            )
