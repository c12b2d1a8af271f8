"""Per-axis constant-acceleration (CA) Kalman filter, vectorised over many independent series.

Model of one axis (one series), sampling period ``T`` [seed 001, eqs 6-7]::

    X(k+1) = Phi X(k) + w(k),   X = [s, u, a]  (position, velocity, acceleration)
    Z(k)   = H X(k) + n(k),     H = [1 0 0],  var n = sigma_R^2

    Phi = [[1, T, T^2/2],        Q = 2 alpha sigma_a^2 [[T^5/20, T^4/8, T^3/6],
           [0, 1, T    ],                                [T^4/8,  T^3/3, T^2/2],
           [0, 0, 1    ]]                                [T^3/6,  T^2/2, T    ]]

``Q`` is exactly the covariance of a white jerk of spectral density ``q = 2 alpha sigma_a^2``
integrated over one period (the Singer manoeuvre model in its small ``alpha T`` limit, with the
plain CA transition as printed), so only the product ``alpha sigma_a^2`` matters. The paper
gives no values for ``alpha`` and ``sigma_a``; the defaults of :func:`build` are our choice.

Initial conditions as printed [seed 001, after eq 8], from the first two samples ``Z(1), Z(2)``
(1-based in the paper; our sample indices 0 and 1)::

    X(2) = [Z(2), (Z(2) - Z(1)) / T, 0]
    P(2) = [[sigma_R^2,   sigma_R^2/T,     0],
            [sigma_R^2/T, 2 sigma_R^2/T^2, 0],
            [0,           0,               0]]

so the filter has no estimate at sample 0 (NaN there) and starts at sample 1.

"Series" are independent scalar tracks, e.g. ships x axes (north, east) or a heading: all
arrays carry a leading series axis ``m``. Series built by :func:`build` with ``axes=2`` are
ship-major: series ``2 i`` is ship ``i`` north, ``2 i + 1`` ship ``i`` east, so a ``(n, 2)``
measurement array reshapes to ``(2 n,)`` in C order. The measurement update is closed form
(``H`` picks the position, the innovation variance is a scalar): no matrix inversion.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

#: state dimension: position, velocity, acceleration
CA_DIMS = 3

#: defaults of :func:`build` (the paper gives T = 2 s and no values for the others)
DEFAULTS: dict[str, float] = {
    "dt_s": 2.0,            # sampling period T [seed 001, section 4.1]
    "sigma_m": 3.0,         # measurement noise sigma_R (our choice: a DGPS-class fix)
    "sigma_acc_mps2": 0.05,  # manoeuvre acceleration sigma_a (our choice)
    "alpha_per_s": 1.0 / 30.0,  # manoeuvre "operation parameter" alpha (our choice)
}


@dataclass(frozen=True)
class CAParams:
    """Filter parameters, one entry per series, ``(m,)`` float arrays.

    Attributes:
        dt_s: sampling period T, s.
        sigma_meas: measurement noise standard deviation sigma_R, in the series' unit
            (m for positions, rad for a heading).
        sigma_acc: manoeuvre acceleration standard deviation sigma_a, series' unit per s^2.
        alpha_per_s: the paper's operation parameter alpha, 1/s.
    """

    dt_s: np.ndarray
    sigma_meas: np.ndarray
    sigma_acc: np.ndarray
    alpha_per_s: np.ndarray

    @classmethod
    def of(cls, m: int, dt_s: float | np.ndarray, sigma_meas: float | np.ndarray,
           sigma_acc: float | np.ndarray, alpha_per_s: float | np.ndarray) -> CAParams:
        """Parameters for ``m`` series from scalars or ``(m,)`` arrays (broadcast)."""
        def col(v: float | np.ndarray) -> np.ndarray:
            return np.broadcast_to(np.asarray(v, dtype=float), (m,)).copy()

        return cls(col(dt_s), col(sigma_meas), col(sigma_acc), col(alpha_per_s))

    @property
    def m(self) -> int:
        return int(self.dt_s.shape[0])


def build(configs: Sequence[Mapping[str, Any]], axes: int = 1) -> CAParams:
    """Parameters from per-ship config dicts, each ship repeated for ``axes`` series.

    Keys (all optional, defaults in :data:`DEFAULTS`): ``dt_s`` (s), ``sigma_m`` (m, position
    fix noise per axis), ``sigma_acc_mps2`` (m/s^2), ``alpha_per_s`` (1/s).
    Series order is ship-major (ship 0 axis 0, ship 0 axis 1, ship 1 axis 0, ...).
    """
    def col(key: str) -> np.ndarray:
        v = np.array([float(c.get(key, DEFAULTS[key])) for c in configs], dtype=float)
        return np.repeat(v, axes)

    p = CAParams(col("dt_s"), col("sigma_m"), col("sigma_acc_mps2"), col("alpha_per_s"))
    if not (np.all(p.dt_s > 0) and np.all(p.sigma_meas > 0) and np.all(p.sigma_acc >= 0)
            and np.all(p.alpha_per_s >= 0)):  # (NaN fails too)
        raise ValueError("CA filter needs dt_s > 0, sigma_m > 0, sigma_acc_mps2 >= 0, "
                         "alpha_per_s >= 0")
    return p


def transition(dt_s: np.ndarray) -> np.ndarray:
    """Transition matrices Phi [seed 001, eq 6], ``(m, 3, 3)``; ``dt_s`` is ``(m,)`` s."""
    t = np.asarray(dt_s, dtype=float)
    phi = np.zeros((*t.shape, 3, 3))
    phi[..., 0, 0] = phi[..., 1, 1] = phi[..., 2, 2] = 1.0
    phi[..., 0, 1] = phi[..., 1, 2] = t
    phi[..., 0, 2] = 0.5 * t * t
    return phi


def process_noise(params: CAParams) -> np.ndarray:
    """Process noise covariance Q [seed 001, eq 6], ``(m, 3, 3)``, as printed."""
    t = params.dt_s
    q = 2.0 * params.alpha_per_s * params.sigma_acc**2
    out = np.empty((*t.shape, 3, 3))
    out[..., 0, 0] = t**5 / 20.0
    out[..., 0, 1] = out[..., 1, 0] = t**4 / 8.0
    out[..., 0, 2] = out[..., 2, 0] = t**3 / 6.0
    out[..., 1, 1] = t**3 / 3.0
    out[..., 1, 2] = out[..., 2, 1] = t**2 / 2.0
    out[..., 2, 2] = t
    return out * q[..., None, None]


def initial_state(params: CAParams, z1: np.ndarray, z2: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Initial estimate X(2) and covariance P(2) from two samples [seed 001, after eq 8].

    Args:
        z1, z2: ``(m,)`` the first two measurements of each series (series' unit).

    Returns:
        ``x`` ``(m, 3)`` and ``P`` ``(m, 3, 3)`` at the time of ``z2``.
    """
    t, r = params.dt_s, params.sigma_meas**2
    x = np.stack([z2, (z2 - z1) / t, np.zeros_like(t)], axis=-1)
    p = np.zeros((*t.shape, 3, 3))
    p[..., 0, 0] = r
    p[..., 0, 1] = p[..., 1, 0] = r / t
    p[..., 1, 1] = 2.0 * r / t**2
    return x, p


