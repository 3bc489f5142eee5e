"""What ``wz calibrate`` keeps of a run: each sensor's result, and the boxes and frames its
pictures are drawn from (:mod:`wz_cli.calibrate`, :mod:`wz_cli.calibrate_pictures`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from wz_shared.arrays import F64
from wz_shared.messages import CalibrationState, DetectionBatch, SensorCalibration
from wz_shared.self_calibration import corrected_pose
from wz_shared.site import Pose

#: A box centre's height above the road when its detection has none [m] (the detections are
#: on the road plane; the pictures move their centres from one pose to another).
DEFAULT_CENTRE_HEIGHT_M = 0.8


@dataclass(frozen=True)
class SensorResult:
    """One sensor's calibration as the run ended."""

    sensor_id: str
    kind: str
    nominal: Pose
    message: SensorCalibration | None
    #: Changes of state: (stamp, state, detail).
    history: list[tuple[float, str, str]] = field(default_factory=list)

    @property
    def state(self) -> str:
        return "no data" if self.message is None else str(self.message.state)

    @property
    def calibrated(self) -> bool:
        return self.message is not None and self.message.state == CalibrationState.CALIBRATED

    @property
    def learned(self) -> Pose:
        if self.message is None:
            return self.nominal
        return corrected_pose(self.nominal, self.message.correction)


@dataclass(frozen=True)
class LidarView:
    """One LiDAR batch's boxes in the sensor's own frame (so that they can be placed with any
    pose): centres (K, 3) [m], headings (K,) [rad] about the sensor's z, sizes (K, 3) l, w, h."""

    stamp_s: float
    centres: F64
    headings: F64
    sizes: F64

    def centres_site(self, pose: Pose) -> F64:
        return np.asarray(self.centres @ pose.rotation().T + pose.position_m, dtype=np.float64)


@dataclass(frozen=True)
class CameraShot:
    """A camera frame kept for the pictures."""

    sensor_id: str
    stamp_s: float
    jpeg: bytes


def lidar_view(batch: DetectionBatch, pose: Pose) -> LidarView:
    """``batch``'s boxes, placed with ``pose``, back in the sensor frame."""
    rows = []
    for d in batch.detections:
        height = d.height_m if d.height_m else 2.0 * DEFAULT_CENTRE_HEIGHT_M
        rows.append(
            (
                d.x_m,
                d.y_m,
                0.5 * height,
                d.heading_rad if d.heading_rad is not None else math.nan,
                d.length_m or 4.5,
                d.width_m or 1.8,
                height,
            )
        )
    table = np.array(rows, dtype=np.float64).reshape(-1, 7)
    centres = (table[:, :3] - pose.position_m) @ pose.rotation()
    headings = table[:, 3] - math.radians(pose.yaw_deg)
    return LidarView(batch.stamp, centres, headings, table[:, 4:7])
