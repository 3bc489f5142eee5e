"""Ground height per square cell, from the lowest background point in it (:class:`GroundGrid`),
for the background models of :mod:`wz_lidar_detector.background`."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from wz_shared.arrays import F64, I64

# Ground cells: x and y cell indices offset by 2**30 (non-negative, below 2**31) and packed as
# x << 32 | y, so that the key stays positive.
_CELL_OFFSET = 1 << 30


class GroundGrid:
    """Ground height per square cell, from the lowest background point in it.

    Far from the sensor the ground is hit in rings tens of metres apart (a 64-beam sensor 6 m up
    sees the ground at 100 m every ~20 m of range), so most cells there hold no background. A
    lookup in such a cell takes the median of the ``neighbours`` nearest known cells within
    ``search_radius_m``.

    Parameters
    ----------
    cell_m
        Edge of the square cells [m].
    cell_keys
        ``(C,)`` sorted int64 keys of the cells that hold background (x index << 32 | y index,
        each offset by 2**30).
    ground_z_m
        ``(C,)`` lowest background z [m] in each cell.
    search_radius_m
        How far to look for known cells around an unknown one [m]; 0 for no search.
    neighbours
        Known cells whose median is taken.
    """

    def __init__(
        self,
        cell_m: float,
        cell_keys: I64,
        ground_z_m: F64,
        *,
        search_radius_m: float = 30.0,
        neighbours: int = 4,
    ) -> None:
        if cell_keys.shape != ground_z_m.shape:
            raise ValueError("cell_keys and ground_z_m must have the same shape")
        self.cell_m = float(cell_m)
        self.cell_keys = cell_keys
        self.ground_z = ground_z_m
        self.search_radius_m = float(search_radius_m)
        self.neighbours = int(neighbours)
        self._tree: cKDTree | None = None

    @staticmethod
    def _keys(xy_m: F64, cell_m: float) -> I64:
        ij = np.floor(xy_m / cell_m).astype(np.int64) + _CELL_OFFSET
        keys: I64 = (ij[:, 0] << 32) | ij[:, 1]
        return keys

    @classmethod
    def from_points(cls, xyz_m: npt.ArrayLike, cell_m: float = 1.0) -> GroundGrid:
        """Lowest z of the finite points in each cell.

        Parameters
        ----------
        xyz_m
            ``(N, 3)`` background points [m] (NaN rows are ignored).
        cell_m
            Cell edge [m].
        """
        xyz = np.asarray(xyz_m, dtype=np.float64).reshape(-1, 3)
        xyz = xyz[np.isfinite(xyz).all(axis=1)]
        keys = cls._keys(xyz[:, :2], cell_m)
        order = np.lexsort((xyz[:, 2], keys))  # by cell, then z ascending
        keys, z = keys[order], xyz[order, 2]
        first = np.ones(len(keys), dtype=bool)
        first[1:] = keys[1:] != keys[:-1]
        return cls(cell_m, keys[first], z[first])

    def _cell_centres(self) -> F64:
        i = (self.cell_keys >> 32) - _CELL_OFFSET
        j = (self.cell_keys & 0xFFFFFFFF) - _CELL_OFFSET
        centres: F64 = (np.column_stack([i, j]) + 0.5) * self.cell_m
        return centres

    def lookup(self, xy_m: npt.ArrayLike) -> F64:
        """Ground z [m] under each ``(K, 2)`` x, y [m]; NaN where nothing is known nearby."""
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        if len(self.cell_keys) == 0:
            return np.full(len(xy), np.nan)
        keys = self._keys(xy, self.cell_m)
        position = np.searchsorted(self.cell_keys, keys)
        position[position == len(self.cell_keys)] = 0
        found = self.cell_keys[position] == keys
        result: F64 = np.where(found, self.ground_z[position], np.nan)
        if found.all() or self.search_radius_m <= 0:
            return result
        if self._tree is None:
            self._tree = cKDTree(self._cell_centres())
        missing = np.flatnonzero(~found)
        count = min(self.neighbours, len(self.cell_keys))
        distance, index = self._tree.query(
            xy[missing], k=count, distance_upper_bound=self.search_radius_m
        )
        distance, index = distance.reshape(len(missing), -1), index.reshape(len(missing), -1)
        near = np.isfinite(distance)
        heights = np.where(near, self.ground_z[np.minimum(index, len(self.ground_z) - 1)], np.nan)
        # Median of the finite heights of each row (np.nanmedian is ten times slower): sorting
        # puts NaN last, so the finite ones are the first `known` of each row.
        heights.sort(axis=1)
        known = near.sum(axis=1)
        rows = np.flatnonzero(known > 0)
        low = heights[rows, (known[rows] - 1) // 2]
        high = heights[rows, known[rows] // 2]
        result[missing[rows]] = 0.5 * (low + high)
        return result


def ground_arrays(ground: GroundGrid | None) -> dict[str, npt.NDArray[np.generic]]:
    ground = ground or GroundGrid(1.0, np.zeros(0, np.int64), np.zeros(0))
    return {
        "ground_cell_m": np.array(ground.cell_m),
        "ground_cell_keys": ground.cell_keys,
        "ground_z_m": ground.ground_z,
        "ground_search_radius_m": np.array(ground.search_radius_m),
        "ground_neighbours": np.array(ground.neighbours),
    }


def ground_height_at(ground: GroundGrid | None, xy_m: F64) -> F64:
    """Ground height [m] under ``(K, 2)`` x, y [m]; NaN where unknown (everywhere: no ground)."""
    if ground is None:
        return np.full(len(np.asarray(xy_m).reshape(-1, 2)), np.nan)
    return ground.lookup(xy_m)


def ground_from_arrays(arrays: dict[str, npt.NDArray[np.generic]]) -> GroundGrid | None:
    keys = np.asarray(arrays["ground_cell_keys"], dtype=np.int64)
    if len(keys) == 0:
        return None
    return GroundGrid(
        float(arrays["ground_cell_m"]),
        keys,
        np.asarray(arrays["ground_z_m"], dtype=np.float64),
        search_radius_m=float(arrays["ground_search_radius_m"]),
        neighbours=int(arrays["ground_neighbours"]),
    )
