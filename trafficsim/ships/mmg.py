"""The ``mmg`` family: the MMG standard method of Yasukawa & Yoshimura, as a compiled kernel.

Reference: Yasukawa H., Yoshimura Y. (2015) "Introduction of MMG standard method for ship
maneuvering predictions", J Mar Sci Technol 20:37-52, doi:10.1007/s00773-014-0293-y, cited
below as [YY15] with the model part it describes (motion equations, hull forces, propeller,
rudder). The paper is cited through secondary sources: the formulas below are the standard
method as published and reproduced in public implementations, and the KVLCC2 numbers
in the ship files are those of the paper's KVLCC2 tables as transcribed identically in several
public sources (ShipMMG.jl, TUD_RL, others), see the ship files.

Motion (3 DOF, at midship, [YY15] motion equations) with ``v`` the sway velocity at midship::

    (m + m_x) u' - (m + m_y) v r - x_G m r^2               = X_H + X_R + X_P + X_A
    (m + m_y) v' + (m + m_x) u r + x_G m r'                 = Y_H + Y_R + Y_A
    (I_zG + x_G^2 m + J_z) r' + x_G m (v' + u r)           = N_H + N_R + N_A

Hull [YY15] hull forces, with U = sqrt(u^2 + v^2), v' = v/U, r' = r L/U, beta = asin(-v')::

    X_H = 1/2 rho L d U^2 (-R0' + X'vv v'^2 + X'vr v'r' + X'rr r'^2 + X'vvvv v'^4)
    Y_H = 1/2 rho L d U^2 (Y'v v' + Y'r r' + Y'vvv v'^3 + Y'vvr v'^2 r' + Y'vrr v'r'^2 + Y'rrr r'^3)
    N_H = 1/2 rho L^2 d U^2 (N'v v' + ... same terms with N')

Propeller [YY15] propeller force and wake: X_P = (1 - t_P) rho n^2 D^4 K_T(J),
K_T = k0 + k1 J + k2 J^2, J = u (1 - w_P) / (n D), with the wake in manoeuvring motion
(1 - w_P)/(1 - w_P0) = 1 + (1 - exp(-C1 |beta_P|)) (C2 - 1), beta_P = beta - x'_P r',
C2 = C2+ for beta_P > 0, C2- otherwise. (Some implementations use the older form
w_P = w_P0 exp(-4 beta_P^2); the standard method's C1, C2 form is used here, with the KVLCC2
C1 = 2.0, C2 = 1.6 / 1.1 of [YY15]; C1 = 0 gives a constant wake.)

Rudder [YY15] rudder forces and inflow: F_N = 1/2 rho A_R U_R^2 f_alpha sin(alpha_R),
alpha_R = delta - atan(v_R/u_R), v_R = U gamma_R beta_R, beta_R = beta - l'_R r'
(gamma_R+ for beta_R > 0, gamma_R- otherwise),
u_R = eps u (1 - w_P) sqrt(eta {1 + kappa (sqrt(1 + 8 K_T/(pi J^2)) - 1)}^2 + 1 - eta),
eta = D / H_R; X_R = -(1 - t_R) F_N sin delta, Y_R = -(1 + a_H) F_N cos delta,
N_R = -(x_R + a_H x_H) F_N cos delta.

Sign of the rudder: in the MMG axes (x forward, y starboard, z down) a positive delta gives a
positive normal force, a port-side force at the stern and a positive (starboard) yaw moment, so
delta > 0 turns the ship to starboard exactly as this package requires; no flip is needed.

Implementation choices (documented deviations, none changes the paper's model at speed):

* The propeller and rudder inflow formulas are written without J in a denominator:
  n^2 D^4 K_T = D^2 (k0 n^2 D^2 + k1 n D u_P + k2 u_P^2) and
  u_P (1 + kappa (sqrt(1 + 8 K_T/(pi J^2)) - 1)) = (1 - kappa) u_P + kappa sqrt(u_P^2 + 8 n^2 D^2
  K_T / pi) with u_P = (1 - w_P) u; algebraically identical for n > 0, finite at n = 0.
* Low speed: v', r' are formed with U_d = sqrt(U^2 + U_0^2) and the hull forces scaled with U_d^2
  (U_0 = ``LOW_SPEED_FN`` sqrt(g L), 0.2 % of the Froude speed, i.e. a relative change of
  U_0^2/U^2 ~ 2e-4 at Fn 0.142), so the hull terms go smoothly to zero at rest instead of
  dividing by zero; the resistance term is -R0' U^2 u/sqrt(u^2 + U_0^2) so it always opposes
  the surge velocity (also astern) and vanishes at rest. A ship at rest with n = 0 feels exactly
  zero force.
* Four-quadrant fallback (the paper covers n >= 0, u > 0 only):
  - n >= 0 and u_P < 0 (going astern with the propeller ahead): the open-water curve is taken at
    J = 0 (bollard thrust); the race (aft) meets the ship's own flow (forward) at the rudder, so
    u_R = eps sgn(s) sqrt(|s|) with the signed mean square s = eta race^2 - u_P^2: the
    ship's flow from behind at n = 0 (u_R = eps u_P), the race once it is strong enough;
  - n < 0 (astern): thrust = c_rev k0 rho n|n| D^4 + rho D^2 k2 max(u_P, 0)^2, i.e. the bollard
    K_T times a reverse-efficiency ratio ``astern_thrust_ratio`` (c_rev), plus the drag the
    open-water curve gives at n = 0 so that the thrust is continuous through n = 0; the race
    over the rudder is the one at n = 0 (the reversed propeller's flows forward, away from
    the rudder), so the rudder inflow is continuous through n = 0 too, ahead and astern
    (u_R = eps u_P going astern).
  - the drift angle is beta = asin(-v/U_d), bounded for any u, and alpha_R uses atan2 so flow
    from behind (u_R < 0) reverses the rudder force, as it does on a real rudder.
* Wind: Isherwood (1972) loads of :mod:`trafficsim.ships.wind` are added to X, Y, N.
* Rudder neutral offset ``delta_0`` (rad, default 0): the hull feels ``delta + delta_0``, the
  "neutral rudder angle" of a single-screw ship's propeller asymmetry (the
  ``propeller_asymmetry`` effect of :mod:`trafficsim.effects`); 0 changes nothing.

Layout: :meth:`MMGFamily.build` turns ship files into :class:`MMGParams` (``(n,)`` columns, all
constant products precomputed); :func:`accel` is the compiled scalar kernel for one ship on its
packed row (``base.pack``); ``base.accelerations(FAMILY, params, x, env)`` evaluates it for
``(8, n)`` states and the batch engine calls it through :mod:`trafficsim.ships.kernels`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from trafficsim.jit import inline_kernel, kernel
from trafficsim.ships import wind
from trafficsim.ships.base import (
    ADDED_MASS,
    BOLLARD_THRUST,
    FLOW_STRAIGHTENING,
    GYRADIUS,
    LIFT_GRADIENT,
    RHO_WATER,
    RPS,
    RUDDER,
    RUDDER_DRAG_DEDUCTION,
    THRUST_DEDUCTION,
    WAKE_FRACTION,
    WAKE_RATIO,
    Limit,
    U,
    V,
    coefficient,
    particular,
    register,
)
from trafficsim.ships.base import R as YAW_RATE

G = 9.80665  # m/s2
#: Regularising speed U_0 = LOW_SPEED_FN * sqrt(g L) for the non-dimensional hull terms.
LOW_SPEED_FN = 0.002
_EIGHT_OVER_PI = 8.0 / math.pi

_PARTICULARS: dict[str, float | None] = {
    "displacement_m3": None,        # volume of displacement
    "lcg_m": 0.0,                   # x_G, longitudinal centre of gravity forward of midship
    "propeller_diameter_m": None,   # D_P
    "rudder_area_m2": None,         # A_R (movable area)
    "rudder_height_m": None,        # H_R (span)
}


@dataclass(frozen=True)
class MMGParams:
    """Constants of ``n`` MMG ships, ``(n,)`` float arrays (built once; the field order is the
    column order of the packed row that :func:`accel` reads).

    Attributes:
        L: length between perpendiculars, m.
        u0sq: square of the regularising speed U_0, m2/s2.
        x0 .. x4: R0', X'vv, X'vr, X'rr, X'vvvv times 1/2 rho L d (kg/m).
        y0 .. y5: Y'v, Y'r, Y'vvv, Y'vvr, Y'vrr, Y'rrr times 1/2 rho L d (kg/m).
        n0 .. n5: N'v, ... N'rrr times 1/2 rho L^2 d (kg).
        rho_d2: rho D^2 (kg/m); d_p: propeller diameter D, m; one_m_tp: 1 - t_P.
        one_m_wp0, w_c1, w_c2p, w_c2m, x_p: wake model (1 - w_P0, C1, C2+, C2-, x'_P).
        k0, k1, k2: open-water K_T polynomial.
        c_rev: astern bollard thrust / ahead bollard thrust (fallback, see module doc).
        eps, kappa, eta: rudder inflow constants (epsilon, kappa, D/H_R).
        gam_p, gam_m, l_r: flow straightening gamma_R+ / gamma_R- and l'_R.
        rud_k: 1/2 rho A_R f_alpha (kg/m).
        xr_k, yr_k, nr_k: -(1 - t_R), -(1 + a_H), -(x_R + a_H x_H) (the last in m).
        mx_den: 1/(m + m_x) (1/kg); m_my, m_mx: m + m_y, m + m_x (kg); xg_m: x_G m (kg m).
        inv11, inv12, inv22: inverse of the sway-yaw mass matrix [[m+m_y, x_G m], [x_G m, I]]
            with I = I_zG + x_G^2 m + J_z.
        wind_*: windage columns, :data:`trafficsim.ships.wind.WINDAGE_FIELDS`.
    """

    L: np.ndarray
    u0sq: np.ndarray
    x0: np.ndarray
    x1: np.ndarray
    x2: np.ndarray
    x3: np.ndarray
    x4: np.ndarray
    y0: np.ndarray
    y1: np.ndarray
    y2: np.ndarray
    y3: np.ndarray
    y4: np.ndarray
    y5: np.ndarray
    n0: np.ndarray
    n1: np.ndarray
    n2: np.ndarray
    n3: np.ndarray
    n4: np.ndarray
    n5: np.ndarray
    rho_d2: np.ndarray
    d_p: np.ndarray
    one_m_tp: np.ndarray
    one_m_wp0: np.ndarray
    w_c1: np.ndarray
    w_c2p: np.ndarray
    w_c2m: np.ndarray
    x_p: np.ndarray
    k0: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    c_rev: np.ndarray
    eps: np.ndarray
    kappa: np.ndarray
    eta: np.ndarray
    gam_p: np.ndarray
    gam_m: np.ndarray
    l_r: np.ndarray
    rud_k: np.ndarray
    xr_k: np.ndarray
    yr_k: np.ndarray
    nr_k: np.ndarray
    mx_den: np.ndarray
    m_my: np.ndarray
    m_mx: np.ndarray
    xg_m: np.ndarray
    inv11: np.ndarray
    inv12: np.ndarray
    inv22: np.ndarray
    wind_al: np.ndarray
    wind_af: np.ndarray
    wind_lb: np.ndarray
    wind_sl: np.ndarray
    wind_cl: np.ndarray
    wind_masts: np.ndarray
    wind_ss: np.ndarray
    wind_qx: np.ndarray
    wind_qy: np.ndarray
    wind_qn: np.ndarray
    delta0: np.ndarray


_HULL = (("x0", "R0"), ("x1", "X_vv"), ("x2", "X_vr"), ("x3", "X_rr"), ("x4", "X_vvvv"),
         ("y0", "Y_v"), ("y1", "Y_r"), ("y2", "Y_vvv"), ("y3", "Y_vvr"), ("y4", "Y_vrr"),
         ("y5", "Y_rrr"),
         ("n0", "N_v"), ("n1", "N_r"), ("n2", "N_vvv"), ("n3", "N_vvr"), ("n4", "N_vrr"),
         ("n5", "N_rrr"))

# Columns of the packed parameter row (``base.pack``): the MMGParams fields in order.
_FIELDS = tuple(f.name for f in fields(MMGParams))
(_L, _U0SQ, _X0, _X1, _X2, _X3, _X4, _Y0, _Y1, _Y2, _Y3, _Y4, _Y5,
 _N0, _N1, _N2, _N3, _N4, _N5, _RHO_D2, _D_P, _ONE_M_TP, _ONE_M_WP0, _W_C1, _W_C2P, _W_C2M,
 _X_P, _K0, _K1, _K2, _C_REV, _EPS, _KAPPA, _ETA, _GAM_P, _GAM_M, _L_R, _RUD_K,
 _XR_K, _YR_K, _NR_K, _MX_DEN, _M_MY, _M_MX, _XG_M, _INV11, _INV12, _INV22) = range(48)
_W0 = _FIELDS.index(wind.WINDAGE_FIELDS[0])
_W1 = _W0 + len(wind.WINDAGE_FIELDS)
_DELTA0 = _FIELDS.index("delta0")
#: the columns of :func:`mass_terms`, consecutive in both MMG families' parameter rows
MASS_FIELDS = ("mx_den", "m_my", "m_mx", "xg_m", "inv11", "inv12", "inv22")
assert _FIELDS[_MX_DEN:_INV22 + 1] == MASS_FIELDS and _FIELDS[_W0:_W1] == wind.WINDAGE_FIELDS


class MMGFamily:
    """MMG standard method [YY15] with a simple astern fallback and Isherwood wind loads.

    The equations are the compiled scalar kernel :func:`accel` (one ship).
    """

    name = "mmg"
    supports_astern = True
    #: Non-dimensional coefficients (primes dropped), [YY15] notation; None = required.
    coefficients: Mapping[str, float | None] = {
        # hull resistance and manoeuvring derivatives
        "R0": None, "X_vv": None, "X_vr": None, "X_rr": None, "X_vvvv": None,
        "Y_v": None, "Y_r": None, "Y_vvv": None, "Y_vvr": None, "Y_vrr": None, "Y_rrr": None,
        "N_v": None, "N_r": None, "N_vvv": None, "N_vvr": None, "N_vrr": None, "N_rrr": None,
        # added masses (by 1/2 rho L^2 d, J_z by 1/2 rho L^4 d) and yaw gyradius k_zz / L
        "m_x": None, "m_y": None, "J_z": None, "k_zz": 0.25,
        # propeller: thrust deduction, wake, x'_P, open-water K_T, wake change C1, C2
        "t_P": None, "w_P0": None, "x_P": None, "k_0": None, "k_1": None, "k_2": None,
        "C_1": 0.0, "C_2_plus": 1.0, "C_2_minus": 1.0,
        # rudder and hull-rudder interaction
        "t_R": None, "a_H": None, "x_H": None, "x_R": -0.5,
        "gamma_R_plus": None, "gamma_R_minus": None, "l_R": None,
        "epsilon": None, "kappa": None, "f_alpha": None,
        # astern fallback: astern bollard K_T / ahead bollard K_T (not in [YY15])
        "astern_thrust_ratio": 0.7,
        # rudder neutral offset, rad (propeller asymmetry; not in [YY15])
        "delta_0": 0.0,
    }
    limits: Mapping[str, Limit] = {
        "R0": Limit(gt=0, what="resistance coefficient"),
        "m_x": ADDED_MASS, "m_y": ADDED_MASS, "J_z": ADDED_MASS, "k_zz": GYRADIUS,
        "t_P": THRUST_DEDUCTION, "w_P0": WAKE_FRACTION, "k_0": BOLLARD_THRUST,
        "C_1": Limit(ge=0, what="rate of the wake change with the drift angle"),
        "C_2_plus": Limit(gt=0, what="wake ratio at large drift angles"),
        "C_2_minus": Limit(gt=0, what="wake ratio at large drift angles"),
        "t_R": RUDDER_DRAG_DEDUCTION,
        "gamma_R_plus": FLOW_STRAIGHTENING, "gamma_R_minus": FLOW_STRAIGHTENING,
        "epsilon": WAKE_RATIO, "kappa": Limit(ge=0, what="propeller race coefficient"),
        "f_alpha": LIFT_GRADIENT,
        "astern_thrust_ratio": Limit(ge=0, what="astern / ahead bollard thrust"),
    }

    def cross_problems(self, ship: Mapping[str, Any]) -> list[tuple[str, str]]:
        """No checks between numbers beyond the ranges of :attr:`limits`."""
        return []

    def build(self, ships: Sequence[Mapping[str, Any]]) -> MMGParams:
        """Parameters from ship-file dicts (``particulars`` and ``coefficients``).

        Required particulars besides length/beam/draught: ``displacement_m3``,
        ``propeller_diameter_m``, ``rudder_area_m2``, ``rudder_height_m``; optional ``lcg_m``
        (x_G, default 0) and the windage particulars of :mod:`trafficsim.ships.wind`.
        """
        def col(key: str) -> np.ndarray:
            return np.array([coefficient(s, key, self.coefficients[key], self.name)
                             for s in ships], dtype=float)

        def part(key: str) -> np.ndarray:
            return np.array([particular(s, key, _PARTICULARS, self.name) for s in ships],
                            dtype=float)

        rho = RHO_WATER
        L, d = part("length_m"), part("draught_m")
        disp, x_g = part("displacement_m3"), part("lcg_m")
        d_p, h_r = part("propeller_diameter_m"), part("rudder_height_m")
        a_r = part("rudder_area_m2")
        fx = 0.5 * rho * L * d          # force scale / U^2
        fn = fx * L                     # moment scale / U^2, also the added-mass scale
        m = rho * disp
        m_x, m_y = col("m_x") * fn, col("m_y") * fn
        j_z = col("J_z") * fn * L * L
        i_zg = m * (col("k_zz") * L) ** 2
        i_tot = i_zg + x_g**2 * m + j_z
        a_h = col("a_H")
        hull = {f: col(k) * (fn if f[0] == "n" else fx) for f, k in _HULL}
        w = wind.build(ships)
        return MMGParams(
            L=L,
            u0sq=LOW_SPEED_FN**2 * G * L,
            **hull,
            rho_d2=rho * d_p**2,
            d_p=d_p,
            one_m_tp=1.0 - col("t_P"),
            one_m_wp0=1.0 - col("w_P0"),
            w_c1=col("C_1"),
            w_c2p=col("C_2_plus"),
            w_c2m=col("C_2_minus"),
            x_p=col("x_P"),
            k0=col("k_0"), k1=col("k_1"), k2=col("k_2"),
            c_rev=col("astern_thrust_ratio"),
            eps=col("epsilon"),
            kappa=col("kappa"),
            eta=d_p / h_r,
            gam_p=col("gamma_R_plus"),
            gam_m=col("gamma_R_minus"),
            l_r=col("l_R"),
            rud_k=0.5 * rho * a_r * col("f_alpha"),
            xr_k=-(1.0 - col("t_R")),
            yr_k=-(1.0 + a_h),
            nr_k=-(col("x_R") + a_h * col("x_H")) * L,
            **mass_terms(m, m_x, m_y, i_tot, x_g),
            **{f.name: getattr(w, f.name) for f in fields(w)},
            delta0=col("delta_0"),
        )


@kernel
def accel(p: np.ndarray, x: np.ndarray, env: np.ndarray) -> tuple[float, float, float]:
    """Body-frame accelerations of ONE ship ([YY15] motion equations at midship).

    Args:
        p: ``float64[59]`` packed parameter row (``base.pack(params)[i]``, see
            :class:`MMGParams`).
        x: ``float64[8]`` state in the ``base`` layout: u, v (at midship, relative to the
            water, m/s), r (rad/s), rudder (rad, + = starboard turn), rps (rev/s).
        env: ``float64[4]`` (current north, current east, wind speed, wind from): the wind loads
            use it; the current is in the kinematics (base).

    Returns:
        ``(du, dv, dr)`` in m/s2, m/s2, rad/s2.
    """
    u, v, r, n = x[U], x[V], x[YAW_RATE], x[RPS]
    delta = x[RUDDER] + p[_DELTA0]
    u2, v2 = u * u, v * v
    big_u2 = u2 + v2
    ud2 = big_u2 + p[_U0SQ]
    inv_ud = 1.0 / math.sqrt(ud2)
    ud = ud2 * inv_ud
    q = r * p[_L]  # r' U_d, m/s

    # hull [YY15], written dimensionally: U_d^2 v'^a r'^b = v^a q^b U_d^(2-a-b); the resistance
    # -R0' U^2 always opposes u and vanishes at rest
    x_h = (-p[_X0] * big_u2 * u / math.sqrt(u2 + p[_U0SQ]) + p[_X1] * v2 + p[_X2] * v * q
           + p[_X3] * q * q + p[_X4] * v2 * v2 / ud2)
    c1, c2, c3, c4 = v2 * v, v2 * q, v * q * q, q * q * q
    y_h = ud * (p[_Y0] * v + p[_Y1] * q) + inv_ud * (
        p[_Y2] * c1 + p[_Y3] * c2 + p[_Y4] * c3 + p[_Y5] * c4)
    n_h = ud * (p[_N0] * v + p[_N1] * q) + inv_ud * (
        p[_N2] * c1 + p[_N3] * c2 + p[_N4] * c3 + p[_N5] * c4)

    # drift angle and non-dimensional yaw rate, bounded at any speed (|v| < U_d)
    beta = math.asin(-v * inv_ud)
    r_nd = q * inv_ud

    # propeller wake and thrust [YY15]; n^2 D^2 K_T(J) without J in a denominator
    beta_p = beta - p[_X_P] * r_nd
    c2_w = p[_W_C2P] if beta_p > 0.0 else p[_W_C2M]
    one_m_wp = p[_ONE_M_WP0] * (1.0 + (1.0 - math.exp(-p[_W_C1] * abs(beta_p))) * (c2_w - 1.0))
    u_p = one_m_wp * u
    u_pp = max(u_p, 0.0)
    nd = n * p[_D_P]
    drag = p[_K2] * u_pp * u_pp
    if n >= 0.0:
        ktn2d2 = p[_K0] * nd * nd + p[_K1] * nd * u_pp + drag
        race_k = ktn2d2
    else:
        # astern fallback (module doc): reversed bollard thrust, the race as at n = 0
        ktn2d2 = -p[_C_REV] * p[_K0] * nd * nd + drag
        race_k = drag
    # rudder inflow with the propeller race [YY15]; going astern, the signed mean square
    race = (1.0 - p[_KAPPA]) * u_pp + p[_KAPPA] * math.sqrt(
        max(u_pp * u_pp + _EIGHT_OVER_PI * race_k, 0.0))
    if u_p >= 0.0:
        u_r = p[_EPS] * math.sqrt(p[_ETA] * race * race + (1.0 - p[_ETA]) * u_p * u_p)
    else:
        sq = p[_ETA] * race * race - u_p * u_p
        u_r = p[_EPS] * math.copysign(math.sqrt(abs(sq)), sq)
    thrust = p[_RHO_D2] * ktn2d2

    # rudder normal force with flow straightening [YY15]
    beta_r = beta - p[_L_R] * r_nd
    v_r = math.sqrt(big_u2) * (p[_GAM_P] if beta_r > 0.0 else p[_GAM_M]) * beta_r
    f_n = p[_RUD_K] * (u_r * u_r + v_r * v_r) * math.sin(delta - math.atan2(v_r, u_r))
    cos_d = math.cos(delta)

    xa, ya, na = wind.loads1(p[_W0:_W1], x, env)
    xf = x_h + p[_ONE_M_TP] * thrust + p[_XR_K] * f_n * math.sin(delta) + xa
    yf = y_h + p[_YR_K] * f_n * cos_d + ya
    nf = n_h + p[_NR_K] * f_n * cos_d + na

    return midship_accel(p, _MX_DEN, xf, yf, nf, u, v, r)


def mass_terms(m: np.ndarray, m_x: np.ndarray, m_y: np.ndarray, i_tot: np.ndarray,
               x_g: np.ndarray) -> dict[str, np.ndarray]:
    """The mass columns of the motion equations at midship [YY15] (``mx_den`` ... ``inv22``
    of :class:`MMGParams`, in that order): mass ``m``, added masses ``m_x``, ``m_y`` (kg), yaw
    inertia about midship with added inertia ``i_tot`` (kg m^2), ``x_G`` (m)."""
    m_my, xg_m = m + m_y, x_g * m
    det = m_my * i_tot - xg_m**2
    return dict(zip(MASS_FIELDS, (1.0 / (m + m_x), m_my, m + m_x, xg_m, i_tot / det,
                                  -xg_m / det, m_my / det), strict=True))


@inline_kernel
def midship_accel(p: np.ndarray, at: int, xf: float, yf: float, nf: float, u: float, v: float,
                  r: float) -> tuple[float, float, float]:
    """``(du, dv, dr)`` from the total forces ``xf, yf, nf`` by the motion equations at midship
    [YY15]; ``p[at:at + 7]`` holds the columns of :func:`mass_terms` in their order."""
    mx_den, m_my, m_mx, xg_m = p[at], p[at + 1], p[at + 2], p[at + 3]
    inv11, inv12, inv22 = p[at + 4], p[at + 5], p[at + 6]
    ur = u * r
    du = (xf + m_my * v * r + xg_m * r * r) * mx_den
    rhs_y = yf - m_mx * ur
    rhs_n = nf - xg_m * ur
    return du, inv11 * rhs_y + inv12 * rhs_n, inv12 * rhs_y + inv22 * rhs_n


FAMILY = register(MMGFamily())
