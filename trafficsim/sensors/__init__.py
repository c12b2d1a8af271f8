"""Own-ship navigation sensors: what a ship's instruments report about its own true state.

One module per instrument, all with the same shape:

* ``build(configs[, dt]) -> Params``: per-ship config dicts (documented keys, units in the key
  names, defaults for missing keys) to a frozen dataclass of ``(n,)`` arrays, built once.
* ``init(params, draws) -> State`` for instruments with memory (stationary start of coloured
  errors), then a pure ``step(params, state, truth, draws) -> (State, reading)``; instruments
  without memory have a pure ``measure(params, truth, draws) -> reading``.
* Nothing draws random numbers: every function takes its draws as ``(n, dims)`` arrays of
  standard normals or uniforms on [0, 1), with ``dims`` given by the module constants
  (``GNSS_NORMAL_DIMS`` ...) and the :data:`trafficsim.noise.PURPOSES` stream named by
  ``*_PURPOSE``. Same draws in, same readings out, and ship ``i``'s reading depends only on
  ship ``i``'s truth, parameters and draws.

Modules: :mod:`.gnss` (position fixes), :mod:`.compass` (gyro and magnetic heading),
:mod:`.speed_log` (EM, Doppler and pulse logs), :mod:`.actuators` (rudder angle and shaft speed
feedback), :mod:`.waves` (wave-frequency motion added to measured heading and position).
Sensors of other ships (radar, AIS) live beside them and use the same helpers.

Settings are refused beyond physical bounds as well as below them (``column``'s ``maximum``):
generous limits no real instrument exceeds, each module giving its reasons; antennas and levers
must also lie on board the ship (:func:`trafficsim.navigation.check_on_board`).

This file holds the small helpers the modules share (config columns, angle wrapping,
first-order Gauss-Markov coefficients). Truth comes as the ``(8, n)`` state of
:mod:`trafficsim.ships.base`.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from trafficsim.errors import InputError
from trafficsim.io.yamlio import finite_number, shown
from trafficsim.jit import inline_kernel

TWO_PI = 2.0 * math.pi
KNOT_MPS = 1852.0 / 3600.0
#: farthest an antenna or log transducer may sit from the reference point in any ship, m (body
#: x and y): half the length of the longest ship built (458 m overall); with the ship file
#: known, its own hull bounds it (:func:`trafficsim.navigation.check_on_board`)
MAX_LEVER_M = 250
#: longest correlation time, outage or coast of an instrument or filter setting, s: one day
#: (a "slowly wandering" error with a longer time is a constant bias over any run)
ONE_DAY_S = 86400


def check_keys(configs: Sequence[Mapping], allowed: Iterable[str], what: str) -> None:
    """Raise :class:`InputError` naming the ship and key if a config has an unknown key."""
    allowed = set(allowed)
    for i, cfg in enumerate(configs):
        unknown = sorted(set(cfg) - allowed)
        if unknown:
            raise InputError(f"unknown key(s) {unknown}; expected some of {sorted(allowed)}",
                             key=f"{what}[{i}]")


_PLAIN_NUMBERS = {float, int}


def column(configs: Sequence[Mapping], key: str, default: float | Sequence[float],
           what: str, scale: float = 1.0, minimum: float | None = None,
           strictly: bool = False, maximum: float | None = None,
           strictly_max: bool = False) -> np.ndarray:
    """``(n,)`` float array of ``cfg.get(key, default) * scale`` over ships.

    Args:
        configs: per-ship config dicts.
        key: config key.
        default: value for ships without the key: one number, or one per ship.
        what: name of the config section, for error messages.
        scale: unit conversion applied after reading (e.g. degrees to radians).
        minimum: if given, values below it (or equal, with ``strictly``) are an error.
        maximum: if given, values above it (or equal, with ``strictly_max``) are an error.
            Both bounds are in the config's unit (before ``scale``).
    """
    n = len(configs)
    defaults = np.broadcast_to(np.asarray(default, dtype=float), (n,)).tolist()
    values = [d if (v := cfg.get(key, None)) is None else v
              for cfg, d in zip(configs, defaults, strict=True)]
    if set(map(type, values)) <= _PLAIN_NUMBERS:  # the common case, at once
        try:
            out = np.array(values, dtype=float)
        except OverflowError:  # an integer beyond the float range: reported below
            out = None
        if (out is not None and np.isfinite(out).all()
                and (minimum is None or not np.any(out <= minimum if strictly else out < minimum))
                and (maximum is None
                     or not np.any(out >= maximum if strictly_max else out > maximum))):
            return out * scale
    out = np.empty(n)
    for i, cfg in enumerate(configs):  # build time only, never on the step path
        raw = cfg.get(key, None)
        value = defaults[i] if raw is None else raw
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise InputError(f"expected a number, got {shown(raw)}", key=f"{what}[{i}].{key}")
        value = finite_number(value)
        if value is None:
            raise InputError(f"expected a finite number, got {shown(raw)}",
                             key=f"{what}[{i}].{key}")
        if minimum is not None and (value < minimum or (strictly and value == minimum)):
            rel = ">" if strictly else ">="
            raise InputError(f"must be {rel} {minimum}, got {value}", key=f"{what}[{i}].{key}")
        if maximum is not None and (value > maximum or (strictly_max and value == maximum)):
            rel = "<" if strictly_max else "<="
            raise InputError(f"must be {rel} {maximum}, got {value}", key=f"{what}[{i}].{key}")
        out[i] = value
    return out * scale


def flags(configs: Sequence[Mapping], key: str, what: str, default: bool = True) -> np.ndarray:
    """``(n,)`` bool array of ``cfg.get(key, default)``; a non-boolean value is an error."""
    out = []
    for i, cfg in enumerate(configs):
        value = cfg.get(key, default)
        if not isinstance(value, bool):
            raise InputError(f"expected true or false, got {value!r}", key=f"{what}[{i}].{key}")
        out.append(value)
    return np.array(out, dtype=bool)


def choice(configs: Sequence[Mapping], key: str, options: Sequence[str], default: str | None,
           what: str) -> list[str]:
    """Per-ship string option; ``default=None`` makes the key required."""
    out = []
    for i, cfg in enumerate(configs):
        value = cfg.get(key, default)
        if value not in options:
            raise InputError(f"expected one of {list(options)}, got {value!r}",
                             key=f"{what}[{i}].{key}")
        out.append(str(value))
    return out


def wrap_2pi(angle: np.ndarray) -> np.ndarray:
    """Angle wrapped to [0, 2 pi), rad (exactly: ``np.mod`` alone can return 2 pi)."""
    out = np.mod(angle, TWO_PI)
    return np.where(out >= TWO_PI, 0.0, out)


@inline_kernel
def mod_2pi_scalar(angle: float) -> float:
    """``np.mod(angle, 2 pi)`` of one angle in a compiled loop, bit for bit; the division only
    outside ``(-2 pi, 2 pi)`` (within it ``fmod`` is exact and the result is ``angle`` or
    ``angle + 2 pi``; the division costs more than the rest of a typical caller)."""
    if 0.0 <= angle < TWO_PI:
        return angle + 0.0  # (-0.0 becomes +0.0, as np.mod gives it)
    if -TWO_PI < angle < 0.0:
        return angle + TWO_PI
    return angle % TWO_PI


@inline_kernel
def wrap_2pi_scalar(angle: float) -> float:
    """:func:`wrap_2pi` of one angle in a compiled loop, bit for bit."""
    out = mod_2pi_scalar(angle)
    return 0.0 if out >= TWO_PI else out


def wrap_pi(angle: np.ndarray) -> np.ndarray:
    """Angle wrapped to [-pi, pi), rad."""
    return wrap_2pi(np.asarray(angle) + math.pi) - math.pi


def gauss_markov(sigma: np.ndarray, tau_s: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discretisation of a first-order Gauss-Markov process, ``b' = -b/tau + noise``.

    Returns ``(a, q)`` with ``b[k+1] = a b[k] + q z``, ``z`` standard normal: ``a = exp(-dt/tau)``
    and ``q = sigma sqrt(1 - a^2)``, so the stationary standard deviation is ``sigma`` at any
    ``dt`` and the autocorrelation at lag ``dt`` is ``a``.

    Args:
        sigma: ``(n,)`` stationary standard deviation (any unit).
        tau_s: ``(n,)`` correlation time, s, > 0.
        dt: time step, s.
    """
    a = np.exp(-float(dt) / tau_s)
    return a, sigma * np.sqrt(1.0 - a * a)


def rotate_body_to_earth(psi: np.ndarray, bx: np.ndarray,
                         by: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """North and east components of the body-frame vector ``(bx, by)`` at heading ``psi``.

    ``north = bx cos psi - by sin psi``, ``east = bx sin psi + by cos psi`` (x forward,
    y starboard, heading clockwise from north) [seed 003, eq 5].
    """
    c, s = np.cos(psi), np.sin(psi)
    return bx * c - by * s, bx * s + by * c
