"""Background models for a roadside LiDAR that does not move (pure core, sensor frame).

A sensor on a mast sees the same road, kerbs, barriers and trees in every frame; what differs
from that static background is traffic. A background model answers, per point of a frame, "is
this point nearer than the background along its ray (or in free space)?" in a millisecond or two,
which replaces the reference path's ROI, ground fit, height filter and outlier removal.

Two models, one protocol (:class:`BackgroundModel`):

:class:`RangeImageBackground` (organized frames: one slot per beam and column)
    Per slot, the range of the background along that ray. Learned at start-up from up to 255
    frames spread over several seconds (:class:`RangeBackgroundLearner`: a histogram of each
    slot's ranges, one byte per bin): the background is the *farthest* surface whose returns
    make up at least ``min_support_fraction`` of the frames, since vehicles passing are always
    *nearer* than the road behind them. A slot where no surface shows that often is *open
    sky* (background range +inf): it never returns, or returns only when traffic crosses it,
    at ever different ranges (a ray along the road over the horizon, which queued traffic may
    block in a third of the frames). A slot a swaying mast moves across an edge (a kerb, a
    drum, a sign post) sees two surfaces; with ``near_support_fraction`` below 1 the nearer
    one is taken when it shows often enough.
    Foreground: a valid point nearer than the background by more than
    ``max(margin_min_m, margin_range_fraction * background range)``, and within ``max_range_m``;
    so any return in an open-sky slot within range is foreground (a vehicle against the sky, or
    rain: the clusterer's size limits deal with the latter). The model follows slow changes
    (:meth:`RangeImageBackground.update`): an EMA of the range in slots that currently see the
    background, and a slot whose return stays *farther* than the model for ``reveal_frames``
    frames in a row takes the new range (a parked vehicle that left). A new static object nearer
    than the model (a cone placed after start-up) stays foreground: the tracker sees it as a
    stationary object, which is the safe side in a work zone.
:class:`VoxelBackground` (any cloud, organized or not; or a given background cloud)
    Occupancy of a voxel grid: the set of voxels the background occupies, as sorted int64 keys
    (21 bits per axis). Built from a background cloud (e.g. an accumulated map) or learned from
    frames (voxels occupied in at least ``min_occupancy_fraction`` of them), optionally dilated
    by one voxel (26-neighbourhood) to absorb the jitter of surfaces near a voxel face. Foreground:
    a valid point whose voxel is not background, including points outside the learned extent
    (unknown space is not background; limit the range in the pipeline). Static: it does not
    update; learn a new one to refresh it.

Both give the height of the ground under a point (:meth:`BackgroundModel.ground_z_m`), from the
lowest background point in each ``ground_cell_m`` square, or from the nearest known squares
where the beams left the ground unseen (:class:`GroundGrid`), so that a vehicle's box stands on
the road even when its lowest returns were lost to the background margin, and ground speckle
and overhanging foliage can be told from vehicles.

Save and load: ``.npz`` at a path the caller gives, with ``format_version``, the model ``kind``
and its shape (rows x columns) or voxel size; a file of another kind, version or shape raises
:class:`BackgroundFileError` (a ``ValueError``) saying what differs. A frame whose slot count
differs from a range-image model raises :class:`ShapeMismatchError` (the node then rebuilds).
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from wz_lidar_detector.detection import PointFrame
from wz_lidar_detector.ground_grid import (
    GroundGrid,
    ground_arrays,
    ground_from_arrays,
    ground_height_at,
)
from wz_shared.arrays import F32, F64, I64, U64, Bool

PathLike = str | os.PathLike[str]

#: Version of the ``.npz`` layout written by :meth:`RangeImageBackground.save` and
#: :meth:`VoxelBackground.save`; bump it when the layout or the learning rule changes.
#: 2: range-image slots need a supported background (``min_support_fraction``).
#: 3: the range-image background is the farthest supported surface (not a percentile).
FORMAT_VERSION = 3

# Voxel keys: each integer voxel index is offset by 2**20 and packed into 21 bits
# (x << 42 | y << 21 | z), which covers +-2**20 voxels per axis (+-524 km at 0.5 m).
_KEY_BITS = 21
_KEY_OFFSET = 1 << (_KEY_BITS - 1)
_KEY_MASK = (1 << _KEY_BITS) - 1
#: Voxel index offsets of the 26-neighbourhood and the voxel itself, (27, 3).
_NEIGHBOURHOOD_27 = np.array(
    [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], dtype=np.int64
)


class BackgroundFileError(ValueError):
    """A background ``.npz`` that cannot be loaded as asked (kind, version or shape differ)."""


class ShapeMismatchError(ValueError):
    """A frame whose beam/column layout differs from the range-image model's."""


@runtime_checkable
class BackgroundModel(Protocol):
    """What the fast pipeline needs from a background model."""

    def foreground_mask(self, frame: PointFrame) -> Bool:
        """``(N,)`` bool over ``frame.points``: valid points that are not background."""
        ...

    def ground_z_m(self, xy_m: F64) -> F64:
        """``(K,)`` ground height [m] under each ``(K, 2)`` x, y [m]; NaN where unknown."""
        ...

    def update(self, frame: PointFrame) -> None:
        """Let the model follow slow changes of the scene (a no-op for static models)."""
        ...


