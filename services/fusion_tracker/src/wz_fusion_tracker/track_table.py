"""The tracks' bookkeeping: per-track objects (:class:`Track`), per-track columns over the
state bank's slots (:class:`TrackTable`), and the store of every live and lost track
(:class:`TrackStore`) that the tracker's steps work on.

Like the states in the bank, the bookkeeping is held as arrays over the bank's slots, so a
cycle counts the hits of 200 tracks in a few vectorised operations, not 200 Python calls.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from wz_fusion_tracker.imm import IMMStateBank
from wz_fusion_tracker.kalman import TrackStateBank
from wz_fusion_tracker.types import UNKNOWN_CLASS, TrackerCounters, TrackHistory
from wz_shared.arrays import F64, IntP
from wz_shared.motion import STATE_DIM

#: The priors and posteriors of the tracks one batch updated, row k for its k-th track:
#: ``(stamp_s, x_pred (K, 4), P_pred (K, 4, 4), x_filt (K, 4), P_filt (K, 4, 4))``. A plain
#: tuple of a float and arrays: Python's garbage collector stops tracking it, and the entries
#: holding it, after one pass, where it would scan a dataclass or a NamedTuple in every full
#: collection, and 200 tracks keep up to ``max_history`` entries each.
UpdateRecord = tuple[float, F64, F64, F64, F64]
#: One update of a track: the batch's record and the track's row in it.
HistoryEntry = tuple[UpdateRecord, int]


@dataclass(slots=True, eq=False)
class Track:
    """The per-track objects of a live track: its id, slot, update history and, while it is
    tentative, its hit stamps. Its state lives in the bank and the rest of its bookkeeping in
    the tracker's :class:`TrackTable`, both at row ``slot``."""

    track_id: int
    slot: int
    max_history: int
    hit_stamps_s: deque[float] = field(default_factory=deque)
    history: deque[HistoryEntry] = field(init=False)
    #: When it was lost (``TrackerSettings.lost_memory_s``) [s].
    lost_s: float = math.nan
    #: Started on the speed prior along the road (``initial_speed_mps``), not a measured
    #: speed: what the hand-over takes out when it fuses an old track's speed with this one's.
    speed_from_prior: bool = False

    def __post_init__(self) -> None:
        self.history = deque(maxlen=self.max_history)

    def to_history(self) -> TrackHistory:
        stamps_s: list[float] = []
        x_pred: list[F64] = []
        P_pred: list[F64] = []
        x_filt: list[F64] = []
        P_filt: list[F64] = []
        for (stamp_s, batch_x_pred, batch_P_pred, batch_x_filt, batch_P_filt), k in self.history:
            stamps_s.append(stamp_s)
            x_pred.append(batch_x_pred[k])
            P_pred.append(batch_P_pred[k])
            x_filt.append(batch_x_filt[k])
            P_filt.append(batch_P_filt[k])
        return TrackHistory(
            track_id=self.track_id,
            stamps_s=np.array(stamps_s),
            x_filt=np.array(x_filt).reshape(-1, STATE_DIM),
            P_filt=np.array(P_filt).reshape(-1, STATE_DIM, STATE_DIM),
            x_pred=np.array(x_pred).reshape(-1, STATE_DIM),
            P_pred=np.array(P_pred).reshape(-1, STATE_DIM, STATE_DIM),
        )


