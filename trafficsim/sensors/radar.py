"""Radar / ARPA plots of other ships: range and bearing from own antenna, as earth-frame positions.

Observations are per *directed* pair (observer ``i``, target ``j``) of ships in one encounter:
:func:`directed_pairs` turns the batch's ``pair_i < pair_j`` into both directions, ``m = 2 P``
pairs, shape ``(m,)`` for every per-pair array here.

Measurement model of one plot (one antenna revolution, per pair):

* the antenna sits at body ``(antenna_x_m, antenna_y_m)`` from the observer's reference point
  [seed 003, eq 5]; the radar measures the target's reference point (no glint, no hull extent);
* range ``r = |p_t - p_a| + sigma_r z_1`` and bearing relative to own heading
  ``b = atan2(p_t - p_a) - psi + sigma_b z_2`` (Gaussian);
* the plot is put on the chart with the observer's *own estimated* position and heading,
  ``p_plot = p_a_est + r (cos(psi_est + b), sin(psi_est + b))``, so own navigation errors
  (gyro error, GNSS error) propagate into the target plot as they do on a real ARPA;
* a plot exists on scan steps only (one scan every ``scan_period_s``: 20-30 rpm is 2-3 s),
  when ``min_range_m <= true range <= max_range_nm`` and with probability ``p_detect`` per scan.
  MSC.192(79) 5.3.1.1 specifies detection as an indication in at least 8 out of 10 scans at a
  false-alarm probability of 1e-4 (hence ``p_detect`` = 0.8) and table 2 a clutter-free
  detection range of 11 NM for SOLAS ships > 5000 GT (X and S band, antenna 15 m); 12 NM is
  the default maximum. MSC.192(79) 5.4.1 asks for a navigation buoy to be detected from 40 m
  from the antenna (the default minimum range).

Default noise: the sensor-error budget of IMO resolution A.823(19) (ARPA performance standards,
annex: the sensor errors on which its tracking-accuracy figures are based). Range: pulse shape,
normal sigma 20 m, and quantisation, rectangular +-0.01 NM (sigma 18.52/sqrt 3 = 10.7 m):
``sigma_r = sqrt(20^2 + 10.7^2) = 22.7 m``. Bearing: beam shape sigma 0.05 deg, antenna backlash
rectangular +-0.05 deg (0.029 deg), quantisation rectangular +-0.1 deg (0.058 deg), synchro
encoder sigma 0.03 deg: ``sigma_b = 0.087 deg``. The systematic roll-pitch bearing error and the
gyro and log errors of that budget are not radar noise here: heading errors come from the own
navigation estimate that the caller passes in. MSC.192(79) 5.25.4.7.1 allows measured target
range and bearing errors of 50 m (or 1 % of range) and 2 deg (95 %), a looser bound
(``sigma_range_m`` 25, ``sigma_bearing_deg`` 1 reproduce it).

Converted-measurement covariance (for a Kalman filter in the earth frame): the polar noise
mapped through the Jacobian of the polar-to-Cartesian conversion at the measured range and
bearing, ``R = J diag(sigma_r^2, sigma_b^2 + var_psi) J^T + P_own`` with
``J = [[cos t, -r sin t], [sin t, r cos t]]``, ``t = psi_est + b`` (the linearised "converted
measurement" of Lerro & Bar-Shalom 1993, IEEE TAES 29(3)); ``var_psi`` (own heading variance) and
``P_own`` (own position covariance) are optional inputs from the own navigation filter. The
conversion bias ``r (1 - exp(-sigma_b^2 / 2)) ~ r sigma_b^2 / 2`` is 0.03 m at 12 NM for the
default ``sigma_b`` and 3.4 m for 1 deg, negligible next to the cross-range sigma ``r sigma_b``
(33 m and 390 m), so no debiasing is applied.

Draws: at need, from one stream per directed pair (``radar`` purpose): ``RADAR_NORMAL_DIMS``
standard normals per pair at every scan of its observer (range, bearing, detection; the plot is
detected when ``z_3 < Phi^-1(p_detect)``, a uniform event from a normal draw so that one stream
serves all three), none between scans (:func:`trafficsim.noise.normal_from`).

Config keys (per observer ship; defaults in brackets): ``sigma_range_m`` [22.7],
``sigma_bearing_deg`` [0.087], ``max_range_nm`` [12.0], ``min_range_m`` [40.0], ``p_detect``
[0.8], ``scan_period_s`` [2.5], ``scan_phase_s`` [0.0] (time of the first scan), ``antenna_x_m``
[0.0], ``antenna_y_m`` [0.0], ``enabled`` [true].

Upper bounds, generous limits no real ship's radar reaches: ``sigma_range_m`` at most 1 km
(MSC.192(79) allows 50 m or 1 % of range, 95 %), ``sigma_bearing_deg`` at most 30 deg (it
allows 2 deg, 95 %), ``max_range_nm`` at most 96 NM (the longest range scale of ship radars;
``min_range_m`` must not exceed it), ``scan_period_s`` at most 60 s (antennas turn at 20-30
rpm, 2-3 s a scan), ``p_detect`` at most 1, the antenna within 250 m
(:data:`trafficsim.sensors.MAX_LEVER_M`) of the reference point, and on board the ship's own
hull where the ship file is known.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from trafficsim.errors import InputError
from trafficsim.geometry import atan2, cos_sin
from trafficsim.jit import kernel
from trafficsim.noise import check_streams, normal_from
from trafficsim.sensors import MAX_LEVER_M, check_keys, column, flags, wrap_2pi_scalar
from trafficsim.ships.base import EAST, NORTH, PSI

#: standard normals per directed pair per scan: range noise, bearing noise, detection draw
RADAR_NORMAL_DIMS = 3
RADAR_PURPOSE = "radar"

NM = 1852.0
#: antenna revolution period, s (a ship's radar turns at 24 rpm)
DEFAULT_SCAN_PERIOD_S = 2.5
#: A.823(19) annex sensor errors: pulse shape 20 m, range quantisation +-0.01 NM rectangular
DEFAULT_SIGMA_RANGE_M = math.hypot(20.0, 0.01 * NM / math.sqrt(3.0))
#: beam shape 0.05, backlash +-0.05 rect., quantisation +-0.1 rect., encoder 0.03 (deg)
DEFAULT_SIGMA_BEARING_DEG = math.sqrt(0.05**2 + 0.05**2 / 3.0 + 0.1**2 / 3.0 + 0.03**2)
KEYS = ("sigma_range_m", "sigma_bearing_deg", "max_range_nm", "min_range_m", "p_detect",
        "scan_period_s", "scan_phase_s", "antenna_x_m", "antenna_y_m", "enabled")
MAX_SIGMA_RANGE_M = 1000  # MSC.192(79): 50 m or 1 % of range (95 %)
MAX_SIGMA_BEARING_DEG = 30  # MSC.192(79): 2 deg (95 %)
MAX_RANGE_NM = 96  # the longest range scale of ship radars
MAX_SCAN_PERIOD_S = 60  # antennas turn at 20-30 rpm


def directed_pairs(pair_i: np.ndarray, pair_j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Observer and target indices ``(m,)`` of both directions of every pair, ``m = 2 P``.

    The first ``P`` entries are ``i -> j`` (observer ``pair_i``), the last ``P`` are ``j -> i``.
    """
    pi = np.asarray(pair_i, dtype=np.int64)
    pj = np.asarray(pair_j, dtype=np.int64)
    return np.concatenate([pi, pj]), np.concatenate([pj, pi])


