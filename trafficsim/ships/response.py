"""``response`` family: the identified polynomial manoeuvring model of Shi et al. [seed 001, eq 2].

The model (Shi, Zhao, Peng & Shen 2009, TransNav 3(1):105-110) is three polynomials in the
surge and sway velocities ``u, v``, the yaw rate ``r``, the rudder angle ``delta`` and the
propeller speed ``n`` [seed 001, eq 2]::

    du/dt = a1 u^2 + a2 v^2 + a3 r^2 + a4 delta^2 + a5 v r + a6 v delta + a7 r delta
            + a8 u n + a9 n^2
    dv/dt = b1 v + b2 r + b3 delta + b4 u r
    dr/dt = c1 v + c2 r + c3 delta

Its 16 parameters were identified with an extended Kalman filter from simulator zig-zag data
sampled at T = 2 s [seed 001, sec 4.1, eq 4]; the Euler form ``x(k+1) = x(k) + T f`` of eq 4 makes
them continuous-time coefficients per second.

Units of the coefficients (the paper does not state them; they are inferred and stated here):
ship files hold ``a1..c3`` in the paper's units, which are

* ``u, v`` in m/s, time in s;
* ``r`` in deg/s and ``delta`` in deg (the simulator records heading and rudder in degrees and
  ``r`` is derived from the heading [seed 001, sec 4.1]). With ``r`` and ``delta`` in degrees the
  yaw coefficient ``c1`` matches the order of a hull's ``N_v/(I_z - N_rdot)`` and the
  rudder-drag term ``a4 delta^2`` is a sizeable fraction of the thrust; in radians both would be
  negligible. The same reading reproduces the identified model's turning indices of
  [seed 001, table 2] (advance 805, transfer 525, diameter 978 m): the paper gives neither rudder
  angle nor speed; fitted to the advance and the transfer (21.4 deg rudder from 45.9 rpm,
  7.0 kn), the tactical diameter comes out 1023 m, 4.6 % above the table
  (``tests/ships/test_response.py``);
* ``n`` in rev/min ("propeller RPM" [seed 001, sec 2]).

Conversion to SI inside (``D = 180/pi`` deg per rad, 60 rpm per rev/s): with ``r, delta`` in rad
and ``n`` in rev/s, ``du/dt`` in m/s2 uses ``a3 D^2, a4 D^2, a5 D, a6 D, a7 D^2, 60 a8,
3600 a9``; ``dv/dt`` in m/s2 uses ``b2 D, b3 D, b4 D``; ``dr/dt`` in rad/s2 is the paper's deg/s2
divided by ``D``, i.e. ``c1 / D, c2, c3``.

Table 1 prints ``a1 = +1.4347e-4``. With that sign ``a8^2 - 4 a1 a9 < 0`` and ``du/dt > 0`` at
every speed in straight running, so the ship would never reach a steady speed; the ship file
(``bulk_carrier.yaml``) uses ``a1 = -1.4347e-4``, the only single sign change that gives a stable
straight run (``u = 0.0781`` m/s per rpm). The identified sway-yaw part is straight-line stable
only while ``b1 c2 - (b2 + b4 u) c1 > 0``, i.e. for ``u < 7.72`` m/s; the ship file's ``rps_max``
keeps the ship below that.

Sign conventions: the paper's frame has x forward, y to starboard and ``r`` positive turning to
starboard [seed 001, sec 2, fig 1], the same as ours. With the identified ``c3 > 0`` and
``c2 < 0`` a positive rudder angle gives a positive (starboard) steady yaw rate, so no sign flip is
needed; a ship file with ``c3 < 0`` would be a ship whose positive helm turns to port.

Two guards keep the polynomial sane outside the straight-ahead regime it was expanded about
[seed 001, sec 2] (both leave the paper's model unchanged for ``u >= rudder_fade_speed_mps``):

* resistance ``a1 u|u|`` instead of ``a1 u^2``, so that it always opposes the motion;
* the rudder terms (``a4, a6, a7, b3, c3``) are scaled by ``min(1, (u / u_fade)^2)``: rudder force
  grows with the square of the inflow speed, and without the fade a ship at rest with helm on
  would turn on the spot.

Astern: the propeller enters only through ``a8 u n + a9 n^2``. With the identified ``a9 > 0`` the
``n^2`` term pushes the ship ahead whatever the sign of ``n``, so the form cannot reverse thrust:
``supports_astern = False`` and negative propeller speeds act as a stopped engine (``n = 0``).
Wind is not modelled (the identification data were taken without wind [seed 001, sec 4]).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.errors import ShipLibraryError
from trafficsim.jit import kernel
from trafficsim.ships.base import RPS, RUDDER, Limit, U, V, register, stack
from trafficsim.ships.base import R as YAW_RATE

DEG_PER_RAD = 180.0 / np.pi
RPM_PER_RPS = 60.0

_NAMES = ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8", "a9", "b1", "b2", "b3", "b4",
          "c1", "c2", "c3")


@dataclass(frozen=True)
class ResponseParams:
    """SI coefficients of [seed 001, eq 2], each ``(n,)``; see the module docstring for units.

    Attributes:
        A1..A9: surge terms, m/s2 per (unit of the SI product they multiply).
        B1..B4: sway terms, C1..C3: yaw terms.
        u_fade: speed below which the rudder terms fade out, m/s.
    """

    A1: np.ndarray
    A2: np.ndarray
    A3: np.ndarray
    A4: np.ndarray
    A5: np.ndarray
    A6: np.ndarray
    A7: np.ndarray
    A8: np.ndarray
    A9: np.ndarray
    B1: np.ndarray
    B2: np.ndarray
    B3: np.ndarray
    B4: np.ndarray
    C1: np.ndarray
    C2: np.ndarray
    C3: np.ndarray
    u_fade: np.ndarray


class ResponseFamily:
    """Identified polynomial response model [seed 001, eq 2, table 1].

    The equations are the compiled scalar kernel :func:`accel` (one ship);
    ``base.accelerations(FAMILY, params, x, env)`` evaluates it for ``(8, n)`` states and the batch
    engine calls it through ``kernels``.
    """

    name = "response"
    supports_astern = False
    coefficients: Mapping[str, float | None] = {
        **{k: None for k in _NAMES},
        "rudder_fade_speed_mps": 1.0,
    }
    limits: Mapping[str, Limit] = {
        "rudder_fade_speed_mps": Limit(gt=0, what="speed below which the rudder fades; 0 "
                                                  "would turn a ship at rest"),
    }

    def cross_problems(self, ship: Mapping[str, Any]) -> list[tuple[str, str]]:
        """No checks between numbers beyond the ranges of :attr:`limits`."""
        return []

    def build(self, ships: Sequence[Mapping[str, Any]]) -> ResponseParams:
        """Convert the paper-unit coefficients of each ship file to SI ``(n,)`` arrays."""
        c = [s["coefficients"] for s in ships]
        p = {k: stack(c, k) for k in _NAMES}
        u_fade = stack(c, "rudder_fade_speed_mps", 1.0)
        for ship, fade in zip(ships, u_fade, strict=True):
            if not fade > 0.0:  # (0 makes the fade 0/0 at rest: a ship at rest would turn)
                raise ShipLibraryError(
                    f"response ship '{ship.get('name', '?')}': expected rudder_fade_speed_mps "
                    f"> 0, got {fade}", path=ship.get("path"),
                    key="coefficients.rudder_fade_speed_mps")
        D, N = DEG_PER_RAD, RPM_PER_RPS
        return ResponseParams(
            A1=p["a1"], A2=p["a2"], A3=p["a3"] * D**2, A4=p["a4"] * D**2, A5=p["a5"] * D,
            A6=p["a6"] * D, A7=p["a7"] * D**2, A8=p["a8"] * N, A9=p["a9"] * N**2,
            B1=p["b1"], B2=p["b2"] * D, B3=p["b3"] * D, B4=p["b4"] * D,
            C1=p["c1"] / D, C2=p["c2"], C3=p["c3"],
            u_fade=u_fade,
        )


# Columns of the packed parameter row (``base.pack``): the ResponseParams fields in order.
(_A1, _A2, _A3, _A4, _A5, _A6, _A7, _A8, _A9, _B1, _B2, _B3, _B4, _C1, _C2, _C3,
 _U_FADE) = range(17)


@kernel
def accel(p: np.ndarray, x: np.ndarray, env: np.ndarray) -> tuple[float, float, float]:
    """Body-frame accelerations of ONE ship [seed 001, eq 2] in SI, with the two guards of the
    module docstring (``a1 u|u|`` resistance, rudder terms faded below ``u_fade``).

    Args:
        p: ``float64[17]`` packed parameter row (``base.pack(params)[i]``, SI, see
            :class:`ResponseParams`).
        x: ``float64[8]`` state in the ``base`` layout (u, v in m/s relative to the water, r and
            rudder in rad, RPS in rev/s).
        env: ``float64[4]`` (current north, current east, wind speed, wind from); unused (no wind
            model; current is in the kinematics).

    Returns:
        ``(du, dv, dr)`` in m/s2, m/s2, rad/s2.
    """
    u, v, r = x[U], x[V], x[YAW_RATE]
    n = max(x[RPS], 0.0)  # the n^2 form cannot give astern thrust
    q = u / p[_U_FADE]
    fade = min(1.0, q * q)
    d = x[RUDDER]
    du = (p[_A1] * u * abs(u) + p[_A2] * v * v + p[_A3] * r * r + p[_A5] * v * r
          + fade * (p[_A4] * d * d + p[_A6] * v * d + p[_A7] * r * d)
          + p[_A8] * u * n + p[_A9] * n * n)
    dv = p[_B1] * v + p[_B2] * r + p[_B4] * u * r + fade * p[_B3] * d
    dr = p[_C1] * v + p[_C2] * r + fade * p[_C3] * d
    return du, dv, dr


FAMILY = register(ResponseFamily())
