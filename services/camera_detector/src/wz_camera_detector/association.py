"""Camera-radar association and fusion: the detector's step 5, as a pure core.

Inputs: camera objects already ranged onto the road (site-frame ground positions with their
2x2 covariance, class, score and image-tracker local id), one :class:`RadarScan` and the radar's
:class:`SensorMount`. Output: one :class:`FusedObject` per object seen by either sensor.
:func:`fuse_camera_radar` runs, in this order:

1. **Radar to site frame** (:func:`radar_targets_to_site`). A radar reports slant range ``r``
   and azimuth ``a`` in its sensor frame. The reflection is assumed to lie at height
   ``target_height_m`` (the simulated radar reflects at the box centre height), so with the
   mount height ``h = z_s - target_height_m`` the horizontal range is
   ``rho = sqrt(r^2 - h^2)``. The mount is taken as level in pitch and roll for this step (a
   traffic radar is levelled; the simulator's azimuth plane is the sensor's x-y plane), so the
   site bearing is ``theta = yaw_s + a`` with ``yaw_s`` the ground heading of the sensor's x
   axis, and the point is ``p = p_s + rho (cos theta, sin theta)``. With the unit line of sight
   ``u = (cos theta, sin theta)`` and its left normal ``n = (-sin theta, cos theta)``, the
   Jacobian of ``p`` in ``(r, a)`` is ``J = [u r / rho, n rho]``, so::

       R = J diag(sigma_r^2, sigma_a^2) J^T
         = (sigma_r r / rho)^2 u u^T + (rho sigma_a)^2 n n^T           [m^2]

2. **Gate** (:func:`gate_distances`). The radar echoes from the centre of a vehicle's nearest
   visible face (:func:`face_offsets`, the simulator's echo model), the camera object is the
   vehicle's centre ``c``: with the camera's heading ``e`` (its left normal ``n``) and class
   size ``L x W``, the echo is at ``c + f``, ``f`` the end face's ``+-(L/2) e`` or the side
   face's ``+-(W/2) n``, whichever centre is nearer the radar (about half a length towards the
   radar for an approaching vehicle: 2.3 m for a car, 8 m for a truck). Each camera object is
   compared at that expected echo point. Then the squared Mahalanobis distance between that
   point ``c`` and radar point ``p``, with both covariances and an extra variance along the
   radar's line of sight ``u`` for what the face model misses (size and heading guesses, the
   echo wandering over the face)::

       S = P_c + R + sigma_extent^2 u u^T,    d^2 = (c - p)^T S^-1 (c - p)

   A pair is admissible when ``d^2 < gate_chi2`` (chi-square with 2 degrees of freedom; the
   default 13.82 keeps 99.9 % of true pairs). Mahalanobis distance is used rather than separate
   range and azimuth gates because the camera's error ellipse is not aligned with the radar's
   polar axes unless the camera and radar share a mast position.

3. **Global nearest neighbour** (:func:`associate`): the assignment minimising the sum of
   ``d^2`` over admissible pairs (``scipy.optimize.linear_sum_assignment``); pairs beyond the
   gate are forbidden, never forced. A pair is then dropped as *ambiguous* when a partner
   left over by the assignment fits almost as well: an unpaired echo within
   ``ambiguity_margin_chi2`` of the pair's ``d^2`` for its camera object, or an unpaired
   camera object as close to its echo. Two cars side by side at 180 m, the nearer hiding the
   other from the camera, give one box and two echoes 1.1 degrees apart (the radar's azimuth
   std is 0.5 degrees) at ranges the camera cannot tell apart: pairing the box with either
   makes a vehicle from one car's lane and the other's speed, which the tracker then follows
   between the two. Dropped pairs leave a camera-only object and radar-only ones, each with
   its own, honest uncertainty.

4. **Fuse** each pair (:func:`fuse_pair`): range and radial speed from the radar, bearing and
   class from the camera. The fused point is built in the radar's polar frame: on the
   camera's bearing ``u_c`` seen from the radar, at the distance ``t`` whose echo
   ``t u_c + f`` (``f`` the face offset of step 2) is at the radar's horizontal range
   ``rho_r`` (:func:`centre_range_m`): ``p_f = p_s + t u_c``. Head-on, ``t = rho_r + L/2``.
   Moving the echo along the line of sight instead (as before 2026-11-30) put a car's centre
   up to 0.9 m across the road where the line of sight crosses it steeply: 15-20 m before a
   radar on a pole 9 m aside of the lanes (generated site 10602). Its covariance models range
   and bearing as independent, the range error being the radar's and the bearing error the
   camera's::

       sigma_rho^2   = (sigma_r r / rho_r)^2 + sigma_extent^2      (radar range, horizontal,
                                                                    and the face model's error)
       sigma_theta^2 = n_c^T P_c n_c / rho_c^2                      (camera bearing, rad^2)
       P_f = sigma_rho^2 u_c u_c^T + (rho_r^2 sigma_theta^2) n_c n_c^T

   where ``rho_c`` is the camera object's horizontal distance from the radar. The camera's
   along-line-of-sight error and the radar's azimuth error are discarded, not averaged in: the
   model suits the usual case of a camera ranging poorly (flat-road ranging from pixel rows) and
   a radar resolving azimuth poorly (a few degrees of beam).

5. **Speed** (:func:`along_road_speed`): a radial speed ``v_r`` is the projection of the
   velocity on the *slant* line of sight, which dips by the elevation ``e`` from the mast to
   the echo (``cos e = rho / r``). A road vehicle moves level, so with the road heading ``psi``
   (direction of travel, site frame) the along-road speed is
   ``v = v_r / (cos e cos(theta_r - psi))``, ``theta_r`` the radar's own bearing of the echo
   (the line the radial speed lies on; the camera's bearing is the better one for the
   position, not for this: near the mast a camera box seen from above is a metre or more off
   across, and with its bearing the cars' speeds 15-20 m before the default site's mast were
   0.56 m/s slow (median), with the radar's 0.00), positive in the direction of travel; where
   the line of sight is too close to perpendicular to the motion (``|cos e cos(theta - psi)| <
   min_speed_cosine``) the division is meaningless and the speed is None. Without a road
   heading the speed is the horizontal radial speed ``|v_r| / cos e``. Leaving ``cos e`` out
   (as before 2026-11-29) made every speed near a high mast too slow: on the default site (radar
   5 m up, echoes 0.75 m) 0.6 m/s at 25 m and 1.7 m/s at 15 m, for a car at 25 m/s.

6. **Leftovers.** An unmatched camera object passes through as ``"camera"`` (no speed). An
   unmatched radar target becomes ``"radar"`` (class unknown, score ``radar_only_score``) when it
   moves (``|v_r| > min_radar_only_speed_mps``) and is strong enough
   (``rcs_dbsm >= min_radar_only_rcs_dbsm``): a vehicle the camera misses at night or in fog.
   Its echo is taken for the nearest face of a car-sized vehicle on the road's heading and
   moved to that vehicle's centre (:func:`centre_from_echo`), and its variance along the road
   widened by ``radar_only_size_std_m^2`` (it could be a truck: a vehicle's unknown length lies
   along its heading, whatever the line of sight).
   An unmatched echo on the footprint of a camera object (its class's typical length and width
   on its heading, plus ``echo_on_body_margin_m``) is another echo of that vehicle, not a
   vehicle of its own, and dropped: a 16.5 m truck seen from the side near the mast returns
   echoes from the cab to the trailer's end, and each used to become a "car" 6 m ahead of the
   truck's centre (measured on a generated site: 484 of 805 false tracks).
   Anything else is clutter (guard rails, signs, rain) and dropped.

Nothing here does I/O: the node decodes the scan and camera objects, calls
:func:`fuse_camera_radar`, and publishes :func:`to_detection` of each result.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field
from scipy.optimize import linear_sum_assignment

from wz_shared.arrays import F64, Bool
from wz_shared.geometry import polar_covariance
from wz_shared.messages import Detection, RadarScan, RadarTarget, VehicleClass
from wz_shared.sensor_mounts import intrinsics_of
from wz_shared.site import RadarIntrinsics, SensorMount

FusedSource = Literal["camera+radar", "camera", "radar"]

#: Cost of a forbidden pair in the assignment; far above any admissible ``d^2``.
_FORBIDDEN_COST = 1e12


class AssociationSettings(BaseModel):
    """Parameters of :func:`fuse_camera_radar`; metres, seconds, radians, dBsm."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: Gate on the squared Mahalanobis distance (chi-square, 2 dof; 13.82 keeps 99.9 %).
    gate_chi2: float = Field(default=13.82, gt=0.0)
    #: A pair is ambiguous when an unpaired echo (or camera object) is within this of its
    #: ``d^2`` (6: the alternative at least 1/20 as likely); 0 turns the check off.
    ambiguity_margin_chi2: float = Field(default=6.0, ge=0.0)
    #: Std of the offset between the radar's reflection point and the camera's ground point
    #: along the radar's line of sight [m] (about half a car length seen end-on).
    reflection_extent_std_m: float = Field(default=1.0, ge=0.0)
    #: ... and across it [m]: the echo comes from anywhere on the face's width (a car is
    #: 1.8 m wide), while the camera's bearing is the box's middle.
    reflection_width_std_m: float = Field(default=0.5, ge=0.0)
    #: Std of the fused centre along the line of sight once the echo is set back by the
    #: class's half-length [m]: the face model's error (length, heading, which face echoed).
    #: Measured in simulation against truth: 0.26-0.42 m RMSE within 125 m.
    centre_std_m: float = Field(default=0.35, ge=0.0)
    #: Height of the radar reflection above the road [m] (box centre height of a car).
    target_height_m: float = Field(default=0.75, allow_inf_nan=False)
    #: Smallest horizontal range used in the Jacobians [m]: a target under the mast has none.
    min_horizontal_range_m: float = Field(default=1.0, gt=0.0)
    #: An unmatched radar target is kept when its |radial speed| exceeds this [m/s].
    min_radar_only_speed_mps: float = Field(default=1.0, ge=0.0)
    #: ... and its RCS is at least this [dBsm] (simulated clutter sits around -10 dBsm).
    min_radar_only_rcs_dbsm: float = Field(default=0.0, allow_inf_nan=False)
    #: Std of a radar-only object's centre along the road, for not knowing its length (the
    #: echo is taken for a car's nearest face; a truck's centre is 6 m further) [m].
    radar_only_size_std_m: float = Field(default=3.0, ge=0.0)
    #: An unmatched echo within this of a camera object's footprint (its class's typical size
    #: on its heading) is taken for another echo of that vehicle and dropped [m]: the radar's
    #: range noise and a few tenths of a degree of azimuth at 100 m.
    echo_on_body_margin_m: float = Field(default=1.0, ge=0.0)
    #: Score given to a radar-only detection, in [0, 1].
    radar_only_score: float = Field(default=0.5, ge=0.0, le=1.0)
    #: Smallest |cos(line of sight - road heading)| at which a radial speed is converted.
    min_speed_cosine: float = Field(default=0.2, gt=0.0, le=1.0)


