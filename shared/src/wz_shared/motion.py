"""The constant-velocity motion model with road-aligned white-noise acceleration, and RTS
smoothing over stored states: one model for the fusion tracker, the gateway and the evaluation.

**State and transition.** A vehicle's state in the site frame (metres, ``x`` east, ``y`` north,
seconds) follows the linear constant-velocity model (Saba et al. 2025, Eq. 7-8)::

    x = [x, y, vx, vy]                                          [m, m, m/s, m/s]
    x_k = F x_{k-1} + w,   F = [[I, dt I], [0, I]],   w ~ N(0, Q)      (I: the 2x2 identity)

**Process noise.** ``Q`` is the discretised white-noise acceleration model: an acceleration
``a`` (2-vector) held constant over ``dt`` moves the state by ``G a`` with
``G = [[dt^2/2 I], [dt I]]`` (4x2), so::

    Q = G Sigma_a G^T = [[dt^4/4 Sigma_a, dt^3/2 Sigma_a],
                         [dt^3/2 Sigma_a, dt^2   Sigma_a]]

With an isotropic ``Sigma_a = sigma_a^2 I`` this is the paper's Eq. 9 (:func:`white_noise_q`).
On a highway a vehicle accelerates and brakes hard along the road but drifts little across it,
so :func:`road_aligned_q` gives the acceleration different standard deviations along and
across the direction of travel::

    Sigma_a = Rot(h) diag(sigma_along^2, sigma_across^2) Rot(h)^T,   h: the heading

which keeps the predicted covariance long and thin along the lane. The heading is the road's
where the tracker knows it, else the state's own direction of travel; below
``heading_min_speed_mps`` a velocity's direction means nothing and the noise is isotropic
(``sigma_along`` both ways). :class:`ProcessNoise` holds the numbers; the fusion tracker's
settings define them (``sigma_along_mps2``, ``sigma_across_mps2``, ``heading_min_speed_mps``),
and its track batches carry them to the gateway, which smooths with them.

**Prediction.** :func:`predict_cv` predicts a stack of states with the block structure of
``F`` written out: with ``P = [[A, B], [B^T, C]]`` (2x2 blocks) and ``S = Sigma_a``::

    A' = A + dt (B + B^T) + dt^2 C + dt^4/4 S
    B' = B + dt C + dt^3/2 S
    C' = C + dt^2 S
    p' = p + dt v,   v' = v

**RTS smoothing.** A Kalman filter's estimate at ``t_k`` uses the measurements up to ``t_k``;
for offline work (evaluation, recorded trajectories, an ended track's stored points) every
estimate can use the whole track. The Rauch-Tung-Striebel smoother (:func:`rts_smooth`) runs
backwards over the filtered states ``x_k|k, P_k|k``, with ``F_k = F(t_{k+1} - t_k)``::

    x_{k+1|k} = F_k x_k|k,           P_{k+1|k} = F_k P_k|k F_k^T + Q_k      (the filter's prior)
    C_k       = P_k|k F_k^T P_{k+1|k}^-1
    x_k|n     = x_k|k + C_k (x_{k+1|n} - x_{k+1|k})
    P_k|n     = P_k|k + C_k (P_{k+1|n} - P_{k+1|k}) C_k^T

The priors are either taken as the filter stored them (best: the tracker's ``Q`` followed the
road's heading, which the states alone do not tell) or recomputed from a :class:`ProcessNoise`
with ``Q_k`` oriented along the state ``x_k|k``'s own velocity (:func:`recomputed_priors`). The
gateway stores a track's published snapshots; a snapshot at a cycle without a measurement is
the tracker's prediction, so consecutive stored points of a coasting track are related by
exactly this prior (white-noise acceleration composes over sub-intervals), and the smoother
adds nothing there that was not in the data.

Nothing here does I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64

#: Dimension of the state ``[x, y, vx, vy]``.
STATE_DIM = 4


@dataclass(frozen=True, slots=True)
class ProcessNoise:
    """The white-noise acceleration of the motion model; the defaults are the fusion tracker's.

    Attributes
    ----------
    sigma_along_mps2
        Std of the acceleration along the direction of travel [m/s^2].
    sigma_across_mps2
        Std of the acceleration across it [m/s^2].
    heading_min_speed_mps
        Below this speed a state's own heading is not trusted and the noise is isotropic
        (``sigma_along`` both ways) [m/s].
    """

    sigma_along_mps2: float = 3.5
    sigma_across_mps2: float = 3.0
    heading_min_speed_mps: float = 2.0

    @classmethod
    def isotropic(cls, sigma_a_mps2: float) -> ProcessNoise:
        """The paper's model: the same acceleration std ``sigma_a`` [m/s^2] in every direction."""
        return cls(sigma_a_mps2, sigma_a_mps2)

    def q(self, dt_s: float, heading_rad: float = 0.0) -> F64:
        """``Q`` over ``dt_s`` [s] with ``sigma_along`` along ``heading_rad`` [rad], shape (4, 4):
        :func:`white_noise_q` when isotropic, else :func:`road_aligned_q`."""
        if self.sigma_along_mps2 == self.sigma_across_mps2:
            return white_noise_q(dt_s, self.sigma_along_mps2)
        return road_aligned_q(dt_s, self.sigma_along_mps2, self.sigma_across_mps2, heading_rad)

    def sigma_across_at(self, speed_mps: npt.ArrayLike) -> F64:
        """The std across the heading of states moving at ``speed_mps`` [m/s]: ``sigma_across``,
        or ``sigma_along`` below ``heading_min_speed_mps`` (isotropic)."""
        slow = np.asarray(speed_mps, dtype=np.float64) < self.heading_min_speed_mps
        return np.where(slow, self.sigma_along_mps2, self.sigma_across_mps2)


