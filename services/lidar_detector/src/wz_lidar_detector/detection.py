"""Inputs and outputs of both detection paths (pure data, sensor frame).

Both paths take a :class:`PointFrame` (points in the sensor frame: x forward, y left, z up) and
return a :class:`DetectionResult`: oriented 3D boxes in the sensor frame, the foreground mask,
and the time each named step took. The node moves boxes to the site frame with the mount pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from wz_shared.arrays import Bool
from wz_shared.messages import VehicleClass

# One LiDAR frame: defined with the file readers, in the shared library.
from wz_shared.pointcloud_files import PointFrame as PointFrame


@dataclass(frozen=True)
class BoxDetection:
    """One detected vehicle: an oriented box in the sensor frame.

    Attributes
    ----------
    center_xyz_m
        Box centre [m].
    size_lwh_m
        Length (along ``heading_rad``), width, height [m].
    heading_rad
        Heading of the length axis, counter-clockwise from the sensor's x axis [rad]; a box is
        symmetric, so heading is defined modulo pi unless the path knows the direction.
    object_class
        Class from the box's dimensions.
    num_points
        Points of the cluster.
    covariance_xy_m2
        2x2 covariance of the centre's x, y [m^2] in the sensor frame.
    score
        Confidence 0..1.
    completed_from_far_end
        The length was completed from the end away from the sensor, towards it: the near end
        is cut by the field of view (:func:`wz_lidar_detector.boxfit.fit_box`).
    """

    center_xyz_m: tuple[float, float, float]
    size_lwh_m: tuple[float, float, float]
    heading_rad: float
    object_class: VehicleClass
    num_points: int
    covariance_xy_m2: tuple[tuple[float, float], tuple[float, float]]
    score: float = 1.0
    completed_from_far_end: bool = False


@dataclass
class DetectionResult:
    """Output of one path on one frame."""

    detections: list[BoxDetection]
    #: Foreground (object) points that went into clustering, as a mask over the input points.
    foreground: Bool
    #: Wall time of each named step [s], in order.
    timings_s: dict[str, float] = field(default_factory=dict)
