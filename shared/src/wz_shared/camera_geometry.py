"""Roadside camera geometry: pinhole model with optional lens distortion, flat-road ranging.

Pure numpy, no I/O. The simulator renders with it and the camera detector ranges with it, so
neither service depends on the other for the geometry.

- :class:`PinholeCamera`: intrinsics ``K`` from the camera's calibration, else from the
  horizontal field of view and the resolution (square pixels, principal point at the image
  centre), extrinsics from the mount's pose,
  projection of site points to pixels, pixel rays, and the flat-road back-projection
  (:func:`backproject_to_ground`). An optional :class:`LensDistortion` (OpenCV's ``k1, k2, p1,
  p2, k3``) is applied in :meth:`PinholeCamera.project` and removed in
  :meth:`PinholeCamera.pixel_to_camera_ray`; without it the model is the ideal pinhole.
- The paper's Eq. 1-2 (:func:`paper_pixel_angles`, :func:`paper_flat_road_ground_point`):
  pixel to angles, then angles to a point on the flat road ``z = 0``, as published (no lens
  distortion).

Frames and pixels
-----------------
- Site frame: ENU metres. Sensor frame (the mount's pose): x forward, y left, z up.
- Camera (optical) frame: z forward along the optical axis, x right, y down;
  ``p_optical = (-y_sensor, -z_sensor, x_sensor)``.
- Normalized image coordinates: ``(x, y) = (X / Z, Y / Z)`` of an optical-frame point.
- Continuous pixel coordinates ``(u, v)``: the image spans ``[0, W] x [0, H]``, ``u`` to the
  right and ``v`` down; pixel (row ``i``, column ``j``) covers ``[j, j + 1) x [i, i + 1)`` and its
  centre is ``(j + 0.5, i + 0.5)``. The principal point is the image centre ``(W / 2, H / 2)``,
  as in the paper's Eq. 1, unless a calibration gives it (OpenCV's ``cx`` + 0.5: OpenCV puts
  the top-left pixel's centre at 0, :mod:`wz_shared.camera_calibration`).
- Depth: the optical z of a point [m] (distance along the optical axis, not the range).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64
from wz_shared.camera_calibration import ASPECT_TOLERANCE, CalibrationError
from wz_shared.sensor_mounts import intrinsics_of
from wz_shared.site import CameraIntrinsics, SensorMount

# Optical axes (columns) in the sensor frame: x_opt = -y_s, y_opt = -z_s, z_opt = x_s.
_SENSOR_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

#: Fixed-point iterations of :meth:`LensDistortion.undistort` at most (cv2.undistortPoints
#: stops after 5 by default; 20 reach 1e-6 px for moderate distortion at a 90 degree corner).
UNDISTORT_MAX_ITERATIONS = 20


def camera_intrinsics(mount: SensorMount) -> CameraIntrinsics:
    """The mount's camera intrinsics, or a ValueError naming the sensor if it is not a camera."""
    return intrinsics_of(
        mount,
        CameraIntrinsics,
        "a camera model needs camera intrinsics (width_px, height_px, horizontal_fov_deg)",
    )


