"""Extended Kalman filter on the ship model, with current estimation [seed 002, ch 4.4, 5.3, 7].

Filter state, ``x`` of shape ``(n, N_X)`` (SI, radians), one row per ship:

========  ==========================================================================
``XN``    north position of the reference point (midship), m
``XE``    east position, m
``XPSI``  heading, rad, 0 = north, clockwise, kept in [0, 2 pi)
``XU``    surge velocity relative to the water, m/s
``XV``    sway velocity relative to the water, m/s
``XR``    yaw rate, rad/s
``XCN``   current towards north, m/s (random walk: the disturbance states of [seed 002, ch 7.3])
``XCE``   current towards east, m/s
========  ==========================================================================

with covariance ``P`` of shape ``(n, N_X, N_X)``. Rudder angle and propeller speed are measured
INPUTS, not states (the thesis drives its model with the measured delta_A and n_A, "variances for
rudder angle and engine revolutions were ignored because these parameters are not estimated"
[seed 002, ch 3.4]); their measurement noise may be fed to the process noise (below).

Measurements, ``z`` of shape ``(n, N_Z)`` with a boolean validity mask of the same shape (a missing
component is simply not used): GNSS (or Decca) position north and east, compass heading, speed
log (surge through the water, "the log measures speed through the water only" [seed 002, ch 3.4]).
The measurement model is linear (H picks states 0..3), as in [seed 002, ch 7.1 (ii)].

Time update [seed 002, eqs 4.13-4.14, 5.8-5.9, 7.1]:

* the state is propagated with the SAME compiled RK4 integrator the simulation uses
  (:func:`trafficsim.ships.kernels.step_ships`, the batch form of ``base.step``), with the
  estimated current as the environment's current and the measured rudder and rps held over the
  step (zero-order hold) or driven towards known commands through the actuator lags;
* the covariance with ``P- = A P A^T + Q_d`` where ``A = expm(F dt)`` [eq 4.14] and ``Q_d`` comes
  from Van Loan's method (Van Loan 1978, "Computing integrals involving the matrix exponential",
  IEEE Trans. Autom. Control 23(3):395-404): ``expm([[-F, Q_c], [0, F^T]] dt) = [[., E12],
  [0, E22]]``, ``A = E22^T``, ``Q_d = A E12``. This is the exact discrete covariance of the
  continuous white process noise ``Q_c`` [eq 5.9] over the step, i.e. ``C N C^T`` of eq 7.1.

``F`` is the Jacobian of the ship's derivative at the current estimate (the thesis' EKF
"linearised about the most recent optimal estimate" [seed 002, ch 7.1]): kinematic rows in closed
form, acceleration rows by central finite differences of the family's own compiled
``accel(p, x, env)`` kernel (the function :func:`trafficsim.ships.base.accelerations` evaluates),
so the filter works for every model family without a hand-written Jacobian.
:func:`ship_jacobian` gives the full ``(8, 8)`` Jacobian over the ``base`` state; for the
``modular`` family it is compared with the state-dependent factorisation
:func:`trafficsim.ships.modular.linearised_F` of [seed 002, eq 4.10, appendix D] in the tests.

Matrix exponentials are computed by scaling and squaring with a Pade approximant of degree 3, 5,
7, 9 or 13 chosen from the norm (Higham 2005, "The scaling and squaring method for the matrix
exponential revisited", SIAM J. Matrix Anal. Appl. 26(4):1179-1193, algorithm 2.3 and table 2.3)
in compiled loops over the ships (:mod:`trafficsim.estimation.linalg`): :func:`expm_stack` for any
stack, and for Van Loan's matrix a
block-wise evaluation after diagonal balancing (:func:`_van_loan_one`), about a third of the work
of the 16x16 exponential. (The thesis found the plain Maclaurin series needs 50-70 terms and used
Leverrier's resolvent method instead [seed 002, ch 4.4].)

Linearisation limits: ``F`` is frozen over the step, as the thesis' filter assumes "constant
course and speed during each sample period" [seed 002, ch 7.1]. For Catfish turning with 15 deg
rudder over 1 s this puts the u, v, r rows of ``A`` several per cent off the true sensitivity of
the step (tested); on straight runs it is exact to 1e-3.

Measurement update [seed 002, eqs 5.11-5.13, E17-E19]: the Kalman gain over the valid components
only, the covariance in Joseph form ``(I - K H) P (I - K H)^T + K R K^T`` (equal to eq 5.13 for the
optimal gain, and symmetric positive semi-definite in floating point), heading innovation wrapped
to [-pi, pi). The update returns the innovations, their covariance and the NIS for gating and for
:mod:`trafficsim.estimation.adaptive`.

Process noise (continuous spectral densities ``Q_c``, diagonal): white accelerations in surge, sway
and yaw (model error), optional white position noise, and random-walk current. Measured-input
noise (rudder, rps) adds ``Gamma Sigma Gamma^T`` with ``Gamma = dt (I + A) B / 2`` (trapezoid rule
for the integral ``(A - I) F^-1 B`` of [seed 002, eq 4.15]; F is singular here), ``B`` the rudder
and rps columns of the Jacobian.

Everything is vectorised over ships: numpy for assembly, compiled loops (``trafficsim.jit.kernel``)
for the Jacobian, the matrix exponentials and the update; no Python loop over ships.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from trafficsim.estimation.linalg import (  # noqa: F401  (expm_stack, van_loan: API)
    _PADE,
    _THETA,
    _mm,
    _van_loan_one,
    expm_stack,
    van_loan,
)
from trafficsim.jit import kernel
from trafficsim.sensors import wrap_2pi
from trafficsim.ships import base, kernels
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, RUDDER, R, U, V, gather_ship

#: number of filter states and their indices (see the module docstring)
N_X = 8
XN, XE, XPSI, XU, XV, XR, XCN, XCE = range(N_X)
#: number of measurement components and their indices: GNSS north, east, compass, speed log
N_Z = 4
ZN, ZE, ZPSI, ZU = range(N_Z)
#: filter state measured by each measurement component (H is a selection matrix)
Z_STATE = (XN, XE, XPSI, XU)

_TWO_PI = 2.0 * math.pi

# Central finite differences of the accelerations: columns psi, u, v, r, rudder, rps (base state
# rows; north and east cannot enter a family's accelerations, which see no position) and current
# north, east (environment rows 0, 1: they enter only through the apparent wind).
_JAC_ROWS = np.array([PSI, U, V, R, RUDDER, RPS, -1, -2], dtype=np.int64)
#: typical magnitude of each perturbed quantity; the step is ``_FD_REL * max(|value|, scale)``
_JAC_SCALE = np.array([1.0, 1.0, 1.0, 0.01, 0.1, 1.0, 0.1, 0.1])
_FD_REL = 1e-5  # central differences: truncation ~ h^2, round-off ~ eps/h, both ~1e-10 relative


# --------------------------------------------------------------------------------------------
# parameters, model, state
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EkfParams:
    """Filter tuning per ship, ``(n,)`` float arrays in SI units (variances, spectral densities).

    Attributes:
        gnss_var_m2: variance of each GNSS position component, m2.
        compass_var_rad2: heading measurement variance, rad2.
        log_var_m2ps2: speed-log variance, (m/s)2.
        q_position, q_surge, q_sway, q_yaw, q_current: process noise spectral densities:
            white position noise m2/s, white accelerations (m/s2)2/s, (m/s2)2/s, (rad/s2)2/s,
            random-walk current (m/s)2/s.
        rudder_var_rad2, rps_var: measured-input noise variances (rad2, (rev/s)2).
        init_position_var_m2, init_heading_var_rad2, init_velocity_var_m2ps2,
        init_yaw_rate_var_rad2ps2, init_current_var_m2ps2: initial covariance diagonal.
    """

    gnss_var_m2: np.ndarray
    compass_var_rad2: np.ndarray
    log_var_m2ps2: np.ndarray
    q_position: np.ndarray
    q_surge: np.ndarray
    q_sway: np.ndarray
    q_yaw: np.ndarray
    q_current: np.ndarray
    rudder_var_rad2: np.ndarray
    rps_var: np.ndarray
    init_position_var_m2: np.ndarray
    init_heading_var_rad2: np.ndarray
    init_velocity_var_m2ps2: np.ndarray
    init_yaw_rate_var_rad2ps2: np.ndarray
    init_current_var_m2ps2: np.ndarray


#: config keys of :func:`build` and their defaults (units in the names; ``per_rthz`` = per
#: square root of hertz, the square root of a spectral density; ``per_rts`` = per root second)
DEFAULTS: Mapping[str, float] = {
    "gnss_sigma_m": 5.0,  # per axis
    "compass_sigma_deg": 1.0,
    "log_sigma_mps": 0.2,
    "position_noise_m_per_rts": 0.0,
    "surge_noise_mps2_per_rthz": 0.005,
    "sway_noise_mps2_per_rthz": 0.005,
    "yaw_noise_degps2_per_rthz": 0.05,
    "current_noise_mps_per_rts": 0.001,  # random walk: 0.06 m/s in one hour
    "rudder_noise_deg": 0.0,
    "rps_noise": 0.0,  # rev/s
    "init_position_sigma_m": 10.0,
    "init_heading_sigma_deg": 5.0,
    "init_velocity_sigma_mps": 0.5,
    "init_yaw_rate_sigma_degps": 1.0,
    "init_current_sigma_mps": 1.0,
}
#: upper bound of each key of :data:`DEFAULTS`, generous limits that keep the filter meaningful:
#: measurement noise as the instruments' bounds (:mod:`trafficsim.sensors`: 1000 m, 30 deg,
#: 5 m/s, 10 deg, 120 rpm); process noise far beyond a ship's motion (a velocity random walk of
#: 1 m/s in one second, a current changing by 6 m/s in an hour); initial uncertainty a gross
#: error (10 km), any heading, 100 kn, a fast craft's 30 deg/s turn, a 20 kn tidal race
MAXIMA: Mapping[str, float] = {
    "gnss_sigma_m": 1000,
    "compass_sigma_deg": 30,
    "log_sigma_mps": 5,
    "position_noise_m_per_rts": 10,
    "surge_noise_mps2_per_rthz": 1,
    "sway_noise_mps2_per_rthz": 1,
    "yaw_noise_degps2_per_rthz": 10,
    "current_noise_mps_per_rts": 0.1,
    "rudder_noise_deg": 10,
    "rps_noise": 2,  # rev/s, 120 rpm
    "init_position_sigma_m": 10_000,
    "init_heading_sigma_deg": 180,
    "init_velocity_sigma_mps": 50,
    "init_yaw_rate_sigma_degps": 30,
    "init_current_sigma_mps": 10,
}


def build(configs: Sequence[Mapping[str, Any]]) -> EkfParams:
    """Filter parameters from per-ship config dicts (keys and defaults: :data:`DEFAULTS`).

    Raises:
        ValueError: on an unknown key, a negative value or one beyond :data:`MAXIMA`.
    """
    for cfg in configs:
        unknown = set(cfg) - set(DEFAULTS)
        if unknown:
            raise ValueError(f"unknown EKF config keys {sorted(unknown)}; known: {list(DEFAULTS)}")

    def get(key: str) -> np.ndarray:
        out = base.stack(configs, key, DEFAULTS[key])
        if not np.all((out >= 0.0) & np.isfinite(out)):  # (NaN fails too)
            raise ValueError(f"EKF config {key!r} must be a finite number >= 0")
        if np.any(out > MAXIMA[key]):
            raise ValueError(f"EKF config {key!r} must be <= {MAXIMA[key]}, got "
                             f"{float(out.max()):g}")
        return out

    deg = math.pi / 180.0
    return EkfParams(
        gnss_var_m2=get("gnss_sigma_m") ** 2,
        compass_var_rad2=(get("compass_sigma_deg") * deg) ** 2,
        log_var_m2ps2=get("log_sigma_mps") ** 2,
        q_position=get("position_noise_m_per_rts") ** 2,
        q_surge=get("surge_noise_mps2_per_rthz") ** 2,
        q_sway=get("sway_noise_mps2_per_rthz") ** 2,
        q_yaw=(get("yaw_noise_degps2_per_rthz") * deg) ** 2,
        q_current=get("current_noise_mps_per_rts") ** 2,
        rudder_var_rad2=(get("rudder_noise_deg") * deg) ** 2,
        rps_var=get("rps_noise") ** 2,
        init_position_var_m2=get("init_position_sigma_m") ** 2,
        init_heading_var_rad2=(get("init_heading_sigma_deg") * deg) ** 2,
        init_velocity_var_m2ps2=get("init_velocity_sigma_mps") ** 2,
        init_yaw_rate_var_rad2ps2=(get("init_yaw_rate_sigma_degps") * deg) ** 2,
        init_current_var_m2ps2=get("init_current_sigma_mps") ** 2,
    )


@dataclass(frozen=True)
class ShipModel:
    """The filter's ship model: the simulation's packed tables, any mix of model families.

    Attributes:
        codes: ``(n,)`` int64 family codes (:data:`trafficsim.ships.kernels.FAMILY_CODE`).
        params: ``(n, k)`` packed family parameters (``base.pack``, zero-padded across families).
        actuators: ``(n, 6)`` actuator table (``base.actuator_table``).
        substeps_per_s: ``(n,)`` RK4 sub-steps per simulated second (``1 / max_dt_s``).
    """

    codes: np.ndarray
    params: np.ndarray
    actuators: np.ndarray
    substeps_per_s: np.ndarray

    @property
    def n(self) -> int:
        return self.codes.shape[0]

    @classmethod
    def from_family(cls, family: base.ModelFamily, params: Any, act: base.Actuators,
                    max_dt_s: float | np.ndarray = 1.0) -> ShipModel:
        """Ships of one family, as ``base.step(family, params, act, ...)`` integrates them."""
        table = base.pack(params)
        n = table.shape[0]
        return cls(codes=np.full(n, kernels.FAMILY_CODE[family.name], dtype=np.int64),
                   params=table, actuators=base.actuator_table(act),
                   substeps_per_s=np.broadcast_to(1.0 / np.asarray(max_dt_s, float), (n,)).copy())

    @classmethod
    def from_specs(cls, specs: Sequence[Mapping[str, Any]]) -> ShipModel:
        """Ships from ship-file dicts (``load_ship``), families mixed (build time only)."""
        fams = base.families()
        n = len(specs)
        codes = np.array([kernels.FAMILY_CODE[s["model"]] for s in specs], dtype=np.int64)
        tables = []
        for name, family in fams.items():  # one pass per family present
            idx = np.flatnonzero(codes == kernels.FAMILY_CODE[name])
            if idx.size:
                tables.append((idx, base.pack(family.build([specs[k] for k in idx]))))
        packed = np.zeros((n, max(t.shape[1] for _, t in tables)))
        for idx, table in tables:
            packed[idx, : table.shape[1]] = table
        max_dt = np.array([float(s.get("integration", {}).get("max_dt_s", 1.0)) for s in specs])
        return cls(codes=codes, params=packed,
                   actuators=base.actuator_table(base.Actuators.from_specs(specs)),
                   substeps_per_s=1.0 / max_dt)

    @classmethod
    def from_batch(cls, batch: Any) -> ShipModel:
        """The model of every ship of a :class:`trafficsim.batch.Batch` (shares its tables)."""
        return cls(codes=batch.family_code, params=batch.params, actuators=batch.actuators,
                   substeps_per_s=batch.substeps_per_s)


class EkfState(NamedTuple):
    """Estimate ``x (n, N_X)`` and covariance ``P (n, N_X, N_X)`` (layout: module docstring)."""

    x: np.ndarray
    P: np.ndarray


class Innovation(NamedTuple):
    """What a measurement update saw, per ship.

    Attributes:
        nu: ``(n, N_Z)`` innovations z - H x- (heading wrapped), 0 where not valid.
        S: ``(n, N_Z, N_Z)`` innovation covariance H P- H^T + R, zero rows/columns where not valid.
        hph: ``(n, N_Z, N_Z)`` the H P- H^T part of S (same masking).
        nis: ``(n,)`` normalised innovation squared nu^T S^-1 nu over the valid components.
        dof: ``(n,)`` int, number of valid components (chi-square degrees of freedom of nis);
            a component that carries no information (S singular with it) is left out of the
            update and of all of these.
    """

    nu: np.ndarray
    S: np.ndarray
    hph: np.ndarray
    nis: np.ndarray
    dof: np.ndarray


def initial_state(params: EkfParams, north_m: np.ndarray, east_m: np.ndarray,
                  heading_rad: np.ndarray, u_mps: np.ndarray, v_mps: Any = 0.0,
                  r_radps: Any = 0.0, current_north_mps: Any = 0.0,
                  current_east_mps: Any = 0.0) -> EkfState:
    """Initial estimate from first measurements or a priori values, all ``(n,)`` (or scalars).

    The covariance is diagonal with the ``init_*`` variances of ``params``.
    """
    n = params.gnss_var_m2.shape[0]
    x = np.empty((n, N_X))
    for k, value in enumerate((north_m, east_m, heading_rad, u_mps, v_mps, r_radps,
                               current_north_mps, current_east_mps)):
        x[:, k] = value
    x[:, XPSI] = wrap_2pi(x[:, XPSI])  # (np.mod alone can give 2 pi)
    P = np.zeros((n, N_X, N_X))
    diag = (params.init_position_var_m2, params.init_position_var_m2,
            params.init_heading_var_rad2, params.init_velocity_var_m2ps2,
            params.init_velocity_var_m2ps2, params.init_yaw_rate_var_rad2ps2,
            params.init_current_var_m2ps2, params.init_current_var_m2ps2)
    for k, var in enumerate(diag):
        P[:, k, k] = var
    return EkfState(x, P)


def measurement_covariance(params: EkfParams, gnss_cov_m2: np.ndarray | None = None,
                           compass_var_rad2: np.ndarray | None = None,
                           log_var_m2ps2: np.ndarray | None = None) -> np.ndarray:
    """Measurement covariance R ``(n, N_Z, N_Z)``: the configured values, or the ones given.

    Args:
        gnss_cov_m2: ``(n, 2, 2)`` north/east position covariance, m2 (e.g. the fused covariance
            of :func:`trafficsim.estimation.fusion.fuse` or an adaptive estimate).
        compass_var_rad2, log_var_m2ps2: ``(n,)`` overrides.
    """
    n = params.gnss_var_m2.shape[0]
    R = np.zeros((n, N_Z, N_Z))
    if gnss_cov_m2 is None:
        R[:, ZN, ZN] = R[:, ZE, ZE] = params.gnss_var_m2
    else:
        R[:, ZN:ZE + 1, ZN:ZE + 1] = gnss_cov_m2
    R[:, ZPSI, ZPSI] = params.compass_var_rad2 if compass_var_rad2 is None else compass_var_rad2
    R[:, ZU, ZU] = params.log_var_m2ps2 if log_var_m2ps2 is None else log_var_m2ps2
    return R


def process_noise_density(params: EkfParams) -> np.ndarray:
    """Continuous process-noise spectral density ``Q_c``, ``(n, N_X, N_X)`` diagonal."""
    n = params.gnss_var_m2.shape[0]
    Qc = np.zeros((n, N_X, N_X))
    for k, q in ((XN, params.q_position), (XE, params.q_position), (XU, params.q_surge),
                 (XV, params.q_sway), (XR, params.q_yaw), (XCN, params.q_current),
                 (XCE, params.q_current)):
        Qc[:, k, k] = q
    return Qc


# --------------------------------------------------------------------------------------------
# Jacobians
# --------------------------------------------------------------------------------------------


@kernel
def _accel_jacobian_one(code: int, p: np.ndarray, x: np.ndarray, env: np.ndarray,
                        rows: np.ndarray, scale: np.ndarray, rel: float, out: np.ndarray) -> None:
    """Central differences of ``kernels.accel`` for one ship: ``out (3, len(rows))``.

    ``rows[c] >= 0`` perturbs that base-state row of ``x``, ``-1``/``-2`` the current north/east
    entry of ``env``; both are restored.
    """
    for c in range(rows.shape[0]):
        row = rows[c]
        save = x[row] if row >= 0 else env[-row - 1]
        h = rel * max(abs(save), scale[c])
        if row >= 0:
            x[row] = save + h
        else:
            env[-row - 1] = save + h
        a1, b1, c1 = kernels.accel(code, p, x, env)
        if row >= 0:
            x[row] = save - h
        else:
            env[-row - 1] = save - h
        a2, b2, c2 = kernels.accel(code, p, x, env)
        if row >= 0:
            x[row] = save
        else:
            env[-row - 1] = save
        inv = 0.5 / h
        out[0, c] = (a1 - a2) * inv
        out[1, c] = (b1 - b2) * inv
        out[2, c] = (c1 - c2) * inv


@kernel
def _accel_jacobian(codes: np.ndarray, P: np.ndarray, X: np.ndarray, E: np.ndarray,
                    rows: np.ndarray, scale: np.ndarray, rel: float, out: np.ndarray) -> None:
    """:func:`_accel_jacobian_one` for every ship: ``out (n, 3, len(rows))``."""
    n = X.shape[1]
    x = np.empty(8)
    env = np.empty(4)
    for i in range(n):
        gather_ship(X, E, i, x, env)
        _accel_jacobian_one(codes[i], P[i], x, env, rows, scale, rel, out[i])


@kernel
def _filter_matrices(codes: np.ndarray, P: np.ndarray, X: np.ndarray, E: np.ndarray,
                     rows: np.ndarray, scale: np.ndarray, rel: float, F: np.ndarray,
                     B: np.ndarray) -> None:
    """Filter ``F (n, 8, 8)`` and input ``B (n, 8, 2)`` matrices (see :func:`filter_jacobian`).

    Filter states 0..5 are base rows 0..5 (north .. yaw rate); 6, 7 the current.
    """
    n = X.shape[1]
    x = np.empty(8)
    env = np.empty(4)
    a = np.empty((3, rows.shape[0]))
    for i in range(n):
        gather_ship(X, E, i, x, env)
        _accel_jacobian_one(codes[i], P[i], x, env, rows, scale, rel, a)
        Fi = F[i]
        Bi = B[i]
        for r in range(8):
            for c in range(8):
                Fi[r, c] = 0.0
            Bi[r, 0] = 0.0
            Bi[r, 1] = 0.0
        c, s = math.cos(x[PSI]), math.sin(x[PSI])
        u, v = x[U], x[V]
        Fi[XN, XPSI] = -u * s - v * c
        Fi[XN, XU] = c
        Fi[XN, XV] = -s
        Fi[XN, XCN] = 1.0
        Fi[XE, XPSI] = u * c - v * s
        Fi[XE, XU] = s
        Fi[XE, XV] = c
        Fi[XE, XCE] = 1.0
        Fi[XPSI, XR] = 1.0
        for q in range(3):
            for col in range(4):  # psi, u, v, r
                Fi[XU + q, XPSI + col] = a[q, col]
            Fi[XU + q, XCN] = a[q, 6]
            Fi[XU + q, XCE] = a[q, 7]
            Bi[XU + q, 0] = a[q, 4]
            Bi[XU + q, 1] = a[q, 5]


def acceleration_jacobian(model: ShipModel, x: np.ndarray, env_rows: np.ndarray) -> np.ndarray:
    """Derivatives of the body accelerations (du, dv, dr), ``(n, 3, 8)``, by central differences.

    Columns: psi, u, v, r, rudder, rps, current north, current east (units of the base state and
    m/s for the current). One compiled loop over ships evaluating the family kernel
    ``kernels.accel`` (what ``base.accelerations`` evaluates) at perturbed states.

    Args:
        model: the ships' model tables.
        x: ``(8, n)`` base state (``trafficsim.ships.base`` layout).
        env_rows: ``(4, n)`` current north/east (m/s), wind speed (m/s), wind from (rad).
    """
    n = x.shape[1]
    out = np.empty((n, 3, _JAC_ROWS.shape[0]))
    _accel_jacobian(model.codes, model.params, np.ascontiguousarray(x, dtype=float),
                    np.ascontiguousarray(env_rows, dtype=float), _JAC_ROWS, _JAC_SCALE,
                    _FD_REL, out)
    return out


def ship_jacobian(model: ShipModel, x: np.ndarray, env_rows: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Jacobian of the ship's time derivative over the ``base`` 8-state, and w.r.t. the current.

    The derivative is that of the simulation (``kernels``): kinematics with current, the family's
    accelerations, and the actuator lags at a command equal to the actual value (so the steering
    gear's rate limit is inactive): ``d rudder'/d rudder = -1/T_R``, ``d rps'/d rps = -1/T_N``
    [seed 002, eqs 4.7-4.8].

    Args:
        model: the ships' model tables.
        x: ``(8, n)`` base state.
        env_rows: ``(4, n)`` environment rows (current north, east, wind speed, wind from).

    Returns:
        ``J (n, 8, 8)`` = d f / d x in base order, ``Jc (n, 8, 2)`` = d f / d (current north, east).
    """
    a = acceleration_jacobian(model, x, env_rows)
    n = x.shape[1]
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    J = np.zeros((n, 8, 8))
    J[:, NORTH, PSI] = -x[U] * s - x[V] * c
    J[:, NORTH, U], J[:, NORTH, V] = c, -s
    J[:, EAST, PSI] = x[U] * c - x[V] * s
    J[:, EAST, U], J[:, EAST, V] = s, c
    J[:, PSI, R] = 1.0
    J[:, U:R + 1][:, :, [PSI, U, V, R, RUDDER, RPS]] = a[:, :, :6]
    J[:, RUDDER, RUDDER] = -1.0 / model.actuators[:, kernels.RUDDER_TAU]
    J[:, RPS, RPS] = -1.0 / model.actuators[:, kernels.ENGINE_TAU]
    Jc = np.zeros((n, 8, 2))
    Jc[:, NORTH, 0] = Jc[:, EAST, 1] = 1.0
    Jc[:, U:R + 1, :] = a[:, :, 6:8]
    return J, Jc