@dataclass(frozen=True)
class RadarParams:
    """Per-observer radar parameters, ``(n,)`` arrays.

    Attributes:
        sigma_range_m: range noise standard deviation, m.
        sigma_bearing_rad: bearing noise standard deviation, rad.
        max_range_m, min_range_m: detection range limits, m.
        p_detect: detection probability per scan (-).
        z_detect: ``Phi^-1(p_detect)``, the threshold on the detection draw (-inf when 0).
        scan_period_s: antenna revolution period, s.
        scan_phase_s: time of the first scan, s.
        antenna_x_m, antenna_y_m: antenna position in the body frame, m.
        enabled: bool, the ship has a radar in use.
    """

    sigma_range_m: np.ndarray
    sigma_bearing_rad: np.ndarray
    max_range_m: np.ndarray
    min_range_m: np.ndarray
    p_detect: np.ndarray
    z_detect: np.ndarray
    scan_period_s: np.ndarray
    scan_phase_s: np.ndarray
    antenna_x_m: np.ndarray
    antenna_y_m: np.ndarray
    enabled: np.ndarray


@dataclass(frozen=True)
class RadarState:
    """Antenna memory: ``next_scan_s`` (n,) time of each observer's next scan, s."""

    next_scan_s: np.ndarray


@dataclass(frozen=True)
class RadarPlots:
    """One step's plots, per directed pair ``(m,)``.

    Attributes:
        valid: bool, a plot of the target exists this step.
        t_s: time of the plot (this step), s.
        north_m, east_m: plotted target position in the earth frame (own estimate based), m.
        cov: ``(m, 2, 2)`` converted-measurement covariance of (north, east), m^2.
        range_m: measured range, m.
        bearing_rad: measured bearing relative to own heading, rad in [-pi, pi).
    Entries of invalid pairs are NaN.
    """

    valid: np.ndarray
    t_s: float
    north_m: np.ndarray
    east_m: np.ndarray
    cov: np.ndarray
    range_m: np.ndarray
    bearing_rad: np.ndarray


