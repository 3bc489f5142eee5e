"""Rauch-Tung-Striebel smoothing of a stored constant-velocity track history.

A Kalman filter's estimate at time ``t_k`` uses the measurements up to ``t_k``; for offline
work (evaluation, recorded trajectories, the dashboard's replay) every estimate can use the
whole track. The RTS smoother runs backwards over the filtered states ``x_k|k, P_k|k``::

    x_{k+1|k} = F_k x_k|k,           P_{k+1|k} = F_k P_k|k F_k^T + Q_k      (the filter's prior)
    C_k       = P_k|k F_k^T P_{k+1|k}^-1
    x_k|n     = x_k|k + C_k (x_{k+1|n} - x_{k+1|k})
    P_k|n     = P_k|k + C_k (P_{k+1|n} - P_{k+1|k}) C_k^T

with ``F_k = F(t_{k+1} - t_k)``. The priors are either recomputed from a :class:`ProcessNoise`
(the same model the filter used) or, better when the filter's ``Q`` changed along the track
(a road-aligned ``Q`` follows the road's heading), taken as stored by the filter: the
multi-target tracker records the prior it used at every update.

A tracker's history can join two filters' updates: when a young track hands its vehicle back
to the old track that lost it (``MultiTargetTracker._hand_over``), the young track's updates
are appended to the old one's, and the first of them starts from a detection, not from a
prediction of the entry before. :func:`smooth_history` smooths each such run on its own.

Nothing here does I/O.
"""

from __future__ import annotations

from itertools import pairwise
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from wz_fusion_tracker.kalman import F64, STATE_DIM, ProcessNoise, cv_transition

if TYPE_CHECKING:
    from wz_fusion_tracker.tracker import TrackHistory


def rts_smooth(
    stamps_s: npt.ArrayLike,
    x_filt: npt.ArrayLike,
    P_filt: npt.ArrayLike,
    noise: ProcessNoise | None,
    *,
    x_pred: npt.ArrayLike | None = None,
    P_pred: npt.ArrayLike | None = None,
) -> tuple[F64, F64]:
    """Rauch-Tung-Striebel smoothing of filtered constant-velocity states (module docstring).

    Parameters
    ----------
    stamps_s
        Time of each filtered state [s], non-decreasing, shape (n,).
    x_filt
        Filtered states ``x_k|k`` [m, m/s], shape (n, 4).
    P_filt
        Filtered covariances ``P_k|k``, shape (n, 4, 4).
    noise
        Process noise the filter predicted with; used to recompute the priors when
        ``x_pred``/``P_pred`` are not given.
    x_pred, P_pred
        The filter's priors ``x_k|k-1`` (n, 4) and ``P_k|k-1`` (n, 4, 4), entry ``k`` being the
        prediction to ``t_k`` used by the update at ``t_k`` (entry 0 is not used). Give both or
        neither.

    Returns
    -------
    x_smooth, P_smooth
        ``x_k|n`` (n, 4) and ``P_k|n`` (n, 4, 4); the last entry equals the filtered one, and a
        single state is returned unchanged.

    Raises
    ------
    ValueError
        Shapes disagree, stamps decrease, or neither ``noise`` nor the priors are given.
    """
    stamps = np.asarray(stamps_s, dtype=np.float64).reshape(-1)
    x = np.array(x_filt, dtype=np.float64).reshape(-1, STATE_DIM)
    P = np.array(P_filt, dtype=np.float64).reshape(-1, STATE_DIM, STATE_DIM)
    n = len(stamps)
    if len(x) != n or len(P) != n:
        raise ValueError(f"{n} stamps but {len(x)} states and {len(P)} covariances")
    if np.any(np.diff(stamps) < 0.0):
        raise ValueError("stamps must not decrease")
    if (x_pred is None) != (P_pred is None):
        raise ValueError("give both x_pred and P_pred, or neither")
    if x_pred is None or P_pred is None:
        if noise is None:
            raise ValueError("either noise or the stored priors x_pred/P_pred are needed")
        dts = np.diff(stamps)
        F_all = cv_transition(dts)
        x_prior = np.empty_like(x)
        P_prior = np.empty_like(P)
        # x_{k+1|k} = F x_k|k,  P_{k+1|k} = F P_k|k F' + Q
        x_prior[1:] = np.einsum("kij,kj->ki", F_all, x[:-1])
        P_prior[1:] = F_all @ P[:-1] @ np.swapaxes(F_all, -1, -2)
        for k, dt in enumerate(dts):
            P_prior[k + 1] += noise.q(float(dt))
    else:
        x_prior = np.asarray(x_pred, dtype=np.float64).reshape(-1, STATE_DIM)
        P_prior = np.asarray(P_pred, dtype=np.float64).reshape(-1, STATE_DIM, STATE_DIM)
        if len(x_prior) != n or len(P_prior) != n:
            raise ValueError(f"{n} stamps but {len(x_prior)} priors")

    x_smooth = x.copy()
    P_smooth = P.copy()
    for k in range(n - 2, -1, -1):
        F = cv_transition(stamps[k + 1] - stamps[k])
        # C = P_k|k F' P_{k+1|k}^-1, solved: C' = P_{k+1|k}^-1 F P_k|k  (both symmetric)
        C = np.linalg.solve(P_prior[k + 1], F @ P[k]).T
        # x_k|n = x_k|k + C (x_{k+1|n} - x_{k+1|k})
        x_smooth[k] = x[k] + C @ (x_smooth[k + 1] - x_prior[k + 1])
        # P_k|n = P_k|k + C (P_{k+1|n} - P_{k+1|k}) C'
        P_k = P[k] + C @ (P_smooth[k + 1] - P_prior[k + 1]) @ C.T
        P_smooth[k] = (P_k + P_k.T) / 2.0
    return x_smooth, P_smooth


def history_segments(history: TrackHistory) -> list[slice]:
    """The runs of ``history`` that are one filter's updates, in order.

    A run starts at a track's first detection, an entry whose prior is its posterior (no
    prediction came before it: :meth:`MultiTargetTracker._spawn` stores it so); any other update
    changes the state's covariance. The first run starts at entry 0; a hand-over starts another.
    """
    n = len(history.stamps_s)
    fresh = np.all(history.x_pred == history.x_filt, axis=1) & np.all(
        history.P_pred == history.P_filt, axis=(1, 2))  # fmt: skip
    starts = [0, *(np.flatnonzero(fresh[1:]) + 1).tolist(), n]
    return [slice(a, b) for a, b in pairwise(starts) if b > a]


def smooth_history(history: TrackHistory) -> tuple[F64, F64]:
    """:func:`rts_smooth` of a tracker history with its stored priors, run by run
    (:func:`history_segments`): a later run's start is not a prediction of the run before, so
    nothing is passed back across the join.

    Returns
    -------
    x_smooth, P_smooth
        Shapes (n, 4) and (n, 4, 4), entry k for the history's entry k.
    """
    x_smooth = np.empty_like(history.x_filt)
    P_smooth = np.empty_like(history.P_filt)
    for run in history_segments(history):
        x_smooth[run], P_smooth[run] = rts_smooth(
            history.stamps_s[run], history.x_filt[run], history.P_filt[run], None,
            x_pred=history.x_pred[run], P_pred=history.P_pred[run])  # fmt: skip
    return x_smooth, P_smooth