def predict(params: CAParams, x: np.ndarray, p: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """Time update [seed 001, eq 7]: ``X(k+1|k) = Phi X(k)``, ``P(k+1|k) = Phi P Phi^T + Q``.

    Args:
        x: ``(m, 3)`` estimate; p: ``(m, 3, 3)`` covariance.
    """
    phi = transition(params.dt_s)
    xp = np.einsum("mij,mj->mi", phi, x)
    pp = phi @ p @ np.swapaxes(phi, -1, -2) + process_noise(params)
    return xp, pp


class Update(NamedTuple):
    """Result of a measurement update (all per series)."""

    x: np.ndarray           # (m, 3) updated estimate (= prediction where no update)
    p: np.ndarray           # (m, 3, 3) updated covariance
    innovation: np.ndarray  # (m,) Z - H X(k+1|k), NaN where no measurement
    innovation_var: np.ndarray  # (m,) H P(k+1|k) H^T + sigma_R^2


def update(params: CAParams, xp: np.ndarray, pp: np.ndarray, z: np.ndarray,
           accept: np.ndarray | None = None) -> Update:
    """Measurement update [seed 001, eq 7] in closed form (H = [1 0 0]).

    Args:
        xp: ``(m, 3)`` prediction; pp: ``(m, 3, 3)`` its covariance.
        z: ``(m,)`` measurement (series' unit); NaN = no measurement (prediction kept).
        accept: optional ``(m,)`` bool; False = measurement rejected (e.g. by
            :func:`trafficsim.estimation.gating.gate`), prediction kept.
    """
    s = pp[:, 0, 0] + params.sigma_meas**2
    nu = z - xp[:, 0]
    use = np.isfinite(nu)
    if accept is not None:
        use &= np.asarray(accept, dtype=bool)
    k = pp[:, :, 0] / s[:, None]  # gain P H^T S^-1, (m, 3)
    nu_used = np.where(use, nu, 0.0)
    x = xp + k * nu_used[:, None]
    # (I - K H) P: subtract K times the first row of P, only where updated
    p = pp - np.where(use[:, None, None], k[:, :, None] * pp[:, None, 0, :], 0.0)
    p = 0.5 * (p + np.swapaxes(p, -1, -2))
    return Update(x, p, nu, s)


def restart(params: CAParams, x: np.ndarray, p: np.ndarray, z: np.ndarray,
            mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Restart the position of masked series at the measurement (after a gate restart).

    A re-fix that is genuinely elsewhere says nothing about velocity and acceleration, so
    those estimates and their covariance are kept; the position becomes ``z`` with variance
    ``sigma_R^2`` and no correlation (our choice: the paper restarts only at the start of a
    record, from two fixes, see :func:`initial_state`).

    Args:
        x ``(m, 3)``, p ``(m, 3, 3)``, z ``(m,)``, mask ``(m,)`` bool.
    """
    mask = np.asarray(mask, dtype=bool) & np.isfinite(z)
    x = x.copy()
    p = p.copy()
    x[mask, 0] = z[mask]
    p[mask, 0, :] = 0.0
    p[mask, :, 0] = 0.0
    p[mask, 0, 0] = params.sigma_meas[mask] ** 2
    return x, p


class Run(NamedTuple):
    """A filtered record; sample 0 is NaN (the filter starts at sample 1)."""

    x: np.ndarray        # (m, N, 3) filtered estimates X(k)
    p: np.ndarray        # (m, N, 3, 3) their covariances P(k)
    x_pred: np.ndarray   # (m, N, 3) predictions X(k|k-1) (NaN at samples 0 and 1)
    p_pred: np.ndarray   # (m, N, 3, 3) prediction covariances P(k|k-1)
    innovation: np.ndarray      # (m, N) Z(k) - H X(k|k-1)
    innovation_var: np.ndarray  # (m, N) its variance S(k)


def run(params: CAParams, z: np.ndarray) -> Run:
    """Filter whole records (offline), vectorised over series, looping over time only.

    Args:
        z: ``(m, N)`` measurements at the period ``dt_s``; NaN = missing. Samples 0 and 1 must
            be present (they initialise the filter [seed 001, after eq 8]).
    """
    z = np.asarray(z, dtype=float)
    m, n = z.shape
    if n < 2 or not np.all(np.isfinite(z[:, :2])):
        raise ValueError("CA filter needs finite first two samples of every series")
    x = np.full((m, n, 3), np.nan)
    p = np.full((m, n, 3, 3), np.nan)
    xp = np.full((m, n, 3), np.nan)
    pp = np.full((m, n, 3, 3), np.nan)
    nu = np.full((m, n), np.nan)
    s = np.full((m, n), np.nan)
    x[:, 1], p[:, 1] = initial_state(params, z[:, 0], z[:, 1])
    for k in range(2, n):
        xp[:, k], pp[:, k] = predict(params, x[:, k - 1], p[:, k - 1])
        up = update(params, xp[:, k], pp[:, k], z[:, k])
        x[:, k], p[:, k], nu[:, k], s[:, k] = up
    return Run(x, p, xp, pp, nu, s)
