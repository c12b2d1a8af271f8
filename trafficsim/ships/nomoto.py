"""``nomoto`` family: first-order K-T steering with a first-order surge lag, for cheap traffic.

Steering is Nomoto's first-order model (Nomoto, Taguchi, Honda & Hirano 1957, "On the steering
qualities of ships", Int. Shipbuilding Progress 4(35); Fossen 2011, "Handbook of Marine Craft
Hydrodynamics and Motion Control", ch. 7.2) with Norrbin's (1963) cubic extension (Fossen 2011,
ch. 7.2, non-linear Nomoto models)::

    T r' + r + n3 r^3 = K delta          (n3 = 0: exactly Nomoto's linear model)

with the speed scaling of the non-dimensional indices (Fossen 2011, ch. 7.2; Clarke et al. 1983)
``K = K' u / L``, ``T = T' L / U``, ``n3 = n3' (L / U)^2``. A ship's steady turn, in
``r' = r L / U``, then solves ``r' + n3' r'^3 = K' delta`` at every speed (turning radius in ship
lengths independent of speed) and its response takes the same distance in ship lengths.
``K'``, ``T'``, ``n3'`` are per-ship constants from the ship file.

Why the cubic: linear indices hold for small rudder angles only; a ship's steady yaw rate
saturates. The Mariner's steady ``r L / U`` at 35 deg rudder is 0.28 where the linear
``K' delta`` is 2.36, which would turn it on a circle of 0.85 L instead of 7 L. Ship files fit
``n3'`` to the steady turns (the "spiral curve") of their source model.

Surge balances a thrust and a resistance that are both quadratic, towards a steady speed
proportional to the propeller speed::

    du/dt = (u_ss |u_ss| - u |u|) / (2 U_service T_u),      u_ss(n) = U_service * n / n_service

(``n`` in rev/s, ``U_service`` the ship file's ``service_speed_kn``, ``n_service`` the
propeller speed giving it, ``T_u`` the surge time constant). Linearised about the service speed
this is the first-order lag ``du/dt = (u_ss - u) / T_u``; away from it the quadratic form keeps
what a linear lag loses: resistance fades as the ship slows, so a crash stop takes realistic
distances (Mariner: about 7 L with half-power astern) instead of stopping exponentially fast.
``u_ss`` is negative for ``n < 0``: the family supports astern running
(``supports_astern = True``).

Sway: the model has no sway dynamics; ``v`` is kept at zero (an initial ``v`` decays with the
yaw time constant, ``dv/dt = -v / T``). Wind is not modelled; current enters the kinematics
(:mod:`trafficsim.ships.base`).

Choices:

* ``u`` in ``K = K' u / L`` is the signed surge speed, so going astern the helm acts the other
  way round (the stern goes to the side the rudder is put), as on a real ship; the astern
  rudder effect is not reduced further.
* ``U = max(|u|, U_FLOOR_FRACTION * U_service)`` in ``T`` and ``U_nl = max(U, U_service / 2)``
  in ``n3``: the model is exact from 10 % (linear part) and 50 % (cubic part) of the service
  speed up. The floors keep a stopped ship's yaw damped (a pure ``T' L / |u|`` would let it turn
  for ever) and the cubic bounded (it grows like ``1 / U^2`` and would make the equation stiff).
* With ``n3' = 0``, at constant ``u`` and ``delta`` the yaw rate tends to ``K delta`` with time
  constant ``T`` exactly, so ``K', T'`` identified from trials or from linear manoeuvring
  derivatives (Nomoto's reduction ``T = T1 + T2 - T3`` of the second-order model) carry over.
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

KNOT = 1852.0 / 3600.0  # m/s per knot
#: Floor of the speed in T = T' L / U, as a fraction of the service speed (yaw damped at rest).
U_FLOOR_FRACTION = 0.1


@dataclass(frozen=True)
class NomotoParams:
    """Per-ship constants, each ``(n,)``.

    Attributes:
        K_prime: non-dimensional gain K' (positive: positive rudder turns to starboard).
        T_prime: non-dimensional time constant T' (> 0, directionally stable).
        length_m: ship length L, m.
        u_service: service speed, m/s.
        rps_service: propeller speed at service speed, rev/s.
        surge_tau_s: surge time constant T_u, s.
        n3_prime: non-dimensional Norrbin cubic coefficient n3' (>= 0).
    """

    K_prime: np.ndarray
    T_prime: np.ndarray
    length_m: np.ndarray
    u_service: np.ndarray
    rps_service: np.ndarray
    surge_tau_s: np.ndarray
    n3_prime: np.ndarray


class NomotoFamily:
    """First-order Nomoto (Norrbin) steering with speed-scaled K, T and a first-order surge lag.

    The equations are the compiled scalar kernel :func:`accel` (one ship);
    ``base.accelerations(FAMILY, params, x, env)`` evaluates it for ``(8, n)`` states and the batch
    engine calls it through ``kernels``.
    """

    name = "nomoto"
    supports_astern = True
    coefficients: Mapping[str, float | None] = {
        "K_prime": None,
        "T_prime": None,
        "rps_service": None,
        "surge_tau_s": None,
        "n3_prime": 0.0,
    }
    limits: Mapping[str, Limit] = {
        "K_prime": Limit(gt=0, what="rudder gain; positive rudder turns to starboard"),
        "T_prime": Limit(gt=0, what="yaw time constant; a ship unstable on its own diverges "
                                    "open-loop"),
        "n3_prime": Limit(ge=0, what="Norrbin's cubic yaw damping"),
        "rps_service": Limit(gt=0, what="propeller speed at the service speed"),
        "surge_tau_s": Limit(gt=0, what="surge time constant"),
    }

    def cross_problems(self, ship: Mapping[str, Any]) -> list[tuple[str, str]]:
        """The service speed must be within the engine's reach (``rps_max``)."""
        rps_max, rps_service = (float(ship["actuators"]["rps_max"]),
                                float(ship["coefficients"]["rps_service"]))
        if rps_max < rps_service:
            return [("actuators.rps_max", f"must be >= coefficients.rps_service "
                                          f"({rps_service:g}, the propeller speed at the "
                                          f"service speed), got {rps_max:g}")]
        return []

    def build(self, ships: Sequence[Mapping[str, Any]]) -> NomotoParams:
        """Gather K', T', n3', length, service speed and surge constants into ``(n,)`` arrays."""
        c = [s["coefficients"] for s in ships]
        t_prime, n3_prime = stack(c, "T_prime"), stack(c, "n3_prime", 0.0)
        for ship, t, n3 in zip(ships, t_prime, n3_prime, strict=True):
            # a first-order model of an unstable ship (T' < 0) diverges open-loop
            if not (t > 0.0 and n3 >= 0.0):
                raise ShipLibraryError(
                    f"nomoto ship '{ship.get('name', '?')}': expected T_prime > 0 and "
                    f"n3_prime >= 0, got {t} and {n3}", path=ship.get("path"),
                    key="coefficients")
        return NomotoParams(
            K_prime=stack(c, "K_prime"),
            T_prime=t_prime,
            length_m=stack([s["particulars"] for s in ships], "length_m"),
            u_service=stack(ships, "service_speed_kn") * KNOT,
            rps_service=stack(c, "rps_service"),
            surge_tau_s=stack(c, "surge_tau_s"),
            n3_prime=n3_prime,
        )