def probit(p: np.ndarray) -> np.ndarray:
    """``Phi^-1(p)`` element-wise, with -inf for 0 and +inf for 1 (build time only)."""
    dist = NormalDist()
    return np.array([-math.inf if v <= 0.0 else math.inf if v >= 1.0 else dist.inv_cdf(v)
                     for v in p])


def build(configs: Sequence[Mapping]) -> RadarParams:
    """Radar parameters from per-ship config dicts (keys and defaults: module docstring)."""
    what = "radar"
    check_keys(configs, KEYS, what)
    p_detect = column(configs, "p_detect", 0.8, what, minimum=0.0)
    if np.any(p_detect > 1.0):
        raise InputError(f"p_detect must be <= 1, got {p_detect.max()}", key=f"{what}.p_detect")
    max_range_m = column(configs, "max_range_nm", 12.0, what, scale=NM, minimum=0.0,
                         maximum=MAX_RANGE_NM)
    min_range_m = column(configs, "min_range_m", 40.0, what, minimum=0.0)
    beyond = np.flatnonzero(min_range_m > max_range_m)
    if beyond.size:  # (a radar that can never detect anything)
        i = int(beyond[0])
        raise InputError(f"min_range_m ({min_range_m[i]:g} m) must not exceed max_range_nm "
                         f"({max_range_m[i] / NM:g} NM = {max_range_m[i]:g} m)",
                         key=f"{what}[{i}].min_range_m")
    return RadarParams(
        sigma_range_m=column(configs, "sigma_range_m", DEFAULT_SIGMA_RANGE_M, what, minimum=0.0,
                             maximum=MAX_SIGMA_RANGE_M),
        sigma_bearing_rad=column(configs, "sigma_bearing_deg", DEFAULT_SIGMA_BEARING_DEG, what,
                                 scale=math.pi / 180.0, minimum=0.0,
                                 maximum=MAX_SIGMA_BEARING_DEG),
        max_range_m=max_range_m,
        min_range_m=min_range_m,
        p_detect=p_detect,
        z_detect=probit(p_detect),
        scan_period_s=column(configs, "scan_period_s", DEFAULT_SCAN_PERIOD_S, what, minimum=0.0,
                             strictly=True, maximum=MAX_SCAN_PERIOD_S),
        scan_phase_s=column(configs, "scan_phase_s", 0.0, what),
        antenna_x_m=column(configs, "antenna_x_m", 0.0, what, minimum=-MAX_LEVER_M,
                           maximum=MAX_LEVER_M),
        antenna_y_m=column(configs, "antenna_y_m", 0.0, what, minimum=-MAX_LEVER_M,
                           maximum=MAX_LEVER_M),
        enabled=flags(configs, "enabled", what),
    )


def init(params: RadarParams) -> RadarState:
    """Antenna state before the first step: first scan at ``scan_phase_s``."""
    return RadarState(next_scan_s=params.scan_phase_s.astype(float).copy())


def scan_due(params: RadarParams, state: RadarState, t_s: float
             ) -> tuple[RadarState, np.ndarray]:
    """Which observers complete a scan at time ``t_s``; advances the scan schedule.

    A scan is due when ``t_s >= next_scan_s`` (to within 1e-9 s); the next scan is then one
    period after the scheduled one (so the mean interval is the period whatever the step), or
    one period after ``t_s`` if the schedule fell more than a period behind (steps longer than
    the scan period give at most one plot per step).

    Returns: the new state and ``due`` (n,) bool.
    """
    due = np.empty(state.next_scan_s.shape[0], dtype=bool)
    nxt = np.empty(state.next_scan_s.shape[0])
    _scan(_c(params.enabled, bool), _c(params.scan_period_s), _c(state.next_scan_s), float(t_s),
          due, nxt)
    return RadarState(next_scan_s=nxt), due


