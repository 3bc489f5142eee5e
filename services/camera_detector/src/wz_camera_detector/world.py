"""From an image box to a vehicle's position on the road (flat road ``z = 0``), pure numpy.

The bottom-centre of a detection box ``(x1, y1, x2, y2)`` [px, edges, as in
:mod:`wz_shared.camera_geometry`] is ``((x1 + x2) / 2, y2)``. It is where the vehicle touches
the road nearest the camera, not under its centre, so back-projecting it alone
(:func:`paper_box_to_ground`, as the paper's Eq. 1-2 did) puts an approaching car about half its
length too close to the camera. :func:`box_to_ground` back-projects the same pixel with the full
pinhole model (lens distortion included) and then moves the point to the vehicle's centre.

Geometry of the correction
--------------------------
For a camera without roll every ground point at the same distance along the camera's
horizontal forward axis ``f`` (the optical axis projected on the road, a unit vector) projects
to the same image row. The box's bottom row is therefore the footprint corner nearest along
``f``, which is closer than the centre by the footprint's half-extent along ``f``::

    e_h = (cos psi, sin psi), e_w = (-sin psi, cos psi)     heading psi, unit axes of the car
    h_f = (L / 2) |f . e_h| + (W / 2) |f . e_w|            [m], the near face's setback

and the box's centre column is close to the vehicle's bearing. So the centre lies on the line of
sight ``s`` (the unit horizontal direction from the camera to the contact point ``p``), ``h_f``
further along ``f``::

    centre = p + h_f / (s . f) s

Seen from behind or from the front (heading along ``f``), ``h_f = L / 2``: the contact is on
the near face and the centre is half a length further along the heading, away from the camera.
Seen side-on, ``h_f = W / 2``. Obliquely the two half-dimensions add in proportion to how much
of each face the camera sees.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from wz_shared.camera_geometry import (
    PinholeCamera,
    backproject_to_ground,
    paper_flat_road_ground_point,
)
from wz_shared.site import SensorMount

F64 = npt.NDArray[np.float64]


def box_bottom_centre_px(box_xyxy_px: npt.ArrayLike) -> F64:
    """Bottom-centre ``((x1 + x2) / 2, y2)`` [px] of a box ``(x1, y1, x2, y2)``, shape (2,)."""
    x1, _, x2, y2 = (float(value) for value in np.asarray(box_xyxy_px, dtype=np.float64))
    return np.array([0.5 * (x1 + x2), y2])


def box_to_ground(
    camera: PinholeCamera,
    box_xyxy_px: npt.ArrayLike,
    heading_rad: float,
    length_m: float,
    width_m: float,
) -> tuple[float, float]:
    """Vehicle centre on the road from its image box, heading and size (full pinhole model).

    Back-projects the box's bottom-centre to the road ``z = 0`` and moves it along the line of
    sight by the near face's setback (see the module docstring)::

        centre = p + h_f / (s . f) s,    h_f = (L / 2) |f . e_h| + (W / 2) |f . e_w|

    Parameters
    ----------
    camera
        The camera that took the image (with its lens distortion, if any).
    box_xyxy_px
        Box ``(x1, y1, x2, y2)`` [px, continuous, pixel edges], shape (4,).
    heading_rad
        The vehicle's heading in the site frame [rad], counter-clockwise from east; the
        correction depends on it only modulo pi (front and back faces are alike).
    length_m, width_m
        The vehicle's length and width [m] (e.g. a class's typical size).

    Returns
    -------
    x_m, y_m
        Estimated centre in the site frame [m]; NaN, NaN if the bottom-centre is at or above the
        horizon.

    Raises
    ------
    ValueError
        If a dimension is negative, or the camera looks straight down (no forward axis).
    """
    if length_m < 0.0 or width_m < 0.0:
        raise ValueError(f"vehicle length {length_m} m and width {width_m} m must not be negative")
    contact = backproject_to_ground(camera, box_bottom_centre_px(box_xyxy_px)[None, :])[0, :2]
    if not np.all(np.isfinite(contact)):
        return math.nan, math.nan
    optical_axis = camera.rotation_site_from_camera[:, 2]
    horizontal_norm = math.hypot(optical_axis[0], optical_axis[1])
    if horizontal_norm < 1e-9:
        raise ValueError(
            f"camera {camera.mount.sensor_id!r} looks straight down: no forward axis to place a "
            "vehicle's near face along"
        )
    forward = optical_axis[:2] / horizontal_norm
    sight = contact - camera.position_m[:2]
    sight /= np.linalg.norm(sight)
    heading_axis = np.array([math.cos(heading_rad), math.sin(heading_rad)])
    width_axis = np.array([-heading_axis[1], heading_axis[0]])
    # Half-extent of the footprint along the forward axis: the near face's setback from the centre.
    setback_m = 0.5 * length_m * abs(float(forward @ heading_axis)) + 0.5 * width_m * abs(
        float(forward @ width_axis)
    )
    # The contact point is in front of the camera, so s . f > 0 (bounded below by the field of view).
    centre = contact + setback_m / float(sight @ forward) * sight
    return float(centre[0]), float(centre[1])


def paper_box_to_ground(mount: SensorMount, box_xyxy_px: npt.ArrayLike) -> tuple[float, float]:
    """The paper's ranging: the box's bottom-centre through Eq. 1-2, used as the position.

    No correction to the vehicle's centre and no lens model, as published; kept as the
    reference :func:`box_to_ground` improves on.

    Parameters
    ----------
    mount
        The camera's mount (pose and intrinsics).
    box_xyxy_px
        Box ``(x1, y1, x2, y2)`` [px, continuous, pixel edges], shape (4,).

    Returns
    -------
    x_m, y_m
        Ground point under the bottom-centre in the site frame [m]; NaN, NaN at or above the
        horizon.
    """
    point = paper_flat_road_ground_point(mount, box_bottom_centre_px(box_xyxy_px)[None, :])[0]
    return float(point[0]), float(point[1])
