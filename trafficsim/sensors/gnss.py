"""GNSS (or any radio) position fixes of the antenna: noise, coloured error, gross errors, outages.

Raw fixes only; a receiver's own SOG/COG output belongs to the position-velocity filter.

Error model of one fix, per axis (north, east), m:

* white noise of standard deviation ``sigma_m`` per axis. DGPS: 2 m [seed 000, eq 4, R = 4 m^2].
  Fix accuracies quoted as DRMS (radius of the error circle, ``DRMS = sqrt(a^2 + b^2)`` with
  ``a, b`` the semi-axes of the error ellipse [seed 002, sec 2.8]) are per-axis
  ``sigma = drms / sqrt(2)`` for a circular error: the Decca fixes of seed 002 (sec 3.4) have
  DRMS 10 m (South-West British chain by day) and 100 m (English chain), so per-axis 7.07 m
  and 70.7 m. For a circular normal error ``P(r < drms) = 1 - exp(-1) = 63.2 %`` and
  ``P(r < 2 drms) = 98.2 %`` (seed 002 quotes 68.3 %, which holds only for a very elongated
  ellipse);
* an optional first-order Gauss-Markov error (slowly wandering, e.g. atmospheric or multipath
  bias), stationary per-axis standard deviation ``gm_sigma_m``, correlation time ``gm_tau_s``,
  advanced every step (exact discretisation, :func:`trafficsim.sensors.gauss_markov`);
* gross errors: with probability ``gross_prob`` per fix, one fix jumps by ``gross_size_m`` in a
  uniformly random direction (multipath or a false signal path [seed 002, sec 6.6]; seed 002
  reports 0.7 % of Trisponder fixes failing a 100 m gate);
* outages: a two-state chain advanced every step. Outages start at ``dropout_rate_per_h`` per
  hour of available time (per-step probability ``1 - exp(-rate dt)``) and end with per-step
  probability ``min(1, dt / dropout_mean_s)``, so outage lengths are geometric with mean
  exactly ``dropout_mean_s`` (at least one step). The long-run unavailable fraction is
  ``p_start / (p_start + p_end)``;
* update rate: a fix every ``k = max(1, round(1 / (rate_hz dt)))`` steps, at steps 0, k, 2k ...
  (the Decca Mk53 gave one every 1.56 s nominally [seed 002, sec 3.4]);
* antenna lever arm: the antenna sits at body ``(antenna_x_m, antenna_y_m)`` (x forward,
  y starboard) from the reference point, so the true antenna position is
  ``p + R(psi) r_a`` [seed 003, eq 5]: a constant offset in the body frame whose earth-frame
  direction turns with the heading.

``valid`` is true on steps where a new fix arrives (scheduled and no outage). Between fixes the
reading repeats the last valid fix (NaN before the first), as a receiver repeats its last
position with a status flag: use ``valid`` to decide whether to update a filter.

Config keys (per ship; defaults in brackets): ``sigma_m`` [2.0] or ``drms_m`` (not both),
``rate_hz`` [1.0], ``gm_sigma_m`` [0.0], ``gm_tau_s`` [300.0], ``gross_prob`` [0.0],
``gross_size_m`` [50.0], ``dropout_rate_per_h`` [0.0], ``dropout_mean_s`` [30.0],
``antenna_x_m`` [0.0], ``antenna_y_m`` [0.0].

Upper bounds (:data:`MAX_SIGMA_M` ...), generous limits no real receiver reaches: ``sigma_m``,
``drms_m`` and ``gm_sigma_m`` at most 1000 m (coarse fixes are 10-200 m DRMS: Decca 10-100 m
[seed 002, sec 3.4], stand-alone GPS with its 100 m 2drms "in the vicinity of 150 to 200 metres"
[seed 002, sec 1.2]; DGPS 2 m [seed 000]; only Omega's 95 % of 6-7 NM [seed 002, sec 2.5], no fix
for collision avoidance, is coarser); ``gross_size_m`` at most 10 km (seed 002's gross errors
fail a 100 m window [seed 002, sec 6.6]); ``rate_hz`` at most 100 Hz (the fastest receivers);
``gm_tau_s`` and ``dropout_mean_s`` at most one day; ``dropout_rate_per_h`` at most 3600 (an
outage starting every second); ``gross_prob`` at most 1; the antenna within 250 m
(:data:`trafficsim.sensors.MAX_LEVER_M`) of the reference point, and on board the ship's own
hull where the ship file is known.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from trafficsim.errors import InputError
from trafficsim.sensors import (
    MAX_LEVER_M,
    ONE_DAY_S,
    TWO_PI,
    check_keys,
    column,
    gauss_markov,
    rotate_body_to_earth,
)
from trafficsim.ships.base import EAST, NORTH, PSI

#: standard normals per ship per step: white noise north, east; Gauss-Markov drive north, east
GNSS_NORMAL_DIMS = 4
#: uniforms per ship per step: gross-error event, gross-error direction, outage transition
GNSS_UNIFORM_DIMS = 3
GNSS_NORMAL_PURPOSE = "gnss"
GNSS_UNIFORM_PURPOSE = "gnss_gross"

DEFAULT_SIGMA_M = 2.0  # DGPS [seed 000, eq 4]
#: per-axis noise, DRMS and Gauss-Markov error, m: five times the coarsest fixes of [seed 002,
#: sec 1.2, 3.4] (150-200 m)
MAX_SIGMA_M = 1000
MAX_GROSS_SIZE_M = 10_000  # ten times MAX_SIGMA_M; seed 002's gate is 100 m [sec 6.6]
MAX_RATE_HZ = 100  # the fastest receivers' output rate
MAX_DROPOUT_RATE_PER_H = 3600  # an outage starting every second of available time
KEYS = ("sigma_m", "drms_m", "rate_hz", "gm_sigma_m", "gm_tau_s", "gross_prob", "gross_size_m",
        "dropout_rate_per_h", "dropout_mean_s", "antenna_x_m", "antenna_y_m")


@dataclass(frozen=True)
class GnssParams:
    """Per-ship GNSS parameters, ``(n,)`` arrays, for one time step ``dt``.

    Attributes:
        sigma_m: white noise standard deviation per axis, m.
        gm_a, gm_q: Gauss-Markov step coefficients ``b' = a b + q z`` (-, m).
        gm_sigma_m: Gauss-Markov stationary standard deviation per axis, m.
        gross_prob: probability of a gross error per fix (-).
        gross_size_m: size of a gross error, m.
        p_start, p_end: per-step probabilities that an outage starts / ends (-).
        every: fix every ``every`` steps (int).
        antenna_x_m, antenna_y_m: antenna position in the body frame from the reference point, m.
        dt: time step, s (scalar).
    """

    sigma_m: np.ndarray
    gm_a: np.ndarray
    gm_q: np.ndarray
    gm_sigma_m: np.ndarray
    gross_prob: np.ndarray
    gross_size_m: np.ndarray
    p_start: np.ndarray
    p_end: np.ndarray
    every: np.ndarray
    antenna_x_m: np.ndarray
    antenna_y_m: np.ndarray
    dt: float


    @cached_property
    def has_lever_arm(self) -> bool:
        """Whether any antenna sits off the reference point (else the shift is skipped)."""
        return bool(np.any(self.antenna_x_m) or np.any(self.antenna_y_m))

@dataclass(frozen=True)
class GnssState:
    """Receiver memory: ``counter`` (n,) int steps since the last scheduled fix (mod ``every``),
    ``up`` (n,) bool no outage, ``gm_m`` (n, 2) Gauss-Markov error north/east (m), ``last_m``
    (n, 2) last valid fix north/east (m, NaN before the first)."""

    counter: np.ndarray
    up: np.ndarray
    gm_m: np.ndarray
    last_m: np.ndarray


@dataclass(frozen=True)
class GnssFix:
    """One step's reading: ``north_m``, ``east_m`` (n,) antenna fix (last valid one held),
    ``valid`` (n,) bool a new fix arrived this step, ``gross`` (n,) bool that fix has a gross
    error (truth-side diagnostic, a real receiver does not know)."""

    north_m: np.ndarray
    east_m: np.ndarray
    valid: np.ndarray
    gross: np.ndarray


def build(configs: Sequence[Mapping], dt: float) -> GnssParams:
    """Parameters for ``n`` ships from per-ship config dicts (keys in the module docstring).

    Args:
        configs: ``n`` mappings.
        dt: simulation time step, s (the receiver is stepped once per step).
    """
    what = "gnss"
    dt = float(dt)
    if not dt > 0.0:
        raise InputError(f"dt must be > 0, got {dt}", key=what)
    check_keys(configs, KEYS, what)
    for i, cfg in enumerate(configs):
        if "sigma_m" in cfg and "drms_m" in cfg:
            raise InputError("give sigma_m (per axis) or drms_m, not both",
                             key=f"{what}[{i}]")
    # drms = sqrt(sx^2 + sy^2) with sx = sy [seed 002, sec 2.8]
    drms_sigma = column(configs, "drms_m", DEFAULT_SIGMA_M * math.sqrt(2.0), what,
                        minimum=0.0, maximum=MAX_SIGMA_M) / math.sqrt(2.0)
    sigma = column(configs, "sigma_m", drms_sigma, what, minimum=0.0, maximum=MAX_SIGMA_M)
    rate = column(configs, "rate_hz", 1.0, what, minimum=0.0, strictly=True,
                  maximum=MAX_RATE_HZ)
    gm_sigma = column(configs, "gm_sigma_m", 0.0, what, minimum=0.0, maximum=MAX_SIGMA_M)
    gm_tau = column(configs, "gm_tau_s", 300.0, what, minimum=0.0, strictly=True,
                    maximum=ONE_DAY_S)
    gross_prob = column(configs, "gross_prob", 0.0, what, minimum=0.0, maximum=1)
    dropout_rate = column(configs, "dropout_rate_per_h", 0.0, what, minimum=0.0,
                          maximum=MAX_DROPOUT_RATE_PER_H) / 3600.0
    dropout_mean = column(configs, "dropout_mean_s", 30.0, what, minimum=0.0, strictly=True,
                          maximum=ONE_DAY_S)
    gm_a, gm_q = gauss_markov(gm_sigma, gm_tau, dt)
    return GnssParams(
        sigma_m=sigma, gm_a=gm_a, gm_q=gm_q, gm_sigma_m=gm_sigma, gross_prob=gross_prob,
        gross_size_m=column(configs, "gross_size_m", 50.0, what, minimum=0.0,
                            maximum=MAX_GROSS_SIZE_M),
        p_start=-np.expm1(-dropout_rate * dt),
        p_end=np.minimum(1.0, dt / dropout_mean),
        every=np.maximum(1, np.rint(1.0 / (rate * dt))).astype(np.int64),
        antenna_x_m=column(configs, "antenna_x_m", 0.0, what, minimum=-MAX_LEVER_M,
                           maximum=MAX_LEVER_M),
        antenna_y_m=column(configs, "antenna_y_m", 0.0, what, minimum=-MAX_LEVER_M,
                           maximum=MAX_LEVER_M),
        dt=dt)


def init(params: GnssParams, normals: np.ndarray) -> GnssState:
    """Receiver memory at the start: no outage, first fix due at step 0, Gauss-Markov error
    drawn from its stationary distribution.

    Args:
        normals: ``(n, GNSS_NORMAL_DIMS)`` standard normals (columns 2, 3 are used).
    """
    n = params.sigma_m.shape[0]
    return GnssState(counter=np.zeros(n, dtype=np.int64), up=np.ones(n, dtype=bool),
                     gm_m=params.gm_sigma_m[:, None] * normals[:, 2:4],
                     last_m=np.full((n, 2), np.nan))


def antenna_position(params: GnssParams, x: np.ndarray,
                     psi_offset_rad: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """True antenna position north, east (m, ``(n,)`` each): ``p + R(psi) r_a`` [seed 003, eq 5].

    Args:
        x: ``(8, n)`` truth state (rows NORTH, EAST, PSI used).
        psi_offset_rad: optional ``(n,)`` extra yaw (e.g. wave-induced) turning the lever arm.
    """
    if not params.has_lever_arm:
        return x[NORTH].copy(), x[EAST].copy()
    psi = x[PSI] if psi_offset_rad is None else x[PSI] + psi_offset_rad
    dn, de = rotate_body_to_earth(psi, params.antenna_x_m, params.antenna_y_m)
    return x[NORTH] + dn, x[EAST] + de


def to_reference_point(params: GnssParams, north_m: np.ndarray, east_m: np.ndarray,
                       psi_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shift antenna fixes to the reference point with a measured heading [seed 003, eq 5].

    A heading error ``e`` leaves a position error of ``2 |r_a| sin(e / 2)`` [seed 003, eq 6].

    Args:
        north_m, east_m: ``(n,)`` antenna fixes, m.
        psi_rad: ``(n,)`` heading used for the shift (e.g. the compass reading), rad.
    """
    if not params.has_lever_arm:
        return north_m, east_m
    dn, de = rotate_body_to_earth(psi_rad, params.antenna_x_m, params.antenna_y_m)
    return north_m - dn, east_m - de


