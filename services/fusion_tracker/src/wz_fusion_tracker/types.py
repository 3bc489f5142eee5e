"""The tracker's record types: what goes in (:class:`Measurement`), what comes out
(:class:`TrackState`, :class:`TrackHistory`) and what it counts (:class:`TrackerCounters`).

Plain frozen dataclasses of floats and numpy arrays, site frame, metres and seconds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64, IntP

TrackStatus = Literal["tentative", "confirmed", "coasting"]
#: Road heading [rad, counter-clockwise from east] at a site position ``(x_m, y_m)``.
HeadingAt = Callable[[float, float], float]
#: :data:`HeadingAt` for arrays of positions.
HeadingsAt = Callable[[F64, F64], npt.ArrayLike]

#: The class a detector reports when it cannot tell; never outvotes a known class.
UNKNOWN_CLASS = "unknown"

#: No pairs: an empty index array (read-only, shared).
NO_INDEX: IntP = np.zeros(0, dtype=np.intp)
NO_INDEX.flags.writeable = False


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
    completed_from_far_end
        The sensor completed the box's length from its end away from it (its near end unseen):
        re-centring with the track's length moves it towards the sensor, not away.
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
    completed_from_far_end: bool = False


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
    """The updates of one track, for :func:`~wz_shared.motion.rts_smooth`.

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
    #: Measurements that took up a track outside its gate
    #: (:func:`~wz_fusion_tracker.identity.reacquisitions`).
    tracks_reacquired: int = 0
    #: Young tracks that handed their vehicle back to a coasting track
    #: (:func:`~wz_fusion_tracker.identity.hand_over`).
    tracks_handed_over: int = 0
    #: ... of which to a lost track (``lost_memory_s``), which then lived again.
    tracks_resumed: int = 0
    #: Coasting or lost tracks ended by :func:`~wz_fusion_tracker.identity.hand_over` in
    #: favour of the young track that took their vehicle up: its id was published already, or
    #: the old track slid across the road (``hand_over_max_lateral_speed_mps``).
    tracks_superseded: int = 0
    #: Unmatched measurements that started no track, being near a confirmed one
    #: (:attr:`TrackerSettings.spawn_gate_chi2`).
    measurements_suppressed: int = 0
    #: Unmatched measurements that started no track, their position too uncertain
    #: (:attr:`TrackerSettings.spawn_max_std_m`).
    measurements_unlocated: int = 0
    #: Radar speeds outside their gate (:attr:`TrackerSettings.speed_gate_chi2`), not used.
    speeds_rejected: int = 0
