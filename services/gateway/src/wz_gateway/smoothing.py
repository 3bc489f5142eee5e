"""Rauch-Tung-Striebel smoothing of a stored fused trajectory: pure, no I/O.

While a track lives, the gateway stores the tracker's estimate at every cycle, which used the
measurements up to that cycle only. When the track has ended, every point can use the whole
track: the RTS smoother runs backwards over the stored states ``x_k`` and covariances ``P_k``
(taken as the filter's ``x_k|k``, ``P_k|k``) of the constant-velocity model::

    x = [x, y, vx, vy]                                         [m, m, m/s, m/s]
    F_k = [[I, dt_k I], [0, I]],  dt_k = t_{k+1} - t_k
    x_{k+1|k} = F_k x_k|k,        P_{k+1|k} = F_k P_k|k F_k^T + Q_k     (the prior)
    C_k = P_k|k F_k^T P_{k+1|k}^-1
    x_k|n = x_k|k + C_k (x_{k+1|n} - x_{k+1|k})
    P_k|n = P_k|k + C_k (P_{k+1|n} - P_{k+1|k}) C_k^T

``Q_k`` is the white-noise acceleration of the fusion tracker's motion model, road-aligned: an
acceleration with standard deviation ``sigma_along`` along the direction of travel (the state's
heading at ``t_k``) and ``sigma_across`` across it (isotropic ``sigma_along`` below
:data:`HEADING_MIN_SPEED_MPS`, where a heading means nothing)::

    G = [[dt^2/2 I], [dt I]],  Sigma_a = Rot(h) diag(sigma_along^2, sigma_across^2) Rot(h)^T
    Q = G Sigma_a G^T

The tracker's snapshot at a cycle without a measurement is its prediction, so consecutive
stored points of a coasting track are related by exactly this prior (white-noise acceleration
composes over sub-intervals), and the smoother adds nothing there that was not in the data.

The gateway cannot import the tracker (services share only ``wz_shared``); its tests compare
this function with the tracker's :func:`wz_fusion_tracker.smoothing.rts_smooth` and with
filterpy's ``rts_smoother``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from wz_shared.site import Site

F64 = npt.NDArray[np.float64]

#: Dimension of the state ``[x, y, vx, vy]``.
STATE_DIM = 4
#: Below this speed a state's heading is not trusted: the process noise is isotropic [m/s]
#: (the tracker's ``heading_min_speed_mps``).
HEADING_MIN_SPEED_MPS = 2.0


def cv_transitions(dt_s: F64) -> F64:
    """``F = [[I, dt I], [0, I]]`` for each interval, shape (m, 4, 4) for ``dt_s`` (m,) [s]."""
    F = np.tile(np.eye(STATE_DIM), (len(dt_s), 1, 1))
    F[:, 0, 2] = dt_s
    F[:, 1, 3] = dt_s
    return F


def road_aligned_q(dt_s: F64, heading_rad: F64, sigma_along_mps2: float,
                   sigma_across_mps2: float | F64) -> F64:  # fmt: skip
    """White-noise acceleration ``Q = G Sigma_a G^T`` per interval (module docstring).

    Parameters
    ----------
    dt_s
        Interval lengths [s], shape (m,).
    heading_rad
        Direction of ``sigma_along`` for each interval, counter-clockwise from east [rad],
        shape (m,).
    sigma_along_mps2, sigma_across_mps2
        Acceleration standard deviations along and across the heading [m/s^2]; the one across
        may differ per interval, shape (m,).

    Returns
    -------
    Q
        Shape (m, 4, 4), symmetric positive semi-definite.
    """
    cos, sin = np.cos(heading_rad), np.sin(heading_rad)
    along2, across2 = sigma_along_mps2**2, sigma_across_mps2**2
    # Sigma_a = Rot(h) diag(along^2, across^2) Rot(h)^T, written out per entry
    s_xx = along2 * cos**2 + across2 * sin**2
    s_yy = along2 * sin**2 + across2 * cos**2
    s_xy = (along2 - across2) * cos * sin
    sigma_a = np.stack([np.stack([s_xx, s_xy], -1), np.stack([s_xy, s_yy], -1)], -2)
    # Q = G Sigma_a G^T with G = [[dt^2/2 I], [dt I]]: blocks dt^4/4, dt^3/2, dt^2 times Sigma_a
    dt = dt_s[:, None, None]
    Q = np.empty((len(dt_s), STATE_DIM, STATE_DIM))
    Q[:, :2, :2] = dt**4 / 4.0 * sigma_a
    Q[:, :2, 2:] = dt**3 / 2.0 * sigma_a
    Q[:, 2:, :2] = dt**3 / 2.0 * sigma_a
    Q[:, 2:, 2:] = dt**2 * sigma_a
    return Q


def rts_smooth(stamps_s: npt.ArrayLike, x_filt: npt.ArrayLike, P_filt: npt.ArrayLike, *,
               sigma_along_mps2: float, sigma_across_mps2: float) -> tuple[F64, F64]:  # fmt: skip
    """RTS-smooth one track's stored constant-velocity states (module docstring).

    Parameters
    ----------
    stamps_s
        Time of each state [s], non-decreasing, shape (n,).
    x_filt
        Stored states ``[x, y, vx, vy]`` [m, m/s], shape (n, 4).
    P_filt
        Their covariances, shape (n, 4, 4).
    sigma_along_mps2, sigma_across_mps2
        The process noise's acceleration standard deviations [m/s^2].

    Returns
    -------
    x_smooth, P_smooth
        Shapes (n, 4) and (n, 4, 4); the last entry equals the stored one, and a single state
        is returned unchanged.

    Raises
    ------
    ValueError
        Shapes disagree or stamps decrease.
    """
    stamps = np.asarray(stamps_s, dtype=np.float64).reshape(-1)
    x = np.array(x_filt, dtype=np.float64).reshape(-1, STATE_DIM)
    P = np.array(P_filt, dtype=np.float64).reshape(-1, STATE_DIM, STATE_DIM)
    n = len(stamps)
    if len(x) != n or len(P) != n:
        raise ValueError(f"{n} stamps but {len(x)} states and {len(P)} covariances")
    if np.any(np.diff(stamps) < 0.0):
        raise ValueError("stamps must not decrease")
    if n < 2:
        return x, P
    dt = np.diff(stamps)
    speed = np.hypot(x[:-1, 2], x[:-1, 3])
    heading = np.arctan2(x[:-1, 3], x[:-1, 2])
    across = np.where(speed < HEADING_MIN_SPEED_MPS, sigma_along_mps2, sigma_across_mps2)
    Q = road_aligned_q(dt, heading, sigma_along_mps2, across)
    F = cv_transitions(dt)
    # x_{k+1|k} = F x_k|k,  P_{k+1|k} = F P_k|k F^T + Q   (entry k: the prior at t_{k+1})
    x_prior = np.einsum("kij,kj->ki", F, x[:-1])
    P_prior = F @ P[:-1] @ np.swapaxes(F, -1, -2) + Q
    # C_k = P_k|k F^T P_{k+1|k}^-1, solved for all k at once: C^T = P_{k+1|k}^-1 F P_k|k (both
    # covariances symmetric). A singular prior (a repeated stamp of an exact state) has no
    # inverse: the pseudo-inverse then passes nothing back through that step.
    FP = F @ P[:-1]
    try:
        C = np.swapaxes(np.linalg.solve(P_prior, FP), -1, -2)
    except np.linalg.LinAlgError:
        C = np.swapaxes(np.linalg.pinv(P_prior, hermitian=True) @ FP, -1, -2)
    x_smooth = x.copy()
    P_smooth = P.copy()
    for k in range(n - 2, -1, -1):
        # x_k|n = x_k|k + C (x_{k+1|n} - x_{k+1|k})
        x_smooth[k] = x[k] + C[k] @ (x_smooth[k + 1] - x_prior[k])
        # P_k|n = P_k|k + C (P_{k+1|n} - P_{k+1|k}) C^T, symmetrised against rounding
        P_k = P[k] + C[k] @ (P_smooth[k + 1] - P_prior[k]) @ C[k].T
        P_smooth[k] = (P_k + P_k.T) / 2.0
    return x_smooth, P_smooth


# --- a stored trajectory -------------------------------------------------------------------


@dataclass(frozen=True)
class StoredTrajectory:
    """One track life's stored points, oldest first, as arrays of one length n.

    ``covariance`` is (n, 4, 4); ``length_m``/``width_m`` are NaN where the tracker gave none;
    the rest are (n,). ``received_at`` is the gateway's wall clock of each point [Unix s].
    """

    track_id: int
    stamp: F64
    x_m: F64
    y_m: F64
    vx_mps: F64
    vy_mps: F64
    covariance: F64
    latitude_deg: F64
    longitude_deg: F64
    station_m: F64
    offset_m: F64
    lane_index: npt.NDArray[np.int64]
    speed_mps: F64
    heading_rad: F64
    object_class: tuple[str, ...]
    status: tuple[str, ...]
    length_m: F64
    width_m: F64
    received_at: F64

    def __len__(self) -> int:
        return len(self.stamp)


def smooth_trajectory(points: StoredTrajectory, site: Site, *, sigma_along_mps2: float,
                      sigma_across_mps2: float) -> StoredTrajectory:  # fmt: skip
    """The smoothed trajectory of an ended track: :func:`rts_smooth` on its states, then the
    road frame, lane and WGS84 position of each smoothed state.

    What hindsight knows better is taken from the last point for every point: the class (the
    tracker's vote over the whole track) and the size. Stamps, status and ``received_at`` are
    kept (retention then deletes a smoothed point with its fused one).
    """
    x = np.column_stack([points.x_m, points.y_m, points.vx_mps, points.vy_mps])
    x_s, P_s = rts_smooth(points.stamp, x, points.covariance, sigma_along_mps2=sigma_along_mps2,
                          sigma_across_mps2=sigma_across_mps2)  # fmt: skip
    station, offset = site.road_frame.to_road(x_s[:, 0], x_s[:, 1])
    lane = np.maximum(np.asarray(site.lane_index_at(offset)), -1).astype(np.int64)
    latitude, longitude, _ = site.geo_frame.to_wgs84(x_s[:, 0], x_s[:, 1])
    n = len(points)
    return replace(
        points,
        x_m=x_s[:, 0], y_m=x_s[:, 1], vx_mps=x_s[:, 2], vy_mps=x_s[:, 3], covariance=P_s,
        latitude_deg=np.asarray(latitude, dtype=np.float64),
        longitude_deg=np.asarray(longitude, dtype=np.float64),
        station_m=np.asarray(station, dtype=np.float64),
        offset_m=np.asarray(offset, dtype=np.float64), lane_index=lane,
        speed_mps=np.hypot(x_s[:, 2], x_s[:, 3]), heading_rad=np.arctan2(x_s[:, 3], x_s[:, 2]),
        object_class=(points.object_class[-1],) * n,
        length_m=np.full(n, points.length_m[-1]), width_m=np.full(n, points.width_m[-1]),
    )  # fmt: skip
