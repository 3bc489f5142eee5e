"""Constant-velocity Kalman filter in three forms: functions, one filter, a vectorised bank.

Every tracker in this package estimates a vehicle's state in the site frame (metres, ``x``
east, ``y`` north, seconds)::

    x = [x, y, vx, vy]                          [m, m, m/s, m/s]

with the constant-velocity model and its road-aligned white-noise acceleration of
:mod:`wz_shared.motion` (transition ``F``, process noise ``Q``, :class:`ProcessNoise`, the
block-form prediction), shared with the gateway's smoother, and position measurements::

    z_k = H x_k + v,       H = [[1, 0, 0, 0],       v ~ N(0, R)      (paper Eq. 10)
                                [0, 1, 0, 0]]

**Update.** The covariance update uses the Joseph form
``P = (I - K H) P (I - K H)^T + K R K^T``, then symmetrises: the short form ``(I - K H) P`` is
equal in exact arithmetic but loses symmetry and positive definiteness under rounding when a
precise sensor (a LiDAR at centimetres) updates an uncertain track.

**Three forms, one model.** :func:`predict`, :func:`update` and :func:`innovation` are the
textbook equations and accept leading batch dimensions; :class:`KalmanFilter` wraps one target
for readability (the paper's pipeline); :class:`TrackStateBank` keeps ``N`` targets in arrays
``x (N, 4)`` and ``P (N, 4, 4)`` and predicts and updates any subset in one vectorised call,
predicting with :func:`~wz_shared.motion.predict_cv` (the block structure of ``F`` written
out, no 4x4 products) and inverting 2x2 innovation covariances in closed form. The tests run
the three side by side and against filterpy.

Nothing here does I/O.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64, IntP
from wz_shared.motion import STATE_DIM, ProcessNoise, cv_transition, predict_cv

#: Dimension of a position measurement ``[x, y]``.
POSITION_DIM = 2


def position_h() -> F64:
    """The position measurement matrix ``H = [[1, 0, 0, 0], [0, 1, 0, 0]]`` (paper Eq. 10).

    Returns
    -------
    H
        Shape (2, 4), a fresh array.
    """
    return np.eye(POSITION_DIM, STATE_DIM, dtype=np.float64)


# ----------------------------------------------------------------------------- function form


def _transpose(A: F64) -> F64:
    return np.swapaxes(A, -1, -2)


def _symmetrise(P: F64) -> F64:
    return (P + _transpose(P)) / 2.0


def predict(
    x: npt.ArrayLike, P: npt.ArrayLike, F: npt.ArrayLike, Q: npt.ArrayLike
) -> tuple[F64, F64]:
    """Kalman prediction (paper Eq. 11-12).

    ::

        x_p = F x
        P_p = F P F^T + Q

    Parameters
    ----------
    x
        State, shape (n,) or (..., n).
    P
        State covariance, shape (n, n) or (..., n, n).
    F
        Transition, shape (n, n) or (..., n, n).
    Q
        Process noise covariance, shape (n, n) or (..., n, n).

    Returns
    -------
    x_p, P_p
        Predicted state and covariance, the batch dimensions broadcast.
    """
    x_ = np.asarray(x, dtype=np.float64)
    P_ = np.asarray(P, dtype=np.float64)
    F_ = np.asarray(F, dtype=np.float64)
    Q_ = np.asarray(Q, dtype=np.float64)
    # x_p = F x
    x_p = (F_ @ x_[..., None])[..., 0]
    # P_p = F P F' + Q
    P_p = F_ @ P_ @ _transpose(F_) + Q_
    return x_p, _symmetrise(P_p)


def innovation(
    x: npt.ArrayLike, P: npt.ArrayLike, z: npt.ArrayLike, H: npt.ArrayLike, R: npt.ArrayLike
) -> tuple[F64, F64]:
    """Innovation and its covariance (paper Eq. 13 and the line after).

    ::

        y = z - H x
        S = H P H^T + R

    Parameters
    ----------
    x, P
        Prior state (..., n) and covariance (..., n, n).
    z
        Measurement, shape (..., m).
    H
        Measurement matrix, shape (m, n) or (..., m, n).
    R
        Measurement noise covariance, shape (..., m, m).

    Returns
    -------
    y, S
        Innovation (..., m) and its covariance (..., m, m).
    """
    x_ = np.asarray(x, dtype=np.float64)
    P_ = np.asarray(P, dtype=np.float64)
    H_ = np.asarray(H, dtype=np.float64)
    # y = z - H x
    y = np.asarray(z, dtype=np.float64) - (H_ @ x_[..., None])[..., 0]
    # S = H P H' + R
    S = H_ @ P_ @ _transpose(H_) + np.asarray(R, dtype=np.float64)
    return y, S


def update(
    x: npt.ArrayLike, P: npt.ArrayLike, z: npt.ArrayLike, H: npt.ArrayLike, R: npt.ArrayLike
) -> tuple[F64, F64]:
    """Kalman measurement update (paper Eq. 13-16), covariance in Joseph form.

    ::

        y = z - H x
        S = H P H^T + R
        K = P H^T S^-1
        x = x + K y
        P = (I - K H) P (I - K H)^T + K R K^T     (then (P + P^T) / 2)

    Parameters
    ----------
    x, P
        Prior state (..., n) and covariance (..., n, n).
    z
        Measurement, shape (..., m).
    H
        Measurement matrix, shape (m, n) or (..., m, n).
    R
        Measurement noise covariance, shape (m, m) or (..., m, m), positive definite.

    Returns
    -------
    x, P
        Posterior state and covariance.
    """
    x_ = np.asarray(x, dtype=np.float64)
    P_ = np.asarray(P, dtype=np.float64)
    H_ = np.asarray(H, dtype=np.float64)
    R_ = np.asarray(R, dtype=np.float64)
    y, S = innovation(x_, P_, z, H_, R_)
    # K = P H' S^-1, solved rather than inverted (S symmetric: K' = S^-1 H P)
    K = _transpose(np.asarray(np.linalg.solve(S, H_ @ P_), dtype=np.float64))
    # x = x + K y
    x_post = x_ + (K @ y[..., None])[..., 0]
    # P = (I - K H) P (I - K H)' + K R K'  (Joseph form: symmetric positive definite under
    # rounding, which the short form (I - K H) P does not guarantee)
    I_KH = np.eye(x_.shape[-1]) - K @ H_
    P_post = I_KH @ P_ @ _transpose(I_KH) + K @ R_ @ _transpose(K)
    return x_post, _symmetrise(P_post)


# ----------------------------------------------------------------------------- one target


class KalmanFilter:
    """One target's constant-velocity Kalman filter: the functions above, with state kept.

    Parameters
    ----------
    x
        Initial state ``[x, y, vx, vy]`` [m, m/s], shape (4,).
    P
        Initial covariance, shape (4, 4), symmetric positive definite.
    """

    def __init__(self, x: npt.ArrayLike, P: npt.ArrayLike) -> None:
        #: Current state [m, m/s], shape (4,); read it, change it through the methods.
        self.x = np.array(x, dtype=np.float64).reshape(STATE_DIM)
        #: Current covariance, shape (4, 4).
        self.P = np.array(P, dtype=np.float64).reshape(STATE_DIM, STATE_DIM)

    def predict(self, dt_s: float, noise: ProcessNoise, heading_rad: float = 0.0) -> None:
        """Predict ``dt_s`` [s] ahead: ``x = F x``, ``P = F P F^T + Q``, ``Q`` of ``noise`` with
        ``sigma_along`` along ``heading_rad`` [rad] (:meth:`ProcessNoise.q`)."""
        self.x, self.P = predict(self.x, self.P, cv_transition(dt_s), noise.q(dt_s, heading_rad))

    def innovation(
        self, z: npt.ArrayLike, R: npt.ArrayLike, H: npt.ArrayLike | None = None
    ) -> tuple[F64, F64]:
        """``y = z - H x``, ``S = H P H^T + R``; ``H`` defaults to :func:`position_h`."""
        return innovation(self.x, self.P, z, position_h() if H is None else H, R)

    def update(self, z: npt.ArrayLike, R: npt.ArrayLike, H: npt.ArrayLike | None = None) -> None:
        """Update with measurement ``z`` of noise ``R`` (:func:`update`, Joseph form).

        Parameters
        ----------
        z
            Measurement, shape (m,); a position ``[x, y]`` [m] by default.
        R
            Its noise covariance, shape (m, m).
        H
            Measurement matrix (m, 4); :func:`position_h` when omitted.
        """
        self.x, self.P = update(self.x, self.P, z, position_h() if H is None else H, R)


# ----------------------------------------------------------------------------- many targets


def _inverse_2x2(S: F64) -> F64:
    """Closed-form inverse of a stack of 2x2 matrices, (..., 2, 2)."""
    a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = a * d - b * c
    inverse = np.empty_like(S)
    inverse[..., 0, 0] = d / det
    inverse[..., 0, 1] = -b / det
    inverse[..., 1, 0] = -c / det
    inverse[..., 1, 1] = a / det
    return inverse


def update_position_blocks(x: F64, P: F64, z: F64, R: F64) -> tuple[F64, F64]:
    """Position update ``H = [I 0]`` of a stack of states, Joseph form, 2x2 closed-form inverse.

    ::

        y = z - p,  S = P[:2, :2] + R,  K = P[:, :2] S^-1      (P[:, :2] = P H^T, 4x2)
        x = x + K y
        P = (I - K H) P (I - K H)^T + K R K^T

    Parameters
    ----------
    x, P
        Priors, shapes (K, 4) and (K, 4, 4).
    z
        Positions [m], shape (K, 2).
    R
        Their covariances [m^2], shape (K, 2, 2).

    Returns
    -------
    x, P
        Posteriors, new arrays.
    """
    # y = z - H x
    y = z - x[:, :2]
    # S = H P H' + R
    S = P[:, :2, :2] + R
    # K = P H' S^-1
    K = P[:, :, :2] @ _inverse_2x2(S)
    Kt = np.ascontiguousarray(_transpose(K))
    # x = x + K y
    x_post = x + np.einsum("kij,kj->ki", K, y)
    # P = (I - K H) P (I - K H)' + K R K', the Joseph form's products with H = [I 0] written
    # out: M = (I - K H) P = P - K P[:2, :], then M (I - K H)' = M - M[:, :2] K'.
    M = P - K @ P[:, :2, :]
    P_post = M - M[:, :, :2] @ Kt + K @ R @ Kt
    return x_post, _symmetrise(P_post)


class SlotBank(ABC):
    """Slot bookkeeping shared by the state banks: which rows are in use, and their stamps.

    Each target occupies a *slot*, a row of the bank's arrays and of ``stamp_s (capacity,)``,
    the time its state refers to [s]. Slots are reused after :meth:`remove`; the arrays double
    when full (a subclass grows its own in :meth:`_grow_arrays`).
    """

    def __init__(self, capacity: int) -> None:
        capacity = max(1, capacity)
        self._stamp_s = np.zeros(capacity)
        self._live = np.zeros(capacity, dtype=bool)
        self._free: list[int] = list(range(capacity - 1, -1, -1))

    def __len__(self) -> int:
        return int(np.count_nonzero(self._live))

    @property
    def capacity(self) -> int:
        """Number of slots allocated."""
        return len(self._live)

    def live_slots(self) -> IntP:
        """Slots in use, increasing, shape (N,)."""
        return np.flatnonzero(self._live)

    def stamps_s(self, slots: npt.ArrayLike) -> F64:
        """Times the states of ``slots`` refer to [s], shape (K,) (a copy)."""
        return self._stamp_s[np.asarray(slots, dtype=np.intp)]

    def _take_slot(self, stamp_s: float) -> int:
        """A free slot, now in use at ``stamp_s``; the caller fills its state."""
        if not self._free:
            old = self.capacity
            self._grow_arrays(old)
            self._stamp_s = np.concatenate([self._stamp_s, np.zeros(old)])
            self._live = np.concatenate([self._live, np.zeros(old, dtype=bool)])
            self._free.extend(range(2 * old - 1, old - 1, -1))
        slot = self._free.pop()
        self._stamp_s[slot] = stamp_s
        self._live[slot] = True
        return slot

    @abstractmethod
    def _grow_arrays(self, added: int) -> None:
        """Append ``added`` rows to the subclass's state arrays."""

    def remove(self, slot: int) -> None:
        """Free ``slot`` for reuse."""
        if not self._live[slot]:
            raise KeyError(f"slot {slot} is not in use")
        self._live[slot] = False
        self._free.append(slot)


