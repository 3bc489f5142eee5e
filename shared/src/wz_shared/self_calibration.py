"""What every sensor's self-calibration shares: the corrected pose, the state, the message.

A sensor's *correction* (:class:`~wz_shared.messages.PoseCorrection`) is added to the site
file's pose: its angles to the pose's yaw, pitch and roll, its shift to the position.
:func:`corrected_pose` builds the pose the detector then measures with, and
:class:`CalibrationLog` keeps the state a sensor's estimator is in (prior, learning,
calibrated, bumped: :class:`~wz_shared.messages.CalibrationState`) and writes the
:class:`~wz_shared.messages.SensorCalibration` message the detector publishes.

The estimators themselves live where each sensor's measurements are made:
:mod:`wz_lidar_detector.calibration` (the LiDAR from the road: its ground plane and its
vehicles on the site's lanes) and :mod:`wz_camera_detector.calibration` (the camera and the
radar against the LiDAR's vehicles: rotation and clock). Nothing here does I/O.

Down-weighting
--------------
While an angle is uncertain, so is every position measured through it: a yaw known to
``sigma`` radians moves a vehicle ``r sigma`` across the sensor's line of sight at range
``r``. :func:`angular_covariance` is that term; the detectors add it to each detection's
covariance, so a sensor that is learning or was just bumped weighs less in the fused track
until its angles are known again, and nothing else in the tracker changes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from wz_shared.arrays import F64
from wz_shared.messages import (
    MAX_CLOCK_OFFSET_S,
    MAX_POSITION_CORRECTION_M,
    MAX_TILT_CORRECTION_DEG,
    MAX_YAW_CORRECTION_DEG,
    CalibrationState,
    PoseCorrection,
    SensorCalibration,
)
from wz_shared.site import Pose


def _clip(value: float, bound: float) -> float:
    return float(min(bound, max(-bound, value)))


def bounded(correction: PoseCorrection) -> PoseCorrection:
    """``correction`` with each part clipped to its bound (``MAX_*_CORRECTION``)."""
    return correction.model_copy(
        update={
            "yaw_deg": _clip(correction.yaw_deg, MAX_YAW_CORRECTION_DEG),
            "pitch_deg": _clip(correction.pitch_deg, MAX_TILT_CORRECTION_DEG),
            "roll_deg": _clip(correction.roll_deg, MAX_TILT_CORRECTION_DEG),
            "x_m": _clip(correction.x_m, MAX_POSITION_CORRECTION_M),
            "y_m": _clip(correction.y_m, MAX_POSITION_CORRECTION_M),
            "z_m": _clip(correction.z_m, MAX_POSITION_CORRECTION_M),
        }
    )


def bounded_correction(**parts: float | None) -> PoseCorrection:
    """A correction from an estimator's raw values, each angle and shift clipped to its bound
    (:func:`bounded`) before it is checked: a fit past a bound (a ground fit 1.0009 m off on a
    generated site) is held at the bound rather than stopping the detector with a validation
    error."""
    clipped = bounded(PoseCorrection.model_construct(None, **parts))  # type: ignore[arg-type]
    return PoseCorrection.model_validate(clipped.model_dump())


def offset_pose(
    pose: Pose,
    *,
    yaw_deg: float = 0.0,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    x_m: float = 0.0,
    y_m: float = 0.0,
    z_m: float = 0.0,
) -> Pose:
    """``pose`` with each angle and coordinate moved by the given amount (unbounded: an
    estimator's trial step, a simulated set-up error)."""
    return Pose(
        x_m=pose.x_m + x_m,
        y_m=pose.y_m + y_m,
        z_m=pose.z_m + z_m,
        yaw_deg=pose.yaw_deg + yaw_deg,
        pitch_deg=pose.pitch_deg + pitch_deg,
        roll_deg=pose.roll_deg + roll_deg,
    )


def corrected_pose(nominal: Pose, correction: PoseCorrection) -> Pose:
    """The pose the sensor is learned to have: the site file's plus the correction."""
    c = correction
    return offset_pose(
        nominal,
        yaw_deg=c.yaw_deg,
        pitch_deg=c.pitch_deg,
        roll_deg=c.roll_deg,
        x_m=c.x_m,
        y_m=c.y_m,
        z_m=c.z_m,
    )


def angular_covariance(
    sensor_xy_m: tuple[float, float], points_xy_m: F64, angle_std_rad: float
) -> F64:
    """Covariance [m^2] an angle known to ``angle_std_rad`` adds to positions seen from a
    sensor, shape (N, 2, 2): ``(r sigma)^2`` across each point's line of sight."""
    points = np.atleast_2d(np.asarray(points_xy_m, dtype=np.float64))
    rel = points - np.asarray(sensor_xy_m, dtype=np.float64)
    across = np.stack([-rel[:, 1], rel[:, 0]], axis=1)  # length r, perpendicular
    return np.asarray(angle_std_rad**2 * across[:, :, None] * across[:, None, :], dtype=np.float64)


@dataclass
class CalibrationLog:
    """One sensor's calibration state and the message that tells it.

    The estimator calls :meth:`enter` on a change of state and :meth:`message` whenever the
    node is to publish; :attr:`changed` says whether the state moved since the last message.
    """

    site_id: str
    sensor_id: str
    sensor_kind: Literal["lidar", "camera", "radar"]
    state: CalibrationState = CalibrationState.PRIOR
    state_since_s: float = 0.0
    detail: str = ""
    changed: bool = True
    #: Every change of state: (stamp, state, detail), oldest first (the last 50).
    history: list[tuple[float, CalibrationState, str]] = field(default_factory=list)

    def enter(self, state: CalibrationState, stamp_s: float, detail: str) -> None:
        """Move to ``state`` at ``stamp_s`` (nothing when already there)."""
        if state == self.state:
            return
        self.state = state
        self.state_since_s = max(0.0, stamp_s)
        self.detail = detail
        self.changed = True
        self.history = [*self.history[-49:], (stamp_s, state, detail)]

    def message(
        self,
        stamp_s: float,
        correction: PoseCorrection,
        clock_offset_s: float = 0.0,
        clock_offset_std_s: float | None = None,
        samples: int = 0,
    ) -> SensorCalibration:
        """The message to publish now (clears :attr:`changed`)."""
        self.changed = False
        clock = _clip(clock_offset_s, MAX_CLOCK_OFFSET_S)
        return SensorCalibration(
            site=self.site_id,
            source_id=self.sensor_id,
            stamp=max(0.0, stamp_s),
            sensor_kind=self.sensor_kind,
            state=self.state,
            state_since_s=self.state_since_s,
            correction=bounded(correction),
            clock_offset_s=clock,
            clock_offset_std_s=clock_offset_std_s,
            samples=max(0, int(samples)),
            detail=self.detail[:500],
        )


def robust_std(values: F64) -> float:
    """Standard deviation from the median absolute deviation (1.4826 MAD); 0 for < 2 values."""
    values = np.asarray(values, dtype=np.float64)
    if values.size < 2:
        return 0.0
    return float(1.4826 * np.median(np.abs(values - np.median(values))))
