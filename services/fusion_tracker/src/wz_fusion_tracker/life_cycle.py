"""A track's life cycle: started from a measurement no track took, confirmed after enough hits,
deleted when it stops being updated (or kept coasting through a sensor's outage, or while
another vehicle hides it), kept as lost for a while for the hand-over, then ended. Functions on
the :class:`TrackStore`, called by :class:`~wz_fusion_tracker.tracker.MultiTargetTracker`'s
cycle (spawn and prune steps)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.track_table import Track, TrackStore
from wz_fusion_tracker.types import Measurement
from wz_shared.arrays import F64, Bool, IntP
from wz_shared.motion import STATE_DIM
from wz_shared.occlusion import CLASS_HEIGHT_M, Boxes


def start_track(
    store: TrackStore,
    settings: TrackerSettings,
    track_id: int,
    measurement: Measurement,
    R: F64,
    sensor_id: str,
    stamp_s: float,
    heading: float | None,
) -> Track:
    """Start tentative track ``track_id``: ``x = [z, v0]``, ``P = blockdiag(R, P_v)``.

    Without a road heading: ``v0 = 0``, ``P_v = sigma_v^2 I``. With one, ``h``:
    ``v0 = s (cos h, sin h)`` with ``s`` the radar speed (std ``speed_std_mps``) or
    ``initial_speed_mps`` (std ``initial_velocity_std_mps``), and
    ``P_v = Rot(h) diag(std_s^2, sigma_across_v^2) Rot(h)^T``, ``h`` the road's heading at the
    measurement (None: no road there).
    """
    x = np.array([measurement.x_m, measurement.y_m, 0.0, 0.0])
    P = np.zeros((STATE_DIM, STATE_DIM))
    P[:2, :2] = R
    speed_from_prior = False
    if heading is None:
        P[2, 2] = P[3, 3] = settings.initial_velocity_std_mps**2
    else:
        if settings.use_speed_measurements and measurement.speed_mps is not None:
            speed, speed_std = measurement.speed_mps, settings.speed_std_mps
        else:
            speed, speed_std = settings.initial_speed_mps, settings.initial_velocity_std_mps
            speed_from_prior = True
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
    track = Track(
        track_id=track_id,
        slot=store.bank.add(x, P, stamp_s),
        max_history=settings.max_history,
        speed_from_prior=speed_from_prior,
    )
    table = store.table
    table.reset(track.slot, stamp_s, heading)
    store.tracks[track.track_id] = track
    store.changed()
    store.counters.tracks_started += 1
    length, width = measurement.length_m, measurement.width_m
    table.record_hits(
        np.array([track.slot]),
        stamp_s,
        table.sensor_column(sensor_id),
        np.array([table.class_column(measurement.object_class)]),
        np.array([measurement.score], dtype=np.float64),
        np.array([math.nan if length is None else length], dtype=np.float64),
        np.array([math.nan if width is None else width], dtype=np.float64),
    )
    track.hit_stamps_s.append(stamp_s)
    track.history.append(((stamp_s, x[None], P[None], x[None], P[None]), 0))
    if measurement.local_track_id is not None:
        store.local_ids[(sensor_id, measurement.local_track_id)] = track.track_id
    check_confirmation(store, settings, track, stamp_s)
    return track


def check_confirmation(
    store: TrackStore, settings: TrackerSettings, track: Track, stamp_s: float
) -> None:
    """Confirm a tentative track with ``confirm_hits`` hits within ``confirm_window_s``,
    ``confirm_min_age_s`` after its first; its hit stamps (the latest appended)."""
    window_start_s = stamp_s - settings.confirm_window_s
    while track.hit_stamps_s and track.hit_stamps_s[0] < window_start_s:
        track.hit_stamps_s.popleft()
    table = store.table
    if (
        not table.confirmed[track.slot]
        and len(track.hit_stamps_s) >= settings.confirm_hits
        and stamp_s - table.born_s[track.slot] >= settings.confirm_min_age_s
    ):
        table.confirmed[track.slot] = True
        table.confirmed_s[track.slot] = stamp_s
        track.hit_stamps_s.clear()  # only needed until confirmation
        store.counters.tracks_confirmed += 1


#: Whether a site point ``(x_m, y_m)`` lies in a stretch no sensor sees between seen ones
#: (:class:`wz_shared.coverage.SensorGaps`).
InSensorGap = Callable[[float, float], bool]
#: Whether other vehicles (``Boxes``) hide each point (K, 3) [m] from every sensor that covers
#: it (:meth:`wz_shared.coverage.SiteSight.hidden`).
HiddenFromSensors = Callable[[F64, Boxes], Bool]


@dataclass(frozen=True)
class Sight:
    """Where the site's sensors cannot see a vehicle, as the life cycle asks it: stretches no
    sensor covers (``in_sensor_gap``) and spots other vehicles hide (``hidden_from_sensors``);
    None: not known."""

    in_sensor_gap: InSensorGap | None = None
    hidden_from_sensors: HiddenFromSensors | None = None


def expired(
    store: TrackStore,
    settings: TrackerSettings,
    slots: IntP,
    stamp_s: float,
    last_batch_s: Mapping[str, float],
    sight: Sight = Sight(),
) -> Bool:
    """Which tracks of ``slots`` are to be deleted at ``stamp_s``, shape (K,).

    A tentative track not updated for ``tentative_max_age_s``, a confirmed one for
    ``max_coast_s``; but a confirmed track one of whose sensors has gone silent (an outage,
    not a vehicle gone: no batch from it for ``sensor_silent_after_s``) coasts up to
    ``max_outage_coast_s``, so it keeps its id when the sensor comes back. Any, not all:
    a vehicle passing under the mast during a LiDAR outage also leaves the camera's view,
    and the camera still sending frames does not mean it could see the vehicle.
    A confirmed track whose predicted position lies in a stretch no sensor sees, or did
    ``max_coast_s`` ago (``in_sensor_gap``: the blind cone under a mast, between the cameras
    facing upstream and the LiDAR's first beams on the road), coasts up to
    ``max_gap_coast_s``: the vehicle is out of sight, not gone, and comes back on the far
    side, where a new track would take a new id.
    A confirmed track whose predicted position other tracked vehicles hide from every sensor
    that covers it (``hidden_from_sensors``: a car beside or behind a truck) coasts up to
    ``max_occlusion_coast_s``: the sensors cannot see it, so missing it says nothing.
    ``last_batch_s``: the newest batch stamp processed per sensor."""
    table = store.table
    updated_s = table.updated_s[slots]
    age_s = stamp_s - updated_s
    confirmed = table.confirmed[slots]
    deleted: Bool = np.where(
        confirmed, age_s > settings.max_coast_s, age_s > settings.tentative_max_age_s
    )
    outage = np.flatnonzero(deleted & confirmed & (age_s <= settings.max_outage_coast_s))
    if len(outage):
        # the sensors that saw it shortly before its last update, and the silent ones
        seen = table.sensor_updated_s[slots[outage]]
        recent = seen >= (updated_s[outage] - settings.max_coast_s)[:, None]
        newest_s = np.array([last_batch_s.get(sensor, -math.inf) for sensor in table.sensor_ids])
        silent = newest_s < stamp_s - settings.sensor_silent_after_s
        deleted[outage] = ~(recent & silent[None, :]).any(axis=1)
    in_sensor_gap = sight.in_sensor_gap
    if in_sensor_gap is not None and settings.coast_sensor_gaps:
        hidden = np.flatnonzero(deleted & confirmed & (age_s <= settings.max_gap_coast_s))
        if len(hidden):
            bank = store.bank
            x = bank.states(slots[hidden])
            dt = stamp_s - bank.stamps_s(slots[hidden])
            # in the gap now, or a coast ago: out of it, it is given the usual coast to be
            # taken up again on the far side
            for k, row in enumerate(hidden.tolist()):
                times = (dt[k], max(0.0, dt[k] - settings.max_coast_s))
                if in_gap_at(x[k, :2], x[k, 2:], times, in_sensor_gap):
                    deleted[row] = False
    if sight.hidden_from_sensors is not None and settings.max_occlusion_coast_s > 0.0:
        rows = np.flatnonzero(deleted & confirmed & (age_s <= settings.max_occlusion_coast_s))
        if len(rows):
            deleted[rows] = ~hidden_now(store, slots[rows], stamp_s, sight.hidden_from_sensors)
    return deleted


def hidden_now(
    store: TrackStore, slots: IntP, stamp_s: float, hidden_from_sensors: HiddenFromSensors
) -> Bool:
    """Whether the other tracks hide each of ``slots`` (K,) from every sensor covering it at
    ``stamp_s``: each predicted along the road (:func:`along_road`) to its roof (its class's
    height), the live tracks in the way predicted at their velocities, as boxes of their
    measured footprints and their classes' heights (:class:`~wz_shared.occlusion.Boxes`)."""
    x, u, along_speed = along_road(store, slots)
    dt = stamp_s - store.bank.stamps_s(slots)
    table = store.table
    targets = np.column_stack(
        [
            x[:, :2] + (u * (along_speed * dt)[:, None]),
            [CLASS_HEIGHT_M.get(c, CLASS_HEIGHT_M["unknown"]) for c in table.object_classes(slots)],
        ]
    )
    _, others = store.live()
    if not len(others):
        return np.zeros(len(slots), dtype=bool)
    y, axis, _ = along_road(store, others)
    ahead = y[:, :2] + y[:, 2:] * (stamp_s - store.bank.stamps_s(others))[:, None]
    sizes = table.sizes(others)
    heading = np.arctan2(axis[:, 1], axis[:, 0])
    boxes = Boxes.of(
        ahead[:, 0], ahead[:, 1], heading, sizes[:, 0], sizes[:, 1], table.object_classes(others)
    )
    return hidden_from_sensors(targets, boxes)


def in_gap_at(
    start_xy: F64, velocity_xy: F64, times_s: Iterable[float], in_sensor_gap: InSensorGap
) -> bool:
    """Whether a track at ``start_xy`` moving at ``velocity_xy`` lies in a sensor gap at any
    of ``times_s`` after (a road-frame lookup each: a few points, not a sweep)."""
    for t in times_s:
        px, py = start_xy + velocity_xy * t
        if in_sensor_gap(float(px), float(py)):
            return True
    return False


def along_road(store: TrackStore, slots: IntP) -> tuple[F64, F64, F64]:
    """What an unseen track is predicted with: its state (K, 4), its heading's unit vector
    (K, 2) (the road's where known, else its velocity's) and its speed along it (K,).
    Predicted along the road (that speed along that heading, the offset across held):
    seconds of a lateral velocity carried forward would put it off the road, and a vehicle
    that changed lanes while hidden (a late merge behind a truck) comes back one lane over
    from where it was last seen, not from that drift."""
    x = store.bank.states(slots)
    heading = store.table.heading_rad[slots]
    heading = np.where(np.isfinite(heading), heading, np.arctan2(x[:, 3], x[:, 2]))
    u = np.stack([np.cos(heading), np.sin(heading)], axis=1)
    return x, u, np.einsum("tk,tk->t", x[:, 2:], u)


def _out_of_gaps(
    store: TrackStore,
    settings: TrackerSettings,
    tracks: list[Track],
    stamp_s: float,
    in_sensor_gap: InSensorGap,
) -> list[Track]:
    """Of lost ``tracks`` past ``lost_memory_s``, those to forget at ``stamp_s``: all but the
    ones predicted in a sensor gap now or ``lost_memory_s`` ago (and lost for less than
    ``max_gap_memory_s``). Predicted as the hand-over does: along the track's heading at its
    speed along it, its offset across held."""
    slots = np.array([t.slot for t in tracks], dtype=np.intp)
    x, u, along_speed = along_road(store, slots)
    dt = stamp_s - store.bank.stamps_s(slots)
    return [
        track
        for k, track in enumerate(tracks)
        if stamp_s - track.lost_s > settings.max_gap_memory_s
        or not in_gap_at(
            x[k, :2],
            u[k] * along_speed[k],
            (dt[k], max(0.0, dt[k] - settings.lost_memory_s)),
            in_sensor_gap,
        )
    ]


def _unhidden(
    store: TrackStore,
    settings: TrackerSettings,
    tracks: list[Track],
    stamp_s: float,
    hidden_from_sensors: HiddenFromSensors,
) -> list[Track]:
    """Of lost ``tracks`` past ``lost_memory_s``, those to forget at ``stamp_s``: all but the
    ones other vehicles still hide (:func:`hidden_now`) that were lost for less than
    ``max_occlusion_memory_s``: a car that stays beside a truck in a queue comes back when the
    truck pulls away, and the hand-over gives it its old id."""
    young = [t for t in tracks if stamp_s - t.lost_s <= settings.max_occlusion_memory_s]
    if not young:
        return tracks
    slots = np.array([t.slot for t in young], dtype=np.intp)
    keep = {
        t.track_id
        for t, hid in zip(
            young, hidden_now(store, slots, stamp_s, hidden_from_sensors), strict=True
        )
        if hid
    }
    return [t for t in tracks if t.track_id not in keep]


def prune(
    store: TrackStore,
    settings: TrackerSettings,
    stamp_s: float,
    last_batch_s: Mapping[str, float],
    sight: Sight = Sight(),
) -> None:
    """Delete the tracks expired at ``stamp_s`` (:func:`expired`): a confirmed one is kept as
    lost for ``lost_memory_s`` (its slot too, for the hand-over; longer in a sensor gap or
    hidden by other vehicles, ``sight``), then ends and its history is handed out; the
    sensors' local ids that pointed at a deleted track are forgotten."""
    live, slots = store.live()
    if not live:
        gone_tracks: list[Track] = []
    else:
        expired_rows = np.flatnonzero(
            expired(store, settings, slots, stamp_s, last_batch_s, sight)
        ).tolist()
        gone_tracks = [live[i] for i in expired_rows]
    memory_s = settings.lost_memory_s
    confirmed = store.table.confirmed
    for track in gone_tracks:
        del store.tracks[track.track_id]
        store.changed()
        store.counters.tracks_deleted += 1
        if confirmed[track.slot] and memory_s > 0.0:
            track.lost_s = stamp_s  # its slot stays, for the hand-over's prediction
            store.lost[track.track_id] = track
            continue
        store.bank.remove(track.slot)
        if confirmed[track.slot]:
            store.finished.append(track.to_history())
    if store.lost:
        forgotten = [t for t in store.lost.values() if stamp_s - t.lost_s > memory_s]
        in_sensor_gap = sight.in_sensor_gap
        if forgotten and in_sensor_gap is not None and settings.max_gap_memory_s > 0.0:
            forgotten = _out_of_gaps(store, settings, forgotten, stamp_s, in_sensor_gap)
        hide = sight.hidden_from_sensors
        if forgotten and hide is not None and settings.max_occlusion_memory_s > 0.0:
            forgotten = _unhidden(store, settings, forgotten, stamp_s, hide)
        for track in forgotten:
            del store.lost[track.track_id]
            store.bank.remove(track.slot)
            store.finished.append(track.to_history())
    if gone_tracks:
        gone = {t.track_id for t in gone_tracks}
        local_ids = store.local_ids
        store.local_ids = {k: v for k, v in local_ids.items() if v not in gone}