class TrackStateBank(SlotBank):
    """States of many targets in arrays, predicted and updated a subset at a time.

    Each target occupies a *slot* (:class:`SlotBank`): row ``slot`` of ``x (capacity, 4)`` and
    ``P (capacity, 4, 4)``. Every method takes an array of distinct slots and does its maths in
    one vectorised pass.

    Parameters
    ----------
    capacity
        Initial number of slots.
    """

    def __init__(self, capacity: int = 64) -> None:
        super().__init__(capacity)
        self._x = np.zeros((self.capacity, STATE_DIM))
        self._P = np.broadcast_to(np.eye(STATE_DIM), (self.capacity, STATE_DIM, STATE_DIM)).copy()

    def add(self, x: npt.ArrayLike, P: npt.ArrayLike, stamp_s: float) -> int:
        """Store a new target's state ``x`` (4,) and ``P`` (4, 4) at ``stamp_s`` [s]; its slot."""
        slot = self._take_slot(stamp_s)
        self._x[slot] = np.asarray(x, dtype=np.float64).reshape(STATE_DIM)
        self._P[slot] = np.asarray(P, dtype=np.float64).reshape(STATE_DIM, STATE_DIM)
        return slot

    def _grow_arrays(self, added: int) -> None:
        self._x = np.concatenate([self._x, np.zeros((added, STATE_DIM))])
        eyes = np.broadcast_to(np.eye(STATE_DIM), (added, STATE_DIM, STATE_DIM))
        self._P = np.concatenate([self._P, eyes])

    def copy_slot(self, source: int, target: int) -> None:
        """Give ``target`` the state, covariance and stamp of ``source``."""
        self._x[target] = self._x[source]
        self._P[target] = self._P[source]
        self._stamp_s[target] = self._stamp_s[source]

    def states(self, slots: npt.ArrayLike) -> F64:
        """States of ``slots`` [m, m/s], shape (K, 4) (a copy)."""
        return self._x[np.asarray(slots, dtype=np.intp)]

    def covariances(self, slots: npt.ArrayLike) -> F64:
        """Covariances of ``slots``, shape (K, 4, 4) (a copy)."""
        return self._P[np.asarray(slots, dtype=np.intp)]

    def set(self, slots: npt.ArrayLike, x: F64, P: F64, stamp_s: npt.ArrayLike) -> None:
        """Overwrite the states of ``slots`` with ``x`` (K, 4), ``P`` (K, 4, 4) at ``stamp_s``."""
        index = np.asarray(slots, dtype=np.intp)
        self._x[index] = x
        self._P[index] = P
        self._stamp_s[index] = stamp_s

    def commit_prior(self, slots: npt.ArrayLike, x: F64, P: F64, stamp_s: float) -> None:
        """Store a prediction of :meth:`predicted` (possibly widened) as the state of ``slots``
        at ``stamp_s``: :meth:`set` (the IMM bank's counterpart keeps its modes)."""
        self.set(slots, x, P, stamp_s)

    def predicted(
        self,
        slots: npt.ArrayLike,
        stamp_s: npt.ArrayLike,
        sigma_along_mps2: npt.ArrayLike,
        sigma_across_mps2: npt.ArrayLike,
        heading_rad: npt.ArrayLike = 0.0,
    ) -> tuple[F64, F64]:
        """States of ``slots`` predicted to ``stamp_s`` [s], without storing them.

        ``dt = stamp_s - stamp_s[slot]`` per slot, then :func:`~wz_shared.motion.predict_cv`.

        Parameters
        ----------
        slots
            Distinct slots, shape (K,).
        stamp_s
            Target time [s], scalar or (K,); not before any slot's own stamp.
        sigma_along_mps2, sigma_across_mps2, heading_rad
            Process noise of :func:`~wz_shared.motion.road_aligned_q`, scalars or (K,).

        Returns
        -------
        x_p, P_p
            Shapes (K, 4), (K, 4, 4).
        """
        index = np.asarray(slots, dtype=np.intp)
        dt = (
            np.broadcast_to(np.asarray(stamp_s, dtype=np.float64), index.shape)
            - self._stamp_s[index]
        )
        return predict_cv(
            self._x[index], self._P[index], dt, sigma_along_mps2, sigma_across_mps2, heading_rad
        )

    def predict_to(
        self,
        slots: npt.ArrayLike,
        stamp_s: npt.ArrayLike,
        sigma_along_mps2: npt.ArrayLike,
        sigma_across_mps2: npt.ArrayLike,
        heading_rad: npt.ArrayLike = 0.0,
    ) -> None:
        """Predict ``slots`` to ``stamp_s`` [s] and store (see :meth:`predicted`)."""
        x_p, P_p = self.predicted(slots, stamp_s, sigma_along_mps2, sigma_across_mps2, heading_rad)
        index = np.asarray(slots, dtype=np.intp)
        self.set(
            index, x_p, P_p, np.broadcast_to(np.asarray(stamp_s, dtype=np.float64), index.shape)
        )

    def predict(
        self,
        slots: npt.ArrayLike,
        dt_s: npt.ArrayLike,
        sigma_along_mps2: npt.ArrayLike,
        sigma_across_mps2: npt.ArrayLike,
        heading_rad: npt.ArrayLike = 0.0,
    ) -> None:
        """Predict ``slots`` by ``dt_s`` [s] (scalar or (K,), >= 0) and store."""
        index = np.asarray(slots, dtype=np.intp)
        dt = np.broadcast_to(np.asarray(dt_s, dtype=np.float64), index.shape)
        self.predict_to(
            index, self._stamp_s[index] + dt, sigma_along_mps2, sigma_across_mps2, heading_rad
        )

    def update(
        self,
        slots: npt.ArrayLike,
        z: npt.ArrayLike,
        R: npt.ArrayLike,
        H: npt.ArrayLike | None = None,
    ) -> None:
        """Update ``slots`` with one measurement each, in one vectorised Joseph-form update.

        Parameters
        ----------
        slots
            Distinct slots, shape (K,).
        z
            Measurements, shape (K, m); positions ``[x, y]`` [m] when ``H`` is omitted.
        R
            Their covariances, shape (K, m, m).
        H
            Measurement matrix (m, 4) or (K, m, 4); omitted: positions, handled by
            :func:`update_position_blocks`, otherwise :func:`update`.
        """
        index = np.asarray(slots, dtype=np.intp)
        z_ = np.asarray(z, dtype=np.float64)
        R_ = np.asarray(R, dtype=np.float64)
        if H is None:
            x_post, P_post = update_position_blocks(self._x[index], self._P[index], z_, R_)
        else:
            x_post, P_post = update(self._x[index], self._P[index], z_, H, R_)
        self._x[index] = x_post
        self._P[index] = P_post


def is_symmetric_positive_definite(P: F64, tolerance: float = 1e-9) -> bool:
    """Whether every matrix of ``P`` (..., n, n) is symmetric (to ``tolerance`` relative to its
    largest entry) and has a Cholesky factor."""
    scale = max(float(np.max(np.abs(P))), 1.0) if P.size else 1.0
    if not np.all(np.abs(P - _transpose(P)) <= tolerance * scale):
        return False
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return False
    return True
