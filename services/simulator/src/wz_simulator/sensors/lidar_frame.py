"""What a simulated LiDAR sweep hands on: the organized points, their labels, the vehicles'
truth boxes and the frame's metadata message.
"""

from __future__ import annotations

from dataclasses import dataclass

from wz_shared.arrays import F32, I32
from wz_shared.messages import LidarFrameMeta


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

    points: F32
    labels: I32
    vehicle_ids: tuple[str, ...]
    boxes: tuple[LidarTruthBox, ...]
    meta: LidarFrameMeta

    @property
    def range_image(self) -> F32:
        """The points as a ``(rows, columns, 4)`` view."""
        image: F32 = self.points.reshape(self.meta.rows, self.meta.columns, 4)
        return image
