"""Target tracker: one constant-velocity Kalman filter per observed ship (per directed pair).

Each observer keeps a track of every other ship of its encounter, fed by its radar plots
(:mod:`trafficsim.sensors.radar`) and the AIS reports it receives (:mod:`trafficsim.sensors.ais`).
Arrays are per directed pair, ``(m,)`` (:func:`trafficsim.sensors.radar.directed_pairs`).

Model. State ``x = [north, east, v_north, v_east]`` (m, m/s) in the earth frame, the constant
velocity ("PV") model driven by white acceleration noise of spectral density ``q`` (m^2/s^3) per
axis [seed 000, eqs 2-4; seed 002, sec 2.7: "a constant velocity model disturbed by a constant
acceleration between updates"]: over an interval ``d``::

    F(d) = [[I, d I], [0, I]]      Q(d) = q [[d^3/3 I, d^2/2 I], [d^2/2 I, d I]]

(seed 000 orders the state velocity first; this is the same model permuted). Predict
``x = F x``, ``P = F P F^T + Q``; update with ``K = P H^T (H P H^T + R)^-1``,
``x = x + K (z - H x)``, ``P = (I - K H) P`` [seed 002, app. E, eqs E17-E19; seed 001, eq 7],
the last written as ``P - (P H^T) S^-1 (P H^T)^T`` and kept exactly symmetric.

The constant velocity model lags a manoeuvring target [seed 000, sect. 3]; ``q`` trades
smoothing against that lag. Seed 000 tries 0.001, 0.01 and 0.1 m^2/s^3 and finds 0.01 best for
following a 100 m ship *through* its manoeuvres from 1 s DGPS fixes. A tracker of other ships
must instead predict CPA and TCPA tens of minutes ahead from 2.5 s radar plots with tens of
metres of noise, mostly of ships on steady courses, so the default is the heavier smoothing of
0.001 m^2/s^3: on the A.823(19) test scenarios (8 NM, 20 kn relative) the 95 % DCPA error after
3 min of tracking is then about 0.15 NM (0.33 NM at 0.01), while the velocity estimate follows a
manoeuvre with a time constant of roughly ``(sigma^2 T / q)^(1/4)`` = 30 s (20 s at 0.01) for
plot noise ``sigma`` = 22 m every ``T`` = 2.5 s.

Measurements (irregular intervals: the filter predicts over whatever time separates two
measurements, so scan periods, AIS intervals and missed detections need nothing special):

* radar plot: position, ``H = [I 0]``, ``R`` = the plot's converted-measurement covariance
  (:mod:`trafficsim.sensors.radar`: polar noise through the conversion Jacobian, plus own
  navigation uncertainty when given);
* AIS report: position and velocity (SOG/COG as ``v = SOG (cos COG, sin COG)``), ``H = I``,
  ``R = diag(s_p^2 + e_p^2/12 I, s_v^2 I + J diag(e_sog^2/12, (SOG e_cog)^2/12) J^T)`` with the
  assumed AIS noise ``s_p`` (``ais_sigma_position_m``), ``s_v`` (``ais_sigma_velocity_mps``), the
  quantisation steps ``e`` of the message fields (uniform rounding error, variance step^2 / 12)
  and ``J`` the rotation from along/across course to north/east.

Time stamps and latency. The track is held at the time ``t`` of the newest measurement it has
accepted. A measurement stamped ``t_r >= t`` is used in sequence (predict to ``t_r``, update).
AIS reports arrive ``latency`` after their stamp, often after radar plots newer than the stamp
have been used, so ``t_r < t`` (an out-of-sequence measurement):

* exact *reprocessing* when the late measurement is newer than the oldest of the last
  ``HISTORY`` (4) accepted measurements, which the track keeps together with the estimate just
  before each: it restarts from the estimate before the first newer measurement, predicts to
  ``t_r``, uses the late one, then uses the newer ones again in order. The result is the one
  of processing everything in time order (with the default 2 s latency and 2.5 s scans there
  is at most one newer plot). A late report older than the measurement that started the track
  restarts the track from the report and reuses the newer measurements;
* older than that: the report is *propagated forward with the model* (retrodicted measurement
  function). With ``d = t - t_r`` the state then was ``x_r = F(-d) (x - w)``, ``w`` the process
  noise over ``[t_r, t]``, so ``z = H F(-d) x + v - H F(-d) w``: the update at ``t`` uses
  ``H' = H F(-d)`` and ``R' = R + H' Q(d) H'^T``. The correlation between ``w`` and the current
  estimation error is neglected (the exact treatment is Bar-Shalom, IEEE TAES 38(3), 2002).
  Both errors contain ``w``, so the update is unbiased but over-confident where ``q d`` is not
  small against the AIS velocity variance: 13.5 s behind six plots at the default ``q``, the
  velocity variance comes out 22 % below (the position variance 12 % above) that of the exact
  result and the estimate differs from it by up to 0.4 standard deviations. The history then
  restarts, since its stored estimates lack the report.

Either way a report counts at the time its position refers to, so latency leaves no lag.
With ``latency_compensation`` off, reports are used as if stamped on arrival (what a receiver
that ignores the time stamp does): the track then lags by about ``speed * latency`` along track.

Track management:

* initiation on the first measurement of an untracked target: from a radar plot, position =
  plot, velocity 0 with standard deviation ``init_speed_sigma_mps`` per axis (one-point
  initiation); from an AIS report, state = report, ``P = R``;
* gating: a measurement whose normalised innovation squared ``nu^T S^-1 nu`` exceeds the
  chi-square quantile of ``gate_probability`` (2 or 4 degrees of freedom) is rejected and the
  track coasts on its prediction; after each rejection the window opens (threshold times
  ``1 + failures``) and after ``max_gate_failures`` consecutive rejections the track restarts from
  the measurement - the window test of [seed 002, sec 6.6] ("opening the window on an update
  which follows a failure", "test for several consecutive failures and restarted");
* deletion when no measurement has been accepted for ``coast_s`` (default 30 s, 12 scans at
  2.5 s: with detection probability 0.8 the chance of losing a present target is 0.2^12 = 4e-9
  per scan; MSC.192(79) 5.25.4.3 asks a tracker to hold targets seen in 5 of 10 scans).

Config keys (per observer ship; defaults in brackets): ``accel_psd_m2ps3`` [0.001],
``coast_s`` [30.0], ``init_speed_sigma_mps`` [10.0], ``gate_probability`` [0.9999],
``max_gate_failures`` [3], ``latency_compensation`` [true], ``ais_sigma_position_m`` [5.0],
``ais_sigma_velocity_mps`` [0.1], ``use_radar`` [true], ``use_ais`` [true].

All pairs run in one compiled loop (``@kernel``) with closed-form predictions and a Cholesky
solve of the 2x2 or 4x4 innovation covariance; no per-pair Python loop.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields

import numpy as np

from trafficsim.errors import InputError
from trafficsim.geometry import cpa
from trafficsim.jit import kernel
from trafficsim.sensors import check_keys, column, flags
from trafficsim.sensors.ais import COG_STEP_RAD, POSITION_STEP_M, SOG_STEP_MPS, AisReports
from trafficsim.sensors.radar import RadarPlots

N_STATE = 4
POS_N, POS_E, VEL_N, VEL_E = range(N_STATE)
#: accepted measurements remembered per track for exact out-of-sequence reprocessing
HISTORY = 4
DEFAULT_Q_M2PS3 = 0.001  # one of the values of [seed 000, sect. 2]; see module docstring
KEYS = ("accel_psd_m2ps3", "coast_s", "init_speed_sigma_mps", "gate_probability",
        "max_gate_failures", "latency_compensation", "ais_sigma_position_m",
        "ais_sigma_velocity_mps", "use_radar", "use_ais")


@dataclass(frozen=True)
class TrackerParams:
    """Per-observer tracker settings, ``(n,)`` arrays.

    Attributes:
        q_m2ps3: acceleration noise spectral density per axis, m^2/s^3.
        coast_s: time without accepted measurement after which a track is deleted, s.
        init_speed_sigma_mps: initial velocity standard deviation per axis (radar start), m/s.
        gate2, gate4: chi-square gate thresholds for 2 and 4 degrees of freedom.
        max_gate_failures: consecutive rejections before restarting a track (int).
        latency_compensation, use_radar, use_ais: bool switches.
        ais_sigma_position_m, ais_sigma_velocity_mps: assumed AIS noise, m and m/s.
    """

    q_m2ps3: np.ndarray
    coast_s: np.ndarray
    init_speed_sigma_mps: np.ndarray
    gate2: np.ndarray
    gate4: np.ndarray
    max_gate_failures: np.ndarray
    latency_compensation: np.ndarray
    use_radar: np.ndarray
    use_ais: np.ndarray
    ais_sigma_position_m: np.ndarray
    ais_sigma_velocity_mps: np.ndarray


@dataclass(frozen=True)
class TrackState:
    """Tracks per directed pair ``(m,)``.

    Attributes:
        x: ``(m, 4)`` state north, east (m), v_north, v_east (m/s) at time ``t_s``.
        P: ``(m, 4, 4)`` its covariance.
        t_s: ``(m,)`` time of the state = stamp of the newest accepted measurement, s.
        active: ``(m,)`` bool, the target is tracked.
        gate_failures: ``(m,)`` int consecutive gate rejections.
        n_updates: ``(m,)`` int accepted measurements since initiation.
        hist_n: ``(m,)`` int, measurements in the history (at most ``HISTORY``).
        hist_t, hist_dim, hist_z, hist_R: ``(m, HISTORY)``, ``(m, HISTORY)`` int,
            ``(m, HISTORY, 4)``, ``(m, HISTORY, 4, 4)``: the newest accepted measurements, oldest
            first: time stamp, dimension (2 position, 4 full state), value and covariance
            (zero-padded to 4).
        pre_x, pre_P, pre_t: ``(m, HISTORY, 4)``, ``(m, HISTORY, 4, 4)``, ``(m, HISTORY)``: the
            estimate just before each of them and its time (NaN time: that measurement
            started the track). Used to reprocess late measurements exactly.
    """

    x: np.ndarray
    P: np.ndarray
    t_s: np.ndarray
    active: np.ndarray
    gate_failures: np.ndarray
    n_updates: np.ndarray
    hist_n: np.ndarray
    hist_t: np.ndarray
    hist_dim: np.ndarray
    hist_z: np.ndarray
    hist_R: np.ndarray
    pre_x: np.ndarray
    pre_P: np.ndarray
    pre_t: np.ndarray

    def copy(self) -> TrackState:
        return TrackState(*(getattr(self, f.name).copy() for f in fields(self)))


def chi2_quantile_even(p: float, dof: int) -> float:
    """Quantile of the chi-square distribution with an even number of degrees of freedom.

    Uses the closed-form survival function ``exp(-x/2) sum_{j < dof/2} (x/2)^j / j!`` and
    bisection (build time only).
    """
    if dof % 2 or dof <= 0:
        raise ValueError("dof must be a positive even number")

    def survival(x: float) -> float:
        h = 0.5 * x
        return math.exp(-h) * sum(h**j / math.factorial(j) for j in range(dof // 2))

    lo, hi = 0.0, 1.0
    while survival(hi) > 1.0 - p:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if survival(mid) > 1.0 - p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def build(configs: Sequence[Mapping]) -> TrackerParams:
    """Tracker settings from per-observer config dicts (keys and defaults: module docstring)."""
    what = "tracker"
    check_keys(configs, KEYS, what)
    p_gate = column(configs, "gate_probability", 0.9999, what, minimum=0.0, strictly=True)
    if np.any(p_gate >= 1.0):
        raise InputError("gate_probability must be < 1", key=f"{what}.gate_probability")
    fails = column(configs, "max_gate_failures", 3, what, minimum=1.0)
    if np.any(fails != np.round(fails)):
        raise InputError("max_gate_failures must be an integer", key=f"{what}.max_gate_failures")
    return TrackerParams(
        q_m2ps3=column(configs, "accel_psd_m2ps3", DEFAULT_Q_M2PS3, what, minimum=0.0),
        coast_s=column(configs, "coast_s", 30.0, what, minimum=0.0, strictly=True),
        init_speed_sigma_mps=column(configs, "init_speed_sigma_mps", 10.0, what, minimum=0.0,
                                    strictly=True),
        gate2=np.array([chi2_quantile_even(p, 2) for p in p_gate]),
        gate4=np.array([chi2_quantile_even(p, 4) for p in p_gate]),
        max_gate_failures=fails.astype(np.int64),
        latency_compensation=flags(configs, "latency_compensation", what),
        use_radar=flags(configs, "use_radar", what),
        use_ais=flags(configs, "use_ais", what),
        ais_sigma_position_m=column(configs, "ais_sigma_position_m", 5.0, what, minimum=0.0),
        ais_sigma_velocity_mps=column(configs, "ais_sigma_velocity_mps", 0.1, what,
                                      minimum=0.0),
    )


def init(n_pairs: int) -> TrackState:
    """No target tracked yet, for ``n_pairs`` directed pairs."""
    m, h = int(n_pairs), HISTORY
    return TrackState(
        x=np.full((m, N_STATE), np.nan), P=np.full((m, N_STATE, N_STATE), np.nan),
        t_s=np.full(m, np.nan), active=np.zeros(m, dtype=bool),
        gate_failures=np.zeros(m, dtype=np.int64), n_updates=np.zeros(m, dtype=np.int64),
        hist_n=np.zeros(m, dtype=np.int64), hist_t=np.full((m, h), np.nan),
        hist_dim=np.zeros((m, h), dtype=np.int64), hist_z=np.zeros((m, h, N_STATE)),
        hist_R=np.zeros((m, h, N_STATE, N_STATE)), pre_x=np.full((m, h, N_STATE), np.nan),
        pre_P=np.full((m, h, N_STATE, N_STATE), np.nan), pre_t=np.full((m, h), np.nan))


def ais_measurement(reports: AisReports, sigma_position_m: np.ndarray,
                    sigma_velocity_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """AIS reports as measurements of the full state.

    Args:
        reports: ``(m,)`` received reports.
        sigma_position_m, sigma_velocity_mps: ``(m,)`` assumed noise of position (per axis) and
            of the ground velocity behind SOG/COG (per axis).

    Returns: ``z`` ``(m, 4)`` (north, east, v_north, v_east) and ``R`` ``(m, 4, 4)`` (module
    docstring), NaN rows where no report was received.
    """
    sog, cog = reports.sog_mps, reports.cog_rad
    c, s = np.cos(cog), np.sin(cog)
    z = np.stack([reports.north_m, reports.east_m, sog * c, sog * s], axis=1)
    m = z.shape[0]
    R = np.zeros((m, N_STATE, N_STATE))
    var_p = sigma_position_m**2 + POSITION_STEP_M**2 / 12.0
    R[:, 0, 0] = R[:, 1, 1] = var_p
    var_v = sigma_velocity_mps**2
    along = SOG_STEP_MPS**2 / 12.0
    across = (sog * COG_STEP_RAD) ** 2 / 12.0
    R[:, 2, 2] = var_v + c * c * along + s * s * across
    R[:, 3, 3] = var_v + s * s * along + c * c * across
    R[:, 2, 3] = R[:, 3, 2] = c * s * (along - across)
    R[~reports.valid] = np.nan
    return z, R


def step(params: TrackerParams, state: TrackState, obs: np.ndarray, t_s: float,
         radar: RadarPlots | None = None, ais: AisReports | None = None,
         inplace: bool = False) -> TrackState:
    """Use this step's radar plots and AIS reports, start and delete tracks.

    Args:
        params: ``(n,)`` tracker settings of the observers.
        state: tracks ``(m,)``.
        obs: ``(m,)`` int observer ship of each directed pair.
        t_s: time of this step, s (plots are stamped now; AIS reports carry their own stamp).
        radar: this step's plots, or None.
        ais: this step's received reports, or None.
        inplace: update ``state`` itself instead of a copy (the engine's step path).

    Returns: the new tracks (each held at the time of its newest measurement; use
    :func:`predict` for the state at another time).
    """
    m = obs.shape[0]
    t_s = float(t_s)
    if radar is not None:
        r_valid = radar.valid & params.use_radar[obs]
        r_t = np.full(m, radar.t_s)
        r_z = np.stack([radar.north_m, radar.east_m], axis=1)
        r_R = radar.cov
    else:
        r_valid, r_t = np.zeros(m, dtype=bool), np.full(m, t_s)
        r_z, r_R = np.zeros((m, 2)), np.zeros((m, 2, 2))
    if ais is not None:
        a_valid = ais.valid & params.use_ais[obs]
        a_t = np.where(params.latency_compensation[obs], ais.stamp_s, t_s)
        a_z, a_R = ais_measurement(ais, params.ais_sigma_position_m[obs],
                                   params.ais_sigma_velocity_mps[obs])
    else:
        a_valid, a_t = np.zeros(m, dtype=bool), np.full(m, t_s)
        a_z, a_R = np.zeros((m, 4)), np.zeros((m, 4, 4))

    new = state if inplace else state.copy()

    def c(a: np.ndarray, dtype: type = float) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=dtype)

    _step_kernel(new.x, new.P, new.t_s, new.active, new.gate_failures, new.n_updates,
                 new.hist_n, new.hist_t, new.hist_dim, new.hist_z, new.hist_R, new.pre_x,
                 new.pre_P, new.pre_t,
                 c(params.q_m2ps3[obs]), c(params.coast_s[obs]),
                 c(params.init_speed_sigma_mps[obs]), c(params.gate2[obs]), c(params.gate4[obs]),
                 c(params.max_gate_failures[obs], np.int64), t_s,
                 c(r_valid, bool), c(r_t), c(r_z), c(r_R), c(a_valid, bool), c(a_t), c(a_z),
                 c(a_R))
    return new


def predict(params: TrackerParams, state: TrackState, obs: np.ndarray, t_s: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """Track states and covariances predicted to time ``t_s`` (NaN for untracked pairs).

    ``t_s`` should not be earlier than the tracks' times ``state.t_s`` (the current step time
    never is: no measurement is stamped after it).

    Returns: ``x`` ``(m, 4)`` and ``P`` ``(m, 4, 4)``.
    """
    d = float(t_s) - state.t_s
    q = params.q_m2ps3[obs]
    x = state.x.copy()
    x[:, :2] += d[:, None] * state.x[:, 2:]
    P = state.P.copy()
    P[:, :2, :] += d[:, None, None] * P[:, 2:, :]
    P[:, :, :2] += d[:, None, None] * P[:, :, 2:]
    q3, q2, q1 = q * d**3 / 3.0, q * d**2 / 2.0, q * d
    for a in range(2):
        P[:, a, a] += q3
        P[:, a, a + 2] += q2
        P[:, a + 2, a] += q2
        P[:, a + 2, a + 2] += q1
    x[~state.active] = np.nan
    P[~state.active] = np.nan
    return x, P


def cpa_from_tracks(x_track: np.ndarray, own_north_m: np.ndarray, own_east_m: np.ndarray,
                    own_vn_mps: np.ndarray, own_ve_mps: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """DCPA (m) and TCPA (s) of each tracked target from the observer's own estimated motion.

    Args:
        x_track: ``(m, 4)`` track states at the current time (:func:`predict`).
        own_north_m, own_east_m, own_vn_mps, own_ve_mps: ``(m,)`` observer's own estimated
            position and ground velocity (gather the ``(n,)`` own estimates with ``obs``).
    """
    return cpa(x_track[:, 0] - own_north_m, x_track[:, 1] - own_east_m,
               x_track[:, 2] - own_vn_mps, x_track[:, 3] - own_ve_mps)


# ---------------------------------------------------------------- compiled per-pair filter

#: how a measurement is used (see :func:`_use`)
IN_SEQUENCE, REPROCESS, RESTART, FORWARD = range(4)


@kernel
def _predict_inplace(x: np.ndarray, P: np.ndarray, d: float, q: float) -> None:
    """x = F(d) x, P = F P F^T + Q(d) for the 4-state constant-velocity model."""
    x[0] += d * x[2]
    x[1] += d * x[3]
    for j in range(4):
        P[0, j] += d * P[2, j]
        P[1, j] += d * P[3, j]
    for i in range(4):
        P[i, 0] += d * P[i, 2]
        P[i, 1] += d * P[i, 3]
    q3, q2, q1 = q * d * d * d / 3.0, q * d * d / 2.0, q * d
    for a in range(2):
        P[a, a] += q3
        P[a, a + 2] += q2
        P[a + 2, a] += q2
        P[a + 2, a + 2] += q1


@kernel
def _cholesky(S: np.ndarray, dim: int, L: np.ndarray) -> bool:
    """Lower Cholesky factor of the leading ``dim x dim`` block; False if not positive."""
    for i in range(dim):
        for j in range(i + 1):
            acc = S[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            if i == j:
                if acc <= 0.0:
                    return False
                L[i, i] = math.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
    return True


@kernel
def _solve(L: np.ndarray, dim: int, b: np.ndarray, out: np.ndarray) -> None:
    """Solve ``L L^T out = b`` (leading ``dim`` entries)."""
    for i in range(dim):
        acc = b[i]
        for k in range(i):
            acc -= L[i, k] * out[k]
        out[i] = acc / L[i, i]
    for i in range(dim - 1, -1, -1):
        acc = out[i]
        for k in range(i + 1, dim):
            acc -= L[k, i] * out[k]
        out[i] = acc / L[i, i]


@kernel
def _start(x: np.ndarray, P: np.ndarray, dim: int, z: np.ndarray, Rm: np.ndarray,
           sv0: float) -> None:
    """Track initiation from one measurement (position or full state)."""
    for i in range(4):
        x[i] = 0.0
        for j in range(4):
            P[i, j] = 0.0
    for i in range(dim):
        x[i] = z[i]
        for j in range(dim):
            P[i, j] = Rm[i, j]
    if dim == 2:
        P[2, 2] = sv0 * sv0
        P[3, 3] = sv0 * sv0


@kernel
def _update(x: np.ndarray, P: np.ndarray, dim: int, lag: float, q: float, z: np.ndarray,
            Rm: np.ndarray, gate: float) -> bool:
    """Kalman update of ``x, P`` (in place, only if accepted) with the first ``dim`` states
    measured; ``lag > 0`` uses the measurement as stamped ``lag`` s before the state's time
    (``H' = H F(-lag)``, ``R' = R + H' Q(lag) H'^T``). Returns False when the normalised
    innovation squared exceeds ``gate`` (or ``S`` is not positive definite).

    ``H' Q(lag) H'^T`` is ``Q(lag)`` with its position-velocity terms negated
    (``q lag^3/3``, ``-q lag^2/2``, ``q lag`` per axis), written out rather than multiplied.
    """
    # H' x and P H'^T: row i of H' is e_i, minus lag e_(i+2) for the positions
    hx = np.empty(4)
    pht = np.empty((4, 4))
    for i in range(dim):
        hx[i] = x[i] - lag * x[i + 2] if i < 2 else x[i]
        for r in range(4):
            pht[r, i] = P[r, i] - lag * P[r, i + 2] if i < 2 else P[r, i]
    S = np.empty((4, 4))
    for i in range(dim):
        for j in range(dim):
            hph = pht[i, j] - lag * pht[i + 2, j] if i < 2 else pht[i, j]
            S[i, j] = hph + Rm[i, j]
    if lag > 0.0:
        for a in range(2):
            S[a, a] += q * lag**3 / 3.0
            if dim == 4:
                S[a, a + 2] -= 0.5 * q * lag**2
                S[a + 2, a] -= 0.5 * q * lag**2
                S[a + 2, a + 2] += q * lag
    L = np.zeros((4, 4))
    if not _cholesky(S, dim, L):
        return False
    nu = np.empty(4)
    for i in range(dim):
        nu[i] = z[i] - hx[i]
    w = np.empty(4)
    _solve(L, dim, nu, w)
    nis = 0.0
    for i in range(dim):
        nis += nu[i] * w[i]
    if nis > gate:
        return False
    # x += P H'^T S^-1 nu;  P -= (P H'^T) S^-1 (P H'^T)^T, row by row
    K = np.empty((4, 4))
    row = np.empty(4)
    sol = np.empty(4)
    for r in range(4):
        for j in range(dim):
            row[j] = pht[r, j]
        _solve(L, dim, row, sol)
        for j in range(dim):
            K[r, j] = sol[j]
    for r in range(4):
        acc = 0.0
        for j in range(dim):
            acc += pht[r, j] * w[j]
        x[r] += acc
    for r in range(4):
        for c in range(r, 4):
            acc = P[r, c]
            for j in range(dim):
                acc -= K[r, j] * pht[c, j]
            P[r, c] = acc
    for r in range(4):  # keep P exactly symmetric
        for c in range(r):
            P[r, c] = P[c, r]
    return True


@kernel
def _copy(src_x: np.ndarray, src_P: np.ndarray, dst_x: np.ndarray, dst_P: np.ndarray) -> None:
    """dst = src for a state and its covariance (explicit loops compile much faster than
    slice assignment)."""
    for i in range(4):
        dst_x[i] = src_x[i]
        for j in range(4):
            dst_P[i, j] = src_P[i, j]


@kernel
def _make_room(k: int, j: int, hist_n: np.ndarray, hist_t: np.ndarray, hist_dim: np.ndarray,
               hist_z: np.ndarray, hist_R: np.ndarray, pre_x: np.ndarray, pre_P: np.ndarray,
               pre_t: np.ndarray) -> int:
    """Open slot ``j`` of pair ``k``'s history (slots ``j..`` move up one; a full history first
    drops its oldest entry). Returns the slot to write, or -1 when the history is full and the
    new entry would be the oldest (it is then not kept: the estimates after it contain it).
    The new slot still holds the old slot ``j``'s pre-estimate."""
    n = hist_n[k]
    if n == hist_t.shape[1]:
        if j == 0:
            return -1
        for s in range(n - 1):  # drop the oldest
            hist_t[k, s], hist_dim[k, s], pre_t[k, s] = (hist_t[k, s + 1], hist_dim[k, s + 1],
                                                         pre_t[k, s + 1])
            _copy(hist_z[k, s + 1], hist_R[k, s + 1], hist_z[k, s], hist_R[k, s])
            _copy(pre_x[k, s + 1], pre_P[k, s + 1], pre_x[k, s], pre_P[k, s])
        n -= 1
        j -= 1
    for s in range(n, j, -1):
        hist_t[k, s], hist_dim[k, s], pre_t[k, s] = (hist_t[k, s - 1], hist_dim[k, s - 1],
                                                     pre_t[k, s - 1])
        _copy(hist_z[k, s - 1], hist_R[k, s - 1], hist_z[k, s], hist_R[k, s])
        _copy(pre_x[k, s - 1], pre_P[k, s - 1], pre_x[k, s], pre_P[k, s])
    hist_n[k] = n + 1
    return j


