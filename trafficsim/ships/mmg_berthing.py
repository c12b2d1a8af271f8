"""The ``mmg_berthing`` family: the low-speed MMG model for docking and berthing of Miyauchi et
al. (2022), as a compiled kernel.

References (cited below by their tags):

* [M22] Miyauchi Y., Maki A., Umeda N., Rachman D. M., Akimoto Y. (2022) "System parameter
  exploration of ship maneuvering model for automatic docking/berthing using CMA-ES", J Mar Sci
  Technol 27:1065-1083, doi:10.1007/s00773-022-00889-3: the model as a whole and the Esso
  Osaka 3 m model's parameter folder (``principal_particulars.csv``, ``MMG_params.csv``,
  ``model_switch.csv``) that :mod:`trafficsim.diagnose.mmgfolder` reads.
* [YNI09] Yoshimura Y., Nakao I., Ishibashi A. (2009) "Unified mathematical model for ocean and
  harbour manoeuvring", MARSIM 2009: linear hull derivatives plus cross-flow drag, valid from
  ocean-going speed down to berthing (large drift angles, turning on the spot, going astern).
* [YY15] Yasukawa H., Yoshimura Y. (2015) "Introduction of MMG standard method for ship
  maneuvering predictions", J Mar Sci Technol 20:37-52: motion equations, propeller thrust in
  the first quadrant, rudder force and hull-rudder interaction (as in :mod:`.mmg`).
* Hachii's piecewise-linear model of the propeller thrust, side force and yaw moment with the
  propeller reversed (third and fourth quadrants), Ueno's measurements on the training ship
  Seiunmaru for the side force and moment of a propeller ahead on a ship going astern (second
  quadrant), Kitagawa's rudder inflow with the propeller reversed, Fujii's normal-force slope:
  these names are those [M22]'s authors give the terms in the simulator they published with
  the parameter folder (NAOE-5thLab ``mmg-1p1r-simulator``, CC BY-NC 4.0). Those papers and the
  text of [M22] are cited through that simulator: the forms below follow its behaviour (no
  code of it is used), and where this module departs from it the departure is listed under
  "Choices".

Motion (3 DOF at midship, [YY15]), identical to :mod:`.mmg`::

    (m + m_x) u' - (m + m_y) v r - x_G m r^2      = X_H + X_P + X_R + X_A
    (m + m_y) v' + (m + m_x) u r + x_G m r'        = Y_H + Y_P + Y_R + Y_A
    (I_zG + x_G^2 m + J_z) r' + x_G m (v' + u r)  = N_H + N_P + N_R + N_A

Hull [YNI09], with U = sqrt(u^2 + v^2), beta = atan2(v, u) (0 ahead, +-pi astern)::

    X_H = 1/2 rho L d [(X_0F + (X_0A - X_0F) |beta| / pi) u U + X_vr v r L]
    Y_H = 1/2 rho L d [Y_v v |u| + Y_r r L u]
          - 1/2 rho d C_D int |v + C_rY r x| (v + C_rY r x) dx
    N_H = 1/2 rho L^2 d [N_v v u + N_r r L |u|]
          - 1/2 rho d C_D int |v + C_rN r x| (v + C_rN r x) x dx

the integrals over the length, x from -L/2 to L/2 (the cross-flow drag of the sections, whose
local sway velocity is v + r x; C_rY, C_rN correct the yaw-rate part). X_0F, X_0A are the
resistance coefficients going ahead and astern (negative numbers; the surge resistance turns
from one to the other with the drift angle). The integrands are piecewise polynomials in x
(quadratic, cubic), integrated here in closed form on either side of the point where the local
velocity changes sign -- the exact value of what the published simulator sums numerically.

Propeller, with J_s = u / (n D) (the advance ratio without wake) and the wake in manoeuvring
motion w_P = w_P0 - tau_P |beta_P| - C_P beta_P^2, beta_P = (v + x_P L r) / U, 1 - w_P clipped
to (0, 1] and set to 1 when going astern (u <= 0) [M22]::

    n >= 0:  X_P = (1 - t_P) rho n^2 D^4 K_T(J),  K_T = k_0 + k_1 J + k_2 J^2,  J = (1 - w_P) J_s
             Y_P = N_P = 0 going ahead; going astern (u < 0, second quadrant, Ueno):
             Y_P = 1/2 rho L d (n P)^2 (a_P5 J_s^2 + a_P6 J_s + a_P7),  N_P likewise with
             1/2 rho L^2 d and b_P5..b_P7 (P = pitch), each switched by switch_prop_y / _n
    n < 0:   X_P = rho n^2 D^4 (c_P1 + c_P2 J_s) for J_s >= c_P3, else rho n^2 D^4 c_P0
             Y_P = 1/2 rho L d (n D)^2 (a_P2 + a_P3 J_s) for J_s < -0.35,
                   (a_P0 + a_P1 J_s) for -0.35 <= J_s <= -0.06, a_P4 for J_s > -0.06
             N_P likewise with 1/2 rho L^2 d and b_P0..b_P4          (Hachii)

All of it is evaluated as n^2 K_T(J) D^2 = k_0 (nD)^2 + k_1 (nD) u_P + k_2 u_P^2 and the like,
without J in a denominator, so it stays finite at n = 0.

Rudder [YY15] with the low-speed inflow of [M22]: eta = D / H_R, kappa = k_x / epsilon,
u_P = (1 - w_P) u, q = n^2 D^2 K_T (thrust over rho D^2, without 1 - t_P)::

    n >= 0 and q > 0 (propeller race aft):
        u_R = epsilon sqrt(eta (u_P + kappa (sqrt(u_P^2 + 8 q / pi) - u_P))^2 + (1 - eta) u_P^2)
    otherwise, u >= 0 (Kitagawa; propeller reversed or unloaded):
        p_1 = epsilon u_P + sign(n) k_x,rev sqrt(8 |q| / pi),  p_2 = epsilon u_P
        u_R^2 (signed) = eta sign(p_1) p_1^2 + (1 - eta) p_2^2 + C_PR u^2
    otherwise (u < 0, propeller reversed):  u_R = u
    v_R = -gamma (v + l_R L r),  U_R^2 = u_R^2 + v_R^2,  alpha_R = delta - atan2(v_R, u_R)
    F_N = 1/2 rho A_R f_alpha U_R^2 sin alpha_R,   f_alpha = 6.13 lambda / (lambda + 2.25) (Fujii)
    X_R = -(1 - t_R) F_N sin delta,  Y_R = -(1 + a_H) F_N cos delta,
    N_R = -(x_R + a_H x_H) L F_N cos delta

``switch_rudder_astern`` = 0 drops the rudder force whenever n <= 0 (the folder's
``switch_rudder``). Sign of the rudder: as in :mod:`.mmg`, delta > 0 turns the ship to
starboard (checked on the FRT-DS-ESSO data, README "Trial data").

Choices (where this module departs from, or had to complete, the published simulator):

* Continuity at n = 0 and at u = 0. The published simulator's propeller force jumps there: as
  n -> 0+ the open-water polynomial extrapolated to J -> infinity leaves a drag k_2 u_P^2 that is
  absent at n = 0 and for n < 0, and the second-quadrant side force jumps from 0 to
  a_P7 (n P)^2 as u crosses zero and to a_P5 (P/D)^2 u^2 as n crosses zero; the rudder inflow
  jumps from Kitagawa's (propeller suction, u_R < 0) to u_R = u = 0 as u crosses zero with the
  propeller reversed. Here (constants :data:`J_FADE`, :data:`J_RAMP`): beyond |J| = J_FADE = 1
  (past the open-water curve's K_T = 0, near J = 0.7 for a usual propeller) the forces of a
  propeller turning ahead fade as J_FADE / |J|, i.e. linearly in n as n -> 0; the second-quadrant
  side force and moment ramp in linearly over |J_s| < J_RAMP = 0.05 from zero at u = 0; and
  Kitagawa's inflow blends linearly into the fourth quadrant's u_R = u over |J_s| < J_RAMP.
  Elsewhere the published forms hold unchanged; replayed on the FRT-DS-ESSO runs, the bands
  (and the switch below) change the heading errors by at most 0.02 deg RMS against the published
  forms, while the jumps they remove were 1-5 % of the accelerations at u = 0 and n = 0
  (``tests/ships/test_mmg_berthing.py``). The remaining discontinuities of the published
  model are kept: between the propeller-race inflow and Kitagawa's at K_T = 0 (the C_PR u^2 term
  appears there), and the small steps between Hachii's linear pieces (their coefficients make
  them nearly continuous).
* The flow-straightening coefficient: gamma_R_minus for beta_R = -(v + l_R L r) / U < 0 and
  gamma_R_plus for beta_R > 0, the switch of [YY15], continuous in v_R. The published simulator
  switches on the sign of v + x_R L r instead, which makes v_R jump by (gamma_R_plus -
  gamma_R_minus)(l_R - x_R) L r there. The folder's ``gammaP_rudder`` (used where v + ... >= 0,
  i.e. beta_R <= 0) is gamma_R_minus and ``gammaN_rudder`` gamma_R_plus.
* The wake angle beta_P is taken as 0 at U = 0 (it is undefined there; u_P = 0 anyway).
* Not implemented (the folder reader refuses them): the second thrust model of the published
  simulator (``switch_prop_x`` = 2, with ``Jmin``, ``alpha_prop``), its second astern rudder
  inflow (``switch_ur`` = 2, with ``coeff_urudder_zero``) and Lindenburg's rudder normal and
  tangential force (``switch_fn`` = 2, with ``maxtickness_rudder``).
* Wind: the Isherwood (1972) loads of :mod:`trafficsim.ships.wind`, as in :mod:`.mmg`, when the
  ship file gives windage areas (the published simulator uses Fujiwara's regression instead).
* Rudder neutral offset ``delta_0`` (rad, default 0): the hull feels delta + delta_0 (the
  ``propeller_asymmetry`` effect of :mod:`trafficsim.effects`), as in :mod:`.mmg`.
* Water density: particular ``water_density_kgpm3`` (default 1025; 998 for the fresh-water pond
  of the Esso Osaka model) sets the mass (density x displacement) and all hydrodynamic forces.

Layout: :meth:`MMGBerthingFamily.build` turns ship files into :class:`BerthingParams` (``(n,)``
columns, constant products precomputed); :func:`accel` is the compiled scalar kernel for one
ship on its packed row (``base.pack``), dispatched by :mod:`trafficsim.ships.kernels`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from trafficsim.errors import ShipLibraryError
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
from trafficsim.ships.mmg import MASS_FIELDS, mass_terms, midship_accel

#: |J| beyond which the forces of a propeller turning ahead fade as J_FADE / |J| (module doc)
J_FADE = 1.0
#: |J_s| over which the forces switched at u = 0 are blended linearly (module doc)
J_RAMP = 0.05
#: J_s limits of Hachii's linear pieces (n < 0)
J_SYN = -0.35
J_SYN0 = -0.06
_EIGHT_OVER_PI = 8.0 / math.pi

_PARTICULARS: dict[str, float | None] = {
    "displacement_m3": None,         # volume of displacement
    "lcg_m": 0.0,                    # x_G, forward of midship
    "propeller_diameter_m": None,    # D
    "propeller_pitch_ratio": None,   # P / D
    "rudder_area_m2": None,          # A_R
    "rudder_height_m": None,         # H_R
    "water_density_kgpm3": RHO_WATER,
}


@dataclass(frozen=True)
class BerthingParams:
    """Constants of ``n`` ships, ``(n,)`` float arrays; field order = packed row layout.

    Attributes:
        half_l: L / 2, m.
        x0f, x0a: X_0F, X_0A times 1/2 rho L d (kg/m, negative); xvr: X_vr 1/2 rho L^2 d (kg).
        yv, yr: Y_v 1/2 rho L d (kg/m), Y_r 1/2 rho L^2 d (kg).
        nv, nr: N_v 1/2 rho L^2 d (kg), N_r 1/2 rho L^3 d (kg m).
        kcf: 1/2 rho d C_D (kg/m^2); cry, crn: C_rY, C_rN.
        rho_d2: rho D^2 (kg/m); d_p: D (m); one_m_tp: 1 - t_P.
        wp0, tau_p, cp_p, xp_l: w_P0, tau_P, C_P and x_P L (m).
        k0, k1, k2: open-water K_T polynomial.
        c0 .. c3: Hachii's astern thrust (c_P0..c_P3).
        ya0 .. ya4, nb0 .. nb4: Hachii's side force and moment, times 1/2 rho L d and
            1/2 rho L^2 d.
        ya5 .. ya7, nb5 .. nb7: second-quadrant side force and moment (Ueno), times
            1/2 rho L d (P/D)^2 and 1/2 rho L^2 d (P/D)^2 and their switch (0 or 1).
        eps, kappa, kx_rev, c_pr, eta: rudder inflow (epsilon, k_x / epsilon, k_x,rev, C_PR,
            D / H_R).
        gam_p, gam_m, l_r: gamma_R_plus, gamma_R_minus, l_R L (m).
        rud_k: 1/2 rho A_R f_alpha (kg/m); rud_astern: 1 if the rudder acts at n <= 0.
        xr_k, yr_k, nr_k: -(1 - t_R), -(1 + a_H), -(x_R + a_H x_H) L (m).
        mx_den, m_my, m_mx, xg_m, inv11, inv12, inv22: mass terms as in :class:`.mmg.MMGParams`.
        wind_*: windage columns, :data:`trafficsim.ships.wind.WINDAGE_FIELDS`.
        delta0: rudder neutral offset, rad.
    """

    half_l: np.ndarray
    x0f: np.ndarray
    x0a: np.ndarray
    xvr: np.ndarray
    yv: np.ndarray
    yr: np.ndarray
    nv: np.ndarray
    nr: np.ndarray
    kcf: np.ndarray
    cry: np.ndarray
    crn: np.ndarray
    rho_d2: np.ndarray
    d_p: np.ndarray
    one_m_tp: np.ndarray
    wp0: np.ndarray
    tau_p: np.ndarray
    cp_p: np.ndarray
    xp_l: np.ndarray
    k0: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    c0: np.ndarray
    c1: np.ndarray
    c2: np.ndarray
    c3: np.ndarray
    ya0: np.ndarray
    ya1: np.ndarray
    ya2: np.ndarray
    ya3: np.ndarray
    ya4: np.ndarray
    ya5: np.ndarray
    ya6: np.ndarray
    ya7: np.ndarray
    nb0: np.ndarray
    nb1: np.ndarray
    nb2: np.ndarray
    nb3: np.ndarray
    nb4: np.ndarray
    nb5: np.ndarray
    nb6: np.ndarray
    nb7: np.ndarray
    eps: np.ndarray
    kappa: np.ndarray
    kx_rev: np.ndarray
    c_pr: np.ndarray
    eta: np.ndarray
    gam_p: np.ndarray
    gam_m: np.ndarray
    l_r: np.ndarray
    rud_k: np.ndarray
    rud_astern: np.ndarray
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


_FIELDS = tuple(f.name for f in fields(BerthingParams))
(_HALF_L, _X0F, _X0A, _XVR, _YV, _YR, _NV, _NR, _KCF, _CRY, _CRN, _RHO_D2, _D_P, _ONE_M_TP,
 _WP0, _TAU_P, _CP_P, _XP_L, _K0, _K1, _K2, _C0, _C1, _C2, _C3,
 _YA0, _YA1, _YA2, _YA3, _YA4, _YA5, _YA6, _YA7, _NB0, _NB1, _NB2, _NB3, _NB4, _NB5, _NB6, _NB7,
 _EPS, _KAPPA, _KX_REV, _C_PR, _ETA, _GAM_P, _GAM_M, _L_R, _RUD_K, _RUD_ASTERN,
 _XR_K, _YR_K, _NR_K, _MX_DEN, _M_MY, _M_MX, _XG_M, _INV11, _INV12, _INV22) = range(61)
_W0 = _FIELDS.index(wind.WINDAGE_FIELDS[0])
_W1 = _W0 + len(wind.WINDAGE_FIELDS)
_DELTA0 = _FIELDS.index("delta0")
assert _FIELDS[_MX_DEN:_INV22 + 1] == MASS_FIELDS and _FIELDS[_W0:_W1] == wind.WINDAGE_FIELDS


class MMGBerthingFamily:
    """Low-speed MMG model of [M22] with Isherwood wind loads (module doc)."""

    name = "mmg_berthing"
    supports_astern = True
    #: Non-dimensional coefficients ([M22] / [YY15] notation); None = required.
    coefficients: Mapping[str, float | None] = {
        # hull [YNI09]: resistance ahead / astern (negative), surge-sway coupling, linear
        # derivatives, cross-flow drag and its yaw-rate corrections
        "X_0F": None, "X_0A": None, "X_vr": None, "Y_v": None, "Y_r": None, "N_v": None,
        "N_r": None, "C_D": None, "C_rY": None, "C_rN": None,
        # added masses (by 1/2 rho L^2 d; J_z by 1/2 rho L^4 d) and yaw gyradius k_zz / L
        "m_x": None, "m_y": None, "J_z": None, "k_zz": 0.25,
        # propeller: thrust deduction, wake (w_P0, tau_P, C_P), x'_P, open-water K_T
        "t_P": None, "w_P0": None, "tau_P": None, "C_P": None, "x_P": None,
        "k_0": None, "k_1": None, "k_2": None,
        # Hachii's astern thrust (c_P0..c_P3), side force (a_P0..a_P4) and moment (b_P0..b_P4);
        # the second quadrant's side force (a_P5..a_P7) and moment (b_P5..b_P7) with switches
        "c_P0": None, "c_P1": None, "c_P2": None, "c_P3": None,
        **{f"a_P{i}": None for i in range(8)}, **{f"b_P{i}": None for i in range(8)},
        "switch_prop_y": 1.0, "switch_prop_n": 1.0,
        # rudder and interaction; k_x = epsilon kappa; reversed-propeller inflow k_x,rev, C_PR
        "t_R": None, "a_H": None, "x_H": None, "x_R": -0.5, "l_R": None,
        "gamma_R_plus": None, "gamma_R_minus": None, "epsilon": None, "k_x": None,
        "k_x_reverse": None, "C_PR": None, "f_alpha": None, "switch_rudder_astern": 1.0,
        # rudder neutral offset, rad (propeller asymmetry; not in [M22])
        "delta_0": 0.0,
    }
    limits: Mapping[str, Limit] = {
        "X_0F": Limit(lt=0, what="resistance coefficient ahead, negative"),
        "X_0A": Limit(lt=0, what="resistance coefficient astern, negative"),
        "C_D": Limit(ge=0, what="cross-flow drag coefficient"),
        "m_x": ADDED_MASS, "m_y": ADDED_MASS, "J_z": ADDED_MASS, "k_zz": GYRADIUS,
        "t_P": THRUST_DEDUCTION, "w_P0": WAKE_FRACTION, "k_0": BOLLARD_THRUST,
        "t_R": RUDDER_DRAG_DEDUCTION,
        "gamma_R_plus": FLOW_STRAIGHTENING, "gamma_R_minus": FLOW_STRAIGHTENING,
        "epsilon": WAKE_RATIO, "k_x": Limit(ge=0, what="propeller race coefficient"),
        "f_alpha": LIFT_GRADIENT,
        **{key: Limit(one_of=(0.0, 1.0), what="a switch") for key in (
            "switch_prop_y", "switch_prop_n", "switch_rudder_astern")},
    }

    def cross_problems(self, ship: Mapping[str, Any]) -> list[tuple[str, str]]:
        """No checks between numbers beyond the ranges of :attr:`limits`."""
        return []

    def build(self, ships: Sequence[Mapping[str, Any]]) -> BerthingParams:
        """Parameters from ship-file dicts (``particulars`` and ``coefficients``).

        Required particulars besides length/beam/draught: ``displacement_m3``,
        ``propeller_diameter_m``, ``propeller_pitch_ratio``, ``rudder_area_m2``,
        ``rudder_height_m``; optional ``lcg_m`` (default 0), ``water_density_kgpm3`` (default
        1025) and the windage particulars of :mod:`trafficsim.ships.wind`.
        """
        def col(key: str) -> np.ndarray:
            return np.array([coefficient(s, key, self.coefficients[key], self.name)
                             for s in ships], dtype=float)

        def part(key: str) -> np.ndarray:
            return np.array([particular(s, key, _PARTICULARS, self.name) for s in ships],
                            dtype=float)

        for key in ("switch_prop_y", "switch_prop_n", "switch_rudder_astern"):
            bad = [s for s in ships if coefficient(s, key, 1.0, self.name) not in (0.0, 1.0)]
            if bad:
                raise ShipLibraryError(f"coefficient '{key}' must be 0 or 1 (ship "
                                       f"{bad[0].get('name', '?')})", path=bad[0].get("path"),
                                       key=f"coefficients.{key}")
        rho = part("water_density_kgpm3")
        L, d = part("length_m"), part("draught_m")
        disp, x_g = part("displacement_m3"), part("lcg_m")
        d_p, h_r = part("propeller_diameter_m"), part("rudder_height_m")
        pd2 = part("propeller_pitch_ratio") ** 2
        fx = 0.5 * rho * L * d
        fn = fx * L
        m = rho * disp
        m_x, m_y = col("m_x") * fn, col("m_y") * fn
        j_z = col("J_z") * fn * L * L
        i_tot = m * (col("k_zz") * L) ** 2 + x_g**2 * m + j_z
        a_h, eps = col("a_H"), col("epsilon")
        sw_y, sw_n = col("switch_prop_y"), col("switch_prop_n")
        w = wind.build(ships)
        return BerthingParams(
            half_l=0.5 * L,
            x0f=fx * col("X_0F"), x0a=fx * col("X_0A"), xvr=fn * col("X_vr"),
            yv=fx * col("Y_v"), yr=fn * col("Y_r"), nv=fn * col("N_v"), nr=fn * L * col("N_r"),
            kcf=0.5 * rho * d * col("C_D"), cry=col("C_rY"), crn=col("C_rN"),
            rho_d2=rho * d_p**2, d_p=d_p, one_m_tp=1.0 - col("t_P"),
            wp0=col("w_P0"), tau_p=col("tau_P"), cp_p=col("C_P"), xp_l=col("x_P") * L,
            k0=col("k_0"), k1=col("k_1"), k2=col("k_2"),
            c0=col("c_P0"), c1=col("c_P1"), c2=col("c_P2"), c3=col("c_P3"),
            **{f"ya{i}": fx * col(f"a_P{i}") for i in range(5)},
            **{f"ya{i}": fx * pd2 * sw_y * col(f"a_P{i}") for i in range(5, 8)},
            **{f"nb{i}": fn * col(f"b_P{i}") for i in range(5)},
            **{f"nb{i}": fn * pd2 * sw_n * col(f"b_P{i}") for i in range(5, 8)},
            eps=eps, kappa=col("k_x") / eps, kx_rev=col("k_x_reverse"), c_pr=col("C_PR"),
            eta=d_p / h_r, gam_p=col("gamma_R_plus"), gam_m=col("gamma_R_minus"),
            l_r=col("l_R") * L,
            rud_k=0.5 * rho * part("rudder_area_m2") * col("f_alpha"),
            rud_astern=col("switch_rudder_astern"),
            xr_k=-(1.0 - col("t_R")), yr_k=-(1.0 + a_h),
            nr_k=-(col("x_R") + a_h * col("x_H")) * L,
            **mass_terms(m, m_x, m_y, i_tot, x_g),
            **{f.name: getattr(w, f.name) for f in fields(w)},
            delta0=col("delta_0"),
        )


@inline_kernel
def _piece(a: float, b: float, x0: float, x1: float, moment: bool) -> float:
    """int_{x0}^{x1} (a + b x)^2 dx, or with ``moment`` int (a + b x)^2 x dx (exact)."""
    d1, d2, d3 = x1 - x0, x1 * x1 - x0 * x0, x1**3 - x0**3
    if not moment:
        return a * a * d1 + a * b * d2 + b * b * d3 / 3.0
    return 0.5 * a * a * d2 + 2.0 * a * b * d3 / 3.0 + 0.25 * b * b * (x1**4 - x0**4)


@kernel
def cross_flow(a: float, b: float, half_l: float, moment: bool) -> float:
    """Cross-flow integral of [YNI09] in closed form: int_{-L/2}^{L/2} |a + b x| (a + b x) dx
    (m^3/s^2), or with ``moment`` the same times x (m^4/s^2); a = v (m/s), b = C_r r (1/s).

    The integrand is sign(a + b x) (a + b x)^2: a polynomial on either side of the section
    x_0 = -a / b where the local velocity changes sign, so each side is integrated exactly.
    """
    lo, hi = -half_l, half_l
    if b != 0.0:
        x_zero = -a / b
        if lo < x_zero < hi:
            s_lo = 1.0 if a + b * lo > 0.0 else -1.0
            return (s_lo * _piece(a, b, lo, x_zero, moment)
                    - s_lo * _piece(a, b, x_zero, hi, moment))
    # no sign change inside: the local velocity has the sign of its midship value a (a = 0
    # with b != 0 changes sign at midship, handled above; a = b = 0 gives 0)
    s = 1.0 if a > 0.0 else (-1.0 if a < 0.0 else 0.0)
    return s * _piece(a, b, lo, hi, moment)


@kernel
def propeller(p: np.ndarray, u: float, v: float, r: float, n: float
              ) -> tuple[float, float, float, float, float]:
    """Propeller of ONE ship (module doc): ``(X_P, Y_P, N_P, u_P, q)``, N, N, N m, m/s and
    q = n^2 D^2 K_T (m^2/s^2, the thrust over rho D^2 without the thrust deduction)."""
    big_u = math.sqrt(u * u + v * v)
    beta_p = (v + p[_XP_L] * r) / big_u if big_u > 0.0 else 0.0
    one_m_wp = 1.0
    if u > 0.0:
        one_m_wp = 1.0 - (p[_WP0] - p[_TAU_P] * abs(beta_p) - p[_CP_P] * beta_p * beta_p)
        one_m_wp = min(max(one_m_wp, 1e-12), 1.0)
    u_p = one_m_wp * u
    nd = n * p[_D_P]
    y_p = 0.0
    n_p = 0.0
    if n >= 0.0:
        q = p[_K0] * nd * nd + p[_K1] * nd * u_p + p[_K2] * u_p * u_p
        if abs(u_p) > J_FADE * nd:  # |J| > J_FADE: fade as J_FADE / |J| (0 at n = 0)
            q *= J_FADE * nd / abs(u_p)
        thrust = p[_RHO_D2] * p[_ONE_M_TP] * q
        if u < 0.0:
            # second quadrant (Ueno): 1/2 rho L d (P/D)^2 (a5 u^2 + a6 u nD + a7 (nD)^2)
            g = 1.0
            au = -u
            if au < J_RAMP * nd:
                g = au / (J_RAMP * nd)
            elif au > J_FADE * nd:
                g = J_FADE * nd / au
            y_p = g * (p[_YA5] * u * u + p[_YA6] * u * nd + p[_YA7] * nd * nd)
            n_p = g * (p[_NB5] * u * u + p[_NB6] * u * nd + p[_NB7] * nd * nd)
    else:
        js = u / nd
        # Hachii: n^2 D^2 (c_P1 + c_P2 J_s) above J_s = c_P3, n^2 D^2 c_P0 below
        q = p[_C1] * nd * nd + p[_C2] * u * nd if js >= p[_C3] else p[_C0] * nd * nd
        thrust = p[_RHO_D2] * q
        nd2 = nd * nd
        if js < J_SYN:
            y_p = p[_YA2] * nd2 + p[_YA3] * u * nd
            n_p = p[_NB2] * nd2 + p[_NB3] * u * nd
        elif js <= J_SYN0:
            y_p = p[_YA0] * nd2 + p[_YA1] * u * nd
            n_p = p[_NB0] * nd2 + p[_NB1] * u * nd
        else:
            y_p = p[_YA4] * nd2
            n_p = p[_NB4] * nd2
    return thrust, y_p, n_p, u_p, q


@kernel
def rudder_inflow(p: np.ndarray, u: float, n: float, u_p: float, q: float) -> float:
    """Longitudinal rudder inflow u_R (m/s) of ONE ship (module doc)."""
    if n >= 0.0 and q > 0.0:
        race = u_p + p[_KAPPA] * (math.sqrt(u_p * u_p + _EIGHT_OVER_PI * q) - u_p)
        return p[_EPS] * math.sqrt(p[_ETA] * race * race + (1.0 - p[_ETA]) * u_p * u_p)
    if u < 0.0:
        return u
    sign_n = 1.0 if n > 0.0 else (-1.0 if n < 0.0 else 0.0)
    p1 = p[_EPS] * u_p + sign_n * p[_KX_REV] * math.sqrt(_EIGHT_OVER_PI * abs(q))
    p2 = p[_EPS] * u_p
    sq = (p[_ETA] * (1.0 if p1 >= 0.0 else -1.0) * p1 * p1 + (1.0 - p[_ETA]) * p2 * p2
          + p[_C_PR] * u * u)
    u_r = math.copysign(math.sqrt(abs(sq)), sq)
    band = J_RAMP * abs(n * p[_D_P])
    if n < 0.0 and u < band:  # blend into the fourth quadrant's u_R = u as u -> 0
        f = u / band
        u_r = f * u_r + (1.0 - f) * u
    return u_r


@kernel
def accel(p: np.ndarray, x: np.ndarray, env: np.ndarray) -> tuple[float, float, float]:
    """Body-frame accelerations of ONE ship ([YY15] motion equations at midship).

    Args:
        p: ``float64[72]`` packed parameter row (:class:`BerthingParams`).
        x: ``float64[8]`` state in the ``base`` layout: u, v (midship, through the water,
            m/s), r (rad/s), rudder (rad, + = starboard turn), rps (rev/s).
        env: ``float64[4]`` (current north, current east, wind speed, wind from); the wind
            loads use it, the current is in the kinematics.

    Returns:
        ``(du, dv, dr)`` in m/s2, m/s2, rad/s2.
    """
    u, v, r, n = x[U], x[V], x[YAW_RATE], x[RPS]
    delta = x[RUDDER] + p[_DELTA0]
    big_u = math.sqrt(u * u + v * v)

    # hull [YNI09]
    frac_astern = abs(math.atan2(v, u)) / math.pi
    x_h = (p[_X0F] + (p[_X0A] - p[_X0F]) * frac_astern) * u * big_u + p[_XVR] * v * r
    y_h = (p[_YV] * v * abs(u) + p[_YR] * r * u
           - p[_KCF] * cross_flow(v, p[_CRY] * r, p[_HALF_L], False))
    n_h = (p[_NV] * v * u + p[_NR] * r * abs(u)
           - p[_KCF] * cross_flow(v, p[_CRN] * r, p[_HALF_L], True))

    # propeller and rudder
    x_p, y_p, n_p, u_p, q = propeller(p, u, v, r, n)
    u_r = rudder_inflow(p, u, n, u_p, q)
    lat = v + p[_L_R] * r
    v_r = -(p[_GAM_M] if lat >= 0.0 else p[_GAM_P]) * lat
    f_n = p[_RUD_K] * (u_r * u_r + v_r * v_r) * math.sin(delta - math.atan2(v_r, u_r))
    if n <= 0.0 and p[_RUD_ASTERN] == 0.0:
        f_n = 0.0
    cos_d = math.cos(delta)

    xa, ya, na = wind.loads1(p[_W0:_W1], x, env)
    xf = x_h + x_p + p[_XR_K] * f_n * math.sin(delta) + xa
    yf = y_h + y_p + p[_YR_K] * f_n * cos_d + ya
    nf = n_h + n_p + p[_NR_K] * f_n * cos_d + na

    return midship_accel(p, _MX_DEN, xf, yf, nf, u, v, r)


FAMILY = register(MMGBerthingFamily())