class TrackTable:
    """The bookkeeping of every track as arrays over the bank's slots (row = slot).

    A cycle touches every live track (predict, gate) and every matched one (update, count the
    hit, vote the class, keep the size): done per track in Python that bookkeeping cost as much
    as the Kalman filter's maths for 200 tracks. As columns of arrays it is a handful of
    vectorised operations per batch. A row is reset when its slot is given to a new track.

    Attributes (row ``s``)
    ----------------------
    born_s, updated_s
        First and latest update [s].
    confirmed, confirmed_s, hits
        Life cycle: confirmed yet, when [s] (NaN: not yet), number of updates (the first
        detection included).
    heading_rad
        The road's heading at the latest update [rad], NaN where there is no road.
    sensor_updated_s
        Latest update by each sensor (column: :attr:`sensor_ids`) [s], -inf for never.
    class_weight, class_last_vote
        The class vote (column: :attr:`class_names`): summed scores, and the hit number of
        the latest vote (0: never), which breaks ties by recency.
    lengths_m, widths_m, length_count, width_count
        The last ``size_window`` measured lengths and widths, a ring per row (NaN: not yet
        filled; the next is written at ``count % size_window``), and how many were measured.
    """

    def __init__(self, size_window: int, capacity: int = 64) -> None:
        self.size_window = size_window
        self.sensor_ids: list[str] = []
        self._sensor_column: dict[str, int] = {}
        self.class_names: list[str] = []
        self._class_column: dict[str, int] = {}
        self.born_s = np.zeros(capacity)
        self.updated_s = np.zeros(capacity)
        self.confirmed = np.zeros(capacity, dtype=bool)
        self.confirmed_s = np.full(capacity, math.nan)
        self.hits = np.zeros(capacity, dtype=np.int64)
        self.heading_rad = np.full(capacity, math.nan)
        self.sensor_updated_s = np.full((capacity, 0), -math.inf)
        self.class_weight = np.zeros((capacity, 0))
        self.class_last_vote = np.zeros((capacity, 0), dtype=np.int64)
        self.lengths_m = np.full((capacity, size_window), math.nan)
        self.widths_m = np.full((capacity, size_window), math.nan)
        self.length_count = np.zeros(capacity, dtype=np.int64)
        self.width_count = np.zeros(capacity, dtype=np.int64)
        # running medians (and the length's upper quartile), recomputed when a size came
        self._sizes = np.full((capacity, 3), math.nan)  # median length, width, length q75
        self._sizes_stale = np.zeros(capacity, dtype=bool)

    # --- rows and columns ---

    def reset(self, slot: int, stamp_s: float, heading_rad: float | None) -> None:
        """Row ``slot`` for a new track first seen at ``stamp_s``, with no hit yet."""
        while slot >= len(self.updated_s):
            self._grow()
        self.born_s[slot] = self.updated_s[slot] = stamp_s
        self.confirmed[slot] = False
        self.confirmed_s[slot] = math.nan
        self.hits[slot] = 0
        self.heading_rad[slot] = math.nan if heading_rad is None else heading_rad
        self.sensor_updated_s[slot] = -math.inf
        self.class_weight[slot] = 0.0
        self.class_last_vote[slot] = 0
        self.lengths_m[slot] = self.widths_m[slot] = math.nan
        self.length_count[slot] = self.width_count[slot] = 0
        self._sizes[slot] = math.nan
        self._sizes_stale[slot] = False

    def _grow(self) -> None:
        """Double the rows (new rows are reset when their slot is taken)."""
        for name in (
            "born_s",
            "updated_s",
            "confirmed",
            "confirmed_s",
            "hits",
            "heading_rad",
            "sensor_updated_s",
            "class_weight",
            "class_last_vote",
            "lengths_m",
            "widths_m",
            "length_count",
            "width_count",
            "_sizes",
            "_sizes_stale",
        ):
            array = getattr(self, name)
            setattr(self, name, np.concatenate([array, np.zeros_like(array)]))

    def sensor_column(self, sensor_id: str) -> int:
        """The column of ``sensor_id`` in :attr:`sensor_updated_s` (added when new)."""
        column = self._sensor_column.get(sensor_id)
        if column is None:
            column = self._sensor_column[sensor_id] = len(self.sensor_ids)
            self.sensor_ids.append(sensor_id)
            never = np.full((len(self.updated_s), 1), -math.inf)
            self.sensor_updated_s = np.concatenate([self.sensor_updated_s, never], axis=1)
        return column

    def class_column(self, name: str) -> int:
        """The column of class ``name`` in the vote (added when new)."""
        column = self._class_column.get(name)
        if column is None:
            column = self._class_column[name] = len(self.class_names)
            self.class_names.append(name)
            rows = len(self.updated_s)
            self.class_weight = np.concatenate([self.class_weight, np.zeros((rows, 1))], axis=1)
            self.class_last_vote = np.concatenate(
                [self.class_last_vote, np.zeros((rows, 1), dtype=np.int64)], axis=1
            )
        return column

    def class_columns(self, names: Sequence[str]) -> IntP:
        """:meth:`class_column` of each of ``names``, shape (K,)."""
        lookup = self._class_column
        if not lookup.keys() >= set(names):
            for name in names:
                self.class_column(name)
        return np.fromiter(map(lookup.__getitem__, names), np.intp, len(names))

    # --- hits ---

    def record_hits(
        self,
        slots: IntP,
        stamp_s: float,
        sensor_column: int,
        class_columns: IntP,
        scores: F64,
        lengths_m: F64,
        widths_m: F64,
    ) -> None:
        """Count an update of each of ``slots`` (distinct) at ``stamp_s`` by one sensor: the
        hit, the class vote (``class_columns``, weighted by ``scores``), the measured sizes
        (NaN or <= 0: not measured); all shape (K,)."""
        self.hits[slots] += 1
        self.updated_s[slots] = stamp_s
        self.sensor_updated_s[slots, sensor_column] = stamp_s
        self.class_weight[slots, class_columns] += scores
        self.class_last_vote[slots, class_columns] = self.hits[slots]
        for values, ring, count in (
            (lengths_m, self.lengths_m, self.length_count),
            (widths_m, self.widths_m, self.width_count),
        ):
            measured = values > 0.0  # False for NaN
            if not measured.any():
                continue
            rows = slots[measured]
            ring[rows, count[rows] % self.size_window] = values[measured]
            count[rows] += 1
            self._sizes_stale[rows] = True

    def absorb(self, target: int, source: int) -> None:
        """Row ``target`` takes up the track of row ``source`` (a hand-over): its latest update,
        heading and per-sensor stamps, and its hits added; class vote and sizes stay."""
        self.updated_s[target] = self.updated_s[source]
        self.hits[target] += self.hits[source]
        self.heading_rad[target] = self.heading_rad[source]
        seen = np.isfinite(self.sensor_updated_s[source])
        self.sensor_updated_s[target, seen] = self.sensor_updated_s[source, seen]

    # --- read-outs ---

    def sizes(self, slots: IntP) -> F64:
        """Median measured length and width and the lengths' upper quartile of ``slots`` [m],
        shape (K, 3), NaN where not measured (the quartile: fewer than three lengths).

        The upper quartile is what the tracker's reference point takes as the track's length
        (``MultiTargetTracker._reference_point``): a partial view only shortens a box.
        """
        stale = slots[self._sizes_stale[slots]]
        if len(stale):
            self._sizes_stale[stale] = False
            window = self.size_window
            for column, ring, count in (
                (0, self.lengths_m, self.length_count),
                (1, self.widths_m, self.width_count),
            ):
                ordered = np.sort(ring[stale], axis=1)  # NaN (unfilled) last
                n = np.minimum(count[stale], window)
                has = n > 0
                low = np.take_along_axis(ordered, np.maximum(n - 1, 0)[:, None] // 2, axis=1)[:, 0]
                high = np.take_along_axis(ordered, (n // 2)[:, None], axis=1)[:, 0]
                self._sizes[stale, column] = np.where(has, (low + high) / 2.0, math.nan)
                if column == 0:
                    quartile = np.take_along_axis(
                        ordered, np.maximum((3 * (n - 1)) // 4, 0)[:, None], axis=1
                    )[:, 0]
                    self._sizes[stale, 2] = np.where(n >= 3, quartile, math.nan)
        return self._sizes[slots]

    def object_classes(self, slots: IntP) -> list[str]:
        """The class vote's winner of each of ``slots``: the largest summed score among the
        known classes voted for, ties to the latest vote; "unknown" with no known vote."""
        if not self.class_names:
            return [UNKNOWN_CLASS] * len(slots)
        votes = self.class_last_vote[slots]
        voted = votes > 0
        unknown = self._class_column.get(UNKNOWN_CLASS)
        if unknown is not None:
            voted[:, unknown] = False
        weight = np.where(voted, self.class_weight[slots], -math.inf)
        best = voted & (weight == weight.max(axis=1, keepdims=True))
        winner = np.argmax(np.where(best, votes, -1), axis=1)
        names = self.class_names
        any_known: list[bool] = np.any(voted, axis=1).tolist()
        return [
            names[c] if ok else UNKNOWN_CLASS
            for c, ok in zip(winner.tolist(), any_known, strict=True)
        ]

    def last_update_by_sensor(self, slot: int) -> dict[str, float]:
        """Latest update stamp per sensor that updated row ``slot`` [s]."""
        stamps = self.sensor_updated_s[slot].tolist()
        return {
            sensor: s for sensor, s in zip(self.sensor_ids, stamps, strict=True) if s != -math.inf
        }


class TrackStore:
    """Every track the tracker holds, and what follows a track's identity.

    Attributes
    ----------
    bank
        The tracks' states and covariances, one slot per live or lost track.
    table
        Their bookkeeping (:class:`TrackTable`), row = slot.
    tracks
        The live tracks by id, in id order.
    lost
        Confirmed tracks past their coast, kept ``lost_memory_s`` (their slots too), by id.
    local_ids
        ``(sensor_id, local_track_id)`` -> the id of the track it last updated.
    finished
        Histories of ended confirmed tracks, until popped.
    counters
        What the tracker has done (shared with it).
    """

    def __init__(
        self,
        bank: TrackStateBank | IMMStateBank,
        size_window: int,
        max_finished_histories: int,
        counters: TrackerCounters,
    ) -> None:
        self.bank = bank
        self.table = TrackTable(size_window)
        self.tracks: dict[int, Track] = {}
        self.lost: dict[int, Track] = {}
        self.local_ids: dict[tuple[str, int], int] = {}
        self.finished: deque[TrackHistory] = deque(maxlen=max_finished_histories)
        self.counters = counters
        # tracks' values and their slots, rebuilt after tracks changes (changed())
        self._live_cache: tuple[list[Track], IntP] | None = None

    def live(self) -> tuple[list[Track], IntP]:
        """The live tracks in id order and their slots (cached until :meth:`changed`)."""
        if self._live_cache is None:
            live = list(self.tracks.values())
            self._live_cache = (live, np.array([t.slot for t in live], dtype=np.intp))
        return self._live_cache

    def changed(self) -> None:
        """To be called whenever a track enters or leaves :attr:`tracks`."""
        self._live_cache = None