#: Size assumed for a radar-only object (a car), for its echo's face [m].
RADAR_ONLY_LENGTH_M = 4.6
RADAR_ONLY_WIDTH_M = 1.8


@dataclass(frozen=True, slots=True)
class CameraObject:
    """One camera object ranged onto the road, in the site frame.

    Attributes
    ----------
    local_id
        The image tracker's local id (>= 0).
    x_m, y_m
        Ground position [m], site frame.
    covariance_m2
        Position covariance [m^2], shape (2, 2), symmetric positive definite.
    object_class
        Class from the image detector.
    score
        Detector score in [0, 1].
    heading_rad
        Assumed heading [rad], CCW from east (the road's); None: the echo is taken at the
        centre.
    length_m, width_m
        Assumed size [m] (the class's typical one), for the radar's echo (its nearest face).
    """

    local_id: int
    x_m: float
    y_m: float
    covariance_m2: F64
    object_class: VehicleClass
    score: float
    heading_rad: float | None = None
    length_m: float = 0.0
    width_m: float = 0.0


@dataclass(frozen=True, slots=True)
class RadarPoint:
    """One radar target converted to the site frame (see the module docstring, step 1).

    Attributes
    ----------
    target_index
        Index of the target in its scan's ``targets``.
    x_m, y_m
        Ground position [m], site frame.
    covariance_m2
        Position covariance [m^2], shape (2, 2).
    slant_range_m
        Measured slant range ``r`` [m].
    horizontal_range_m
        Horizontal range ``rho`` from the mast [m].
    bearing_rad
        Site-frame bearing ``theta`` of the line of sight, counter-clockwise from east [rad].
    radial_speed_mps
        Radial speed [m/s], positive away from the radar.
    rcs_dbsm
        Radar cross-section [dBsm].
    """

    target_index: int
    x_m: float
    y_m: float
    covariance_m2: F64
    slant_range_m: float
    horizontal_range_m: float
    bearing_rad: float
    radial_speed_mps: float
    rcs_dbsm: float

    @property
    def sensor_xy_m(self) -> tuple[float, float]:
        """The radar's ground position [m]: the point ``rho`` back along the line of sight."""
        return (
            self.x_m - self.horizontal_range_m * math.cos(self.bearing_rad),
            self.y_m - self.horizontal_range_m * math.sin(self.bearing_rad),
        )


