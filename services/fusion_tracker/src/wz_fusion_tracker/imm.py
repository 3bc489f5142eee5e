"""Interacting multiple model (IMM) estimator over a bank of targets.

A driver approaching a lane closure mostly keeps the lane at a steady speed, and now and then
brakes hard or merges. One constant-velocity model must pick one process noise for both: low,
and the track lags a merge by a lane width for a second or two; high, and the track wanders
across the lane with every noisy detection while the vehicle drives straight. The IMM
(Blom and Bar-Shalom 1988; Bar-Shalom, Li and Kirubarajan 2001, section 11.6) runs several
models side by side and weighs them by how well each predicted the measurements:

- mode 0, **steady**: white acceleration with small stds along and across the road (lane
  keeping, gentle speed changes);
- mode 1, **manoeuvre**: the tracker's ordinary stds (braking at 6-9 m/s^2, a merge).

Both modes are the constant-velocity model of :mod:`wz_shared.motion` on the same state
``[x, y, vx, vy]``, differing only in ``Q``; so the mixing needs no state conversion. One cycle,
per target, with mode probabilities ``mu_i`` and the Markov chain's transition probabilities
``p_ij(dt)``:

::

    c_j      = sum_i p_ij mu_i                                  (predicted mode probability)
    mu_i|j   = p_ij mu_i / c_j                                  (mixing weights)
    x0_j     = sum_i mu_i|j x_i
    P0_j     = sum_i mu_i|j (P_i + (x_i - x0_j)(x_i - x0_j)^T)
    x_j, P_j = CV prediction of (x0_j, P0_j) over dt with Q_j
    -- measurement z --
    x_j, P_j = Kalman update of each mode (Joseph form)
    L_j      = N(y_j; 0, S_j)                                   (each mode's likelihood)
    mu_j     = c_j L_j / sum_k c_k L_k

and the output (gating, snapshots, smoothing) is the moment-matched mixture::

    x = sum_j mu_j x_j,   P = sum_j mu_j (P_j + (x_j - x)(x_j - x)^T)

**Asynchronous sensors.** Batches arrive at irregular intervals, so the transition matrix is
that of a continuous-time chain with mean sojourn ``tau_j`` in each mode, over the actual
``dt``: for two modes, with rates ``a = 1 / tau_0`` and ``b = 1 / tau_1``,
``e = exp(-(a + b) dt)``::

    P(dt) = 1 / (a + b) [[b + a e,  a (1 - e)],
                         [b (1 - e), a + b e ]]

``dt = 0`` (two sensors with one stamp) mixes nothing. New targets start with the chain's
stationary probabilities ``(b, a) / (a + b)``.

:class:`IMMStateBank` has the interface of :class:`~wz_fusion_tracker.kalman.TrackStateBank`,
so the tracker drives either. Its tests cross-check it against filterpy's ``IMMEstimator`` and,
with two equal modes, against the single-model bank.

Nothing here does I/O.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from wz_fusion_tracker.kalman import (
    SlotBank,
    _inverse_2x2,
    update,
    update_position_blocks,
)
from wz_shared.arrays import F64, IntP
from wz_shared.motion import STATE_DIM, predict_cv

#: Mode probabilities are kept at least this, so that a mode long out of favour can come back
#: within one update (a floor well below any probability that changes a decision).
MODE_PROBABILITY_FLOOR = 1e-6


def two_mode_transition(dt_s: npt.ArrayLike, sojourn_0_s: float, sojourn_1_s: float) -> F64:
    """Transition probabilities ``p_ij`` of a two-state continuous-time Markov chain over ``dt``.

    Parameters
    ----------
    dt_s
        Time steps [s], shape (K,), each >= 0.
    sojourn_0_s, sojourn_1_s
        Mean time spent in mode 0 and in mode 1 before leaving it [s], > 0.

    Returns
    -------
    P
        Shape (K, 2, 2), row ``i`` the probabilities of being in each mode ``dt`` after being
        in mode ``i``; rows sum to 1.
    """
    dt = np.asarray(dt_s, dtype=np.float64)
    a, b = 1.0 / sojourn_0_s, 1.0 / sojourn_1_s
    e = np.exp(-(a + b) * dt)
    out = np.empty((*dt.shape, 2, 2))
    out[..., 0, 1] = a * (1.0 - e) / (a + b)
    out[..., 0, 0] = 1.0 - out[..., 0, 1]
    out[..., 1, 0] = b * (1.0 - e) / (a + b)
    out[..., 1, 1] = 1.0 - out[..., 1, 0]
    return out


def mixture_moments(weights: F64, x: F64, P: F64) -> tuple[F64, F64]:
    """Mean and covariance of a Gaussian mixture, per target.

    ::

        x = sum_j w_j x_j,   P = sum_j w_j (P_j + (x_j - x)(x_j - x)^T)

    Parameters
    ----------
    weights
        Shape (K, M), rows summing to 1.
    x, P
        Components, shapes (K, M, n) and (K, M, n, n).
    """
    mean = np.einsum("km,kma->ka", weights, x)
    spread = x - mean[:, None, :]
    cov = np.einsum("km,kmab->kab", weights, P) + np.einsum(
        "km,kma,kmb->kab", weights, spread, spread
    )
    return mean, 0.5 * (cov + np.swapaxes(cov, -1, -2))


def _log_likelihood(y: F64, S: F64) -> F64:
    """``log N(y; 0, S)`` up to the constant ``-m/2 log 2 pi`` (the same for every mode), (K,)."""
    if S.shape[-1] == 2:
        det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
        d2 = np.einsum("ki,kij,kj->k", y, _inverse_2x2(S), y)
        return np.asarray(-0.5 * (d2 + np.log(det)), dtype=np.float64)
    _sign, log_det = np.linalg.slogdet(S)
    d2 = np.einsum("ki,ki->k", y, np.linalg.solve(S, y[..., None])[..., 0])
    return np.asarray(-0.5 * (d2 + log_det), dtype=np.float64)


class IMMStateBank(SlotBank):
    """States of many targets, each an IMM of constant-velocity modes that differ in ``Q``.

    Per slot: mode states ``x (M, 4)``, covariances ``P (M, 4, 4)``, mode probabilities
    ``mu (M,)``, and the stamp they refer to. The methods take the same arguments as
    :class:`~wz_fusion_tracker.kalman.TrackStateBank`'s, except that the acceleration stds may
    be given per mode, shape (M,) or (K, M); :meth:`states` and :meth:`covariances` return the
    moment-matched mixture.

    Parameters
    ----------
    sojourn_s
        Mean time in each mode before leaving it [s], (steady, manoeuvre); two modes.
    capacity
        Initial number of slots.
    """

    def __init__(self, sojourn_s: tuple[float, float], capacity: int = 64) -> None:
        if len(sojourn_s) != 2 or min(sojourn_s) <= 0.0:
            raise ValueError(f"two positive mode sojourn times are needed, got {sojourn_s}")
        self.sojourn_s = (float(sojourn_s[0]), float(sojourn_s[1]))
        self.modes = 2
        a, b = 1.0 / self.sojourn_s[0], 1.0 / self.sojourn_s[1]
        #: The chain's stationary distribution: a new target's mode probabilities.
        self.initial_probabilities = np.array([b, a]) / (a + b)
        super().__init__(capacity)
        self._xm = np.zeros((self.capacity, self.modes, STATE_DIM))
        self._Pm = np.broadcast_to(
            np.eye(STATE_DIM), (self.capacity, self.modes, STATE_DIM, STATE_DIM)
        ).copy()
        self._mu = np.broadcast_to(self.initial_probabilities, (self.capacity, self.modes)).copy()
        # The last prediction (see commit_prior): per-mode priors, predicted mode probabilities,
        # their mixture and stamp, by row; the row of each slot whose state has not changed
        # since.
        self._last: tuple[F64, F64, F64, F64, F64, F64] | None = None
        self._last_row: dict[int, int] = {}

    # --- slots ---

    def add(self, x: npt.ArrayLike, P: npt.ArrayLike, stamp_s: float) -> int:
        """Store a new target, every mode at ``x`` (4,), ``P`` (4, 4), the stationary mode
        probabilities, at ``stamp_s`` [s]; its slot."""
        slot = self._take_slot(stamp_s)
        self._xm[slot] = np.asarray(x, dtype=np.float64).reshape(STATE_DIM)
        self._Pm[slot] = np.asarray(P, dtype=np.float64).reshape(STATE_DIM, STATE_DIM)
        self._mu[slot] = self.initial_probabilities
        self._last_row.pop(slot, None)
        return slot

    def remove(self, slot: int) -> None:
        """Free ``slot`` for reuse."""
        super().remove(slot)
        self._last_row.pop(slot, None)

    def copy_slot(self, source: int, target: int) -> None:
        """Give ``target`` the whole state of ``source`` (modes, probabilities, stamp)."""
        self._xm[target] = self._xm[source]
        self._Pm[target] = self._Pm[source]
        self._mu[target] = self._mu[source]
        self._stamp_s[target] = self._stamp_s[source]
        self._last_row.pop(target, None)

    def _grow_arrays(self, added: int) -> None:
        m = self.modes
        self._xm = np.concatenate([self._xm, np.zeros((added, m, STATE_DIM))])
        eyes = np.broadcast_to(np.eye(STATE_DIM), (added, m, STATE_DIM, STATE_DIM))
        self._Pm = np.concatenate([self._Pm, eyes])
        self._mu = np.concatenate(
            [self._mu, np.broadcast_to(self.initial_probabilities, (added, m))]
        )

    # --- reading ---

    def states(self, slots: npt.ArrayLike) -> F64:
        """Mixture means of ``slots`` [m, m/s], shape (K, 4)."""
        index = np.asarray(slots, dtype=np.intp)
        return np.asarray(
            np.einsum("km,kma->ka", self._mu[index], self._xm[index]), dtype=np.float64
        )

    def covariances(self, slots: npt.ArrayLike) -> F64:
        """Mixture covariances of ``slots``, shape (K, 4, 4)."""
        index = np.asarray(slots, dtype=np.intp)
        return mixture_moments(self._mu[index], self._xm[index], self._Pm[index])[1]

    def mode_probabilities(self, slots: npt.ArrayLike) -> F64:
        """Mode probabilities of ``slots``, shape (K, M), rows summing to 1 (a copy)."""
        return self._mu[np.asarray(slots, dtype=np.intp)]

    # --- prediction ---

    def _predict_modes(
        self,
        index: IntP,
        stamp_s: npt.ArrayLike,
        sigma_along_mps2: npt.ArrayLike,
        sigma_across_mps2: npt.ArrayLike,
        heading_rad: npt.ArrayLike,
    ) -> tuple[F64, F64, F64]:
        """Mix and predict each mode of ``index`` to ``stamp_s``: ``x_j``, ``P_j``, ``c_j``."""
        k, m = len(index), self.modes
        dt = (
            np.broadcast_to(np.asarray(stamp_s, dtype=np.float64), index.shape)
            - (self._stamp_s[index])
        )
        mu, xm, Pm = self._mu[index], self._xm[index], self._Pm[index]
        pi = two_mode_transition(dt, *self.sojourn_s)  # (K, i, j)
        c = np.einsum("ki,kij->kj", mu, pi)
        w = mu[:, :, None] * pi / c[:, None, :]  # mu_i|j
        x0 = np.einsum("kij,kia->kja", w, xm)
        spread = xm[:, :, None, :] - x0[:, None, :, :]  # (K, i, j, 4)
        P0 = np.einsum("kij,kiab->kjab", w, Pm) + np.einsum(
            "kij,kija,kijb->kjab", w, spread, spread
        )
        along = np.broadcast_to(np.asarray(sigma_along_mps2, dtype=np.float64), (k, m))
        across = np.broadcast_to(np.asarray(sigma_across_mps2, dtype=np.float64), (k, m))
        heading = np.broadcast_to(np.asarray(heading_rad, dtype=np.float64), index.shape)
        x_p, P_p = predict_cv(
            x0.reshape(k * m, STATE_DIM),
            P0.reshape(k * m, STATE_DIM, STATE_DIM),
            np.repeat(dt, m),
            along.reshape(-1),
            across.reshape(-1),
            np.repeat(heading, m),
        )
        return x_p.reshape(k, m, STATE_DIM), P_p.reshape(k, m, STATE_DIM, STATE_DIM), c

    def predicted(
        self,
        slots: npt.ArrayLike,
        stamp_s: npt.ArrayLike,
        sigma_along_mps2: npt.ArrayLike,
        sigma_across_mps2: npt.ArrayLike,
        heading_rad: npt.ArrayLike = 0.0,
    ) -> tuple[F64, F64]:
        """Mixture of ``slots`` predicted to ``stamp_s`` [s], without storing it.

        The per-mode priors are kept until the next call, for :meth:`commit_prior`.

        Parameters
        ----------
        slots
            Distinct slots, shape (K,).
        stamp_s
            Target time [s], scalar or (K,); not before any slot's own stamp.
        sigma_along_mps2, sigma_across_mps2
            Acceleration stds per mode [m/s^2], shape (M,) or (K, M).
        heading_rad
            Road heading [rad], scalar or (K,).

        Returns
        -------
        x_p, P_p
            Shapes (K, 4), (K, 4, 4).
        """
        index = np.asarray(slots, dtype=np.intp)
        xm, Pm, c = self._predict_modes(
            index, stamp_s, sigma_along_mps2, sigma_across_mps2, heading_rad
        )
        x_p, P_p = mixture_moments(c, xm, Pm)
        stamps = np.broadcast_to(np.asarray(stamp_s, dtype=np.float64), index.shape).copy()
        self._last = (stamps, xm, Pm, c, x_p, P_p)
        self._last_row = {slot: row for row, slot in enumerate(index.tolist())}
        return x_p, P_p

    def _changed(self, index: IntP) -> None:
        """The states of ``index`` changed: the last prediction no longer holds for them."""
        if self._last_row:
            for slot in index.tolist():
                self._last_row.pop(slot, None)

    def predict_to(
        self,
        slots: npt.ArrayLike,
        stamp_s: npt.ArrayLike,
        sigma_along_mps2: npt.ArrayLike,
        sigma_across_mps2: npt.ArrayLike,
        heading_rad: npt.ArrayLike = 0.0,
    ) -> None:
        """Predict ``slots`` to ``stamp_s`` [s] and store (see :meth:`predicted`)."""
        index = np.asarray(slots, dtype=np.intp)
        xm, Pm, c = self._predict_modes(
            index, stamp_s, sigma_along_mps2, sigma_across_mps2, heading_rad
        )
        self._xm[index], self._Pm[index], self._mu[index] = xm, Pm, c
        self._stamp_s[index] = np.broadcast_to(np.asarray(stamp_s, dtype=np.float64), index.shape)
        self._changed(index)

    def commit_prior(self, slots: npt.ArrayLike, x: F64, P: F64, stamp_s: float) -> None:
        """Store the prediction of :meth:`predicted` for ``slots`` as their state at ``stamp_s``.

        ``x`` (K, 4) and ``P`` (K, 4, 4) are the mixture the caller was given, possibly
        changed (the tracker widens a lost track's prior before taking it up again): the
        change is applied to every mode. A slot the last prediction did not cover, or covered
        to another stamp, gets ``x`` and ``P`` in every mode (its mode probabilities kept).
        """
        index = np.asarray(slots, dtype=np.intp)
        x = np.asarray(x, dtype=np.float64)
        P = np.asarray(P, dtype=np.float64)
        xm = np.repeat(x[:, None, :], self.modes, axis=1)
        Pm = np.repeat(P[:, None, :, :], self.modes, axis=1)
        mu = self._mu[index]
        if self._last is not None and self._last_row:
            last_stamps, last_xm, last_Pm, last_c, last_x, last_P = self._last
            rows = np.array(
                [self._last_row.get(slot, -1) for slot in index.tolist()], dtype=np.intp
            )
            ok = rows >= 0
            ok[ok] = last_stamps[rows[ok]] == stamp_s
            if ok.any():
                r = rows[ok]
                xm[ok] = last_xm[r] + (x[ok] - last_x[r])[:, None, :]
                Pm[ok] = last_Pm[r] + (P[ok] - last_P[r])[:, None, :, :]
                mu = mu.copy()
                mu[ok] = last_c[r]
        self._xm[index], self._Pm[index], self._mu[index] = xm, Pm, mu
        self._stamp_s[index] = stamp_s
        self._changed(index)

    # --- update ---

    def update(
        self,
        slots: npt.ArrayLike,
        z: npt.ArrayLike,
        R: npt.ArrayLike,
        H: npt.ArrayLike | None = None,
    ) -> None:
        """Update every mode of ``slots`` with one measurement each; reweigh the modes.

        Parameters
        ----------
        slots
            Distinct slots, shape (K,).
        z
            Measurements, shape (K, m); positions ``[x, y]`` [m] when ``H`` is omitted.
        R
            Their covariances, shape (K, m, m).
        H
            Measurement matrix (m, 4) or (K, m, 4); omitted: positions.
        """
        index = np.asarray(slots, dtype=np.intp)
        k, m = len(index), self.modes
        z_ = np.repeat(np.asarray(z, dtype=np.float64), m, axis=0)
        R_ = np.repeat(np.asarray(R, dtype=np.float64), m, axis=0)
        x = self._xm[index].reshape(k * m, STATE_DIM)
        P = self._Pm[index].reshape(k * m, STATE_DIM, STATE_DIM)
        if H is None:
            y = z_ - x[:, :2]
            S = P[:, :2, :2] + R_
            x_post, P_post = update_position_blocks(x, P, z_, R_)
        else:
            H_ = np.asarray(H, dtype=np.float64)
            if H_.ndim == 3:
                H_ = np.repeat(H_, m, axis=0)
            y = z_ - (H_ @ x[:, :, None])[:, :, 0]
            S = H_ @ P @ np.swapaxes(H_, -1, -2) + R_
            x_post, P_post = update(x, P, z_, H_, R_)
        log_l = _log_likelihood(y, S).reshape(k, m)
        log_w = np.log(self._mu[index]) + log_l
        w = np.exp(log_w - log_w.max(axis=1, keepdims=True))
        mu = w / w.sum(axis=1, keepdims=True)
        mu = np.maximum(mu, MODE_PROBABILITY_FLOOR)
        self._mu[index] = mu / mu.sum(axis=1, keepdims=True)
        self._xm[index] = x_post.reshape(k, m, STATE_DIM)
        self._Pm[index] = P_post.reshape(k, m, STATE_DIM, STATE_DIM)
        self._changed(index)