def cv_transition(dt_s: npt.ArrayLike) -> F64:
    """Constant-velocity transition matrix ``F = [[I, dt I], [0, I]]`` (paper Eq. 8).

    Parameters
    ----------
    dt_s
        Time step [s], a scalar or an array of shape (...,); may be 0.

    Returns
    -------
    F
        Shape (4, 4) for a scalar ``dt_s``, (..., 4, 4) for an array.
    """
    dt = np.asarray(dt_s, dtype=np.float64)
    F = np.broadcast_to(np.eye(STATE_DIM), (*dt.shape, STATE_DIM, STATE_DIM)).copy()
    F[..., 0, 2] = dt
    F[..., 1, 3] = dt
    return F


def acceleration_covariance(
    sigma_along_mps2: npt.ArrayLike, sigma_across_mps2: npt.ArrayLike, heading_rad: npt.ArrayLike
) -> F64:
    """``Sigma_a = Rot(h) diag(sigma_along^2, sigma_across^2) Rot(h)^T`` [m^2/s^4], (..., 2, 2)."""
    var_along = np.square(np.asarray(sigma_along_mps2, dtype=np.float64))
    var_across = np.square(np.asarray(sigma_across_mps2, dtype=np.float64))
    heading = np.asarray(heading_rad, dtype=np.float64)
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    # Rot diag Rot^T written out: the along direction is (cos h, sin h), across (-sin h, cos h).
    sxx = var_along * cos_h**2 + var_across * sin_h**2
    syy = var_along * sin_h**2 + var_across * cos_h**2
    sxy = (var_along - var_across) * cos_h * sin_h
    sigma_a = np.empty((*np.broadcast_shapes(sxx.shape, syy.shape, sxy.shape), 2, 2))
    sigma_a[..., 0, 0] = sxx
    sigma_a[..., 1, 1] = syy
    sigma_a[..., 0, 1] = sigma_a[..., 1, 0] = sxy
    return sigma_a


def _kron_q(T: F64, sigma_a: F64) -> F64:
    """``Q = T kron Sigma_a``: ``Q[2i + a, 2j + b] = T[i, j] Sigma_a[a, b]``, (..., 4, 4)."""
    blocks = T[..., :, None, :, None] * sigma_a[..., None, :, None, :]
    shape = np.broadcast_shapes(T.shape[:-2], sigma_a.shape[:-2])
    return np.asarray(
        np.broadcast_to(blocks, (*shape, 2, 2, 2, 2)).reshape(*shape, STATE_DIM, STATE_DIM),
        dtype=np.float64,
    )


