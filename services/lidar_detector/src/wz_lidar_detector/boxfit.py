"""A vehicle's box from the faces a roadside LiDAR sees of it (pure core, sensor frame).

A LiDAR sees the faces of a vehicle that turn towards it: one face (the front of a far vehicle
coming head-on, or the side of a vehicle abeam) or two (an L: side and front). The centroid of
those points lies on the visible faces, up to half a vehicle length (or width) nearer the sensor
than the vehicle's centre. This module fits the box instead:

1. **Heading**: search-based rectangle fitting with the *closeness* criterion of Zhang et al.
   (2017), "Efficient L-Shape Fitting for Vehicle Detection Using Laser Scanners" (IEEE IV). For
   each candidate orientation theta, project the points on ``e1 = (cos, sin)`` and
   ``e2 = (-sin, cos)``; a point's distance to the nearest rectangle edge along each axis is
   ``d_i = min(max(c_i) - c_i, c_i - min(c_i))``, and the score is

       score(theta) = sum_points 1 / max(min(d_1, d_2), d_0)

   (points that hug two perpendicular edges score high). The criterion is defined on a scan's
   visible outline, so the points are first reduced to the nearest one per bearing bin (a
   multi-beam sensor also returns roof, hood and windscreen points inside the outline). All
   candidates are scored at once as an ``(H, N)`` array: a coarse sweep of
   ``heading_step_deg`` over [0, 90) deg, or over ``prior +- tolerance`` when a heading prior is
   given (a roadside sensor knows that traffic moves along the road), then a fine sweep of
   ``refine_step_deg`` around the best. With a prior, a cluster shorter than
   ``min_side_for_heading_m`` along it shows only an end (curved bumper and hood, which do not
   tell the heading) and keeps the prior.
2. **Length axis**: with a prior, the axis nearest the prior. Without one, the longer visible
   extent when it is longer than ``end_face_max_m`` (a side is in view); otherwise the shape is
   ambiguous (an end face and the hood, or a short stretch of side) and the vehicle is taken to
   be seen end-on, as a sensor looking along the road sees far vehicles: the length axis is the
   one nearer the line of sight. Give the prior where the road's direction is known.
3. **Completion**: the visible extent underestimates the hidden sides. Along each axis the box is
   grown to at least the class's typical dimension (:data:`CLASS_SHAPES`), *away from the
   sensor*: the visible face is the one nearer the sensor, so the far edge moves. When the
   sensor's projection on the axis falls inside the visible span (a vehicle abeam), the box grows
   evenly at both ends. The near end is not always a face: where a nearer vehicle hides what
   lies just beyond it (a truck in the far lane behind a car in the near one,
   :func:`hidden_near_end`, the caller's test with the other clusters' points), the vehicle may
   go on either way and its length is grown evenly at both ends too (completed away from the
   sensor, a truck whose cab is hidden came out 14 m behind its centre, its box running ahead
   of it at 20 m/s as the truck came out). The class used for the completion comes from the visible extents (lower
   bounds): heavy when the visible length or the height passes the reference path's heavy
   thresholds, a motorcycle when an L no bigger than a motorcycle is seen along a known length
   axis (without it, such an L is more likely a car end-on), otherwise a car (4.5 x 1.8 m).
   A heavy vehicle's length
   ranges from 6 to 25 m, so it is taken from what is visible when its side is in view (seen
   at least ``side_view_min_deg`` off its length axis: a box's side face is in view whole or
   not at all), and completed to ``heavy_length_m`` (16 m, a tractor-semitrailer, the usual
   heavy vehicle on a freeway) only when it is seen end-on.
   The centre is the completed box's centre. Where the near end is cut by the field of view's
   lower edge instead (a vehicle going into or coming out of the blind cone under a high
   mast; the caller's test), the end *away* from the sensor is the face: the length is
   completed from it *towards* the sensor (``near_end_cut``), and ``completed_from_far_end``
   says so (a consumer that knows the vehicle's length moves the centre towards the sensor).
4. **Height**: from the top of the points down to the ground (the background's ground height
   under the vehicle when known, else the lowest point).
5. **Class**: :func:`wz_lidar_detector.reference.class_from_size` of the completed box, the same
   rule as the reference path.
6. **Covariance** of the centre's x, y [m^2], the sum of

   - the sensor's part, in the bearing frame of the centre: ``sigma_range = range_noise_m``
     along the ray and ``sigma_across = range * angular_resolution`` across it (edges are
     located to about one beam step);
   - the shape's part, in the box frame: along an axis completed from one end,
     ``(sigma_dim / 2)^2`` (the centre moves by half the error of the assumed dimension); grown at
     both ends, ``+ ((dim - visible) / 2)^2 / 3`` as well; seen whole, 0 (but the length of a
     heavy vehicle seen end-on is always uncertain: ``(heavy_length_std_m / 2)^2``); a car
     completed from its near face at a range where the beams cannot rule out a heavy
     vehicle's height (``height + range * beam_spacing >= 2.6 m``) gets
     ``((heavy_length - car_length) / 2)^2``: its centre may be a semitrailer's.

   So one face seen gives a covariance long along the unseen dimension; an L gives a small one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from wz_lidar_detector.reference import (
    HEAVY_MIN_HEIGHT_M,
    HEAVY_MIN_LENGTH_M,
    MOTORCYCLE_MAX_LENGTH_M,
    MOTORCYCLE_MAX_WIDTH_M,
    class_from_size,
)
from wz_shared.arrays import F64
from wz_shared.messages import VehicleClass


class BoxFitSettings(BaseModel):
    """Parameters of :func:`fit_box` (lengths in metres, angles in degrees)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: Step of the coarse heading sweep [deg].
    heading_step_deg: float = Field(default=1.0, gt=0.0, le=15.0)
    #: Step of the fine sweep around the coarse best [deg].
    refine_step_deg: float = Field(default=0.1, gt=0.0)
    #: Zhang's d_0: distances below it count as it, so one point on an edge cannot dominate [m].
    closeness_floor_m: float = Field(default=0.01, gt=0.0)
    #: The heading search runs on the visible outline: the nearest point per bearing bin of
    #: this width [deg] (roof, hood and windscreen returns lie inside the outline); 0: all.
    outline_bin_deg: float = Field(default=0.2, ge=0.0)
    #: Points of the outline used for the heading search (an even subsample); extents use all.
    max_fit_points: int = Field(default=200, ge=8)
    #: With a prior, a cluster shorter than this along the prior shows no side, only an end
    #: (bumper, hood: curved), which does not tell the heading: it keeps the prior [m].
    min_side_for_heading_m: float = Field(default=1.5, ge=0.0)
    #: A visible extent below this along an axis: that axis shows no face [m].
    thin_face_m: float = Field(default=0.5, ge=0.0)
    #: Without a prior, a single face no longer than this is a front or rear face [m].
    end_face_max_m: float = Field(default=2.6, gt=0.0)
    #: Range noise of one return, 1 sigma [m].
    range_noise_m: float = Field(default=0.05, gt=0.0)
    #: Angle between neighbouring beams or columns, the coarser of the two [deg].
    angular_resolution_deg: float = Field(default=0.2, gt=0.0)
    #: Vertical angle between neighbouring beams [deg] (64 beams over 41 deg: 0.65). A far
    #: vehicle's top can lie up to ``range * beam_spacing`` above its highest return: a
    #: tractor-semitrailer seen end-on at 120 m shows 2.2 m of its 4 m.
    beam_spacing_deg: float = Field(default=0.65, ge=0.0)
    #: Length a heavy vehicle is completed to when less of it is visible [m]. On a freeway most
    #: heavy vehicles are tractor-semitrailers (16-22 m; the simulator's are 16.5 m); lower it
    #: where box trucks and buses dominate. Its spread is ``heavy_length_std_m``.
    heavy_length_m: float = Field(default=16.0, gt=0.0)
    heavy_length_std_m: float = Field(default=4.0, ge=0.0)
    #: A heavy vehicle seen at least this far off its length axis shows its side whole: its
    #: visible length is its length, not completed [deg].
    side_view_min_deg: float = Field(default=20.0, ge=0.0, le=90.0)
    #: How far a vehicle's front may run on ahead of its roof line, below it [m]: a car's
    #: bonnet and windscreen (the roof's front edge is 1.5-2.2 m behind the bumper on a
    #: sedan), a tractor's cab and the gap before a trailer that stands above it. Where a box
    #: is completed from its far end and that end is its front seen only high up, the front
    #: lies up to this much further on, less where a beam above would have met it
    #: (:func:`hidden_front_m`); 0 turns it off.
    hidden_front_car_m: float = Field(default=2.0, ge=0.0)
    hidden_front_heavy_m: float = Field(default=3.5, ge=0.0)
    #: A front hidden below a vehicle's roof line (a bonnet, a cab below a trailer) stands no
    #: lower than this below the roof [m]: a sedan's bonnet top is 0.55-0.7 m below its roof.
    #: A beam that comes down this far below the roof beyond the far end would have met it.
    hidden_front_drop_m: float = Field(default=0.75, gt=0.0)