@dataclass(frozen=True, slots=True)
class FusedObject:
    """One object after camera-radar fusion, in the site frame.

    Attributes
    ----------
    source
        ``"camera+radar"``, ``"camera"`` or ``"radar"``.
    x_m, y_m
        Position [m], site frame.
    covariance_m2
        Position covariance [m^2], shape (2, 2), symmetric positive definite.
    object_class
        The camera's class; ``UNKNOWN`` for a radar-only object.
    score
        The camera's score; ``radar_only_score`` for a radar-only object.
    speed_mps
        Along-road speed [m/s] (or ``|radial speed|`` without a road heading); None without
        radar or where the line of sight is nearly across the road.
    camera_local_id
        The camera object's local id, None for a radar-only object.
    radar_target_index
        Index of the radar target in its scan, None for a camera-only object.
    """

    source: FusedSource
    x_m: float
    y_m: float
    covariance_m2: F64
    object_class: VehicleClass
    score: float
    speed_mps: float | None
    camera_local_id: int | None
    radar_target_index: int | None


def _radar_intrinsics(mount: SensorMount) -> RadarIntrinsics:
    return intrinsics_of(mount, RadarIntrinsics, "camera-radar association needs the radar's mount")


def _unit(bearing_rad: float) -> tuple[F64, F64]:
    """Line-of-sight unit vector ``u`` and its left normal ``n``, each shape (2,)."""
    cos_b, sin_b = math.cos(bearing_rad), math.sin(bearing_rad)
    return np.array([cos_b, sin_b]), np.array([-sin_b, cos_b])