def _q_from_acceleration_covariance(dt_s: npt.ArrayLike, sigma_a: F64) -> F64:
    """``Q = G Sigma_a G^T = T(dt) kron Sigma_a``, ``T = [[dt^4/4, dt^3/2], [dt^3/2, dt^2]]``."""
    dt = np.asarray(dt_s, dtype=np.float64)
    dt2 = dt * dt
    T = np.stack(
        [
            np.stack([dt2 * dt2 / 4.0, dt2 * dt / 2.0], axis=-1),
            np.stack([dt2 * dt / 2.0, dt2], axis=-1),
        ],
        axis=-2,
    )
    return _kron_q(T, sigma_a)


def white_noise_q(dt_s: npt.ArrayLike, sigma_a_mps2: npt.ArrayLike) -> F64:
    """Discretised white-noise acceleration process noise, isotropic (paper Eq. 9).

    ::

        Q = sigma_a^2 [[dt^4/4, 0,      dt^3/2, 0     ],
                       [0,      dt^4/4, 0,      dt^3/2],
                       [dt^3/2, 0,      dt^2,   0     ],
                       [0,      dt^3/2, 0,      dt^2  ]]

    Parameters
    ----------
    dt_s
        Time step [s], scalar or (...,).
    sigma_a_mps2
        Standard deviation of the acceleration, the same in every direction [m/s^2].

    Returns
    -------
    Q
        Shape (4, 4) or (..., 4, 4) [m^2, m^2/s, m^2/s^2].
    """
    dt = np.asarray(dt_s, dtype=np.float64)
    var_a = np.square(np.asarray(sigma_a_mps2, dtype=np.float64))
    dt2 = dt * dt
    Q = np.zeros((*np.broadcast_shapes(dt.shape, var_a.shape), STATE_DIM, STATE_DIM))
    Q[..., 0, 0] = Q[..., 1, 1] = var_a * dt2 * dt2 / 4.0
    Q[..., 0, 2] = Q[..., 2, 0] = Q[..., 1, 3] = Q[..., 3, 1] = var_a * dt2 * dt / 2.0
    Q[..., 2, 2] = Q[..., 3, 3] = var_a * dt2
    return Q


def road_aligned_q(
    dt_s: npt.ArrayLike,
    sigma_along_mps2: npt.ArrayLike,
    sigma_across_mps2: npt.ArrayLike,
    heading_rad: npt.ArrayLike,
) -> F64:
    """White-noise acceleration process noise with different stds along and across the heading
    (module docstring): ``Q = G Sigma_a G^T``. With ``sigma_along == sigma_across`` it equals
    :func:`white_noise_q` (up to rounding).

    Parameters
    ----------
    dt_s
        Time step [s], scalar or (...,).
    sigma_along_mps2
        Std of the acceleration along the heading [m/s^2], scalar or (...,).
    sigma_across_mps2
        Std of the acceleration across it [m/s^2], scalar or (...,).
    heading_rad
        Heading, counter-clockwise from the site x axis (east) [rad], scalar or (...,).

    Returns
    -------
    Q
        Shape (4, 4) or (..., 4, 4), the arguments broadcast together.
    """
    sigma_a = acceleration_covariance(sigma_along_mps2, sigma_across_mps2, heading_rad)
    return _q_from_acceleration_covariance(dt_s, sigma_a)