def _base_state(state_x: np.ndarray, rudder_rad: np.ndarray, rps: np.ndarray) -> np.ndarray:
    """``(8, n)`` base state from the filter state ``(n, N_X)`` and the measured inputs."""
    X = np.empty((8, state_x.shape[0]))
    X[:6] = state_x[:, :6].T
    X[RUDDER] = rudder_rad
    X[RPS] = rps
    return X


def _env_rows(state_x: np.ndarray, wind_speed_mps: Any, wind_from_rad: Any) -> np.ndarray:
    E = np.empty((4, state_x.shape[0]))
    E[0] = state_x[:, XCN]
    E[1] = state_x[:, XCE]
    E[2] = wind_speed_mps
    E[3] = wind_from_rad
    return E


def filter_jacobian(model: ShipModel, x: np.ndarray, rudder_rad: np.ndarray, rps: np.ndarray,
                    wind_speed_mps: Any = 0.0, wind_from_rad: Any = 0.0
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time filter matrices at the estimate: ``F (n, N_X, N_X)``, ``B (n, N_X, 2)``.

    ``F = d f / d x`` for the filter state (the rows of the current are zero: random walk), the
    filter-state block of :func:`ship_jacobian` plus its current columns, and ``B`` the derivative
    w.r.t. the measured inputs (rudder rad, rps rev/s). One compiled loop over ships.

    Args:
        x: ``(n, N_X)`` filter state; rudder_rad, rps: ``(n,)`` measured inputs;
        wind_speed_mps, wind_from_rad: ``(n,)`` or scalars, the wind the ship knows.
    """
    X = _base_state(x, rudder_rad, rps)
    E = _env_rows(x, wind_speed_mps, wind_from_rad)
    return _filter_matrices_of(model, X, E)


def _filter_matrices_of(model: ShipModel, X: np.ndarray, E: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    n = X.shape[1]
    F = np.empty((n, N_X, N_X))
    B = np.empty((n, N_X, 2))
    _filter_matrices(model.codes, model.params, X, E, _JAC_ROWS, _JAC_SCALE, _FD_REL, F, B)
    return F, B


@kernel
def _propagate_covariance(F: np.ndarray, Qc: np.ndarray, B: np.ndarray, Su: np.ndarray,
                          P: np.ndarray, dt: float, pade: np.ndarray, theta: np.ndarray,
                          P_out: np.ndarray, A_all: np.ndarray) -> None:
    """P_out = A P A^T + Qd + G Su G^T per ship, G = dt (I + A) B / 2 (input noise)."""
    n, k = F.shape[0], F.shape[1]
    nu = B.shape[2]
    W = np.empty((18, k, k))
    d = np.empty(k)
    piv = np.empty(k, dtype=np.int64)
    Qd = np.empty((k, k))
    T = np.empty((k, k))
    G = np.empty((k, nu))
    for i in range(n):
        A = A_all[i]
        _van_loan_one(F[i], Qc[i], dt, W, d, piv, pade, theta, A, Qd)
        _mm(A, P[i], T, 1.0, False, False)
        any_input = False
        for a in range(nu):
            if Su[i, a] > 0.0:
                any_input = True
        if any_input:
            for r in range(k):
                for a in range(nu):
                    acc = B[i, r, a]
                    for m in range(k):
                        acc += A[r, m] * B[i, m, a]
                    G[r, a] = 0.5 * dt * acc
        Po = P_out[i]
        for r in range(k):
            for c in range(r, k):
                acc = Qd[r, c]
                for m in range(k):
                    acc += T[r, m] * A[c, m]
                if any_input:
                    for a in range(nu):
                        acc += G[r, a] * Su[i, a] * G[c, a]
                Po[r, c] = acc
                Po[c, r] = acc


# --------------------------------------------------------------------------------------------
# time and measurement updates
# --------------------------------------------------------------------------------------------


def predict(params: EkfParams, model: ShipModel, state: EkfState, rudder_rad: np.ndarray,
            rps: np.ndarray, dt: float, *, wind_speed_mps: Any = 0.0, wind_from_rad: Any = 0.0,
            rudder_cmd_rad: np.ndarray | None = None, rps_cmd: np.ndarray | None = None,
            process_noise: np.ndarray | None = None) -> EkfState:
    """Time update over ``dt`` seconds [seed 002, eqs 4.13-4.14, 5.8-5.9, 7.1].

    Args:
        params: filter tuning; model: the ships' model tables (``n`` ships).
        state: estimate ``x (n, N_X)``, ``P (n, N_X, N_X)``.
        rudder_rad: ``(n,)`` measured actual rudder angle, rad (+ = starboard).
        rps: ``(n,)`` measured propeller speed, rev/s.
        dt: step, s.
        wind_speed_mps, wind_from_rad: ``(n,)`` or scalars, the wind known to the ship.
        rudder_cmd_rad, rps_cmd: ``(n,)`` commands over the step if known: the prediction then
            runs the steering gear and engine lags from the measured values towards them exactly
            as the simulation does; default: the measured values held (zero-order hold).
        process_noise: ``Q_c`` of ``params`` (:func:`process_noise_density`), to save forming
            it on every step.

    Returns:
        The predicted estimate and covariance.
    """
    x = state.x
    act = model.actuators
    rudder = np.clip(rudder_rad, -act[:, kernels.RUDDER_MAX], act[:, kernels.RUDDER_MAX])
    rps_in = np.clip(rps, act[:, kernels.RPS_MIN], act[:, kernels.RPS_MAX])
    X = _base_state(x, rudder, rps_in)
    E = _env_rows(x, wind_speed_mps, wind_from_rad)

    # covariance: linearise at the current estimate, discretise, propagate
    n = x.shape[0]
    F, B = _filter_matrices_of(model, X, E)
    Su = np.stack([params.rudder_var_rad2, params.rps_var], axis=1)
    P_new = np.empty((n, N_X, N_X))
    A = np.empty((n, N_X, N_X))  # workspace: the transition of each ship
    Qc = process_noise_density(params) if process_noise is None else process_noise
    _propagate_covariance(F, Qc, B, Su,
                          np.ascontiguousarray(state.P, dtype=float), float(dt), _PADE, _THETA,
                          P_new, A)

    # state: the simulation's own RK4 with the estimated current
    rc = rudder if rudder_cmd_rad is None else np.asarray(rudder_cmd_rad, dtype=float)
    nc = rps_in if rps_cmd is None else np.asarray(rps_cmd, dtype=float)
    substeps = np.maximum(1, np.ceil(dt * model.substeps_per_s - 1e-9)).astype(np.int64)
    kernels.step_ships(model.codes, model.params, act, X,
                       np.broadcast_to(rc, (n,)).copy(), np.broadcast_to(nc, (n,)).copy(),
                       E, float(dt), substeps)
    x_new = x.copy()
    x_new[:, :6] = X[:6].T
    return EkfState(x_new, P_new)


@kernel
def _update(x: np.ndarray, P: np.ndarray, z: np.ndarray, mask: np.ndarray, R: np.ndarray,
            zstate: np.ndarray, wrap: np.ndarray, nu_out: np.ndarray, S_out: np.ndarray,
            hph_out: np.ndarray, nis_out: np.ndarray, dof_out: np.ndarray) -> None:
    """Masked Kalman update in place for every ship (Cholesky of S, Joseph form); a valid
    component that carries no information (its pivot of S is not positive: the components
    before it, or a zero-noise instrument on an exactly known state, fix it) is left out."""
    n, k = x.shape
    nz = z.shape[1]
    idx = np.empty(nz, dtype=np.int64)
    nu = np.empty(nz)
    S = np.empty((nz, nz))
    L = np.empty((nz, nz))
    K = np.empty((k, nz))
    PHt = np.empty((k, nz))
    T = np.empty((k, k))
    w = np.empty(nz)
    for i in range(n):
        m = 0
        for j in range(nz):
            if mask[i, j]:
                idx[m] = j
                m += 1
        dof_out[i] = 0
        nis_out[i] = 0.0
        for a in range(nz):
            nu_out[i, a] = 0.0
            for b in range(nz):
                S_out[i, a, b] = 0.0
                hph_out[i, a, b] = 0.0
        # Cholesky S = L L^T; a component whose pivot is not positive is already fixed exactly
        # by the ones before it (no information): it is left out and the rest factored again
        bad = 0
        while m > 0 and bad >= 0:
            for a in range(m):
                ja = idx[a]
                sa = zstate[ja]
                d = z[i, ja] - x[i, sa]
                if wrap[ja]:
                    d = (d + math.pi) % (2.0 * math.pi) - math.pi
                nu[a] = d
                for b in range(m):
                    jb = idx[b]
                    S[a, b] = P[i, sa, zstate[jb]] + R[i, ja, jb]
                for r in range(k):
                    PHt[r, a] = P[i, r, sa]
            bad = -1
            for a in range(m):
                for b in range(a + 1):
                    acc = S[a, b]
                    for c in range(b):
                        acc -= L[a, c] * L[b, c]
                    if a == b:
                        if not acc > 0.0:
                            bad = a
                            break
                        L[a, a] = math.sqrt(acc)
                    else:
                        L[a, b] = acc / L[b, b]
                if bad >= 0:
                    break
            if bad >= 0:
                for a in range(bad, m - 1):
                    idx[a] = idx[a + 1]
                m -= 1
        if m == 0:
            continue
        # K^T = S^-1 (P H^T)^T: forward and back substitution, one column of K^T per state
        for r in range(k):
            for a in range(m):
                acc = PHt[r, a]
                for c in range(a):
                    acc -= L[a, c] * K[r, c]
                K[r, a] = acc / L[a, a]
            for a in range(m - 1, -1, -1):
                acc = K[r, a]
                for c in range(a + 1, m):
                    acc -= L[c, a] * K[r, c]
                K[r, a] = acc / L[a, a]
        # NIS with the same factor
        nis = 0.0
        for a in range(m):
            acc = nu[a]
            for c in range(a):
                acc -= L[a, c] * w[c]
            w[a] = acc / L[a, a]
            nis += w[a] * w[a]
        for a in range(m):
            ja = idx[a]
            nu_out[i, ja] = nu[a]
            for b in range(m):
                jb = idx[b]
                S_out[i, ja, jb] = S[a, b]
                hph_out[i, ja, jb] = S[a, b] - R[i, ja, jb]
        nis_out[i] = nis
        dof_out[i] = m
        # state
        for r in range(k):
            acc = 0.0
            for a in range(m):
                acc += K[r, a] * nu[a]
            x[i, r] += acc
        # Joseph form (I - K H) P (I - K H)^T + K R K^T with H a selection:
        # T = P - K P[sel, :], then T - T[:, sel] K^T, then + K R K^T
        Pi = P[i]
        for r in range(k):
            for c in range(k):
                acc = Pi[r, c]
                for a in range(m):
                    acc -= K[r, a] * Pi[zstate[idx[a]], c]
                T[r, c] = acc
        for a in range(m):  # KR = K R_sel (k x m), stored in PHt (no longer needed)
            for r in range(k):
                acc = 0.0
                for b in range(m):
                    acc += K[r, b] * R[i, idx[b], idx[a]]
                PHt[r, a] = acc
        for r in range(k):
            for c in range(r, k):
                acc = T[r, c]
                for a in range(m):
                    acc += (PHt[r, a] - T[r, zstate[idx[a]]]) * K[c, a]
                Pi[r, c] = acc
                Pi[c, r] = acc


_ZSTATE = np.array(Z_STATE, dtype=np.int64)
_WRAP = np.array([False, False, True, False])


def update(params: EkfParams, state: EkfState, z: np.ndarray, mask: np.ndarray,
           R: np.ndarray | None = None) -> tuple[EkfState, Innovation]:
    """Measurement update with the valid components [seed 002, eqs 5.11-5.13, E17-E19].

    Args:
        params: filter tuning (gives R when ``R`` is None).
        state: predicted estimate ``x (n, N_X)``, ``P (n, N_X, N_X)``.
        z: ``(n, N_Z)`` measurements: north m, east m, heading rad, speed log m/s.
        mask: ``(n, N_Z)`` bool, True where the component is valid; an all-False row leaves that
            ship's estimate unchanged (prediction only).
        R: ``(n, N_Z, N_Z)`` measurement covariance (see :func:`measurement_covariance`).

    Returns:
        The updated estimate and the :class:`Innovation` record.
    """
    if R is None:
        R = measurement_covariance(params)
    n = state.x.shape[0]
    x = state.x.copy()
    P = np.array(state.P, dtype=float, order="C")
    nu = np.empty((n, N_Z))
    S = np.empty((n, N_Z, N_Z))
    hph = np.empty((n, N_Z, N_Z))
    nis = np.empty(n)
    dof = np.empty(n, dtype=np.int64)
    _update(x, P, np.ascontiguousarray(z, dtype=float),
            np.ascontiguousarray(mask, dtype=np.bool_), np.ascontiguousarray(R, dtype=float),
            _ZSTATE, _WRAP, nu, S, hph, nis, dof)
    x[:, XPSI] = wrap_2pi(x[:, XPSI])  # (np.mod alone can give 2 pi)
    return EkfState(x, P), Innovation(nu, S, hph, nis, dof)


def state_error(x_est: np.ndarray, x_true: np.ndarray) -> np.ndarray:
    """Estimation error ``x_est - x_true`` ``(n, N_X)`` with the heading difference wrapped."""
    e = x_est - x_true
    e[:, XPSI] = (e[:, XPSI] + math.pi) % _TWO_PI - math.pi
    return e


def nees(error: np.ndarray, P: np.ndarray, components: Sequence[int] | None = None
         ) -> np.ndarray:
    """Normalised estimation error squared ``e^T P^-1 e`` per ship, ``(n,)``.

    Args:
        error: ``(n, N_X)`` (see :func:`state_error`); P: ``(n, N_X, N_X)``.
        components: the state indices to use (a marginal: the sub-block of P), default all.
    """
    if components is not None:
        idx = np.asarray(components)
        error = error[:, idx]
        P = P[:, idx[:, None], idx[None, :]]
    sol = np.linalg.solve(P, error[..., None])[..., 0]  # batched LAPACK over the stack
    return np.einsum("ni,ni->n", error, sol)


def truth_state(x_base: np.ndarray, current_north_mps: Any, current_east_mps: Any
                ) -> np.ndarray:
    """The filter-layout ``(n, N_X)`` view of a simulated ``(8, n)`` truth and its current."""
    n = x_base.shape[1]
    out = np.empty((n, N_X))
    out[:, :6] = x_base[:6].T
    out[:, XCN] = current_north_mps
    out[:, XCE] = current_east_mps
    return out