# --------------------------------------------------------------------------------------------
# Keys and ground
# --------------------------------------------------------------------------------------------


def voxel_indices(xyz_m: npt.ArrayLike, voxel_m: float) -> I64:
    """Integer voxel index of each point.

    Parameters
    ----------
    xyz_m
        ``(N, 3)`` finite points [m].
    voxel_m
        Voxel edge [m]; voxel ``(i, j, k)`` spans ``[i * voxel_m, (i + 1) * voxel_m)`` in x, etc.

    Returns
    -------
    I64
        ``(N, 3)`` voxel indices.
    """
    xyz = np.asarray(xyz_m, dtype=np.float64).reshape(-1, 3)
    return np.floor(xyz / voxel_m).astype(np.int64)


def pack_keys(indices: I64) -> I64:
    """``(N, 3)`` voxel indices to ``(N,)`` int64 keys (21 bits per axis); order is x, y, z."""
    shifted = indices + _KEY_OFFSET
    if shifted.size and (shifted.min() < 0 or shifted.max() > _KEY_MASK):
        raise ValueError(f"voxel index beyond +-{_KEY_OFFSET} voxels: make the voxels larger")
    packed: I64 = (shifted[:, 0] << (2 * _KEY_BITS)) | (shifted[:, 1] << _KEY_BITS)
    packed |= shifted[:, 2]
    return packed


def unpack_keys(keys: I64) -> I64:
    """Inverse of :func:`pack_keys`: ``(N,)`` keys to ``(N, 3)`` voxel indices."""
    fields = [(keys >> (shift * _KEY_BITS)) & _KEY_MASK for shift in (2, 1, 0)]
    indices: I64 = np.stack(fields, axis=1) - _KEY_OFFSET
    return indices


def dilate_keys(keys: I64) -> I64:
    """Sorted unique keys of the voxels and their 26 neighbours."""
    indices = unpack_keys(keys)
    grown = (indices[:, None, :] + _NEIGHBOURHOOD_27[None, :, :]).reshape(-1, 3)
    return np.unique(pack_keys(grown))


def _sorted_member(sorted_keys: I64, keys: I64) -> Bool:
    """Whether each of ``keys`` is in ``sorted_keys`` (sorted, unique)."""
    if len(sorted_keys) == 0:
        return np.zeros(len(keys), dtype=bool)
    position = np.searchsorted(sorted_keys, keys)
    position[position == len(sorted_keys)] = 0
    found: Bool = sorted_keys[position] == keys
    return found


def _frame_xyz(frame: PointFrame) -> F32:
    xyz: F32 = np.asarray(frame.points[:, :3], dtype=np.float32)
    return xyz


def _valid(xyz: F32) -> Bool:
    # A no-return slot has NaN x; some drivers write NaN in y or z only, or inf: check all.
    valid: Bool = np.isfinite(xyz[:, 0]) & np.isfinite(xyz[:, 1]) & np.isfinite(xyz[:, 2])
    return valid


def _ranges(xyz: F32) -> F32:
    # Column by column: numpy's reductions over a short last axis are several times slower.
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    ranges: F32 = np.sqrt(x * x + y * y + z * z)
    return ranges


def _write_model(
    path: PathLike, kind: str, arrays: dict[str, npt.NDArray[np.generic]], ground: GroundGrid | None
) -> None:
    """Write a model's file: format version and kind, the model's ``arrays``, then its ground."""
    arrays = {
        "format_version": np.array(FORMAT_VERSION),
        "kind": np.array(kind),
        **arrays,
        **ground_arrays(ground),
    }
    # Through a file object so that numpy does not append ".npz" to the caller's path.
    with open(path, "wb") as stream:
        np.savez(stream, **arrays)  # type: ignore[arg-type]


_GROUND_FIELDS = (
    "ground_cell_m",
    "ground_cell_keys",
    "ground_z_m",
    "ground_search_radius_m",
    "ground_neighbours",
)


def _read_npz(
    path: PathLike, kind: str, fields: Sequence[str]
) -> dict[str, npt.NDArray[np.generic]]:
    """The arrays of a background file of ``kind`` holding ``fields``; else a clear error."""
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        raise BackgroundFileError(
            f"{os.fspath(path)}: not a readable .npz file ({error})"
        ) from error
    for name in ("format_version", "kind"):
        if name not in arrays:
            raise BackgroundFileError(f"{os.fspath(path)}: no '{name}': not a background model")
    version = int(arrays["format_version"])
    if version != FORMAT_VERSION:
        raise BackgroundFileError(
            f"{os.fspath(path)}: background format version {version}, this software reads "
            f"version {FORMAT_VERSION}: learn the background again"
        )
    found_kind = str(arrays["kind"])
    if found_kind != kind:
        raise BackgroundFileError(
            f"{os.fspath(path)}: holds a '{found_kind}' background, expected '{kind}'"
        )
    missing = [name for name in (*fields, *_GROUND_FIELDS) if name not in arrays]
    if missing:
        raise BackgroundFileError(
            f"{os.fspath(path)}: '{kind}' background without {', '.join(missing)}: the file is "
            "damaged, learn the background again"
        )
    return arrays