def predict_cv(
    x: F64,
    P: F64,
    dt_s: F64,
    sigma_along_mps2: npt.ArrayLike,
    sigma_across_mps2: npt.ArrayLike,
    heading_rad: npt.ArrayLike,
) -> tuple[F64, F64]:
    """Constant-velocity prediction ``F x``, ``F P F^T + Q`` of a stack of states, the block
    form of the module docstring: the same numbers as the textbook products with
    :func:`cv_transition` and :func:`road_aligned_q`, without 4x4 products.

    Parameters
    ----------
    x
        States, shape (K, 4).
    P
        Covariances, shape (K, 4, 4).
    dt_s
        Time steps [s], shape (K,).
    sigma_along_mps2, sigma_across_mps2, heading_rad
        Acceleration stds [m/s^2] and heading [rad], scalars or shape (K,).

    Returns
    -------
    x_p, P_p
        Shapes (K, 4) and (K, 4, 4), new arrays.
    """
    dt = dt_s[:, None, None]
    dt2 = dt * dt
    S = acceleration_covariance(sigma_along_mps2, sigma_across_mps2, heading_rad)
    # F P F' in place of two 4x4 products: rows first (F P: position rows += dt velocity rows),
    # then columns ((F P) F': position columns += dt velocity columns).
    P_p = P.copy()
    P_p[:, :2, :] += dt * P[:, 2:, :]
    P_p[:, :, :2] += dt * P_p[:, :, 2:]
    # + Q = T(dt) kron S
    P_p[:, :2, :2] += (dt2 * dt2 / 4.0) * S
    Q_cross = (dt2 * dt / 2.0) * S
    P_p[:, :2, 2:] += Q_cross
    P_p[:, 2:, :2] += Q_cross
    P_p[:, 2:, 2:] += dt2 * S
    # x = F x
    x_p = x.copy()
    x_p[:, :2] += dt_s[:, None] * x[:, 2:]
    return x_p, P_p


def recomputed_priors(
    stamps_s: F64, x_filt: F64, P_filt: F64, noise: ProcessNoise
) -> tuple[F64, F64]:
    """The priors ``x_{k+1|k}`` (n - 1, 4) and ``P_{k+1|k}`` (n - 1, 4, 4) of filtered states
    (n, 4), (n, 4, 4) at ``stamps_s`` (n,): ``Q_k`` along the velocity of ``x_k|k``, isotropic
    below ``noise.heading_min_speed_mps`` (module docstring)."""
    dt = np.diff(stamps_s)
    x = x_filt[:-1]
    heading = np.arctan2(x[:, 3], x[:, 2])
    sigma_a = acceleration_covariance(
        noise.sigma_along_mps2, noise.sigma_across_at(np.hypot(x[:, 2], x[:, 3])), heading
    )
    # T(dt) written with powers (dt**4 where predict_cv has dt2 * dt2): the rounding stored
    # trajectories have always been smoothed with, equal to the filter's within an ulp.
    T = np.stack(
        [np.stack([dt**4 / 4.0, dt**3 / 2.0], axis=-1), np.stack([dt**3 / 2.0, dt**2], axis=-1)],
        axis=-2,
    )
    F = cv_transition(dt)
    # x_{k+1|k} = F x_k|k,  P_{k+1|k} = F P_k|k F^T + Q
    x_prior = np.einsum("kij,kj->ki", F, x)
    P_prior = F @ P_filt[:-1] @ np.swapaxes(F, -1, -2) + _kron_q(T, sigma_a)
    return x_prior, P_prior


def rts_smooth(
    stamps_s: npt.ArrayLike,
    x_filt: npt.ArrayLike,
    P_filt: npt.ArrayLike,
    noise: ProcessNoise | None = None,
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
        Process noise the filter predicted with; the priors are recomputed with it
        (:func:`recomputed_priors`) when ``x_pred``/``P_pred`` are not given.
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
        if n < 2:
            return x, P
        x_prior, P_prior = recomputed_priors(stamps, x, P, noise)
    else:
        x_prior = np.asarray(x_pred, dtype=np.float64).reshape(-1, STATE_DIM)
        P_prior = np.asarray(P_pred, dtype=np.float64).reshape(-1, STATE_DIM, STATE_DIM)
        if len(x_prior) != n or len(P_prior) != n:
            raise ValueError(f"{n} stamps but {len(x_prior)} priors")
        if n < 2:
            return x, P
        x_prior, P_prior = x_prior[1:], P_prior[1:]  # entry k: the prior at t_{k+1}
    F = cv_transition(np.diff(stamps))
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
