"""Association: which measurement belongs to which track.

The steps of a tracker's data association (Stone Soup's hypothesiser and data associator), as
pure functions on arrays:

- *gate*: squared Mahalanobis distance of each (track, measurement) pair,
  ``d^2 = y^T S^-1 y``, ``y = z - H x_p``, ``S = H P_p H^T + R`` (:func:`innovation_statistics`,
  vectorised, and only for the pairs a cheap bound cannot rule out: :func:`gated_pairs`); pairs
  with ``d^2 > gate_chi2`` are forbidden. Mahalanobis rather than metres because the sensors'
  errors are far from round: a camera ranges badly along its line of sight and well across it,
  and a track's predicted uncertainty is long along the road, so a fixed radius in metres would
  be too tight one way and too loose the other. A radar speed far from a track's speed forbids
  the pair too (:func:`speed_gated`, Doppler-aided gating);
- *cost*: the innovation's negative log-likelihood ``d^2 + ln det S`` (:func:`association_cost`),
  lowered by ``local_track_id_bonus`` where the measurement's ``(sensor_id, local_track_id)``
  last updated the track (:func:`local_id_bonus`): the sensor's own continuity breaks near-ties
  (two similar cars at the same range), and only among pairs that pass the gate;
- *assign*: global nearest neighbour, the one-to-one assignment of least total cost
  (:func:`gnn_assign`, ``scipy.optimize.linear_sum_assignment``). Greedy nearest-first goes
  wrong where it matters: two cars side by side in adjacent lanes, 3.6 m apart. Confirmed
  tracks are served first, tentative ones get the measurements left (:func:`cascade_assign`):
  a spurious track started by one outlying detection must not steal a real track's detections;
- *robust update*: Huber's inflation of a matched outlier's covariance (:func:`huber_inflated`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.types import NO_INDEX, Measurement
from wz_shared.arrays import F64, IntP

#: Cost of a forbidden pair in the assignment: above any sum of allowed costs.
_FORBIDDEN_COST = 1e9
#: Above this many (track, measurement) pairs, gating first discards the pairs that cannot pass.
_SPARSE_GATE_MIN_PAIRS = 2000
#: d2 given to the pairs the pre-gate discards (beyond any gate the caller uses).
_FAR_D2 = 1e12


def innovation_statistics(
    x_pred: F64,
    P_pred: F64,
    z: F64,
    R: F64,
    time_offset_s: F64 | None = None,
    max_d2: float = 1e3,
) -> tuple[F64, F64]:
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


def _sparse_innovation_statistics(
    x_pred: F64, P_pred: F64, z: F64, R: F64, time_offset_s: F64 | None, max_d2: float
) -> tuple[F64, F64]:
    """:func:`innovation_statistics` on the pairs that can be near (:func:`_candidate_pairs`):
    the rest get ``_FAR_D2``."""
    rows, cols, pair_d2, pair_log_det = _candidate_statistics(
        x_pred, P_pred, z, R, time_offset_s, max_d2
    )
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


def gated_pairs(
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
        rows, cols, d2, log_det = _candidate_statistics(x_pred, P_pred, z, R, time_offset_s, max_d2)
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
    cols = order[np.arange(total) + starts] if total else NO_INDEX
    if total:
        dx = z[cols, 0] - x_pred[rows, 0]
        dy = z[cols, 1] - x_pred[rows, 1]
        distance = np.sqrt(dx * dx + dy * dy) - reach[rows]
        near = (distance <= 0.0) | (
            distance * distance <= max_d2 * (track_trace[rows] + meas_trace[cols])
        )
        rows, cols = rows[near], cols[near]
    return rows, cols


def _pair_statistics(x: F64, P: F64, z: F64, R: F64, offsets: F64 | None) -> tuple[F64, F64]:
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
        return NO_INDEX, NO_INDEX
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
        return NO_INDEX
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
    picked = cascade_assign_pairs(cost[rows, columns], rows, columns, first_rows)
    return rows[picked], columns[picked]


def cascade_assign_pairs(
    cost: F64,
    rows: IntP,
    columns: IntP,
    first_rows: npt.NDArray[np.bool_],
) -> IntP:
    """:func:`cascade_assign` on allowed pairs given as arrays (as :func:`_gnn_assign_pairs`):
    the indices of the pairs chosen, by increasing row."""
    if not len(rows):
        return NO_INDEX
    picked = [NO_INDEX]
    free_columns = np.ones(int(columns.max()) + 1, dtype=bool)
    first = first_rows[rows]
    for stage in (first, ~first):
        if not stage.any():
            continue  # e.g. no tentative track: nothing to assign
        # the stage's allowed pairs whose measurement no earlier stage took
        candidates = np.flatnonzero(stage & free_columns[columns])
        chosen = candidates[
            _gnn_assign_pairs(cost[candidates], rows[candidates], columns[candidates])
        ]
        free_columns[columns[chosen]] = False
        picked.append(chosen)
    chosen = np.concatenate(picked)
    return chosen[np.argsort(rows[chosen])]


def huber_inflated(R: F64, columns: IntP, d2: F64, huber_k: float) -> F64:
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


def speed_gated(
    d2: F64,
    pair_rows: IntP,
    pair_columns: IntP,
    x_pred: F64,
    P_pred: F64,
    road_heading_rad: F64,
    speeds: F64,
    settings: TrackerSettings,
) -> F64:
    """``d2`` of the pairs (``pair_rows``, ``pair_columns``) with those whose radar speed
    misses the track's speed gate set to inf (Doppler-aided gating).

    ``y = s - u . v``, ``S = u^T P_v u + sigma_s^2`` with ``u`` the track's road heading;
    forbidden when ``y^2 > speed_association_chi2 S``.

    Parameters
    ----------
    d2
        Squared Mahalanobis distance of each pair, (K,).
    pair_rows, pair_columns
        The pairs' track rows and measurement columns, (K,).
    x_pred, P_pred
        Predicted track states (T, 4) and covariances (T, 4, 4).
    road_heading_rad
        The road's heading at each track [rad], (T,), NaN where there is none.
    speeds
        Each measurement's radar speed along the road [m/s], (M,), NaN where there is none.
    """
    if not np.isfinite(speeds).any():
        return d2
    # Only pairs within a gate are ever looked at again (association, spawn suppression).
    rows, columns = pair_rows, pair_columns
    road = road_heading_rad[rows]
    known = np.flatnonzero(
        np.isfinite(road)
        & np.isfinite(speeds[columns])
        & (d2 <= max(settings.gate_chi2, settings.spawn_gate_chi2))
    )
    rows, columns, road = rows[known], columns[known], road[known]
    if not len(rows):
        return d2
    cos, sin = np.cos(road), np.sin(road)
    predicted = x_pred[rows, 2] * cos + x_pred[rows, 3] * sin
    P_v = P_pred[rows]
    variance = (
        cos * cos * P_v[:, 2, 2]
        + cos * sin * (P_v[:, 2, 3] + P_v[:, 3, 2])
        + sin * sin * P_v[:, 3, 3]
        + settings.speed_std_mps**2
    )
    y = speeds[columns] - predicted
    bad = y * y > settings.speed_association_chi2 * variance
    if not bad.any():
        return d2
    d2 = d2.copy()
    d2[known[bad]] = np.inf
    return d2


def local_id_bonus(
    bonus_value: float,
    track_ids: Iterable[int],
    local_ids: Mapping[tuple[str, int], int],
    sensor_id: str,
    measurements: Sequence[Measurement],
    pair_rows: IntP,
    pair_columns: IntP,
) -> F64 | None:
    """The cost reduction of each pair: ``bonus_value`` where the measurement's
    ``(sensor_id, local_track_id)`` last updated the pair's track (``local_ids``: that key ->
    track id; ``track_ids``: the id of each track row), else 0; None when no pair has one."""
    if bonus_value == 0.0:
        return None
    if all(measurement.local_track_id is None for measurement in measurements):
        return None  # a sensor without a tracker of its own
    row_of = {track_id: row for row, track_id in enumerate(track_ids)}
    # per measurement, the row of the track its local id last updated (-1: none)
    continued = np.full(len(measurements), -1)
    for column, measurement in enumerate(measurements):
        if measurement.local_track_id is None:
            continue
        track_id = local_ids.get((sensor_id, measurement.local_track_id))
        if track_id is not None and track_id in row_of:
            continued[column] = row_of[track_id]
    same = continued[pair_columns] == pair_rows
    return np.where(same, bonus_value, 0.0) if same.any() else None
