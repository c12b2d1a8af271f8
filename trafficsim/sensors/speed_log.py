"""Speed logs: electromagnetic (EM), Doppler and pulse (impeller) logs.

What a log measures follows from its physics [seed 002, sec 2.10]:

* EM and pulse logs sense the flow past the hull, so they measure speed THROUGH THE WATER
  (``reference: water``): a current does not change their reading. The pulse log of the
  'Catfish' "measures speed through the water only" [seed 002, sec 3.4].
* A Doppler log in bottom-track mode (sea bed within range, depth < about 400 m) measures
  speed OVER GROUND (``reference: ground``, the default for Doppler); in deep water it tracks a
  water layer 10-30 m down and then measures through the water (``reference: water``).

The log sits at body ``(lever_x_m, lever_y_m)`` from the reference point, so it senses
``u - r y_l`` and ``v + r x_l``. Reading of each channel::

    m = (1 + scale_error) v_true + bias + max(sigma_mps, sigma_rel |v_true|) z

Defaults by ``kind``: ``"em"`` longitudinal only, sigma 0.1 kn (seed 002: EM accuracy 0.1 % of
the range in use); ``"doppler"`` longitudinal and transverse, sigma ``max(0.1 kn, 0.2 % of
the value)`` [seed 002, sec 2.10]; ``"pulse"`` longitudinal only, sigma ``sqrt(0.5) = 0.71
m/s`` (variance of u 0.5 (m/s)^2, "of the order of 1 knot" [seed 002, sec 3.4]).

Without a transverse channel ``v_mps`` is NaN and ``v_valid`` false.

Config keys (per ship): ``kind`` ["em"], ``reference`` [by kind], ``transverse`` [by kind],
``sigma_mps`` [by kind], ``sigma_rel`` [by kind], ``transverse_sigma_mps`` [= sigma_mps],
``scale_error`` [0.0] (fraction, 0.01 = reads 1 % high), ``bias_mps`` [0.0],
``transverse_bias_mps`` [0.0], ``lever_x_m`` [0.0], ``lever_y_m`` [0.0].

Upper bounds, generous limits no real log reaches: ``sigma_mps``, ``transverse_sigma_mps`` and
the biases (in size) at most 5 m/s, about 10 kn (seven times the pulse log's 0.71 m/s, itself
"of the order of 1 knot" [seed 002, sec 3.4]); ``sigma_rel`` and ``scale_error`` (in size)
below 1, an error as large as the speed itself (logs are good to 0.1-2 % of the value or
range [seed 002, sec 2.10]); the transducer within 250 m
(:data:`trafficsim.sensors.MAX_LEVER_M`) of the reference point, and on board the ship's own
hull where the ship file is known.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from trafficsim.errors import InputError
from trafficsim.sensors import KNOT_MPS, MAX_LEVER_M, check_keys, choice, column
from trafficsim.ships.base import Env, R, U, V, ground_velocity_body

#: standard normals per ship per step: longitudinal, transverse
LOG_NORMAL_DIMS = 2
LOG_PURPOSE = "log"

KINDS = ("em", "doppler", "pulse")
DEFAULTS = {  # kind -> (reference, transverse, sigma_mps, sigma_rel)
    "em": ("water", False, 0.1 * KNOT_MPS, 0.0),
    "doppler": ("ground", True, 0.1 * KNOT_MPS, 0.002),  # [seed 002, sec 2.10]
    "pulse": ("water", False, math.sqrt(0.5), 0.0),  # [seed 002, sec 3.4]
}
KEYS = ("kind", "reference", "transverse", "sigma_mps", "sigma_rel", "transverse_sigma_mps",
        "scale_error", "bias_mps", "transverse_bias_mps", "lever_x_m", "lever_y_m")
MAX_ERROR_MPS = 5  # noise and bias: 7 x the pulse log's 0.71 m/s [seed 002, sec 3.4]


@dataclass(frozen=True)
class LogParams:
    """Per-ship log parameters, ``(n,)`` arrays.

    Attributes:
        ground: True = speed over ground (Doppler bottom track), False = through the water.
        transverse: True if the log has a transverse channel.
        sigma_mps, transverse_sigma_mps: noise floor of each channel, m/s.
        sigma_rel: noise proportional to the measured component (-).
        scale_error: scale-factor error (-).
        bias_mps, transverse_bias_mps: constant errors, m/s.
        lever_x_m, lever_y_m: transducer position in the body frame, m.
    """

    ground: np.ndarray
    transverse: np.ndarray
    sigma_mps: np.ndarray
    transverse_sigma_mps: np.ndarray
    sigma_rel: np.ndarray
    scale_error: np.ndarray
    bias_mps: np.ndarray
    transverse_bias_mps: np.ndarray
    lever_x_m: np.ndarray
    lever_y_m: np.ndarray


@dataclass(frozen=True)
class LogReading:
    """Longitudinal ``u_mps`` and transverse ``v_mps`` readings (n,), m/s (body frame); ``v_mps``
    is NaN where ``v_valid`` (n,) is false (no transverse channel)."""

    u_mps: np.ndarray
    v_mps: np.ndarray
    v_valid: np.ndarray


def build(configs: Sequence[Mapping]) -> LogParams:
    """Parameters for ``n`` ships from per-ship config dicts (keys in the module docstring)."""
    what = "log"
    check_keys(configs, KEYS, what)
    kinds = choice(configs, "kind", KINDS, "em", what)
    ground, transverse = [], []
    for i, (cfg, kind) in enumerate(zip(configs, kinds, strict=True)):
        ref_default, trans_default, _, _ = DEFAULTS[kind]
        ref = cfg.get("reference", ref_default)
        if ref not in ("water", "ground"):
            raise InputError(f"expected 'water' or 'ground', got {ref!r}",
                             key=f"{what}[{i}].reference")
        if ref == "ground" and kind != "doppler":
            article = "an EM" if kind == "em" else "a pulse"
            raise InputError(f"{article} log senses the flow past the hull: it measures "
                             "through the water, not over ground", key=f"{what}[{i}].reference")
        trans = cfg.get("transverse", trans_default)
        if not isinstance(trans, bool):
            raise InputError(f"expected true or false, got {trans!r}",
                             key=f"{what}[{i}].transverse")
        if trans and kind == "pulse":
            raise InputError("a pulse (impeller) log has no transverse channel",
                             key=f"{what}[{i}].transverse")
        ground.append(ref == "ground")
        transverse.append(trans)
    sigma = column(configs, "sigma_mps", [DEFAULTS[k][2] for k in kinds], what, minimum=0.0,
                   maximum=MAX_ERROR_MPS)
    return LogParams(
        ground=np.array(ground, dtype=bool), transverse=np.array(transverse, dtype=bool),
        sigma_mps=sigma,
        transverse_sigma_mps=column(configs, "transverse_sigma_mps", sigma, what, minimum=0.0,
                                    maximum=MAX_ERROR_MPS),
        sigma_rel=column(configs, "sigma_rel", [DEFAULTS[k][3] for k in kinds], what,
                         minimum=0.0, maximum=1, strictly_max=True),
        scale_error=column(configs, "scale_error", 0.0, what, minimum=-1.0, strictly=True,
                           maximum=1, strictly_max=True),
        bias_mps=column(configs, "bias_mps", 0.0, what, minimum=-MAX_ERROR_MPS,
                        maximum=MAX_ERROR_MPS),
        transverse_bias_mps=column(configs, "transverse_bias_mps", 0.0, what,
                                   minimum=-MAX_ERROR_MPS, maximum=MAX_ERROR_MPS),
        lever_x_m=column(configs, "lever_x_m", 0.0, what, minimum=-MAX_LEVER_M,
                         maximum=MAX_LEVER_M),
        lever_y_m=column(configs, "lever_y_m", 0.0, what, minimum=-MAX_LEVER_M,
                         maximum=MAX_LEVER_M))


def sensed_velocity(params: LogParams, x: np.ndarray,
                    env: Env) -> tuple[np.ndarray, np.ndarray]:
    """Error-free velocity the log senses, body frame, m/s, ``(n,)`` each.

    Through the water (EM, pulse, Doppler water track) or over ground (Doppler bottom track,
    :func:`trafficsim.ships.base.ground_velocity_body`), at the transducer position.

    Args:
        x: ``(8, n)`` truth state (U, V, R, PSI rows used).
        env: environment (the current matters only for ``ground`` logs).
    """
    ug, vg = ground_velocity_body(x, env)
    u = np.where(params.ground, ug, x[U])
    v = np.where(params.ground, vg, x[V])
    # rigid-body velocity at the transducer: v + r x (r_l), r about the down axis
    return u - x[R] * params.lever_y_m, v + x[R] * params.lever_x_m


def measure(params: LogParams, x: np.ndarray, env: Env, normals: np.ndarray) -> LogReading:
    """The log's reading this step.

    Args:
        params: from :func:`build`.
        x: ``(8, n)`` truth state.
        env: environment (current).
        normals: ``(n, LOG_NORMAL_DIMS)`` standard normals (purpose ``"log"``).
    """
    u, v = sensed_velocity(params, x, env)
    gain = 1.0 + params.scale_error
    sig_u = np.maximum(params.sigma_mps, params.sigma_rel * np.abs(u))
    sig_v = np.maximum(params.transverse_sigma_mps, params.sigma_rel * np.abs(v))
    um = gain * u + params.bias_mps + sig_u * normals[:, 0]
    vm = gain * v + params.transverse_bias_mps + sig_v * normals[:, 1]
    return LogReading(u_mps=um, v_mps=np.where(params.transverse, vm, np.nan),
                      v_valid=params.transverse.copy())
