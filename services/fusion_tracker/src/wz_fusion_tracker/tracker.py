"""Multi-target tracker over asynchronous sensors: one track per vehicle in the site frame.

The product's tracker. Sensors (a LiDAR at 20 Hz, a camera with the radar fused in at 10 Hz)
publish batches of detections with their own stamps; :class:`MultiTargetTracker` turns them into
tracks with stable ids. Its parts follow the steps of a tracker (as in Stone Soup and Autoware's
multi_object_tracker), each in its own module:

- :mod:`~wz_fusion_tracker.settings`: its parameters (:class:`TrackerSettings`);
- :mod:`~wz_fusion_tracker.types`: what goes in and out (:class:`Measurement`,
  :class:`TrackState`, :class:`TrackHistory`, :class:`TrackerCounters`);
- :mod:`~wz_fusion_tracker.association`: gating, costs, assignment, Huber's inflation;
- :mod:`~wz_fusion_tracker.updater`: the measurement models (position, radar speed along the
  road), the speed gate and the batched update, returning what it did;
- :mod:`~wz_fusion_tracker.track_table`: every track's bookkeeping as arrays over the state
  bank's slots;
- :mod:`~wz_fusion_tracker.identity`: re-acquisition, hand-over, duplicate merging, retirement;
- here: the reorder window and the cycle.

**Reorder window.** Batches arrive a little out of stamp order (each sensor has its own latency)
and a Kalman filter cannot predict backwards. :meth:`MultiTargetTracker.add` therefore buffers
batches and processes, in stamp order, every batch older than ``newest stamp seen -
reorder_window_s``; :meth:`~MultiTargetTracker.flush` processes the rest. A batch arriving with
a stamp before the last processed one is beyond the window: it is counted in
``counters.batches_late`` and dropped. The price is ``reorder_window_s`` of latency; the gain is
that any arrival order within the window gives exactly the same tracks. Equal stamps are
processed by sensor id, so that too does not depend on arrival order.

**One cycle per batch** (:meth:`MultiTargetTracker._process`), at the batch's stamp ``t``:

1. *prune*: delete tentative tracks not updated for ``tentative_max_age_s`` and confirmed ones
   not updated for ``max_coast_s`` (a deleted confirmed track is *lost* for ``lost_memory_s``
   more: not published, but its id may resume);
2. *predict* every live track from its own last update to ``t`` (``dt`` may be 0); a track's
   stored state only ever changes at an update, so a prediction for gating costs nothing when
   the track is not matched; one constant-velocity model
   (:class:`~wz_fusion_tracker.kalman.TrackStateBank`) or, with ``motion_model="imm"``, two
   mixed (:class:`~wz_fusion_tracker.imm.IMMStateBank`);
3. *associate*: gate, cost and assign (:mod:`~wz_fusion_tracker.association`), confirmed
   tracks served before tentative ones;
4. *update* the matched tracks in one batched Kalman update (position, then the radar's
   along-road speed where given and a road heading is known), then re-acquire confirmed tracks
   that missed updates with measurements left near them;
5. *spawn* a tentative track from each unmatched measurement of a sensor allowed to start
   tracks (``track_start_sensor_ids``: a clutter-prone channel may only continue tracks);
   tentative -> confirmed after ``confirm_hits`` updates within ``confirm_window_s``, and no
   sooner than ``confirm_min_age_s`` after its first detection; a confirmed track not updated
   for ``coasting_after_s`` reports "coasting". Ids increase from 1 and are never reused;
6. *identity*: the hand-over (a young track of a vehicle come back gives it its old id) and
   duplicate merging (:mod:`~wz_fusion_tracker.identity`).

**Process noise.** White-noise acceleration, road-aligned
(:func:`~wz_shared.motion.road_aligned_q`): ``sigma_along`` along the direction of
travel, ``sigma_across`` across it. The direction is the road's heading at the track's position
when the tracker is given a ``heading_at(x, y)`` hook, otherwise the track's own velocity
heading once it moves faster than ``heading_min_speed_mps``, otherwise isotropic with
``sigma_along``. The acceleration is held over each prediction step (from a track's last
update), so across the road it is ``min(sigma_across, max_across_speed_change_mps / dt)``
(:func:`capped_across`): a vehicle's sideways velocity changes by about a lane change's peak
sideways speed at most, however long it goes unseen. Uncapped, a track coasting for a second
moved 1.5 m across (1 sigma) and its gate took a car one lane over.

**Radar speed.** A detection's ``speed_mps`` (the radar's speed along the road) is used, when a
``heading_at`` hook gives the road heading ``h``, as a second measurement of the matched track:
``z = speed``, ``H = [0, 0, cos h, sin h]``, ``R = speed_std_mps^2``; and to initialise a new
track's velocity. Without a hook it is ignored (its direction would be unknown).

**Per track** the tracker also keeps a class vote (weighted by score; "unknown" never outvotes a
known class), running medians of the measured length and width, the last update stamp per
sensor, and the history needed for RTS smoothing (the prior and posterior of every update, see
:func:`wz_shared.motion.rts_smooth`), in
:class:`~wz_fusion_tracker.track_table.TrackTable`.

Nothing here does I/O: the node converts bus messages to :class:`Measurement`, calls
:meth:`MultiTargetTracker.add`, and publishes :meth:`MultiTargetTracker.tracks`.
"""

