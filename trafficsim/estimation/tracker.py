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
  per scan; MSC.192(79) 5.25.4.3 asks a tracker to hold targets seen in 5 of 10 scans). The
  time counts from the step that accepted the newest measurement, not from its stamp: a
  tracker can only miss what has not arrived, so an AIS-only track is kept whenever reports
  arrive more often than ``coast_s``, however old their stamps.

Config keys (per observer ship; defaults in brackets): ``accel_psd_m2ps3`` [0.001],
``coast_s`` [30.0], ``init_speed_sigma_mps`` [10.0], ``gate_probability`` [0.9999],
``max_gate_failures`` [3], ``latency_compensation`` [true], ``ais_sigma_position_m`` [5.0],
``ais_sigma_velocity_mps`` [0.1], ``use_radar`` [true], ``use_ais`` [true].

Upper bounds that keep the filter meaningful: ``accel_psd_m2ps3`` at most 10 m^2/s^3 (a hundred
times the largest of seed 000's tries, 0.1 [seed 000, sect. 2]: a white acceleration of some
3 m/s^2 rms over a second, beyond any ship, and a velocity that merely differences the plots),
``coast_s`` at most one hour (an AIS-only track of a ship at anchor hears a report every 3 min;
an hour-old track is no picture of a ship), ``init_speed_sigma_mps`` at most 50 m/s (about
100 kn), and the assumed AIS noise as bounded in :mod:`trafficsim.sensors.ais`.

All pairs run in one compiled loop (``@kernel``) with closed-form predictions; ``S^-1`` comes in
closed form for a radar plot (2x2) and by 2x2 blocks for an AIS report (4x4, a Schur complement
solve: no explicit 4x4 inverse, which loses accuracy when position and velocity are strongly
correlated); covariances are kept exactly symmetric. There is no per-pair Python loop. The loop
reads the radar plots and AIS reports as they come (the AIS measurement is formed inside it) and the
observers' settings from a table of the distinct settings and a row number per pair, gathered once
(:func:`pair_settings`; a campaign's ships share a few rows, which stay in cache); a pair without a
measurement costs a few tests. The history is a ring buffer of fixed-size records, so accepting a
measurement writes one record instead of moving the whole history, and the loop prefetches the track
and the records a pair will touch a few pairs ahead (the history does not fit in cache). A
measurement goes into the history only while a report stamped before it is on its way to the
observer (:attr:`AisReports.in_flight_s`, passed to :func:`step`), the one case in which it can be
used again; otherwise the history is emptied, since no later measurement can be stamped before it.
With 2 s latency and reports every 2-10 s that leaves most plots unrecorded, and the tracks are the
same to the bit as with every measurement recorded (tested).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields

import numpy as np

from trafficsim.errors import InputError
from trafficsim.geometry import cos_sin, cpa
from trafficsim.jit import kernel, prefetch
from trafficsim.sensors import check_keys, column, flags
from trafficsim.sensors.ais import (
    COG_STEP_RAD,
    MAX_SIGMA_POSITION_M,
    MAX_SIGMA_VELOCITY_MPS,
    POSITION_STEP_M,
    SOG_STEP_MPS,
    AisReports,
)
from trafficsim.sensors.radar import RadarPlots

N_STATE = 4
POS_N, POS_E, VEL_N, VEL_E = range(N_STATE)
#: accepted measurements remembered per track for exact out-of-sequence reprocessing
HISTORY = 4
DEFAULT_Q_M2PS3 = 0.001  # one of the values of [seed 000, sect. 2]; see module docstring
MAX_Q_M2PS3 = 10  # a hundred times the largest of [seed 000, sect. 2]
MAX_COAST_S = 3600  # an hour: a track that old is no picture of a ship
MAX_INIT_SPEED_SIGMA_MPS = 50  # about 100 kn
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
        heard_s: ``(m,)`` time of the step that accepted the newest measurement, s (coasting
            counts from it).
        active: ``(m,)`` bool, the target is tracked.
        gate_failures: ``(m,)`` int consecutive gate rejections.
        n_updates: ``(m,)`` int accepted measurements since initiation.
        hist_n: ``(m,)`` int, measurements in the history (at most ``HISTORY``).
        hist_start: ``(m,)`` int, row of ``hist`` holding the oldest of them.
        hist: ``(m, HISTORY, H_SIZE)`` ring buffer of the newest accepted measurements: the
            ``s``-th oldest is row ``(hist_start + s) % HISTORY``. A row holds (offsets
            ``H_*``) the time stamp, the dimension (2 position, 4 full state), the value (4)
            and the lower triangle of the covariance (packed row by row; the leading ``dim``
            block is used), then the time of the estimate just before it (NaN: it started the
            track) and that estimate (4, and the upper triangle of its covariance packed row by
            row). Used to reprocess late measurements exactly.
    """

    x: np.ndarray
    P: np.ndarray
    t_s: np.ndarray
    heard_s: np.ndarray
    active: np.ndarray
    gate_failures: np.ndarray
    n_updates: np.ndarray
    hist_n: np.ndarray
    hist_start: np.ndarray
    hist: np.ndarray

    def copy(self) -> TrackState:
        return TrackState(*(getattr(self, f.name).copy() for f in fields(self)))


@functools.lru_cache(maxsize=256)
def chi2_quantile_even(p: float, dof: int) -> float:
    """Quantile of the chi-square distribution with an even number of degrees of freedom.

    Uses the closed-form survival function ``exp(-x/2) sum_{j < dof/2} (x/2)^j / j!`` and
    bisection (build time only; remembered, since every ship of a batch asks the same).
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
        q_m2ps3=column(configs, "accel_psd_m2ps3", DEFAULT_Q_M2PS3, what, minimum=0.0,
                       maximum=MAX_Q_M2PS3),
        coast_s=column(configs, "coast_s", 30.0, what, minimum=0.0, strictly=True,
                       maximum=MAX_COAST_S),
        init_speed_sigma_mps=column(configs, "init_speed_sigma_mps", 10.0, what, minimum=0.0,
                                    strictly=True, maximum=MAX_INIT_SPEED_SIGMA_MPS),
        gate2=np.array([chi2_quantile_even(p, 2) for p in p_gate]),
        gate4=np.array([chi2_quantile_even(p, 4) for p in p_gate]),
        max_gate_failures=fails.astype(np.int64),
        latency_compensation=flags(configs, "latency_compensation", what),
        use_radar=flags(configs, "use_radar", what),
        use_ais=flags(configs, "use_ais", what),
        ais_sigma_position_m=column(configs, "ais_sigma_position_m", 5.0, what, minimum=0.0,
                                    maximum=MAX_SIGMA_POSITION_M),
        ais_sigma_velocity_mps=column(configs, "ais_sigma_velocity_mps", 0.1, what,
                                      minimum=0.0, maximum=MAX_SIGMA_VELOCITY_MPS),
    )


