"""Multi-target tracker over asynchronous sensors: one track per vehicle in the site frame.

The product's tracker. Sensors (a LiDAR at 20 Hz, a camera with the radar fused in at 10 Hz)
publish batches of detections with their own stamps; :class:`MultiTargetTracker` turns them into
tracks with stable ids. Its parts follow the steps of a tracker (as in Stone Soup and Autoware's
multi_object_tracker), each a small function or method:

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
   not updated for ``max_coast_s``;
2. *predict* every live track from its own last update to ``t`` (``dt`` may be 0); a track's
   stored state only ever changes at an update, so a prediction for gating costs nothing when
   the track is not matched; one constant-velocity model (:class:`~wz_fusion_tracker.kalman.TrackStateBank`)
   or, with ``motion_model="imm"``, two mixed (:class:`~wz_fusion_tracker.imm.IMMStateBank`);
3. *gate*: squared Mahalanobis distance of each (track, measurement) pair,
   ``d^2 = y^T S^-1 y``, ``y = z - H x_p``, ``S = H P_p H^T + R`` (vectorised, and only for
   the pairs a cheap bound cannot rule out: :func:`_candidate_pairs`); pairs with
   ``d^2 > gate_chi2`` are forbidden. Mahalanobis rather than metres because the
   sensors' errors are far from round: a camera ranges badly along its line of sight and well
   across it, and a track's predicted uncertainty is long along the road (``road_aligned_q``),
   so a fixed radius in metres would be too tight one way and too loose the other;
4. *associate*: global nearest neighbour, the one-to-one assignment minimising the total cost
   (:func:`gnn_assign`, ``scipy.optimize.linear_sum_assignment``), the cost being the
   innovation's negative log-likelihood ``d^2 + ln det S`` (:func:`association_cost`).
   Greedy nearest-first goes wrong where it matters: two cars side by side in adjacent lanes,
   3.6 m apart. Confirmed tracks are served first, tentative ones get the measurements left
   (:func:`cascade_assign`): a spurious track started by one outlying detection, uncertain and
   close to a real vehicle, must not steal the real track's next detections;
5. *update* the matched tracks in one batched Kalman update (position, then the radar's
   along-road speed where given and a road heading is known);
6. *spawn* a tentative track from each unmatched measurement of a sensor allowed to start
   tracks (``track_start_sensor_ids``: a clutter-prone channel may only continue tracks);
7. *life cycle*: tentative -> confirmed after ``confirm_hits`` updates within
   ``confirm_window_s``, and no sooner than ``confirm_min_age_s`` after its first detection;
   a confirmed track not updated for ``coasting_after_s`` reports
   "coasting", and is deleted after ``max_coast_s``. Ids increase from 1 and are never reused;
   a deleted confirmed track is *lost* for ``lost_memory_s`` more (not published), and resumes
   its id if its vehicle comes back as a new track (:meth:`MultiTargetTracker._hand_over`).

**Identity prior.** Each sensor has its own tracker and tags detections with a
``local_track_id``. When a measurement's ``(sensor_id, local_track_id)`` last updated track T,
the pair's cost is lowered by ``local_track_id_bonus`` (units of ``-2 ln likelihood``), so the sensor's own
continuity breaks near-ties, e.g. two similar cars at the same range. It only ranks pairs that
pass the gate: a stale or switched local id can never force a pair the gate refuses.

**Process noise.** White-noise acceleration, road-aligned (:func:`~wz_fusion_tracker.kalman.road_aligned_q`):
``sigma_along`` along the direction of travel, ``sigma_across`` across it. The direction is
the road's heading at the track's position when the tracker is given a ``heading_at(x, y)``
hook, otherwise the track's own velocity heading once it moves faster than
``heading_min_speed_mps``, otherwise isotropic with ``sigma_along``.

**Radar speed.** A detection's ``speed_mps`` (the radar's speed along the road) is used, when a
``heading_at`` hook gives the road heading ``h``, as a second measurement of the matched track:
``z = speed``, ``H = [0, 0, cos h, sin h]``, ``R = speed_std_mps^2``; and to initialise a new
track's velocity. Without a hook it is ignored (its direction would be unknown).

**Per track** the tracker also keeps a class vote (weighted by score; "unknown" never outvotes a
known class), running medians of the measured length and width, the last update stamp per
sensor, and the history needed for RTS smoothing (the prior and posterior of every update, see
:func:`wz_fusion_tracker.smoothing.rts_smooth`). Like the states in the bank, that bookkeeping
is held as arrays over the bank's slots (:class:`_TrackTable`), so a cycle counts the hits of
200 tracks in a few vectorised operations, not 200 Python calls.

Nothing here does I/O: the node converts bus messages to :class:`Measurement`, calls
:meth:`MultiTargetTracker.add`, and publishes :meth:`MultiTargetTracker.tracks`.
"""

from __future__ import annotations

import heapq
import logging
import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy.optimize import linear_sum_assignment

from wz_fusion_tracker.imm import IMMStateBank
from wz_fusion_tracker.kalman import F64, STATE_DIM, TrackStateBank

_log = logging.getLogger(__name__)

IntP = npt.NDArray[np.intp]
TrackStatus = Literal["tentative", "confirmed", "coasting"]
HeadingAt = Callable[[float, float], float]
HeadingsAt = Callable[[F64, F64], npt.ArrayLike]

#: The class a detector reports when it cannot tell; never outvotes a known class.
UNKNOWN_CLASS = "unknown"

#: Cost of a forbidden pair in the assignment: above any sum of allowed costs.
_FORBIDDEN_COST = 1e9

#: No pairs: an empty index array (read-only, shared).
_NO_INDEX: IntP = np.zeros(0, dtype=np.intp)
_NO_INDEX.flags.writeable = False