def radar_targets_to_site(
    targets: Sequence[RadarTarget],
    mount: SensorMount,
    settings: AssociationSettings | None = None,
) -> list[RadarPoint]:
    """Convert radar targets to site-frame ground points with covariance (module step 1).

    Parameters
    ----------
    targets : sequence of RadarTarget, length N
        Targets in the radar's sensor frame (slant range [m], azimuth [rad]).
    mount : SensorMount
        The radar's mount (pose and :class:`RadarIntrinsics` noise stds).
    settings : AssociationSettings or None
        ``target_height_m`` and ``min_horizontal_range_m``; defaults when None.

    Returns
    -------
    list of RadarPoint, length N
        In input order; ``target_index`` is the position in ``targets``.

    Raises
    ------
    ValueError
        If ``mount`` is not a radar.
    """
    settings = settings or AssociationSettings()
    intrinsics = _radar_intrinsics(mount)
    range_std_m = intrinsics.range_noise_std_m
    azimuth_std_rad = math.radians(intrinsics.azimuth_noise_std_deg)
    height_m = mount.pose.z_m - settings.target_height_m
    heading_rad = mount.pose.ground_heading_rad()
    points: list[RadarPoint] = []
    for index, target in enumerate(targets):
        slant_m = target.range_m
        rho_m = math.sqrt(max(slant_m * slant_m - height_m * height_m, 0.0))
        # The Jacobian's r / rho grows without bound under the mast; clamp rho there.
        rho_jacobian_m = max(rho_m, settings.min_horizontal_range_m)
        bearing = heading_rad + target.azimuth_rad
        # R = (sigma_r r / rho)^2 u u^T + (rho sigma_a)^2 n n^T
        covariance = polar_covariance(
            bearing,
            (range_std_m * max(slant_m, rho_jacobian_m) / rho_jacobian_m) ** 2,
            (rho_jacobian_m * azimuth_std_rad) ** 2,
        )
        points.append(
            RadarPoint(
                target_index=index,
                x_m=mount.pose.x_m + rho_m * math.cos(bearing),
                y_m=mount.pose.y_m + rho_m * math.sin(bearing),
                covariance_m2=covariance,
                slant_range_m=slant_m,
                horizontal_range_m=rho_m,
                bearing_rad=bearing,
                radial_speed_mps=target.radial_speed_mps,
                rcs_dbsm=target.rcs_dbsm,
            )
        )
    return points


def face_offsets(
    to_sensor_xy_m: npt.ArrayLike,
    heading_rad: npt.ArrayLike,
    length_m: npt.ArrayLike,
    width_m: npt.ArrayLike,
) -> F64:
    """From vehicles' centres to the centres of their faces nearest a sensor [m], shape (K, 2).

    A vehicle's footprint turns two faces to a sensor: an end face (``+-L/2`` along its heading
    ``e``) and a side face (``+-W/2`` across it, ``n``); the echo comes from the one whose centre
    is nearer (the echo model of :mod:`wz_simulator.sensors.radar`). With ``t`` the sensor seen
    from the centre, ``t_e = t . e`` and ``t_n = t . n``, the end face's centre is the nearer when
    ``(|t_e| - L/2)^2 + t_n^2 <= t_e^2 + (|t_n| - W/2)^2``, that is
    ``L |t_e| - W |t_n| >= (L^2 - W^2) / 4``.

    Parameters
    ----------
    to_sensor_xy_m
        The sensor's position minus each vehicle's centre [m], shape (K, 2) or (2,).
    heading_rad, length_m, width_m
        Each vehicle's heading [rad] and size [m], scalars or shape (K,).
    """
    t = np.atleast_2d(np.asarray(to_sensor_xy_m, dtype=np.float64))
    heading = np.asarray(heading_rad, dtype=np.float64)
    half_l = 0.5 * np.asarray(length_m, dtype=np.float64)
    half_w = 0.5 * np.asarray(width_m, dtype=np.float64)
    e = np.stack([np.cos(heading), np.sin(heading)], axis=-1).reshape(-1, 2)
    n = np.stack([-e[:, 1], e[:, 0]], axis=1)
    t_e = np.einsum("ki,ki->k", t, e)
    t_n = np.einsum("ki,ki->k", t, n)
    end = _end_face_nearer(t_e, t_n, half_l, half_w)
    sign_e = np.where(t_e >= 0.0, 1.0, -1.0)
    sign_n = np.where(t_n >= 0.0, 1.0, -1.0)
    offsets: F64 = np.where(
        end[:, None], (sign_e * half_l)[:, None] * e, (sign_n * half_w)[:, None] * n
    )
    return offsets


def face_offset(
    centre_xy_m: tuple[float, float],
    sensor_xy_m: tuple[float, float],
    heading_rad: float,
    length_m: float,
    width_m: float,
) -> tuple[float, float]:
    """:func:`face_offsets` of one vehicle centred at ``centre_xy_m`` [m], in plain floats: it
    runs a few times per camera object and radar target of every frame, where numpy's
    per-call cost is twenty times the arithmetic."""
    tx, ty = sensor_xy_m[0] - centre_xy_m[0], sensor_xy_m[1] - centre_xy_m[1]
    ex, ey = math.cos(heading_rad), math.sin(heading_rad)
    t_e, t_n = tx * ex + ty * ey, ty * ex - tx * ey
    half_l, half_w = 0.5 * length_m, 0.5 * width_m
    if _end_face_nearer(t_e, t_n, half_l, half_w):
        along = half_l if t_e >= 0.0 else -half_l
        return along * ex, along * ey
    across = half_w if t_n >= 0.0 else -half_w
    return -across * ey, across * ex