@kernel
def _write(k: int, j: int, tm: float, dim: int, z: np.ndarray, Rm: np.ndarray,
           hist_t: np.ndarray, hist_dim: np.ndarray, hist_z: np.ndarray,
           hist_R: np.ndarray) -> None:
    """Store a measurement (zero-padded to 4) in slot ``j`` of pair ``k``'s history."""
    hist_t[k, j], hist_dim[k, j] = tm, dim
    for a in range(4):
        hist_z[k, j, a] = z[a] if a < dim else 0.0
        for b in range(4):
            hist_R[k, j, a, b] = Rm[a, b] if (a < dim and b < dim) else 0.0


@kernel
def _use(k: int, dim: int, tm: float, z: np.ndarray, Rm: np.ndarray, x: np.ndarray,
         P: np.ndarray, t_state: np.ndarray, active: np.ndarray, fails: np.ndarray,
         n_upd: np.ndarray, hist_n: np.ndarray, hist_t: np.ndarray, hist_dim: np.ndarray,
         hist_z: np.ndarray, hist_R: np.ndarray, pre_x: np.ndarray, pre_P: np.ndarray,
         pre_t: np.ndarray, q: float, sv0: float, gate: float, max_fail: int) -> None:
    """Use one measurement (``dim`` 2: position, 4: full state) stamped ``tm`` on pair ``k``.

    Cases: in sequence (predict, update); late, with the estimate before the newer
    measurements in the history (restart from it, update, use the newer ones again: exact);
    late, older than the track itself (start from it, use the newer ones again: exact); late
    beyond the history (forward propagation, approximate). One update call site for the new
    measurement (compile time grows with every inlined copy).
    """
    xk, Pk = x[k], P[k]
    xw, Pw = np.empty(4), np.empty((4, 4))
    n = hist_n[k]
    lag = 0.0
    j = n
    t_w = tm
    if not active[k]:
        case = RESTART
    elif tm >= t_state[k]:
        case = IN_SEQUENCE
        _copy(xk, Pk, xw, Pw)
        _predict_inplace(xw, Pw, tm - t_state[k], q)
    else:
        j = 0
        while j < n and hist_t[k, j] <= tm:
            j += 1
        if j < n and math.isnan(pre_t[k, j]):
            case = RESTART
        elif j < n and pre_t[k, j] <= tm:
            case = REPROCESS
            _copy(pre_x[k, j], pre_P[k, j], xw, Pw)
            _predict_inplace(xw, Pw, tm - pre_t[k, j], q)
        else:
            case = FORWARD
            _copy(xk, Pk, xw, Pw)
            lag = t_state[k] - tm
    if case == RESTART:
        _start(xw, Pw, dim, z, Rm, sv0)
        accepted = True
    else:  # the window opens after each failure [seed 002, sec 6.6]
        accepted = _update(xw, Pw, dim, lag, q, z, Rm, gate * (1.0 + fails[k]))
    if not accepted:
        fails[k] += 1
        if fails[k] < max_fail:
            return
        active[k] = False  # restart the track from the measurement [seed 002, sec 6.6]
        _start(xw, Pw, dim, z, Rm, sv0)
        case = RESTART
    if not active[k]:  # a new track
        hist_n[k] = 0
        j = 0
        t_state[k] = tm
        active[k], n_upd[k] = True, 0
    if case == FORWARD:
        hist_n[k] = 0  # the stored estimates lack this measurement: start the history anew
    else:
        slot = _make_room(k, j, hist_n, hist_t, hist_dim, hist_z, hist_R, pre_x, pre_P, pre_t)
        if slot >= 0:
            _write(k, slot, tm, dim, z, Rm, hist_t, hist_dim, hist_z, hist_R)
            if case == IN_SEQUENCE:
                _copy(xk, Pk, pre_x[k, slot], pre_P[k, slot])
                pre_t[k, slot] = t_state[k]
                t_state[k] = tm
            elif case == RESTART and slot == 0:
                pre_t[k, 0] = math.nan
        # use the newer measurements again, in order, from the new estimate
        for s in range(slot + 1, hist_n[k]):
            _copy(xw, Pw, pre_x[k, s], pre_P[k, s])
            pre_t[k, s] = t_w
            _predict_inplace(xw, Pw, hist_t[k, s] - t_w, q)
            _update(xw, Pw, hist_dim[k, s], 0.0, q, hist_z[k, s], hist_R[k, s], math.inf)
            t_w = hist_t[k, s]
    _copy(xw, Pw, xk, Pk)
    fails[k] = 0
    n_upd[k] += 1


