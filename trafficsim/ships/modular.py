"""The ``modular`` family: the 3-DOF modular model of the catamaran 'Catfish' [seed 002, ch 4].

Equations [seed 002, eqs 4.1-4.6, 4.9], origin at the mass centre, forces split into hull (H),
propeller (P), rudder (R) and disturbance (D) modules::

    (m - X_udot) du             = X_H + X_P + X_R + m v r
    (m - Y_vdot) dv - Y_rdot dr = Y_H + Y_P + Y_R - m u r
    (I_z - N_rdot) dr - N_vdot dv = N_H + N_P + N_R

    X_H = X_uu u|u| + X_vv v^2
    Y_H = Y_v v + Y_r r + Y_vvv v^3 + Y_rvv r v^2      (Y_v, Y_r ~ U;  Y_vvv, Y_rvv ~ 1/U)
    N_H = N_v v + N_r r + N_vvv v^3 + N_rvv r v^2      (likewise)
    X_P = X_nn n|n|,   Y_P = Y_n n,   N_P = N_n n       (n = shaft speed, rad/s)
    X_R = X_dd d^2
    Y_R = Y_d d + Y_dd d^2 + Y_ddd d^3                  (all rudder terms ~ U^2 / U_cal)
    N_R = N_d d + N_dd d^2 + N_ddd d^3 + N_ndd n^2 d^2

The disturbance module D is empty here: a uniform current enters through the water-relative
velocities (``trafficsim.ships.base``) and the wind coefficients X_ua, Y_va, N_va are 0 in tables
4.1-4.3. Mass m = 8500 kg and I_z = 117469 kg m2 [seed 002, appendix D] are ship-file particulars.

Units and signs
---------------
* Rudder: the thesis' positive rudder turns the boat to PORT (N_d < 0 with r positive clockwise;
  the group's Nomoto gain K_n = -0.3617 1/s [seed 002, appended paper eq 8]). The ship file keeps
  the printed coefficients and signs; this family uses ``d = -x[RUDDER]`` so that a positive
  RUDDER turns to starboard as the project requires.
* Propeller: the thesis' n is the shaft speed in rad/s (see X_nn); ``base`` carries propeller
  rev/s, so ``n = 2 pi RPS``; engine rpm = ``60 * gear_ratio * RPS`` with the engine/screw
  reduction 1.66:1 [seed 002, ch 3.2]: 2500 engine rpm (rated power) is ``rps_max`` = 25.1 rev/s.
  The thesis has no astern thrust (X_nn n^2 only): ``supports_astern = False``, ``rps_min = 0``.
* Prime coefficients are made dimensional with rho = 1025 kg/m3, L = 11.17 m (overall length with
  rudders [seed 002, ch 3.2]) and U = sqrt(u^2 + v^2), re-dimensionalised at every call as the
  thesis does "at each sampling instant" [seed 002, appended paper, 'State-space model'].

Reading of the printed tables
-----------------------------
The tables are OCR of a scanned thesis. The yardstick for every ambiguous item is the thesis' own
numerical F for Catfish [seed 002, eq 9.9 = appended paper eq 9]: X2 = 0.004, X4 = -0.138,
Y1 = 0.573, Y6 = -0.308, Y8 = 1, N1 = -0.273, N6 = -0.092, N8 = -1.444, T_R = 1 s, T_N = 2 s.
With the readings below, appendix D evaluated at 8.9 kn (the 2200 rpm speed) reproduces all ten
entries within 0.5 % (tested); no other reading found does. "U_cal" is 8.9 kn = 4.579 m/s.

==================  ===================  ===================================================
printed             used                 why
==================  ===================  ===================================================
X_udot -0.000624,   x 0.5 rho L^3        printed factor is not a mass; SNAME factor (-446 kg,
 "0.5 rho L^2"                           5 %); with it X4 = -0.138 as eq 9.9 (L^2: -0.145)
X_uu -269.84,       -269.84 N s2/m2      already dimensional (with the factor the resistance
 "0.5 rho L^2 U"                         at 9 kn would be 1.7e9 N); X4 = X_uu u/(m - X_udot)
                                         = -0.138 at 8.9 kn as eq 9.9
X_vv -0.00758,      x 0.5 rho L^2        printed factor is one L short (not kg/m); SNAME
 "0.5 rho L"
X_dd -0.005173,     x 0.5 rho L^2 U^2    a rudder term: scaled like Y_d (see Y_d)
                     / U_cal
 "0.5 rho L^2"
X_nn 0.2772         0.2772 N s2/rad2,    steady u = n sqrt(X_nn / -X_uu): 8.65 kn at 2200 rpm,
                    n = shaft rad/s      4.32 kn at 1100 rpm (stated 8.9 and 4.2). u ~ n is
                                         forced by X_u = X_uuu = X_un = 0, and +-2.9 % is the
                                         best a proportional law can do (speed ratio 2.12 for
                                         2x rpm): the printed value is that minimax fit.
                                         X2 = X_nn n/(m - X_udot) = 0.0044 (printed 0.004);
                                         the 'forward speed of 4.455 m/s' of the appended
                                         paper's Nomoto constants is this 2200 rpm speed
X_u, X_uuu, X_un,   omitted              0.0 in table 4.1
 X_rr, X_ua 0.0
row 'Y_n-dot' 0.0   Y_n = 0 (optional)   eq 4.5 Y_nn n_A: side thrust of same-handed screws
row 'Y_v-dot'       Y_v = -0.018         the four rows after Y_n are Y_v, Y_vdot, Y_r, Y_rdot
 -0.018 (no factor)  x 0.5 rho L^2 U     (as eq 4.5 orders them); the printed factors of rows
                                         2-4 (L^3, L^3 U, L^4) then fit exactly. Y6 = -0.308
row 'Y_r-dot'       Y_vdot = -0.0111     printed factor L^3 is the Y_vdot one; ~ -m' (-0.0119).
 -0.0111, L^3        x 0.5 rho L^3       Reading -0.018 as Y_vdot and -0.0111 as Y_v gives
                                         Y6 = -0.15: rejected
row 'Y_r' 0.004,    Y_r = +0.004         factor fits; Y8 = 0.998 (printed 1). As Y_v (the
 L^3 U               x 0.5 rho L^3 U     other reading) +0.004 would be a destabilising sway
                                         force: rejected
row 'Y_r-dot'       Y_rdot = -0.000288   factor fits
 -0.000288, L^4      x 0.5 rho L^4
Y_vv -0.08          Y_vvv (v^3)          eq 4.5 writes 'Y_vv v^3'; factor L^2/U is the v^3 one
 0.5 rho L^2/U
Y_rv 0.15           Y_rvv (r v^2)        eq 4.5 '+ Y_rv r v^2', factor L^3/U; sign of eq 4.5
 0.5 rho L^3/U       x 0.5 rho L^3/U     (appendix D prints '- Y_rv r v': a sign slip)
Y_d 0.0299621       x 0.5 rho L^2 U^2    the printed factor, over U_cal: with U^2 alone eq 9.9's
 0.5 rho L^2 U^2     / U_cal             rudder column comes out 4.6x too large (Y1 = 2.62,
                                         N1 = -1.25) and r/d = 2.9 1/s; over U_cal,
                                         Y1 = 0.572, N1 = -0.272 at 8.9 kn and the linear
                                         yaw-rate gain r/d = 0.63 1/s there against 0.599
                                         1/s of the group's transfer function G3 [appended
                                         paper eq 13]. Rudder lift grows as U^2 and the hull
                                         forces as U, so r/d grows as U and the turning
                                         circle keeps its size at every speed
Y_dd -0.023234      x 0.5 rho L^2 U^2    even term = the turning asymmetry; sign of eq 4.5 (+)
Y_ddd 0.1818182     x 0.5 rho L^2 U^2    as printed (same sign as Y_d)
row 'Y_va', Y_dv    omitted              wind and d v^2 terms, 0.0
row 'N_n-dot' 0.0   N_n = 0 (optional)   eq 4.6 N_nn n_A: moment of same-handed screws
row 'N_v-dot'       N_v = -0.01          rows as for sway: N_v, N_vdot, N_r, N_rdot; the
 -0.01, "0.5 rho     x 0.5 rho L^3 U     printed 'L U' is L^3 U with the cube lost.
 L U"                                    N6 = -0.092
row 'N_r-dot'       N_vdot = -0.004054   printed factor L^4 is the N_vdot one
 -0.004054, L^4      x 0.5 rho L^4
N_r -0.0089, L^4 U  x 0.5 rho L^4 U      as printed; N8 = -1.441 (printed -1.444)
row 'N_r-dot'       N_rdot = -0.001464   factor fits; ~ -I_z' (-0.00132)
 -0.001464, L^5      x 0.5 rho L^5
N_vv 0.016, N_rv    N_vvv, N_rvv          as Y_vvv, Y_rvv (factors L^3/U, L^4/U; eq 4.6 signs)
 -0.05
N_d -0.014981,      x 0.5 rho L^3 U^2    as Y_d (over U_cal). N_d/Y_d = N_dd/Y_dd =
 N_dd 0.0116172,                         N_ddd/Y_ddd = -0.5 in prime terms: one rudder force
                                         at x = -L/2 (stern)
 N_ddd -0.090909
N_ndd n^2 d^2       N_ndd = 0, optional  the "further coefficient" of ch 4.6 has no printed
 (ch 4.6, no value)  (N m s2/rad4)       value; the printed asymmetry is the even rudder terms
app. D 'Y_dd',      Y_theta = Y_rdot/(m - Y_vdot), N_theta = N_vdot/(I_z - N_rdot): the
 'N_dd' in factors  added-mass coupling of the mass matrix (OCR turned theta into delta)
app. D X6           (X_vv v + m r)/(m - X_udot): eq 4.1 gives + m r v (printed '- m r')
app. D Y4, N4       -m r/((m - Y_vdot) D) and -N_theta m r/((m - Y_vdot) D): the printed forms
                    lack the division by m - Y_vdot (dimensionally wrong)
==================  ===================  ===================================================

Behaviour (tested): 8.65 kn at 2200 rpm, 4.32 kn at 1100 rpm, 9.83 kn at 2500 rpm. Steady turning
diameters to starboard / port: 187 / 206 m at 5 deg, 107 / 123 m at 10 deg, 76 / 89 m at 15 deg,
31 / 37 m at 35 deg, the same from every approach speed (all forces grow as U^2 in a turn whose
velocities scale with U). The thesis states that turning circles to the
two sides differ "due to rotation of both propellers in the same direction" [seed 002, ch 4.6] but
not which side is tighter; with the printed even rudder terms and the sign flip, starboard is.
Setting Y_dd = N_dd = N_ndd = 0 (and Y_n = N_n = 0) makes the model mirror-symmetric.

Validity: acceptable up to 15 deg rudder [seed 002, ch 4.6]. The positive cubic rudder term
makes the rudder force 2.8x (port) to 3.7x (starboard) the linear value at 35 deg, so hard-over
turns are probably tighter than the real boat's.

``linearised_F`` gives the state-dependent F of eq 4.10 (appendix D) for the later EKF.

Yaw dynamics: the sway-yaw block of F at 4.455 m/s has the poles -0.385 and -1.317 1/s, so its
slow time constant, 2.60 s, is the group's T2 = 2.581 s [appended paper eq 8; ch 9.4 "2.6
seconds"] (tested). That F has no Coriolis term -m u in its r column (appendix D puts -m u r in
the u column, where it vanishes at r = 0); the model keeps eq 4.2's -m u r, whose linearisation
has the poles -0.167 and -1.229 1/s, so the boat answers the rudder more slowly than eq 8's
constants say (63 % of the steady yaw rate after about 5 s instead of about 3.8 s).

Implementation: the force equations exist once, in the compiled scalar kernel ``accel`` (numba,
one ship, parameters packed in the field order of ``ModularParams``); ``linearised_F`` is a
vectorised numpy function for offline use that shares the kernel's rudder-sign, shaft-speed and
mass-matrix helpers.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.errors import ShipLibraryError
from trafficsim.jit import kernel
from trafficsim.ships.base import (
    EAST,
    N_STATE,
    NORTH,
    PSI,
    RHO_WATER,
    RPS,
    RUDDER,
    Limit,
    R,
    U,
    V,
    register,
    stack,
)

#: Speed at which the printed rudder coefficients, with table 4.2's factor U^2, give eq 9.9's
#: rudder column: 8.9 kn, the 2200 rpm speed (see the module table); the rudder terms are
#: ``coefficient * 0.5 rho L^k U^2 / U_CAL_MPS``.
U_CAL_MPS = 8.9 * 1852.0 / 3600.0
#: Eq 4.10 state order (delta_A, n_A, x, u, y, v, psi, r) as indices into the base state:
#: ``F[np.ix_(EQ410_ORDER, EQ410_ORDER)]`` lays ``linearised_F`` out as the thesis prints it.
EQ410_ORDER = (RUDDER, RPS, NORTH, U, EAST, V, PSI, R)
_TWO_PI = 2.0 * math.pi
_U_FLOOR = 1e-6  # m/s; the 1/U terms are bounded (|v| <= U) so the floor only avoids 0/0

_PARTICULARS = ("mass_kg", "yaw_inertia_kgm2", "gear_ratio")


@dataclass(frozen=True)
class ModularParams:
    """Dimensional coefficients, ``(n,)`` arrays (SI; angles in rad, n in shaft rad/s).

    Terms marked ``*U`` are multiplied by U (m/s) at run time, ``/U`` divided by U.
    """

    mass: np.ndarray  # m, kg
    m11: np.ndarray  # m - X_udot, kg
    m22: np.ndarray  # m - Y_vdot, kg
    m33: np.ndarray  # I_z - N_rdot, kg m2
    y_rdot: np.ndarray  # Y_rdot, kg m
    n_vdot: np.ndarray  # N_vdot, kg m
    x_uu: np.ndarray  # N s2/m2
    x_vv: np.ndarray  # N s2/m2
    x_dd: np.ndarray  # *U, N s/(m rad2)
    x_nn: np.ndarray  # N s2/rad2
    y_v: np.ndarray  # *U
    y_r: np.ndarray  # *U
    y_vvv: np.ndarray  # /U
    y_rvv: np.ndarray  # /U
    y_d: np.ndarray  # *U
    y_dd: np.ndarray  # *U
    y_ddd: np.ndarray  # *U
    y_n: np.ndarray  # N s/rad
    n_v: np.ndarray  # *U
    n_r: np.ndarray  # *U
    n_vvv: np.ndarray  # /U
    n_rvv: np.ndarray  # /U
    n_d: np.ndarray  # *U
    n_dd: np.ndarray  # *U
    n_ddd: np.ndarray  # *U
    n_n: np.ndarray  # N m s/rad
    n_ndd: np.ndarray  # N m s2/rad4
    gear_ratio: np.ndarray  # engine rpm / screw rpm
    tau_rudder_s: np.ndarray  # T_R of eq 4.7 (for linearised_F)
    tau_engine_s: np.ndarray  # T_N of eq 4.8 (for linearised_F)


def _particulars(ships: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    out = []
    for ship in ships:
        p = ship["particulars"]
        missing = [k for k in _PARTICULARS if k not in p]
        if missing:
            raise ShipLibraryError(
                f"model 'modular' needs particulars {', '.join(missing)} "
                "(mass kg, yaw moment of inertia kg m2, engine/screw gear ratio)",
                path=ship.get("path"), key="particulars")
        out.append(p)
    return out


class ModularFamily:
    """Hull + propeller + rudder modules of [seed 002, eqs 4.4-4.9].

    The equations are the compiled scalar kernel :func:`accel` (one ship);
    ``base.accelerations(FAMILY, params, x, env)`` evaluates it for ``(8, n)`` states and the batch
    engine calls it through ``kernels``.
    """

    name = "modular"
    supports_astern = False
    coefficients: Mapping[str, float | None] = {
        "X_udot": None, "X_uu": None, "X_vv": None, "X_dd": None, "X_nn": None,
        "Y_v": None, "Y_vdot": None, "Y_r": None, "Y_rdot": None, "Y_vvv": None, "Y_rvv": None,
        "Y_d": None, "Y_dd": None, "Y_ddd": None,
        "N_v": None, "N_vdot": None, "N_r": None, "N_rdot": None, "N_vvv": None, "N_rvv": None,
        "N_d": None, "N_dd": None, "N_ddd": None,
        "Y_n": 0.0, "N_n": 0.0, "N_ndd": 0.0,
    }
    limits: Mapping[str, Limit] = {
        "X_udot": Limit(le=0, what="surge added mass derivative, -m_x"),
        "Y_vdot": Limit(le=0, what="sway added mass derivative, -m_y"),
        "N_rdot": Limit(le=0, what="yaw added inertia derivative, -J_z"),
        "X_uu": Limit(lt=0, what="resistance coefficient, negative"),
        "X_nn": Limit(gt=0, what="propeller thrust coefficient"),
    }

    def cross_problems(self, ship: Mapping[str, Any]) -> list[tuple[str, str]]:
        """No checks between numbers beyond the ranges of :attr:`limits`."""
        return []

    def build(self, ships: Sequence[Mapping[str, Any]]) -> ModularParams:
        """Dimensionalise the ship-file coefficients (module table) into ``(n,)`` arrays."""
        parts = _particulars(ships)
        c = [s["coefficients"] for s in ships]
        act = [s["actuators"] for s in ships]

        def k(name: str) -> np.ndarray:
            return stack(c, name, self.coefficients[name])

        L = stack(parts, "length_m")
        h = 0.5 * RHO_WATER
        m = stack(parts, "mass_kg")
        rudder = h * L**2 / U_CAL_MPS
        return ModularParams(
            mass=m,
            m11=m - k("X_udot") * h * L**3,
            m22=m - k("Y_vdot") * h * L**3,
            m33=stack(parts, "yaw_inertia_kgm2") - k("N_rdot") * h * L**5,
            y_rdot=k("Y_rdot") * h * L**4,
            n_vdot=k("N_vdot") * h * L**4,
            x_uu=k("X_uu"), x_vv=k("X_vv") * h * L**2, x_dd=k("X_dd") * rudder, x_nn=k("X_nn"),
            y_v=k("Y_v") * h * L**2, y_r=k("Y_r") * h * L**3,
            y_vvv=k("Y_vvv") * h * L**2, y_rvv=k("Y_rvv") * h * L**3,
            y_d=k("Y_d") * rudder, y_dd=k("Y_dd") * rudder, y_ddd=k("Y_ddd") * rudder,
            y_n=k("Y_n"),
            n_v=k("N_v") * h * L**3, n_r=k("N_r") * h * L**4,
            n_vvv=k("N_vvv") * h * L**3, n_rvv=k("N_rvv") * h * L**4,
            n_d=k("N_d") * rudder * L, n_dd=k("N_dd") * rudder * L, n_ddd=k("N_ddd") * rudder * L,
            n_n=k("N_n"), n_ndd=k("N_ndd"),
            gear_ratio=stack(parts, "gear_ratio"),
            tau_rudder_s=stack(act, "rudder_tau_s"),
            tau_engine_s=stack(act, "engine_tau_s"),
        )


# Columns of the packed parameter row (``base.pack``): the ModularParams fields in order.
(_MASS, _M11, _M22, _M33, _Y_RDOT, _N_VDOT, _X_UU, _X_VV, _X_DD, _X_NN,
 _Y_V, _Y_R, _Y_VVV, _Y_RVV, _Y_D, _Y_DD, _Y_DDD, _Y_N,
 _N_V, _N_R, _N_VVV, _N_RVV, _N_D, _N_DD, _N_DDD, _N_N, _N_NDD,
 _GEAR_RATIO, _TAU_RUDDER_S, _TAU_ENGINE_S) = range(30)


@kernel
def accel(p: np.ndarray, x: np.ndarray, env: np.ndarray) -> tuple[float, float, float]:
    """Body-frame accelerations of ONE ship [seed 002, eqs 4.1-4.6, 4.9].

    Sum of the hull, propeller and rudder modules plus the rigid-body terms of eqs 4.1-4.3, then
    the sway/yaw added-mass coupling (Y_rdot, N_vdot) solved in closed form.

    Args:
        p: ``float64[30]`` packed parameter row (``base.pack(params)[i]``, SI, see
            :class:`ModularParams`).
        x: ``float64[8]`` state in the ``base`` layout (u, v in m/s relative to the water, r in
            rad/s, rudder in rad with + = starboard, RPS in propeller rev/s).
        env: ``float64[4]`` (current north, current east, wind speed, wind from); unused: the
            current is in the kinematics (base) and the wind coefficients are zero [tables
            4.1-4.3].

    Returns:
        ``(du, dv, dr)`` in m/s2, m/s2, rad/s2.
    """
    u, v, r = x[U], x[V], x[R]
    speed = math.hypot(u, v)
    d, n = _thesis_controls(x[RUDDER], x[RPS])
    xh, yh, nh = _hull_forces(p, u, v, r, speed)
    xp, yp, np_ = _propeller_forces(p, n)
    xr, yr, nr = _rudder_forces(p, speed, d, n)
    m = p[_MASS]
    fx = xh + xp + xr + m * v * r
    fy = yh + yp + yr - m * u * r
    fn = nh + np_ + nr
    dv, dr = _solve_sway_yaw(p[_M22], p[_M33], p[_Y_RDOT], p[_N_VDOT], fy, fn)
    return fx / p[_M11], dv, dr


@kernel
def _thesis_controls(rudder: float, rps: float) -> tuple[float, float]:
    """Thesis rudder angle d (rad, + = port, so ``d = -RUDDER``) and shaft speed n (rad/s).

    Pure arithmetic, so :func:`linearised_F` runs the same code on ``(n,)`` arrays via
    ``py_func``.
    """
    return -rudder, _TWO_PI * rps


@kernel
def _solve_sway_yaw(m22: float, m33: float, y_rdot: float, n_vdot: float, fy: float, fn: float
                    ) -> tuple[float, float]:
    """Solve [[m22, -Y_rdot], [-N_vdot, m33]] (dv, dr) = (fy, fn).

    Pure arithmetic: :func:`linearised_F` runs the same code element-wise on ``(n,)`` arrays via
    ``py_func``.
    """
    det = m22 * m33 - y_rdot * n_vdot
    return (m33 * fy + y_rdot * fn) / det, (n_vdot * fy + m22 * fn) / det


@kernel
def _hull_forces(p: np.ndarray, u: float, v: float, r: float, speed: float
                 ) -> tuple[float, float, float]:
    """Hull module X_H, Y_H (N) and N_H (N m) [seed 002, eqs 4.4-4.6, 4.9]; ``speed`` = U, m/s."""
    inv = 1.0 / max(speed, _U_FLOOR)
    v2 = v * v
    xh = p[_X_UU] * u * abs(u) + p[_X_VV] * v2
    yh = speed * (p[_Y_V] * v + p[_Y_R] * r) + inv * v2 * (p[_Y_VVV] * v + p[_Y_RVV] * r)
    nh = speed * (p[_N_V] * v + p[_N_R] * r) + inv * v2 * (p[_N_VVV] * v + p[_N_RVV] * r)
    return xh, yh, nh


@kernel
def _propeller_forces(p: np.ndarray, n: float) -> tuple[float, float, float]:
    """Propeller module X_P, Y_P (N), N_P (N m) at shaft speed ``n`` (rad/s): thrust X_nn n|n|
    and the side force and moment of the same-handed screws Y_n n, N_n n [seed 002, eqs 4.4-4.6,
    ch 3.2]."""
    return p[_X_NN] * n * abs(n), p[_Y_N] * n, p[_N_N] * n


@kernel
def _rudder_forces(p: np.ndarray, speed: float, d: float, n: float) -> tuple[float, float, float]:
    """Rudder module X_R, Y_R (N), N_R (N m) [seed 002, eqs 4.4-4.6, ch 4.6].

    Polynomial in the thesis rudder angle ``d`` (rad, + = port), scaled by U^2 (the
    coefficients hold ``1 / U_CAL_MPS``, module table; ``speed`` = U in m/s), plus the
    asymmetry term N_ndd n^2 d^2 (``n`` shaft rad/s).
    """
    d2, u2 = d * d, speed * speed
    xr = u2 * p[_X_DD] * d2
    yr = u2 * d * (p[_Y_D] + d * (p[_Y_DD] + d * p[_Y_DDD]))
    nr = u2 * d * (p[_N_D] + d * (p[_N_DD] + d * p[_N_DDD])) + p[_N_NDD] * n * n * d2
    return xr, yr, nr


def engine_rpm(params: ModularParams, rps: np.ndarray) -> np.ndarray:
    """Engine rpm from propeller rev/s, ``(n,)`` (gear 1.66:1 [seed 002, ch 3.2])."""
    return np.asarray(rps) * 60.0 * params.gear_ratio


def rps_from_engine_rpm(params: ModularParams, rpm: np.ndarray) -> np.ndarray:
    """Propeller rev/s for engine rpm, ``(n,)``."""
    return np.asarray(rpm) / (60.0 * params.gear_ratio)


def linearised_F(params: ModularParams, x: np.ndarray) -> np.ndarray:
    """State matrix F of eq 4.10, appendix-D coefficients, at state ``x (8, n)``; ``(n, 8, 8)``.

    Rows and columns are in the ``base`` state order and units (RUDDER + = starboard, RPS in rev/s);
    ``F[:, EQ410_ORDER][:, :, EQ410_ORDER]`` is the thesis layout. Like appendix D, F is a
    state-dependent factorisation, not a Jacobian: each term of the accelerations is assigned to one
    state column with the rest of the term frozen in the coefficient, so ``F(x) @ x`` equals the
    calm-water derivative of u, v, r exactly (current is the disturbance input G_D of eq 4.12, and
    the rudder and engine rows are the lags -1/T_R, -1/T_N of eqs 4.7-4.8 without the demand).
    Assignment (as appendix D, with the sign slips corrected, see the module table):

    * u row: X1 = X_dd U^2 d (rudder col), X2 = X_nn n (n col), X4 = X_uu |u| (u col),
      X6 = X_vv v + m r (v col), all over (m - X_udot).
    * v, r rows: rudder col (Y_d + Y_dd d + Y_ddd d^2) U^2 [+ N_ndd n^2 d for N], u col -m r,
      v col (Y_v U + Y_rvv r v/U + Y_vvv v^2/U), r col Y_r U, n col Y_n, then the sway/yaw
      added-mass coupling (the Y_theta, N_theta of appendix D) applied to both rows.
    * position rows: the body velocities rotated by psi (eq 4.10 has x' = u, y' = v along the axes
      at the start of the step, psi = 0 there); psi row: psi' = r.

    Where it equals the Jacobian: at straight running (v = r = rudder = 0) the rudder, u, v and n
    columns of the v and r rows and the rudder, v and r columns of the u row. The r column of the v
    and r rows lacks the Coriolis term -m u (through the added-mass coupling; appendix D puts
    -m u r in the u column, where it vanishes at r = 0), and the quadratic X_uu, X_nn entries are
    half the Jacobian's. An EKF propagating covariance may want the true Jacobian instead.
    """
    p = params
    n_ships = x.shape[1]
    # the kernel's own pure-arithmetic helpers, run element-wise by numpy (py_func)
    speed = np.hypot(x[U], x[V])
    d, nrad = _thesis_controls.py_func(x[RUDDER], x[RPS])
    inv = 1.0 / np.maximum(speed, _U_FLOOR)
    u, v, r = x[U], x[V], x[R]
    F = np.zeros((n_ships, N_STATE, N_STATE))

    # surge [appendix D X1, X2, X4, X6]; d = -RUDDER and n = 2 pi RPS fold into the columns
    u2 = speed * speed  # the rudder terms' U^2
    F[:, U, RUDDER] = u2 * p.x_dd * x[RUDDER] / p.m11
    F[:, U, RPS] = p.x_nn * np.abs(nrad) * _TWO_PI / p.m11
    F[:, U, U] = p.x_uu * np.abs(u) / p.m11
    F[:, U, V] = (p.x_vv * v + p.mass * r) / p.m11

    # sway and yaw before the added-mass coupling: columns rudder, u, v, r, rps
    cols = (RUDDER, U, V, R, RPS)
    y_rows = (
        -u2 * (p.y_d + d * (p.y_dd + d * p.y_ddd)),
        -p.mass * r,
        speed * p.y_v + inv * v * (p.y_rvv * r + p.y_vvv * v),
        speed * p.y_r,
        _TWO_PI * p.y_n,
    )
    n_rows = (
        -u2 * (p.n_d + d * (p.n_dd + d * p.n_ddd)) - p.n_ndd * nrad * nrad * d,
        np.zeros(n_ships),
        speed * p.n_v + inv * v * (p.n_rvv * r + p.n_vvv * v),
        speed * p.n_r,
        _TWO_PI * p.n_n,
    )
    for col, fy, fn in zip(cols, y_rows, n_rows, strict=True):
        F[:, V, col], F[:, R, col] = _solve_sway_yaw.py_func(p.m22, p.m33, p.y_rdot, p.n_vdot,
                                                             fy, fn)

    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    F[:, NORTH, U], F[:, NORTH, V] = c, -s
    F[:, EAST, U], F[:, EAST, V] = s, c
    F[:, PSI, R] = 1.0
    F[:, RUDDER, RUDDER] = -1.0 / p.tau_rudder_s
    F[:, RPS, RPS] = -1.0 / p.tau_engine_s
    return F


FAMILY = register(ModularFamily())
