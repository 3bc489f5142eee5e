"""Whether other vehicles hide a spot from a sensor: the sight line and the boxes in its way.

A sensor at ``s`` (site frame, ``z`` its height above the road) sees a point ``t`` unless the
straight segment from ``s`` to ``t`` passes through a vehicle: an upright box of the vehicle's
footprint (centre, heading, length, width) from the road up to its height. In a box's own frame
the segment's ground track enters the footprint at ``u_in`` and leaves it at ``u_out``
(``0 <= u <= 1`` along the segment; the slab method on the two axes); the sight line is blocked
when it is lower than the box's top anywhere in between, that is at the lower of its two
heights there (it is straight):

.. math::

    \\min\\big(z(u_{in}), z(u_{out})\\big) < H, \\qquad z(u) = z_s + u\\,(z_t - z_s)

A box whose footprint holds the target itself is the vehicle seen there, not one in the way,
and never hides it. Vehicle heights by class are those of the AASHTO design vehicles
(:data:`CLASS_HEIGHT_M`); a tracker reports footprints, not heights. Pure numpy: the
tracker's core uses it.

:class:`wz_shared.coverage.SiteSight` asks it of a site's sensors together: a point is hidden when every sensor
that covers it has a vehicle in its sight line. The gateway uses it for the lanes at its
traffic detector (:mod:`wz_gateway.lane_sight`); the tracker, for a track that stopped being
updated behind a truck (it keeps coasting: ``max_occlusion_coast_s``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64, Bool

#: Heights by vehicle class [m]: AASHTO's design vehicles (Green Book, Table 2-1a): a passenger
#: car 1.3 m, taken at 1.5 m for today's share of SUVs and pickups; single-unit and
#: semitrailer trucks 4.1 m (13.5 ft); a city bus 3.2 m; a motorcycle 1.4 m with its rider.
CLASS_HEIGHT_M: dict[str, float] = {
    "car": 1.5,
    "truck": 4.1,
    "bus": 3.2,
    "motorcycle": 1.4,
    "unknown": 1.5,
}
#: Footprint assumed where a tracker gave none [m]: a passenger car's.
DEFAULT_LENGTH_M = 4.5
DEFAULT_WIDTH_M = 1.8
#: Footprints are this much larger each side when deciding whether a box holds the target:
#: a track's centre is off by a few decimetres [m].
_HOLDS_MARGIN_M = 0.3


@dataclass(frozen=True)
class Boxes:
    """Upright vehicle boxes, arrays of one length N (site frame, metres, radians)."""

    x_m: F64
    y_m: F64
    heading_rad: F64
    length_m: F64
    width_m: F64
    height_m: F64

    @classmethod
    def of(
        cls,
        x_m: npt.ArrayLike,
        y_m: npt.ArrayLike,
        heading_rad: npt.ArrayLike,
        length_m: npt.ArrayLike,
        width_m: npt.ArrayLike,
        object_class: Iterable[str],
    ) -> Boxes:
        """Boxes of tracked vehicles: NaN lengths and widths take a car's, heights their
        class's (:data:`CLASS_HEIGHT_M`; an unknown class a car's)."""
        length = np.asarray(length_m, dtype=np.float64)
        width = np.asarray(width_m, dtype=np.float64)
        height = np.array(
            [CLASS_HEIGHT_M.get(str(c), CLASS_HEIGHT_M["unknown"]) for c in object_class],
            dtype=np.float64,
        )
        return cls(
            x_m=np.asarray(x_m, dtype=np.float64),
            y_m=np.asarray(y_m, dtype=np.float64),
            heading_rad=np.asarray(heading_rad, dtype=np.float64),
            length_m=np.where(np.isnan(length), DEFAULT_LENGTH_M, length),
            width_m=np.where(np.isnan(width), DEFAULT_WIDTH_M, width),
            height_m=height.reshape(length.shape),
        )

    def __len__(self) -> int:
        return int(self.x_m.size)


def hidden(sensor_m: npt.ArrayLike, targets_m: npt.ArrayLike, boxes: Boxes) -> Bool:
    """Whether a box hides each target from the sensor (module docstring).

    Parameters
    ----------
    sensor_m : array_like, shape (3,)
        The sensor's position (site frame; ``z`` above the road) [m].
    targets_m : array_like, shape (M, 3)
        The points to be seen [m].
    boxes : Boxes
        The vehicles that may be in the way (N of them).

    Returns
    -------
    ndarray of bool, shape (M,)
    """
    sensor = np.asarray(sensor_m, dtype=np.float64).reshape(3)
    targets = np.asarray(targets_m, dtype=np.float64).reshape(-1, 3)
    if len(boxes) == 0 or targets.shape[0] == 0:
        return np.zeros(targets.shape[0], dtype=bool)
    cos, sin = np.cos(boxes.heading_rad), np.sin(boxes.heading_rad)
    half = np.stack([boxes.length_m, boxes.width_m], axis=-1) / 2.0  # (N, 2)

    def box_frame(x: F64, y: F64) -> F64:
        """Points (…, ) against every box: (…, N, 2) in the boxes' own axes."""
        dx = x[..., None] - boxes.x_m
        dy = y[..., None] - boxes.y_m
        return np.stack([cos * dx + sin * dy, -sin * dx + cos * dy], axis=-1)

    start = box_frame(np.array(sensor[0]), np.array(sensor[1]))[None]  # (1, N, 2)
    end = box_frame(targets[:, 0], targets[:, 1])  # (M, N, 2)
    step = end - start
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (-half - start) / step
        b = (half - start) / step
    flat = step == 0.0
    inside_slab = np.abs(start) <= half
    lo = np.where(flat, np.where(inside_slab, -np.inf, np.inf), np.minimum(a, b))
    hi = np.where(flat, np.where(inside_slab, np.inf, -np.inf), np.maximum(a, b))
    u_in = np.maximum(lo.max(axis=-1), 0.0)
    u_out = np.minimum(hi.min(axis=-1), 1.0)
    crosses = u_in <= u_out
    z0, z1 = sensor[2], targets[:, 2:3]
    lowest = np.minimum(z0 + u_in * (z1 - z0), z0 + u_out * (z1 - z0))
    holds_target = np.all(np.abs(end) <= half + _HOLDS_MARGIN_M, axis=-1)
    blocked = crosses & (lowest < boxes.height_m) & ~holds_target
    result: Bool = blocked.any(axis=-1)
    return result