@overload
def _end_face_nearer(t_e: float, t_n: float, half_l: float, half_w: float) -> bool: ...
@overload
def _end_face_nearer(t_e: F64, t_n: F64, half_l: F64, half_w: F64) -> Bool: ...
def _end_face_nearer(t_e: Any, t_n: Any, half_l: Any, half_w: Any) -> Any:
    """Whether the end face's centre is nearer the sensor than the side face's (floats, or
    arrays): ``(|t_e| - L/2)^2 + t_n^2 <= t_e^2 + (|t_n| - W/2)^2``, reduced."""
    return half_l * abs(t_e) - half_w * abs(t_n) >= half_l**2 - half_w**2


def centre_from_echo(
    echo_xy_m: tuple[float, float],
    sensor_xy_m: tuple[float, float],
    heading_rad: float,
    length_m: float,
    width_m: float,
) -> tuple[tuple[float, float], tuple[float, float]]:
    """The centre of a vehicle whose nearest face's centre (:func:`face_offsets`) is at
    ``echo_xy_m`` [m], and half the gap to the other possible centre.

    The centre is the echo moved back by half a length along the heading (end face) or by
    half a width across it (side face), on the side away from the sensor: whichever of the
    two is consistent (its nearest face is the one assumed). Seen from a broad angle both can
    be (a long vehicle's side centre, or the end of one standing a half-length further on):
    then the centre is their midpoint and the half-gap ``g`` says how far either lies from it
    (the caller adds ``g g^T`` to the variance). Where neither is (a sensor within the
    footprint's reach: under the mast) the end face is taken, with ``g = 0``.

    Returns
    -------
    centre, half_gap
        ``(x, y)`` [m] and ``(gx, gy)`` [m] (zeros when only one centre fits).
    """
    ex, ey = echo_xy_m
    e = (math.cos(heading_rad), math.sin(heading_rad))
    n = (-e[1], e[0])
    to_sensor = (sensor_xy_m[0] - ex, sensor_xy_m[1] - ey)
    sign_e = 1.0 if to_sensor[0] * e[0] + to_sensor[1] * e[1] >= 0.0 else -1.0
    sign_n = 1.0 if to_sensor[0] * n[0] + to_sensor[1] * n[1] >= 0.0 else -1.0
    end = (ex - sign_e * 0.5 * length_m * e[0], ey - sign_e * 0.5 * length_m * e[1])
    side = (ex - sign_n * 0.5 * width_m * n[0], ey - sign_n * 0.5 * width_m * n[1])
    fits = []
    for centre in (end, side):
        dx, dy = face_offset(centre, sensor_xy_m, heading_rad, length_m, width_m)
        fits.append(math.hypot(centre[0] + dx - ex, centre[1] + dy - ey) < 1e-6)
    if fits[0] and fits[1]:
        middle = (0.5 * (end[0] + side[0]), 0.5 * (end[1] + side[1]))
        return middle, (end[0] - middle[0], end[1] - middle[1])
    return (side if fits[1] and not fits[0] else end), (0.0, 0.0)


def expected_echo(camera: CameraObject, radar_xy_m: tuple[float, float]) -> CameraObject:
    """The camera object moved to where the radar should see it: the centre of its face
    nearest the radar (step 2, :func:`face_offsets`); unmoved without a heading."""
    if camera.heading_rad is None:
        return camera
    dx, dy = face_offset(
        (camera.x_m, camera.y_m), radar_xy_m, camera.heading_rad, camera.length_m, camera.width_m
    )
    return dataclasses.replace(camera, x_m=camera.x_m + dx, y_m=camera.y_m + dy)


def centre_range_m(radar_rho_m: float, bearing_rad: float, face_xy_m: tuple[float, float]) -> float:
    """How far from the radar, along ``bearing_rad``, a vehicle's centre lies whose echo
    (its centre plus ``face_xy_m``, :func:`face_offsets`) is ``radar_rho_m`` away: ``t`` with
    ``|t u + f| = rho``, ``t = -(u . f) + sqrt(rho^2 - |f|^2 + (u . f)^2)``. Where no ``t``
    solves it (an echo nearer than the face's reach across the bearing: under the mast), the
    echo's range plus the offset's part along the bearing."""
    u = (math.cos(bearing_rad), math.sin(bearing_rad))
    along = u[0] * face_xy_m[0] + u[1] * face_xy_m[1]
    across_sq = face_xy_m[0] ** 2 + face_xy_m[1] ** 2 - along * along
    discriminant = radar_rho_m * radar_rho_m - across_sq
    if discriminant < 0.0:
        return radar_rho_m - along
    return -along + math.sqrt(discriminant)


