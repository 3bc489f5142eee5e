"""The radar learns its yaw and its clock against the LiDAR's objects (issue 39).

A radar target is a range, an azimuth and a radial speed. Paired with the LiDAR's objects at
``stamp - dt`` (each object's echo: the centre of its face nearest the radar, the simulator's
model, :func:`~wz_camera_detector.association.face_offsets`), the bearing residual is the yaw
correction and the horizontal range residual is ``c + (u . v) dt`` for the object's velocity
``v`` along the line of sight ``u``; a late clock moves the bearing too, by the bearing's rate
times ``dt`` (fast near the radar). The yaw, the clock and ``c`` are fitted on both residuals
together (Gauss-Newton, the pairs matched again between steps). At one speed a late clock and a
range offset look alike in range, so ``c`` is held near zero (the fusion ranges with the same
echo model); the near bearings tell the clock apart. Fitted on the ranges alone, the clock
traded against ``c`` and left its error in the near bearings, which the yaw took: 0.08 deg on a
surveyed radar and 0.2 deg off on real masts (replays of seeds 3 and 5); now 0.00 and 0.09. A
vote over the bearing residuals starts it; a knock shows as the recent bearings standing off.
The camera's module (:mod:`wz_camera_detector.calibration`) holds the shared settings and the
LiDAR's reference objects.
"""

from __future__ import annotations

import logging
import math
from collections import deque

import numpy as np

from wz_camera_detector.association import face_offsets
from wz_camera_detector.calibration import ReferenceObjects, SensorCalibrationSettings
from wz_shared.arrays import F64, Bool
from wz_shared.messages import CalibrationState, PoseCorrection, RadarScan, SensorCalibration
from wz_shared.self_calibration import CalibrationLog, bounded_correction, corrected_pose
from wz_shared.site import SensorMount

log = logging.getLogger("wz_camera_detector.radar_calibration")