@dataclass(frozen=True)
class ClassShape:
    """Typical plan dimensions of a class [m] and their spread (1 sigma) [m]."""

    length_m: float
    width_m: float
    length_std_m: float
    width_std_m: float
    #: The length is open-ended (trucks from 6 to 25 m): always uncertain along the length.
    open_length: bool = False


#: Typical dimensions used to complete a box from its visible faces; a heavy vehicle's length
#: and its spread come from :class:`BoxFitSettings`.
CLASS_SHAPES: dict[VehicleClass, ClassShape] = {
    VehicleClass.CAR: ClassShape(4.5, 1.8, 0.4, 0.1),
    VehicleClass.MOTORCYCLE: ClassShape(2.2, 0.8, 0.2, 0.1),
    VehicleClass.TRUCK: ClassShape(16.0, 2.5, 4.0, 0.1, open_length=True),
}


@dataclass(frozen=True)
class BoxFit:
    """A completed box.

    Attributes
    ----------
    center_xyz_m
        Centre of the completed box [m].
    size_lwh_m
        Length (along ``heading_rad``), width, height [m].
    heading_rad
        Direction of the length axis [rad], counter-clockwise from x; within ``pi/2`` of the
        prior when one was given, else in (-pi/2, pi/2].
    object_class
        :func:`class_from_size` of the completed box.
    covariance_xy_m2
        ``(2, 2)`` covariance of the centre's x, y [m^2].
    visible_lw_m
        Visible extent of the points along the length and width axes [m].
    faces_seen
        1 (a single face, or a blob) or 2 (an L).
    completed_lw
        Whether the length / width was grown beyond the visible extent.
    completed_from_far_end
        The length was completed from the end away from the sensor, towards it (the near end
        cut by the field of view: ``fit_box(near_end_cut=True)``).
    """

    center_xyz_m: tuple[float, float, float]
    size_lwh_m: tuple[float, float, float]
    heading_rad: float
    object_class: VehicleClass
    covariance_xy_m2: F64
    visible_lw_m: tuple[float, float]
    faces_seen: int
    completed_lw: tuple[bool, bool]
    completed_from_far_end: bool = False


