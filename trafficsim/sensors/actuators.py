"""Feedback sensors of the actuators: rudder angle indicator and shaft speed (rpm) sensor.

Each reading is ``quantise(truth + bias + sigma z, resolution)`` with mid-tread rounding to the
nearest multiple of the resolution (an A/D converter or a digital indicator; resolution 0 =
analogue). Rounding a signal that spreads over many steps leaves an error uniform on
``[-q/2, q/2]`` (variance ``q^2 / 12``).

Seed 002 measured rudder angle with an LVDT on the hydraulic ram and engine revolutions with a
pulse tachometer, and ignored both sensors' variances (sec 3.4): the defaults are therefore
perfect sensors; configure noise, bias and resolution per ship.

Config keys (per ship): ``rudder_sigma_deg`` [0.0], ``rudder_bias_deg`` [0.0],
``rudder_resolution_deg`` [0.0], ``shaft_sigma_rpm`` [0.0], ``shaft_bias_rpm`` [0.0],
``shaft_resolution_rpm`` [0.0]. Readings are in SI (rad, rev/s) like the truth rows RUDDER, RPS.

Upper bounds, generous limits no real indicator reaches: the rudder's noise, bias (in size) and
resolution at most 10 deg (more than a quarter of a 35 deg helm; seed 002's LVDT reads the ram
directly [sec 3.4]), the shaft's at most 120 rpm (the whole range of a slow-speed diesel, a few
per cent of a small craft's engine speed).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from trafficsim.sensors import check_keys, column
from trafficsim.ships.base import RPS, RUDDER

#: standard normals per ship per step: rudder, shaft
ACTUATOR_NORMAL_DIMS = 2
ACTUATOR_PURPOSE = "actuators"

KEYS = ("rudder_sigma_deg", "rudder_bias_deg", "rudder_resolution_deg", "shaft_sigma_rpm",
        "shaft_bias_rpm", "shaft_resolution_rpm")
MAX_RUDDER_ERROR_DEG = 10  # over a quarter of a 35 deg helm
MAX_SHAFT_ERROR_RPM = 120  # the whole range of a slow-speed diesel


@dataclass(frozen=True)
class ActuatorSensorParams:
    """Per-ship parameters, ``(n,)`` arrays: rudder in rad, shaft in rev/s.

    Attributes:
        rudder_sigma_rad, rudder_bias_rad, rudder_resolution_rad: rudder indicator.
        shaft_sigma_rps, shaft_bias_rps, shaft_resolution_rps: shaft speed sensor.
    """

    rudder_sigma_rad: np.ndarray
    rudder_bias_rad: np.ndarray
    rudder_resolution_rad: np.ndarray
    shaft_sigma_rps: np.ndarray
    shaft_bias_rps: np.ndarray
    shaft_resolution_rps: np.ndarray


@dataclass(frozen=True)
class ActuatorReading:
    """``rudder_rad`` (n,) rudder angle reading, rad (+ = starboard helm); ``rps`` (n,) shaft
    speed reading, rev/s."""

    rudder_rad: np.ndarray
    rps: np.ndarray


def build(configs: Sequence[Mapping]) -> ActuatorSensorParams:
    """Parameters for ``n`` ships from per-ship config dicts (keys in the module docstring)."""
    what = "actuators"
    check_keys(configs, KEYS, what)
    deg, rpm = math.radians(1.0), 1.0 / 60.0
    rud, shaft = MAX_RUDDER_ERROR_DEG, MAX_SHAFT_ERROR_RPM
    return ActuatorSensorParams(
        rudder_sigma_rad=column(configs, "rudder_sigma_deg", 0.0, what, deg, minimum=0.0,
                                maximum=rud),
        rudder_bias_rad=column(configs, "rudder_bias_deg", 0.0, what, deg, minimum=-rud,
                               maximum=rud),
        rudder_resolution_rad=column(configs, "rudder_resolution_deg", 0.0, what, deg,
                                     minimum=0.0, maximum=rud),
        shaft_sigma_rps=column(configs, "shaft_sigma_rpm", 0.0, what, rpm, minimum=0.0,
                               maximum=shaft),
        shaft_bias_rps=column(configs, "shaft_bias_rpm", 0.0, what, rpm, minimum=-shaft,
                              maximum=shaft),
        shaft_resolution_rps=column(configs, "shaft_resolution_rpm", 0.0, what, rpm,
                                    minimum=0.0, maximum=shaft))


def quantise(value: np.ndarray, resolution: np.ndarray) -> np.ndarray:
    """Round ``value`` to the nearest multiple of ``resolution`` (unchanged where it is 0).

    Args:
        value, resolution: ``(n,)`` arrays in the same unit.
    """
    step = np.where(resolution > 0.0, resolution, 1.0)
    return np.where(resolution > 0.0, np.round(value / step) * step, value)


def measure(params: ActuatorSensorParams, x: np.ndarray,
            normals: np.ndarray) -> ActuatorReading:
    """Rudder angle and shaft speed readings this step.

    Args:
        params: from :func:`build`.
        x: ``(8, n)`` truth state (RUDDER = actual rudder angle, rad; RPS, rev/s).
        normals: ``(n, ACTUATOR_NORMAL_DIMS)`` standard normals (purpose ``"actuators"``).
    """
    rudder = x[RUDDER] + params.rudder_bias_rad + params.rudder_sigma_rad * normals[:, 0]
    rps = x[RPS] + params.shaft_bias_rps + params.shaft_sigma_rps * normals[:, 1]
    return ActuatorReading(rudder_rad=quantise(rudder, params.rudder_resolution_rad),
                           rps=quantise(rps, params.shaft_resolution_rps))
