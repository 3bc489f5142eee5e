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

Fitting the whole box
---------------------
The middle column is the vehicle's bearing only for a short, low vehicle far away. A box's left
and right edges are the outermost of the vehicle's corners, its top ones included: a
semitrailer 16.5 m long and 4 m tall, 30 m from a mast beside the road, reaches across the
image from its near front corner to its far rear top corner, and the middle of that span is
about a metre across the road from its centre. On the simulator's label boxes the contact-point
estimate is off across the road by +1.2 m for trucks at 20-40 m and +0.4 m at 40-60 m, +0.23 m
and +0.09 m for cars.

:func:`fit_box_to_ground` therefore starts from the contact-point estimate and moves the
centre on the road until the image box of the vehicle's outline (:class:`VehicleShape`: the
class's body box on wheels, on the road's heading) has the detected box's left, right and
bottom edges: Gauss-Newton on those three residuals [px] in the two unknowns (x, y), as
monocular 3D detectors fit a box of known size to a 2D box (Mousavian et al., "3D Bounding Box
Estimation Using Deep Learning and Geometry", CVPR 2017). The top edge is left out: heights
within a class vary more than lengths matter to it.

A box drawn around a vehicle's pixels (a label, and so what a detector trained on labels draws)
has its edges on the outer edges of the outermost pixels, while the vehicle's own outline
crosses those pixels somewhere inside: on average half a pixel in (measured on the simulator's
labels: 0.4-0.5 px on each side beyond 40 m). The fit matches the outline to the box brought in
by that half pixel (:data:`PIXEL_EDGE_INSET_PX`); without it the bottom edge alone puts a car
at 100 m about 2 m too near.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64
from wz_shared.camera_geometry import (
    PinholeCamera,
    backproject_to_ground,
    paper_flat_road_ground_point,
)
from wz_shared.site import SensorMount


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


#: Gauss-Newton steps of :func:`fit_box_to_ground`; it converges to 1 mm in 2-4.
FIT_MAX_ITERATIONS = 8
#: How far inside a box's edges [px] the vehicle's outline lies on average (half a pixel).
PIXEL_EDGE_INSET_PX = 0.5
#: Finite-difference step for the fit's Jacobian [m].
_FIT_STEP_M = 0.05
#: Below these (site-frame m), a fit step ends the iterations.
_FIT_TOLERANCE_M = 1e-3
#: A fit that moves the centre further than this from the contact-point estimate, or leaves a
#: residual above :data:`_FIT_MAX_RESIDUAL_PX`, is not trusted: the contact-point estimate is
#: kept (a box cut by another vehicle or the image is not a whole vehicle's box).
_FIT_MAX_MOVE_M = 5.0
_FIT_MAX_RESIDUAL_PX = 6.0


@dataclass(frozen=True)
class VehicleShape:
    """A vehicle's outline as a camera sees it: a body box on wheels [m].

    The body spans ``length_m x width_m`` from ``clearance_m`` above the road to ``height_m``;
    the wheels meet the road ``wheel_inset_m`` inside the body's ends. The box's bottom edge is
    the lowest of these: from a mast, a car's bumper (0.28 m up) projects further up the image
    than the front wheels' foot half a metre behind it, so treating the body as reaching the road
    places a car about half a metre too far from the camera.
    """

    length_m: float
    width_m: float
    height_m: float
    clearance_m: float = 0.0
    wheel_inset_m: float = 0.0

    def __post_init__(self) -> None:
        if (
            min(self.length_m, self.width_m, self.height_m, self.clearance_m, self.wheel_inset_m)
            < 0.0
        ):
            raise ValueError(f"vehicle shape {self} must not have negative dimensions")
        if self.clearance_m >= self.height_m or 2.0 * self.wheel_inset_m >= self.length_m:
            raise ValueError(f"vehicle shape {self}: the body and wheels do not fit")

    def outline_points(self) -> F64:
        """The outline's corners in the vehicle frame (along, across, up), shape (12, 3): the
        body's eight and the four points where the outer wheels meet the road."""
        half_l, half_w = 0.5 * self.length_m, 0.5 * self.width_m
        body = [
            (a * half_l, b * half_w, z)
            for a in (-1.0, 1.0)
            for b in (-1.0, 1.0)
            for z in (self.clearance_m, self.height_m)
        ]
        wheels = [
            (a * (half_l - self.wheel_inset_m), b * half_w, 0.0)
            for a in (-1.0, 1.0)
            for b in (-1.0, 1.0)
        ]
        return np.array(body + wheels, dtype=np.float64)


def vehicle_image_boxes(
    camera: PinholeCamera,
    centres_xy_m: npt.ArrayLike,
    heading_rad: float,
    shape: VehicleShape,
) -> F64:
    """Image boxes ``(x1, y1, x2, y2)`` [px] of vehicles standing on the road, shape (K, 4).

    Each vehicle has its centre on the road at one of ``centres_xy_m`` (shape (K, 2)), the
    given heading and shape; its box spans its projected outline points (not clipped to the
    image; NaN where a point is behind the camera).
    """
    centres = np.atleast_2d(np.asarray(centres_xy_m, dtype=np.float64))
    local = shape.outline_points()
    cos_h, sin_h = math.cos(heading_rad), math.sin(heading_rad)
    offsets = np.stack(
        [
            local[:, 0] * cos_h - local[:, 1] * sin_h,
            local[:, 0] * sin_h + local[:, 1] * cos_h,
            local[:, 2],
        ],
        axis=1,
    )
    ground = np.concatenate([centres, np.zeros((centres.shape[0], 1))], axis=1)[:, None, :]
    uv, _ = camera.project((ground + offsets[None, :, :]).reshape(-1, 3))
    uv = uv.reshape(centres.shape[0], local.shape[0], 2)
    return np.stack(
        [
            uv[:, :, 0].min(axis=1),
            uv[:, :, 1].min(axis=1),
            uv[:, :, 0].max(axis=1),
            uv[:, :, 1].max(axis=1),
        ],
        axis=1,
    )


def fit_box_to_ground(
    camera: PinholeCamera,
    box_xyxy_px: npt.ArrayLike,
    heading_rad: float,
    shape: VehicleShape,
) -> tuple[float, float]:
    """Vehicle centre on the road whose outline's image box has the detected box's left, right
    and bottom edges (module docstring, "Fitting the whole box").

    Starts from :func:`box_to_ground` (the contact point moved by the near face's setback) and
    takes Gauss-Newton steps on the three edge residuals [px]. Falls back to that start when the
    fit does not converge to a box within a few pixels of the detected one, or wanders metres
    away from it (a box cut by an occluder or the image edge is not a whole vehicle's).

    Parameters
    ----------
    camera
        The camera that took the image.
    box_xyxy_px
        Detected box ``(x1, y1, x2, y2)`` [px, continuous, pixel edges], shape (4,).
    heading_rad
        The vehicle's heading in the site frame [rad].
    shape
        The vehicle's shape (a class's typical one).

    Returns
    -------
    x_m, y_m
        Estimated centre in the site frame [m]; NaN, NaN if the box's bottom is at or above the
        horizon.
    """
    box = np.asarray(box_xyxy_px, dtype=np.float64).reshape(1, 4)
    x_m, y_m = fit_boxes_to_ground(camera, box, [heading_rad], [shape])[0]
    return float(x_m), float(y_m)


def fit_boxes_to_ground(
    camera: PinholeCamera,
    boxes_xyxy_px: npt.ArrayLike,
    headings_rad: npt.ArrayLike,
    shapes: list[VehicleShape],
) -> F64:
    """:func:`fit_box_to_ground` for a frame's boxes at once (the Gauss-Newton steps of all
    of them in one projection each), shape (K, 2) [m]; rows of NaN for boxes at or above the
    horizon.

    Parameters
    ----------
    camera
        The camera that took the image.
    boxes_xyxy_px
        Boxes ``(x1, y1, x2, y2)`` [px], shape (K, 4).
    headings_rad
        Each vehicle's heading in the site frame [rad], shape (K,).
    shapes
        Each vehicle's shape, K of them.
    """
    boxes = np.asarray(boxes_xyxy_px, dtype=np.float64).reshape(-1, 4)
    headings = np.asarray(headings_rad, dtype=np.float64).reshape(-1)
    if not (len(boxes) == len(headings) == len(shapes)):
        raise ValueError(f"{len(boxes)} boxes, {len(headings)} headings, {len(shapes)} shapes")
    starts = np.array(
        [
            box_to_ground(camera, box, heading, shape.length_m, shape.width_m)
            for box, heading, shape in zip(boxes, headings, shapes, strict=True)
        ],
        dtype=np.float64,
    ).reshape(-1, 2)
    fitted = starts.copy()
    todo = np.flatnonzero(np.all(np.isfinite(starts), axis=1))
    if len(todo) == 0:
        return fitted
    # Each vehicle's outline on its heading, centred on the origin: (K, 12, 3) [m].
    local = np.stack([shapes[i].outline_points() for i in todo])
    cos_h, sin_h = np.cos(headings[todo])[:, None], np.sin(headings[todo])[:, None]
    offsets = np.stack(
        [
            local[..., 0] * cos_h - local[..., 1] * sin_h,
            local[..., 0] * sin_h + local[..., 1] * cos_h,
            local[..., 2],
        ],
        axis=2,
    )
    edges = [0, 2, 3]  # left, right, bottom
    inset = np.array([PIXEL_EDGE_INSET_PX, -PIXEL_EDGE_INSET_PX, -PIXEL_EDGE_INSET_PX])
    target = boxes[todo][:, edges] + inset
    start = starts[todo]
    centre = start.copy()
    residual = np.full((len(todo), 3), np.inf)
    failed = np.zeros(len(todo), dtype=bool)
    active = np.ones(len(todo), dtype=bool)
    probe_steps = np.array([[0.0, 0.0], [_FIT_STEP_M, 0.0], [0.0, _FIT_STEP_M]])
    for _ in range(FIT_MAX_ITERATIONS):
        now = np.flatnonzero(active)
        if len(now) == 0:
            break
        probes = centre[now][:, None, :] + probe_steps[None, :, :]  # (k, 3, 2)
        image = _outline_boxes(camera, probes, offsets[now])[..., edges]  # (k, 3, 3)
        lost = ~np.all(np.isfinite(image), axis=(1, 2))
        failed[now[lost]] = True
        active[now[lost]] = False
        now, image = now[~lost], image[~lost]
        residual[now] = image[:, 0] - target[now]
        jacobian = np.transpose(image[:, 1:] - image[:, :1], (0, 2, 1)) / _FIT_STEP_M  # (k,3,2)
        step = -(np.linalg.pinv(jacobian) @ residual[now][:, :, None])[:, :, 0]
        centre[now] += step
        done = np.hypot(step[:, 0], step[:, 1]) < _FIT_TOLERANCE_M
        if done.any():
            final = now[done]
            image = _outline_boxes(camera, centre[final][:, None, :], offsets[final])
            residual[final] = image[:, 0][:, edges] - target[final]
            active[final] = False
    trusted = (
        ~failed
        & np.all(np.isfinite(residual), axis=1)
        & (np.abs(residual).max(axis=1) <= _FIT_MAX_RESIDUAL_PX)
        & (np.hypot(*(centre - start).T) <= _FIT_MAX_MOVE_M)
    )
    fitted[todo] = np.where(trusted[:, None], centre, start)
    return fitted


def _outline_boxes(camera: PinholeCamera, centres_m: F64, offsets_m: F64) -> F64:
    """Image boxes [px] of vehicles (outline ``offsets_m``, shape (K, 12, 3)) standing with
    their centres at ``centres_m`` (shape (K, P, 2): P places each), shape (K, P, 4)."""
    count, places = centres_m.shape[:2]
    ground = np.concatenate([centres_m, np.zeros((count, places, 1))], axis=2)
    points = ground[:, :, None, :] + offsets_m[:, None, :, :]  # (K, P, 12, 3)
    uv, _ = camera.project(points.reshape(-1, 3))
    uv = uv.reshape(count, places, -1, 2)
    return np.concatenate([uv.min(axis=2), uv.max(axis=2)], axis=2)


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