def closeness_scores(xy_m: F64, headings_rad: F64, floor_m: float) -> F64:
    """Zhang's closeness criterion of each candidate rectangle orientation.

    Parameters
    ----------
    xy_m
        ``(N, 2)`` points [m].
    headings_rad
        ``(H,)`` candidate orientations of the rectangle's first axis [rad].
    floor_m
        ``d_0`` [m].

    Returns
    -------
    F64
        ``(H,)`` scores; the best orientation has the highest.
    """
    # (H, N) projections on e1 = (cos, sin) and e2 = (-sin, cos): one row per candidate, so
    # that the reductions run along contiguous memory.
    cos, sin = np.cos(headings_rad)[:, None], np.sin(headings_rad)[:, None]
    x, y = xy_m[:, 0], xy_m[:, 1]
    along = cos * x + sin * y
    across = cos * y - sin * x
    distance = np.minimum(
        along.max(axis=1, keepdims=True) - along, along - along.min(axis=1, keepdims=True)
    )
    d_across = np.minimum(
        across.max(axis=1, keepdims=True) - across, across - across.min(axis=1, keepdims=True)
    )
    np.minimum(distance, d_across, out=distance)
    np.maximum(distance, floor_m, out=distance)
    scores: F64 = np.reciprocal(distance, out=distance).sum(axis=1)
    return scores


