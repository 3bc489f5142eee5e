"""Rauch-Tung-Striebel smoothing of a tracker's stored track history.

The smoother itself, and its maths, is :func:`wz_shared.motion.rts_smooth`; the multi-target
tracker records the prior it used at every update, so a history is smoothed with its stored
priors (the filter's ``Q`` followed the road's heading, which the states alone do not tell).

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

from wz_shared.arrays import F64
from wz_shared.motion import rts_smooth

if TYPE_CHECKING:
    from wz_fusion_tracker.tracker import TrackHistory


def history_segments(history: TrackHistory) -> list[slice]:
    """The runs of ``history`` that are one filter's updates, in order.

    A run starts at a track's first detection, an entry whose prior is its posterior (no
    prediction came before it: :meth:`MultiTargetTracker._spawn` stores it so); any other update
    changes the state's covariance. The first run starts at entry 0; a hand-over starts another.
    """
    n = len(history.stamps_s)
    fresh = np.all(history.x_pred == history.x_filt, axis=1) & np.all(
        history.P_pred == history.P_filt, axis=(1, 2)
    )
    starts = [0, *(np.flatnonzero(fresh[1:]) + 1).tolist(), n]
    return [slice(a, b) for a, b in pairwise(starts) if b > a]


def smooth_history(history: TrackHistory) -> tuple[F64, F64]:
    """:func:`~wz_shared.motion.rts_smooth` of a tracker history with its stored priors, run
    by run (:func:`history_segments`): a later run's start is not a prediction of the run
    before, so nothing is passed back across the join.

    Returns
    -------
    x_smooth, P_smooth
        Shapes (n, 4) and (n, 4, 4), entry k for the history's entry k.
    """
    x_smooth = np.empty_like(history.x_filt)
    P_smooth = np.empty_like(history.P_filt)
    for run in history_segments(history):
        x_smooth[run], P_smooth[run] = rts_smooth(
            history.stamps_s[run],
            history.x_filt[run],
            history.P_filt[run],
            x_pred=history.x_pred[run],
            P_pred=history.P_pred[run],
        )
    return x_smooth, P_smooth
