"""Wave-frequency motion added to MEASURED heading and position (never to the truth dynamics).

The manoeuvring model gives the low-frequency motion; first-order wave forces add an
oscillation at the wave encounter frequency that the sensors see and the filters must reject.
Each channel (yaw, surge, sway) is a second-order shaping filter driven by unit white noise
``w`` (``E[w(t) w(s)] = delta(t - s)``) [seed 004, eqs 16-17]::

    z1' = z2
    z2' = -w0^2 z1 - 2 lam w0 z2 + c w

* ``form: bandpass`` (default): output ``y = z2``, transfer function
  ``h(s) = c s / (s^2 + 2 lam w0 s + w0^2)`` (the linear wave response model of Fossen 2011,
  Handbook of Marine Craft Hydrodynamics, ch. 8, with ``K_w = c``). No mean drift; the
  spectrum ``c^2 w^2 / ((w0^2 - w^2)^2 + 4 lam^2 w0^2 w^2)`` peaks exactly at ``w0``. Its
  autocorrelation is ``sigma^2 exp(-mu t) (cos(beta t) - mu/beta sin(beta t))``, ``mu = lam
  w0``, ``beta^2 = w0^2 - mu^2`` (the derivative process of [seed 004, eq 24]).
* ``form: lowpass``: output ``y = z1``, ``h(s) = c / (s^2 + 2 lam w0 s + w0^2)``, the roll
  model of seed 004 with correlation function ``sigma^2 exp(-mu t) (cos(beta t) + mu/beta
  sin(beta t))`` [seed 004, eq 15], ``b = w0``, ``D = sigma^2``; its spectrum peaks at
  ``w0 sqrt(1 - 2 lam^2)``.

The gain ``c`` is chosen so that the stationary standard deviation of ``y`` is the configured
sigma: ``Var z1 = c^2 / (4 lam w0^3)``, ``Var z2 = c^2 / (4 lam w0)``, ``Cov(z1, z2) = 0``
(bandpass ``c = sigma sqrt(4 lam w0)``; lowpass ``c = 2 w0 sqrt(sigma^2 lam w0)``, seed 004's
``2 b sqrt(D mu)`` [eq 16]).

Discretisation is exact for any ``dt``: ``Phi = expm(A dt)`` in closed form (under-, critically
and over-damped), and the process noise ``Q = P - Phi P Phi^T`` with ``P`` the stationary
covariance (the discrete Lyapunov identity of the exact discretisation), factored by a 2x2
Cholesky, so the variance and autocorrelation are right at every sample. All three channels of a
ship share ``w0`` and ``lam`` (one encounter spectrum) and have independent noise.

The surge and sway displacements are body-frame and are rotated by the heading into north/east
offsets. Config keys (per ship): ``heading_sigma_deg`` [0.0], ``surge_sigma_m`` [0.0],
``sway_sigma_m`` [0.0], ``peak_period_s`` [8.0] (``2 pi / w0``, encounter period),
``damping_ratio`` [0.1] (``lam``), ``form`` ["bandpass"].

The filter itself needs only ``peak_period_s > 0`` and ``damping_ratio > 0`` (exact in every
damping regime); the upper bounds are physical, generous limits no sea reaches:
``heading_sigma_deg`` at most 30 deg (twice the 15 deg roll amplitude seed 004 tests its
platform with [seed 004, sec 5]; wave-induced yaw is a few degrees), ``surge_sigma_m`` and
``sway_sigma_m`` at most 50 m (wave-frequency motion is of the order of the wave amplitude,
some metres even in a storm), ``peak_period_s`` from 0.5 s (a model ship in a tank meets waves
at about 1 s) to 60 s (the encounter period exceeds the wave period in following seas, but
beyond a minute the motion is no longer wave-frequency), ``damping_ratio`` at most 1 (critical
damping: fits of wave spectra give 0.05-0.3, and beyond 1 the response no longer oscillates).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from trafficsim.errors import InputError
from trafficsim.sensors import TWO_PI, check_keys, choice, column, rotate_body_to_earth

#: standard normals per ship per step: (yaw, surge, sway) x (2 per channel)
WAVE_NORMAL_DIMS = 6
WAVE_PURPOSE = "waves"
N_CHANNELS = 3  # yaw, surge, sway
YAW, SURGE, SWAY = range(N_CHANNELS)

FORMS = ("bandpass", "lowpass")
KEYS = ("heading_sigma_deg", "surge_sigma_m", "sway_sigma_m", "peak_period_s",
        "damping_ratio", "form")
MAX_HEADING_SIGMA_DEG = 30  # twice seed 004's 15 deg roll amplitude
MAX_DISPLACEMENT_SIGMA_M = 50  # wave-frequency surge and sway are a few metres
PEAK_PERIOD_RANGE_S = (0.5, 60)  # tank models' encounters to long following-sea ones
MAX_DAMPING_RATIO = 1  # critical damping


@dataclass(frozen=True)
class WaveParams:
    """Per-ship shaping-filter parameters for one time step ``dt``.

    Attributes:
        omega0: ``(n,)`` natural frequency ``w0``, rad/s.
        zeta: ``(n,)`` relative damping ``lam`` (-).
        bandpass: ``(n, 1)`` bool, the output is ``z2`` (else ``z1``).
        gain: ``(n, 3)`` input gain ``c`` per channel (yaw in rad, surge and sway in m, times
            the unit of ``z``).
        phi11, phi12, phi21, phi22: ``(n, 1)`` transition matrix ``expm(A dt)``.
        l11, l21, l22: ``(n, 1)`` Cholesky factor of the process noise for ``c = 1``.
        p11, p22: ``(n, 1)`` stationary variances of ``z1``, ``z2`` for ``c = 1``.
        dt: time step, s.
    """

    omega0: np.ndarray
    zeta: np.ndarray
    bandpass: np.ndarray
    gain: np.ndarray
    phi11: np.ndarray
    phi12: np.ndarray
    phi21: np.ndarray
    phi22: np.ndarray
    l11: np.ndarray
    l21: np.ndarray
    l22: np.ndarray
    p11: np.ndarray
    p22: np.ndarray
    dt: float


@dataclass(frozen=True)
class WaveState:
    """Filter states ``z1``, ``z2`` (n, 3) of the yaw, surge and sway channels for unit gain
    ``c`` (the outputs are ``gain * z2`` for bandpass, ``gain * z1`` for lowpass)."""

    z1: np.ndarray
    z2: np.ndarray


def transition(omega0: np.ndarray, zeta: np.ndarray,
               t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form ``expm(A t)`` of ``A = [[0, 1], [-w0^2, -2 zeta w0]]``, entries ``(n,)``.

    With ``mu = zeta w0`` and ``d = w0^2 - mu^2``: ``expm(A t) = exp(-mu t) (C I + S (A + mu I))``
    where ``C = cos(sqrt(d) t)``, ``S = sin(sqrt(d) t) / sqrt(d)`` for ``d > 0`` (cosh and sinh
    for ``d < 0``; ``C = 1``, ``S = t`` at ``d = 0``) (Cayley-Hamilton for a 2x2 matrix).
    ``phi11`` is the normalised correlation function of [seed 004, eq 15].

    Args:
        omega0: ``(n,)`` natural frequency, rad/s.
        zeta: ``(n,)`` relative damping (-).
        t: time, s.
    """
    t = float(t)
    mu = zeta * omega0
    d = omega0 * omega0 - mu * mu
    root = np.sqrt(np.abs(d))
    arg = root * t
    under = d >= 0.0
    decay = np.exp(-mu * t)
    # over-damped: exp(-mu t) cosh and sinh as two decaying exponentials (cosh alone overflows
    # where exp(-mu t) underflows, a long step of a strongly damped filter)
    over = np.where(under, 0.0, root)
    fast, slow = np.exp(-(mu + over) * t), np.exp(-(mu - over) * t)
    dc = np.where(under, decay * np.cos(arg), 0.5 * (slow + fast))
    # decay sin(x)/x t and decay sinh(x)/x t, -> decay t at x = 0 (critical damping)
    ds = np.where(under, decay * t * np.sinc(arg / math.pi),
                  np.where(over > 0.0, 0.5 * (slow - fast) / np.where(over > 0.0, over, 1.0),
                           decay * t))
    return dc + mu * ds, ds, -omega0 * omega0 * ds, dc - mu * ds