# --------------------------------------------------------------------------------------------
# Range-image background
# --------------------------------------------------------------------------------------------


class RangeBackgroundSettings(BaseModel):
    """Parameters of :class:`RangeImageBackground` (lengths in metres)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: A surface is the background when its returns (within about a margin) make up at least
    #: this fraction of the learning frames; the farthest such surface is taken. A slot with
    #: none is open sky: it looks at nothing and returns only when traffic crosses it, at ever
    #: different ranges.
    min_support_fraction: float = Field(default=0.2, gt=0.0, le=1.0)
    #: A nearer surface whose returns make up at least this fraction of the learning frames is
    #: the slot's background (1: never): a beam the mast's sway swings across the top of a
    #: barrier or the edge of a drum sees both. Measured on the default site and generated
    #: sites with a real mast's sway (refined over 20 s, with ``neighbour_slots``): 0.3 cut
    #: the off-road LiDAR boxes from up to 0.2 a frame to none. The risk: a queue standing
    #: still through 30 % of the learning is learned as background until it leaves
    #: (``reveal_frames``).
    near_support_fraction: float = Field(default=0.3, gt=0.0, le=1.0)
    #: A return within the margin of a neighbouring slot's background is background (the
    #: mast's sway turns beams by a fraction of a slot; see
    #: :meth:`RangeImageBackground.foreground_mask`).
    neighbour_slots: bool = True
    #: Foreground when nearer than the background by more than
    #: ``max(margin_min_m, margin_range_fraction * background range)``.
    margin_min_m: float = Field(default=0.3, ge=0.0)
    margin_range_fraction: float = Field(default=0.01, ge=0.0)
    #: Returns farther than this are never foreground [m].
    max_range_m: float = Field(default=200.0, gt=0.0)
    #: EMA weight of the current range in slots that see their background (per frame).
    ema_weight: float = Field(default=0.02, ge=0.0, le=1.0)
    #: Frames in a row a slot must return farther than its model before the model takes the
    #: new range (at 10 Hz, 100 frames = 10 s).
    reveal_frames: int = Field(default=100, ge=1)
    #: Cell edge of the ground-height grid [m].
    ground_cell_m: float = Field(default=1.0, gt=0.0)


class RangeImageBackground:
    """Background range per (beam, column) slot of an organized frame.

    Parameters
    ----------
    background_range_m
        ``(rows, columns)`` background range [m] of each slot; +inf for open sky.
    settings
        Margins and update rates.
    ground
        Ground heights, or None when unknown.
    """

    kind = "range_image"

    def __init__(
        self,
        background_range_m: npt.ArrayLike,
        settings: RangeBackgroundSettings | None = None,
        ground: GroundGrid | None = None,
    ) -> None:
        image = np.array(background_range_m, dtype=np.float32)
        if image.ndim != 2 or min(image.shape) < 1:
            raise ValueError(f"background_range_m must be (rows, columns), got {image.shape}")
        if np.isnan(image).any():
            raise ValueError("background_range_m holds NaN: use +inf for open sky")
        self.settings = settings or RangeBackgroundSettings()
        self._range_m: F32 = image.reshape(-1)
        self._shape = (int(image.shape[0]), int(image.shape[1]))
        self._farther_frames = np.zeros(image.size, dtype=np.int32)
        self.ground = ground

    @property
    def rows(self) -> int:
        return self._shape[0]

    @property
    def columns(self) -> int:
        return self._shape[1]

    @property
    def background_range_m(self) -> F32:
        """``(rows, columns)`` copy of the background range [m]; +inf for open sky."""
        return self._range_m.reshape(self._shape).copy()

    @classmethod
    def learn(
        cls, frames: Sequence[PointFrame], settings: RangeBackgroundSettings | None = None
    ) -> RangeImageBackground:
        """Learn the background from organized frames of one sensor (see
        :class:`RangeBackgroundLearner`, which does the same one frame at a time).

        Parameters
        ----------
        frames
            K >= 1 organized frames of the same rows x columns (more than 255: 255 of them,
            evenly spread). Vehicles may pass.
        settings
            Parameters; defaults if None.
        """
        if not frames:
            raise ValueError("learning a range-image background needs at least one frame")
        if len(frames) > RangeBackgroundLearner.MAX_FRAMES:
            pick = np.rint(np.linspace(0, len(frames) - 1, RangeBackgroundLearner.MAX_FRAMES))
            frames = [frames[k] for k in pick.astype(int)]
        learner = RangeBackgroundLearner(frames[0].rows, frames[0].columns, settings)
        for index, frame in enumerate(frames):
            try:
                learner.add(frame)
            except ShapeMismatchError as error:
                raise ShapeMismatchError(f"frame {index}: {error}") from error
        return learner.finish()

    def _check(self, frame: PointFrame) -> None:
        if not frame.organized or (frame.rows, frame.columns) != self._shape:
            raise ShapeMismatchError(
                f"frame has {frame.rows}x{frame.columns} slots ({len(frame.points)} points), the "
                f"background model {self.rows}x{self.columns}: the sensor's mode changed, "
                "rebuild the background model"
            )

    def _margin_m(self) -> F32:
        # Open-sky slots (+inf) get the minimum margin, not inf (inf - inf would be NaN).
        settings = self.settings
        finite_range = np.where(np.isinf(self._range_m), np.float32(0.0), self._range_m)
        margin: F32 = np.maximum(
            np.float32(settings.margin_min_m),
            np.float32(settings.margin_range_fraction) * finite_range,
        )
        return margin

    def foreground_mask(self, frame: PointFrame) -> Bool:
        """Valid points nearer than their slot's background by more than the margin.

        Parameters
        ----------
        frame
            Organized frame of the model's rows x columns.

        Returns
        -------
        Bool
            ``(rows * columns,)``; False for no-return slots and returns beyond ``max_range_m``.
            In open-sky slots every valid return within ``max_range_m`` is foreground.

        Raises
        ------
        ShapeMismatchError
            The frame's layout differs from the model's.
        """
        self._check(frame)
        xyz = _frame_xyz(frame)
        with np.errstate(invalid="ignore"):
            ranges = _ranges(xyz)
            # NaN ranges compare False, so no-return slots are never foreground.
            margin = self._margin_m()
            nearer = ranges < self._range_m - margin
            mask: Bool = nearer & (ranges <= np.float32(self.settings.max_range_m))
        if self.settings.neighbour_slots:
            self._drop_neighbours_background(mask, ranges, margin)
        return mask

    def _drop_neighbours_background(self, mask: Bool, ranges: F32, margin_m: F32) -> None:
        """Clear the candidates that lie on a neighbouring slot's background (in place).

        A mast sways by hundredths of a degree, a fraction of a slot (0.18 deg for 2048
        columns; beams are a few tenths apart): a beam at the edge of a barrier, a drum or a
        kerb swings between the two surfaces its neighbours see steadily. A return within the
        margin of the background of one of the 8 neighbouring slots is that surface, seen a
        little turned, not a vehicle. A vehicle loses only the returns that coincide with a
        neighbour's background: beside a post at the same range, or on the ground line of the
        beam below.
        """
        candidates = np.flatnonzero(mask)
        if len(candidates) == 0:
            return
        rows, columns = self._shape
        row, column = np.divmod(candidates, columns)
        candidate_range = ranges[candidates]
        background = self._range_m.reshape(self._shape)
        margin = margin_m.reshape(self._shape)
        explained = np.zeros(len(candidates), dtype=bool)
        with np.errstate(invalid="ignore"):
            for d_row in (-1, 0, 1):
                other_row = row + d_row
                inside = (other_row >= 0) & (other_row < rows)
                other_row = np.clip(other_row, 0, rows - 1)
                for d_column in (-1, 0, 1):
                    if d_row == 0 and d_column == 0:
                        continue
                    # A spinning sensor's columns wrap round; a fixed one's edge columns
                    # have one neighbour fewer, which only keeps a little more foreground.
                    other_column = (column + d_column) % columns
                    neighbour = background[other_row, other_column]
                    explained |= inside & (
                        np.abs(candidate_range - neighbour) <= margin[other_row, other_column]
                    )
        mask[candidates[explained]] = False

    def update(self, frame: PointFrame) -> None:
        """Follow slow changes of the scene (see the module docstring).

        Slots that see their background (within the margin) move their range towards the
        current one by ``ema_weight``; a slot that returns farther than its background for
        ``reveal_frames`` frames in a row takes the current range. Open-sky slots stay open sky.

        Raises
        ------
        ShapeMismatchError
            The frame's layout differs from the model's.
        """
        self._check(frame)
        with np.errstate(invalid="ignore"):
            ranges = _ranges(_frame_xyz(frame))
            margin = self._margin_m()
            difference = ranges - self._range_m  # NaN where no return, -inf in open sky
            on_background = np.abs(difference) <= margin
            farther = difference > margin
        self._range_m[on_background] += (
            np.float32(self.settings.ema_weight) * (difference[on_background])
        )
        self._farther_frames[farther] += 1
        # A nearer return (traffic) breaks the run; a no-return slot neither extends nor breaks it.
        self._farther_frames[on_background | (difference < -margin)] = 0
        revealed = self._farther_frames >= self.settings.reveal_frames
        self._range_m[revealed] = ranges[revealed]
        self._farther_frames[revealed] = 0

    def ground_z_m(self, xy_m: F64) -> F64:
        """Ground height [m] under ``(K, 2)`` x, y [m]; NaN where unknown."""
        return ground_height_at(self.ground, xy_m)

    def save(self, path: PathLike) -> None:
        """Write the model to ``path`` (``.npz``; the name is used as given)."""
        arrays = {
            "rows": np.array(self.rows),
            "columns": np.array(self.columns),
            "background_range_m": self._range_m.reshape(self._shape),
            "settings_json": np.array(self.settings.model_dump_json()),
        }
        _write_model(path, self.kind, arrays, self.ground)

    @classmethod
    def load(
        cls, path: PathLike, *, rows: int | None = None, columns: int | None = None
    ) -> RangeImageBackground:
        """Read a model written by :meth:`save`.

        Parameters
        ----------
        path
            The ``.npz`` file.
        rows, columns
            The layout the caller's sensor has; when given, a model of another layout raises.

        Raises
        ------
        BackgroundFileError
            Not a range-image background, another format version, or another layout.
        """
        arrays = _read_npz(
            path, cls.kind, ("rows", "columns", "background_range_m", "settings_json")
        )
        shape = (int(arrays["rows"]), int(arrays["columns"]))
        wanted = (
            rows if rows is not None else shape[0],
            columns if columns is not None else shape[1],
        )
        if wanted != shape:
            raise BackgroundFileError(
                f"{os.fspath(path)}: background for {shape[0]}x{shape[1]} slots, the sensor has "
                f"{wanted[0]}x{wanted[1]}: learn the background again"
            )
        try:
            settings = RangeBackgroundSettings.model_validate_json(str(arrays["settings_json"]))
        except ValidationError as error:
            raise BackgroundFileError(
                f"{os.fspath(path)}: settings not readable ({error}): learn the background again"
            ) from error
        ground = ground_from_arrays(arrays)
        return cls(np.asarray(arrays["background_range_m"]).reshape(shape), settings, ground)


#: Slots :meth:`RangeBackgroundLearner.finish` works on at once.
_FINISH_BLOCK_SLOTS = 4096


class RangeBackgroundLearner:
    """Learns a :class:`RangeImageBackground` one frame at a time, in fixed memory.

    Each slot keeps a histogram of its ranges over the learning frames, in bins one margin wide
    (``max(margin_min_m, margin_range_fraction * range)``, up to ``max_range_m``, then one bin
    for everything beyond): one byte per slot and bin, so at most 255 frames (about 36 MB for
    a 64 x 2048 sensor), and no frame is kept. A learning that spans many seconds therefore
    costs no more memory than one of two seconds; it must span several periods of the mast's
    sway (1-4 s), or a slot at the edge of a kerb, a drum or a sign post sees only one of the
    two surfaces the sway swings it between, and the other comes out as a vehicle at every
    swing.

    The background of a slot is the *farthest* surface that shows, i.e. whose returns (within
    about a margin: the bin and its two neighbours) make up at least ``min_support_fraction``
    of the frames: traffic only ever comes nearer than the road behind it. A slot where no
    surface shows that often is open sky (+inf). With ``near_support_fraction`` below 1, the
    *nearest* surface that shows in at least that fraction of the frames is taken instead (a
    slot a swaying beam moves across an edge). The range taken is the weighted mean of the
    surface's bins' centres.

    Parameters
    ----------
    rows, columns
        Layout of the frames.
    settings
        Parameters; defaults if None.
    """

    #: Frames a histogram of bytes can count.
    MAX_FRAMES = 255

    def __init__(
        self, rows: int, columns: int, settings: RangeBackgroundSettings | None = None
    ) -> None:
        if rows < 1 or columns < 1:
            raise ValueError(
                f"a range-image background needs rows and columns, got {rows}x{columns}"
            )
        self.settings = settings or RangeBackgroundSettings()
        self.shape = (int(rows), int(columns))
        self.edges_m = _range_bin_edges(self.settings)
        #: Centre of each bin within max_range_m; the bin beyond has none (+inf).
        self._centres = np.append(0.5 * (self.edges_m[:-1] + self.edges_m[1:]), np.inf)
        slots = rows * columns
        #: Bins 0..n-1 within max_range_m, bin n beyond it.
        self._histogram = np.zeros((slots, len(self.edges_m)), dtype=np.uint8)
        self._direction_sum = np.zeros((slots, 3), dtype=np.float64)
        self.frames = 0

    @property
    def full(self) -> bool:
        return self.frames >= self.MAX_FRAMES

    def add(self, frame: PointFrame) -> None:
        """Count one frame's ranges.

        Raises
        ------
        ShapeMismatchError
            The frame is not organized, or its layout is not the learner's.
        ValueError
            Already :data:`MAX_FRAMES` frames.
        """
        if not frame.organized:
            raise ShapeMismatchError("frame is not organized: use VoxelBackground")
        if (frame.rows, frame.columns) != self.shape:
            raise ShapeMismatchError(
                f"frame has {frame.rows}x{frame.columns} slots, the learner "
                f"{self.shape[0]}x{self.shape[1]}: learn from frames of one sensor mode"
            )
        if self.full:
            raise ValueError(f"a range background learns from at most {self.MAX_FRAMES} frames")
        xyz = _frame_xyz(frame)
        ranges = _ranges(xyz)
        with np.errstate(invalid="ignore"):
            usable = _valid(xyz) & (ranges > 0)
        slots = np.flatnonzero(usable)
        bins = np.searchsorted(self.edges_m, ranges[slots], side="right") - 1
        # One return per slot and frame, so no index repeats; on the flat array (a 2-D fancy
        # index is ten times slower).
        flat = self._histogram.reshape(-1)
        flat[slots * self._histogram.shape[1] + bins] += np.uint8(1)
        unit = np.zeros(xyz.shape, dtype=np.float32)
        np.divide(xyz, ranges[:, None], out=unit, where=usable[:, None])
        self._direction_sum += unit
        self.frames += 1

    def finish(self) -> RangeImageBackground:
        """The background of the frames added so far (at least one)."""
        if self.frames == 0:
            raise ValueError("learning a range-image background needs at least one frame")
        settings = self.settings
        slots = self._histogram.shape[0]
        background = np.empty(slots, dtype=np.float64)
        open_sky = np.empty(slots, dtype=bool)
        beyond = np.empty(slots, dtype=bool)
        # In blocks of slots that stay in the cache: the whole histogram at once took 1.7 s
        # for 64 x 2048 slots, blocks take a few hundred ms.
        for start in range(0, slots, _FINISH_BLOCK_SLOTS):
            block = slice(start, min(start + _FINISH_BLOCK_SLOTS, slots))
            background[block], open_sky[block], beyond[block] = self._surfaces(
                self._histogram[block]
            )
        norm = np.linalg.norm(self._direction_sum, axis=1)
        seen = ~open_sky & ~beyond & (norm > 0)
        points = self._direction_sum[seen] / norm[seen, None] * background[seen, None]
        ground = GroundGrid.from_points(points, settings.ground_cell_m) if len(points) else None
        return RangeImageBackground(
            background.astype(np.float32).reshape(self.shape), settings, ground
        )

    def _surfaces(self, histogram: npt.NDArray[np.uint8]) -> tuple[F64, Bool, Bool]:
        """Per slot of a block of the histogram: the background range, open sky, and a
        surface beyond ``max_range_m`` (both +inf)."""
        settings = self.settings
        # Support of a surface at bin b: its returns in bins b-1, b, b+1 (about +-1 margin).
        support = histogram.astype(np.uint16)
        support[:, 1:] += histogram[:, :-1]
        support[:, :-1] += histogram[:, 1:]
        bins = histogram.shape[1]
        shows = support >= settings.min_support_fraction * self.frames
        any_shows = shows.any(axis=1)
        chosen = bins - 1 - np.argmax(shows[:, ::-1], axis=1)  # the farthest that shows
        if settings.near_support_fraction < 1.0:
            near = support >= settings.near_support_fraction * self.frames
            has_near = near.any(axis=1)
            chosen = np.where(has_near, np.minimum(chosen, np.argmax(near, axis=1)), chosen)
        # The surface's range: the mean of the centres of bins b-1..b+1, each weighted by its
        # returns, leaving out a bin with under a tenth of them (a neighbouring surface's
        # tail). Within a quarter of a margin of the true range or so; the update's average
        # (``ema_weight``) then takes it the rest of the way.
        rows = np.arange(len(chosen))
        window_support = support[rows, chosen].astype(np.float64)
        weighted = np.zeros(len(chosen))
        weight = np.zeros(len(chosen))
        for offset in (-1, 0, 1):
            index = chosen + offset
            inside = (index >= 0) & (index < bins - 1)
            index = np.clip(index, 0, bins - 1)
            count = histogram[rows, index].astype(np.float64)
            use = inside & (count >= 0.1 * window_support)
            weighted[use] += count[use] * self._centres[index[use]]
            weight[use] += count[use]
        with np.errstate(invalid="ignore", divide="ignore"):
            background = weighted / weight
        # Beyond max_range_m (the last bin) is as good as open sky: nothing there is foreground.
        beyond: Bool = np.asarray(chosen == bins - 1)
        open_sky: Bool = np.asarray(~any_shows)
        background[open_sky | beyond | ~(weight > 0)] = np.inf
        return background, open_sky, beyond


def _range_bin_edges(settings: RangeBackgroundSettings) -> F64:
    """Lower edges of the learning histogram's bins [m]: from 0, each one margin wide (at
    least 5 cm), up to ``max_range_m``; the last edge opens the bin beyond it."""
    edges = [0.0]
    while edges[-1] < settings.max_range_m:
        edge = edges[-1]
        edges.append(edge + max(settings.margin_min_m, settings.margin_range_fraction * edge, 0.05))
    edges[-1] = settings.max_range_m
    return np.array(edges, dtype=np.float64)


# --------------------------------------------------------------------------------------------
# Voxel background
# --------------------------------------------------------------------------------------------


class VoxelBackground:
    """Occupancy of a voxel grid by the static background.

    The model is the sorted array of occupied voxel keys. For speed, :meth:`foreground_mask`
    looks points up in a dense bit table over the keys' bounding box (one bit per voxel, 64
    voxels of a column per word): about 1 ms for the 144k slots of the real 80-beam frame,
    where a ``searchsorted`` over the 90k keys takes about 8 ms. When the table would exceed
    ``max_table_bytes`` (a huge or fine grid) the lookup falls back to ``searchsorted``.

    Parameters
    ----------
    keys
        ``(V,)`` int64 keys (:func:`pack_keys`) of the background voxels; sorted and made unique
        here.
    voxel_m
        Voxel edge [m].
    ground
        Ground heights, or None when unknown.
    max_table_bytes
        Largest dense lookup table to build [bytes]; at most 2**31 words (int32 indices).
    """

    kind = "voxel"

    def __init__(
        self,
        keys: I64,
        voxel_m: float,
        ground: GroundGrid | None = None,
        *,
        max_table_bytes: int = 256 * 2**20,
    ) -> None:
        max_table_bytes = min(max_table_bytes, 8 * (2**31 - 1))
        if not voxel_m > 0:
            raise ValueError(f"voxel_m must be positive, got {voxel_m}")
        self.keys: I64 = np.unique(np.asarray(keys, dtype=np.int64))
        self.voxel_m = float(voxel_m)
        self.ground = ground
        self._table: U64 | None = None
        self._origin = np.zeros(3, dtype=np.int64)
        self._extent = np.zeros(3, dtype=np.int64)
        if len(self.keys):
            indices = unpack_keys(self.keys)
            origin, extent = indices.min(axis=0), np.ptp(indices, axis=0) + 1
            words = (int(extent[2]) + 63) // 64
            if words * int(extent[0]) * int(extent[1]) * 8 <= max_table_bytes:
                relative = indices - origin
                # Word-major layout: most points fall in the lowest 64 voxels of their column,
                # so lookups touch one compact plane of the table.
                table = np.zeros((words, int(extent[0]), int(extent[1])), dtype=np.uint64)
                bits = np.left_shift(np.uint64(1), (relative[:, 2] & 63).astype(np.uint64))
                np.bitwise_or.at(table, (relative[:, 2] >> 6, relative[:, 0], relative[:, 1]), bits)
                self._table = table
                self._origin, self._extent = origin, extent

    @property
    def num_voxels(self) -> int:
        return len(self.keys)

    @classmethod
    def from_points(
        cls,
        xyz_m: npt.ArrayLike,
        voxel_m: float = 0.5,
        *,
        dilate: bool = False,
        ground_cell_m: float = 1.0,
    ) -> VoxelBackground:
        """Background = the voxels that a background cloud occupies.

        Parameters
        ----------
        xyz_m
            ``(N, 3)`` background points [m] (e.g. an accumulated map); NaN rows are ignored.
        voxel_m
            Voxel edge [m].
        dilate
            Add the 26 neighbours of every occupied voxel.
        ground_cell_m
            Cell edge of the ground grid [m]; the ground is the lowest occupied voxel's centre
            in each cell (so within half a voxel of the true surface).
        """
        xyz = np.asarray(xyz_m, dtype=np.float64).reshape(-1, 3)
        xyz = xyz[np.isfinite(xyz).all(axis=1)]
        keys = np.unique(pack_keys(voxel_indices(xyz, voxel_m)))
        return cls._from_keys(keys, voxel_m, dilate, ground_cell_m)

    @classmethod
    def from_frames(
        cls,
        frames: Sequence[PointFrame],
        voxel_m: float = 0.5,
        *,
        min_occupancy_fraction: float = 0.3,
        dilate: bool = False,
        ground_cell_m: float = 1.0,
    ) -> VoxelBackground:
        """Background = voxels occupied in at least ``min_occupancy_fraction`` of the frames.

        Parameters
        ----------
        frames
            K >= 1 frames of a sensor that did not move (organized or not). Vehicles passing
            occupy a voxel in few frames and are left out.
        voxel_m
            Voxel edge [m].
        min_occupancy_fraction
            Fraction of the frames a voxel must be occupied in (0..1]. Keep it well under 0.5:
            a surface that lies on a voxel face (a flat road at a round height) splits its
            returns between two voxels, each occupied in about half the frames. Learn while
            traffic moves: a lane stopped for more than this fraction becomes background.
        dilate, ground_cell_m
            As in :meth:`from_points`.
        """
        if not frames:
            raise ValueError("learning a voxel background needs at least one frame")
        if not 0.0 < min_occupancy_fraction <= 1.0:
            raise ValueError(
                f"min_occupancy_fraction must be in (0, 1], got {min_occupancy_fraction}"
            )
        per_frame = []
        for frame in frames:
            xyz = _frame_xyz(frame)
            xyz = xyz[_valid(xyz)]
            per_frame.append(np.unique(pack_keys(voxel_indices(xyz, voxel_m))))
        keys, counts = np.unique(np.concatenate(per_frame), return_counts=True)
        keys = keys[counts >= min_occupancy_fraction * len(frames)]
        return cls._from_keys(keys, voxel_m, dilate, ground_cell_m)

    @classmethod
    def _from_keys(
        cls, keys: I64, voxel_m: float, dilate: bool, ground_cell_m: float
    ) -> VoxelBackground:
        centres = (unpack_keys(keys) + 0.5) * voxel_m
        ground = GroundGrid.from_points(centres, ground_cell_m) if len(keys) else None
        return cls(dilate_keys(keys) if dilate and len(keys) else keys, voxel_m, ground)

    def is_background(self, xyz_m: npt.ArrayLike) -> Bool:
        """Whether each ``(N, 3)`` point [m] falls in a background voxel (NaN rows: False)."""
        xyz = np.asarray(xyz_m, dtype=np.float32).reshape(-1, 3)
        if self._table is None:
            result = np.zeros(len(xyz), dtype=bool)
            valid = _valid(xyz)
            keys = pack_keys(voxel_indices(xyz[valid], self.voxel_m))
            result[valid] = _sorted_member(self.keys, keys)
            return result
        inside = np.ones(len(xyz), dtype=bool)
        cells = []
        scale = np.float32(1.0 / self.voxel_m)
        with np.errstate(invalid="ignore"):
            for axis in range(3):
                # float32 throughout: a point exactly on a voxel face may fall either side,
                # which a margin of one voxel (dilate) makes harmless.
                cell = np.floor(xyz[:, axis] * scale)
                cell -= np.float32(self._origin[axis])
                inside &= cell >= 0  # NaN compares False
                inside &= cell < self._extent[axis]
                # Outside (or NaN) cells cast to garbage; take(mode="clip") keeps the index in
                # the table and `inside` discards the answer.
                cells.append(cell.astype(np.int32))
        cx, cy, cz = cells
        extent_x, extent_y = int(self._extent[0]), int(self._extent[1])
        flat = (cz >> 6) * extent_x
        flat += cx
        flat *= extent_y
        flat += cy
        word = np.take(self._table, flat, mode="clip")
        bit = np.right_shift(word, (cz & 63).astype(np.uint64)) & np.uint64(1)
        found: Bool = inside & bit.astype(bool)
        return found

    def foreground_mask(self, frame: PointFrame) -> Bool:
        """Valid points whose voxel is not background.

        Returns
        -------
        Bool
            ``(N,)`` over ``frame.points``; points outside the model's extent are foreground.
        """
        xyz = _frame_xyz(frame)
        mask: Bool = _valid(xyz) & ~self.is_background(xyz)
        return mask

    def update(self, frame: PointFrame) -> None:
        """No-op: the voxel model is static (learn a new one to refresh it)."""

    def ground_z_m(self, xy_m: F64) -> F64:
        """Ground height [m] under ``(K, 2)`` x, y [m]; NaN where unknown."""
        return ground_height_at(self.ground, xy_m)

    def save(self, path: PathLike) -> None:
        """Write the model to ``path`` (``.npz``; the name is used as given)."""
        arrays = {"voxel_m": np.array(self.voxel_m), "keys": self.keys}
        _write_model(path, self.kind, arrays, self.ground)

    @classmethod
    def load(cls, path: PathLike, *, voxel_m: float | None = None) -> VoxelBackground:
        """Read a model written by :meth:`save`.

        Parameters
        ----------
        path
            The ``.npz`` file.
        voxel_m
            The voxel size the caller expects [m]; when given, a model of another size raises.

        Raises
        ------
        BackgroundFileError
            Not a voxel background, another format version, or another voxel size.
        """
        arrays = _read_npz(path, cls.kind, ("voxel_m", "keys"))
        stored = float(arrays["voxel_m"])
        if voxel_m is not None and not np.isclose(stored, voxel_m):
            raise BackgroundFileError(
                f"{os.fspath(path)}: background voxels of {stored} m, expected {voxel_m} m: "
                "learn the background again or change the setting"
            )
        ground = ground_from_arrays(arrays)
        return cls(np.asarray(arrays["keys"], dtype=np.int64), stored, ground)


def load_background(path: PathLike) -> RangeImageBackground | VoxelBackground:
    """Read either kind of model from ``path``, by the ``kind`` it holds."""
    try:
        with np.load(path, allow_pickle=False) as archive:
            kind = str(archive["kind"]) if "kind" in archive.files else ""
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        raise BackgroundFileError(
            f"{os.fspath(path)}: not a readable .npz file ({error})"
        ) from error
    if kind == RangeImageBackground.kind:
        return RangeImageBackground.load(path)
    if kind == VoxelBackground.kind:
        return VoxelBackground.load(path)
    raise BackgroundFileError(f"{os.fspath(path)}: not a background model (kind '{kind}')")


def learn_background_from_frames(
    frames: Sequence[PointFrame],
    *,
    range_settings: RangeBackgroundSettings | None = None,
    voxel_m: float = 0.5,
    min_occupancy_fraction: float = 0.3,
) -> RangeImageBackground | VoxelBackground:
    """The model that suits the frames: per-slot ranges when organized, else voxels.

    Parameters
    ----------
    frames
        K >= 1 frames of one sensor that did not move.
    range_settings
        For :class:`RangeImageBackground` (organized frames of one layout).
    voxel_m, min_occupancy_fraction
        For :class:`VoxelBackground` (otherwise).
    """
    if not frames:
        raise ValueError("learning a background needs at least one frame")
    first = frames[0]
    same_layout = all(
        frame.organized and (frame.rows, frame.columns) == (first.rows, first.columns)
        for frame in frames
    )
    if same_layout:
        return RangeImageBackground.learn(frames, range_settings)
    return VoxelBackground.from_frames(
        frames, voxel_m, min_occupancy_fraction=min_occupancy_fraction
    )