@kernel
def _step_kernel(x: np.ndarray, P: np.ndarray, t_state: np.ndarray, active: np.ndarray,
                 fails: np.ndarray, n_upd: np.ndarray, hist_n: np.ndarray, hist_t: np.ndarray,
                 hist_dim: np.ndarray, hist_z: np.ndarray, hist_R: np.ndarray,
                 pre_x: np.ndarray, pre_P: np.ndarray, pre_t: np.ndarray, q: np.ndarray,
                 coast: np.ndarray, sv0: np.ndarray, gate2: np.ndarray, gate4: np.ndarray,
                 max_fail: np.ndarray, t_now: float, r_valid: np.ndarray, r_t: np.ndarray,
                 r_z: np.ndarray, r_R: np.ndarray, a_valid: np.ndarray, a_t: np.ndarray,
                 a_z: np.ndarray, a_R: np.ndarray) -> None:
    for k in range(x.shape[0]):
        # older stamp first, so that in-sequence use is the rule
        ais_first = a_valid[k] and (not r_valid[k] or a_t[k] <= r_t[k])
        for which in range(2):
            use_ais = a_valid[k] and ((which == 0) == ais_first)
            use_radar = r_valid[k] and ((which == 1) == ais_first)
            if use_ais:
                dim, tm, z, Rm, gate = 4, a_t[k], a_z[k], a_R[k], gate4[k]
            elif use_radar:
                dim, tm, z, Rm, gate = 2, r_t[k], r_z[k], r_R[k], gate2[k]
            else:
                continue
            _use(k, dim, tm, z, Rm, x, P, t_state, active, fails, n_upd, hist_n, hist_t,
                 hist_dim, hist_z, hist_R, pre_x, pre_P, pre_t, q[k], sv0[k], gate, max_fail[k])
        if active[k] and t_now - t_state[k] > coast[k]:
            active[k] = False
            fails[k] = 0
            n_upd[k] = 0