def init(n_pairs: int) -> TrackState:
    """No target tracked yet, for ``n_pairs`` directed pairs."""
    m = int(n_pairs)
    return TrackState(
        x=np.full((m, N_STATE), np.nan), P=np.full((m, N_STATE, N_STATE), np.nan),
        t_s=np.full(m, np.nan), heard_s=np.full(m, np.nan), active=np.zeros(m, dtype=bool),
        gate_failures=np.zeros(m, dtype=np.int64), n_updates=np.zeros(m, dtype=np.int64),
        hist_n=np.zeros(m, dtype=np.int64), hist_start=np.zeros(m, dtype=np.int64),
        hist=np.full((m, HISTORY, H_SIZE), np.nan))


#: columns of the per-pair settings table (:func:`pair_settings`)
(S_Q, S_COAST, S_SV0, S_GATE2, S_GATE4, S_MAX_FAIL, S_LATENCY, S_USE_RADAR, S_USE_AIS,
 S_AIS_SP, S_AIS_SV) = range(11)
N_SETTINGS = 11


def pair_settings(params: TrackerParams, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The observers' settings per directed pair: the distinct settings ``(u, N_SETTINGS)``
    float (columns ``S_*``; switches as 0/1, ``max_gate_failures`` as a whole number) and the
    row of each pair ``(m,)`` int32. Build it once for a fixed set of pairs and pass it to
    :func:`step`."""
    p = params
    cols = (p.q_m2ps3, p.coast_s, p.init_speed_sigma_mps, p.gate2, p.gate4, p.max_gate_failures,
            p.latency_compensation, p.use_radar, p.use_ais, p.ais_sigma_position_m,
            p.ais_sigma_velocity_mps)
    per_observer = np.stack([np.asarray(c, dtype=float) for c in cols], axis=1)
    table, row = np.unique(per_observer, axis=0, return_inverse=True)
    return (np.ascontiguousarray(table),
            np.ascontiguousarray(row.reshape(-1)[np.asarray(obs, dtype=np.int64)], np.int32))


#: variance of the rounding error of the AIS position (uniform over one step: step^2 / 12)
VAR_POSITION_QUANT_M2 = POSITION_STEP_M**2 / 12.0
#: variance of the rounding error of the AIS SOG (along course), (m/s)^2
VAR_SOG_QUANT_M2PS2 = SOG_STEP_MPS**2 / 12.0


def ais_measurement(reports: AisReports, sigma_position_m: np.ndarray,
                    sigma_velocity_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """AIS reports as measurements of the full state.

    Args:
        reports: ``(m,)`` received reports.
        sigma_position_m, sigma_velocity_mps: ``(m,)`` assumed noise of position (per axis) and
            of the ground velocity behind SOG/COG (per axis).

    Returns: ``z`` ``(m, 4)`` (north, east, v_north, v_east) and ``R`` ``(m, 4, 4)`` (module
    docstring; the same numbers :func:`step` forms inside its loop), NaN rows where no report
    was received.
    """
    m = reports.valid.shape[0]
    out = np.empty((m, 4 + 16))
    _ais_measurements(_c(reports.valid, bool), _c(reports.north_m), _c(reports.east_m),
                      _c(reports.sog_mps), _c(reports.cog_rad),
                      _c(np.broadcast_to(np.asarray(sigma_position_m, dtype=float), (m,))),
                      _c(np.broadcast_to(np.asarray(sigma_velocity_mps, dtype=float), (m,))), out)
    return out[:, :4].copy(), out[:, 4:].reshape(m, N_STATE, N_STATE).copy()


def _c(a: np.ndarray | float, dtype: type = float) -> np.ndarray:
    """``a`` as a C-contiguous array (one compiled specialisation for every caller)."""
    return np.ascontiguousarray(a, dtype=dtype)


_NONE_B, _NONE_F, _NONE_F3 = np.zeros(0, dtype=bool), np.zeros(0), np.zeros((0, 2, 2))


def step(params: TrackerParams, state: TrackState, obs: np.ndarray, t_s: float,
         radar: RadarPlots | None = None, ais: AisReports | None = None,
         inplace: bool = False, settings: tuple[np.ndarray, np.ndarray] | None = None,
         in_flight_s: np.ndarray | None = None) -> TrackState:
    """Use this step's radar plots and AIS reports, start and delete tracks.

    Args:
        params: ``(n,)`` tracker settings of the observers.
        state: tracks ``(m,)``.
        obs: ``(m,)`` int observer ship of each directed pair.
        t_s: time of this step, s (plots are stamped now; AIS reports carry their own stamp).
        radar: this step's plots, or None.
        ais: this step's received reports, or None.
        inplace: update ``state`` itself instead of a copy (the engine's step path).
        settings: ``pair_settings(params, obs)``, if already gathered (the engine's step path).
        in_flight_s: ``(m,)`` stamp of the oldest AIS report on its way to each observer
            (:attr:`AisReports.in_flight_s`; +inf for none): no measurement of a later step is
            stamped earlier, so the history is kept only where one can come late. None: not
            known, every accepted measurement is kept.

    Returns: the new tracks (each held at the time of its newest measurement; use
    :func:`predict` for the state at another time).
    """
    if settings is None:
        settings = pair_settings(params, obs)
    new = state if inplace else state.copy()
    if radar is not None:
        r = (True, _c(radar.valid, bool), float(radar.t_s), _c(radar.north_m), _c(radar.east_m),
             _c(radar.cov))
    else:
        r = (False, _NONE_B, 0.0, _NONE_F, _NONE_F, _NONE_F3)
    if ais is not None:
        a = (True, _c(ais.valid, bool), _c(ais.stamp_s), _c(ais.north_m), _c(ais.east_m),
             _c(ais.sog_mps), _c(ais.cog_rad))
    else:
        a = (False, _NONE_B, _NONE_F, _NONE_F, _NONE_F, _NONE_F, _NONE_F)
    fl = _NONE_F if in_flight_s is None else _c(in_flight_s)
    _step_kernel(new.x, new.P, new.t_s, new.heard_s, new.active, new.gate_failures, new.n_updates,
                 new.hist_n, new.hist_start, new.hist, *settings, float(t_s), *r, *a, fl)
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
    x = predict_state(state, t_s)
    P = state.P.copy()
    P[:, :2, :] += d[:, None, None] * P[:, 2:, :]
    P[:, :, :2] += d[:, None, None] * P[:, :, 2:]
    q3, q2, q1 = q * d**3 / 3.0, q * d**2 / 2.0, q * d
    for a in range(2):
        P[:, a, a] += q3
        P[:, a, a + 2] += q2
        P[:, a + 2, a] += q2
        P[:, a + 2, a + 2] += q1
    P[~state.active] = np.nan
    return x, P


def predict_state(state: TrackState, t_s: float) -> np.ndarray:
    """The states of :func:`predict` alone (no covariance): ``(m, 4)``, NaN for untracked
    pairs; the transpose of a C-contiguous ``(4, m)`` array (one row per state component, as
    the decision features read them)."""
    rows = np.empty((N_STATE, state.x.shape[0]))
    _predicted_rows(state.x, state.t_s, state.active, float(t_s), rows)
    return rows.T


@kernel
def _predicted_rows(x: np.ndarray, t_state: np.ndarray, active: np.ndarray, t_s: float,
                    rows: np.ndarray) -> None:
    """:func:`predict_state` into ``rows (4, m)``."""
    for k in range(x.shape[0]):
        if active[k]:
            d = t_s - t_state[k]
            rows[POS_N, k] = x[k, POS_N] + d * x[k, VEL_N]
            rows[POS_E, k] = x[k, POS_E] + d * x[k, VEL_E]
            rows[VEL_N, k], rows[VEL_E, k] = x[k, VEL_N], x[k, VEL_E]
        else:
            rows[POS_N, k] = rows[POS_E, k] = rows[VEL_N, k] = rows[VEL_E, k] = math.nan


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
# Helpers take one to three arrays: a compiled call that passes more arrays costs tens of ns
# (and is not inlined), so the working estimate and the measurement in use live in one scratch
# vector at fixed offsets; the filter arithmetic runs on local scalars.

#: how a measurement is used (see :func:`_step_kernel`)
IN_SEQUENCE, REPROCESS, RESTART, FORWARD = range(4)

#: offsets in a history record (a row of ``TrackState.hist``): the measurement (time stamp,
#: dimension, value, lower triangle of the covariance packed row by row; ``H_MEAS`` entries),
#: then the estimate before it (its time, state, upper triangle of its covariance packed row by
#: row)
H_T, H_DIM, H_Z, H_R, H_MEAS = 0, 1, 2, 6, 16
H_PRE_T, H_PRE_X, H_PRE_P = 16, 17, 21
H_SIZE = 31

#: offsets in the scratch vector: working estimate x (4) and the upper triangle of P packed row
#: by row (10: P00 P01 P02 P03 P11 P12 P13 P22 P23 P33), the measurement in use z (4) and the
#: lower triangle of R packed row by row (10)
W_X, W_P, W_Z, W_R = 0, 4, 14, 18
W_SIZE = 28

#: the loop prefetches the track and history records of the pair this many pairs ahead
PREFETCH_AHEAD = 8


@kernel
def _ais_zr(north: float, east: float, sog: float, cog: float, sp: float, sv: float,
            out: np.ndarray, o: int) -> None:
    """AIS report as a full-state measurement (module docstring): ``z`` (4) at ``out[o:]``,
    the lower triangle of ``R`` packed row by row (10) at ``out[o + 4:]``."""
    c, s = cos_sin(cog)
    out[o], out[o + 1], out[o + 2], out[o + 3] = north, east, sog * c, sog * s
    var_p = sp * sp + VAR_POSITION_QUANT_M2
    var_v = sv * sv
    along = VAR_SOG_QUANT_M2PS2
    a = sog * COG_STEP_RAD
    across = a * a / 12.0
    r = o + 4
    out[r], out[r + 1], out[r + 2] = var_p, 0.0, var_p
    out[r + 3], out[r + 4], out[r + 5] = 0.0, 0.0, var_v + c * c * along + s * s * across
    out[r + 6], out[r + 7] = 0.0, 0.0
    out[r + 8], out[r + 9] = c * s * (along - across), var_v + s * s * along + c * c * across


@kernel
def _ais_measurements(valid: np.ndarray, north: np.ndarray, east: np.ndarray, sog: np.ndarray,
                      cog: np.ndarray, sp: np.ndarray, sv: np.ndarray, out: np.ndarray) -> None:
    """:func:`_ais_zr` for every report into the rows of ``out`` ``(m, 20)`` (``z``, then ``R``
    4x4 row-major; NaN if not valid)."""
    w = np.empty(14)
    for k in range(out.shape[0]):
        if valid[k]:
            _ais_zr(north[k], east[k], sog[k], cog[k], sp[k], sv[k], w, 0)
            for i in range(4):
                out[k, i] = w[i]
                for j in range(i + 1):
                    out[k, 4 + 4 * i + j] = out[k, 4 + 4 * j + i] = w[4 + i * (i + 1) // 2 + j]
        else:
            for i in range(20):
                out[k, i] = math.nan


@kernel
def _set_P(w: np.ndarray, p00: float, p01: float, p02: float, p03: float, p11: float,
           p12: float, p13: float, p22: float, p23: float, p33: float) -> None:
    """Working covariance = the given upper triangle."""
    w[W_P], w[W_P + 1], w[W_P + 2], w[W_P + 3], w[W_P + 4] = p00, p01, p02, p03, p11
    w[W_P + 5], w[W_P + 6], w[W_P + 7], w[W_P + 8], w[W_P + 9] = p12, p13, p22, p23, p33


@kernel
def _set_predicted(w: np.ndarray, x0: float, x1: float, x2: float, x3: float, p00: float,
                   p01: float, p02: float, p03: float, p11: float, p12: float, p13: float,
                   p22: float, p23: float, p33: float, d: float, q: float) -> None:
    """Working estimate = ``x``, ``P`` (upper triangle) predicted over ``d``: ``x = F(d) x``,
    ``P = F P F^T + Q(d)``."""
    w[W_X], w[W_X + 1], w[W_X + 2], w[W_X + 3] = x0 + d * x2, x1 + d * x3, x2, x3
    a02, a03, a12, a13 = p02 + d * p22, p03 + d * p23, p12 + d * p23, p13 + d * p33
    q3, q2, q1 = q * d * d * d / 3.0, q * d * d / 2.0, q * d
    _set_P(w, p00 + d * p02 + d * a02 + q3, p01 + d * p03 + d * a12, a02 + q2, a03,
           p11 + d * p13 + d * a13 + q3, a12, a13 + q2, p22 + q1, p23, p33 + q1)


@kernel
def _predict(w: np.ndarray, d: float, q: float) -> None:
    """The working estimate predicted over ``d``."""
    _set_predicted(w, w[W_X], w[W_X + 1], w[W_X + 2], w[W_X + 3], w[W_P], w[W_P + 1],
                   w[W_P + 2], w[W_P + 3], w[W_P + 4], w[W_P + 5], w[W_P + 6], w[W_P + 7],
                   w[W_P + 8], w[W_P + 9], d, q)


@kernel
def _load_predicted(x: np.ndarray, P: np.ndarray, k: int, w: np.ndarray, d: float, q: float
                    ) -> None:
    """Working estimate = track ``k`` predicted over ``d``."""
    _set_predicted(w, x[k, 0], x[k, 1], x[k, 2], x[k, 3], P[k, 0, 0], P[k, 0, 1], P[k, 0, 2],
                   P[k, 0, 3], P[k, 1, 1], P[k, 1, 2], P[k, 1, 3], P[k, 2, 2], P[k, 2, 3],
                   P[k, 3, 3], d, q)


@kernel
def _start(w: np.ndarray, dim: int, sv0: float) -> None:
    """Track initiation from the measurement in use (position or full state; the covariance
    from the lower triangle of ``R``, so that it is symmetric)."""
    r = W_R
    if dim == 4:
        for i in range(4):
            w[W_X + i] = w[W_Z + i]
        _set_P(w, w[r], w[r + 1], w[r + 3], w[r + 6], w[r + 2], w[r + 4], w[r + 7], w[r + 5],
               w[r + 8], w[r + 9])
    else:
        w[W_X], w[W_X + 1], w[W_X + 2], w[W_X + 3] = w[W_Z], w[W_Z + 1], 0.0, 0.0
        _set_P(w, w[r], w[r + 1], 0.0, 0.0, w[r + 2], 0.0, 0.0, sv0 * sv0, 0.0, sv0 * sv0)


@kernel
def _update2(w: np.ndarray, lag: float, q: float, gate: float) -> bool:
    """Kalman update of the working estimate with a position measurement (``H = [I 0]``; the
    rest as :func:`_update4`). ``S^-1 = adj(S) / det(S)``."""
    p00, p01, p02, p03, p11 = w[W_P], w[W_P + 1], w[W_P + 2], w[W_P + 3], w[W_P + 4]
    p12, p13, p22, p23, p33 = w[W_P + 5], w[W_P + 6], w[W_P + 7], w[W_P + 8], w[W_P + 9]
    # rows r of P H'^T: (h_r0, h_r1)
    h00, h01 = p00 - lag * p02, p01 - lag * p03
    h10, h11 = p01 - lag * p12, p11 - lag * p13
    h20, h21 = p02 - lag * p22, p12 - lag * p23
    h30, h31 = p03 - lag * p23, p13 - lag * p33
    s00 = h00 - lag * h20 + w[W_R]
    s10 = h10 - lag * h30 + w[W_R + 1]
    s11 = h11 - lag * h31 + w[W_R + 2]
    if lag > 0.0:
        s00 += q * lag**3 / 3.0
        s11 += q * lag**3 / 3.0
    det = s00 * s11 - s10 * s10
    if s00 <= 0.0 or det <= 0.0:
        return False
    inv = 1.0 / det
    i00, i01, i11 = s11 * inv, -s10 * inv, s00 * inv
    nu0 = w[W_Z] - (w[W_X] - lag * w[W_X + 2])
    nu1 = w[W_Z + 1] - (w[W_X + 1] - lag * w[W_X + 3])
    v0, v1 = i00 * nu0 + i01 * nu1, i01 * nu0 + i11 * nu1
    if not nu0 * v0 + nu1 * v1 <= gate:  # (a NaN measurement is rejected too)
        return False
    # gain rows K_r = S^-1 (h_r0, h_r1)
    k00, k01 = i00 * h00 + i01 * h01, i01 * h00 + i11 * h01
    k10, k11 = i00 * h10 + i01 * h11, i01 * h10 + i11 * h11
    k20, k21 = i00 * h20 + i01 * h21, i01 * h20 + i11 * h21
    k30, k31 = i00 * h30 + i01 * h31, i01 * h30 + i11 * h31
    w[W_X] += h00 * v0 + h01 * v1
    w[W_X + 1] += h10 * v0 + h11 * v1
    w[W_X + 2] += h20 * v0 + h21 * v1
    w[W_X + 3] += h30 * v0 + h31 * v1
    _set_P(w, p00 - k00 * h00 - k01 * h01, p01 - k00 * h10 - k01 * h11,
           p02 - k00 * h20 - k01 * h21, p03 - k00 * h30 - k01 * h31,
           p11 - k10 * h10 - k11 * h11, p12 - k10 * h20 - k11 * h21,
           p13 - k10 * h30 - k11 * h31, p22 - k20 * h20 - k21 * h21,
           p23 - k20 * h30 - k21 * h31, p33 - k30 * h30 - k31 * h31)
    return True


@kernel
def _solve4(a00: float, a01: float, a11: float, e00: float, e01: float, e10: float, e11: float,
            g00: float, g01: float, g11: float, b0: float, b1: float, b2: float, b3: float
            ) -> tuple[float, float, float, float]:
    """``S^-1 b`` by blocks (:func:`_update4`): ``A^-1`` (a00, a01, a11), ``E = A^-1 B``,
    ``C^-1`` (g00, g01, g11); ``y = b_v - E^T b_p``, ``v_v = C^-1 y``,
    ``v_p = A^-1 b_p - E v_v``."""
    y2, y3 = b2 - (e00 * b0 + e10 * b1), b3 - (e01 * b0 + e11 * b1)
    v2, v3 = g00 * y2 + g01 * y3, g01 * y2 + g11 * y3
    return (a00 * b0 + a01 * b1 - (e00 * v2 + e01 * v3),
            a01 * b0 + a11 * b1 - (e10 * v2 + e11 * v3), v2, v3)


@kernel
def _update4(w: np.ndarray, lag: float, q: float, gate: float) -> bool:
    """Kalman update of the working estimate (only if accepted) with a full-state measurement;
    ``lag > 0`` uses it as stamped ``lag`` s before the state's time (``H' = H F(-lag)``,
    ``R' = R + H' Q(lag) H'^T``). Returns False when the normalised innovation squared exceeds
    ``gate`` (or ``S`` is not positive definite).

    ``H' Q(lag) H'^T`` is ``Q(lag)`` with its position-velocity terms negated
    (``q lag^3/3``, ``-q lag^2/2``, ``q lag`` per axis), written out rather than multiplied.
    ``S = [[A, B], [B^T, D]]`` in 2x2 blocks (position, velocity) is solved through
    ``E = A^-1 B`` and the Schur complement ``C = D - B^T E`` (``S`` is positive definite if and
    only if ``A`` and ``C`` are), for ``nu`` and for the gain rows ``K = P H'^T S^-1``;
    ``P - K (P H'^T)^T`` is formed on the upper triangle and mirrored.
    """
    p00, p01, p02, p03, p11 = w[W_P], w[W_P + 1], w[W_P + 2], w[W_P + 3], w[W_P + 4]
    p12, p13, p22, p23, p33 = w[W_P + 5], w[W_P + 6], w[W_P + 7], w[W_P + 8], w[W_P + 9]
    r = W_R
    # rows r of P H'^T: (h_r0, h_r1, p_r2, p_r3)
    h00, h01 = p00 - lag * p02, p01 - lag * p03
    h10, h11 = p01 - lag * p12, p11 - lag * p13
    h20, h21 = p02 - lag * p22, p12 - lag * p23
    h30, h31 = p03 - lag * p23, p13 - lag * p33
    s00 = h00 - lag * h20 + w[r]
    s10 = h10 - lag * h30 + w[r + 1]
    s11 = h11 - lag * h31 + w[r + 2]
    s20, s21, s22 = h20 + w[r + 3], h21 + w[r + 4], p22 + w[r + 5]
    s30, s31, s32, s33 = h30 + w[r + 6], h31 + w[r + 7], p23 + w[r + 8], p33 + w[r + 9]
    if lag > 0.0:
        s00 += q * lag**3 / 3.0
        s20 -= 0.5 * q * lag**2
        s22 += q * lag
        s11 += q * lag**3 / 3.0
        s31 -= 0.5 * q * lag**2
        s33 += q * lag
    det = s00 * s11 - s10 * s10
    if s00 <= 0.0 or det <= 0.0:
        return False
    inv = 1.0 / det
    a00, a01, a11 = s11 * inv, -s10 * inv, s00 * inv  # A^-1
    e00, e01 = a00 * s20 + a01 * s21, a00 * s30 + a01 * s31
    e10, e11 = a01 * s20 + a11 * s21, a01 * s30 + a11 * s31
    c00 = s22 - (s20 * e00 + s21 * e10)
    c01 = s32 - (s20 * e01 + s21 * e11)
    c11 = s33 - (s30 * e01 + s31 * e11)
    det = c00 * c11 - c01 * c01
    if c00 <= 0.0 or det <= 0.0:
        return False
    inv = 1.0 / det
    g00, g01, g11 = c11 * inv, -c01 * inv, c00 * inv  # C^-1
    nu0 = w[W_Z] - (w[W_X] - lag * w[W_X + 2])
    nu1 = w[W_Z + 1] - (w[W_X + 1] - lag * w[W_X + 3])
    nu2, nu3 = w[W_Z + 2] - w[W_X + 2], w[W_Z + 3] - w[W_X + 3]
    v0, v1, v2, v3 = _solve4(a00, a01, a11, e00, e01, e10, e11, g00, g01, g11, nu0, nu1, nu2,
                             nu3)
    if not nu0 * v0 + nu1 * v1 + nu2 * v2 + nu3 * v3 <= gate:  # (NaN: rejected)
        return False
    k00, k01, k02, k03 = _solve4(a00, a01, a11, e00, e01, e10, e11, g00, g01, g11, h00, h01,
                                 p02, p03)
    k10, k11, k12, k13 = _solve4(a00, a01, a11, e00, e01, e10, e11, g00, g01, g11, h10, h11,
                                 p12, p13)
    k20, k21, k22, k23 = _solve4(a00, a01, a11, e00, e01, e10, e11, g00, g01, g11, h20, h21,
                                 p22, p23)
    k30, k31, k32, k33 = _solve4(a00, a01, a11, e00, e01, e10, e11, g00, g01, g11, h30, h31,
                                 p23, p33)
    w[W_X] += h00 * v0 + h01 * v1 + p02 * v2 + p03 * v3
    w[W_X + 1] += h10 * v0 + h11 * v1 + p12 * v2 + p13 * v3
    w[W_X + 2] += h20 * v0 + h21 * v1 + p22 * v2 + p23 * v3
    w[W_X + 3] += h30 * v0 + h31 * v1 + p23 * v2 + p33 * v3
    _set_P(w, p00 - k00 * h00 - k01 * h01 - k02 * p02 - k03 * p03,
           p01 - k00 * h10 - k01 * h11 - k02 * p12 - k03 * p13,
           p02 - k00 * h20 - k01 * h21 - k02 * p22 - k03 * p23,
           p03 - k00 * h30 - k01 * h31 - k02 * p23 - k03 * p33,
           p11 - k10 * h10 - k11 * h11 - k12 * p12 - k13 * p13,
           p12 - k10 * h20 - k11 * h21 - k12 * p22 - k13 * p23,
           p13 - k10 * h30 - k11 * h31 - k12 * p23 - k13 * p33,
           p22 - k20 * h20 - k21 * h21 - k22 * p22 - k23 * p23,
           p23 - k20 * h30 - k21 * h31 - k22 * p23 - k23 * p33,
           p33 - k30 * h30 - k31 * h31 - k32 * p23 - k33 * p33)
    return True


@kernel
def _load_track(x: np.ndarray, P: np.ndarray, k: int, w: np.ndarray) -> None:
    """Working estimate = track ``k``."""
    for i in range(4):
        w[W_X + i] = x[k, i]
    o = W_P
    for i in range(4):
        for j in range(i, 4):
            w[o] = P[k, i, j]
            o += 1


@kernel
def _store_track(w: np.ndarray, x: np.ndarray, P: np.ndarray, k: int) -> None:
    """Track ``k`` = working estimate."""
    for i in range(4):
        x[k, i] = w[W_X + i]
    o = W_P
    for i in range(4):
        for j in range(i, 4):
            P[k, i, j] = P[k, j, i] = w[o]
            o += 1


@kernel
def _load_pre(hist: np.ndarray, k: int, row: int, w: np.ndarray) -> None:
    """Working estimate = the estimate before record ``row`` of pair ``k``."""
    for i in range(14):
        w[W_X + i] = hist[k, row, H_PRE_X + i]


@kernel
def _store_pre(w: np.ndarray, hist: np.ndarray, k: int, row: int, t_pre: float) -> None:
    """The estimate before record ``row`` of pair ``k`` = working estimate, at ``t_pre``."""
    hist[k, row, H_PRE_T] = t_pre
    for i in range(14):
        hist[k, row, H_PRE_X + i] = w[W_X + i]


@kernel
def _store_pre_track(x: np.ndarray, P: np.ndarray, k: int, hist: np.ndarray, row: int,
                     t_pre: float) -> None:
    """The estimate before record ``row`` of pair ``k`` = track ``k``, at ``t_pre``."""
    hist[k, row, H_PRE_T] = t_pre
    for i in range(4):
        hist[k, row, H_PRE_X + i] = x[k, i]
    o = H_PRE_P
    for i in range(4):
        for j in range(i, 4):
            hist[k, row, o] = P[k, i, j]
            o += 1


@kernel
def _write_measurement(w: np.ndarray, hist: np.ndarray, k: int, row: int, tm: float,
                       dim: int) -> None:
    """Record ``row`` of pair ``k`` = the measurement in use (its leading ``dim`` block)."""
    hist[k, row, H_T], hist[k, row, H_DIM] = tm, dim
    hist[k, row, H_Z], hist[k, row, H_Z + 1] = w[W_Z], w[W_Z + 1]
    for i in range(3):
        hist[k, row, H_R + i] = w[W_R + i]
    if dim == 4:
        hist[k, row, H_Z + 2], hist[k, row, H_Z + 3] = w[W_Z + 2], w[W_Z + 3]
        for i in range(3, 10):
            hist[k, row, H_R + i] = w[W_R + i]


@kernel
def _read_measurement(hist: np.ndarray, k: int, row: int, w: np.ndarray) -> int:
    """Measurement in use = record ``row`` of pair ``k``; returns its dimension."""
    dim = 4 if hist[k, row, H_DIM] == 4.0 else 2
    for i in range(dim):
        w[W_Z + i] = hist[k, row, H_Z + i]
    for i in range(dim * (dim + 1) // 2):
        w[W_R + i] = hist[k, row, H_R + i]
    return dim


@kernel
def _make_room(hist: np.ndarray, k: int, j: int, n: int, start: int) -> tuple[int, int, int]:
    """Open place ``j`` (0 = oldest) of pair ``k``'s history of ``n`` records starting at ring
    row ``start``: places ``j..`` move up one; a full history first drops its oldest entry (the
    ring start advances). Returns the place to write (or -1 when the history is full and the
    new entry would be the oldest: it is then not kept, the estimates after it contain it), the
    new count and the new start. The opened record still holds the old place ``j``'s
    pre-estimate. Only the measurements move: the caller rewrites the pre-estimates of all the
    places after ``j`` when it uses their measurements again."""
    if n == HISTORY:
        if j == 0:
            return -1, n, start
        start = (start + 1) % HISTORY
        n -= 1
        j -= 1
    for s in range(n, j, -1):
        dst, src = (start + s) % HISTORY, (start + s - 1) % HISTORY
        for i in range(H_MEAS):
            hist[k, dst, i] = hist[k, src, i]
    return j, n + 1, start


@kernel
def _step_kernel(x: np.ndarray, P: np.ndarray, t_state: np.ndarray, heard: np.ndarray,
                 active: np.ndarray, fails: np.ndarray, n_upd: np.ndarray, hist_n: np.ndarray,
                 hist_start: np.ndarray, hist: np.ndarray, settings: np.ndarray,
                 setting_row: np.ndarray, t_now: float,
                 has_radar: bool, r_valid: np.ndarray, r_t: float, r_north: np.ndarray,
                 r_east: np.ndarray, r_cov: np.ndarray, has_ais: bool, a_valid: np.ndarray,
                 a_stamp: np.ndarray, a_north: np.ndarray, a_east: np.ndarray,
                 a_sog: np.ndarray, a_cog: np.ndarray, in_flight: np.ndarray) -> None:
    """Use each pair's radar plot and AIS report (the older stamp first), then delete tracks
    that coasted too long. ``settings``, ``setting_row``: :func:`pair_settings`.

    Using one measurement (``dim`` 2: position, 4: full state) stamped ``tm`` on pair ``k``
    has four cases: in sequence (predict, update); late, with the estimate before the newer
    measurements in the history (restart from it, update, use the newer ones again: exact);
    late, older than the track itself (start from it, use the newer ones again: exact); late
    beyond the history (forward propagation, approximate). Written once, inside the loop over
    pairs (compile time grows with every inlined copy; a call passing the state arrays costs
    more than the update).

    Ahead of pair ``k`` it prefetches, for pair ``k + PREFETCH_AHEAD`` if it has a
    measurement, the covariance and the history records to be written (those it holds and
    the next for a late AIS report): they are scattered over more memory than the caches hold.
    """
    w = np.zeros(W_SIZE)
    m = x.shape[0]
    hist_flat, P_flat = hist.reshape(hist.size), P.reshape(P.size)
    known = in_flight.shape[0] > 0
    for k in range(m):
        f = k + PREFETCH_AHEAD
        if f < m and ((has_radar and r_valid[f]) or (has_ais and a_valid[f])):
            o = f * HISTORY * H_SIZE
            first, rows = hist_n[f], int(has_radar and r_valid[f]) + int(has_ais and a_valid[f])
            if has_ais and a_valid[f] and a_stamp[f] < t_state[f]:  # the records it holds
                first, rows = 0, min(hist_n[f] + 1, HISTORY)
            elif known and in_flight[f] > t_now:  # nothing will be recorded
                rows = 0
            for s in range(rows):
                row = o + (hist_start[f] + first + s) % HISTORY * H_SIZE
                for i in range(0, H_SIZE, 8):
                    prefetch(hist_flat, row + i)
                prefetch(hist_flat, row + H_SIZE - 1)
            for i in range(0, 16, 8):
                prefetch(P_flat, 16 * f + i)
            prefetch(P_flat, 16 * f + 15)
        sk = setting_row[k]
        # (a measurement with a NaN field is none: a run of them must not restart the track
        # from NaN, as the gate's rejections would)
        use_r = (has_radar and r_valid[k] and settings[sk, S_USE_RADAR] != 0.0
                 and not (math.isnan(r_north[k]) or math.isnan(r_east[k])))
        use_a = (has_ais and a_valid[k] and settings[sk, S_USE_AIS] != 0.0
                 and not (math.isnan(a_north[k]) or math.isnan(a_east[k])
                          or math.isnan(a_sog[k]) or math.isnan(a_cog[k])))
        if use_r or use_a:
            a_t = (a_stamp[k] if settings[sk, S_LATENCY] != 0.0 else t_now) if use_a else t_now
            # older stamp first, so that in-sequence use is the rule
            ais_first = use_a and (not use_r or a_t <= r_t)
            for which in range(2):
                if use_a and ((which == 0) == ais_first):
                    dim, tm, gate = 4, a_t, settings[sk, S_GATE4]
                    _ais_zr(a_north[k], a_east[k], a_sog[k], a_cog[k], settings[sk, S_AIS_SP],
                            settings[sk, S_AIS_SV], w, W_Z)
                elif use_r and ((which == 1) == ais_first):
                    dim, tm, gate = 2, r_t, settings[sk, S_GATE2]
                    w[W_Z], w[W_Z + 1] = r_north[k], r_east[k]
                    w[W_R], w[W_R + 1], w[W_R + 2] = r_cov[k, 0, 0], r_cov[k, 1, 0], r_cov[k, 1, 1]
                else:
                    continue
                q, sv0 = settings[sk, S_Q], settings[sk, S_SV0]
                n, start = hist_n[k], hist_start[k]
                lag = 0.0
                j = n
                t_w = tm
                if not active[k]:
                    case = RESTART
                elif tm >= t_state[k]:
                    case = IN_SEQUENCE
                    _load_predicted(x, P, k, w, tm - t_state[k], q)
                else:
                    j = 0
                    while j < n and hist[k, (start + j) % HISTORY, H_T] <= tm:
                        j += 1
                    pre_t = hist[k, (start + j) % HISTORY, H_PRE_T] if j < n else math.nan
                    if j < n and math.isnan(pre_t):
                        case = RESTART
                    elif j < n and pre_t <= tm:
                        case = REPROCESS
                        _load_pre(hist, k, (start + j) % HISTORY, w)
                        _predict(w, tm - pre_t, q)
                    else:
                        case = FORWARD
                        _load_track(x, P, k, w)
                        lag = t_state[k] - tm
                if case == RESTART:
                    _start(w, dim, sv0)
                    accepted = True
                else:  # the window opens after each failure [seed 002, sec 6.6]
                    gate *= 1.0 + fails[k]
                    accepted = _update4(w, lag, q, gate) if dim == 4 else _update2(w, lag, q, gate)
                if not accepted:
                    fails[k] += 1
                    if fails[k] < settings[sk, S_MAX_FAIL]:
                        continue
                    active[k] = False  # restart the track from the measurement [seed 002, sec 6.6]
                    _start(w, dim, sv0)
                    case = RESTART
                if not active[k]:  # a new track
                    hist_n[k] = 0
                    j = 0
                    t_state[k] = tm
                    active[k], n_upd[k] = True, 0
                if case == FORWARD:
                    hist_n[k] = 0  # the stored estimates lack this measurement: start anew
                elif j == hist_n[k] and known and not in_flight[k] < tm:
                    # nothing on its way is stamped before this measurement, so no later one
                    # will be: no history can be needed again
                    hist_n[k] = 0
                    t_state[k] = tm
                else:
                    slot, hist_n[k], start = _make_room(hist, k, j, hist_n[k], hist_start[k])
                    hist_start[k] = start
                    if slot >= 0:
                        row = (start + slot) % HISTORY
                        _write_measurement(w, hist, k, row, tm, dim)
                        if case == IN_SEQUENCE:
                            _store_pre_track(x, P, k, hist, row, t_state[k])
                            t_state[k] = tm
                        elif case == RESTART and slot == 0:
                            hist[k, row, H_PRE_T] = math.nan
                    # use the newer measurements again, in order, from the new estimate
                    for s in range(slot + 1, hist_n[k]):
                        row = (start + s) % HISTORY
                        _store_pre(w, hist, k, row, t_w)
                        t_h = hist[k, row, H_T]
                        _predict(w, t_h - t_w, q)
                        if _read_measurement(hist, k, row, w) == 4:
                            _update4(w, 0.0, q, math.inf)
                        else:
                            _update2(w, 0.0, q, math.inf)
                        t_w = t_h
                _store_track(w, x, P, k)
                fails[k] = 0
                n_upd[k] += 1
                heard[k] = t_now
        if active[k] and t_now - heard[k] > settings[sk, S_COAST]:
            active[k] = False
            fails[k] = 0
            n_upd[k] = 0
