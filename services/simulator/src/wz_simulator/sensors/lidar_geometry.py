"""Geometry of the LiDAR's scene: box corners and triangles, ground polygons, the static mesh,
and the exact azimuth and elevation extents that decide which rays may meet a vehicle.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F32, F64, Bool, IntP
from wz_simulator.sensors.scene import BOX_CORNER_SIGNS, BOX_FACES, Box, GroundPolygon, Material

#: Corner indices of the 6 faces of a box (``BOX_FACES``), shape (6, 4).
BOX_FACE_CORNERS = np.array(BOX_FACES, dtype=np.intp)
#: The 12 triangles of a box (two per face of ``BOX_FACES``, in face order), as corner indices.
BOX_TRIANGLES = np.array(
    [tri for a, b, c, d in BOX_FACES for tri in ((a, b, c), (a, c, d))], dtype=np.uint32
)
TRIANGLES_PER_BOX = len(BOX_TRIANGLES)
#: The 12 edges of a box as pairs of corner indices (:meth:`Box.corners` order).
_BOX_EDGES = np.array(
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]]
)
#: Edges of the volume a box sweeps along a segment (corners 0-7 at the start, 8-15 at the end):
#: every edge of its convex hull is an edge of either box or joins a corner to its copy.
SWEPT_BOX_EDGES = np.concatenate(
    [_BOX_EDGES, _BOX_EDGES + 8, np.column_stack([np.arange(8), np.arange(8) + 8])]
)
#: Slack on interval ends (columns, radians) against float round-off in the ray culling.


def box_corners(centers_m: F64, sizes_lwh_m: F64, yaws_rad: F64) -> F64:
    """Corners of many boxes at once, in :meth:`Box.corners` order.

    Parameters
    ----------
    centers_m : ndarray, shape (n, 3)
        Box centres [m].
    sizes_lwh_m : ndarray, shape (n, 3)
        Length (along the yaw), width, height [m].
    yaws_rad : ndarray, shape (n,)
        Yaw, counter-clockwise about z [rad].

    Returns
    -------
    ndarray, shape (n, 8, 3)
    """
    local = 0.5 * sizes_lwh_m[:, None, :] * BOX_CORNER_SIGNS[None, :, :]
    cos_yaw, sin_yaw = np.cos(yaws_rad)[:, None], np.sin(yaws_rad)[:, None]
    corners = np.empty_like(local)
    corners[..., 0] = cos_yaw * local[..., 0] - sin_yaw * local[..., 1]
    corners[..., 1] = sin_yaw * local[..., 0] + cos_yaw * local[..., 1]
    corners[..., 2] = local[..., 2]
    corners += centers_m[:, None, :]
    return corners


def triangulate_polygon(vertices_xy: npt.ArrayLike) -> npt.NDArray[np.uint32]:
    """Triangulate a simple polygon by ear clipping.

    Parameters
    ----------
    vertices_xy : array_like, shape (n, 2)
        Vertices in order (either orientation; a repeated closing vertex is dropped).

    Returns
    -------
    ndarray of uint32, shape (m, 3)
        Triangles as vertex indices, counter-clockwise; collinear vertices yield no triangle.

    Raises
    ------
    ValueError
        Fewer than 3 vertices, or no ear found (a self-intersecting polygon).
    """
    points = np.asarray(vertices_xy, dtype=np.float64)
    count = len(points)
    if count >= 2 and np.allclose(points[0], points[-1]):
        count -= 1
    if count < 3:
        raise ValueError(f"a ground polygon needs at least 3 vertices, got {count}")
    x, y = points[:count, 0], points[:count, 1]
    twice_area = float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    remaining = list(range(count)) if twice_area >= 0 else list(range(count - 1, -1, -1))
    scale = float(np.ptp(points[:count], axis=0).max()) or 1.0
    eps = 1e-12 * scale * scale
    triangles: list[tuple[int, int, int]] = []
    while len(remaining) > 3:
        ring = np.asarray(remaining)
        prev_pts, cur_pts, next_pts = (
            points[np.roll(ring, 1)],
            points[ring],
            points[np.roll(ring, -1)],
        )
        edge_a, edge_b = cur_pts - prev_pts, next_pts - cur_pts
        cross = edge_a[:, 0] * edge_b[:, 1] - edge_a[:, 1] * edge_b[:, 0]
        collinear = np.flatnonzero(np.abs(cross) <= eps)
        if len(collinear):
            remaining.pop(int(collinear[0]))
            continue
        for i in np.flatnonzero(cross > eps).tolist():
            a, b, c = prev_pts[i], cur_pts[i], next_pts[i]
            others = points[np.delete(ring, [(i - 1) % len(ring), i, (i + 1) % len(ring)])]
            # Inside (or on the edge of) triangle abc: all three edge cross products >= 0.
            inside = np.ones(len(others), dtype=bool)
            for p, q in ((a, b), (b, c), (c, a)):
                inside &= (q[0] - p[0]) * (others[:, 1] - p[1]) - (q[1] - p[1]) * (
                    others[:, 0] - p[0]
                ) >= -eps
            if not inside.any():
                m = len(remaining)
                triangles.append((remaining[(i - 1) % m], remaining[i], remaining[(i + 1) % m]))
                remaining.pop(i)
                break
        else:
            raise ValueError("ground polygon has no ear: is it self-intersecting?")
    if len(remaining) == 3:
        triangles.append((remaining[0], remaining[1], remaining[2]))
    return np.asarray(triangles, dtype=np.uint32).reshape(-1, 3)


def static_mesh(
    boxes: Sequence[Box],
    ground: Sequence[GroundPolygon],
    position_m: F64,
    max_range_m: float,
    base_ground_material: Material,
) -> tuple[F32, npt.NDArray[np.uint32], IntP]:
    """Vertices (centred on ``position_m``), triangles and per-triangle material of a static
    scene, with a base ground plane under everything wide enough for every downward beam
    within ``max_range_m`` (at z = 0, or 1 cm below the lowest polygon)."""
    vertex_blocks: list[F64] = []
    triangle_blocks: list[npt.NDArray[np.uint32]] = []
    material_blocks: list[IntP] = []
    offset = 0

    def add(vertices: F64, triangles: npt.NDArray[np.uint32], material: IntP) -> None:
        nonlocal offset
        vertex_blocks.append(vertices - position_m)
        triangle_blocks.append(triangles + np.uint32(offset))
        material_blocks.append(material)
        offset += len(vertices)

    if boxes:
        centers = np.array([box.center_xyz_m for box in boxes], dtype=np.float64)
        sizes = np.array([box.size_lwh_m for box in boxes], dtype=np.float64)
        yaws = np.array([box.yaw_rad for box in boxes], dtype=np.float64)
        corners = box_corners(centers, sizes, yaws).reshape(-1, 3)
        count = len(boxes)
        triangles = (
            BOX_TRIANGLES[None, :, :]
            + np.uint32(8) * np.arange(count, dtype=np.uint32)[:, None, None]
        ).reshape(-1, 3)
        materials = np.repeat(
            np.array([int(box.material) for box in boxes], dtype=np.intp), TRIANGLES_PER_BOX
        )
        add(corners, triangles, materials)
    lowest = 0.0
    for polygon in ground:
        xy = np.asarray(polygon.vertices_xy_m, dtype=np.float64)
        triangles = triangulate_polygon(xy)
        vertices = np.column_stack([xy, np.full(len(xy), polygon.z_m)])
        add(vertices, triangles, np.full(len(triangles), int(polygon.material), np.intp))
        lowest = min(lowest, polygon.z_m - 0.01)
    # Base plane under everything, wide enough for every downward beam within range.
    half = max_range_m + 100.0
    px, py = position_m[0], position_m[1]
    plane = np.array(
        [
            [px - half, py - half, lowest],
            [px + half, py - half, lowest],
            [px + half, py + half, lowest],
            [px - half, py + half, lowest],
        ]
    )
    add(
        plane,
        np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32),
        np.full(2, int(base_ground_material), np.intp),
    )
    return (
        np.ascontiguousarray(np.concatenate(vertex_blocks), dtype=np.float32),
        np.ascontiguousarray(np.concatenate(triangle_blocks), dtype=np.uint32),
        np.concatenate(material_blocks),
    )


# --- one sweep ----------------------------------------------------------------------


def elevation_extent(corners: F64, edges: IntP) -> tuple[F64, F64]:
    """Highest and lowest elevation [rad] of any point of convex bodies, seen from the origin.

    Exact: the extremes of a body's projection on the unit sphere lie on the projections of its
    edges, great-circle arcs whose highest (lowest) point is an end or the apex (antipode) of
    their circle, when the apex lies on the arc. (A body around the vertical axis also
    covers the nadir or zenith: see :func:`azimuth_extent`.)

    Parameters
    ----------
    corners : ndarray, shape (..., n, 3)
        Corners of the bodies [m], none containing the origin.
    edges : ndarray of int, shape (e, 2)
        Pairs of corner indices, including every edge of the bodies' convex hulls.

    Returns
    -------
    top, bottom : ndarray, shape (...)
    """
    x, y, z = corners[..., 0], corners[..., 1], corners[..., 2]
    elevation = np.arctan2(z, np.hypot(x, y))
    top, bottom = elevation.max(axis=-1), elevation.min(axis=-1)
    ax, ay, az = (corners[..., edges[:, 0], i] for i in range(3))
    bx, by, bz = (corners[..., edges[:, 1], i] for i in range(3))
    # n = a x b, normal of the arc's great circle; its apex p = (-nx nz, -ny nz, nx^2 + ny^2)
    # (z projected on the circle's plane) lies on the arc a -> b iff p.(n x a) >= 0 and
    # p.(b x n) >= 0; the antipode -p iff both are <= 0.
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    horizontal2 = nx * nx + ny * ny
    px, py = -nx * nz, -ny * nz
    from_a = px * (ny * az - nz * ay) + py * (nz * ax - nx * az) + horizontal2 * (nx * ay - ny * ax)
    to_b = px * (by * nz - bz * ny) + py * (bz * nx - bx * nz) + horizontal2 * (bx * ny - by * nx)
    tilted = horizontal2 > 1e-12 * (horizontal2 + nz * nz)  # else the circle is the horizon
    apex_elevation = np.arctan2(np.sqrt(horizontal2), np.abs(nz))
    high = tilted & (from_a >= 0) & (to_b >= 0)
    low = tilted & (from_a <= 0) & (to_b <= 0)
    top = np.maximum(top, np.where(high, apex_elevation, -np.inf).max(axis=-1))
    bottom = np.minimum(bottom, np.where(low, -apex_elevation, np.inf).min(axis=-1))
    return top, bottom


def azimuth_extent(x: F64, y: F64) -> tuple[F64, F64, Bool]:
    """Azimuths [rad] met by convex bodies, from their corners' x and y, shape (..., n).

    Returns
    -------
    start, span : ndarray, shape (...)
        The azimuths met are ``[start, start + span]`` (exact: the corners' azimuths less the
        widest gap between them).
    around : ndarray of bool, shape (...)
        The body surrounds the vertical axis (no gap wider than pi): every azimuth is met.
    """
    azimuth = np.sort(np.arctan2(y, x), axis=-1)
    gaps = np.diff(azimuth, axis=-1, append=azimuth[..., :1] + 2.0 * np.pi)
    widest = gaps.argmax(axis=-1)[..., None]
    widest_gap = np.take_along_axis(gaps, widest, axis=-1)[..., 0]
    start = np.take_along_axis(azimuth, (widest + 1) % x.shape[-1], axis=-1)[..., 0]
    return start, 2.0 * np.pi - widest_gap, widest_gap <= np.pi


def centred_grid(count: int) -> F64:
    """``count`` points of a unit-spaced 3D grid, as compact as possible, centred on 0, (n, 3)."""
    side = max(1, math.ceil(count ** (1.0 / 3.0) - 1e-9))
    index = np.arange(count)
    grid = np.column_stack([index % side, (index // side) % side, index // (side * side)])
    centred: F64 = grid - 0.5 * (grid.max(axis=0) + grid.min(axis=0))
    return centred.astype(np.float64)