@kernel
def _scan(enabled: np.ndarray, period: np.ndarray, next_scan: np.ndarray, t_s: float,
          due: np.ndarray, out: np.ndarray) -> None:
    """:func:`scan_due` for every observer: ``due`` and the new schedule ``out``."""
    for i in range(next_scan.shape[0]):
        due[i] = enabled[i] and t_s >= next_scan[i] - 1e-9
        out[i] = next_scan[i]
        if due[i]:
            nxt = next_scan[i] + period[i]
            out[i] = t_s + period[i] if nxt <= t_s + 1e-9 else nxt


def measure(params: RadarParams, due: np.ndarray, obs: np.ndarray, tgt: np.ndarray,
            x_true: np.ndarray, est_north_m: np.ndarray, est_east_m: np.ndarray,
            est_psi_rad: np.ndarray, streams: np.ndarray, t_s: float,
            own_heading_var_rad2: np.ndarray | None = None,
            own_pos_cov_m2: np.ndarray | None = None) -> RadarPlots:
    """Radar plots of every directed pair at time ``t_s`` (one compiled loop over pairs).

    Args:
        params: observer radar parameters, ``(n,)``.
        due: ``(n,)`` bool, observers whose scan completes now (:func:`scan_due`).
        obs, tgt: ``(m,)`` int observer and target ship indices (:func:`directed_pairs`).
        x_true: ``(8, n)`` true states (:mod:`trafficsim.ships.base` layout).
        est_north_m, est_east_m, est_psi_rad: ``(n,)`` each observer's own estimated reference
            point position (m) and heading (rad), used to put the plot on the chart.
        streams: ``(m, 4)`` uint64 random-stream states, one per pair
            (:attr:`trafficsim.noise.NoiseBank.state`), advanced in place by the
            ``RADAR_NORMAL_DIMS`` numbers of every pair whose observer scans now.
        t_s: time of this step, s.
        own_heading_var_rad2: optional ``(n,)`` variance of the own heading estimate, rad^2.
        own_pos_cov_m2: optional ``(n, 2, 2)`` covariance of the own position estimate, m^2.
    """
    m = obs.shape[0]
    check_streams(streams, m)
    p = params
    var_psi = (_NONE if own_heading_var_rad2 is None
               else _c(np.broadcast_to(own_heading_var_rad2, due.shape)))
    pos_cov = (_NONE3 if own_pos_cov_m2 is None
               else _c(np.broadcast_to(own_pos_cov_m2, (due.shape[0], 2, 2))))
    plots = RadarPlots(valid=np.empty(m, dtype=bool), t_s=float(t_s), north_m=np.empty(m),
                       east_m=np.empty(m), cov=np.empty((m, 2, 2)), range_m=np.empty(m),
                       bearing_rad=np.empty(m))
    _plots((_c(p.sigma_range_m), _c(p.sigma_bearing_rad), _c(p.max_range_m),
            _c(p.min_range_m), _c(p.z_detect), _c(p.antenna_x_m), _c(p.antenna_y_m)),
           _c(due, bool), _c(obs, np.int64), _c(tgt, np.int64), _c(x_true), _c(est_north_m),
           _c(est_east_m), _c(est_psi_rad), streams, var_psi, pos_cov,
           (plots.valid, plots.north_m, plots.east_m, plots.cov, plots.range_m,
            plots.bearing_rad))
    return plots


def _c(a: np.ndarray, dtype: type = float) -> np.ndarray:
    """``a`` as a C-contiguous array (one compiled specialisation for every caller)."""
    return np.ascontiguousarray(a, dtype=dtype)


_NONE, _NONE3 = np.zeros(0), np.zeros((0, 2, 2))


