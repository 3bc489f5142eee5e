"""Where the camera sees things: clipping in 3D and projection to OpenCV fixed-point polygons.

The pinhole geometry itself (:class:`~wz_shared.camera_geometry.PinholeCamera`) lives in the
shared library; a :class:`Projector` adds what the renderer needs on top: the near plane and a
guard band as clip planes (so fixed-point vertices stay small), per-pixel rays for exact plane
depth, and the projection of many quads at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wz_shared.arrays import F64, I32, Bool, IntP
from wz_shared.camera_geometry import PinholeCamera
from wz_simulator.sensors.camera_paint import Quads

SHIFT = 4  # fractional bits of the fixed-point vertices handed to OpenCV
ONE = float(1 << SHIFT)


def clip_polygon(polygon: F64, planes: F64) -> F64:
    """Sutherland-Hodgman clip of a convex polygon (n, 3) to half-spaces ``a . p + d >= 0``.

    ``planes`` is (P, 4) rows (a_x, a_y, a_z, d). Returns (m, 3), m = 0 when nothing is left.
    """
    points = polygon
    for plane in planes:
        if points.shape[0] == 0:
            break
        dist = points @ plane[:3] + plane[3]
        inside = dist >= 0.0
        if inside.all():
            continue
        if not inside.any():
            return np.zeros((0, 3))
        out: list[F64] = []
        count = points.shape[0]
        for i in range(count):
            j = (i + 1) % count
            if inside[i]:
                out.append(points[i])
            if inside[i] != inside[j]:
                t = dist[i] / (dist[i] - dist[j])
                out.append(points[i] + t * (points[j] - points[i]))
        points = np.array(out) if out else np.zeros((0, 3))
    return points


@dataclass(frozen=True)
class Projected:
    """Quads as OpenCV fixed-point polygons (pixel-centre origin), or None where nothing shows."""

    polygons: list[I32 | None]
    bounds: I32  # (Q, 4) x0, y0, x1, y1 pixel indices (inclusive), meaningless where None


class Projector:
    """Clips and projects site-frame polygons for one camera.

    Parameters
    ----------
    camera
        The ideal pinhole camera.
    near_m
        Near clipping plane [m].
    """

    def __init__(self, camera: PinholeCamera, near_m: float) -> None:
        self.camera = camera
        cam = camera
        width, height = cam.width_px, cam.height_px
        f, fy, cx, cy = cam.focal_px, cam.focal_y_px, cam.cx_px, cam.cy_px
        # Clip planes in the optical frame (a . p + d >= 0): near plane, then a guard band of
        # one image size around the image so fixed-point vertices stay small.
        u_min, u_max, v_min, v_max = -width, 2.0 * width, -height, 2.0 * height
        self.clip_planes = np.array(
            [
                [0.0, 0.0, 1.0, -near_m],
                [f, 0.0, cx - u_min, 0.0],
                [-f, 0.0, u_max - cx, 0.0],
                [0.0, fy, cy - v_min, 0.0],
                [0.0, -fy, v_max - cy, 0.0],
            ]
        )
        # Per-pixel rays (unit optical depth) at pixel centres.
        self.ray_x = ((np.arange(width) + 0.5 - cx) / f).astype(np.float32)
        self.ray_y = ((np.arange(height) + 0.5 - cy) / fy).astype(np.float32)

    def project_quads(self, quads_site: F64, drawable: Bool) -> Projected:
        """Clip (in 3D, where needed) and project quads (Q, 4, 3) to fixed-point polygons."""
        cam = self.camera
        width, height = cam.width_px, cam.height_px
        camera = self.camera.site_to_camera(quads_site)  # (Q, 4, 3)
        z = camera[..., 2]
        planes = self.clip_planes
        # a . p + d for every plane and vertex: clean quads need no clipping.
        plane_dist = camera @ planes[:, :3].T + planes[:, 3]  # (Q, 4, P)
        clean = (plane_dist >= 0.0).all(axis=(1, 2))
        safe_z = np.where(clean[:, None], z, 1.0)
        u = cam.cx_px + cam.focal_px * camera[..., 0] / safe_z
        v = cam.cy_px + cam.focal_y_px * camera[..., 1] / safe_z
        # Whole quads off one side of the image show nothing.
        offscreen = (
            (u.max(axis=1) < 0)
            | (u.min(axis=1) > width)
            | (v.max(axis=1) < 0)
            | (v.min(axis=1) > height)
        )
        fixed = np.empty((*u.shape, 2), dtype=np.int32)
        fixed[..., 0] = np.rint((u - 0.5) * ONE)
        fixed[..., 1] = np.rint((v - 0.5) * ONE)
        bounds = np.empty((quads_site.shape[0], 4), dtype=np.int32)
        bounds[:, 0] = np.floor(u.min(axis=1) - 0.5)
        bounds[:, 1] = np.floor(v.min(axis=1) - 0.5)
        bounds[:, 2] = np.ceil(u.max(axis=1) - 0.5)
        bounds[:, 3] = np.ceil(v.max(axis=1) - 0.5)
        show = drawable & clean & ~offscreen
        polygons: list[I32 | None] = [None] * quads_site.shape[0]
        for q in np.flatnonzero(show).tolist():
            polygons[q] = fixed[q]
        # Quads crossing the near plane or the guard band: clip in 3D, then project.
        fully_out = (plane_dist < 0.0).all(axis=1).any(axis=1)
        for q in np.flatnonzero(drawable & ~clean & ~fully_out).tolist():
            clipped = clip_polygon(camera[q], planes)
            if clipped.shape[0] < 3:
                continue
            uq = cam.cx_px + cam.focal_px * clipped[:, 0] / clipped[:, 2]
            vq = cam.cy_px + cam.focal_y_px * clipped[:, 1] / clipped[:, 2]
            if uq.max() < 0 or uq.min() > width or vq.max() < 0 or vq.min() > height:
                continue
            pts = np.empty((uq.size, 2), dtype=np.int32)
            pts[:, 0] = np.rint((uq - 0.5) * ONE)
            pts[:, 1] = np.rint((vq - 0.5) * ONE)
            polygons[q] = pts
            bounds[q] = (
                math.floor(uq.min() - 0.5),
                math.floor(vq.min() - 0.5),
                math.ceil(uq.max() - 0.5),
                math.ceil(vq.max() - 0.5),
            )
        np.clip(bounds[:, 0::2], 0, width - 1, out=bounds[:, 0::2])
        np.clip(bounds[:, 1::2], 0, height - 1, out=bounds[:, 1::2])
        return Projected(polygons, bounds)

    def front_facing(self, quads: Quads) -> Bool:
        centroid = quads.site.mean(axis=1)
        facing: Bool = np.einsum("qi,qi->q", centroid - self.camera.position_m, quads.normal) < 0.0
        return facing

    def range_to(self, points_site: F64) -> F64:
        distance: F64 = np.linalg.norm(points_site - self.camera.position_m, axis=-1)
        return distance

    def face_planes(self, quads_site: F64, normals: F64) -> tuple[F64, F64]:
        """Planes ``n . p = c`` of faces in the optical frame: n (F, 3), c (F,)."""
        normal_cam = normals @ self.camera.rotation_site_from_camera
        offset = np.einsum("fi,fi->f", normal_cam, self.camera.site_to_camera(quads_site[:, 0]))
        return normal_cam, offset

    def plane_depth(self, normal_cam: F64, offset: F64, rows: IntP, cols: IntP) -> F64:
        """Optical depth of planes at pixel centres: ``z = c / (n . r)``, r = ray of the pixel."""
        denom = (
            normal_cam[:, 0] * self.ray_x[cols]
            + normal_cam[:, 1] * self.ray_y[rows]
            + normal_cam[:, 2]
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = offset / denom
        result: F64 = np.where(denom < -1e-12, depth, np.inf)
        return result

    # --- background ---------------------------------------------------------------------------

    def project_polygon(self, polygon_site: F64) -> tuple[I32, tuple[int, int, int, int]] | None:
        """Clip a site polygon (n, 3) in 3D and project it (a concave one stays fillable).

        Returns OpenCV fixed-point vertices and the pixel bounds ``(x0, y0, x1, y1)`` (x1, y1
        exclusive, inside the image), or None when nothing of it shows.
        """
        cam = self.camera
        clipped = clip_polygon(cam.site_to_camera(polygon_site), self.clip_planes)
        if clipped.shape[0] < 3:
            return None
        u = cam.cx_px + cam.focal_px * clipped[:, 0] / clipped[:, 2]
        v = cam.cy_px + cam.focal_y_px * clipped[:, 1] / clipped[:, 2]
        x0, x1 = max(0, math.floor(u.min() - 0.5)), min(cam.width_px, math.ceil(u.max() + 0.5))
        y0, y1 = max(0, math.floor(v.min() - 0.5)), min(cam.height_px, math.ceil(v.max() + 0.5))
        if x1 <= x0 or y1 <= y0:
            return None
        pts = np.empty((u.size, 2), dtype=np.int32)
        pts[:, 0] = np.rint((u - 0.5) * ONE)
        pts[:, 1] = np.rint((v - 0.5) * ONE)
        return pts, (x0, y0, x1, y1)