def gate_distances(
    camera_objects: Sequence[CameraObject],
    radar_points: Sequence[RadarPoint],
    reflection_extent_std_m: float,
    reflection_width_std_m: float = 0.0,
) -> F64:
    """Squared Mahalanobis distance of every camera-radar pair (module step 2).

    Parameters
    ----------
    camera_objects : sequence of CameraObject, length C
    radar_points : sequence of RadarPoint, length R
    reflection_extent_std_m : float
        Std [m] added along each radar line of sight for the reflection-point offset.
    reflection_width_std_m : float
        Std [m] added across it (where on the face's width the echo came from).

    Returns
    -------
    ndarray, shape (C, R)
        ``d^2 = (c - p)^T (P_c + R + sigma_extent^2 u u^T + sigma_width^2 n n^T)^-1 (c - p)``
        [dimensionless], ``n`` the normal of the line of sight ``u``.
    """
    n_camera, n_radar = len(camera_objects), len(radar_points)
    if n_camera == 0 or n_radar == 0:
        return np.zeros((n_camera, n_radar))
    camera_xy = np.array([(c.x_m, c.y_m) for c in camera_objects])  # (C, 2)
    camera_cov = np.stack([c.covariance_m2 for c in camera_objects])  # (C, 2, 2)
    radar_xy = np.array([(p.x_m, p.y_m) for p in radar_points])  # (R, 2)
    line_of_sight = np.array([_unit(p.bearing_rad)[0] for p in radar_points])  # (R, 2)
    normal = np.stack([-line_of_sight[:, 1], line_of_sight[:, 0]], axis=1)  # (R, 2)
    radar_cov = (
        np.stack([p.covariance_m2 for p in radar_points])
        + reflection_extent_std_m**2 * np.einsum("ri,rj->rij", line_of_sight, line_of_sight)
        + reflection_width_std_m**2 * np.einsum("ri,rj->rij", normal, normal)
    )  # (R, 2, 2)
    innovation = camera_xy[:, None, :] - radar_xy[None, :, :]  # (C, R, 2)
    innovation_cov = camera_cov[:, None, :, :] + radar_cov[None, :, :, :]  # (C, R, 2, 2)
    solved = np.linalg.solve(innovation_cov, innovation[..., None])[..., 0]
    distances: F64 = np.einsum("cri,cri->cr", innovation, solved)
    return distances


def associate(
    distances_sq: F64, gate_chi2: float, ambiguity_margin_chi2: float = 0.0
) -> list[tuple[int, int]]:
    """Global nearest neighbour on gated squared distances (module step 3).

    Parameters
    ----------
    distances_sq : ndarray, shape (C, R)
        Squared Mahalanobis distances from :func:`gate_distances`.
    gate_chi2 : float
        Pairs with ``d^2 >= gate_chi2`` are never matched.
    ambiguity_margin_chi2 : float
        A pair is dropped when an admissible camera object or echo the assignment left
        unpaired is within this of its ``d^2``; 0: no check.

    Returns
    -------
    list of (int, int)
        ``(camera index, radar index)`` pairs minimising the summed ``d^2``, by camera index,
        less the ambiguous ones.
    """
    if distances_sq.size == 0:
        return []
    admissible = distances_sq < gate_chi2
    cost = np.where(admissible, distances_sq, _FORBIDDEN_COST)
    rows, columns = linear_sum_assignment(cost)
    pairs = [
        (int(row), int(column))
        for row, column in zip(rows.tolist(), columns.tolist(), strict=True)
        if admissible[row, column]
    ]
    if ambiguity_margin_chi2 <= 0.0 or not pairs:
        return pairs
    free_rows = np.ones(distances_sq.shape[0], dtype=bool)
    free_columns = np.ones(distances_sq.shape[1], dtype=bool)
    for row, column in pairs:
        free_rows[row] = free_columns[column] = False
    clear = []
    for row, column in pairs:
        limit = distances_sq[row, column] + ambiguity_margin_chi2
        rival_echo = free_columns & admissible[row] & (distances_sq[row] < limit)
        rival_camera = free_rows & admissible[:, column] & (distances_sq[:, column] < limit)
        if not (rival_echo.any() or rival_camera.any()):
            clear.append((row, column))
    return clear


def elevation_cosine(radar: RadarPoint) -> float:
    """``cos e = rho / r`` of a radar point's line of sight (1 for a zero slant range)."""
    if radar.slant_range_m <= 0.0:
        return 1.0
    return min(1.0, radar.horizontal_range_m / radar.slant_range_m)