@kernel
def _plots(params: tuple, due: np.ndarray, obs: np.ndarray, tgt: np.ndarray,
           x_true: np.ndarray, est_n: np.ndarray, est_e: np.ndarray, est_psi: np.ndarray,
           streams: np.ndarray, var_psi: np.ndarray, pos_cov: np.ndarray, out: tuple) -> None:
    """The measurement model of the module docstring for every pair; NaN where no plot.

    ``params``: per-observer ``(sigma_range_m, sigma_bearing_rad, max_range_m, min_range_m,
    z_detect, antenna_x_m, antenna_y_m)``; ``out``: ``(valid, north_m, east_m, cov, range_m,
    bearing_rad)`` of :class:`RadarPlots`. ``var_psi`` / ``pos_cov`` empty when not given. The
    antenna offset is turned to the earth frame as in
    :func:`trafficsim.sensors.rotate_body_to_earth` [seed 003, eq 5].
    """
    sr, sb, rmax, rmin, zdet, ant_x, ant_y = params
    valid, north, east, cov, rng_out, brg_out = out
    has_var, has_cov = var_psi.shape[0] > 0, pos_cov.shape[0] > 0
    for k in range(obs.shape[0]):
        i, j = obs[k], tgt[k]
        ok = False
        z_range = z_bearing = 0.0
        if due[i]:
            z_range, z_bearing = normal_from(streams, k), normal_from(streams, k)
        if due[i] and normal_from(streams, k) < zdet[i]:
            psi = x_true[PSI, i]
            ax, ay = ant_x[i], ant_y[i]
            offset = ax != 0.0 or ay != 0.0  # (no rotation of a zero offset: saves two sincos)
            off_n = off_e = 0.0
            if offset:
                c, s = cos_sin(psi)
                off_n, off_e = ax * c - ay * s, ax * s + ay * c
            rel_n = x_true[NORTH, j] - (x_true[NORTH, i] + off_n)
            rel_e = x_true[EAST, j] - (x_true[EAST, i] + off_e)
            true_range = math.sqrt(rel_n * rel_n + rel_e * rel_e)
            rng = true_range + sr[i] * z_range
            ok = true_range <= rmax[i] and true_range >= rmin[i] and rng > 0.0
        valid[k] = ok
        if not ok:
            north[k] = east[k] = rng_out[k] = brg_out[k] = math.nan
            cov[k, 0, 0] = cov[k, 0, 1] = cov[k, 1, 0] = cov[k, 1, 1] = math.nan
            continue
        true_brg = atan2(rel_e, rel_n) - psi
        brg = wrap_2pi_scalar(true_brg + sb[i] * z_bearing + math.pi) - math.pi
        psi_est = est_psi[i]
        if offset:
            ce, se = cos_sin(psi_est)
            off_n, off_e = ax * ce - ay * se, ax * se + ay * ce
        theta = psi_est + brg
        c, s = cos_sin(theta)
        north[k] = est_n[i] + off_n + rng * c
        east[k] = est_e[i] + off_e + rng * s
        rng_out[k], brg_out[k] = rng, brg
        var_r = sr[i] * sr[i]
        var_b = sb[i] * sb[i]
        if has_var:
            var_b = var_b + var_psi[i]
        cross = rng * rng * var_b
        c00 = c * c * var_r + s * s * cross
        c11 = s * s * var_r + c * c * cross
        c01 = c * s * (var_r - cross)
        if has_cov:
            c00 += pos_cov[i, 0, 0]
            c11 += pos_cov[i, 1, 1]
            cov[k, 0, 1] = c01 + pos_cov[i, 0, 1]
            cov[k, 1, 0] = c01 + pos_cov[i, 1, 0]
        else:
            cov[k, 0, 1] = cov[k, 1, 0] = c01
        cov[k, 0, 0], cov[k, 1, 1] = c00, c11


def step(params: RadarParams, state: RadarState, t_s: float, obs: np.ndarray, tgt: np.ndarray,
         x_true: np.ndarray, est_north_m: np.ndarray, est_east_m: np.ndarray,
         est_psi_rad: np.ndarray, streams: np.ndarray,
         own_heading_var_rad2: np.ndarray | None = None,
         own_pos_cov_m2: np.ndarray | None = None) -> tuple[RadarState, RadarPlots]:
    """One step: advance the scan schedule and make the plots of observers whose scan is due.

    Arguments as in :func:`scan_due` and :func:`measure`.
    """
    state, due = scan_due(params, state, t_s)
    plots = measure(params, due, obs, tgt, x_true, est_north_m, est_east_m, est_psi_rad, streams,
                    t_s, own_heading_var_rad2, own_pos_cov_m2)
    return state, plots