def step(params: GnssParams, state: GnssState, x: np.ndarray, normals: np.ndarray,
         uniforms: np.ndarray, wave_ne_m: np.ndarray | None = None,
         wave_psi_rad: np.ndarray | None = None) -> tuple[GnssState, GnssFix]:
    """Advance the receiver one step and return this step's reading.

    Args:
        params: from :func:`build`.
        state: from :func:`init` or the previous step.
        x: ``(8, n)`` truth state (NORTH, EAST, PSI rows used), m and rad.
        normals: ``(n, GNSS_NORMAL_DIMS)`` standard normals (purpose ``"gnss"``).
        uniforms: ``(n, GNSS_UNIFORM_DIMS)`` uniforms on [0, 1) (purpose ``"gnss_gross"``).
        wave_ne_m: optional ``(2, n)`` wave-induced displacement north/east, m
            (:func:`trafficsim.sensors.waves.position_offset`).
        wave_psi_rad: optional ``(n,)`` wave-induced yaw, rad (turns the lever arm).

    Returns:
        The new state and a :class:`GnssFix`.
    """
    scheduled = state.counter == 0
    # outage chain: leave "up" with p_start, leave "down" with p_end
    u_out = uniforms[:, 2]
    up = np.where(state.up, u_out >= params.p_start, u_out < params.p_end)
    valid = scheduled & up
    gm = params.gm_a[:, None] * state.gm_m + params.gm_q[:, None] * normals[:, 2:4]
    gross = valid & (uniforms[:, 0] < params.gross_prob)
    jump = np.where(gross, params.gross_size_m, 0.0)
    direction = TWO_PI * uniforms[:, 1]
    north, east = antenna_position(params, x, wave_psi_rad)
    if wave_ne_m is not None:
        north, east = north + wave_ne_m[0], east + wave_ne_m[1]
    north = north + params.sigma_m * normals[:, 0] + gm[:, 0] + jump * np.cos(direction)
    east = east + params.sigma_m * normals[:, 1] + gm[:, 1] + jump * np.sin(direction)
    last = np.where(valid[:, None], np.stack([north, east], axis=1), state.last_m)
    new = GnssState(counter=(state.counter + 1) % params.every, up=up, gm_m=gm, last_m=last)
    return new, GnssFix(north_m=last[:, 0].copy(), east_m=last[:, 1].copy(), valid=valid,
                        gross=gross)
