"""Identity: the steps that keep a vehicle's track id through gaps, duplicates and hand-overs.

Each step works on the :class:`~wz_fusion_tracker.track_table.TrackStore` at a batch's stamp;
the tracker's cycle calls them in this order:

- :func:`reacquisitions` (after the update): a confirmed track that missed a few updates takes
  up an unmatched measurement near it on the road, outside its gate;
- :func:`hand_over` (every :data:`IDENTITY_PERIOD_S`): a young track that took up a coasting
  or lost track's vehicle hands its state to the old track, so the vehicle keeps its old id;
- :func:`merge_duplicates` (right after): of two tracks that are one vehicle, the younger goes;
- :func:`merge_into_trucks` (then): a young track inside a tracked truck's footprint, moving
  with it, is part of that truck (its trailer seen apart from its cab) and goes;
- :func:`retire`: how the hand-over and the merging end a track in favour of another.

A confirmed track past its coast is deleted by the tracker's prune but kept *lost* for
``lost_memory_s`` (not published, taking no measurement): the hand-over may resume it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

from wz_fusion_tracker.association import gnn_assign
from wz_fusion_tracker.life_cycle import InSensorGap, along_road, in_gap_at
from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.track_table import Track, TrackStore
from wz_shared.arrays import F64, IntP

#: The hand-over and duplicate merging run at most this often (data time) [s].
IDENTITY_PERIOD_S = 0.1
#: A track confirmed this long ago [s] has been in a published snapshot (the node publishes
#: at 10 Hz): see :func:`hand_over`.
_PUBLISHED_AFTER_S = 0.1

#: The states of some slots predicted to a stamp with each track's process noise, ``(x (K, 4),
#: P (K, 4, 4))``: the tracker's own prediction.
Predicted = Callable[[IntP, float], tuple[F64, F64]]


def reacquisitions(
    store: TrackStore,
    settings: TrackerSettings,
    slots: IntP,
    x_pred: F64,
    P_pred: F64,
    z: F64,
    pairs: Sequence[tuple[int, int]],
    stamp_s: float,
    time_offset_s: F64 | None,
) -> tuple[list[tuple[int, int]], F64]:
    """Re-acquisition: a confirmed track that has missed updates takes up a measurement near
    it on the road, outside its (by then overconfident) gate.

    A vehicle lost for a few tenths of a second (the LiDAR's blind spot under the mast, an
    occlusion) often comes back a couple of metres from its prediction: biased detections
    before the gap bent its velocity. Rather than start a second track, a measurement left
    unmatched within ``reacquire_along_m`` along and ``reacquire_across_m`` across the
    track's direction updates it, its prior widened by the innovation ``y``
    (``P_pos += y y^T``, ``P_vel += y y^T / gap^2``) so the update can follow. The velocity's
    widening is held to what a speed change of ``reacquire_max_accel_mps2`` over the gap
    explains (``P_vel += y y^T min(1 / gap^2, (a gap)^2 / |y|^2)``): 2 m in 0.3 s is a box that
    came back off its vehicle's centre (a car's front coming into the sparse far rings of a
    LiDAR, 2.2 m long), not a car 7 m/s off its track's speed. Unheld, the next sweep's
    half-metre innovation 0.05 s later took the track from 11.5 to 28.6 m/s (site 9600).

    Parameters
    ----------
    slots, x_pred, P_pred
        The live tracks' slots (T,) and predicted states (T, 4) and covariances (T, 4, 4).
    z
        The batch's measured positions (M, 2) [m].
    pairs
        The (track row, measurement column) pairs the association matched.
    time_offset_s
        Each measurement's capture time after the stamp (M,) [s], or None for all zero.

    Returns
    -------
    new_pairs, P_wide
        The (track row, measurement column) pairs re-acquired, and ``P_pred`` with their
        priors widened: the caller updates those tracks with them.
    """
    table = store.table
    waiting = table.confirmed[slots] & (
        stamp_s - table.updated_s[slots] >= settings.reacquire_after_s
    )
    free = np.ones(len(z), dtype=bool)
    if pairs:
        matched_rows, matched_columns = zip(*pairs, strict=True)
        waiting[list(matched_rows)] = False
        free[list(matched_columns)] = False
    rows, columns = np.flatnonzero(waiting), np.flatnonzero(free)
    if len(rows) == 0 or len(columns) == 0:
        return [], P_pred
    delta = time_offset_s[columns] if time_offset_s is not None else np.zeros(len(columns))
    xr = x_pred[rows]
    y = z[columns][None, :, :] - (xr[:, None, :2] + xr[:, None, 2:] * delta[None, :, None])
    speed = np.hypot(xr[:, 2], xr[:, 3])
    heading = table.heading_rad[slots[rows]]
    own = np.arctan2(xr[:, 3], xr[:, 2])
    heading = np.where(
        np.isfinite(heading) & (speed <= settings.heading_min_speed_mps), heading, own
    )
    u = np.stack([np.cos(heading), np.sin(heading)], axis=1)
    along = np.einsum("tmi,ti->tm", y, u)
    across = y[..., 1] * u[:, None, 0] - y[..., 0] * u[:, None, 1]
    allowed = (np.abs(along) <= settings.reacquire_along_m) & (
        np.abs(across) <= settings.reacquire_across_m
    )
    if not allowed.any():
        return [], P_pred
    found = gnn_assign(np.hypot(along, across), allowed)
    if not found:
        return [], P_pred
    new_pairs = [(int(rows[r]), int(columns[c])) for r, c in found]
    P_wide = P_pred.copy()
    for (row, _column), (r, c) in zip(new_pairs, found, strict=True):
        gap_s = max(stamp_s - float(table.updated_s[slots[row]]), 0.1)
        outer = np.outer(y[r, c], y[r, c])
        P_wide[row, :2, :2] += outer
        scale = 1.0 / gap_s**2
        if settings.reacquire_max_accel_mps2 > 0.0:
            size2 = max(float(outer[0, 0] + outer[1, 1]), 1e-12)
            scale = min(scale, (settings.reacquire_max_accel_mps2 * gap_s) ** 2 / size2)
        P_wide[row, 2:, 2:] += outer * scale
    store.counters.tracks_reacquired += len(new_pairs)
    return new_pairs, P_wide


def hand_over(
    store: TrackStore,
    settings: TrackerSettings,
    stamp_s: float,
    in_sensor_gap: InSensorGap | None = None,
    predicted: Predicted | None = None,
) -> None:
    """Hand-over: a young track that took up a coasting track's vehicle hands its state to it.

    When a vehicle comes back too far from its coasting track's prediction even for
    :func:`reacquisitions` (a long gap, a bent velocity), a new track starts on it. While the
    new track is young (``hand_over_age_s``) and the old one coasts just behind or ahead of
    it (``hand_over_along_m``, ``hand_over_across_m``: the same lane or the next), moving alike
    (within the young track's own velocity uncertainty: :func:`_velocity_within_std`; or at a
    speed and place that braking or speeding up while unseen explains:
    :func:`_speed_change_explains`), and the new one was updated after the old one last
    was, they are one vehicle: the old track takes the new one's state and the new one
    goes, so the vehicle keeps its identity. With ``predicted`` (the tracker's prediction)
    and ``hand_over_fuses_speed``, the speed along the road the old track predicts over its
    gap is fused into that state by the variances (:func:`_fuse_old_speed`).
    The old track is predicted along the road at its speed there, its offset across the
    road held, so the lane test measures from where the vehicle was last seen.
    The old track may also be a lost one (past its coast, within ``lost_memory_s``): it
    lives again. An old track sliding across the road (``hand_over_max_lateral_speed_mps``)
    is no vehicle's: it ends, and the young track carries on. The hand-over runs every
    ``IDENTITY_PERIOD_S``, so it usually comes while the new track is still tentative, and
    the new id is never published. When the new track
    was confirmed ``_PUBLISHED_AFTER_S`` ago or more (its id published: it started while the
    old one was still being updated, a duplicate that took the vehicle over), the vehicle
    keeps the new id and the old track ends: handing it back would change the vehicle's id
    twice.
    """
    table = store.table
    if settings.hand_over_along_m <= 0.0 or len(store.tracks) + len(store.lost) < 2:
        return
    live, slots = store.live()
    updated_s = table.updated_s[slots]
    waiting = table.confirmed[slots] & (stamp_s - updated_s >= settings.reacquire_after_s)
    coasting = [live[i] for i in np.flatnonzero(waiting).tolist()]
    coasting += store.lost.values()
    born_s = table.born_s[slots]
    is_young = (stamp_s - born_s <= settings.hand_over_age_s) & (updated_s > born_s)
    young = [live[i] for i in np.flatnonzero(is_young).tolist()]
    if not coasting or not young:
        return
    old_slots = np.array([t.slot for t in coasting], dtype=np.intp)
    new_slots = np.array([t.slot for t in young], dtype=np.intp)
    x_old, u, along_speed = along_road(store, old_slots)  # predicted along the road
    last_s = store.bank.stamps_s(old_slots)
    x_old[:, :2] += u * (along_speed * (stamp_s - last_s))[:, None]
    x_new = store.bank.states(new_slots)
    x_new[:, :2] += x_new[:, 2:] * (stamp_s - store.bank.stamps_s(new_slots))[:, None]
    d = x_new[None, :, :2] - x_old[:, None, :2]  # (old, new, 2)
    along = np.einsum("onk,ok->on", d, u)
    across = d[..., 1] * u[:, None, 0] - d[..., 0] * u[:, None, 1]
    dv = np.hypot(x_new[None, :, 2] - x_old[:, None, 2], x_new[None, :, 3] - x_old[:, None, 3])
    # The young track must have taken the vehicle up: updated after the old one last was.
    # A stray young track (a box split off a truck's trailer, 7 m behind it) whose last
    # update is older than the coasting track's is not its vehicle come back.
    took_up = table.updated_s[new_slots][None, :] > table.updated_s[old_slots][:, None]
    alike = dv < settings.merge_velocity_difference_mps
    near = (
        (np.abs(along) <= settings.hand_over_along_m)
        & (np.abs(across) <= settings.hand_over_across_m)
        & took_up
    )
    if settings.hand_over_velocity_sigmas > 0.0 and in_sensor_gap is not None:
        # Across a stretch no sensor sees, the vehicle comes back where a sensor first sees
        # it, and its young track's speed is what the first boxes of a vehicle coming into
        # view say: the tolerance grows with that track's own velocity std. Not elsewhere:
        # in a queue, a young track of unknown speed beside a truck is any of its neighbours.
        loose = near & ~alike
        if loose.any():
            loose &= _velocity_within_std(
                settings, u, x_old[:, 2:], x_new[:, 2:], store.bank.covariances(new_slots)
            )
        for row in np.flatnonzero(loose.any(axis=1)).tolist():
            # its predicted way, from its last update to now, checked at five points
            unseen_s = stamp_s - float(last_s[row])
            velocity = u[row] * along_speed[row]
            start = x_old[row, :2] - velocity * unseen_s
            shares = (0.0, 0.25, 0.5, 0.75, 1.0)
            if in_gap_at(start, velocity, [unseen_s * f for f in shares], in_sensor_gap):
                alike[row] |= loose[row]
    if settings.hand_over_max_accel_mps2 > 0.0:
        alike |= _speed_change_explains(
            settings,
            along,
            np.einsum("onk,ok->on", x_new[None, :, 2:] - x_old[:, None, 2:], u),
            stamp_s - table.updated_s[old_slots],
            table.born_s[new_slots][None, :] > table.updated_s[old_slots][:, None],
        )
    sliding = np.abs(x_old[:, 3] * u[:, 0] - x_old[:, 2] * u[:, 1]) > (
        settings.hand_over_max_lateral_speed_mps
    )
    allowed = near & alike
    if not allowed.any():
        return
    resumed = False
    for row, column in gnn_assign(np.abs(along) + np.abs(across), allowed):
        old, new = coasting[row], young[column]
        if new.track_id not in store.tracks:
            continue
        published = stamp_s - table.confirmed_s[new.slot] >= _PUBLISHED_AFTER_S  # NaN: no
        if published or sliding[row]:
            # The young id is published already: giving the vehicle its old id back would
            # rename it a second time. Or the old track slides across the road, no
            # vehicle's. The young track keeps the vehicle; the old one ends.
            if retire(store, old, successor_id=new.track_id):
                store.counters.tracks_superseded += 1
            continue
        if old.track_id in store.lost:
            store.tracks[old.track_id] = store.lost.pop(old.track_id)
            store.counters.tracks_resumed += 1
            resumed = True
        elif old.track_id not in store.tracks:
            continue
        old_speed: tuple[float, float] | None = None
        if predicted is not None and settings.hand_over_fuses_speed:
            young_s = float(store.bank.stamps_s(np.array([new.slot]))[0])
            _, P_old = predicted(np.array([old.slot], dtype=np.intp), young_s)
            old_speed = (float(along_speed[row]), float(u[row] @ P_old[0, 2:, 2:] @ u[row]))
        store.bank.copy_slot(new.slot, old.slot)
        if old_speed is not None:
            _fuse_old_speed(store, settings, old.slot, u[row], *old_speed, new.speed_from_prior)
        table.absorb(old.slot, new.slot)
        old.history.extend(new.history)
        del store.tracks[new.track_id]
        store.changed()
        store.bank.remove(new.slot)
        store.counters.tracks_deleted += 1
        store.counters.tracks_handed_over += 1
        store.local_ids = {
            k: (old.track_id if v == new.track_id else v) for k, v in store.local_ids.items()
        }
    if resumed:  # back in id order
        store.tracks = dict(sorted(store.tracks.items()))
        store.changed()


def _fuse_old_speed(
    store: TrackStore,
    settings: TrackerSettings,
    slot: int,
    u: F64,
    speed_mps: float,
    variance: float,
    from_prior: bool,
) -> None:
    """Fuse an old track's speed along the road ``u`` (2,), ``speed_mps`` with ``variance``
    [m^2/s^2] (its prediction over the gap), into the state at ``slot`` (the young track's, just
    handed over): one scalar Kalman update of the speed along ``u``, position and velocity
    moved by their correlation.

    Two estimates of one vehicle from disjoint data (the sensors before the gap, those after
    it) combine by their information. The young track's speed also holds its birth prior
    (``initial_speed_mps`` with ``initial_velocity_std_mps``, where it was started without a
    measured speed): that prior is taken out (``from_prior``), or it would be counted beside
    the old track's speed, and the vehicle would slow down on the hand-over. The update is
    then the old speed's information less the prior's, ``1/R = 1/var - 1/std0^2`` and
    ``z = R (v/var - v0/std0^2)``.
    """
    if not (math.isfinite(speed_mps) and math.isfinite(variance)) or variance <= 0.0:
        return
    information, weighted = 1.0 / variance, speed_mps / variance
    if from_prior:
        prior_information = 1.0 / settings.initial_velocity_std_mps**2
        information -= prior_information
        weighted -= settings.initial_speed_mps * prior_information
    if information <= 1e-9:
        return
    H = np.array([[0.0, 0.0, float(u[0]), float(u[1])]])
    store.bank.update(
        np.array([slot], dtype=np.intp),
        np.array([[weighted / information]]),
        np.array([[[1.0 / information]]]),
        H,
    )


def retire(store: TrackStore, track: Track, successor_id: int) -> bool:
    """Retirement: end ``track`` (live or lost) now, in favour of track ``successor_id`` that
    follows its vehicle from here on; False if it is gone already.

    Its history is handed out if it was confirmed (its trajectory ends here), and its sensors'
    local ids are handed to the successor, so a sensor that goes on tracking the vehicle under
    the same local id keeps pointing at the vehicle's track.
    """
    if track.track_id in store.lost:
        del store.lost[track.track_id]
    elif track.track_id in store.tracks:
        del store.tracks[track.track_id]
        store.changed()
        store.counters.tracks_deleted += 1
    else:
        return False
    store.bank.remove(track.slot)
    if store.table.confirmed[track.slot]:
        store.finished.append(track.to_history())
    store.local_ids = {
        k: (successor_id if v == track.track_id else v) for k, v in store.local_ids.items()
    }
    return True


def _velocity_within_std(
    settings: TrackerSettings, u: F64, v_old: F64, v_new: F64, P_new: F64
) -> npt.NDArray[np.bool_]:
    """Which (old, new) pairs' velocities agree, shape (O, N): along and across the old
    track's heading ``u`` (O, 2), within ``merge_velocity_difference_mps`` plus
    ``hand_over_velocity_sigmas`` of the young track's own velocity std (``P_new`` (N, 4, 4)).
    A young track's velocity is what its first few boxes say, and its covariance says how
    little that is."""
    w = np.stack([-u[:, 1], u[:, 0]], axis=1)  # across, to the left
    dv = v_new[None, :, :] - v_old[:, None, :]  # (O, N, 2)
    velocity_cov = P_new[:, 2:, 2:]
    tolerance = settings.merge_velocity_difference_mps
    k = settings.hand_over_velocity_sigmas
    within = np.ones(dv.shape[:2], dtype=bool)
    for axis in (u, w):
        difference = np.einsum("onk,ok->on", dv, axis)
        variance = np.einsum("ok,nkl,ol->on", axis, velocity_cov, axis)
        within &= np.abs(difference) <= tolerance + k * np.sqrt(np.maximum(variance, 0.0))
    return within


def _speed_change_explains(
    settings: TrackerSettings,
    along: F64,
    dv_along: F64,
    unseen_s: F64,
    started_after: npt.NDArray[np.bool_],
) -> npt.NDArray[np.bool_]:
    """Which (old, new) pairs a change of speed while unseen explains, shape (O, N).

    ``along``: the young track ahead of the old one's constant-velocity prediction [m];
    ``dv_along``: its velocity minus the old one's, along the old one's heading [m/s];
    ``unseen_s`` (O,): time since the old track's last update. With the acceleration at
    most ``a`` in size and of one sign, the vehicle's speed changed by ``dv`` in
    ``|dv| / a`` at least, so ``|dv| <= a T``, and the young track is displaced in the
    direction of ``dv`` by between ``dv^2 / (2 a)`` and ``|dv| T - dv^2 / (2 a)``."""
    a, slack = settings.hand_over_max_accel_mps2, settings.hand_over_kinematic_slack_m
    change = np.abs(dv_along)
    shift = np.sign(dv_along) * along  # displacement in the direction of the change
    least = change**2 / (2.0 * a)
    most = change * unseen_s[:, None] - least
    return (
        started_after
        & (change <= a * unseen_s[:, None])
        & (shift >= least - slack)
        & (shift <= most + slack)
    )


def merge_duplicates(store: TrackStore, settings: TrackerSettings, stamp_s: float) -> None:
    """Duplicate merging: two live tracks closer than ``merge_distance_m``, their velocities
    within ``merge_velocity_difference_mps``, are one vehicle tracked twice (a sensor's biased
    detection that missed the gate started a second track); the younger is retired.

    Adjacent lanes are 3.6 m apart and a following car is at least ~5 m behind, so no two
    vehicles are that close. The older track (more updates; then the lower id) keeps the
    identity; the other is removed as if expired, its sensor local ids handed to the survivor.
    """
    if settings.merge_distance_m <= 0.0 or len(store.tracks) < 2:
        return
    live, slots = store.live()
    x = store.bank.states(slots)
    dt = stamp_s - store.bank.stamps_s(slots)
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
        settings.merge_velocity_difference_mps
    )
    pairs_i, pairs_j = pairs_i[~slow], pairs_j[~slow]
    if not len(pairs_i):
        return
    close = np.zeros((len(live), len(live)), dtype=bool)
    close[pairs_i, pairs_j] = close[pairs_j, pairs_i] = True
    hits = store.table.hits[slots].tolist()
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
        retire(store, store.tracks[track_id], successor_id=survivor)
        store.counters.tracks_merged += 1


#: Classes whose long footprint a young track may lie in as part of the vehicle
#: (:func:`merge_into_trucks`).
_LONG_CLASSES = frozenset({"truck", "bus"})


def merge_into_trucks(store: TrackStore, settings: TrackerSettings, stamp_s: float) -> None:
    """A young track (younger than ``hand_over_age_s``) whose position lies inside a tracked
    truck's or bus's footprint (its measured median length and width, heading along the road,
    plus ``truck_merge_margin_m`` all round) and whose velocity is within
    ``merge_velocity_difference_mps`` of the truck's is the truck's own trailer or body seen
    apart from its cab (a LiDAR that splits a semitrailer at its coupling, a camera box of the
    trailer alone): it is retired in favour of the truck. A car is never inside a truck's
    footprint; one following 2 m behind a 16 m semitrailer has its centre 4 m beyond the
    rear. Off with ``truck_merge_margin_m`` < 0."""
    if settings.truck_merge_margin_m < 0.0 or len(store.tracks) < 2:
        return
    live, slots = store.live()
    table = store.table
    classes = table.object_classes(slots)
    long_rows = [i for i, c in enumerate(classes) if c in _LONG_CLASSES]
    if not long_rows:
        return
    age_s = stamp_s - table.born_s[slots]
    young_rows = np.flatnonzero(age_s < settings.hand_over_age_s)
    if not len(young_rows):
        return
    x = store.bank.states(slots)
    x[:, :2] += x[:, 2:] * (stamp_s - store.bank.stamps_s(slots))[:, None]
    sizes = table.sizes(slots)
    _, u, _ = along_road(store, slots)
    margin = settings.truck_merge_margin_m
    removed: dict[int, int] = {}
    for i in long_rows:
        length, width = sizes[i, 0], sizes[i, 1]
        if not (np.isfinite(length) and np.isfinite(width)) or age_s[i] < settings.hand_over_age_s:
            continue  # a young truck's footprint is not known yet
        d = x[young_rows, :2] - x[i, :2]
        along = d @ u[i]
        across = d @ np.array([-u[i, 1], u[i, 0]])
        alike = np.hypot(*(x[young_rows, 2:] - x[i, 2:]).T) < settings.merge_velocity_difference_mps
        inside = (np.abs(along) <= length / 2.0 + margin) & (np.abs(across) <= width / 2.0 + margin)
        for j in young_rows[inside & alike].tolist():
            if j != i and live[j].track_id not in removed:
                removed[live[j].track_id] = live[i].track_id
    for track_id, truck_id in removed.items():
        retire(store, store.tracks[track_id], successor_id=truck_id)
        store.counters.tracks_merged += 1