class TrackerSettings(BaseModel):
    """Parameters of :class:`MultiTargetTracker`; metres and seconds of the site frame."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    # --- motion model ---
    #: Std of the white acceleration along the direction of travel [m/s^2]. Drivers brake
    #: hard approaching a lane closure (the simulator's aggressive ones at 6-9 m/s^2): with
    #: 2.0 a braking vehicle left its track's gate and came back under a new id; 3.5 follows
    #: it (measured with ``wz eval``: 5 identity switches in 10 minutes instead of 7).
    sigma_along_mps2: float = Field(default=3.5, gt=0.0)
    #: Std of the white acceleration across it [m/s^2]. Not small: at a lane drop drivers
    #: merge, late ones sharply, and a merge reverses its lateral velocity within 2-3 s; the
    #: white-noise model must let the track follow that. Swept with ``wz eval`` on one 600 s
    #: recording (fused lateral RMSE within 150 m): 0.25: 0.23 m, 0.5: 0.20, 1: 0.18, 2: 0.165,
    #: 3: 0.158, 4.5: 0.169; at 3 also the fewest identity switches (1) and false positives.
    sigma_across_mps2: float = Field(default=3.0, gt=0.0)
    #: "cv": one constant-velocity model with the stds above. "imm": an interacting multiple
    #: model (:mod:`wz_fusion_tracker.imm`) of two: *steady* (the ``imm_steady_*`` stds: lane
    #: keeping) and *manoeuvre* (the stds above: braking, merging). Measured with ``wz eval``
    #: on one 600 s recording (seed 7, within 150 m; docs/fusion-tracker.md): the IMM lowers
    #: the speed RMSE (0.34 -> 0.29 m/s) but not the position error (lateral 0.159 m with
    #: "cv", 0.161-0.179 m with the IMM variants tried) and it costs identity switches
    #: (2 -> 3-4: the steady mode is slow to let go when a driver brakes hard), so "cv" is the
    #: default.
    motion_model: Literal["cv", "imm"] = "cv"
    #: The steady mode's acceleration std along the road [m/s^2].
    imm_steady_sigma_along_mps2: float = Field(default=0.5, gt=0.0)
    #: ... and across it [m/s^2].
    imm_steady_sigma_across_mps2: float = Field(default=0.3, gt=0.0)
    #: Mean time a vehicle stays steady before it manoeuvres [s].
    imm_steady_sojourn_s: float = Field(default=10.0, gt=0.0)
    #: Mean time a manoeuvre lasts [s].
    imm_manoeuvre_sojourn_s: float = Field(default=2.0, gt=0.0)
    #: Without a road heading hook, below this speed a track's heading is not trusted and the
    #: process noise is isotropic (``sigma_along`` both ways) [m/s].
    heading_min_speed_mps: float = Field(default=2.0, ge=0.0)

    # --- association ---
    #: A pair with squared Mahalanobis distance above this is never associated (13.8: the
    #: 99.9 % quantile of chi-square with 2 degrees of freedom) [-].
    gate_chi2: float = Field(default=13.8, gt=0.0)
    #: Cost reduction of a pair whose (sensor, local_track_id) last updated that track, in
    #: units of the cost, ``-2 ln likelihood`` (4: a likelihood ratio of e^2 = 7.4) [-].
    local_track_id_bonus: float = Field(default=4.0, ge=0.0)
    #: Huber's threshold on the Mahalanobis distance ``d`` of a matched pair [sigmas]: beyond
    #: it the measurement's covariance is scaled by ``d / huber_k`` (a heavy-tailed outlier
    #: moves the track by about ``huber_k`` sigmas); 0 turns it off. Both detectors' errors
    #: are heavy-tailed (camera-radar across the road at 60-100 m: std 0.12-0.24 m, robust std
    #: 0.05-0.12 m). Measured with ``wz eval`` on four 600 s recordings (seeds 7, 11, 13, 17,
    #: a bias map from another seed), 2.5 against off: identity switches 8 against 10, the
    #: stored trajectories' paper table 9 in 10 on all four seeds against three, position RMSE
    #: within 0.006 m, speed RMSE 0.004-0.009 m/s higher (docs/fusion-tracker.md).
    huber_k: float = Field(default=2.5, ge=0.0)

    # --- channels ---
    #: Sensor ids whose unmatched detections start tracks; None: every sensor.
    track_start_sensor_ids: tuple[str, ...] | None = None

    # --- life cycle ---
    #: Updates (the first included) within ``confirm_window_s`` that confirm a track.
    confirm_hits: int = Field(default=5, ge=1)
    #: Window over which ``confirm_hits`` are counted [s].
    confirm_window_s: float = Field(default=1.0, gt=0.0)
    #: A track is confirmed no sooner than this after its first detection [s]: with a 20 Hz
    #: and a 10 Hz sensor, 3 hits take 50 ms, too short to tell a vehicle (or a velocity) from
    #: a burst of noise.
    confirm_min_age_s: float = Field(default=0.2, ge=0.0)
    #: A tentative track not updated for longer than this is deleted [s].
    tentative_max_age_s: float = Field(default=0.5, gt=0.0)
    #: A confirmed track not updated for longer than this reports "coasting" [s].
    coasting_after_s: float = Field(default=0.3, ge=0.0)
    #: A confirmed track not updated for longer than this is deleted [s].
    max_coast_s: float = Field(default=1.5, gt=0.0)
    #: ... unless a sensor that saw it has sent nothing for ``sensor_silent_after_s``
    #: (a sensor outage, a network drop): then it coasts up to this [s].
    max_outage_coast_s: float = Field(default=5.0, gt=0.0)
    sensor_silent_after_s: float = Field(default=0.5, gt=0.0)
    #: A confirmed track past its coast is kept this long more as *lost* [s]: not published,
    #: taking no measurement, but a young track of its vehicle come back (the hand-over's
    #: tests, ``hand_over_*``) gives the vehicle its old id back. A car hidden behind a truck
    #: at 100-120 m for 3 s (the LiDAR and camera both in its shadow) otherwise comes back
    #: under a new id. 0 turns it off.
    lost_memory_s: float = Field(default=3.0, ge=0.0)

    # --- timing ---
    #: Batches are held this long behind the newest stamp seen, then processed in order [s].
    reorder_window_s: float = Field(default=0.15, ge=0.0)
    #: A sensor is a track's source in a snapshot if it updated it within this before it [s].
    sources_window_s: float = Field(default=0.25, ge=0.0)
    #: A confirmed track not updated for this long [s] may be taken up by an unmatched
    #: measurement within ``reacquire_along_m`` along its direction and ``reacquire_across_m``
    #: across it [m] (see ``MultiTargetTracker._reacquire``); 0 m turns it off. A following
    #: car in the same lane is at least ~6 m behind, the next lane 3.6 m across.
    reacquire_after_s: float = Field(default=0.2, ge=0.0)
    reacquire_along_m: float = Field(default=4.0, ge=0.0)
    reacquire_across_m: float = Field(default=1.2, ge=0.0)
    #: A track younger than this [s] next to a coasting track, within ``hand_over_along_m``
    #: along the road [m] (and ``reacquire_across_m`` across), is its vehicle come back: it
    #: hands its state to the old track (see ``MultiTargetTracker._hand_over``). 0 turns it off.
    hand_over_age_s: float = Field(default=1.0, ge=0.0)
    hand_over_along_m: float = Field(default=10.0, ge=0.0)
    #: ... and within this across it [m]: a vehicle that changed lanes while unseen (the
    #: merge at the taper starts under the mast, in the LiDAR's blind spot) comes back one
    #: lane (3.6 m) over. A vehicle alongside that was there all along has its own track.
    hand_over_across_m: float = Field(default=4.5, ge=0.0)
    #: A vehicle that braked (or sped up) while unseen comes back with a speed unlike its
    #: old track's, beyond ``merge_velocity_difference_mps``. It is still handed over when a
    #: change of speed at no more than this along the road [m/s^2], over the time since the
    #: old track's last update, explains both its speed and where it is: behind (or ahead of)
    #: the old track's constant-velocity prediction by between ``dv^2 / (2 a)`` (braking as
    #: late as possible) and ``|dv| T - dv^2 / (2 a)`` (as early as possible), within
    #: ``hand_over_kinematic_slack_m``; and the young track started after the old one was
    #: last seen. A car braking at 1.9 m/s^2 hidden behind a truck for 1.6 s came back
    #: 4.1 m/s slower and 3.6 m behind (seed 13). 0 turns it off.
    hand_over_max_accel_mps2: float = Field(default=4.0, ge=0.0)
    hand_over_kinematic_slack_m: float = Field(default=2.0, ge=0.0)
    #: A coasting or lost track moving across the road faster than this [m/s] is not handed a
    #: vehicle: a lane change peaks at 1-1.5 m/s, and a track sliding sideways at 3 m/s
    #: follows no vehicle (a ghost on split boxes, which a few stray detections beside it
    #: would otherwise publish again: seed 13, 38 false-positive samples). It ends instead,
    #: and the young track beside it carries on.
    hand_over_max_lateral_speed_mps: float = Field(default=2.5, gt=0.0)
    #: A box whose length differs from the track's by at least this is re-centred with the
    #: track's length, when the sensor's position is known (``MultiTargetTracker._reference_point``)
    #: [m]; 0 turns it off.
    reference_point_min_m: float = Field(default=1.5, ge=0.0)
    #: An unmatched measurement within this squared Mahalanobis distance of a confirmed track
    #: starts no track: it is that vehicle's outlier (a box fit gone wrong, a biased camera
    #: range), not a new vehicle. A vehicle alongside, in the next lane 3.6 m away, is far
    #: beyond it (about 11 sigma for a 0.3 m lateral std).
    spawn_gate_chi2: float = Field(default=60.0, ge=0.0)
    #: An unmatched measurement whose position is this uncertain (largest std of its R) starts
    #: no track [m]; it may still update one. A camera alone ranges a vehicle by its box's
    #: bottom row, good to a metre or two within 100 m and off by tens of metres near the
    #: horizon: a vehicle at 250 m was ranged at 197 m and, closing in, gave a ghost track
    #: that drifted onto the real vehicle at a third of its speed. Radar-paired and LiDAR
    #: positions are well under it. 0 turns it off.
    spawn_max_std_m: float = Field(default=4.0, ge=0.0)
    #: Two tracks closer than this, moving alike, are one vehicle tracked twice (a sensor's
    #: biased measurement that missed the gate started a second track): the younger is
    #: deleted [m]. Adjacent lanes are 3.6 m apart and a following car at least ~5 m behind,
    #: so 2.5 m never merges two vehicles. 0 turns merging off.
    merge_distance_m: float = Field(default=2.5, ge=0.0)
    #: ... and their velocities differ by less than this [m/s].
    merge_velocity_difference_mps: float = Field(default=4.0, gt=0.0)

    # --- initialisation ---
    #: Std of a new track's unknown velocity (along the road, with a road prior) [m/s].
    initial_velocity_std_mps: float = Field(default=15.0, gt=0.0)
    #: With a road heading hook: std of a new track's velocity across the road [m/s].
    initial_across_velocity_std_mps: float = Field(default=2.0, gt=0.0)
    #: With a road heading hook and no radar speed: a new track's speed along the road [m/s].
    initial_speed_mps: float = 0.0

    # --- radar speed ---
    #: Use a detection's ``speed_mps`` when a road heading hook is given.
    use_speed_measurements: bool = True
    #: Std of a radar speed along the road [m/s].
    speed_std_mps: float = Field(default=0.5, gt=0.0)
    #: A radar speed whose squared normalised innovation exceeds this is not used (10.8: the
    #: 99.9 % quantile of chi-square with 1 degree of freedom) [-].
    speed_gate_chi2: float = Field(default=10.8, gt=0.0)
    #: A measurement whose radar speed is this far outside a track's speed (squared
    #: normalised innovation, see :meth:`MultiTargetTracker._speed_gated`) is not that
    #: track's: the pair is forbidden, and the track does not keep the measurement from
    #: starting one [-]; 0 turns it off. Doppler-aided gating: at 150-200 m a speeder
    #: overtaking in the next lane is 3.6 m across but 8-12 m/s faster, and its camera box
    #: was taken up by the slower car's track (the speed refused by ``speed_gate_chi2``, the
    #: speeder never tracked until it had braked). 50 (about 4 m/s for a settled track) is
    #: loose, for a hard-braking vehicle's track lags its radar speed. Measured with ``wz eval``
    #: on two 600 s recordings (seeds 7 and 11; docs/fusion-tracker.md): speeding recall
    #: 0.972 / 0.941 -> 0.972 / 0.971, late merge 0.968 / 0.935 -> 0.968 / 0.968; at 10.8,
    #: identity switches on seed 11 went 3 -> 5.
    speed_association_chi2: float = Field(default=50.0, ge=0.0)

    # --- bookkeeping ---
    #: Measured lengths and widths kept per track for their running median.
    size_window: int = Field(default=50, ge=1)
    #: Updates kept per track for smoothing (the oldest are dropped).
    max_history: int = Field(default=2000, ge=1)
    #: Histories of deleted confirmed tracks kept until popped (the oldest are dropped).
    max_finished_histories: int = Field(default=1000, ge=0)

    @model_validator(mode="after")
    def _check_life_cycle(self) -> TrackerSettings:
        if self.coasting_after_s >= self.max_coast_s:
            raise ValueError(
                f"coasting_after_s ({self.coasting_after_s}) must be below max_coast_s "
                f"({self.max_coast_s}): a track coasts before it is deleted"
            )
        return self

    def may_start_tracks(self, sensor_id: str) -> bool:
        """Whether unmatched detections of ``sensor_id`` start tracks."""
        return self.track_start_sensor_ids is None or sensor_id in self.track_start_sensor_ids


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class Measurement:
    """One detection as the tracker sees it (the node converts bus messages to this).

    Attributes
    ----------
    x_m, y_m
        Position in the site frame [m].
    covariance_m2
        Its covariance, shape (2, 2), symmetric positive definite [m^2].
    sensor_id
        The sensor that made it; None: the sensor of the batch it comes in.
    object_class
        "car", "truck", "bus", "motorcycle" or "unknown".
    score
        Detection confidence in [0, 1]; weights the class vote.
    length_m, width_m
        Measured size [m], None when not measured.
    speed_mps
        Speed along the road (radar) [m/s], None when not measured.
    local_track_id
        The sensor's own track id of the object, None when it has none.
    time_offset_s
        When it was captured after its batch's stamp [s] (a spinning LiDAR's column time);
        the update uses ``H = [I  delta I]``.
    """

    x_m: float
    y_m: float
    covariance_m2: F64
    sensor_id: str | None = None
    object_class: str = UNKNOWN_CLASS
    score: float = 1.0
    length_m: float | None = None
    width_m: float | None = None
    speed_mps: float | None = None
    local_track_id: int | None = None
    time_offset_s: float = 0.0


@dataclass(frozen=True, slots=True, eq=False)
class TrackState:
    """A snapshot of one track.

    Attributes
    ----------
    track_id
        Unique for the tracker's lifetime, from 1, never reused.
    stamp_s
        Time the state refers to [s].
    x_m, y_m, vx_mps, vy_mps
        State [m, m/s].
    P
        State covariance, shape (4, 4) [m^2, m^2/s, m^2/s^2].
    status
        "tentative", "confirmed" (updated within ``coasting_after_s``) or "coasting".
    object_class
        The class vote's winner.
    length_m, width_m
        Running medians of the measured size [m], None before any measurement.
    sources
        Sensors that updated the track within ``sources_window_s`` before ``stamp_s``, sorted.
    hits
        Number of updates, the first detection included.
    age_s
        Time since the first detection [s].
    time_since_update_s
        Time since the latest update [s].
    last_update_s_by_sensor
        Latest update stamp per sensor [s].
    """

    track_id: int
    stamp_s: float
    x_m: float
    y_m: float
    vx_mps: float
    vy_mps: float
    P: F64
    status: TrackStatus
    object_class: str
    length_m: float | None
    width_m: float | None
    sources: tuple[str, ...]
    hits: int
    age_s: float
    time_since_update_s: float
    last_update_s_by_sensor: Mapping[str, float]

    @property
    def speed_mps(self) -> float:
        """``|v| = sqrt(vx^2 + vy^2)`` [m/s]."""
        return math.hypot(self.vx_mps, self.vy_mps)

    @property
    def heading_rad(self) -> float:
        """``atan2(vy, vx)``, counter-clockwise from east [rad]."""
        return math.atan2(self.vy_mps, self.vx_mps)


@dataclass(frozen=True, slots=True, eq=False)
class TrackHistory:
    """The updates of one track, for :func:`~wz_fusion_tracker.smoothing.rts_smooth`.

    Entry ``k`` is the update at ``stamps_s[k]``: ``x_pred``/``P_pred`` the prior it started
    from (predicted from update ``k - 1``; for the first entry, the initial state itself) and
    ``x_filt``/``P_filt`` its posterior. Shapes (n,), (n, 4), (n, 4, 4).
    """

    track_id: int
    stamps_s: F64
    x_filt: F64
    P_filt: F64
    x_pred: F64
    P_pred: F64


@dataclass(slots=True)
class TrackerCounters:
    """What the tracker has done since it was created (for the node's status)."""

    batches_received: int = 0
    batches_processed: int = 0
    batches_late: int = 0
    measurements_processed: int = 0
    tracks_started: int = 0
    tracks_confirmed: int = 0
    tracks_deleted: int = 0
    #: Deleted as the duplicate of an older track (:attr:`TrackerSettings.merge_distance_m`).
    tracks_merged: int = 0
    #: Measurements that took up a track outside its gate (:meth:`_reacquire`).
    tracks_reacquired: int = 0
    #: Young tracks that handed their vehicle back to a coasting track (:meth:`_hand_over`).
    tracks_handed_over: int = 0
    #: ... of which to a lost track (``lost_memory_s``), which then lived again.
    tracks_resumed: int = 0
    #: Coasting or lost tracks ended by :meth:`_hand_over` in favour of the young track that
    #: took their vehicle up: its id was published already, or the old track slid across the
    #: road (``hand_over_max_lateral_speed_mps``).
    tracks_superseded: int = 0
    #: Unmatched measurements that started no track, being near a confirmed one
    #: (:attr:`TrackerSettings.spawn_gate_chi2`).
    measurements_suppressed: int = 0
    #: Unmatched measurements that started no track, their position too uncertain
    #: (:attr:`TrackerSettings.spawn_max_std_m`).
    measurements_unlocated: int = 0
    #: Radar speeds outside their gate (:attr:`TrackerSettings.speed_gate_chi2`), not used.
    speeds_rejected: int = 0


# ----------------------------------------------------------------------------- association


def innovation_statistics(
    x_pred: F64, P_pred: F64, z: F64, R: F64, time_offset_s: F64 | None = None,
    max_d2: float = 1e3,
) -> tuple[F64, F64]:  # fmt: skip
    """Squared Mahalanobis distance and ``ln det S`` of every (track, measurement) pair.

    ::

        y = z_j - H_j x_i,   S = H_j P_i H_j^T + R_j,   d^2_ij = y^T S^-1 y

    with ``H_j = [I  delta_j I]``: measurement ``j`` was captured ``delta_j`` after the batch's
    stamp (a spinning LiDAR's column time), so it sees the position ``p + delta_j v`` (process
    noise over a fraction of a sweep is neglected); ``delta = 0`` gives ``H = [I 0]``. The 2x2
    inverse is written out: ``d^2 = (S_11 y_0^2 - (S_01 + S_10) y_0 y_1 + S_00 y_1^2) / det S``.

    Parameters
    ----------
    x_pred, P_pred
        Predicted states (T, 4) and covariances (T, 4, 4).
    z, R
        Measured positions (M, 2) [m] and their covariances (M, 2, 2) [m^2].
    time_offset_s
        ``delta`` per measurement (M,) [s], or None for all zero.
    max_d2
        The largest ``d^2`` the caller compares with (its widest gate): with many pairs, a
        pair certainly beyond it is not computed (see :func:`_sparse_innovation_statistics`).

    Returns
    -------
    d2, log_det_S
        Both of shape (T, M); ``d2`` exact up to ``max_d2``, a pair beyond it may be given
        ``_FAR_D2`` (and ``log_det_S`` 0) instead.
    """
    n_tracks, n_meas = len(x_pred), len(z)
    if n_tracks * n_meas > _SPARSE_GATE_MIN_PAIRS:
        return _sparse_innovation_statistics(x_pred, P_pred, z, R, time_offset_s, max_d2)
    # (T, M) arrays element by element, from (T, 1) track and (1, M) measurement columns
    y0 = z[None, :, 0] - x_pred[:, 0, None]
    y1 = z[None, :, 1] - x_pred[:, 1, None]
    s00 = P_pred[:, 0, 0, None] + R[None, :, 0, 0]
    s01 = P_pred[:, 0, 1, None] + R[None, :, 0, 1]
    s10 = P_pred[:, 1, 0, None] + R[None, :, 1, 0]
    s11 = P_pred[:, 1, 1, None] + R[None, :, 1, 1]
    if time_offset_s is not None:
        d = time_offset_s[None, :]
        y0 = y0 - d * x_pred[:, 2, None]
        y1 = y1 - d * x_pred[:, 3, None]
        P = P_pred
        s00 = s00 + d * (P[:, 0, 2, None] + P[:, 2, 0, None]) + d * d * P[:, 2, 2, None]
        s11 = s11 + d * (P[:, 1, 3, None] + P[:, 3, 1, None]) + d * d * P[:, 3, 3, None]
        s01 = s01 + d * (P[:, 0, 3, None] + P[:, 2, 1, None]) + d * d * P[:, 2, 3, None]
        s10 = s10 + d * (P[:, 1, 2, None] + P[:, 3, 0, None]) + d * d * P[:, 3, 2, None]
    det = s00 * s11 - s01 * s10
    d2: F64 = (s11 * y0 * y0 - (s01 + s10) * y0 * y1 + s00 * y1 * y1) / det
    return d2, np.log(det)


#: Duplicate tracks are looked for at most this often (data time) [s].
_MERGE_PERIOD_S = 0.1
#: A track confirmed this long ago [s] has been in a published snapshot (the node publishes
#: at 10 Hz): see :meth:`MultiTargetTracker._hand_over`.
_PUBLISHED_AFTER_S = 0.1

#: Above this many (track, measurement) pairs, gating first discards the pairs that cannot pass.
_SPARSE_GATE_MIN_PAIRS = 2000
#: d2 given to the pairs the pre-gate discards (beyond any gate the caller uses).
_FAR_D2 = 1e12


def _sparse_innovation_statistics(
    x_pred: F64, P_pred: F64, z: F64, R: F64, time_offset_s: F64 | None, max_d2: float
) -> tuple[F64, F64]:
    """:func:`innovation_statistics` on the pairs that can be near (:func:`_candidate_pairs`):
    the rest get ``_FAR_D2``."""
    rows, cols, pair_d2, pair_log_det = _candidate_statistics(x_pred, P_pred, z, R,
                                                              time_offset_s, max_d2)  # fmt: skip
    d2 = np.full((len(x_pred), len(z)), _FAR_D2)
    log_det = np.zeros((len(x_pred), len(z)))
    d2[rows, cols] = pair_d2
    log_det[rows, cols] = pair_log_det
    return d2, log_det


def _candidate_statistics(
    x_pred: F64, P_pred: F64, z: F64, R: F64, time_offset_s: F64 | None, max_d2: float
) -> tuple[IntP, IntP, F64, F64]:
    """The pairs of :func:`_candidate_pairs` with their d2 and ln det S, (K,) each."""
    rows, cols = _candidate_pairs(x_pred, P_pred, z, R, time_offset_s, max_d2)
    offsets = None if time_offset_s is None else time_offset_s[cols]
    d2, log_det = _pair_statistics(x_pred[rows], P_pred[rows], z[cols], R[cols], offsets)
    return rows, cols, d2, log_det


def _gated_pairs(
    x_pred: F64, P_pred: F64, z: F64, R: F64, time_offset_s: F64 | None, max_d2: float
) -> tuple[IntP, IntP, F64, F64]:
    """The (track, measurement) pairs with ``d^2 <= max_d2``, as arrays: what
    :func:`innovation_statistics` gives, without the (T, M) matrices.

    The tracker's cycle works on these: with 200 tracks and 200 measurements a track has a
    handful of pairs within any gate, and each (T, M) operation (fill, add, compare, search)
    costs more than all the pair-wise work.

    Returns
    -------
    rows, columns, d2, log_det_S
        Track rows, measurement columns, squared Mahalanobis distances and ``ln det S``, shape
        (K,) each, by increasing row.
    """
    if len(x_pred) * len(z) > _SPARSE_GATE_MIN_PAIRS:
        rows, cols, d2, log_det = _candidate_statistics(x_pred, P_pred, z, R, time_offset_s,
                                                        max_d2)  # fmt: skip
    else:
        d2_all, log_det_all = innovation_statistics(x_pred, P_pred, z, R, time_offset_s)
        rows, cols = _allowed_pairs(d2_all <= max_d2)
        d2, log_det = d2_all[rows, cols], log_det_all[rows, cols]
    within = d2 <= max_d2
    return rows[within], cols[within], d2[within], log_det[within]


def _candidate_pairs(
    x_pred: F64, P_pred: F64, z: F64, R: F64, time_offset_s: F64 | None, max_d2: float
) -> tuple[IntP, IntP]:
    """The (track, measurement) pairs that can have ``d^2 <= max_d2``, by increasing row.

    A pair can be within ``d^2 <= g`` only if ``|y|^2 <= g lambda_max(S) <= g tr(S)``, since
    ``d^2 >= |y|^2 / lambda_max(S)``. That bound is cheap for all pairs: with capture-time
    offsets up to ``delta`` (``H = [I delta I]``), ``|y| >= |z - p| - delta |v|`` and
    ``tr(S) <= (sqrt(tr P_pos) + delta sqrt(tr P_vel))^2 + tr(R)`` (Cauchy-Schwarz on the
    position-velocity block). The pairs beyond it for ``g = max_d2`` are certainly outside;
    only the rest are computed exactly. With a hundred vehicles along a road a track has a
    handful of candidates, so this is a fraction of the (T, M) work.
    """
    n_tracks = len(x_pred)
    pos_trace = P_pred[:, 0, 0] + P_pred[:, 1, 1]
    if time_offset_s is None:
        reach, track_trace = np.zeros(n_tracks), pos_trace
    else:
        delta = float(np.max(np.abs(time_offset_s)))
        vel_trace = P_pred[:, 2, 2] + P_pred[:, 3, 3]
        reach = delta * np.hypot(x_pred[:, 2], x_pred[:, 3])
        track_trace = (np.sqrt(pos_trace) + delta * np.sqrt(vel_trace)) ** 2
    meas_trace = R[:, 0, 0] + R[:, 1, 1]
    # Candidates along the axis the measurements spread most (the road's): a sorted sweep.
    axis = int(np.argmax(z.max(axis=0) - z.min(axis=0)))
    order = np.argsort(z[:, axis], kind="stable")
    sorted_z = z[order, axis]
    radius = np.sqrt(max_d2 * (track_trace + meas_trace.max())) + reach  # (T,)
    lo = np.searchsorted(sorted_z, x_pred[:, axis] - radius, side="left")
    hi = np.searchsorted(sorted_z, x_pred[:, axis] + radius, side="right")
    counts = hi - lo
    total = int(counts.sum())
    rows = np.repeat(np.arange(n_tracks), counts)
    starts = np.repeat(lo - (np.cumsum(counts) - counts), counts)
    cols = order[np.arange(total) + starts] if total else _NO_INDEX
    if total:
        dx = z[cols, 0] - x_pred[rows, 0]
        dy = z[cols, 1] - x_pred[rows, 1]
        distance = np.sqrt(dx * dx + dy * dy) - reach[rows]
        near = (distance <= 0.0) | (
            distance * distance <= max_d2 * (track_trace[rows] + meas_trace[cols]))
        rows, cols = rows[near], cols[near]
    return rows, cols


def _pair_statistics(
    x: F64, P: F64, z: F64, R: F64, offsets: F64 | None
) -> tuple[F64, F64]:
    """d2 and ln det S of K given pairs (row k: track state k with measurement k)."""
    y0 = z[:, 0] - x[:, 0]
    y1 = z[:, 1] - x[:, 1]
    s00 = P[:, 0, 0] + R[:, 0, 0]
    s01 = P[:, 0, 1] + R[:, 0, 1]
    s10 = P[:, 1, 0] + R[:, 1, 0]
    s11 = P[:, 1, 1] + R[:, 1, 1]
    if offsets is not None:
        d = offsets
        y0 = y0 - d * x[:, 2]
        y1 = y1 - d * x[:, 3]
        s00 = s00 + d * (P[:, 0, 2] + P[:, 2, 0]) + d * d * P[:, 2, 2]
        s11 = s11 + d * (P[:, 1, 3] + P[:, 3, 1]) + d * d * P[:, 3, 3]
        s01 = s01 + d * (P[:, 0, 3] + P[:, 2, 1]) + d * d * P[:, 2, 3]
        s10 = s10 + d * (P[:, 1, 2] + P[:, 3, 0]) + d * d * P[:, 3, 2]
    det = s00 * s11 - s01 * s10
    d2: F64 = (s11 * y0 * y0 - (s01 + s10) * y0 * y1 + s00 * y1 * y1) / det
    return d2, np.log(det)


def mahalanobis_squared(x_pred: F64, P_pred: F64, z: F64, R: F64) -> F64:
    """``d^2 = y^T S^-1 y`` of every (track, measurement) pair, (T, M); see
    :func:`innovation_statistics`."""
    return innovation_statistics(x_pred, P_pred, z, R)[0]


def association_cost(d2: F64, log_det_S: F64, bonus: F64 | None = None) -> F64:
    """Cost of pairing a track with a measurement: the Gaussian negative log-likelihood.

    ::

        cost = d^2 + ln det S - bonus   ( = -2 ln N(y; 0, S) - 2 ln 2 pi - bonus )

    Distance alone (``d^2``) favours the most uncertain track, whose large ``S`` makes every
    measurement look close: a newborn tentative track would steal a confirmed track's
    detection. The ``ln det S`` term is the price of that uncertainty.

    Parameters
    ----------
    d2, log_det_S
        From :func:`innovation_statistics`, (T, M), or of a list of pairs, (K,).
    bonus
        Cost reductions of the same shape, >= 0 (local-track-id continuity), or None.

    Returns
    -------
    cost
        The shape of ``d2``.
    """
    cost = d2 + log_det_S
    return cost if bonus is None else cost - bonus


def gnn_assign(cost: F64, allowed: npt.NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Global nearest neighbour: the one-to-one pairing of least total cost among allowed pairs.

    Forbidden pairs (outside the gate) get a cost above any sum of allowed ones and are dropped
    from the result, so ``linear_sum_assignment`` finds, among the pairings with the most
    allowed pairs, the one of least total cost. A cost never allows a forbidden pair.

    Parameters
    ----------
    cost
        Cost of each (track, measurement) pair, shape (T, M), e.g. :func:`association_cost`.
    allowed
        Which pairs pass the gate, shape (T, M).

    Returns
    -------
    pairs
        ``(track_row, measurement_column)`` by increasing row.
    """
    rows, columns = _gnn_assign_arrays(cost, allowed)
    return list(zip(rows.tolist(), columns.tolist(), strict=True))


def _gnn_assign_arrays(cost: F64, allowed: npt.NDArray[np.bool_]) -> tuple[IntP, IntP]:
    """:func:`gnn_assign` as a row and a column index array, by increasing row.

    The tracker's cycle uses this form: a pairing of 200 tracks as 200 Python tuples costs more
    than the assignment itself.
    """
    if cost.size == 0:
        return _NO_INDEX, _NO_INDEX
    rows, columns = _allowed_pairs(allowed)
    picked = _gnn_assign_pairs(cost[rows, columns], rows, columns)
    return rows[picked], columns[picked]


def _allowed_pairs(allowed: npt.NDArray[np.bool_]) -> tuple[IntP, IntP]:
    """The allowed pairs as a row and a column array, row-major order (flat indices:
    np.nonzero of a 2-D array is slower)."""
    rows, columns = np.divmod(np.flatnonzero(allowed), allowed.shape[1])
    return rows, columns


def _gnn_assign_pairs(cost: F64, rows: IntP, columns: IntP) -> IntP:
    """:func:`gnn_assign` on allowed pairs given as arrays (distinct pairs, their costs (K,)):
    the indices of the pairs chosen, by increasing row."""
    if not len(rows):
        return _NO_INDEX
    # Only rows and columns with an allowed pair take part. A row whose one allowed column has
    # no other allowed row is a component of its own: that pair is in every optimal pairing.
    # On a road, where gates rarely overlap, that leaves a small problem for the solver.
    row_degree = np.bincount(rows)
    column_degree = np.bincount(columns)
    isolated = (row_degree[rows] == 1) & (column_degree[columns] == 1)
    picked = [np.flatnonzero(isolated)]
    if not isolated.all():
        # the other rows and columns with an allowed pair, increasing, and their pairs
        shared = np.flatnonzero(~isolated)
        block_rows, block_columns = np.unique(rows[shared]), np.unique(columns[shared])
        in_rows = np.searchsorted(block_rows, rows[shared])
        in_columns = np.searchsorted(block_columns, columns[shared])
        pair_of = np.full((len(block_rows), len(block_columns)), -1)  # -1: forbidden
        pair_of[in_rows, in_columns] = shared
        block_cost = np.full(pair_of.shape, _FORBIDDEN_COST)
        block_cost[in_rows, in_columns] = cost[shared]
        solved = pair_of[linear_sum_assignment(block_cost)]
        picked.append(solved[solved >= 0])
    chosen = np.concatenate(picked)
    return chosen[np.argsort(rows[chosen])]


def cascade_assign(
    cost: F64, allowed: npt.NDArray[np.bool_], first_rows: npt.NDArray[np.bool_]
) -> list[tuple[int, int]]:
    """:func:`gnn_assign` for the ``first_rows`` (confirmed tracks), then for the other rows
    (tentative tracks) on the measurements left: a new, uncertain track never takes a
    detection an established track can explain.

    Parameters
    ----------
    cost, allowed
        As for :func:`gnn_assign`, (T, M).
    first_rows
        Rows served first, shape (T,).

    Returns
    -------
    pairs
        ``(track_row, measurement_column)`` by increasing row.
    """
    rows, columns = _cascade_assign_arrays(cost, allowed, first_rows)
    return list(zip(rows.tolist(), columns.tolist(), strict=True))


def _cascade_assign_arrays(
    cost: F64, allowed: npt.NDArray[np.bool_], first_rows: npt.NDArray[np.bool_]
) -> tuple[IntP, IntP]:
    """:func:`cascade_assign` as a row and a column index array, by increasing row."""
    rows, columns = _allowed_pairs(allowed)
    picked = _cascade_assign_pairs(cost[rows, columns], rows, columns, first_rows)
    return rows[picked], columns[picked]


def _cascade_assign_pairs(cost: F64, rows: IntP, columns: IntP, first_rows: npt.NDArray[np.bool_],
                          ) -> IntP:  # fmt: skip
    """:func:`cascade_assign` on allowed pairs given as arrays (as :func:`_gnn_assign_pairs`):
    the indices of the pairs chosen, by increasing row."""
    if not len(rows):
        return _NO_INDEX
    picked = [_NO_INDEX]
    free_columns = np.ones(int(columns.max()) + 1, dtype=bool)
    first = first_rows[rows]
    for stage in (first, ~first):
        if not stage.any():
            continue  # e.g. no tentative track: nothing to assign
        # the stage's allowed pairs whose measurement no earlier stage took
        candidates = np.flatnonzero(stage & free_columns[columns])
        chosen = candidates[_gnn_assign_pairs(cost[candidates], rows[candidates],
                                              columns[candidates])]  # fmt: skip
        free_columns[columns[chosen]] = False
        picked.append(chosen)
    chosen = np.concatenate(picked)
    return chosen[np.argsort(rows[chosen])]


def _huber_inflated(R: F64, columns: IntP, d2: F64, huber_k: float) -> F64:
    """Measurement covariances of the matched pairs, widened where the innovation is large.

    A detector's errors have heavy tails (a box fitted to half a vehicle, an echo off the wrong
    face): inside the gate but far from the prediction, a plain Kalman update follows them all
    the way. Huber's M-estimator weights a residual beyond ``k`` sigmas by ``k / d``; in a
    Kalman update that is ``R <- R d / k`` for ``d = sqrt(d^2) > k`` (``d^2`` the pair's squared
    Mahalanobis distance), so an outlier moves the track by about ``k`` sigmas and no more,
    while ordinary measurements are untouched. ``huber_k = 0`` turns it off.

    Parameters
    ----------
    R
        All measurement covariances (M, 2, 2).
    columns, d2
        The matched pairs' measurement columns and squared distances, (K,).

    Returns
    -------
    R_used
        ``R`` (M, 2, 2) with the matched columns' covariances scaled (a copy when any is).
    """
    if huber_k <= 0.0 or not len(columns):
        return R
    d = np.sqrt(np.maximum(d2, 0.0))
    scale = np.maximum(1.0, d / huber_k)
    if not np.any(scale > 1.0):
        return R
    R_used = R.copy()
    R_used[columns] *= scale[:, None, None]
    return R_used


# ----------------------------------------------------------------------------- tracks


#: The priors and posteriors of the tracks one batch updated, row k for its k-th track:
#: ``(stamp_s, x_pred (K, 4), P_pred (K, 4, 4), x_filt (K, 4), P_filt (K, 4, 4))``. A plain
#: tuple of a float and arrays: Python's garbage collector stops tracking it, and the entries
#: holding it, after one pass, where it would scan a dataclass or a NamedTuple in every full
#: collection, and 200 tracks keep up to ``max_history`` entries each.
_UpdateRecord = tuple[float, F64, F64, F64, F64]
#: One update of a track: the batch's record and the track's row in it.
_HistoryEntry = tuple[_UpdateRecord, int]


@dataclass(slots=True, eq=False)
class _Track:
    """The per-track objects of a live track: its id, slot, update history and, while it is
    tentative, its hit stamps. Its state lives in the bank and the rest of its bookkeeping in
    the tracker's :class:`_TrackTable`, both at row ``slot``."""

    track_id: int
    slot: int
    max_history: int
    hit_stamps_s: deque[float] = field(default_factory=deque)
    history: deque[_HistoryEntry] = field(init=False)
    #: When it was lost (``TrackerSettings.lost_memory_s``) [s].
    lost_s: float = math.nan

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


class _TrackTable:
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
        for name in ("born_s", "updated_s", "confirmed", "confirmed_s", "hits", "heading_rad",
                     "sensor_updated_s", "class_weight", "class_last_vote", "lengths_m",
                     "widths_m", "length_count", "width_count", "_sizes", "_sizes_stale"):  # fmt: skip
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
                [self.class_last_vote, np.zeros((rows, 1), dtype=np.int64)], axis=1)  # fmt: skip
        return column

    def class_columns(self, names: Sequence[str]) -> IntP:
        """:meth:`class_column` of each of ``names``, shape (K,)."""
        lookup = self._class_column
        if not lookup.keys() >= set(names):
            for name in names:
                self.class_column(name)
        return np.fromiter(map(lookup.__getitem__, names), np.intp, len(names))

    # --- hits ---

    def record_hits(self, slots: IntP, stamp_s: float, sensor_column: int, class_columns: IntP,
                    scores: F64, lengths_m: F64, widths_m: F64) -> None:  # fmt: skip
        """Count an update of each of ``slots`` (distinct) at ``stamp_s`` by one sensor: the
        hit, the class vote (``class_columns``, weighted by ``scores``), the measured sizes
        (NaN or <= 0: not measured); all shape (K,)."""
        self.hits[slots] += 1
        self.updated_s[slots] = stamp_s
        self.sensor_updated_s[slots, sensor_column] = stamp_s
        self.class_weight[slots, class_columns] += scores
        self.class_last_vote[slots, class_columns] = self.hits[slots]
        for values, ring, count in ((lengths_m, self.lengths_m, self.length_count),
                                    (widths_m, self.widths_m, self.width_count)):  # fmt: skip
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

        The upper quartile is what :meth:`MultiTargetTracker._reference_point` takes as the
        track's length: a partial view only shortens a box.
        """
        stale = slots[self._sizes_stale[slots]]
        if len(stale):
            self._sizes_stale[stale] = False
            window = self.size_window
            for column, ring, count in ((0, self.lengths_m, self.length_count),
                                        (1, self.widths_m, self.width_count)):  # fmt: skip
                ordered = np.sort(ring[stale], axis=1)  # NaN (unfilled) last
                n = np.minimum(count[stale], window)
                has = n > 0
                low = np.take_along_axis(ordered, np.maximum(n - 1, 0)[:, None] // 2, axis=1)[:, 0]
                high = np.take_along_axis(ordered, (n // 2)[:, None], axis=1)[:, 0]
                self._sizes[stale, column] = np.where(has, (low + high) / 2.0, math.nan)
                if column == 0:
                    quartile = np.take_along_axis(
                        ordered, np.maximum((3 * (n - 1)) // 4, 0)[:, None], axis=1)[:, 0]  # fmt: skip
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
        return [names[c] if ok else UNKNOWN_CLASS
                for c, ok in zip(winner.tolist(), any_known, strict=True)]  # fmt: skip

    def last_update_by_sensor(self, slot: int) -> dict[str, float]:
        """Latest update stamp per sensor that updated row ``slot`` [s]."""
        stamps = self.sensor_updated_s[slot].tolist()
        return {sensor: s for sensor, s in zip(self.sensor_ids, stamps, strict=True)
                if s != -math.inf}  # fmt: skip


@dataclass(order=True, slots=True)
class _PendingBatch:
    stamp_s: float
    sensor_id: str
    arrival: int
    measurements: Sequence[Measurement] = field(compare=False)


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
    ) -> None:
        self.settings = settings
        self._heading_at = heading_at
        self._headings_at = headings_at if heading_at is not None else None
        self._sensor_positions = dict(sensor_positions or {})
        self._bank: TrackStateBank | IMMStateBank = (
            IMMStateBank((settings.imm_steady_sojourn_s, settings.imm_manoeuvre_sojourn_s))
            if settings.motion_model == "imm"
            else TrackStateBank()
        )
        self._tracks: dict[int, _Track] = {}  # by track id, in creation (= id) order
        self._table = _TrackTable(settings.size_window)
        # d2 is compared with these gates only: beyond the widest, pairs need not be computed
        # (a little over it, for rounding)
        self._widest_gate_chi2 = 1.01 * max(settings.gate_chi2, settings.spawn_gate_chi2)
        # _tracks' values and their slots, rebuilt after _tracks changes (_tracks_changed)
        self._live_cache: tuple[list[_Track], IntP] | None = None
        # Confirmed tracks past their coast, kept lost_memory_s (their slots too): id -> track
        self._lost: dict[int, _Track] = {}
        if first_track_id < 1:
            raise ValueError(f"track ids start at 1 or more, got {first_track_id}")
        self._next_id = first_track_id
        self._local_ids: dict[tuple[str, int], int] = {}  # (sensor, local id) -> track id
        self._pending: list[_PendingBatch] = []  # a heap by (stamp, sensor, arrival)
        self._arrivals = 0
        self._newest_stamp_s = -math.inf
        self._last_processed_s: float | None = None
        self._next_merge_s = -math.inf
        self._finished: deque[TrackHistory] = deque(maxlen=settings.max_finished_histories)
        self._counters = TrackerCounters()
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
        self._counters.batches_received += 1
        if self._last_processed_s is not None and stamp_s < self._last_processed_s:
            self._counters.batches_late += 1
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
            self._prune(horizon_s)
        return processed

    def _live(self) -> tuple[list[_Track], IntP]:
        """The live tracks in id order and their slots (cached until :meth:`_tracks_changed`)."""
        if self._live_cache is None:
            live = list(self._tracks.values())
            self._live_cache = (live, np.array([t.slot for t in live], dtype=np.intp))
        return self._live_cache

    def _tracks_changed(self) -> None:
        """To be called whenever a track enters or leaves ``_tracks``."""
        self._live_cache = None

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
        return replace(self._counters)

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
        live, slots = self._live()
        if reference_s is not None and live:
            kept = ~self._expired(slots, reference_s)
            if not kept.all():
                live = [t for t, k in zip(live, kept.tolist(), strict=True) if k]
                slots = slots[kept]
        if not live:
            return []
        if stamp_s is None:
            x, P = self._bank.states(slots), self._bank.covariances(slots)
            stamps = self._bank.stamps_s(slots)
        else:
            x, P = self._predicted(slots, stamp_s)
            stamps = np.full(len(live), stamp_s)
        table, settings = self._table, self.settings
        status_s = stamps if reference_s is None else np.full(len(live), reference_s)
        since_update = status_s - table.updated_s[slots]
        confirmed = table.confirmed[slots].tolist()
        coasting = (since_update > settings.coasting_after_s).tolist()
        status: list[TrackStatus] = ["tentative" if not c else "coasting" if late else "confirmed"
                                     for c, late in zip(confirmed, coasting, strict=True)]  # fmt: skip
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
                    sources=tuple(sorted(sensor_ids[c] for c in np.flatnonzero(sources[row]).tolist())),
                    hits=hits[row],
                    age_s=age[row],
                    time_since_update_s=since_list[row],
                    last_update_s_by_sensor=table.last_update_by_sensor(track.slot),
                )
            )
        return snapshots

    def history(self, track_id: int) -> TrackHistory:
        """The stored updates of live track ``track_id`` (KeyError when it is not live)."""
        return self._tracks[track_id].to_history()

    def unfinished_histories(self) -> list[TrackHistory]:
        """Histories of the confirmed tracks not ended yet, by id: the live ones (confirmed or
        coasting) and the lost ones (``lost_memory_s``), which :meth:`pop_finished_histories`
        gives only once they end. For a run that stops now; the tracker is not changed."""
        confirmed = self._table.confirmed
        unfinished = [t for t in self._tracks.values() if confirmed[t.slot]]
        unfinished += self._lost.values()
        return [t.to_history() for t in sorted(unfinished, key=lambda t: t.track_id)]

    def pop_finished_histories(self) -> list[TrackHistory]:
        """Histories of the confirmed tracks ended since the last call, oldest first (a
        confirmed track ends ``lost_memory_s`` after it is deleted, unless it resumes)."""
        finished = list(self._finished)
        self._finished.clear()
        return finished

    # --- one cycle ---

    def _process(self, sensor_id: str, stamp_s: float, measurements: Sequence[Measurement]) -> None:
        """Prune, predict, gate, associate, update, spawn, at the batch's stamp."""
        settings = self.settings
        self._prune(stamp_s)
        self._last_processed_s = stamp_s
        self._counters.batches_processed += 1
        self._last_batch_s[sensor_id] = stamp_s
        self._counters.measurements_processed += len(measurements)
        if not measurements:
            return
        n = len(measurements)
        # column by column: faster than a list of [x, y] lists
        z = np.stack([np.fromiter([m.x_m for m in measurements], np.float64, n),
                      np.fromiter([m.y_m for m in measurements], np.float64, n)],
                     axis=1)  # fmt: skip
        R = np.concatenate([m.covariance_m2 for m in measurements], dtype=np.float64).reshape(
            -1, 2, 2)  # fmt: skip
        offsets = np.fromiter([m.time_offset_s for m in measurements], np.float64, n)
        time_offset_s = offsets if np.any(offsets != 0.0) else None
        # radar speeds along the road, NaN where there is none
        speeds = np.fromiter([math.nan if m.speed_mps is None else m.speed_mps
                              for m in measurements], np.float64, n)  # fmt: skip

        live, slots = self._live()
        pairs: list[tuple[int, int]] = []
        if live:
            x_pred, P_pred = self._predicted(slots, stamp_s)
            # the (track, measurement) pairs within the widest gate, as arrays
            pair_rows, pair_columns, d2, log_det_S = _gated_pairs(
                x_pred, P_pred, z, R, time_offset_s, self._widest_gate_chi2)  # fmt: skip
            if settings.speed_association_chi2 > 0.0 and self._heading_at is not None:
                d2 = self._speed_gated(slots, x_pred, P_pred, pair_rows, pair_columns, d2, speeds)
            cost = association_cost(d2, log_det_S, self._local_id_bonus(
                live, sensor_id, measurements, pair_rows, pair_columns))  # fmt: skip
            allowed = np.flatnonzero(d2 <= settings.gate_chi2)
            picked = allowed[_cascade_assign_pairs(
                cost[allowed], pair_rows[allowed], pair_columns[allowed],
                self._table.confirmed[slots])]  # fmt: skip
            rows, columns = pair_rows[picked], pair_columns[picked]
            if len(rows):
                pairs = list(zip(rows.tolist(), columns.tolist(), strict=True))
                R_used = _huber_inflated(R, columns, d2[picked], settings.huber_k)
                z_used = self._reference_point(slots, rows, columns, z, sensor_id, measurements)
                self._update_matched(
                    [live[row] for row in rows.tolist()],
                    rows,
                    columns,
                    slots,
                    x_pred,
                    P_pred,
                    z_used,
                    R_used,
                    sensor_id,
                    stamp_s,
                    measurements,
                    speeds,
                    time_offset_s,
                )

        if live and settings.reacquire_along_m > 0.0:
            pairs = pairs + self._reacquire(
                live, slots, x_pred, P_pred, z, R, pairs, sensor_id, stamp_s, measurements,
                speeds, time_offset_s)  # fmt: skip

        if settings.may_start_tracks(sensor_id):
            unmatched = np.ones(n, dtype=bool)
            unmatched[[column for _, column in pairs]] = False
            candidates = np.flatnonzero(unmatched)  # by increasing column
            if live and settings.spawn_gate_chi2 > 0.0 and len(candidates):
                # the measurements near a track confirmed as of now (the update may have
                # confirmed some)
                near = (d2 < settings.spawn_gate_chi2) & self._table.confirmed[slots[pair_rows]]
                near_confirmed = np.isin(candidates, pair_columns[near])
                self._counters.measurements_suppressed += int(np.count_nonzero(near_confirmed))
                candidates = candidates[~near_confirmed]
            if settings.spawn_max_std_m > 0.0 and len(candidates):
                # largest eigenvalue of each 2x2 R: (a + c) / 2 + sqrt(((a - c) / 2)^2 + b^2)
                a, b, c = R[candidates, 0, 0], R[candidates, 0, 1], R[candidates, 1, 1]
                largest = 0.5 * (a + c) + np.sqrt((0.5 * (a - c)) ** 2 + b * b)
                located = largest <= settings.spawn_max_std_m**2
                self._counters.measurements_unlocated += int(np.count_nonzero(~located))
                candidates = candidates[located]
            for column in candidates.tolist():
                self._spawn(measurements[column], R[column], sensor_id, stamp_s)
        self._merge_duplicates(stamp_s)

    def _speed_gated(self, slots: IntP, x_pred: F64, P_pred: F64, pair_rows: IntP,
                     pair_columns: IntP, d2: F64, speeds: F64) -> F64:  # fmt: skip
        """``d2`` of the pairs (``pair_rows``, ``pair_columns``) with those whose radar speed
        misses the track's speed gate set to inf.

        ``y = s - u . v``, ``S = u^T P_v u + sigma_s^2`` with ``u`` the track's road heading;
        forbidden when ``y^2 > speed_association_chi2 S``.
        """
        settings = self.settings
        if not np.isfinite(speeds).any():
            return d2
        # Only pairs within a gate are ever looked at again (association, spawn suppression).
        rows, columns = pair_rows, pair_columns
        road = self._table.heading_rad[slots[rows]]
        known = np.flatnonzero(np.isfinite(road) & np.isfinite(speeds[columns])
                               & (d2 <= max(settings.gate_chi2, settings.spawn_gate_chi2)))  # fmt: skip
        rows, columns, road = rows[known], columns[known], road[known]
        if not len(rows):
            return d2
        cos, sin = np.cos(road), np.sin(road)
        predicted = x_pred[rows, 2] * cos + x_pred[rows, 3] * sin
        P_v = P_pred[rows]
        variance = (cos * cos * P_v[:, 2, 2] + cos * sin * (P_v[:, 2, 3] + P_v[:, 3, 2])
                    + sin * sin * P_v[:, 3, 3] + settings.speed_std_mps**2)  # fmt: skip
        y = speeds[columns] - predicted
        bad = y * y > settings.speed_association_chi2 * variance
        if not bad.any():
            return d2
        d2 = d2.copy()
        d2[known[bad]] = np.inf
        return d2

    def _reference_point(
        self, slots: IntP, rows: IntP, columns: IntP, z: F64, sensor_id: str,
        measurements: Sequence[Measurement],
    ) -> F64:  # fmt: skip
        """Matched positions re-centred with the track's length where a sensor saw one end.

        A LiDAR sees the face of a vehicle turned to it and completes the box away from the
        sensor with the length of the class it can tell (a semitrailer seen end-on at 130 m
        shows a car's height: completed as a 4.5 m car, its centre 6 m short). The track knows
        better: its length ``L_t`` (the upper quartile of the measured lengths, since a partial
        view only shortens) against the box's ``L_d`` moves the centre by ``(L_t - L_d) / 2``
        along the track's direction, away from the sensor. Differences below
        ``reference_point_min_m`` are left alone (a car's own spread).
        """
        threshold = self.settings.reference_point_min_m
        sensor = self._sensor_positions.get(sensor_id)
        if sensor is None or threshold <= 0.0:
            return z
        measured = np.fromiter(
            [math.nan if (length := measurements[c].length_m) is None else length
             for c in columns.tolist()], np.float64, len(columns))  # fmt: skip
        matched_slots = slots[rows]
        difference = self._table.sizes(matched_slots)[:, 2] - measured  # NaN: either unknown
        heading = self._table.heading_rad[matched_slots]
        moved = (np.abs(difference) >= threshold) & np.isfinite(heading)  # False for NaN
        if not moved.any():
            return z
        axis = np.stack([np.cos(heading[moved]), np.sin(heading[moved])], axis=1)
        at = columns[moved]
        away = np.where(np.einsum("ki,ki->k", z[at] - np.asarray(sensor), axis) >= 0.0, 1.0, -1.0)
        z_used = z.copy()
        z_used[at] = z[at] + (0.5 * difference[moved] * away)[:, None] * axis
        return z_used

    def _reacquire(
        self, live: Sequence[_Track], slots: IntP, x_pred: F64, P_pred: F64, z: F64, R: F64,
        pairs: Sequence[tuple[int, int]], sensor_id: str, stamp_s: float,
        measurements: Sequence[Measurement], speeds: F64, time_offset_s: F64 | None,
    ) -> list[tuple[int, int]]:  # fmt: skip
        """Take up a confirmed track that has missed updates with a measurement near it on the
        road, outside its (by then overconfident) gate.

        A vehicle lost for a few tenths of a second (the LiDAR's blind spot under the mast, an
        occlusion) often comes back a couple of metres from its prediction: biased detections
        before the gap bent its velocity. Rather than start a second track, a measurement left
        unmatched within ``reacquire_along_m`` along and ``reacquire_across_m`` across the
        track's direction updates it, its prior widened by the innovation ``y``
        (``P_pos += y y^T``, ``P_vel += y y^T / gap^2``) so the update can follow.
        """
        settings = self.settings
        table = self._table
        waiting = table.confirmed[slots] & (
            stamp_s - table.updated_s[slots] >= settings.reacquire_after_s)  # fmt: skip
        free = np.ones(len(z), dtype=bool)
        if pairs:
            matched_rows, matched_columns = zip(*pairs, strict=True)
            waiting[list(matched_rows)] = False
            free[list(matched_columns)] = False
        rows, columns = np.flatnonzero(waiting), np.flatnonzero(free)
        if len(rows) == 0 or len(columns) == 0:
            return []
        delta = time_offset_s[columns] if time_offset_s is not None else np.zeros(len(columns))
        xr = x_pred[rows]
        y = z[columns][None, :, :] - (xr[:, None, :2] + xr[:, None, 2:] * delta[None, :, None])
        speed = np.hypot(xr[:, 2], xr[:, 3])
        heading = table.heading_rad[slots[rows]]
        own = np.arctan2(xr[:, 3], xr[:, 2])
        heading = np.where(np.isfinite(heading) & (speed <= settings.heading_min_speed_mps),
                           heading, own)  # fmt: skip
        u = np.stack([np.cos(heading), np.sin(heading)], axis=1)
        along = np.einsum("tmi,ti->tm", y, u)
        across = y[..., 1] * u[:, None, 0] - y[..., 0] * u[:, None, 1]
        allowed = (np.abs(along) <= settings.reacquire_along_m) & (
            np.abs(across) <= settings.reacquire_across_m)  # fmt: skip
        if not allowed.any():
            return []
        found = gnn_assign(np.hypot(along, across), allowed)
        if not found:
            return []
        new_pairs = [(int(rows[r]), int(columns[c])) for r, c in found]
        P_wide = P_pred.copy()
        for (row, _column), (r, c) in zip(new_pairs, found, strict=True):
            gap_s = max(stamp_s - float(table.updated_s[slots[row]]), 0.1)
            outer = np.outer(y[r, c], y[r, c])
            P_wide[row, :2, :2] += outer
            P_wide[row, 2:, 2:] += outer / gap_s**2
        self._counters.tracks_reacquired += len(new_pairs)
        self._update_matched(
            [live[row] for row, _ in new_pairs],
            np.array([row for row, _ in new_pairs], dtype=np.intp),
            np.array([column for _, column in new_pairs], dtype=np.intp),
            slots, x_pred, P_wide, z, R, sensor_id, stamp_s, measurements, speeds, time_offset_s,
        )  # fmt: skip
        return new_pairs

    def _predicted(self, slots: IntP, stamp_s: float) -> tuple[F64, F64]:
        """The states of ``slots`` predicted to ``stamp_s`` with each track's process noise.

        Along the road's heading where the track has one, else along its own velocity when it
        moves at ``heading_min_speed_mps`` or more, else isotropic (``sigma_along`` both ways).
        """
        settings = self.settings
        x = self._bank.states(slots)
        heading = np.arctan2(x[:, 3], x[:, 2])
        oriented = np.hypot(x[:, 2], x[:, 3]) >= settings.heading_min_speed_mps
        if self._heading_at is not None:
            road = self._table.heading_rad[slots]
            known = np.isfinite(road)
            heading = np.where(known, road, heading)
            oriented = oriented | known
        if settings.motion_model == "cv":
            sigma_across = np.where(oriented, settings.sigma_across_mps2, settings.sigma_along_mps2)
            return self._bank.predicted(
                slots, stamp_s, settings.sigma_along_mps2, sigma_across, heading
            )
        # per mode: (steady, manoeuvre)
        along = np.array([settings.imm_steady_sigma_along_mps2, settings.sigma_along_mps2])
        across = np.where(
            oriented[:, None],
            np.array([settings.imm_steady_sigma_across_mps2, settings.sigma_across_mps2]),
            along,
        )
        return self._bank.predicted(slots, stamp_s, along, across, heading)

    def _local_id_bonus(
        self, live: Sequence[_Track], sensor_id: str, measurements: Sequence[Measurement],
        pair_rows: IntP, pair_columns: IntP,
    ) -> F64 | None:  # fmt: skip
        """The cost reduction of each pair (``local_track_id_bonus`` where the measurement's
        (sensor, local id) last updated the pair's track), or None when no pair has one."""
        bonus_value = self.settings.local_track_id_bonus
        if bonus_value == 0.0:
            return None
        if all(measurement.local_track_id is None for measurement in measurements):
            return None  # a sensor without a tracker of its own
        row_of = {track.track_id: row for row, track in enumerate(live)}
        # per measurement, the row of the track its local id last updated (-1: none)
        continued = np.full(len(measurements), -1)
        for column, measurement in enumerate(measurements):
            if measurement.local_track_id is None:
                continue
            track_id = self._local_ids.get((sensor_id, measurement.local_track_id))
            if track_id is not None and track_id in row_of:
                continued[column] = row_of[track_id]
        same = continued[pair_columns] == pair_rows
        return np.where(same, bonus_value, 0.0) if same.any() else None

    def _update_matched(
        self,
        tracks: Sequence[_Track],
        rows: IntP,
        columns: IntP,
        slots: IntP,
        x_pred: F64,
        P_pred: F64,
        z: F64,
        R: F64,
        sensor_id: str,
        stamp_s: float,
        measurements: Sequence[Measurement],
        speeds: F64,
        time_offset_s: F64 | None = None,
    ) -> None:
        settings = self.settings
        table = self._table
        matched_slots = slots[rows]
        # the prior: each matched track predicted to the batch's stamp
        x_prior, P_prior = x_pred[rows], P_pred[rows]
        self._bank.commit_prior(matched_slots, x_prior, P_prior, stamp_s)
        # position update, all matched tracks at once; a measurement captured delta after
        # the stamp sees p + delta v: H = [I delta I] (see innovation_statistics)
        if time_offset_s is None:
            self._bank.update(matched_slots, z[columns], R[columns])
        else:
            H = np.zeros((len(columns), 2, STATE_DIM))
            H[:, 0, 0] = H[:, 1, 1] = 1.0
            H[:, 0, 2] = H[:, 1, 3] = time_offset_s[columns]
            self._bank.update(matched_slots, z[columns], R[columns], H)

        if self._heading_at is not None:
            x_post = self._bank.states(matched_slots)
            if self._headings_at is not None:
                road = np.asarray(self._headings_at(x_post[:, 0], x_post[:, 1]), dtype=np.float64)
            else:
                road = np.array([self._heading_at(x_m, y_m) for x_m, y_m in x_post[:, :2].tolist()],
                                dtype=np.float64)  # fmt: skip
            road = np.where(np.isfinite(road), road, math.nan)  # no road: NaN
            table.heading_rad[matched_slots] = road
            # radar speed along the road: z = s, H = [0, 0, cos h, sin h], R = sigma_s^2
            speed_rows = np.flatnonzero(np.isfinite(speeds[columns]) & np.isfinite(road)) if (
                settings.use_speed_measurements) else _NO_INDEX  # fmt: skip
            if len(speed_rows):
                h = road[speed_rows]
                H = np.zeros((len(speed_rows), 1, STATE_DIM))
                H[:, 0, 2], H[:, 0, 3] = np.cos(h), np.sin(h)
                measured = speeds[columns[speed_rows]][:, None]
                R_speed = np.full((len(speed_rows), 1, 1), settings.speed_std_mps**2)
                # Gate: a radar speed paired with the wrong echo (the car in the next lane)
                # would drag the velocity by metres per second in one update.
                # y = s - H x,  S = H P H^T + R,  kept when y^2 / S <= speed_gate_chi2.
                speed_slots = matched_slots[speed_rows]
                x_now, P_now = self._bank.states(speed_slots), self._bank.covariances(speed_slots)
                y = measured[:, 0] - np.einsum("mj,mj->m", H[:, 0, :], x_now)
                S = np.einsum("mi,mij,mj->m", H[:, 0, :], P_now, H[:, 0, :]) + R_speed[:, 0, 0]
                keep = y * y <= settings.speed_gate_chi2 * S
                self._counters.speeds_rejected += int(np.count_nonzero(~keep))
                if keep.any():
                    self._bank.update(speed_slots[keep], measured[keep], R_speed[keep], H[keep])

        # the hits: class vote, sizes, per-sensor stamps, all matched tracks at once
        columns_list = columns.tolist()  # Python ints index the measurements faster
        matched = [measurements[column] for column in columns_list]
        k = len(matched)
        table.record_hits(
            matched_slots, stamp_s, table.sensor_column(sensor_id),
            table.class_columns([m.object_class for m in matched]),
            np.fromiter([m.score for m in matched], np.float64, k),
            np.fromiter([math.nan if m.length_m is None else m.length_m for m in matched],
                        np.float64, k),
            np.fromiter([math.nan if m.width_m is None else m.width_m for m in matched],
                        np.float64, k),
        )  # fmt: skip
        # The batch's priors and posteriors, copied once (fancy indexing copies); each track's
        # history entry is this record and its row (not four views and an object per track).
        record: _UpdateRecord = (stamp_s, x_prior, P_prior, self._bank.states(matched_slots),
                                 self._bank.covariances(matched_slots))  # fmt: skip
        for i, track in enumerate(tracks):
            track.history.append((record, i))
        for measurement, track in zip(matched, tracks, strict=True):
            if measurement.local_track_id is not None:
                self._local_ids[(sensor_id, measurement.local_track_id)] = track.track_id
        for i in np.flatnonzero(~table.confirmed[matched_slots]).tolist():
            # a confirmed track has no hits left to count
            tracks[i].hit_stamps_s.append(stamp_s)
            self._check_confirmation(tracks[i], stamp_s)

    def _road_heading(self, x_m: float, y_m: float) -> float | None:
        if self._heading_at is None:
            return None
        heading = float(self._heading_at(x_m, y_m))
        return heading if math.isfinite(heading) else None

    def _spawn(self, measurement: Measurement, R: F64, sensor_id: str, stamp_s: float) -> None:
        """Start a tentative track: ``x = [z, v0]``, ``P = blockdiag(R, P_v)``.

        Without a road heading: ``v0 = 0``, ``P_v = sigma_v^2 I``. With one, ``h``:
        ``v0 = s (cos h, sin h)`` with ``s`` the radar speed (std ``speed_std_mps``) or
        ``initial_speed_mps`` (std ``initial_velocity_std_mps``), and
        ``P_v = Rot(h) diag(std_s^2, sigma_across_v^2) Rot(h)^T``.
        """
        settings = self.settings
        x = np.array([measurement.x_m, measurement.y_m, 0.0, 0.0])
        P = np.zeros((STATE_DIM, STATE_DIM))
        P[:2, :2] = R
        heading = self._road_heading(measurement.x_m, measurement.y_m)
        if heading is None:
            P[2, 2] = P[3, 3] = settings.initial_velocity_std_mps**2
        else:
            if settings.use_speed_measurements and measurement.speed_mps is not None:
                speed, speed_std = measurement.speed_mps, settings.speed_std_mps
            else:
                speed, speed_std = settings.initial_speed_mps, settings.initial_velocity_std_mps
            along = np.array([math.cos(heading), math.sin(heading)])
            across = np.array([-along[1], along[0]])
            x[2:] = speed * along
            P[2:, 2:] = speed_std**2 * np.outer(along, along) + (
                settings.initial_across_velocity_std_mps**2
            ) * np.outer(across, across)
        delta = measurement.time_offset_s
        if delta:
            # captured delta after the stamp: start where it was at the stamp, p = z - delta v0
            x[:2] -= delta * x[2:]
            P[:2, :2] += delta**2 * P[2:, 2:]
            P[:2, 2:] = -delta * P[2:, 2:]
            P[2:, :2] = P[:2, 2:].T
        track = _Track(
            track_id=self._next_id, slot=self._bank.add(x, P, stamp_s),
            max_history=settings.max_history,
        )  # fmt: skip
        table = self._table
        table.reset(track.slot, stamp_s, heading)
        self._next_id += 1
        self._tracks[track.track_id] = track
        self._tracks_changed()
        self._counters.tracks_started += 1
        length, width = measurement.length_m, measurement.width_m
        table.record_hits(
            np.array([track.slot]), stamp_s, table.sensor_column(sensor_id),
            np.array([table.class_column(measurement.object_class)]),
            np.array([measurement.score], dtype=np.float64),
            np.array([math.nan if length is None else length], dtype=np.float64),
            np.array([math.nan if width is None else width], dtype=np.float64),
        )  # fmt: skip
        track.hit_stamps_s.append(stamp_s)
        track.history.append(((stamp_s, x[None], P[None], x[None], P[None]), 0))
        if measurement.local_track_id is not None:
            self._local_ids[(sensor_id, measurement.local_track_id)] = track.track_id
        self._check_confirmation(track, stamp_s)

    def _check_confirmation(self, track: _Track, stamp_s: float) -> None:
        """Confirm a tentative track with ``confirm_hits`` hits within ``confirm_window_s``,
        ``confirm_min_age_s`` after its first; its hit stamps (the latest appended)."""
        window_start_s = stamp_s - self.settings.confirm_window_s
        while track.hit_stamps_s and track.hit_stamps_s[0] < window_start_s:
            track.hit_stamps_s.popleft()
        table = self._table
        if (
            not table.confirmed[track.slot]
            and len(track.hit_stamps_s) >= self.settings.confirm_hits
            and stamp_s - table.born_s[track.slot] >= self.settings.confirm_min_age_s
        ):
            table.confirmed[track.slot] = True
            table.confirmed_s[track.slot] = stamp_s
            track.hit_stamps_s.clear()  # only needed until confirmation
            self._counters.tracks_confirmed += 1

    def _expired(self, slots: IntP, stamp_s: float) -> npt.NDArray[np.bool_]:
        """Which tracks of ``slots`` are to be deleted at ``stamp_s``, shape (K,).

        A tentative track not updated for ``tentative_max_age_s``, a confirmed one for
        ``max_coast_s``; but a confirmed track one of whose sensors has gone silent (an outage,
        not a vehicle gone: no batch from it for ``sensor_silent_after_s``) coasts up to
        ``max_outage_coast_s``, so it keeps its id when the sensor comes back. Any, not all:
        a vehicle passing under the mast during a LiDAR outage also leaves the camera's view,
        and the camera still sending frames does not mean it could see the vehicle."""
        settings, table = self.settings, self._table
        updated_s = table.updated_s[slots]
        age_s = stamp_s - updated_s
        confirmed = table.confirmed[slots]
        expired = np.where(confirmed, age_s > settings.max_coast_s,
                           age_s > settings.tentative_max_age_s)  # fmt: skip
        outage = np.flatnonzero(expired & confirmed & (age_s <= settings.max_outage_coast_s))
        if len(outage):
            # the sensors that saw it shortly before its last update, and the silent ones
            seen = table.sensor_updated_s[slots[outage]]
            recent = seen >= (updated_s[outage] - settings.max_coast_s)[:, None]
            last_batch_s = np.array([self._last_batch_s.get(sensor, -math.inf)
                                     for sensor in table.sensor_ids])  # fmt: skip
            silent = last_batch_s < stamp_s - settings.sensor_silent_after_s
            expired[outage] = ~(recent & silent[None, :]).any(axis=1)
        return expired

    def _hand_over(self, stamp_s: float) -> None:
        """A young track that took up a coasting track's vehicle hands its state to it.

        When a vehicle comes back too far from its coasting track's prediction even for
        :meth:`_reacquire` (a long gap, a bent velocity), a new track starts on it. While the
        new track is young (``hand_over_age_s``) and the old one coasts just behind or ahead of
        it (``hand_over_along_m``, ``hand_over_across_m``: the same lane or the next), moving alike
        (or at a speed and place that braking or speeding up while unseen explains:
        :meth:`_speed_change_explains`), and the new one was updated after the old one last
        was, they are one vehicle: the old track takes the new one's state and the new one
        goes, so the vehicle keeps its identity.
        The old track is predicted along the road at its speed there, its offset across the
        road held, so the lane test measures from where the vehicle was last seen.
        The old track may also be a lost one (past its coast, within ``lost_memory_s``): it
        lives again. An old track sliding across the road (``hand_over_max_lateral_speed_mps``)
        is no vehicle's: it ends, and the young track carries on. The hand-over runs every
        ``_MERGE_PERIOD_S``, so it usually comes while the new track is still tentative, and
        the new id is never published. When the new track
        was confirmed ``_PUBLISHED_AFTER_S`` ago or more (its id published: it started while the
        old one was still being updated, a duplicate that took the vehicle over), the vehicle
        keeps the new id and the old track ends: handing it back would change the vehicle's id
        twice.
        """
        settings, table = self.settings, self._table
        if settings.hand_over_along_m <= 0.0 or len(self._tracks) + len(self._lost) < 2:
            return
        live, slots = self._live()
        updated_s = table.updated_s[slots]
        waiting = table.confirmed[slots] & (stamp_s - updated_s >= settings.reacquire_after_s)
        coasting = [live[i] for i in np.flatnonzero(waiting).tolist()]
        coasting += self._lost.values()
        born_s = table.born_s[slots]
        is_young = (stamp_s - born_s <= settings.hand_over_age_s) & (updated_s > born_s)
        young = [live[i] for i in np.flatnonzero(is_young).tolist()]
        if not coasting or not young:
            return
        old_slots = np.array([t.slot for t in coasting], dtype=np.intp)
        new_slots = np.array([t.slot for t in young], dtype=np.intp)
        x_old = self._bank.states(old_slots)
        heading = table.heading_rad[old_slots]
        heading = np.where(np.isfinite(heading), heading, np.arctan2(x_old[:, 3], x_old[:, 2]))
        u = np.stack([np.cos(heading), np.sin(heading)], axis=1)
        # The old track is predicted along the road (its speed along the road's heading, its
        # offset across held): seconds of a lateral velocity carried forward would put it off
        # the road. A vehicle that changed lanes while hidden (a late merge behind a truck)
        # comes back one lane over from where it was last seen, not from that drift.
        along_speed = np.einsum("ok,ok->o", x_old[:, 2:], u)
        x_old[:, :2] += u * (along_speed * (stamp_s - self._bank.stamps_s(old_slots)))[:, None]
        x_new = self._bank.states(new_slots)
        x_new[:, :2] += x_new[:, 2:] * (stamp_s - self._bank.stamps_s(new_slots))[:, None]
        d = x_new[None, :, :2] - x_old[:, None, :2]  # (old, new, 2)
        along = np.einsum("onk,ok->on", d, u)
        across = d[..., 1] * u[:, None, 0] - d[..., 0] * u[:, None, 1]
        dv = np.hypot(x_new[None, :, 2] - x_old[:, None, 2], x_new[None, :, 3] - x_old[:, None, 3])
        # The young track must have taken the vehicle up: updated after the old one last was.
        # A stray young track (a box split off a truck's trailer, 7 m behind it) whose last
        # update is older than the coasting track's is not its vehicle come back.
        took_up = table.updated_s[new_slots][None, :] > table.updated_s[old_slots][:, None]
        alike = dv < settings.merge_velocity_difference_mps
        if settings.hand_over_max_accel_mps2 > 0.0:
            alike |= self._speed_change_explains(
                along, np.einsum("onk,ok->on", x_new[None, :, 2:] - x_old[:, None, 2:], u),
                stamp_s - table.updated_s[old_slots],
                table.born_s[new_slots][None, :] > table.updated_s[old_slots][:, None])  # fmt: skip
        sliding = np.abs(x_old[:, 3] * u[:, 0] - x_old[:, 2] * u[:, 1]) > (
            settings.hand_over_max_lateral_speed_mps)  # fmt: skip
        allowed = ((np.abs(along) <= settings.hand_over_along_m)
                   & (np.abs(across) <= settings.hand_over_across_m)
                   & alike & took_up)  # fmt: skip
        if not allowed.any():
            return
        resumed = False
        for row, column in gnn_assign(np.abs(along) + np.abs(across), allowed):
            old, new = coasting[row], young[column]
            if new.track_id not in self._tracks:
                continue
            published = stamp_s - table.confirmed_s[new.slot] >= _PUBLISHED_AFTER_S  # NaN: no
            if published or sliding[row]:
                # The young id is published already: giving the vehicle its old id back would
                # rename it a second time. Or the old track slides across the road, no
                # vehicle's. The young track keeps the vehicle; the old one ends.
                if self._retire(old, successor_id=new.track_id):
                    self._counters.tracks_superseded += 1
                continue
            if old.track_id in self._lost:
                self._tracks[old.track_id] = self._lost.pop(old.track_id)
                self._counters.tracks_resumed += 1
                resumed = True
            elif old.track_id not in self._tracks:
                continue
            self._bank.copy_slot(new.slot, old.slot)
            table.absorb(old.slot, new.slot)
            old.history.extend(new.history)
            del self._tracks[new.track_id]
            self._tracks_changed()
            self._bank.remove(new.slot)
            self._counters.tracks_deleted += 1
            self._counters.tracks_handed_over += 1
            self._local_ids = {k: (old.track_id if v == new.track_id else v)
                               for k, v in self._local_ids.items()}  # fmt: skip
        if resumed:  # back in id order
            self._tracks = dict(sorted(self._tracks.items()))
            self._tracks_changed()

    def _retire(self, track: _Track, successor_id: int) -> bool:
        """End ``track`` (live or lost) now, its history handed out if it was confirmed, its
        sensor local ids handed to ``successor_id``; False if it is gone already."""
        if track.track_id in self._lost:
            del self._lost[track.track_id]
        elif track.track_id in self._tracks:
            del self._tracks[track.track_id]
            self._tracks_changed()
            self._counters.tracks_deleted += 1
        else:
            return False
        self._bank.remove(track.slot)
        if self._table.confirmed[track.slot]:
            self._finished.append(track.to_history())
        self._local_ids = {k: (successor_id if v == track.track_id else v)
                           for k, v in self._local_ids.items()}  # fmt: skip
        return True

    def _speed_change_explains(self, along: F64, dv_along: F64, unseen_s: F64,
                               started_after: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:  # fmt: skip
        """Which (old, new) pairs a change of speed while unseen explains, shape (O, N).

        ``along``: the young track ahead of the old one's constant-velocity prediction [m];
        ``dv_along``: its velocity minus the old one's, along the old one's heading [m/s];
        ``unseen_s`` (O,): time since the old track's last update. With the acceleration at
        most ``a`` in size and of one sign, the vehicle's speed changed by ``dv`` in
        ``|dv| / a`` at least, so ``|dv| <= a T``, and the young track is displaced in the
        direction of ``dv`` by between ``dv^2 / (2 a)`` and ``|dv| T - dv^2 / (2 a)``."""
        settings = self.settings
        a, slack = settings.hand_over_max_accel_mps2, settings.hand_over_kinematic_slack_m
        change = np.abs(dv_along)
        shift = np.sign(dv_along) * along  # displacement in the direction of the change
        least = change**2 / (2.0 * a)
        most = change * unseen_s[:, None] - least
        return (started_after & (change <= a * unseen_s[:, None])
                & (shift >= least - slack) & (shift <= most + slack))  # fmt: skip

    def _merge_duplicates(self, stamp_s: float) -> None:
        """Delete the younger of two tracks that are one vehicle (``merge_distance_m``).

        The older track (more updates; then the lower id) keeps the identity; the other is
        removed as if expired, its sensor local ids handed to the survivor.
        """
        settings = self.settings
        if settings.merge_distance_m <= 0.0 or len(self._tracks) + len(self._lost) < 2:
            return
        if stamp_s < self._next_merge_s:
            return
        self._next_merge_s = stamp_s + _MERGE_PERIOD_S
        self._hand_over(stamp_s)
        if len(self._tracks) < 2:
            return
        live, slots = self._live()
        x = self._bank.states(slots)
        dt = stamp_s - self._bank.stamps_s(slots)
        x[:, :2] += x[:, 2:] * dt[:, None]  # positions at the stamp (constant velocity)
        # Sorted along x, a duplicate is within merge_distance_m in x: the candidates of the
        # i-th are the next ones up to hi[i] (exclusive). The close pairs are collected as index
        # arrays; a (T, T) matrix only when there are any.
        order_x = np.argsort(x[:, 0])
        xs = x[order_x, 0]
        n = len(live)
        counts = np.searchsorted(xs, xs + settings.merge_distance_m, side="left") - np.arange(n) - 1
        first = np.repeat(np.arange(n), counts)
        # the k-th candidate of i is i + k + 1
        second = first + np.arange(len(first)) - np.repeat(np.cumsum(counts) - counts, counts) + 1
        a, b = order_x[first], order_x[second]
        near = np.hypot(x[a, 0] - x[b, 0], x[a, 1] - x[b, 1]) < settings.merge_distance_m
        pairs_i, pairs_j = a[near], b[near]
        slow = np.hypot(x[pairs_i, 2] - x[pairs_j, 2], x[pairs_i, 3] - x[pairs_j, 3]) >= (
            settings.merge_velocity_difference_mps)  # fmt: skip
        pairs_i, pairs_j = pairs_i[~slow], pairs_j[~slow]
        if not len(pairs_i):
            return
        close = np.zeros((len(live), len(live)), dtype=bool)
        close[pairs_i, pairs_j] = close[pairs_j, pairs_i] = True
        hits = self._table.hits[slots].tolist()
        order = sorted(range(len(live)), key=lambda i: (-hits[i], live[i].track_id))
        removed: dict[int, int] = {}  # removed track id -> survivor id
        for i in order:
            if live[i].track_id in removed:
                continue
            for j in np.flatnonzero(close[i]):
                other = live[int(j)]
                if other.track_id not in removed and other.track_id != live[i].track_id:
                    removed[other.track_id] = live[i].track_id
        for track_id, survivor in removed.items():
            self._retire(self._tracks[track_id], successor_id=survivor)
            self._counters.tracks_merged += 1

    def _prune(self, stamp_s: float) -> None:
        live, slots = self._live()
        if not live:
            expired: list[_Track] = []
        else:
            expired_rows = np.flatnonzero(self._expired(slots, stamp_s)).tolist()
            expired = [live[i] for i in expired_rows]
        memory_s = self.settings.lost_memory_s
        confirmed = self._table.confirmed
        for track in expired:
            del self._tracks[track.track_id]
            self._tracks_changed()
            self._counters.tracks_deleted += 1
            if confirmed[track.slot] and memory_s > 0.0:
                track.lost_s = stamp_s  # its slot stays, for the hand-over's prediction
                self._lost[track.track_id] = track
                continue
            self._bank.remove(track.slot)
            if confirmed[track.slot]:
                self._finished.append(track.to_history())
        if self._lost:
            for track in [t for t in self._lost.values() if stamp_s - t.lost_s > memory_s]:
                del self._lost[track.track_id]
                self._bank.remove(track.slot)
                self._finished.append(track.to_history())
        if expired:
            gone = {t.track_id for t in expired}
            self._local_ids = {k: v for k, v in self._local_ids.items() if v not in gone}