def stationary_variances(omega0: np.ndarray, zeta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stationary ``Var z1 = 1 / (4 zeta w0^3)`` and ``Var z2 = 1 / (4 zeta w0)`` for ``c = 1``
    (the covariance is 0), ``(n,)`` each."""
    return 1.0 / (4.0 * zeta * omega0 ** 3), 1.0 / (4.0 * zeta * omega0)


def peak_frequency(params: WaveParams) -> np.ndarray:
    """Frequency of the spectral peak of the output, rad/s, ``(n,)``: ``w0`` (bandpass) or
    ``w0 sqrt(1 - 2 lam^2)`` (lowpass; 0 if ``lam >= 1/sqrt(2)``)."""
    low = params.omega0 * np.sqrt(np.maximum(0.0, 1.0 - 2.0 * params.zeta ** 2))
    return np.where(params.bandpass[:, 0], params.omega0, low)


def build(configs: Sequence[Mapping], dt: float) -> WaveParams:
    """Parameters for ``n`` ships from per-ship config dicts (keys in the module docstring).

    Args:
        configs: ``n`` mappings.
        dt: time step, s; the filters are discretised exactly for it.
    """
    what = "waves"
    dt = float(dt)
    if not dt > 0.0:
        raise InputError(f"dt must be > 0, got {dt}", key=what)
    check_keys(configs, KEYS, what)
    forms = choice(configs, "form", FORMS, "bandpass", what)
    shortest, longest = PEAK_PERIOD_RANGE_S
    omega0 = TWO_PI / column(configs, "peak_period_s", 8.0, what, minimum=shortest,
                             maximum=longest)
    zeta = column(configs, "damping_ratio", 0.1, what, minimum=0.0, strictly=True,
                  maximum=MAX_DAMPING_RATIO)
    metres = MAX_DISPLACEMENT_SIGMA_M
    sigma = np.stack([column(configs, "heading_sigma_deg", 0.0, what, math.radians(1.0),
                             minimum=0.0, maximum=MAX_HEADING_SIGMA_DEG),
                      column(configs, "surge_sigma_m", 0.0, what, minimum=0.0, maximum=metres),
                      column(configs, "sway_sigma_m", 0.0, what, minimum=0.0, maximum=metres)],
                     axis=1)
    bandpass = np.array([f == "bandpass" for f in forms], dtype=bool)[:, None]
    p11, p22 = stationary_variances(omega0, zeta)
    # gain so that the output's stationary variance is sigma^2
    gain = sigma / np.sqrt(np.where(bandpass[:, 0], p22, p11))[:, None]
    f11, f12, f21, f22 = transition(omega0, zeta, dt)
    # exact process noise Q = P - Phi P Phi^T (P diagonal), then its 2x2 Cholesky factor
    q11 = p11 - (f11 * f11 * p11 + f12 * f12 * p22)
    q12 = -(f11 * f21 * p11 + f12 * f22 * p22)
    q22 = p22 - (f21 * f21 * p11 + f22 * f22 * p22)
    l11 = np.sqrt(np.maximum(q11, 0.0))
    l21 = np.where(l11 > 0.0, q12 / np.where(l11 > 0.0, l11, 1.0), 0.0)
    l22 = np.sqrt(np.maximum(q22 - l21 * l21, 0.0))

    def col(a: np.ndarray) -> np.ndarray:  # (n, 1) to broadcast over the 3 channels
        return np.ascontiguousarray(a[:, None])

    return WaveParams(omega0=omega0, zeta=zeta, bandpass=bandpass, gain=gain, phi11=col(f11),
                      phi12=col(f12), phi21=col(f21), phi22=col(f22), l11=col(l11),
                      l21=col(l21), l22=col(l22), p11=col(p11), p22=col(p22), dt=dt)


def init(params: WaveParams, normals: np.ndarray) -> WaveState:
    """Filter states drawn from their stationary distribution (the sea is already running).

    Args:
        normals: ``(n, WAVE_NORMAL_DIMS)`` standard normals.
    """
    return WaveState(z1=np.sqrt(params.p11) * normals[:, 0::2],
                     z2=np.sqrt(params.p22) * normals[:, 1::2])


def step(params: WaveParams, state: WaveState, normals: np.ndarray) -> WaveState:
    """Advance all channels one step ``dt``: ``z <- Phi z + L e``.

    Args:
        normals: ``(n, WAVE_NORMAL_DIMS)`` standard normals (purpose ``"waves"``); columns
            ``2j`` and ``2j + 1`` drive channel ``j`` (yaw, surge, sway).
    """
    e1, e2 = normals[:, 0::2], normals[:, 1::2]  # per channel: (yaw, surge, sway)
    z1, z2 = state.z1, state.z2
    return WaveState(z1=params.phi11 * z1 + params.phi12 * z2 + params.l11 * e1,
                     z2=params.phi21 * z1 + params.phi22 * z2 + params.l21 * e1
                     + params.l22 * e2)


def outputs(params: WaveParams, state: WaveState) -> np.ndarray:
    """``(n, 3)`` channel outputs: yaw (rad), surge (m), sway (m)."""
    return params.gain * np.where(params.bandpass, state.z2, state.z1)


def heading_offset(params: WaveParams, state: WaveState) -> np.ndarray:
    """Wave-induced yaw to add to the measured heading, rad, ``(n,)``."""
    return outputs(params, state)[:, YAW]


def position_offset(params: WaveParams, state: WaveState, psi: np.ndarray) -> np.ndarray:
    """Wave-induced displacement to add to measured positions, ``(2, n)`` north/east, m.

    Args:
        psi: ``(n,)`` heading, rad (rotates the body-frame surge/sway displacement).
    """
    y = outputs(params, state)
    north, east = rotate_body_to_earth(psi, y[:, SURGE], y[:, SWAY])
    return np.stack([north, east])