def along_road_speed(
    radar: RadarPoint, road_heading_rad: float | None, min_speed_cosine: float
) -> float | None:
    """Speed from a radar point's radial speed (module step 5), along its own line of sight.

    Parameters
    ----------
    radar : RadarPoint
        Its radial speed ``v_r`` [m/s] (positive away from the radar), site bearing ``theta``
        and ``cos e`` (:func:`elevation_cosine`: the line's dip from the radar to the echo).
    road_heading_rad : float or None
        Direction of travel [rad], site frame; None when unknown.
    min_speed_cosine : float
        Smallest ``|cos e cos(theta - road_heading)|`` at which the conversion is made.

    Returns
    -------
    float or None
        ``v_r / (cos e cos(theta - road_heading))`` [m/s], positive in the direction of
        travel; ``|v_r| / cos e`` without a road heading; None when the line of sight is nearly
        across the vehicle's motion (or, without a road heading, nearly vertical).
    """
    cos_elevation = elevation_cosine(radar)
    if road_heading_rad is None:
        if cos_elevation < min_speed_cosine:
            return None
        return abs(radar.radial_speed_mps) / cos_elevation
    cosine = cos_elevation * math.cos(radar.bearing_rad - road_heading_rad)
    if abs(cosine) < min_speed_cosine:
        return None
    return radar.radial_speed_mps / cosine


def fuse_pair(
    camera: CameraObject,
    radar: RadarPoint,
    mount: SensorMount,
    settings: AssociationSettings | None = None,
    road_heading_rad: float | None = None,
    dt_s: float = 0.0,
) -> FusedObject:
    """Fuse one associated pair: radar range and speed, camera bearing and class (step 4).

    Parameters
    ----------
    camera : CameraObject
    radar : RadarPoint
        Converted by :func:`radar_targets_to_site` with ``mount``.
    mount : SensorMount
        The radar's mount.
    settings : AssociationSettings or None
        Defaults when None.
    road_heading_rad : float or None
        Direction of travel [rad] for the speed; None for ``|v_r|``.
    dt_s : float
        Camera frame time minus scan time [s]: the radar range is carried to the frame's time
        with the radial speed, ``rho_r + v_r dt / cos e`` (the echo moves level; a car at
        30 m/s moves 1 m in a 15 Hz scan period).

    Returns
    -------
    FusedObject
        ``source == "camera+radar"``, position ``p_s + t u_c`` (:func:`centre_range_m`) and
        covariance
        ``sigma_rho^2 u_c u_c^T + rho_r^2 sigma_theta^2 n_c n_c^T`` [m^2].
    """
    settings = settings or AssociationSettings()
    intrinsics = _radar_intrinsics(mount)
    dx, dy = camera.x_m - mount.pose.x_m, camera.y_m - mount.pose.y_m
    camera_bearing = math.atan2(dy, dx)
    camera_rho_m = max(math.hypot(dx, dy), settings.min_horizontal_range_m)
    # The echo moves level: its horizontal range changes by v_r / cos e (rho^2 = r^2 - h^2).
    rho_rate_mps = radar.radial_speed_mps / max(elevation_cosine(radar), settings.min_speed_cosine)
    radar_rho_m = max(0.0, radar.horizontal_range_m + rho_rate_mps * dt_s)
    radar_rho_jacobian_m = max(radar_rho_m, settings.min_horizontal_range_m)
    _, normal = _unit(camera_bearing)
    # sigma_theta^2 = n^T P_c n / rho_c^2: the camera's lateral variance as a bearing variance.
    bearing_variance_rad2 = float(normal @ camera.covariance_m2 @ normal) / camera_rho_m**2
    range_variance_m2 = (
        intrinsics.range_noise_std_m
        * max(radar.slant_range_m, radar_rho_jacobian_m)
        / radar_rho_jacobian_m
    ) ** 2 + settings.centre_std_m**2  # where on the near face it echoed, the face model's
    # guess of length and heading: the centre is that uncertain along the range
    covariance = polar_covariance(
        camera_bearing, range_variance_m2, radar_rho_jacobian_m**2 * bearing_variance_rad2
    )
    if camera.heading_rad is None:
        face = (0.0, 0.0)
    else:
        face = face_offset(
            (camera.x_m, camera.y_m),
            (mount.pose.x_m, mount.pose.y_m),
            camera.heading_rad,
            camera.length_m,
            camera.width_m,
        )
    centre_rho_m = centre_range_m(radar_rho_m, camera_bearing, face)
    return FusedObject(
        source="camera+radar",
        x_m=mount.pose.x_m + centre_rho_m * math.cos(camera_bearing),
        y_m=mount.pose.y_m + centre_rho_m * math.sin(camera_bearing),
        covariance_m2=covariance,
        object_class=camera.object_class,
        score=camera.score,
        speed_mps=along_road_speed(radar, road_heading_rad, settings.min_speed_cosine),
        camera_local_id=camera.local_id,
        radar_target_index=radar.target_index,
    )


def camera_only(camera: CameraObject) -> FusedObject:
    """A camera object passed through unfused (no radar target in its gate, or no scan)."""
    return FusedObject(
        source="camera",
        x_m=camera.x_m,
        y_m=camera.y_m,
        covariance_m2=np.array(camera.covariance_m2, dtype=np.float64),
        object_class=camera.object_class,
        score=camera.score,
        speed_mps=None,
        camera_local_id=camera.local_id,
        radar_target_index=None,
    )


