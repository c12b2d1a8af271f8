"""Heading sensors: gyro compass and magnetic (fluxgate) compass.

Reading, rad, wrapped to [0, 2 pi)::

    psi_m = psi + bias + d(psi) + b_gm + sigma z

* ``bias``: constant error (``bias_deg``);
* ``d(psi) = A + B sin psi + C cos psi + D sin 2psi + E cos 2psi``: the deviation curve of a
  magnetic compass, ``deviation_deg = [A, B, C, D, E]`` in degrees, evaluated at the true
  heading (the error the sensor adds; the nautical "deviation East" has the opposite sign).
  Seed 002 fits a sine function to its swung fluxgate compass (sec 3.4, fig 3.5);
* ``b_gm``: optional first-order Gauss-Markov drift (``drift_sigma_deg`` stationary standard
  deviation, ``drift_tau_s`` correlation time), e.g. a gyro's slowly wandering error;
* ``sigma z``: white noise, ``sigma_deg``.

Defaults by ``kind``: ``"gyro"`` sigma 1 deg (a gyro's random heading error from the ship's
motions is about 1 deg [seed 002, sec 2.9]); ``"magnetic"`` (small-craft fluxgate compass)
sigma ``sqrt(0.0054) rad = 4.21 deg``: the measured heading variance 0.0054 rad^2 of the
'Catfish' 2-phase fluxgate compass after deviation correction, random error "less than 4 deg"
[seed 002, sec 3.4]. A gyro has no deviation: ``deviation_deg`` is only allowed for
``"magnetic"``. Magnetic variation is taken as corrected from the chart (not modelled).

Config keys (per ship): ``kind`` ["gyro"], ``sigma_deg`` [by kind], ``bias_deg`` [0.0],
``drift_sigma_deg`` [0.0], ``drift_tau_s`` [600.0], ``deviation_deg`` [[0, 0, 0, 0, 0]].

Upper bounds, generous limits no real compass reaches: ``sigma_deg`` and ``drift_sigma_deg`` at
most 30 deg (seven times the small-craft fluxgate's 4.2 deg [seed 002, sec 3.4]; a gyro's is
about 1 deg [seed 002, sec 2.9]); each deviation coefficient within +-30 deg (a swung compass's
curve is corrected to a few degrees [seed 002, sec 3.4, fig 3.5]; five of them still allow a
150 deg error); ``bias_deg`` within +-180 deg (any more is the same error plus whole turns);
``drift_tau_s`` at most one day.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from trafficsim.errors import InputError
from trafficsim.sensors import ONE_DAY_S, check_keys, choice, column, gauss_markov, wrap_2pi

#: standard normals per ship per step: white noise, Gauss-Markov drive
COMPASS_NORMAL_DIMS = 2
COMPASS_PURPOSE = "compass"

KINDS = ("gyro", "magnetic")
DEFAULT_SIGMA_DEG = {"gyro": 1.0,  # [seed 002, sec 2.9]
                     "magnetic": math.degrees(math.sqrt(0.0054))}  # [seed 002, sec 3.4]
KEYS = ("kind", "sigma_deg", "bias_deg", "drift_sigma_deg", "drift_tau_s", "deviation_deg")
MAX_SIGMA_DEG = 30  # white noise and drift: 7 x the fluxgate's 4.2 deg [seed 002, sec 3.4]
MAX_DEVIATION_DEG = 30  # each coefficient A..E; corrected curves are a few deg [seed 002, 3.4]
MAX_BIAS_DEG = 180  # beyond, the same error plus whole turns


@dataclass(frozen=True)
class CompassParams:
    """Per-ship compass parameters, ``(n,)`` arrays, rad, for one time step.

    Attributes:
        magnetic: True for a magnetic compass.
        sigma_rad: white noise standard deviation.
        bias_rad: constant error.
        dev_a, dev_b, dev_c, dev_d, dev_e: deviation coefficients A..E, rad.
        drift_a, drift_q: Gauss-Markov step coefficients (-, rad).
        drift_sigma_rad: Gauss-Markov stationary standard deviation.
    """

    magnetic: np.ndarray
    sigma_rad: np.ndarray
    bias_rad: np.ndarray
    dev_a: np.ndarray
    dev_b: np.ndarray
    dev_c: np.ndarray
    dev_d: np.ndarray
    dev_e: np.ndarray
    drift_a: np.ndarray
    drift_q: np.ndarray
    drift_sigma_rad: np.ndarray


    @cached_property
    def has_deviation(self) -> bool:
        """Whether any ship has a deviation curve (else it is skipped)."""
        return bool(any(np.any(c) for c in (self.dev_a, self.dev_b, self.dev_c, self.dev_d,
                                            self.dev_e)))

@dataclass(frozen=True)
class CompassState:
    """Compass memory: ``drift_rad`` (n,) Gauss-Markov error, rad."""

    drift_rad: np.ndarray


def _deviation(configs: Sequence[Mapping], kinds: list[str]) -> np.ndarray:
    """``(5, n)`` deviation coefficients in degrees."""
    out = np.zeros((5, len(configs)))
    for i, cfg in enumerate(configs):
        if "deviation_deg" not in cfg:
            continue
        key = f"compass[{i}].deviation_deg"
        if kinds[i] != "magnetic":
            raise InputError("a gyro compass has no deviation curve", key=key)
        try:
            coef = np.asarray(cfg["deviation_deg"], dtype=float)
        except (TypeError, ValueError):
            raise InputError("expected 5 numbers [A, B, C, D, E]", key=key) from None
        if coef.shape != (5,) or not np.all(np.isfinite(coef)):
            raise InputError(f"expected 5 finite numbers [A, B, C, D, E], got {coef.tolist()}",
                             key=key)
        if np.any(np.abs(coef) > MAX_DEVIATION_DEG):
            raise InputError(f"each coefficient must be within +-{MAX_DEVIATION_DEG} deg, got "
                             f"{coef.tolist()}", key=key)
        out[:, i] = coef
    return out


def build(configs: Sequence[Mapping], dt: float) -> CompassParams:
    """Parameters for ``n`` ships from per-ship config dicts (keys in the module docstring).

    Args:
        configs: ``n`` mappings.
        dt: time step, s (for the Gauss-Markov drift).
    """
    what = "compass"
    check_keys(configs, KEYS, what)
    kinds = choice(configs, "kind", KINDS, "gyro", what)
    deg = math.radians(1.0)
    sigma = column(configs, "sigma_deg", [DEFAULT_SIGMA_DEG[k] for k in kinds], what,
                   scale=deg, minimum=0.0, maximum=MAX_SIGMA_DEG)
    drift_sigma = column(configs, "drift_sigma_deg", 0.0, what, scale=deg, minimum=0.0,
                         maximum=MAX_SIGMA_DEG)
    drift_tau = column(configs, "drift_tau_s", 600.0, what, minimum=0.0, strictly=True,
                       maximum=ONE_DAY_S)
    drift_a, drift_q = gauss_markov(drift_sigma, drift_tau, dt)
    dev = np.radians(_deviation(configs, kinds))
    return CompassParams(
        magnetic=np.array([k == "magnetic" for k in kinds]), sigma_rad=sigma,
        bias_rad=column(configs, "bias_deg", 0.0, what, scale=deg, minimum=-MAX_BIAS_DEG,
                        maximum=MAX_BIAS_DEG),
        dev_a=dev[0], dev_b=dev[1], dev_c=dev[2], dev_d=dev[3], dev_e=dev[4],
        drift_a=drift_a, drift_q=drift_q, drift_sigma_rad=drift_sigma)


def deviation(params: CompassParams, psi: np.ndarray) -> np.ndarray:
    """Deviation ``A + B sin psi + C cos psi + D sin 2psi + E cos 2psi``, rad, ``(n,)``.

    Args:
        psi: ``(n,)`` heading, rad.
    """
    s, c = np.sin(psi), np.cos(psi)
    s2, c2 = 2.0 * s * c, c * c - s * s
    return (params.dev_a + params.dev_b * s + params.dev_c * c + params.dev_d * s2
            + params.dev_e * c2)


def init(params: CompassParams, normals: np.ndarray) -> CompassState:
    """Compass memory at the start: drift from its stationary distribution.

    Args:
        normals: ``(n, COMPASS_NORMAL_DIMS)`` standard normals (column 1 is used).
    """
    return CompassState(drift_rad=params.drift_sigma_rad * normals[:, 1])


def step(params: CompassParams, state: CompassState, psi: np.ndarray, normals: np.ndarray,
         wave_psi_rad: np.ndarray | None = None) -> tuple[CompassState, np.ndarray]:
    """Advance the compass one step and return its heading reading.

    Args:
        params: from :func:`build`.
        state: from :func:`init` or the previous step.
        psi: ``(n,)`` true heading, rad (row PSI of the truth state).
        normals: ``(n, COMPASS_NORMAL_DIMS)`` standard normals (purpose ``"compass"``).
        wave_psi_rad: optional ``(n,)`` wave-induced yaw, rad
            (:func:`trafficsim.sensors.waves.heading_offset`).

    Returns:
        The new state and the heading reading, ``(n,)`` rad in [0, 2 pi).
    """
    drift = params.drift_a * state.drift_rad + params.drift_q * normals[:, 1]
    hull = psi if wave_psi_rad is None else psi + wave_psi_rad
    reading = hull + params.bias_rad + drift + params.sigma_rad * normals[:, 0]
    if params.has_deviation:
        reading = reading + deviation(params, hull)
    return CompassState(drift_rad=drift), wrap_2pi(reading)
