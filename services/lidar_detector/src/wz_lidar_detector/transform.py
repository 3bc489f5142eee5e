"""Sensor frame to site frame: boxes with the mount pose, and boxes to :class:`Detection`.

With ``R`` the mount's rotation (:meth:`wz_shared.site.Pose.rotation`) and ``t`` its position,

    p_site = R p_sensor + t

The heading is the direction of the box's length axis: its unit vector
``h = (cos heading, sin heading, 0)`` rotates to ``R h`` and the site heading is
``atan2((R h)_y, (R h)_x)``; for a level mount (no pitch, no roll) that is ``heading + yaw``.
The centre's 2x2 covariance rotates with the top-left 2x2 block ``R2`` of ``R``:

    C_site = R2 C R2^T

(the x, y block of ``R [[C, 0], [0, 0]] R^T``: the sensor gives no z uncertainty here).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from wz_lidar_detector.detection import BoxDetection
from wz_shared.messages import Detection
from wz_shared.site import Pose


def wrap_angle(angle_rad: float) -> float:
    """An angle in (-pi, pi] [rad]."""
    wrapped = math.remainder(angle_rad, math.tau)
    return math.pi if wrapped == -math.pi else wrapped


def box_to_site(box: BoxDetection, pose: Pose) -> BoxDetection:
    """The same box in the site frame (centre, heading and covariance moved; sizes kept)."""
    rotation = pose.rotation()
    center = rotation @ np.asarray(box.center_xyz_m, dtype=np.float64) + pose.position_m
    # R h for the heading's unit vector h in the sensor's x-y plane.
    heading_vector = rotation @ np.array([math.cos(box.heading_rad), math.sin(box.heading_rad), 0])
    heading = math.atan2(heading_vector[1], heading_vector[0])
    # C_site = R2 C R2^T; averaged with its transpose so rounding keeps it symmetric.
    r2 = rotation[:2, :2]
    covariance = r2 @ np.asarray(box.covariance_xy_m2, dtype=np.float64) @ r2.T
    covariance = 0.5 * (covariance + covariance.T)
    return replace(
        box,
        center_xyz_m=(float(center[0]), float(center[1]), float(center[2])),
        heading_rad=wrap_angle(heading),
        covariance_xy_m2=(
            (float(covariance[0, 0]), float(covariance[0, 1])),
            (float(covariance[1, 0]), float(covariance[1, 1])),
        ),
    )


def to_detection(box: BoxDetection) -> Detection:
    """A box (already in the site frame) as a :class:`Detection` message.

    Raises
    ------
    pydantic.ValidationError
        For a box with non-finite values (the node counts and drops it).
    """
    (sxx, sxy), (syx, syy) = box.covariance_xy_m2
    length, width, height = box.size_lwh_m
    return Detection(
        x_m=box.center_xyz_m[0],
        y_m=box.center_xyz_m[1],
        covariance_m2=[sxx, sxy, syx, syy],
        object_class=box.object_class,
        score=min(1.0, max(0.0, box.score)),
        length_m=length,
        width_m=width,
        height_m=height,
        heading_rad=wrap_angle(box.heading_rad),
        completed_from_far_end=box.completed_from_far_end,
    )


def detections_in_site(boxes: Sequence[BoxDetection], pose: Pose) -> list[Detection]:
    """Sensor-frame boxes as site-frame :class:`Detection` messages, in the same order."""
    return [to_detection(box_to_site(box, pose)) for box in boxes]