def _on_body(radar: RadarPoint, camera: CameraObject, margin_m: float) -> bool:
    """Whether the echo lies on ``camera``'s footprint (its size on its heading) + margin."""
    if camera.heading_rad is None or camera.length_m <= 0.0:
        return False
    dx, dy = radar.x_m - camera.x_m, radar.y_m - camera.y_m
    cos_h, sin_h = math.cos(camera.heading_rad), math.sin(camera.heading_rad)
    along = dx * cos_h + dy * sin_h
    across = -dx * sin_h + dy * cos_h
    return (
        abs(along) <= camera.length_m / 2.0 + margin_m
        and abs(across) <= camera.width_m / 2.0 + margin_m
    )


def _radar_only(
    radar: RadarPoint, settings: AssociationSettings, road_heading_rad: float | None
) -> FusedObject | None:
    """A radar-only object, or None for clutter (too slow or too weak)."""
    moving = abs(radar.radial_speed_mps) > settings.min_radar_only_speed_mps
    if not moving or radar.rcs_dbsm < settings.min_radar_only_rcs_dbsm:
        return None
    # The echo is on the vehicle's near face: move it to the centre of a car-sized vehicle on
    # the road's heading, and widen the range variance by what the size guess cannot know (a
    # truck's centre is 8 m behind its face, a car's 2.3 m).
    x_m, y_m, covariance = radar.x_m, radar.y_m, radar.covariance_m2
    if road_heading_rad is not None:
        (x_m, y_m), half_gap = centre_from_echo(
            (x_m, y_m),
            radar.sensor_xy_m,
            road_heading_rad,
            RADAR_ONLY_LENGTH_M,
            RADAR_ONLY_WIDTH_M,
        )
        road, _ = _unit(road_heading_rad)
        covariance = (
            covariance
            + settings.radar_only_size_std_m**2 * np.outer(road, road)
            + np.outer(half_gap, half_gap)
        )
    return FusedObject(
        source="radar",
        x_m=x_m,
        y_m=y_m,
        covariance_m2=covariance,
        object_class=VehicleClass.UNKNOWN,
        score=settings.radar_only_score,
        speed_mps=along_road_speed(radar, road_heading_rad, settings.min_speed_cosine),
        camera_local_id=None,
        radar_target_index=radar.target_index,
    )


def fuse_camera_radar(
    camera_objects: Sequence[CameraObject],
    scan: RadarScan,
    mount: SensorMount,
    settings: AssociationSettings | None = None,
    road_heading_rad: float | None = None,
    dt_s: float = 0.0,
) -> list[FusedObject]:
    """Associate and fuse one frame's camera objects with one radar scan (all steps).

    Parameters
    ----------
    camera_objects : sequence of CameraObject, length C
        Site-frame ground positions with covariance.
    scan : RadarScan
        The radar scan nearest in time (no motion compensation here).
    mount : SensorMount
        The radar's mount.
    settings : AssociationSettings or None
        Defaults when None.
    road_heading_rad : float or None
        Direction of travel at the site [rad], CCW from east; None for ``|v_r|`` speeds.
    dt_s : float
        Camera frame time minus scan time [s]; radar ranges are carried to the frame's time
        with their radial speeds (see :func:`fuse_pair`). Gating uses the scan as it is.

    Returns
    -------
    list of FusedObject
        Fused pairs (by camera index), then camera-only objects (by camera index), then
        radar-only objects (by target index). Every camera object appears exactly once; each
        radar target at most once.

    Raises
    ------
    ValueError
        If ``mount`` is not a radar.
    """
    settings = settings or AssociationSettings()
    radar_points = radar_targets_to_site(scan.targets, mount, settings)
    radar_xy = (mount.pose.x_m, mount.pose.y_m)
    echoes = [expected_echo(camera, radar_xy) for camera in camera_objects]
    distances_sq = gate_distances(
        echoes, radar_points, settings.reflection_extent_std_m, settings.reflection_width_std_m
    )
    pairs = associate(distances_sq, settings.gate_chi2, settings.ambiguity_margin_chi2)
    fused = [
        fuse_pair(camera_objects[c], radar_points[r], mount, settings, road_heading_rad, dt_s)
        for c, r in pairs
    ]
    matched_camera = {c for c, _ in pairs}
    matched_radar = {r for _, r in pairs}
    fused.extend(
        camera_only(camera)
        for index, camera in enumerate(camera_objects)
        if index not in matched_camera
    )
    for index, radar in enumerate(radar_points):
        if index in matched_radar:
            continue
        if any(_on_body(radar, c, settings.echo_on_body_margin_m) for c in camera_objects):
            continue
        radar_only = _radar_only(radar, settings, road_heading_rad)
        if radar_only is not None:
            fused.append(radar_only)
    return fused


def to_detection(obj: FusedObject) -> Detection:
    """The bus message of a fused object.

    Parameters
    ----------
    obj : FusedObject

    Returns
    -------
    Detection
        Position [m], covariance flattened row-major [m^2], class, score, speed [m/s] and the
        camera's local id as ``local_track_id`` (None for a radar-only object).
    """
    return Detection(
        x_m=obj.x_m,
        y_m=obj.y_m,
        covariance_m2=[float(value) for value in np.asarray(obj.covariance_m2).reshape(4)],
        object_class=obj.object_class,
        score=obj.score,
        speed_mps=obj.speed_mps,
        local_track_id=obj.camera_local_id,
    )
