"""Road-frame and WGS84 geometry of a site: pure numpy and pyproj, no I/O.

Frames (see docs/architecture.md, "Frames of reference and time")
-----------------------------------------------------------------
- Site frame: local ENU metres (x east, y north, z up) at the site's WGS84 origin.
- Road frame: station ``s`` [m] along the centerline polyline, in the order of its vertices, and
  offset ``d`` [m] from it, positive to the left of the direction of travel.

Why not a nearest-segment projection
------------------------------------
Projecting a point on its nearest segment leaves a wedge-shaped gap on the outside of every vertex
of a curve (no segment's perpendicular reaches it) and an overlap on the inside (two segments'
perpendiculars reach it), so ``(x, y) -> (s, d) -> (x, y)`` fails by centimetres to metres there.
:class:`RoadFrame` instead gives every vertex a unit normal (the normalised mean of its two
segments' left normals) and lets the normal vary linearly along each segment:

.. math::

    p(u) = P_i + u (P_{i+1} - P_i), \\qquad n(u) = N_i + u (N_{i+1} - N_i), \\qquad u \\in [0, 1]

    (x, y) = p(u) + d \\, n(u) / |n(u)|, \\qquad s = s_i + u \\, |P_{i+1} - P_i|

The normal lines then sweep the plane continuously across vertices, and the map is smooth and
invertible within a tube around the line whose radius is about the local radius of curvature. On a
polyline sampled from a circle every vertex normal points at the centre, so every normal line of
the polyline passes through it: offsets are radial, as on the true arc. Beyond either end the
frame extrapolates along the end segment with its normal held fixed (``s < 0`` or
``s > length_m``).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from pyproj import Transformer

from wz_shared.arrays import F64

# Tolerance on the segment parameter u when accepting a root at a segment's end: a point on the
# normal line through a vertex is found by both segments, and rounding must not lose it.
_U_TOLERANCE = 1e-9
# Largest turn between two consecutive segments the road frame accepts [deg]: beyond it the mean
# normal at the vertex is ill-conditioned and the tube of invertibility shrinks to nothing.
MAX_VERTEX_TURN_DEG = 150.0
# Points per batch of the exhaustive search = this / number of segments: keeps temporaries in
# cache.
_CHUNK_ELEMENTS = 1 << 14
# Points within this distance of the centerline [m] are resolved by the grid search of to_road;
# farther points take the exhaustive search.
GRID_REACH_M = 40.0
# Side of a grid cell [m], unless the site is so large that there would be too many cells.
_GRID_CELL_M = 10.0
_GRID_MAX_CELLS = 1 << 18
# Points per batch of the grid search: keeps temporaries in cache.
_GRID_CHUNK_POINTS = 2048


def polar_covariance(
    bearing_rad: float,
    range_variance_m2: float,
    lateral_variance_m2: float,
    min_variance_m2: float = 1e-6,
) -> F64:
    """A position seen along a line of sight at ``bearing_rad`` (CCW from the site x axis):
    ``sigma_rho^2 u u^T + sigma_lat^2 n n^T`` [m^2], shape (2, 2), with ``u`` the line of sight,
    ``n`` its left normal, and each variance at least ``min_variance_m2``."""
    cos_b, sin_b = math.cos(bearing_rad), math.sin(bearing_rad)
    u, n = np.array([cos_b, sin_b]), np.array([-sin_b, cos_b])
    covariance: F64 = max(range_variance_m2, min_variance_m2) * np.outer(u, u) + max(
        lateral_variance_m2, min_variance_m2
    ) * np.outer(n, n)
    return covariance


class RoadFrame:
    """Station/offset coordinates along a centerline polyline.

    Parameters
    ----------
    centerline_xy_m : array_like, shape (N, 2)
        Vertices of the centerline in the site frame [m], N >= 2, in the direction of travel.
        Consecutive vertices must be distinct and turn by less than ``MAX_VERTEX_TURN_DEG``.

    Raises
    ------
    ValueError
        If the polyline has the wrong shape, non-finite values, coincident vertices or a turn
        sharper than ``MAX_VERTEX_TURN_DEG``.

    Notes
    -----
    ``to_road`` and ``to_site`` are inverse to each other (to rounding, about 1e-12 m) for offsets
    smaller than the local radius of curvature, e.g. |d| <= 30 m on curves of radius >= 100 m with
    vertices up to 25 m apart. Where several (s, d) map to one point (inside a curve beyond its
    centre, or where the road passes near itself) ``to_road`` returns the one with the smallest
    |d|.
    """

    def __init__(self, centerline_xy_m: npt.ArrayLike) -> None:
        vertices = np.array(centerline_xy_m, dtype=np.float64)
        if vertices.ndim != 2 or vertices.shape[0] < 2 or vertices.shape[1] != 2:
            raise ValueError(
                f"a centerline needs an (N, 2) array of N >= 2 vertices, got shape {vertices.shape}"
            )
        if not np.all(np.isfinite(vertices)):
            raise ValueError("centerline vertices must be finite numbers")
        deltas = np.diff(vertices, axis=0)
        lengths = np.hypot(deltas[:, 0], deltas[:, 1])
        short = np.flatnonzero(lengths < 1e-6)
        if short.size:
            i = int(short[0])
            raise ValueError(f"centerline vertices {i} and {i + 1} coincide")
        tangents = deltas / lengths[:, None]
        segment_normals = np.stack([-tangents[:, 1], tangents[:, 0]], axis=1)
        cos_turn = np.sum(tangents[:-1] * tangents[1:], axis=1)
        sharp = np.flatnonzero(cos_turn < np.cos(np.radians(MAX_VERTEX_TURN_DEG)))
        if sharp.size:
            i = int(sharp[0]) + 1
            turn = float(np.degrees(np.arccos(np.clip(cos_turn[i - 1], -1.0, 1.0))))
            raise ValueError(
                f"the centerline turns by {turn:.1f} deg at vertex {i}; at most "
                f"{MAX_VERTEX_TURN_DEG:.0f} deg is allowed between consecutive segments"
            )
        vertex_normals = np.empty_like(vertices)
        vertex_normals[0] = segment_normals[0]
        vertex_normals[-1] = segment_normals[-1]
        mean_normals = segment_normals[:-1] + segment_normals[1:]
        vertex_normals[1:-1] = (
            mean_normals / np.hypot(mean_normals[:, 0], mean_normals[:, 1])[:, None]
        )

        self._vertices = vertices
        self._deltas = deltas
        self._lengths = lengths
        self._vertex_normals = vertex_normals
        self._normal_deltas = np.diff(vertex_normals, axis=0)
        self._stations = np.concatenate([[0.0], np.cumsum(lengths)])
        cross_d_b = (
            deltas[:, 0] * self._normal_deltas[:, 1] - deltas[:, 1] * self._normal_deltas[:, 0]
        )
        cross_d_a = deltas[:, 0] * vertex_normals[:-1, 1] - deltas[:, 1] * vertex_normals[:-1, 0]
        # Per-segment constants of the foot equation, shape (10, segments), gathered by _solve.
        self._segment_columns = np.ascontiguousarray(
            np.column_stack(
                [
                    vertices[:-1],
                    deltas,
                    vertex_normals[:-1],
                    self._normal_deltas,
                    -cross_d_b,
                    cross_d_a,
                ]
            ).T
        )
        for array in (self._vertices, self._stations):
            array.flags.writeable = False
        self._build_grid()

    # --- properties ------------------------------------------------------------------------

    @property
    def vertices_xy_m(self) -> F64:
        """Centerline vertices in the site frame [m], shape (N, 2), read-only."""
        return self._vertices

    @property
    def vertex_stations_m(self) -> F64:
        """Station of each vertex [m], shape (N,), read-only; the first is 0."""
        return self._stations

    @property
    def length_m(self) -> float:
        """Length of the centerline polyline [m]."""
        return float(self._stations[-1])

    @property
    def segment_count(self) -> int:
        """Number of segments, N - 1."""
        return int(self._lengths.size)

    # --- road -> site ----------------------------------------------------------------------

    def _locate(self, station_m: F64) -> tuple[npt.NDArray[np.intp], F64]:
        """Segment index and parameter u of each station; u < 0 or u > 1 beyond the ends."""
        segment = np.searchsorted(self._stations, station_m, side="right") - 1
        segment = np.clip(segment, 0, self.segment_count - 1)
        u = (station_m - self._stations[segment]) / self._lengths[segment]
        return segment, u

    def _unit_normal(self, segment: npt.NDArray[np.intp], u: F64) -> F64:
        """Interpolated unit normal, shape (..., 2); held fixed beyond the ends."""
        u_clamped = np.clip(u, 0.0, 1.0)[..., None]
        normal = self._vertex_normals[segment] + u_clamped * self._normal_deltas[segment]
        normal_length: F64 = np.hypot(normal[..., 0], normal[..., 1])[..., None]
        return normal / normal_length

    def normal_at(self, station_m: npt.ArrayLike) -> F64:
        """Unit left normal of the road frame at each station.

        Parameters
        ----------
        station_m : array_like, shape (...)
            Stations [m].

        Returns
        -------
        ndarray, shape (..., 2)
            Unit vector in the site frame, pointing to the left of the direction of travel; it
            turns continuously through vertices (linear interpolation of the vertex normals).
        """
        station = np.asarray(station_m, dtype=np.float64)
        segment, u = self._locate(station)
        return self._unit_normal(segment, u)

    def tangent_at(self, station_m: npt.ArrayLike) -> F64:
        """Unit tangent of the road frame (direction of travel) at each station, shape (..., 2).

        The tangent is the normal of :meth:`normal_at` turned 90 deg clockwise, so it is
        continuous through vertices; at a vertex of a polyline sampled from a circle it is the
        circle's tangent there.
        """
        normal = self.normal_at(station_m)
        return np.stack([normal[..., 1], -normal[..., 0]], axis=-1)

    def heading_at_point(self, x_m: float, y_m: float) -> float:
        """Heading of the direction of travel [rad] at the station of the site point (x, y)."""
        station, _ = self.to_road(x_m, y_m)
        return float(np.asarray(self.heading_at(station)).reshape(-1)[0])

    def heading_at(self, station_m: npt.ArrayLike) -> F64:
        """Heading of the direction of travel at each station.

        Parameters
        ----------
        station_m : array_like, shape (...)
            Stations [m].

        Returns
        -------
        ndarray, shape (...)
            Heading [rad] counter-clockwise from the site +x axis (east), in (-pi, pi].

        Notes
        -----
        This is the heading of the frame's tangent (:meth:`tangent_at`), continuous along the
        road, not of the polyline segment: the two agree on straight runs and at mid-segment of
        a uniform curve, and differ by half the vertex's turn at a vertex (0.5 deg for 25 m
        vertices on a 1500 m curve), where the frame's heading is the smoother estimate.
        """
        tangent = self.tangent_at(station_m)
        heading: F64 = np.arctan2(tangent[..., 1], tangent[..., 0])
        return heading

    def to_site(self, station_m: npt.ArrayLike, offset_m: npt.ArrayLike) -> tuple[F64, F64]:
        """Road frame to site frame.

        Parameters
        ----------
        station_m, offset_m : array_like, broadcastable, shape (...)
            Station s [m] and offset d [m] (left positive).

        Returns
        -------
        x_m, y_m : ndarray, shape (...)
            Site-frame position [m]: ``p(u) + d n(u) / |n(u)|``.
        """
        station, offset = np.broadcast_arrays(
            np.asarray(station_m, dtype=np.float64), np.asarray(offset_m, dtype=np.float64)
        )
        segment, u = self._locate(station)
        normal = self._unit_normal(segment, u)
        base = self._vertices[segment] + u[..., None] * self._deltas[segment]
        xy = base + offset[..., None] * normal
        return xy[..., 0], xy[..., 1]

    # --- site -> road ----------------------------------------------------------------------

    def to_road(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> tuple[F64, F64]:
        """Site frame to road frame.

        Parameters
        ----------
        x_m, y_m : array_like, broadcastable, shape (...)
            Site-frame position [m].

        Returns
        -------
        station_m, offset_m : ndarray, shape (...)
            Station s [m] (negative before the first vertex, above ``length_m`` after the last)
            and offset d [m], positive to the left.

        Notes
        -----
        On segment i, with ``w = q - P_i``, ``D = P_{i+1} - P_i``, ``a = N_i`` and
        ``b = N_{i+1} - N_i``, the foot parameter u solves ``(w - u D) x (a + u b) = 0``:

        .. math::  -(D \\times b) u^2 + (w \\times b - D \\times a) u + w \\times a = 0

        A root in [0, 1] is a candidate with ``d = (w - u D) . n(u) / |n(u)|``, and the candidate
        with the smallest |d| wins. Since ``|d| >= dist(q, segment i)``, a segment farther from q
        than the best candidate cannot win, which makes two exact searches possible:

        - fast: a grid of cells lists, for each cell, the segments within ``GRID_REACH_M`` of it;
          a point whose best candidate among its cell's segments has ``|d| <= GRID_REACH_M`` is
          done;
        - exhaustive (other points): solve the nearest segment and its neighbours, then every
          segment nearer than the best candidate so far.

        A point with no candidate at all (far inside a sharp curve) falls back to its projection
        on the nearest segment.
        """
        x, y = np.broadcast_arrays(
            np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64)
        )
        shape = x.shape
        qx = x.ravel()
        qy = y.ravel()
        station, offset, resolved = self._to_road_grid(qx, qy)
        rest = np.flatnonzero(~resolved)
        chunk = max(1, _CHUNK_ELEMENTS // self.segment_count)
        for start in range(0, rest.size, chunk):
            part = rest[start : start + chunk]
            station[part], offset[part] = self._to_road_exhaustive(qx[part], qy[part])
        return station.reshape(shape), offset.reshape(shape)

    def _build_grid(self) -> None:
        """Grid of cells, each listing the segments within ``GRID_REACH_M`` of it (CSR layout)."""
        reach = GRID_REACH_M
        lower = self._vertices.min(axis=0) - reach
        upper = self._vertices.max(axis=0) + reach
        extent = upper - lower
        # Cells of _GRID_CELL_M, or larger where the site would need more than _GRID_MAX_CELLS.
        cell = max(_GRID_CELL_M, float(np.sqrt(extent[0] * extent[1] / _GRID_MAX_CELLS)))
        cells_x, cells_y = (int(n) for n in np.ceil(extent / cell).astype(int) + 1)
        segment_lower = np.minimum(self._vertices[:-1], self._vertices[1:]) - reach
        segment_upper = np.maximum(self._vertices[:-1], self._vertices[1:]) + reach
        first = np.floor((segment_lower - lower) / cell).astype(np.intp)
        last = np.floor((segment_upper - lower) / cell).astype(np.intp)
        pairs_cell: list[npt.NDArray[np.intp]] = []
        pairs_segment: list[npt.NDArray[np.intp]] = []
        for segment in range(self.segment_count):
            ix, iy = np.meshgrid(
                np.arange(first[segment, 0], last[segment, 0] + 1),
                np.arange(first[segment, 1], last[segment, 1] + 1),
            )
            # Keep only cells really within reach of the segment (the bounding box of a diagonal
            # segment holds many that are not): centre distance <= reach + half a cell diagonal.
            centre_x = lower[0] + (ix + 0.5) * cell
            centre_y = lower[1] + (iy + 0.5) * cell
            near = self._segment_distance(centre_x, centre_y, segment) <= reach + cell * 0.7072
            pairs_cell.append((ix * cells_y + iy)[near])
            pairs_segment.append(np.full(int(near.sum()), segment, dtype=np.intp))
        cell_ids = np.concatenate(pairs_cell)
        segment_ids = np.concatenate(pairs_segment)
        order = np.argsort(cell_ids, kind="stable")
        counts = np.bincount(cell_ids, minlength=cells_x * cells_y)
        self._grid_lower = lower
        self._grid_cell_m = cell
        self._grid_shape = (cells_x, cells_y)
        self._grid_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.intp)
        self._grid_segments = segment_ids[order]

    def _segment_distance(self, x_m: F64, y_m: F64, segment: int) -> F64:
        """Euclidean distance [m] from points to one segment (clamped projection)."""
        wx = x_m - self._vertices[segment, 0]
        wy = y_m - self._vertices[segment, 1]
        dx, dy = self._deltas[segment]
        t = np.clip((wx * dx + wy * dy) / self._lengths[segment] ** 2, 0.0, 1.0)
        distance: F64 = np.hypot(wx - t * dx, wy - t * dy)
        return distance

    def _to_road_grid(self, qx: F64, qy: F64) -> tuple[F64, F64, npt.NDArray[np.bool_]]:
        """Fast search among each point's cell's segments; ``resolved`` is False where unsure."""
        station = np.full(qx.size, np.nan)
        offset = np.full(qx.size, np.nan)
        resolved = np.zeros(qx.size, dtype=bool)
        ix = np.floor((qx - self._grid_lower[0]) / self._grid_cell_m)
        iy = np.floor((qy - self._grid_lower[1]) / self._grid_cell_m)
        inside = np.flatnonzero(
            (ix >= 0) & (ix < self._grid_shape[0]) & (iy >= 0) & (iy < self._grid_shape[1])
        )
        for start in range(0, inside.size, _GRID_CHUNK_POINTS):
            points = inside[start : start + _GRID_CHUNK_POINTS]
            cell = ix[points].astype(np.intp) * self._grid_shape[1] + iy[points].astype(np.intp)
            counts = self._grid_start[cell + 1] - self._grid_start[cell]
            # One (point, segment) pair per segment listed in the point's cell.
            pair_point = np.repeat(np.arange(points.size), counts)
            pair_first = np.cumsum(counts) - counts
            within = np.arange(pair_point.size) - pair_first[pair_point]
            pair_segment = self._grid_segments[self._grid_start[cell][pair_point] + within]
            u, d = self._solve(qx[points][pair_point], qy[points][pair_point], pair_segment)
            segment, best_u, best_d = self._best_per_point(
                points.size, pair_point, pair_segment, u, d
            )
            segment, best_u, best_d = self._beyond_ends(
                qx[points], qy[points], segment, best_u, best_d
            )
            station[points] = self._stations[segment] + best_u * self._lengths[segment]
            offset[points] = best_d
            resolved[points] = np.abs(best_d) <= GRID_REACH_M
        return station, offset, resolved

    @staticmethod
    def _best_per_point(
        count: int,
        pair_point: npt.NDArray[np.intp],
        pair_segment: npt.NDArray[np.intp],
        u: F64,
        d: F64,
    ) -> tuple[npt.NDArray[np.intp], F64, F64]:
        """Smallest-|d| pair of each point; pairs grouped by point in increasing order.

        Points without a pair get segment 0, u = 0 and d = inf.
        """
        segment = np.zeros(count, dtype=np.intp)
        best_u = np.zeros(count)
        best_d = np.full(count, np.inf)
        if pair_point.size == 0:
            return segment, best_u, best_d
        magnitude = np.abs(d)
        group_start = np.flatnonzero(np.diff(pair_point, prepend=-1))
        group_point = pair_point[group_start]
        smallest = np.minimum.reduceat(magnitude, group_start)
        is_smallest = magnitude == np.repeat(smallest, np.diff(group_start, append=d.size))
        hit = np.flatnonzero(is_smallest)
        # The first hit of each point (infinite minima hit too: such a point keeps d = inf).
        first_hit = hit[np.diff(pair_point[hit], prepend=-1) != 0]
        segment[group_point] = pair_segment[first_hit]
        best_u[group_point] = u[first_hit]
        best_d[group_point] = d[first_hit]
        return segment, best_u, best_d

    def _to_road_exhaustive(self, qx: F64, qy: F64) -> tuple[F64, F64]:
        """Search over all segments, pruned by distance; shape (count,) in and out."""
        count = qx.size
        last = self.segment_count - 1
        rows = np.arange(count)

        # Distance from every point to every segment, shape (count, segments).
        wx = qx[:, None] - self._vertices[None, :-1, 0]
        wy = qy[:, None] - self._vertices[None, :-1, 1]
        along = wx * self._deltas[:, 0] + wy * self._deltas[:, 1]
        t = np.clip(along / self._lengths**2, 0.0, 1.0)
        ex = wx - t * self._deltas[:, 0]
        ey = wy - t * self._deltas[:, 1]
        distance_sq = ex * ex + ey * ey
        nearest = np.argmin(distance_sq, axis=1)

        # Candidates on the nearest segment and its neighbours, and beyond the ends.
        window = np.clip(nearest[:, None] + np.array([-1, 0, 1]), 0, last)
        u, d = self._solve(qx[:, None], qy[:, None], window)
        pick = np.argmin(np.abs(d), axis=1)
        best_segment, best_u, best_d = self._beyond_ends(
            qx, qy, window[rows, pick], u[rows, pick], d[rows, pick]
        )

        # Any other segment nearer than the best candidate could still hold a better one.
        in_window = np.zeros_like(distance_sq, dtype=bool)
        in_window[rows[:, None], window] = True
        point, segment = np.nonzero((distance_sq < best_d[:, None] ** 2) & ~in_window)
        if point.size:
            more_u, more_d = self._solve(qx[point], qy[point], segment)
            order = np.lexsort((np.abs(more_d), point))
            first = np.unique(point[order], return_index=True)[1]
            chosen = order[first]
            point, segment = point[chosen], segment[chosen]
            more_u, more_d = more_u[chosen], more_d[chosen]
            better = np.abs(more_d) < np.abs(best_d[point])
            point, segment = point[better], segment[better]
            best_segment[point] = segment
            best_u[point] = more_u[better]
            best_d[point] = more_d[better]

        # No normal line through the point: fall back to the nearest-segment projection.
        lost = np.flatnonzero(~np.isfinite(best_d))
        if lost.size:
            k = nearest[lost]
            best_segment[lost] = k
            best_u[lost] = t[lost, k]
            side = np.sign(self._deltas[k, 0] * wy[lost, k] - self._deltas[k, 1] * wx[lost, k])
            best_d[lost] = side * np.sqrt(distance_sq[lost, k])

        station = self._stations[best_segment] + best_u * self._lengths[best_segment]
        return station, best_d

    def _beyond_ends(
        self,
        qx: F64,
        qy: F64,
        segment: npt.NDArray[np.intp],
        u: F64,
        d: F64,
    ) -> tuple[npt.NDArray[np.intp], F64, F64]:
        """Replace (segment, u, d) by the extrapolation beyond an end where that has smaller |d|.

        Beyond the ends the frame is the end segment's line with its normal held fixed, so the
        foot is the orthogonal projection on that line, taken where it falls outside the segment.
        """
        last = self.segment_count - 1
        for end, past in ((0, 0.0), (last, 1.0)):
            ewx = qx - self._vertices[end, 0]
            ewy = qy - self._vertices[end, 1]
            end_u = (ewx * self._deltas[end, 0] + ewy * self._deltas[end, 1]) / self._lengths[
                end
            ] ** 2
            # u < 0 past the start of the first segment, u > 1 past the end of the last.
            outside = end_u < 0.0 if past == 0.0 else end_u > 1.0
            normal = self._vertex_normals[0 if end == 0 else -1]
            end_d = (ewx - end_u * self._deltas[end, 0]) * normal[0] + (
                ewy - end_u * self._deltas[end, 1]
            ) * normal[1]
            better = outside & (np.abs(end_d) < np.abs(d))
            segment = np.where(better, end, segment)
            u = np.where(better, end_u, u)
            d = np.where(better, end_d, d)
        return segment, u, d

    def _solve(self, qx: F64, qy: F64, segment: npt.NDArray[np.intp]) -> tuple[F64, F64]:
        """Best root u in [0, 1] on ``segment`` and its offset d; d = inf where there is none.

        ``qx``, ``qy`` and ``segment`` broadcast together; the outputs have their shape.
        """
        px, py, dx, dy, ax, ay, bx, by, quad_a, d_cross_a = self._segment_columns[:, segment]
        wx = qx - px
        wy = qy - py
        # A u^2 + B u + C = 0, from (w - u D) x (a + u b) = 0; A depends on the segment only.
        quad_b = (wx * by - wy * bx) - d_cross_a
        quad_c = wx * ay - wy * ax
        discriminant = quad_b * quad_b - 4.0 * quad_a * quad_c
        root_disc = np.sqrt(np.maximum(discriminant, 0.0))
        # Numerically stable pair of roots; q / A is inf on a straight segment (A = 0), where
        # C / q is the linear root.
        half = -0.5 * (quad_b + np.copysign(root_disc, quad_b))
        real = discriminant >= 0.0
        best_u = np.zeros(half.shape)
        best_d = np.full(half.shape, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            for root in (half / quad_a, quad_c / half):
                # Offsets only where the root lies on the segment: most pairs have none.
                on = np.nonzero(real & (root >= -_U_TOLERANCE) & (root <= 1.0 + _U_TOLERANCE))
                u = root[on]
                nx = ax[on] + u * bx[on]
                ny = ay[on] + u * by[on]
                d = ((wx[on] - u * dx[on]) * nx + (wy[on] - u * dy[on]) * ny) / np.hypot(nx, ny)
                better = np.abs(d) < np.abs(best_d[on])
                best_u[on] = np.where(better, u, best_u[on])
                best_d[on] = np.where(better, d, best_d[on])
        return best_u, best_d


class GeoFrame:
    """WGS84 to and from the site frame: exact local ENU (topocentric) at an origin.

    Parameters
    ----------
    latitude_deg, longitude_deg : float
        WGS84 geodetic latitude and longitude of the site-frame origin [deg].
    altitude_m : float
        Ellipsoidal height of the origin [m]; the site frame's z = 0 there.

    Notes
    -----
    The transform is the PROJ pipeline ``cart`` (geodetic to geocentric) then ``topocentric``
    (geocentric to ENU at the origin): a rigid rotation and translation of ECEF, with no map
    projection distortion. A point on the ellipsoid 1 km from the origin lies about 8 cm below
    the origin's tangent plane (z < 0).
    """

    def __init__(self, latitude_deg: float, longitude_deg: float, altitude_m: float = 0.0) -> None:
        self.latitude_deg = float(latitude_deg)
        self.longitude_deg = float(longitude_deg)
        self.altitude_m = float(altitude_m)
        self._transformer = Transformer.from_pipeline(
            "+proj=pipeline +step +proj=cart +ellps=WGS84 +step +proj=topocentric +ellps=WGS84 "
            f"+lat_0={self.latitude_deg!r} +lon_0={self.longitude_deg!r} +h_0={self.altitude_m!r}"
        )

    def to_site(
        self,
        latitude_deg: npt.ArrayLike,
        longitude_deg: npt.ArrayLike,
        altitude_m: npt.ArrayLike | None = None,
    ) -> tuple[F64, F64, F64]:
        """WGS84 to site frame.

        Parameters
        ----------
        latitude_deg, longitude_deg : array_like, broadcastable, shape (...)
            Geodetic latitude and longitude [deg].
        altitude_m : array_like, shape (...), optional
            Ellipsoidal height [m]; by default the origin's altitude (not 0: a point 365 m below
            the origin would land 365 m below the site frame, and shrunk toward it by h / R).

        Returns
        -------
        x_m, y_m, z_m : ndarray, shape (...)
            East, north, up [m] from the origin.
        """
        height = self.altitude_m if altitude_m is None else altitude_m
        lat, lon, alt = np.broadcast_arrays(
            np.asarray(latitude_deg, dtype=np.float64),
            np.asarray(longitude_deg, dtype=np.float64),
            np.asarray(height, dtype=np.float64),
        )
        east, north, up = self._transformer.transform(lon, lat, alt)
        return (
            np.asarray(east, dtype=np.float64).reshape(lat.shape),
            np.asarray(north, dtype=np.float64).reshape(lat.shape),
            np.asarray(up, dtype=np.float64).reshape(lat.shape),
        )

    def to_wgs84(
        self, x_m: npt.ArrayLike, y_m: npt.ArrayLike, z_m: npt.ArrayLike = 0.0
    ) -> tuple[F64, F64, F64]:
        """Site frame to WGS84.

        Parameters
        ----------
        x_m, y_m, z_m : array_like, broadcastable, shape (...)
            East, north, up [m] from the origin; z defaults to the origin's tangent plane.

        Returns
        -------
        latitude_deg, longitude_deg, altitude_m : ndarray, shape (...)
            Geodetic latitude and longitude [deg] and ellipsoidal height [m].
        """
        east, north, up = np.broadcast_arrays(
            np.asarray(x_m, dtype=np.float64),
            np.asarray(y_m, dtype=np.float64),
            np.asarray(z_m, dtype=np.float64),
        )
        lon, lat, alt = self._transformer.transform(east, north, up, direction="INVERSE")
        return (
            np.asarray(lat, dtype=np.float64).reshape(east.shape),
            np.asarray(lon, dtype=np.float64).reshape(east.shape),
            np.asarray(alt, dtype=np.float64).reshape(east.shape),
        )