@dataclass(frozen=True, slots=True)
class LensDistortion:
    """Brown-Conrady lens distortion in OpenCV's convention (``distCoeffs = k1, k2, p1, p2, k3``).

    On normalized image coordinates ``(x, y)``, with ``r^2 = x^2 + y^2``::

        radial = 1 + k1 r^2 + k2 r^4 + k3 r^6
        x_d = x radial + 2 p1 x y + p2 (r^2 + 2 x^2)
        y_d = y radial + p1 (r^2 + 2 y^2) + 2 p2 x y

    All coefficients zero is the identity, exactly.

    Attributes
    ----------
    k1, k2, k3
        Radial coefficients [-] (k1 < 0: barrel).
    p1, p2
        Tangential (decentering) coefficients [-].
    """

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    @property
    def coefficients(self) -> F64:
        """``(k1, k2, p1, p2, k3)`` as OpenCV's ``distCoeffs``, shape (5,)."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])

    def _radial_and_tangential(self, xy: F64) -> tuple[F64, F64, F64]:
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        delta_x = 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x)
        delta_y = self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y
        return radial, delta_x, delta_y

    def distort(self, xy_normalized: npt.ArrayLike) -> F64:
        """Ideal normalized coordinates to distorted ones.

        Parameters
        ----------
        xy_normalized
            Undistorted ``(x, y) = (X / Z, Y / Z)``, shape (N, 2).

        Returns
        -------
        ndarray, shape (N, 2)
            Distorted normalized coordinates ``(x_d, y_d)``.
        """
        xy = np.atleast_2d(np.asarray(xy_normalized, dtype=np.float64))
        radial, delta_x, delta_y = self._radial_and_tangential(xy)
        distorted = np.empty_like(xy)
        distorted[:, 0] = xy[:, 0] * radial + delta_x
        distorted[:, 1] = xy[:, 1] * radial + delta_y
        return distorted

    def undistort(
        self,
        xy_distorted: npt.ArrayLike,
        max_iterations: int = UNDISTORT_MAX_ITERATIONS,
        tolerance: float = 1e-14,
    ) -> F64:
        """Invert :meth:`distort` by fixed-point iteration, as ``cv2.undistortPoints`` does.

        ``x <- (x_d - delta_x(x)) / radial(x)``, starting from ``x = x_d``, until the largest
        update is below ``tolerance`` or after ``max_iterations``. It converges where the
        distortion is monotonic in the radius (moderate coefficients, inside the image).

        Parameters
        ----------
        xy_distorted
            Distorted normalized coordinates, shape (N, 2).
        max_iterations
            Iterations at most.
        tolerance
            Stop when no coordinate moves more than this [normalized units].

        Returns
        -------
        ndarray, shape (N, 2)
            Undistorted normalized coordinates.
        """
        distorted = np.atleast_2d(np.asarray(xy_distorted, dtype=np.float64))
        xy = distorted.copy()
        for _ in range(max_iterations):
            radial, delta_x, delta_y = self._radial_and_tangential(xy)
            updated = np.empty_like(xy)
            updated[:, 0] = (distorted[:, 0] - delta_x) / radial
            updated[:, 1] = (distorted[:, 1] - delta_y) / radial
            step = float(np.nanmax(np.abs(updated - xy))) if xy.size else 0.0
            xy = updated
            if step < tolerance:
                break
        return xy


class PinholeCamera:
    """Pinhole camera on a fixed mount, with optional lens distortion.

    Intrinsics: a calibrated camera's own focal lengths ``fx, fy`` and principal point
    ``cx, cy`` (:class:`~wz_shared.site.CameraIntrinsics` read from its calibration file); else,
    with ``W, H`` the resolution and ``alpha`` the horizontal field of view, square pixels and
    the principal point at the image's centre::

        f = (W / 2) / tan(alpha / 2)   [px]       K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]

    Extrinsics: ``p_camera = R^T (p_site - C)`` with ``C`` the mount position and ``R`` the
    rotation from the optical frame to the site frame. Pixels: ``u = cx + fx x_d``,
    ``v = cy + fy y_d`` with ``(x_d, y_d)`` the distorted normalized coordinates
    (:class:`LensDistortion`), equal to ``(X / Z, Y / Z)`` without distortion.

    Parameters
    ----------
    mount
        A sensor mount with :class:`~wz_shared.site.CameraIntrinsics`.
    distortion
        Lens distortion; None (the default) takes the intrinsics' calibrated distortion, and
        without one the ideal pinhole.
    """

    def __init__(self, mount: SensorMount, distortion: LensDistortion | None = None) -> None:
        intrinsics = camera_intrinsics(mount)
        self.mount = mount
        if distortion is None and intrinsics.distortion is not None:
            distortion = LensDistortion(*intrinsics.distortion)
        #: Lens distortion, None for the ideal pinhole (all-zero coefficients are stored as None,
        #: so that they reproduce the ideal pinhole bit for bit).
        self.distortion = None if distortion == LensDistortion() else distortion
        self.width_px = intrinsics.width_px
        self.height_px = intrinsics.height_px
        half_fov = math.radians(intrinsics.horizontal_fov_deg) / 2.0
        square_focal_px = (self.width_px / 2.0) / math.tan(half_fov)
        #: Horizontal focal length [px] (``fx``).
        self.focal_px = intrinsics.fx_px if intrinsics.fx_px is not None else square_focal_px
        #: Vertical focal length [px] (``fy``; equal to ``fx`` for square pixels).
        self.focal_y_px = intrinsics.fy_px if intrinsics.fy_px is not None else square_focal_px
        self.cx_px = intrinsics.cx_px if intrinsics.cx_px is not None else self.width_px / 2.0
        self.cy_px = intrinsics.cy_px if intrinsics.cy_px is not None else self.height_px / 2.0
        #: Intrinsic matrix, shape (3, 3).
        self.K = np.array(
            [
                [self.focal_px, 0.0, self.cx_px],
                [0.0, self.focal_y_px, self.cy_px],
                [0.0, 0.0, 1.0],
            ]
        )
        #: Vertical field of view [deg] (ignoring distortion and an off-centre principal point).
        self.vertical_fov_deg = math.degrees(
            2.0 * math.atan(self.height_px / 2.0 / self.focal_y_px)
        )
        pose = mount.pose
        #: Camera centre C in the site frame [m], shape (3,).
        self.position_m = np.array([pose.x_m, pose.y_m, pose.z_m])
        #: Rotation from the optical frame to the site frame, shape (3, 3).
        self.rotation_site_from_camera: F64 = pose.rotation() @ _SENSOR_FROM_OPTICAL

    def site_to_camera(self, points_site_m: npt.ArrayLike) -> F64:
        """Site points [m], shape (..., 3), to the optical frame [m], shape (..., 3)."""
        points = np.asarray(points_site_m, dtype=np.float64)
        camera: F64 = (points - self.position_m) @ self.rotation_site_from_camera
        return camera

    def camera_to_site(self, points_camera_m: npt.ArrayLike) -> F64:
        """Optical-frame points [m], shape (..., 3), to the site frame [m], shape (..., 3)."""
        points = np.asarray(points_camera_m, dtype=np.float64)
        site: F64 = points @ self.rotation_site_from_camera.T + self.position_m
        return site

    def distort(self, xy_normalized: npt.ArrayLike) -> F64:
        """Apply the lens distortion to normalized coordinates, shape (N, 2) (identity if none)."""
        xy = np.atleast_2d(np.asarray(xy_normalized, dtype=np.float64))
        return xy.copy() if self.distortion is None else self.distortion.distort(xy)

    def undistort(self, xy_distorted: npt.ArrayLike) -> F64:
        """Remove the lens distortion iteratively, shape (N, 2), see :meth:`LensDistortion.undistort`."""
        xy = np.atleast_2d(np.asarray(xy_distorted, dtype=np.float64))
        return xy.copy() if self.distortion is None else self.distortion.undistort(xy)

    def project(self, points_site_m: npt.ArrayLike) -> tuple[F64, F64]:
        """Project site points to pixels.

        ``u = cx + fx x_d``, ``v = cy + fy y_d`` with ``(x_d, y_d)`` the distorted ``(X / Z, Y / Z)``
        of the optical-frame point ``(X, Y, Z)``.

        Parameters
        ----------
        points_site_m
            Points in the site frame [m], shape (N, 3).

        Returns
        -------
        uv_px
            Continuous pixel coordinates, shape (N, 2); NaN for points not in front of the camera
            (depth <= 0). Points outside the image are not clipped.
        depth_m
            Optical depth Z [m], shape (N,); <= 0 behind the camera.
        """
        camera = self.site_to_camera(np.atleast_2d(np.asarray(points_site_m, dtype=np.float64)))
        depth = camera[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(depth > 0.0, 1.0 / np.where(depth > 0.0, depth, 1.0), np.nan)
        uv = np.empty((camera.shape[0], 2))
        if self.distortion is None:
            uv[:, 0] = self.cx_px + self.focal_px * camera[:, 0] * inv
            uv[:, 1] = self.cy_px + self.focal_y_px * camera[:, 1] * inv
        else:
            distorted = self.distortion.distort(camera[:, :2] * inv[:, None])
            uv[:, 0] = self.cx_px + self.focal_px * distorted[:, 0]
            uv[:, 1] = self.cy_px + self.focal_y_px * distorted[:, 1]
        return uv, depth.copy()

    def pixel_to_camera_ray(self, uv_px: npt.ArrayLike) -> F64:
        """Optical-frame rays ``(x, y, 1)`` (unit depth) through pixels, shape (N, 3).

        ``(x, y)`` are the undistorted normalized coordinates of ``((u - cx) / fx, (v - cy) / fy)``.
        """
        uv = np.atleast_2d(np.asarray(uv_px, dtype=np.float64))
        rays = np.ones((uv.shape[0], 3))
        rays[:, 0] = (uv[:, 0] - self.cx_px) / self.focal_px
        rays[:, 1] = (uv[:, 1] - self.cy_px) / self.focal_y_px
        if self.distortion is not None:
            rays[:, :2] = self.distortion.undistort(rays[:, :2])
        return rays

    def pixel_to_ray(self, uv_px: npt.ArrayLike) -> F64:
        """Unit viewing directions in the site frame through pixels.

        Parameters
        ----------
        uv_px
            Continuous pixel coordinates, shape (N, 2).

        Returns
        -------
        ndarray, shape (N, 3)
            Unit vectors from the camera centre :attr:`position_m` through each pixel.
        """
        rays = self.pixel_to_camera_ray(uv_px) @ self.rotation_site_from_camera.T
        unit: F64 = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        return unit

    def ground_point(self, uv_px: npt.ArrayLike, ground_z_m: float = 0.0) -> F64:
        """Flat-road back-projection, see :func:`backproject_to_ground`."""
        return backproject_to_ground(self, uv_px, ground_z_m)


def camera_at_size(mount: SensorMount, width_px: int, height_px: int) -> PinholeCamera:
    """The mount's camera for frames of another size: the same picture, scaled.

    A camera that streams a smaller (or larger) picture of its sensor keeps the aspect ratio;
    the focal lengths and the principal point scale with the size, the field of view and the
    distortion (on normalized coordinates) stay.

    Raises
    ------
    CalibrationError
        A frame whose aspect ratio differs from the mount's by more than
        :data:`~wz_shared.camera_calibration.ASPECT_TOLERANCE` (a cropped stream, or another
        camera): ranging from it with this mount's model would be wrong. It is a ValueError;
        the message says which sizes and what to do.
    """
    intrinsics = camera_intrinsics(mount)
    if (intrinsics.width_px, intrinsics.height_px) == (width_px, height_px):
        return PinholeCamera(mount)
    scale_x = width_px / intrinsics.width_px
    scale_y = height_px / intrinsics.height_px
    if abs(scale_y / scale_x - 1.0) > ASPECT_TOLERANCE:
        raise CalibrationError(
            f"camera {mount.sensor_id}: a {width_px}x{height_px} frame does not fit the "
            f"calibration made at {intrinsics.width_px}x{intrinsics.height_px}: the aspect ratio "
            "differs (a cropped stream or another camera); calibrate the camera at this "
            "resolution"
        )
    update: dict[str, object] = {"width_px": width_px, "height_px": height_px}
    fx, fy, cx, cy = intrinsics.fx_px, intrinsics.fy_px, intrinsics.cx_px, intrinsics.cy_px
    if fx is not None and fy is not None and cx is not None and cy is not None:
        update |= {
            "fx_px": fx * scale_x,
            "fy_px": fy * scale_y,
            "cx_px": cx * scale_x,
            "cy_px": cy * scale_y,
        }
    return PinholeCamera(
        mount.model_copy(update={"intrinsics": intrinsics.model_copy(update=update)})
    )


def backproject_to_ground(
    camera: PinholeCamera, uv_px: npt.ArrayLike, ground_z_m: float = 0.0
) -> F64:
    """Intersect pixel rays with the flat road ``z = ground_z_m`` (full pinhole model).

    ``p = C + t d`` with ``d`` the pixel's ray and ``t = (ground_z - C_z) / d_z``.

    Parameters
    ----------
    camera
        The camera.
    uv_px
        Continuous pixel coordinates, shape (N, 2).
    ground_z_m
        Height of the road plane in the site frame [m].

    Returns
    -------
    ndarray, shape (N, 3)
        Ground points in the site frame [m]; NaN rows where the ray does not descend to the
        road in front of the camera (at or above the horizon).
    """
    rays = camera.pixel_to_ray(uv_px)
    drop = ground_z_m - camera.position_m[2]
    descending = rays[:, 2] < -1e-12
    scale = drop / np.where(descending, rays[:, 2], -1.0)
    valid = descending & (scale > 0.0)
    scale = np.where(valid, scale, 0.0)
    points: F64 = camera.position_m + scale[:, None] * rays
    points[~valid] = np.nan
    return points


def paper_pixel_angles(
    uv_px: npt.ArrayLike, intrinsics: CameraIntrinsics, tilt_rad: float
) -> tuple[F64, F64]:
    """Paper's Eq. 1 on both image axes: pixel to angles from the optical axis.

    ``x_phi = atan((W - 2 u) / W * tan(alpha_h / 2))`` (left positive) and
    ``y_phi = atan((H - 2 v) / H * tan(alpha_v / 2)) + theta`` (up positive), with ``theta`` the
    camera tilt (the pose's pitch, negative looking down) and ``tan(alpha_v / 2) =
    H / W * tan(alpha_h / 2)`` for square pixels. ``x_phi`` is the angle in the image's
    horizontal plane, before the camera's yaw (added after Eq. 2 as a rotation).

    Parameters
    ----------
    uv_px
        Continuous pixel coordinates, shape (N, 2).
    intrinsics
        Resolution and horizontal field of view.
    tilt_rad
        Camera tilt theta [rad], positive nose-up.

    Returns
    -------
    x_phi_rad, y_phi_rad
        Shape (N,) each [rad].
    """
    uv = np.atleast_2d(np.asarray(uv_px, dtype=np.float64))
    width, height = float(intrinsics.width_px), float(intrinsics.height_px)
    tan_half_h = math.tan(math.radians(intrinsics.horizontal_fov_deg) / 2.0)
    tan_half_v = height / width * tan_half_h
    x_phi = np.arctan((width - 2.0 * uv[:, 0]) / width * tan_half_h)
    y_phi = np.arctan((height - 2.0 * uv[:, 1]) / height * tan_half_v) + tilt_rad
    return x_phi, y_phi


def paper_flat_road_ground_point(mount: SensorMount, uv_px: npt.ArrayLike) -> F64:
    """Paper's Eq. 1-2: pixel to a point on the flat road ``z = 0`` from angles alone.

    With ``h`` the camera height, ``(x_phi, y_phi)`` from Eq. 1, ``omega = -y_phi`` the
    depression of the ray below the horizon and ``y_phi - theta`` the row's angle from the axis::

        forward = h / tan(omega)
        lateral = h / sin(omega) * tan(x_phi) * cos(y_phi - theta)        (Eq. 2, left positive)

    then rotated by the camera's yaw and shifted to its position. For zero roll this is exact
    (it equals :func:`backproject_to_ground` without distortion); with roll it is the paper's
    approximation. The paper's camera has no lens distortion, so none is removed here.

    Parameters
    ----------
    mount
        A camera mount (pose and intrinsics).
    uv_px
        Continuous pixel coordinates, shape (N, 2).

    Returns
    -------
    ndarray, shape (N, 3)
        Ground points in the site frame [m] (z = 0); NaN rows at or above the horizon.
    """
    intrinsics = camera_intrinsics(mount)
    pose = mount.pose
    tilt = math.radians(pose.pitch_deg)
    x_phi, y_phi = paper_pixel_angles(uv_px, intrinsics, tilt)
    omega = -y_phi
    valid = omega > 1e-9
    safe_omega = np.where(valid, omega, 1.0)
    forward = pose.z_m / np.tan(safe_omega)
    lateral = pose.z_m / np.sin(safe_omega) * np.tan(x_phi) * np.cos(y_phi - tilt)
    yaw = math.radians(pose.yaw_deg)
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    points = np.zeros((x_phi.shape[0], 3))
    points[:, 0] = pose.x_m + forward * cos_yaw - lateral * sin_yaw
    points[:, 1] = pose.y_m + forward * sin_yaw + lateral * cos_yaw
    points[~valid] = np.nan
    return points