from __future__ import annotations

import heapq
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from wz_fusion_tracker.association import (
    association_cost,
    cascade_assign_pairs,
    gated_pairs,
    huber_inflated,
    local_id_bonus,
    speed_gated,
)
from wz_fusion_tracker.identity import (
    IDENTITY_PERIOD_S,
    hand_over,
    merge_duplicates,
    merge_into_trucks,
    reacquisitions,
)
from wz_fusion_tracker.imm import IMMStateBank
from wz_fusion_tracker.kalman import TrackStateBank
from wz_fusion_tracker.life_cycle import (
    HiddenFromSensors,
    InSensorGap,
    Sight,
    check_confirmation,
    expired,
    prune,
    start_track,
)
from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.track_table import Track, TrackStore, UpdateRecord
from wz_fusion_tracker.types import (
    HeadingAt,
    HeadingsAt,
    Measurement,
    TrackerCounters,
    TrackHistory,
    TrackState,
    TrackStatus,
)
from wz_fusion_tracker.updater import UpdateOutcome, reference_points, update_matched
from wz_shared.arrays import F64, IntP

__all__ = [
    "Measurement",
    "MultiTargetTracker",
    "TrackHistory",
    "TrackState",
    "TrackerCounters",
    "TrackerSettings",
]

_log = logging.getLogger(__name__)

#: The gated pairs of a batch: track rows, measurement columns, squared Mahalanobis
#: distances (inf where the radar speed forbids the pair) and ``ln det S``, (K,) each.
_Gated = tuple[IntP, IntP, F64, F64]


def capped_across(sigma_across_mps2: npt.ArrayLike, dt_s: npt.ArrayLike, cap_mps: float) -> F64:
    """The acceleration std across the road for a prediction of ``dt_s`` [s]:
    ``min(sigma_across, cap / dt)``, so that the velocity change across it allows
    (``sigma dt``: the acceleration is held over the step) is at most ``cap_mps`` [m/s], about
    a lane change's peak sideways speed, however long a track goes unseen; ``cap_mps`` 0:
    ``sigma_across`` unchanged. Shape: ``sigma_across_mps2`` and ``dt_s`` broadcast."""
    sigma = np.asarray(sigma_across_mps2, dtype=np.float64)
    dt = np.asarray(dt_s, dtype=np.float64)
    if cap_mps <= 0.0:
        return np.broadcast_to(sigma, np.broadcast_shapes(sigma.shape, dt.shape)).copy()
    capped: F64 = np.minimum(sigma, cap_mps / dt)
    return capped


@dataclass(order=True, slots=True)
class _PendingBatch:
    stamp_s: float
    sensor_id: str
    arrival: int
    measurements: Sequence[Measurement] = field(compare=False)


@dataclass(frozen=True, slots=True, eq=False)
class _Batch:
    """One sensor batch in the cycle, its measurements also as arrays: positions ``z`` (M, 2)
    [m], covariances ``R`` (M, 2, 2) [m^2], capture-time offsets (M,) [s] (None: all zero),
    radar speeds along the road (M,) [m/s] (NaN: none)."""

    sensor_id: str
    stamp_s: float
    measurements: Sequence[Measurement]
    z: F64
    R: F64
    time_offset_s: F64 | None
    speeds: F64

    @classmethod
    def of(cls, sensor_id: str, stamp_s: float, measurements: Sequence[Measurement]) -> _Batch:
        n = len(measurements)
        # column by column: faster than a list of [x, y] lists
        z = np.stack(
            [
                np.fromiter([m.x_m for m in measurements], np.float64, n),
                np.fromiter([m.y_m for m in measurements], np.float64, n),
            ],
            axis=1,
        )
        R = np.concatenate([m.covariance_m2 for m in measurements], dtype=np.float64).reshape(
            -1, 2, 2
        )
        offsets = np.fromiter([m.time_offset_s for m in measurements], np.float64, n)
        speeds = np.fromiter(
            [math.nan if m.speed_mps is None else m.speed_mps for m in measurements], np.float64, n
        )
        return cls(
            sensor_id,
            stamp_s,
            measurements,
            z,
            R,
            offsets if np.any(offsets != 0.0) else None,
            speeds,
        )