class RadarSelfCalibration:
    """One radar's yaw and clock learned against the LiDAR's objects (module docstring)."""

    def __init__(
        self,
        site_id: str,
        mount: SensorMount,
        settings: SensorCalibrationSettings,
        reference: ReferenceObjects,
        target_height_m: float = 0.5,
    ) -> None:
        self.mount = mount
        self.nominal = mount.pose
        self.settings = settings
        self.reference = reference
        self.log = CalibrationLog(site_id, mount.sensor_id, "radar")
        self._height = mount.pose.z_m - target_height_m
        #: Per kept scan: (stamp, horizontal range, azimuth, ...) rows.
        self._scans: deque[tuple[float, F64]] = deque()
        self._pending: deque[RadarScan] = deque()
        self._next_keep_s = -math.inf
        self._next_fit_s = -math.inf
        self._initialised = False
        self._bump_votes = 0
        self.yaw_rad = 0.0
        self.clock_offset_s = 0.0
        self.range_offset_m = 0.0
        #: The radar's position across its boresight, learned [m] (left positive).
        self.shift_m = 0.0
        self.std = (math.nan, math.nan)
        self._clock_variance_s2 = math.nan
        self.pairs = 0
        self.correction = PoseCorrection()
        self.pose = mount.pose
        self._last_stamp_s = 0.0

    def observe(self, scan: RadarScan) -> None:
        """A radar scan on the radar's clock."""
        if not self.settings.enabled:
            return
        self._last_stamp_s = max(self._last_stamp_s, scan.stamp)
        if scan.stamp >= self._next_keep_s and scan.targets:
            self._next_keep_s = scan.stamp + 1.0 / self.settings.frames_per_s
            self._pending.append(scan)
        self.pair_pending()
        while self._scans and self._scans[0][0] < scan.stamp - self.settings.window_s:
            self._scans.popleft()
        if scan.stamp >= self._next_fit_s and len(self._scans) >= 10:
            self._next_fit_s = scan.stamp + self.settings.fit_every_s
            self._fit(scan.stamp)

    def pair_pending(self) -> None:
        newest = self.reference.newest_s
        while self._pending:
            scan = self._pending[0]
            if scan.stamp - self.clock_offset_s > newest:
                return
            self._pending.popleft()
            snapshot = self.reference.at(scan.stamp - self.clock_offset_s)
            if snapshot is None or not len(snapshot.xy_m):
                continue
            targets = np.array([(t.range_m, t.azimuth_rad) for t in scan.targets], dtype=np.float64)
            rho = np.sqrt(np.maximum(targets[:, 0] ** 2 - self._height**2, 0.0))
            # rows: per (target, object): rho, azimuth, object x, y, vx, vy, heading, L, W, lag,
            # target index, scan stamp
            rows = []
            for k in range(len(targets)):
                for i in range(len(snapshot.xy_m)):
                    rows.append(
                        (
                            rho[k],
                            targets[k, 1],
                            *snapshot.xy_m[i],
                            *snapshot.velocity_mps[i],
                            snapshot.heading_rad[i],
                            *_SIZES.get(snapshot.object_class[i], _SIZES["car"]),
                            scan.stamp - snapshot.stamp_s,
                            float(k),
                            scan.stamp,
                        )
                    )
            if rows:
                self._scans.append((scan.stamp, np.array(rows, dtype=np.float64)))

    def _predicted(self, rows: F64, clock_s: float) -> tuple[F64, F64, F64]:
        """Bearing [rad] and horizontal range [m] of each row's echo, and its range rate
        [m/s]: the echo is the centre of the object's face nearest the radar (the simulator's
        model; :func:`~wz_camera_detector.association.face_offsets`)."""
        pose = self.nominal
        normal = self._boresight_normal()
        dt = rows[:, 9] - clock_s
        x = rows[:, 2] + rows[:, 4] * dt - (pose.x_m + self.shift_m * normal[0])
        y = rows[:, 3] + rows[:, 5] * dt - (pose.y_m + self.shift_m * normal[1])
        distance = np.hypot(x, y)
        face = face_offsets(-np.stack([x, y], 1), rows[:, 6], rows[:, 7], rows[:, 8])
        ex, ey = x + face[:, 0], y + face[:, 1]
        bearing = np.arctan2(ey, ex)
        rate = (x * rows[:, 4] + y * rows[:, 5]) / np.maximum(distance, 1e-6)
        return bearing, np.hypot(ex, ey), rate

    def _boresight_normal(self) -> F64:
        heading = self.nominal.ground_heading_rad()
        return np.array([-math.sin(heading), math.cos(heading)])

    def _shift_lever(self, rows: F64, bearing: F64) -> F64:
        """``(n_b . n) / r`` per row: the boresight's and the line of sight's left normals."""
        normal = self._boresight_normal()
        los_normal = np.stack([-np.sin(bearing), np.cos(bearing)], 1)
        return np.asarray((los_normal @ normal) / np.maximum(rows[:, 0], 1.0), dtype=np.float64)

    def _fit(self, stamp_s: float) -> None:
        rows = np.concatenate([r for _, r in self._scans])
        heading = self.nominal.ground_heading_rad()
        if not self._initialised or self.log.state == CalibrationState.BUMPED:
            bearing, rho_pred, _ = self._predicted(rows, self.clock_offset_s)
            near = np.abs(rows[:, 0] - rho_pred) < 4.0
            diff = _wrap(heading + rows[near, 1] - bearing[near])
            diff = diff[np.abs(diff) < math.radians(8.0)]
            if diff.size < 20:
                return
            hist, edges = np.histogram(diff, bins=np.radians(np.arange(-8.0, 8.01, 0.2)))
            k = int(np.convolve(hist, [1, 1, 1], mode="same").argmax())
            # diff = heading + azimuth - bearing = -(the radar's yaw error)
            self.yaw_rad = -float(0.5 * (edges[k] + edges[k + 1]))
            self._initialised = True
        elif self.log.state == CalibrationState.CALIBRATED:
            self._check_bump(stamp_s, heading)
        for gate_rad, gate_m in (
            (math.radians(1.5), 3.0),
            (math.radians(1.0), 2.0),
            (math.radians(0.8), 1.5),
            (math.radians(0.8), 1.5),
            (math.radians(0.8), 1.5),
        ):
            bearing, rho_pred, _ = self._predicted(rows, self.clock_offset_s)
            d_bearing = _wrap(heading + self.yaw_rad + rows[:, 1] - bearing)
            d_range = rows[:, 0] - rho_pred - self.range_offset_m
            ok = (np.abs(d_bearing) < gate_rad) & (np.abs(d_range) < gate_m)
            # One object per target: the nearest in range among those in the gate.
            chosen = _best_per_target(rows, ok, np.abs(d_range))
            if chosen.sum() < 20:
                return
            self.pairs = int(chosen.sum())
            self._step(
                rows[chosen], d_bearing[chosen], d_range[chosen], bearing[chosen], rho_pred[chosen]
            )
            bias = d_bearing[chosen]
            yaw_std = (
                1.4826
                * float(np.median(np.abs(bias - np.median(bias))))
                / math.sqrt(self.pairs / self.settings.frames_per_vehicle)
            )
            clock_std = math.sqrt(self._clock_variance_s2 * self.settings.frames_per_vehicle)
            self.std = (math.degrees(yaw_std), clock_std)
            log.debug(
                "radar %s fit: yaw %.3f deg, clock %.1f ms, range offset %.2f m, %d pairs",
                self.mount.sensor_id,
                math.degrees(self.yaw_rad),
                1000 * self.clock_offset_s,
                self.range_offset_m,
                self.pairs,
            )
        self.clock_offset_s = float(np.clip(self.clock_offset_s, -0.5, 0.5))
        if self.pairs >= self.settings.min_pairs:
            normal = self._boresight_normal()
            self.correction = bounded_correction(
                yaw_deg=math.degrees(self.yaw_rad),
                yaw_std_deg=self.std[0],
                x_m=self.shift_m * float(normal[0]),
                y_m=self.shift_m * float(normal[1]),
            )
            self.pose = corrected_pose(self.nominal, self.correction)
        if self.log.state == CalibrationState.PRIOR:
            self.log.enter(CalibrationState.LEARNING, stamp_s, "learning from the LiDAR's vehicles")
        if (
            self.pairs >= self.settings.calibrated_pairs
            and self.std[0] <= self.settings.calibrated_std_deg
            and self.log.state in (CalibrationState.LEARNING, CalibrationState.BUMPED)
        ):
            self.log.enter(
                CalibrationState.CALIBRATED,
                stamp_s,
                f"yaw {math.degrees(self.yaw_rad):+.2f} deg, clock "
                f"{1000 * self.clock_offset_s:+.0f} ms from {self.pairs} targets",
            )

    def _step(self, rows: F64, d_bearing: F64, d_range: F64, bearing: F64, range_now: F64) -> None:
        """One Gauss-Newton step of the yaw, the clock, the range offset (and the shift across
        the boresight with ``radar_shift``) from the paired rows' bearing and range residuals
        together (``bearing``, ``range_now``: the rows' predicted echo at the current clock).

        A late clock moves each object along its path: its range by ``-rate dt`` and its
        bearing by ``-bearing_rate dt``. Near the radar the bearing moves fast (a car 8 m to
        the side at 20 m and 25 m/s: 0.5 deg in 10 ms), so a clock fitted to the ranges alone
        (where it trades against the range offset) would leave its error in the near bearings
        and the yaw would take it. Fitted on both, the bearings pin the clock down.
        """
        eps = 1e-3
        bearing_late, range_late, _ = self._predicted(rows, self.clock_offset_s + eps)
        # d(predicted)/d(clock): the residuals move the other way.
        bearing_rate = np.asarray(_wrap(bearing_late - bearing), dtype=np.float64) / eps
        range_rate = (range_late - range_now) / eps
        n = rows.shape[0]
        sigma_b = max(1.4826 * float(np.median(np.abs(d_bearing - np.median(d_bearing)))), 1e-4)
        sigma_r = max(1.4826 * float(np.median(np.abs(d_range - np.median(d_range)))), 0.05)
        inlier_b = np.abs(d_bearing - np.median(d_bearing)) <= 3.0 * sigma_b
        inlier_r = np.abs(d_range - np.median(d_range)) <= 3.0 * sigma_r
        shift = self.settings.radar_shift
        # The residuals' derivatives by the yaw, the clock, the range offset (and the shift):
        # d_bearing = heading + yaw + azimuth - predicted bearing (a radar moved left by s sees
        # a target at range r a bearing s (n_b . n) / r smaller), d_range = range - predicted
        # range - range offset.
        k = 4 if shift else 3
        j_b = np.zeros((n, k))
        j_b[:, 0] = 1.0
        j_b[:, 1] = -bearing_rate
        j_r = np.zeros((n, k))
        j_r[:, 1] = -range_rate
        j_r[:, 2] = -1.0
        if shift:
            j_b[:, 3] = self._shift_lever(rows, bearing)
        w_b = inlier_b / sigma_b**2
        w_r = inlier_r / sigma_r**2
        normal = (j_b.T * w_b) @ j_b + (j_r.T * w_r) @ j_r
        gradient = (j_b.T * w_b) @ d_bearing + (j_r.T * w_r) @ d_range
        # Priors on the totals (held near zero: the clock, range offset and shift), not on
        # the steps.
        prior = np.zeros((k, k))
        prior[1, 1] = 1.0 / self.settings.prior_clock_s**2
        prior[2, 2] = 1.0 / self.settings.prior_range_m**2
        current = np.zeros(k)
        current[1], current[2] = self.clock_offset_s, self.range_offset_m
        if shift:
            prior[3, 3] = 1.0 / self.settings.prior_horizontal_m**2
            current[3] = self.shift_m
        step = -np.linalg.solve(normal + prior, gradient + prior @ current)
        self.yaw_rad += float(step[0])
        self.clock_offset_s += float(step[1])
        self.range_offset_m += float(step[2])
        if shift:
            self.shift_m = float(np.clip(self.shift_m + step[3], -1.0, 1.0))
        self._clock_variance_s2 = float(np.linalg.inv(normal + prior)[1, 1])

    def _check_bump(self, stamp_s: float, heading: float) -> None:
        recent = [r for t, r in self._scans if t >= stamp_s - self.settings.bump_window_s]
        if not recent:
            return
        rows = np.concatenate(recent)
        bearing, rho_pred, _ = self._predicted(rows, self.clock_offset_s)
        d_bearing = _wrap(heading + self.yaw_rad + rows[:, 1] - bearing)
        d_range = rows[:, 0] - rho_pred - self.range_offset_m
        ok = (np.abs(d_bearing) < math.radians(5.0)) & (np.abs(d_range) < 2.0)
        chosen = _best_per_target(rows, ok, np.abs(d_bearing))
        if chosen.sum() < 8:
            return
        moved = abs(math.degrees(float(np.median(d_bearing[chosen]))))
        self._bump_votes = self._bump_votes + 1 if moved > self.settings.bump_deg else 0
        if self._bump_votes >= 2:
            self._bump_votes = 0
            self.log.enter(
                CalibrationState.BUMPED, stamp_s, f"its bearings stand {moved:.2f} deg off"
            )
            while self._scans and self._scans[0][0] < stamp_s - self.settings.bump_window_s:
                self._scans.popleft()

    @property
    def angle_std_rad(self) -> float:
        if self.log.state in (CalibrationState.PRIOR, CalibrationState.BUMPED) or not math.isfinite(
            self.std[0]
        ):
            return math.radians(1.0)
        return math.radians(self.std[0])

    def message(self) -> SensorCalibration:
        std = self.std[1] if math.isfinite(self.std[1]) else None
        return self.log.message(
            self._last_stamp_s, self.correction, self.clock_offset_s, std, self.pairs
        )


#: Echo sizes (length, width) by class [m].
_SIZES: dict[str, tuple[float, float]] = {
    "car": (4.6, 1.8),
    "truck": (16.5, 2.6),
    "bus": (12.0, 2.55),
    "motorcycle": (2.2, 0.8),
    "unknown": (4.6, 1.8),
}


def _wrap(angle: F64) -> F64:
    return np.asarray((np.asarray(angle) + math.pi) % (2 * math.pi) - math.pi, dtype=np.float64)


def _best_per_target(rows: F64, ok: Bool, cost: F64) -> Bool:
    """Of the rows in ``ok``, the one of least ``cost`` per (scan stamp lag, target) pair."""
    chosen = np.zeros(len(rows), dtype=bool)
    keys = np.round(rows[:, 11] * 1000.0) * 1000.0 + rows[:, 10]
    index = np.flatnonzero(ok)
    if not index.size:
        return chosen
    order = index[np.lexsort((cost[index], keys[index]))]
    _, first = np.unique(keys[order], return_index=True)
    chosen[order[first]] = True
    return chosen