def visible_outline(xy_m: F64, bin_rad: float) -> F64:
    """The outline a sensor at the origin sees: the nearest point in each bearing bin.

    Parameters
    ----------
    xy_m
        ``(N, 2)`` points [m].
    bin_rad
        Width of the bearing bins [rad] (about the sensor's horizontal resolution).

    Returns
    -------
    F64
        ``(K, 2)`` points, K <= N, in bearing order.
    """
    bins = np.floor(np.arctan2(xy_m[:, 1], xy_m[:, 0]) / bin_rad).astype(np.int64)
    order = np.lexsort((np.hypot(xy_m[:, 0], xy_m[:, 1]), bins))  # by bin, nearest first
    sorted_bins = bins[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = sorted_bins[1:] != sorted_bins[:-1]
    outline: F64 = xy_m[order[first]]
    return outline


def search_orientation(
    xy_m: F64,
    settings: BoxFitSettings,
    prior_rad: float | None = None,
    tolerance_rad: float = math.radians(20.0),
) -> float:
    """Best rectangle orientation [rad] by a coarse then a fine closeness sweep.

    Parameters
    ----------
    xy_m
        ``(N, 2)`` points [m] (at least 2).
    settings
        Sweep steps and ``d_0``.
    prior_rad, tolerance_rad
        When a prior is given, only orientations within ``prior +- tolerance`` are tried, and the
        result is the rectangle axis nearest the prior. Otherwise [0, pi/2).
    """
    if settings.outline_bin_deg > 0 and len(xy_m) > 3:
        outline = visible_outline(xy_m, math.radians(settings.outline_bin_deg))
        if len(outline) >= 3:
            xy_m = outline
    stride = max(1, math.ceil(len(xy_m) / settings.max_fit_points))
    points = xy_m[::stride] - xy_m.mean(axis=0)
    floor_m = settings.closeness_floor_m
    coarse = math.radians(settings.heading_step_deg)
    if prior_rad is None:
        low, high = 0.0, math.pi / 2 - 1e-12
    else:
        half = min(tolerance_rad, math.pi / 4)
        low, high = prior_rad - half, prior_rad + half
    candidates: F64 = np.linspace(low, high, max(2, math.ceil((high - low) / coarse) + 1))
    best = float(candidates[np.argmax(closeness_scores(points, candidates, floor_m))])
    fine = math.radians(settings.refine_step_deg)
    count = max(1, math.ceil(coarse / fine))
    candidates = best + fine * np.arange(-count, count + 1, dtype=np.float64)
    if prior_rad is not None:
        candidates = np.clip(candidates, low, high)
    return float(candidates[np.argmax(closeness_scores(points, candidates, floor_m))])


def _completion_class(
    visible_length_m: float,
    visible_width_m: float,
    height_m: float,
    faces_seen: int,
    length_axis_known: bool,
) -> VehicleClass:
    if visible_length_m >= HEAVY_MIN_LENGTH_M or height_m >= HEAVY_MIN_HEIGHT_M:
        return VehicleClass.TRUCK
    # Only an L along a known length axis tells a motorcycle from a car seen end-on.
    if (
        length_axis_known
        and faces_seen == 2
        and visible_length_m <= MOTORCYCLE_MAX_LENGTH_M
        and visible_width_m <= MOTORCYCLE_MAX_WIDTH_M
    ):
        return VehicleClass.MOTORCYCLE
    return VehicleClass.CAR


def _column_step_rad(xy: F64, resolution_deg: float) -> float:
    """The azimuth step between the cluster's columns [rad]: the median gap between distinct
    azimuths, at most the sensor's resolution (dense or synthetic points: smaller)."""
    azimuths = np.unique(np.round(np.arctan2(xy[:, 1], xy[:, 0]), 7))
    gaps = np.diff(azimuths)
    limit = math.radians(resolution_deg)
    return min(float(np.median(gaps)), limit) if len(gaps) else limit


def _complete(low: float, high: float, dimension: float) -> tuple[float, float, str]:
    """Grow ``[low, high]`` (coordinates along an axis; the sensor at 0) to ``dimension``.

    Returns the new interval and how: ``"seen"``, ``"one_end"`` or ``"both_ends"``.
    """
    if high - low >= dimension:
        return low, high, "seen"
    if low >= 0.0:  # the sensor is before the near face: grow the far end
        return low, low + dimension, "one_end"
    if high <= 0.0:
        return high - dimension, high, "one_end"
    middle = 0.5 * (low + high)
    return middle - 0.5 * dimension, middle + 0.5 * dimension, "both_ends"


def hidden_front_m(
    points_xyz_m: F64,
    along_m: F64,
    beams_rad: tuple[float, float] | None,
    longest_m: float,
    drop_m: float,
    slab_m: float = 0.3,
    top_band_m: float = 0.25,
    min_visible_m: float = 1.0,
) -> float:
    """How much further on a vehicle's front may lie than the far end of its points [m].

    Sensor at the origin, the vehicle moving away from it, its points ``points_xyz_m`` (N, 3)
    at ``along_m`` (N,) along its heading. From a mast the lowest beam first meets a vehicle
    coming out from under it on its roof, and the roof hides what lies just beyond: a car's
    bonnet and windscreen, a tractor's cab below its trailer. So where the points of the far
    end (the last ``slab_m``) all lie within ``top_band_m`` of the vehicle's top (its roof
    line, seen over at least ``min_visible_m``: a front face runs down from the top to the
    bumper, and the tip of a bonnet seen alone is no roof), the front may run on up to
    ``longest_m``, unless a beam would have met it: the steepest beam that passes above those
    points comes down ``drop_m`` below the top some distance further on, and a front running
    on past there (a bonnet, a cab: no lower than that below the roof) would have returned
    it. That distance bounds the answer. Heights are read against the vehicle's own top, not
    the ground: the background's ground under the blind cone's edge can be half a metre off
    (site 10604's exit side).

    ``beams_rad``: the lowest beam's elevation and the beam spacing [rad]; None: only the
    height test, the bound ``longest_m``. Returns 0 where the front is seen low, or ruled
    out.
    """
    if longest_m <= 0.0 or len(points_xyz_m) == 0:
        return 0.0
    along_max = float(along_m.max())
    if along_max - float(along_m.min()) < min_visible_m:
        return 0.0
    top = float(points_xyz_m[:, 2].max())
    far = points_xyz_m[along_m >= along_max - slab_m]
    if float(far[:, 2].min()) < top - top_band_m:
        return 0.0
    if beams_rad is None:
        return longest_m
    lowest, spacing = beams_rad
    reach = float(np.median(np.hypot(far[:, 0], far[:, 1])))
    far_top = float(far[:, 2].max())
    if reach <= 0.0 or spacing <= 0.0:
        return longest_m
    # the steepest beam that passes above the far end's points: z = reach * tan(elevation)
    needed = math.atan2(far_top, reach)
    steps = max(0, math.ceil((needed - lowest) / spacing))
    elevation = lowest + steps * spacing
    below_top_z = top - drop_m
    if elevation >= 0.0 or below_top_z >= 0.0:
        return longest_m  # it never comes down that far
    down_at = below_top_z / math.tan(elevation)  # horizontal range where it does
    return float(min(longest_m, max(0.0, down_at - reach)))


def hidden_near_end(
    cluster_xyz_m: F64,
    heading_rad: float,
    others_xyz_m: F64,
    probe_m: float = 1.0,
    clearance_m: float = 0.3,
    angle_tolerance_rad: float = math.radians(0.6),
) -> bool:
    """Whether a nearer object hides what lies just beyond the near end of a vehicle's points.

    Sensor at the origin. Along the vehicle's length axis (``heading_rad``), the end of its
    points nearer the sensor is probed ``probe_m`` further on, at the points' median height and
    lateral position: the end is hidden when some point of ``others_xyz_m`` lies on the line of
    sight to that probe (within ``angle_tolerance_rad`` of its azimuth, ``clearance_m`` or more
    nearer, and at or above the sight line's height there). A vehicle abeam of the sensor (its
    points on both sides of it along the axis) has no near end: False.
    """
    if len(others_xyz_m) == 0 or len(cluster_xyz_m) == 0:
        return False
    axis = np.array([math.cos(heading_rad), math.sin(heading_rad)])
    normal = np.array([-axis[1], axis[0]])
    along = cluster_xyz_m[:, :2] @ axis
    if along.min() >= 0.0:
        probe_along = float(along.min()) - probe_m
    elif along.max() <= 0.0:
        probe_along = float(along.max()) + probe_m
    else:
        return False
    probe_xy = probe_along * axis + float(np.median(cluster_xyz_m[:, :2] @ normal)) * normal
    probe_z = float(np.median(cluster_xyz_m[:, 2]))
    probe_range = float(np.hypot(*probe_xy))
    if probe_range <= clearance_m:
        return False
    ranges = np.hypot(others_xyz_m[:, 0], others_xyz_m[:, 1])
    azimuth_gap = np.angle(
        np.exp(
            1j * (np.arctan2(others_xyz_m[:, 1], others_xyz_m[:, 0]) - math.atan2(*probe_xy[::-1]))
        )
    )
    nearer = ranges <= probe_range - clearance_m
    sight_z = probe_z * ranges / probe_range  # the sight line's height at each point's range
    blocking = (
        nearer
        & (np.abs(azimuth_gap) <= angle_tolerance_rad)
        & (others_xyz_m[:, 2] >= sight_z - clearance_m)
    )
    return bool(blocking.any())


def _rotated_covariance(variance_a: float, variance_b: float, angle_rad: float) -> F64:
    """``R diag(a, b) R^T``, R the rotation by ``angle_rad``: a 2x2 covariance [m^2] with
    variance ``a`` along ``angle_rad`` and ``b`` across it."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    cross = c * s * (variance_a - variance_b)
    covariance: F64 = np.array(
        [
            [c * c * variance_a + s * s * variance_b, cross],
            [cross, s * s * variance_a + c * c * variance_b],
        ]
    )
    return covariance


def fit_box(
    points_xyz_m: npt.ArrayLike,
    *,
    heading_prior_rad: float | None = None,
    heading_tolerance_rad: float = math.radians(20.0),
    ground_z_m: float | None = None,
    settings: BoxFitSettings | None = None,
    near_end_hidden: bool = False,
    near_end_cut: bool = False,
    beams_rad: tuple[float, float] | None = None,
) -> BoxFit:
    """Fit a vehicle's box to the points of its visible faces (see the module docstring).

    Parameters
    ----------
    points_xyz_m
        ``(N, 3)`` finite points of one vehicle [m], sensor frame (sensor at the origin).
    heading_prior_rad
        Expected direction of travel [rad] (e.g. the road's direction here), or None.
    heading_tolerance_rad
        How far the heading may be from the prior [rad] (at most pi/4 is used).
    ground_z_m
        Ground height under the vehicle [m], or None to use the lowest point.
    settings
        Search and noise parameters; defaults if None.
    near_end_hidden
        The end of the visible points nearer the sensor is not a face: a nearer object hides
        what lies beyond it (:func:`hidden_near_end`). The vehicle may go on either way, so a
        length completed from one end is grown evenly at both, with that spread in its
        variance, instead of away from the sensor.
    near_end_cut
        The end of the visible points nearer the sensor is where the field of view's lower
        edge cuts the vehicle, and the far end is a face: the length is grown from the far
        end towards the sensor, with the variance of a length completed from one end, also
        when the visible length already reaches the class's (it is a lower bound). A vehicle
        abeam of the sensor is grown at both ends as before. When that far end is the front
        (``heading_prior_rad`` the direction of travel, the vehicle moving away) and only its
        upper part is seen, the front may lie further on (:func:`hidden_front_m`).
    beams_rad
        The sensor's lowest beam elevation and its beam spacing [rad], for
        :func:`hidden_front_m`'s bound; None (an unorganized frame): the height test alone,
        the front allowed the class's whole reach.

    Returns
    -------
    BoxFit
        The completed box, its class and the covariance of its centre.
    """
    settings = settings or BoxFitSettings()
    points = np.asarray(points_xyz_m, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        raise ValueError("fit_box needs at least one point")
    xy = points[:, :2]
    x, y = points[:, 0], points[:, 1]
    mean_x, mean_y = float(x.mean()), float(y.mean())

    searchable = len(points) >= 2 and max(float(x.max() - x.min()), float(y.max() - y.min())) > 1e-6
    if heading_prior_rad is not None and searchable:
        along_prior = x * math.cos(heading_prior_rad) + y * math.sin(heading_prior_rad)
        searchable = float(along_prior.max() - along_prior.min()) >= settings.min_side_for_heading_m
    if searchable:
        theta = search_orientation(xy, settings, heading_prior_rad, heading_tolerance_rad)
    else:
        theta = 0.0 if heading_prior_rad is None else heading_prior_rad
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    # Projections on the rectangle's axes: axis 0 along theta, axis 1 across.
    projections = (x * cos_t + y * sin_t, y * cos_t - x * sin_t)
    extent = [float(p.max() - p.min()) for p in projections]
    faces_seen = 2 if min(extent) >= settings.thin_face_m else 1
    sight_rad = math.atan2(mean_y, mean_x)
    if heading_prior_rad is None:
        if max(extent) > settings.end_face_max_m:
            length_axis = 0 if extent[0] >= extent[1] else 1  # a side is in view
        else:
            # No face longer than a vehicle's end: most likely seen end-on, so the length
            # axis is the one nearer the line of sight.
            off_sight = abs(math.sin(theta - sight_rad))  # 0: axis 0 lies along the sight line
            length_axis = 0 if off_sight <= math.sqrt(0.5) else 1
        heading = theta + length_axis * math.pi / 2
        heading = (heading + math.pi / 2) % math.pi - math.pi / 2  # (-pi/2, pi/2]
        if heading <= -math.pi / 2 + 1e-12:
            heading += math.pi
    else:
        length_axis = 0
        heading = theta  # the search kept theta within the tolerance of the prior
    cos_h, sin_h = math.cos(heading), math.sin(heading)
    if length_axis == 0 and heading == theta:
        along, across = projections
    else:
        along, across = x * cos_h + y * sin_h, y * cos_h - x * sin_h
    along_min, along_max = float(along.min()), float(along.max())
    across_min, across_max = float(across.min()), float(across.max())
    visible_length, visible_width = along_max - along_min, across_max - across_min

    top = float(points[:, 2].max())
    bottom = float(points[:, 2].min())
    if ground_z_m is not None and math.isfinite(ground_z_m):
        bottom = min(bottom, ground_z_m)
    height = top - bottom

    completion = _completion_class(
        visible_length,
        visible_width,
        height,
        faces_seen,
        length_axis_known=heading_prior_rad is not None or max(extent) > settings.end_face_max_m,
    )
    shape = CLASS_SHAPES[completion]
    # A side face is either wholly in view or not (boxes are convex): seen from well off the
    # length axis, the visible length of a heavy vehicle is its length (a 6 m box truck beside
    # the mast is not a 16 m semitrailer); seen end-on, its length is hidden.
    side_in_view = abs(math.sin(sight_rad - heading)) >= math.sin(
        math.radians(settings.side_view_min_deg)
    )
    length_open = shape.open_length and not side_in_view
    if shape.open_length:
        shape = replace(
            shape,
            length_m=settings.heavy_length_m if length_open else 0.0,
            length_std_m=settings.heavy_length_std_m,
        )
    # The outermost columns fall on average half a column step inside a face's edges (the
    # edge lies anywhere between two columns): across the line of sight a far vehicle looks
    # narrower on both sides, and completing only the far side would shift its centre away
    # from the sensor (0.1-0.17 m at 60-120 m, measured). Both ends get that half step back.
    sight_range_m = math.hypot(mean_x, mean_y)
    half_step_m = 0.5 * sight_range_m * _column_step_rad(xy, settings.angular_resolution_deg)
    along_edge = half_step_m * abs(math.sin(sight_rad - heading))
    across_edge = half_step_m * abs(math.cos(sight_rad - heading))
    low_l, high_l, how_l = _complete(along_min - along_edge, along_max + along_edge, shape.length_m)
    from_far_end = near_end_cut and how_l in ("one_end", "seen")
    hidden_variance = 0.0
    if from_far_end:
        # The near end is the cut one, the far end the face: keep the far end and grow the
        # near one. What is visible is a lower bound of the length even when it reaches the
        # class's: the vehicle may go on into the cone, so the length's spread stays.
        length_m = max(shape.length_m, high_l - low_l)
        if along_min - along_edge >= 0.0:  # the sensor before the near end, as in _complete
            high_l = along_max + along_edge
            low_l = high_l - length_m
        else:
            low_l = along_min - along_edge
            high_l = low_l + length_m
        how_l = "one_end"
        if heading_prior_rad is not None and along_min - along_edge >= 0.0:
            # Moving away: the far end is the front. Seen only at the top, it may be the
            # roof's front edge, the bonnet or cab below the beams: the front lies anywhere up
            # to ``hidden`` further on, uniformly, and the box and its variance say so.
            heavy = completion is VehicleClass.TRUCK
            hidden = hidden_front_m(
                points,
                along,
                beams_rad,
                settings.hidden_front_heavy_m if heavy else settings.hidden_front_car_m,
                settings.hidden_front_drop_m,
            )
            low_l += 0.5 * hidden
            high_l += 0.5 * hidden
            hidden_variance = hidden**2 / 12.0
    elif near_end_hidden and how_l == "one_end":
        middle = 0.5 * (along_min + along_max)
        low_l, high_l, how_l = (
            middle - 0.5 * shape.length_m,
            middle + 0.5 * shape.length_m,
            "both_ends",
        )
    low_w, high_w, how_w = _complete(
        across_min - across_edge, across_max + across_edge, shape.width_m
    )
    length, width = high_l - low_l, high_w - low_w
    mid_l, mid_w = 0.5 * (low_l + high_l), 0.5 * (low_w + high_w)
    centre_x = mid_l * cos_h - mid_w * sin_h
    centre_y = mid_l * sin_h + mid_w * cos_h

    # Shape part of the covariance, in the box frame (length, width).
    def shape_variance(how: str, dimension_std: float, visible: float, dimension: float) -> float:
        if how == "seen":
            return 0.0
        variance = (0.5 * dimension_std) ** 2
        if how == "both_ends":
            variance += (0.5 * (dimension - visible)) ** 2 / 3.0
        return variance

    variance_length = shape_variance(how_l, shape.length_std_m, visible_length, shape.length_m)
    if length_open:
        variance_length = max(variance_length, (0.5 * shape.length_std_m) ** 2)
    variance_length += hidden_variance
    range_m = math.hypot(centre_x, centre_y)
    # Completed as a car from its near face, but too far for the beams to rule out a heavy
    # vehicle's height: the centre lies anywhere from a car's half-length to a heavy
    # vehicle's behind that face, and its variance along the length says so.
    possibly_heavy = (
        completion is not VehicleClass.TRUCK
        and how_l == "one_end"
        and not side_in_view
        and height + range_m * math.radians(settings.beam_spacing_deg) >= HEAVY_MIN_HEIGHT_M
    )
    if possibly_heavy:
        variance_length = max(
            variance_length, (0.5 * (settings.heavy_length_m - shape.length_m)) ** 2
        )
    variance_width = shape_variance(how_w, shape.width_std_m, visible_width, shape.width_m)
    # Sensor part, in the bearing frame of the centre: along the ray and across it.
    sigma_across = max(range_m, 1.0) * math.radians(settings.angular_resolution_deg)
    covariance = _rotated_covariance(variance_length, variance_width, heading)
    covariance += _rotated_covariance(
        settings.range_noise_m**2, sigma_across**2, math.atan2(centre_y, centre_x)
    )

    return BoxFit(
        center_xyz_m=(centre_x, centre_y, 0.5 * (top + bottom)),
        size_lwh_m=(length, width, height),
        heading_rad=heading,
        object_class=class_from_size(length, width, height),
        covariance_xy_m2=covariance,
        visible_lw_m=(visible_length, visible_width),
        faces_seen=faces_seen,
        completed_lw=(how_l != "seen", how_w != "seen"),
        completed_from_far_end=from_far_end,
    )