# ----------------------------------------------------------------------------- the tracker


class MultiTargetTracker:
    """Tracks vehicles from asynchronous sensor batches (see the module docstring).

    Parameters
    ----------
    settings
        Motion model, gate, channels, life cycle and timing.
    heading_at
        Road heading [rad, counter-clockwise from east] at a site position ``(x_m, y_m)``;
        None: no road prior (process noise follows each track's own velocity, radar speeds are
        ignored). A non-finite return means "no road here".
    headings_at
        ``heading_at`` for arrays of positions (the same values), used where many tracks need
        the road's heading at once (a road-frame lookup per point costs a quarter of a
        millisecond); only with ``heading_at``.
    sensor_positions
        Site position of each sensor ``(x_m, y_m)``; with it, a box completed from the face a
        sensor sees is re-centred with the track's own length (:meth:`_reference_point`).
    in_sensor_gap
        Whether a site point ``(x_m, y_m)`` lies in a stretch no sensor sees between seen
        road (:class:`wz_shared.coverage.SensorGaps`); with ``coast_sensor_gaps``, a confirmed
        track predicted there coasts up to ``max_gap_coast_s`` instead of ``max_coast_s``;
        a lost one predicted there is remembered up to ``max_gap_memory_s``.
        None: no such stretch.
    hidden_from_sensors
        Whether other vehicles (boxes) hide each of some site points from every sensor that
        covers it (:meth:`wz_shared.coverage.SiteSight.hidden`); with it, a
        confirmed track hidden so coasts up to ``max_occlusion_coast_s`` and a lost one is
        remembered up to ``max_occlusion_memory_s``. None: not known.
    first_track_id
        The first track's id (a tracker that takes over from another in the same process, for
        a new run, goes on from :attr:`next_track_id` of the old one: ids are never reused).
    """

    def __init__(
        self,
        settings: TrackerSettings,
        heading_at: HeadingAt | None = None,
        sensor_positions: Mapping[str, tuple[float, float]] | None = None,
        headings_at: HeadingsAt | None = None,
        first_track_id: int = 1,
        in_sensor_gap: InSensorGap | None = None,
        hidden_from_sensors: HiddenFromSensors | None = None,
    ) -> None:
        self.settings = settings
        self._sight = Sight(in_sensor_gap, hidden_from_sensors)
        self._heading_at = heading_at
        self._headings_at = headings_at if heading_at is not None else None
        self._sensor_positions = dict(sensor_positions or {})
        bank: TrackStateBank | IMMStateBank = (
            IMMStateBank((settings.imm_steady_sojourn_s, settings.imm_manoeuvre_sojourn_s))
            if settings.motion_model == "imm"
            else TrackStateBank()
        )
        # the live and lost tracks, their states, bookkeeping and sensor local ids
        self._store = TrackStore(
            bank, settings.size_window, settings.max_finished_histories, TrackerCounters()
        )
        # d2 is compared with these gates only: beyond the widest, pairs need not be computed
        # (a little over it, for rounding)
        self._widest_gate_chi2 = 1.01 * max(settings.gate_chi2, settings.spawn_gate_chi2)
        if first_track_id < 1:
            raise ValueError(f"track ids start at 1 or more, got {first_track_id}")
        self._next_id = first_track_id
        self._pending: list[_PendingBatch] = []  # a heap by (stamp, sensor, arrival)
        self._arrivals = 0
        self._newest_stamp_s = -math.inf
        self._last_processed_s: float | None = None
        self._next_identity_s = -math.inf  # the next hand-over and merging (data time)
        self._last_batch_s: dict[str, float] = {}  # newest processed batch stamp per sensor

    # --- input ---

    def add(self, sensor_id: str, stamp_s: float, measurements: Sequence[Measurement]) -> int:
        """Accept one sensor batch; process every buffered batch now older than the window.

        Parameters
        ----------
        sensor_id
            The sensor that produced the batch.
        stamp_s
            The batch's measurement time [s].
        measurements
            Its detections (possibly none: an empty batch still tells the time).

        Returns
        -------
        processed
            Number of batches processed by this call (0 when the batch was late).

        Raises
        ------
        ValueError
            ``stamp_s`` is not finite, or a measurement names another sensor.
        """
        if not math.isfinite(stamp_s):
            raise ValueError(f"batch stamp of {sensor_id!r} must be finite, got {stamp_s}")
        for measurement in measurements:
            if measurement.sensor_id is not None and measurement.sensor_id != sensor_id:
                raise ValueError(
                    f"a measurement of sensor {measurement.sensor_id!r} came in a batch of "
                    f"{sensor_id!r}"
                )
        self._store.counters.batches_received += 1
        if self._last_processed_s is not None and stamp_s < self._last_processed_s:
            self._store.counters.batches_late += 1
            _log.debug(
                "late batch dropped: sensor=%s stamp=%.3f s, last processed %.3f s",
                sensor_id,
                stamp_s,
                self._last_processed_s,
            )
            return 0
        heapq.heappush(
            self._pending, _PendingBatch(stamp_s, sensor_id, self._arrivals, tuple(measurements))
        )
        self._arrivals += 1
        self._newest_stamp_s = max(self._newest_stamp_s, stamp_s)
        return self._release(self._newest_stamp_s - self.settings.reorder_window_s)

    def flush(self) -> int:
        """Process every buffered batch now, in stamp order; the number processed."""
        return self._release(math.inf)

    def advance_to(self, stamp_s: float) -> int:
        """Tell the tracker the time is ``stamp_s`` [s] though no batch came (sensors silent).

        Processes the batches older than ``stamp_s - reorder_window_s`` and prunes the tracks at
        that time, which also makes any later batch before it late.

        Returns
        -------
        processed
            Number of batches processed.
        """
        self._newest_stamp_s = max(self._newest_stamp_s, stamp_s)
        horizon_s = self._newest_stamp_s - self.settings.reorder_window_s
        processed = self._release(horizon_s)
        if self._last_processed_s is None or horizon_s > self._last_processed_s:
            self._last_processed_s = horizon_s
            prune(self._store, self.settings, horizon_s, self._last_batch_s, self._sight)
        return processed

    def _release(self, horizon_s: float) -> int:
        processed = 0
        while self._pending and self._pending[0].stamp_s <= horizon_s:
            batch = heapq.heappop(self._pending)
            self._process(batch.sensor_id, batch.stamp_s, batch.measurements)
            processed += 1
        return processed

    # --- output ---

    @property
    def counters(self) -> TrackerCounters:
        """A copy of the counters."""
        return replace(self._store.counters)

    @property
    def next_track_id(self) -> int:
        """The id the next new track will get."""
        return self._next_id

    @property
    def last_processed_stamp_s(self) -> float | None:
        """Stamp of the latest processed batch (or :meth:`advance_to` horizon) [s]."""
        return self._last_processed_s

    @property
    def pending_batches(self) -> int:
        """Batches buffered in the reorder window."""
        return len(self._pending)

    def tracks(self, stamp_s: float | None = None) -> list[TrackState]:
        """Snapshots of the live tracks, by increasing id; the tracker is not changed.

        Parameters
        ----------
        stamp_s
            Predict every track to this time [s] (not before the last processed stamp); tracks
            that would be deleted by then are left out. None: each track as of its latest
            update, status as of the last processed stamp.

        Returns
        -------
        tracks
            Tentative, confirmed and coasting tracks; filter by ``status`` as needed.

        Raises
        ------
        ValueError
            ``stamp_s`` is before the last processed stamp.
        """
        if (
            stamp_s is not None
            and self._last_processed_s is not None
            and stamp_s < self._last_processed_s
        ):
            raise ValueError(
                f"tracks asked at {stamp_s:.6f} s, before the last processed stamp "
                f"({self._last_processed_s:.6f} s)"
            )
        reference_s = stamp_s if stamp_s is not None else self._last_processed_s
        live, slots = self._store.live()
        if reference_s is not None and live:
            kept = ~expired(
                self._store,
                self.settings,
                slots,
                reference_s,
                self._last_batch_s,
                self._sight,
            )
            if not kept.all():
                live = [t for t, k in zip(live, kept.tolist(), strict=True) if k]
                slots = slots[kept]
        if not live:
            return []
        if stamp_s is None:
            x, P = self._store.bank.states(slots), self._store.bank.covariances(slots)
            stamps = self._store.bank.stamps_s(slots)
        else:
            x, P = self._predicted(slots, stamp_s)
            stamps = np.full(len(live), stamp_s)
        table, settings = self._store.table, self.settings
        status_s = stamps if reference_s is None else np.full(len(live), reference_s)
        since_update = status_s - table.updated_s[slots]
        confirmed = table.confirmed[slots].tolist()
        coasting = (since_update > settings.coasting_after_s).tolist()
        status: list[TrackStatus] = [
            "tentative" if not c else "coasting" if late else "confirmed"
            for c, late in zip(confirmed, coasting, strict=True)
        ]
        classes = table.object_classes(slots)
        sizes = table.sizes(slots)[:, :2]
        sizes_list = np.where(np.isfinite(sizes), sizes, -1.0).tolist()  # -1: not measured
        sensor_stamps = table.sensor_updated_s[slots]
        sources = status_s[:, None] - sensor_stamps <= settings.sources_window_s
        sensor_ids = table.sensor_ids
        x_list, stamps_list = x.tolist(), stamps.tolist()
        hits, age = table.hits[slots].tolist(), (status_s - table.born_s[slots]).tolist()
        since_list = since_update.tolist()
        snapshots = []
        for row, track in enumerate(live):
            state = x_list[row]
            length, width = sizes_list[row]
            snapshots.append(
                TrackState(
                    track_id=track.track_id,
                    stamp_s=stamps_list[row],
                    x_m=state[0],
                    y_m=state[1],
                    vx_mps=state[2],
                    vy_mps=state[3],
                    P=P[row],
                    status=status[row],
                    object_class=classes[row],
                    length_m=None if length < 0.0 else length,
                    width_m=None if width < 0.0 else width,
                    sources=tuple(
                        sorted(sensor_ids[c] for c in np.flatnonzero(sources[row]).tolist())
                    ),
                    hits=hits[row],
                    age_s=age[row],
                    time_since_update_s=since_list[row],
                    last_update_s_by_sensor=table.last_update_by_sensor(track.slot),
                )
            )
        return snapshots

    def history(self, track_id: int) -> TrackHistory:
        """The stored updates of live track ``track_id`` (KeyError when it is not live)."""
        return self._store.tracks[track_id].to_history()

    def unfinished_histories(self) -> list[TrackHistory]:
        """Histories of the confirmed tracks not ended yet, by id: the live ones (confirmed or
        coasting) and the lost ones (``lost_memory_s``), which :meth:`pop_finished_histories`
        gives only once they end. For a run that stops now; the tracker is not changed."""
        confirmed = self._store.table.confirmed
        unfinished = [t for t in self._store.tracks.values() if confirmed[t.slot]]
        unfinished += self._store.lost.values()
        return [t.to_history() for t in sorted(unfinished, key=lambda t: t.track_id)]

    def pop_finished_histories(self) -> list[TrackHistory]:
        """Histories of the confirmed tracks ended since the last call, oldest first (a
        confirmed track ends ``lost_memory_s`` after it is deleted, unless it resumes)."""
        finished = list(self._store.finished)
        self._store.finished.clear()
        return finished

    # --- one cycle ---

    def _process(self, sensor_id: str, stamp_s: float, measurements: Sequence[Measurement]) -> None:
        """One cycle at the batch's stamp: prune, predict, associate, update, identity, spawn.

        The order: prune the tracks expired by ``stamp_s``; predict every live track to it;
        gate and associate the measurements; update the matched tracks; re-acquire confirmed
        tracks that missed updates with measurements left near them; spawn tentative tracks
        from the measurements still left; then hand-over and duplicate merging.
        """
        prune(self._store, self.settings, stamp_s, self._last_batch_s, self._sight)
        self._last_processed_s = stamp_s
        self._store.counters.batches_processed += 1
        self._last_batch_s[sensor_id] = stamp_s
        self._store.counters.measurements_processed += len(measurements)
        if not measurements:
            return
        batch = _Batch.of(sensor_id, stamp_s, measurements)
        live, slots = self._store.live()
        pairs: list[tuple[int, int]] = []
        gated = None
        if live:
            x_pred, P_pred = self._predicted(slots, stamp_s)
            gated = self._gate(slots, x_pred, P_pred, batch)
            rows, columns, d2 = self._associate(live, slots, gated, batch)
            if len(rows):
                pairs = list(zip(rows.tolist(), columns.tolist(), strict=True))
                self._update_associated(live, slots, x_pred, P_pred, rows, columns, d2, batch)
            if self.settings.reacquire_along_m > 0.0:
                pairs = pairs + self._reacquire(live, slots, x_pred, P_pred, pairs, batch)
        if self.settings.may_start_tracks(sensor_id):
            self._spawn_unmatched(batch, pairs, slots, gated)
        self._identity(stamp_s)

    def _gate(self, slots: IntP, x_pred: F64, P_pred: F64, batch: _Batch) -> _Gated:
        """The (track row, measurement column) pairs within the widest gate, their squared
        Mahalanobis distances (inf where the radar speed forbids the pair) and ``ln det S``."""
        settings = self.settings
        pair_rows, pair_columns, d2, log_det_S = gated_pairs(
            x_pred, P_pred, batch.z, batch.R, batch.time_offset_s, self._widest_gate_chi2
        )
        if settings.speed_association_chi2 > 0.0 and self._heading_at is not None:
            d2 = speed_gated(
                d2,
                pair_rows,
                pair_columns,
                x_pred,
                P_pred,
                self._store.table.heading_rad[slots],
                batch.speeds,
                settings,
            )
        return pair_rows, pair_columns, d2, log_det_S

    def _associate(
        self, live: Sequence[Track], slots: IntP, gated: _Gated, batch: _Batch
    ) -> tuple[IntP, IntP, F64]:
        """The matched track rows, measurement columns and their d2: confirmed tracks first,
        each stage a global nearest neighbour on ``d^2 + ln det S - local id bonus``."""
        pair_rows, pair_columns, d2, log_det_S = gated
        bonus = local_id_bonus(
            self.settings.local_track_id_bonus,
            (track.track_id for track in live),
            self._store.local_ids,
            batch.sensor_id,
            batch.measurements,
            pair_rows,
            pair_columns,
        )
        cost = association_cost(d2, log_det_S, bonus)
        allowed = np.flatnonzero(d2 <= self.settings.gate_chi2)
        picked = allowed[
            cascade_assign_pairs(
                cost[allowed],
                pair_rows[allowed],
                pair_columns[allowed],
                self._store.table.confirmed[slots],
            )
        ]
        return pair_rows[picked], pair_columns[picked], d2[picked]

    def _update_associated(
        self,
        live: Sequence[Track],
        slots: IntP,
        x_pred: F64,
        P_pred: F64,
        rows: IntP,
        columns: IntP,
        d2: F64,
        batch: _Batch,
    ) -> None:
        """Update the associated tracks: outliers' covariances widened (Huber), boxes seen from
        one end re-centred with the track's length (:meth:`_reference_point`)."""
        R_used = huber_inflated(batch.R, columns, d2, self.settings.huber_k)
        z_used = reference_points(
            self._store.table,
            self.settings.reference_point_min_m,
            self._sensor_positions.get(batch.sensor_id),
            slots,
            rows,
            columns,
            batch.z,
            batch.measurements,
        )
        self._update_matched(
            [live[row] for row in rows.tolist()],
            rows,
            columns,
            slots,
            x_pred,
            P_pred,
            z_used,
            R_used,
            batch,
        )

    def _reacquire(
        self,
        live: Sequence[Track],
        slots: IntP,
        x_pred: F64,
        P_pred: F64,
        pairs: Sequence[tuple[int, int]],
        batch: _Batch,
    ) -> list[tuple[int, int]]:
        """Re-acquisition (:func:`~wz_fusion_tracker.identity.reacquisitions`) and the update of
        the tracks it takes up; the pairs it made."""
        new_pairs, P_wide = reacquisitions(
            self._store,
            self.settings,
            slots,
            x_pred,
            P_pred,
            batch.z,
            pairs,
            batch.stamp_s,
            batch.time_offset_s,
        )
        if new_pairs:
            self._update_matched(
                [live[row] for row, _ in new_pairs],
                np.array([row for row, _ in new_pairs], dtype=np.intp),
                np.array([column for _, column in new_pairs], dtype=np.intp),
                slots,
                x_pred,
                P_wide,
                batch.z,
                batch.R,
                batch,
            )
        return new_pairs

    def _spawn_unmatched(
        self, batch: _Batch, pairs: Sequence[tuple[int, int]], slots: IntP, gated: _Gated | None
    ) -> None:
        """Start a tentative track from each measurement no track took, unless it lies within
        ``spawn_gate_chi2`` of a confirmed track (that vehicle's outlier) or is too uncertain
        to locate a vehicle (``spawn_max_std_m``)."""
        settings, R = self.settings, batch.R
        unmatched = np.ones(len(batch.measurements), dtype=bool)
        unmatched[[column for _, column in pairs]] = False
        candidates = np.flatnonzero(unmatched)  # by increasing column
        if gated is not None and settings.spawn_gate_chi2 > 0.0 and len(candidates):
            # the measurements near a track confirmed as of now (the update may have
            # confirmed some)
            pair_rows, pair_columns, d2, _ = gated
            near = (d2 < settings.spawn_gate_chi2) & self._store.table.confirmed[slots[pair_rows]]
            near_confirmed = np.isin(candidates, pair_columns[near])
            self._store.counters.measurements_suppressed += int(np.count_nonzero(near_confirmed))
            candidates = candidates[~near_confirmed]
        if settings.spawn_max_std_m > 0.0 and len(candidates):
            # largest eigenvalue of each 2x2 R: (a + c) / 2 + sqrt(((a - c) / 2)^2 + b^2)
            a, b, c = R[candidates, 0, 0], R[candidates, 0, 1], R[candidates, 1, 1]
            largest = 0.5 * (a + c) + np.sqrt((0.5 * (a - c)) ** 2 + b * b)
            located = largest <= settings.spawn_max_std_m**2
            self._store.counters.measurements_unlocated += int(np.count_nonzero(~located))
            candidates = candidates[located]
        for column in candidates.tolist():
            measurement = batch.measurements[column]
            heading = self._road_heading(measurement.x_m, measurement.y_m)
            start_track(
                self._store,
                settings,
                self._next_id,
                measurement,
                R[column],
                batch.sensor_id,
                batch.stamp_s,
                heading,
            )
            self._next_id += 1

    def _identity(self, stamp_s: float) -> None:
        """Every ``IDENTITY_PERIOD_S`` of data time: the hand-over (a vehicle come back gets its
        old id), then duplicate merging. Each has its own switch (``hand_over_along_m``,
        ``merge_distance_m``): turning merging off leaves the hand-over on."""
        store = self._store
        if len(store.tracks) + len(store.lost) < 2 or stamp_s < self._next_identity_s:
            return
        self._next_identity_s = stamp_s + IDENTITY_PERIOD_S
        hand_over(store, self.settings, stamp_s, self._sight.in_sensor_gap, self._predicted)
        merge_duplicates(store, self.settings, stamp_s)
        merge_into_trucks(store, self.settings, stamp_s)

    def _predicted(self, slots: IntP, stamp_s: float) -> tuple[F64, F64]:
        """The states of ``slots`` predicted to ``stamp_s`` with each track's process noise.

        Along the road's heading where the track has one, else along its own velocity when it
        moves at ``heading_min_speed_mps`` or more, else isotropic (``sigma_along`` both ways).
        """
        settings = self.settings
        x = self._store.bank.states(slots)
        heading = np.arctan2(x[:, 3], x[:, 2])
        oriented = np.hypot(x[:, 2], x[:, 3]) >= settings.heading_min_speed_mps
        if self._heading_at is not None:
            road = self._store.table.heading_rad[slots]
            known = np.isfinite(road)
            heading = np.where(known, road, heading)
            oriented = oriented | known
        # the sideways velocity change a step allows is capped (max_across_speed_change_mps)
        dt = np.maximum(stamp_s - self._store.bank.stamps_s(slots), 1e-9)
        cap = settings.max_across_speed_change_mps
        if settings.motion_model == "cv":
            sigma_across = capped_across(settings.sigma_across_mps2, dt, cap)
            sigma_across = np.where(oriented, sigma_across, settings.sigma_along_mps2)
            return self._store.bank.predicted(
                slots, stamp_s, settings.sigma_along_mps2, sigma_across, heading
            )
        # per mode: (steady, manoeuvre)
        along = np.array([settings.imm_steady_sigma_along_mps2, settings.sigma_along_mps2])
        across = np.where(
            oriented[:, None],
            capped_across(
                np.array([settings.imm_steady_sigma_across_mps2, settings.sigma_across_mps2]),
                dt[:, None],
                cap,
            ),
            along,
        )
        return self._store.bank.predicted(slots, stamp_s, along, across, heading)

    def _update_matched(
        self,
        tracks: Sequence[Track],
        rows: IntP,
        columns: IntP,
        slots: IntP,
        x_pred: F64,
        P_pred: F64,
        z: F64,
        R: F64,
        batch: _Batch,
    ) -> UpdateOutcome:
        """Update the tracks ``tracks`` (rows ``rows`` of ``slots``) with the measurements
        ``columns`` of the batch, positions ``z`` (M, 2) and covariances ``R`` (M, 2, 2), from
        the priors ``x_pred`` (T, 4), ``P_pred`` (T, 4, 4): one batched Kalman update of the
        positions, then of the radar speeds along the road
        (:func:`~wz_fusion_tracker.updater.update_matched`); then the hits, class votes,
        sizes, history and confirmation. What the update did, also added to the counters."""
        settings = self.settings
        sensor_id, stamp_s, measurements = batch.sensor_id, batch.stamp_s, batch.measurements
        speeds, time_offset_s = batch.speeds, batch.time_offset_s
        table, bank = self._store.table, self._store.bank
        matched_slots = slots[rows]
        # the prior: each matched track predicted to the batch's stamp
        x_prior, P_prior = x_pred[rows], P_pred[rows]
        self._store.bank.commit_prior(matched_slots, x_prior, P_prior, stamp_s)
        # positions, then the radar speeds along the road's heading at the updated tracks
        outcome = update_matched(
            bank,
            settings,
            matched_slots,
            z[columns],
            R[columns],
            None if time_offset_s is None else time_offset_s[columns],
            None if self._heading_at is None else self._road_headings,
            speeds[columns],
        )
        if outcome.road_heading_rad is not None:
            table.heading_rad[matched_slots] = outcome.road_heading_rad
        self._store.counters.speeds_rejected += outcome.speeds_rejected

        # the hits: class vote, sizes, per-sensor stamps, all matched tracks at once
        columns_list = columns.tolist()  # Python ints index the measurements faster
        matched = [measurements[column] for column in columns_list]
        k = len(matched)
        table.record_hits(
            matched_slots,
            stamp_s,
            table.sensor_column(sensor_id),
            table.class_columns([m.object_class for m in matched]),
            np.fromiter([m.score for m in matched], np.float64, k),
            # a length completed from the far end is the class's guess grown from a part (the
            # near end unseen), not a measure of this vehicle: it does not enter the track's size
            np.fromiter(
                [
                    math.nan if m.length_m is None or m.completed_from_far_end else m.length_m
                    for m in matched
                ],
                np.float64,
                k,
            ),
            np.fromiter(
                [math.nan if m.width_m is None else m.width_m for m in matched], np.float64, k
            ),
        )
        # The batch's priors and posteriors, copied once (fancy indexing copies); each track's
        # history entry is this record and its row (not four views and an object per track).
        record: UpdateRecord = (
            stamp_s,
            x_prior,
            P_prior,
            bank.states(matched_slots),
            bank.covariances(matched_slots),
        )
        for i, track in enumerate(tracks):
            track.history.append((record, i))
        for measurement, track in zip(matched, tracks, strict=True):
            if measurement.local_track_id is not None:
                self._store.local_ids[(sensor_id, measurement.local_track_id)] = track.track_id
        for i in np.flatnonzero(~table.confirmed[matched_slots]).tolist():
            # a confirmed track has no hits left to count
            tracks[i].hit_stamps_s.append(stamp_s)
            check_confirmation(self._store, self.settings, tracks[i], stamp_s)
        return outcome

    def _road_headings(self, xy: F64) -> F64:
        """The road's heading at each site position (K, 2) [rad]; NaN where there is none
        (only with ``heading_at``)."""
        assert self._heading_at is not None
        if self._headings_at is not None:
            road = np.asarray(self._headings_at(xy[:, 0], xy[:, 1]), dtype=np.float64)
        else:
            road = np.array([self._heading_at(x, y) for x, y in xy.tolist()], dtype=np.float64)
        return np.where(np.isfinite(road), road, math.nan)

    def _road_heading(self, x_m: float, y_m: float) -> float | None:
        if self._heading_at is None:
            return None
        heading = float(self._heading_at(x_m, y_m))
        return heading if math.isfinite(heading) else None