# Columns of the packed parameter row (``base.pack``): the NomotoParams fields in order.
_K_PRIME, _T_PRIME, _LENGTH_M, _U_SERVICE, _RPS_SERVICE, _SURGE_TAU_S, _N3_PRIME = range(7)


@kernel
def accel(p: np.ndarray, x: np.ndarray, env: np.ndarray) -> tuple[float, float, float]:
    """Body-frame accelerations of ONE ship of the K-T / surge-lag model (module docstring).

    Args:
        p: ``float64[7]`` packed parameter row (``base.pack(params)[i]``, see
            :class:`NomotoParams`).
        x: ``float64[8]`` state in the ``base`` layout (u, v in m/s relative to the water, r and
            rudder in rad, RPS in rev/s).
        env: ``float64[4]`` (current north, current east, wind speed, wind from); unused (no wind
            model; current is in the kinematics).

    Returns:
        ``(du, dv, dr)`` in m/s2, m/s2, rad/s2.
    """
    u = x[U]
    length, u_service = p[_LENGTH_M], p[_U_SERVICE]
    u_eff = max(abs(u), U_FLOOR_FRACTION * u_service)
    inv_T = u_eff / (p[_T_PRIME] * length)  # 1 / T, T = T' L / U
    K = p[_K_PRIME] * u / length  # K = K' u / L
    r = x[YAW_RATE]
    l_over_u = length / max(u_eff, 0.5 * u_service)
    cubic = p[_N3_PRIME] * (l_over_u * l_over_u) * r * r * r  # n3 r^3, n3 = n3' (L/U)^2
    dr = (K * x[RUDDER] - r - cubic) * inv_T
    u_ss = u_service * x[RPS] / p[_RPS_SERVICE]
    du = (u_ss * abs(u_ss) - u * abs(u)) / (2.0 * u_service * p[_SURGE_TAU_S])
    dv = -x[V] * inv_T
    return du, dv, dr


FAMILY = register(NomotoFamily())
