"""Augmented-state extended Kalman filter identification of the ``response`` model.

The unknown coefficients are appended to the state and estimated with it [seed 001, section 3,
eqs 3-5; seed 002, ch 8.2, eqs 8.1-8.3]: they have no dynamics (``da/dt = 0``), so the
augmented state is

    x^a = [u, v, r, a1..a9, b1..b4, c1..c3]      (19 states)

with the Euler-discretised response model of [seed 001, eq 4] as the transition (``T`` the
sampling period, ``s_m(k)`` the mean of the measured inputs at samples ``k`` and ``k+1``)::

    u(k+1) = u + T (a1 u^2 + a2 v^2 + a3 r^2 + a4 d^2 + a5 v r + a6 v d + a7 r d + a8 u n + a9 n^2)
    v(k+1) = v + T (b1 v + b2 r + b3 d + b4 u r)
    r(k+1) = r + T (c1 v + c2 r + c3 d)
    a, b, c (k+1) = a, b, c (k)

and the measurement ``y = H x^a + e`` with ``H = [I_3 0]``: the surge, sway and yaw rate that
pre-processing derives from position and heading [seed 001, section 4.1]. The EKF recursion is
[seed 001, eq 5] with ``Phi`` the analytic Jacobian of the transition, computed in square-root
form (``P = S S^T``, time and measurement updates by QR factorisations of stacked factors, the
array algorithm of Kaminski, Bryson & Schmidt 1971): with the paper's ``P(0) = 1e5 I`` and
regressors like ``n^2`` (rpm squared) the covariance spans some twenty orders of magnitude, and
the conventional update loses its positive definiteness to rounding; the square-root form gives
the same result in exact arithmetic and stays positive definite.

Units are the paper's (and the ship file's, see :mod:`trafficsim.ships.response`): ``u, v`` in
m/s, ``r`` in deg/s, rudder ``d`` in deg, propeller ``n`` in rpm, so the estimate goes straight
into a ship file. Start as in [seed 001, section 4.2]: ``P(0) = 1e5 I`` for the coefficients,
coefficients zero, states at the first measurement. Several runs are processed in turn: the
motion states restart at each run's first measurement, the coefficients and their covariance
carry over.

Noise (not given in the paper; our choices): measurement covariance from the smoother's standard
deviations at each sample (floored), state process noise 10 % of it, coefficient process noise
zero (constant coefficients, as eq 8.1).

The coefficients' standard deviations are the filter's covariance and come out too narrow, the
more so the noisier the measured states: the augmented EKF neglects how its gain depends on the
coefficients (Ljung, IEEE TAC 24(1), 1979). The output-error fit gives the intervals to quote.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

DEG = 180.0 / np.pi
NAMES = ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8", "a9", "b1", "b2", "b3", "b4",
         "c1", "c2", "c3")
N_AUG = 3 + len(NAMES)
#: floors of the measurement standard deviations (m/s, m/s, deg/s)
SIGMA_FLOOR = np.array([1e-3, 1e-3, 1e-3])


@dataclass
class EKFResult:
    """Coefficient estimates of the augmented EKF (paper units, module doc).

    Attributes:
        names: coefficient names ``(16,)``; x: final estimate; std: its standard deviation
            (square root of the filter covariance's diagonal).
        trace: ``(K, 16)`` estimate after each recursion (convergence history).
        run_starts: index into ``trace`` where each run begins.
        innovation_rms: RMS of the normalised innovations per measured state (u, v, r).
        steps, elapsed_s: recursions and wall time.
    """

    names: tuple[str, ...]
    x: np.ndarray
    std: np.ndarray
    trace: np.ndarray
    run_starts: list[int]
    innovation_rms: np.ndarray
    steps: int
    elapsed_s: float

    def summary(self) -> dict[str, Any]:
        return {"coefficients": {n: {"value": float(v), "std": float(s)}
                                 for n, v, s in zip(self.names, self.x, self.std, strict=True)},
                "recursions": self.steps, "elapsed_s": self.elapsed_s,
                "normalised_innovation_rms": {"u": float(self.innovation_rms[0]),
                                              "v": float(self.innovation_rms[1]),
                                              "r": float(self.innovation_rms[2])}}


def transition(x: np.ndarray, d: float, n: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Augmented transition ``f^a`` [seed 001, eq 4] and its Jacobian ``Phi`` ``(19, 19)``."""
    u, v, r = x[0], x[1], x[2]
    a, b, c = x[3:12], x[12:16], x[16:19]
    ra = np.array([u * u, v * v, r * r, d * d, v * r, v * d, r * d, u * n, n * n])
    rb = np.array([v, r, d, u * r])
    rc = np.array([v, r, d])
    xn = x.copy()
    xn[0] = u + T * (a @ ra)
    xn[1] = v + T * (b @ rb)
    xn[2] = r + T * (c @ rc)
    phi = np.eye(N_AUG)
    phi[0, 0] += T * (2.0 * a[0] * u + a[7] * n)
    phi[0, 1] = T * (2.0 * a[1] * v + a[4] * r + a[5] * d)
    phi[0, 2] = T * (2.0 * a[2] * r + a[4] * v + a[6] * d)
    phi[0, 3:12] = T * ra
    phi[1, 0] = T * b[3] * r
    phi[1, 1] += T * b[0]
    phi[1, 2] = T * (b[1] + b[3] * u)
    phi[1, 12:16] = T * rb
    phi[2, 1] = T * c[0]
    phi[2, 2] += T * c[1]
    phi[2, 16:19] = T * rc
    return xn, phi


def identify_response(runs: Sequence[Any], theta0: np.ndarray | None = None,
                      p0: float = 1e5, state_noise_fraction: float = 0.1) -> EKFResult:
    """Run the augmented EKF over smoothed runs (:class:`~trafficsim.identify.preprocess.
    Kinematics`, at their own sampling period) and return the coefficient estimate.

    Args:
        runs: smoothed runs in the order they are processed.
        theta0: starting coefficients ``(16,)`` (default zeros [seed 001, section 4.2]).
        p0: initial coefficient variance (``P(0) = p0 I`` [seed 001, section 4.2]).
        state_noise_fraction: state process noise as a fraction of the measurement variance.
    """
    start = time.perf_counter()
    theta = np.zeros(len(NAMES)) if theta0 is None else np.asarray(theta0, float).copy()
    x = np.zeros(N_AUG)
    x[3:] = theta
    # square-root form: P = S S^T; S_theta the factor of the coefficients' covariance
    s_theta = np.eye(len(NAMES)) * np.sqrt(p0)
    S = np.zeros((N_AUG, N_AUG))
    trace: list[np.ndarray] = []
    run_starts: list[int] = []
    nis: list[np.ndarray] = []
    pre = np.zeros((N_AUG + 3, N_AUG + 3))
    for run in runs:
        sm, tr = run.smooth, run.trial
        y = np.stack([sm["u_mps"], sm["v_mps"], sm["r_radps"] * DEG], axis=1)
        sig = np.stack([sm["sigma_u_mps"], sm["sigma_v_mps"], sm["sigma_r_radps"] * DEG], axis=1)
        sig = np.maximum(np.nan_to_num(sig, nan=1.0), SIGMA_FLOOR)
        d = np.degrees(_fill(tr.rudder_rad))
        n = _fill(tr.rps) * 60.0
        T = run.dt_s
        run_starts.append(len(trace))
        # restart the motion states at the run's first measurement, keep the coefficients
        x[:3] = y[0]
        S[:] = 0.0
        S[:3, :3] = np.diag(sig[0])
        S[3:, 3:] = s_theta
        q_sqrt = np.sqrt(state_noise_fraction)
        for k in range(y.shape[0] - 1):
            dm, nm = 0.5 * (d[k] + d[k + 1]), 0.5 * (n[k] + n[k + 1])  # s_m(k) [seed 001, eq 4]
            x, phi = transition(x, dm, nm, T)
            # time update P = Phi P Phi^T + Q by a QR of the stacked factors
            stacked = np.zeros((N_AUG + 3, N_AUG))
            stacked[:N_AUG] = (phi @ S).T
            stacked[N_AUG:, :3] = np.diag(q_sqrt * sig[k + 1])
            S = np.linalg.qr(stacked, mode="r").T
            # measurement update (H = [I 0]) by a QR of the pre-array [[sqrt R, H S], [0, S]]
            pre[:] = 0.0
            pre[:3, :3] = np.diag(sig[k + 1])
            pre[:3, 3:] = S[:3, :]
            pre[3:, 3:] = S
            post = np.linalg.qr(pre.T, mode="r").T
            sy, kbar = post[:3, :3], post[3:, :3]
            S = post[3:, 3:]
            gain = np.linalg.solve(sy.T, kbar.T).T  # K = Kbar Sy^-1
            nu = y[k + 1] - x[:3]
            x = x + gain @ nu
            nis.append(nu / np.sqrt(np.sum(sy * sy, axis=1)))
            trace.append(x[3:].copy())
        # the coefficients' covariance factor carries over to the next run
        s_theta = np.linalg.qr(S[3:, :].T, mode="r").T
    if not trace:
        raise ValueError("no recursion: runs need at least two samples")
    inn = np.array(nis)
    return EKFResult(names=NAMES, x=x[3:].copy(), std=np.sqrt(np.sum(s_theta * s_theta, axis=1)),
                     trace=np.array(trace), run_starts=run_starts,
                     innovation_rms=np.sqrt(np.mean(inn**2, axis=0)), steps=len(trace),
                     elapsed_s=time.perf_counter() - start)


def _fill(values: np.ndarray) -> np.ndarray:
    ok = np.isfinite(values)
    if ok.all() or not ok.any():
        return np.nan_to_num(values)
    idx = np.arange(values.size)
    return np.interp(idx, idx[ok], values[ok])
