"""An MMG parameter folder (``principal_particulars.csv``, ``MMG_params.csv``,
``model_switch.csv``, as published with the Esso Osaka berthing model of Miyauchi et al. 2022)
read at run time as an ``mmg`` ship spec; nothing of it is stored in the project.

Mapping onto the ``mmg`` family (:mod:`trafficsim.ships.mmg`, [YY15] notation):

=============================  ==========================================================
folder                         ship spec
=============================  ==========================================================
lpp, breadth, draft            length_m, beam_m, draught_m
mass_nd (m / (1/2 rho L^2 d))  displacement_m3 = mass_nd L^2 d / 2 (the model is written in
                               non-dimensional masses, so the density cancels)
x_lcg                          lcg_m
dia_prop, area_rudder          propeller_diameter_m, rudder_area_m2
lambda_rudder (H^2 / A)        rudder_height_m = sqrt(lambda A); f_alpha = 6.13 lambda /
                               (lambda + 2.25) (Fujii's formula, as in [YY15])
x_location_rudder              x_R = x / L
area_projected_trans/lateral   windage_frontal/lateral_area_m2 (wind model off in the base)
massx_nd, massy_nd             m_x, m_y
IzzJzz_nd                      J_z = IzzJzz_nd - mass_nd k_zz^2 with k_zz = 0.25
xuu_nd, xvr_nd                 R0 = -xuu_nd, X_vr
yv_nd, yr_nd, nv_nd, nr_nd     Y_v, Y_r, N_v, N_r
kt_coeff0..2, t_prop,          k_0..k_2, t_P, w_P0, x_P
w_prop_zero, xp_prop_nd
t_rudder, ah_rudder,           t_R, a_H, x_H, l_R, kappa, epsilon, gamma_R_minus,
xh_rudder_nd, lr_rudder_nd,    gamma_R_plus
kx_rudder, epsilon_rudder,
gammaN_rudder, gammaP_rudder
=============================  ==========================================================

What the family cannot represent -- the cross-flow drag hull model (``coeff_drag_sway``,
``cry_cross_flow``, ``crn_cross_flow``, ``coeff_drag_fore``, ``coeff_drag_aft``) in place of
[YY15]'s cubic polynomials, the four-quadrant propeller and its lateral force (``ai_*``, ``bi_*``,
``ci_*``, ``Jmin``, ``alpha_prop``, ``tau_prop``, ``coeff_cp_prop`` with ``switch_prop_y/n``),
the reverse-flow rudder terms (``kx_rudder_reverse``, ``cpr_rudder``, ``coeff_urudder_zero``)
-- is reported as one :class:`~trafficsim.errors.InputError` listing the entries; nothing is
dropped silently. Fujiwara's wind regressors other than the areas (``AOD``, ``LCW``, ``LCBR``,
``HBR``, ``HC``, ``SBW``, ``Lz``) are not needed: the base model runs without wind (the wind is
a candidate effect of the diagnosis, with the Isherwood loads of the areas).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from trafficsim.errors import InputError

FILES = ("principal_particulars.csv", "MMG_params.csv", "model_switch.csv")
NOT_REPRESENTABLE = ("coeff_drag_sway", "cry_cross_flow", "crn_cross_flow", "coeff_drag_fore",
                     "coeff_drag_aft", "tau_prop", "coeff_cp_prop", "Jmin", "alpha_prop",
                     "kx_rudder_reverse", "cpr_rudder", "coeff_urudder_zero")
NOT_REPRESENTABLE_PREFIX = ("ai_coeff_prop", "bi_coeff_prop", "ci_coeff_prop")
_IGNORED = ("rho_fresh", "rho_air", "pitchr", "maxtickness_rudder", "AOD", "LCW", "LCBR", "HBR",
            "HC", "SBW", "Lz")
_SWITCHES = ("switch_prop_x", "switch_prop_y", "switch_prop_n", "switch_rudder", "switch_wind",
             "switch_windtype", "switch_fn", "switch_ur")


def _table(path: Path, value_col: int) -> dict[str, float]:
    if not path.is_file():
        raise InputError(f"missing {path.name} in the MMG parameter folder", path=str(path))
    out: dict[str, float] = {}
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    for line, row in enumerate(rows[1:], start=2):
        if not row or not row[0].strip():
            continue
        try:
            out[row[0].strip()] = float(row[value_col])
        except (ValueError, IndexError):
            raise InputError(f"line {line}: expected a number in column {value_col + 1}, got "
                             f"{row!r}", path=str(path)) from None
    return out


def read_folder(folder: Path) -> dict[str, Any]:
    """The folder as an ``mmg`` ship spec (module doc), or one InputError naming what the
    family cannot represent."""
    pp = _table(folder / FILES[0], 1)
    mp = _table(folder / FILES[1], 1)
    sw = _table(folder / FILES[2], 1)
    known = {"lpp", "breadth", "draft", "mass_nd", "x_lcg", "dia_prop", "area_rudder",
             "lambda_rudder", "x_location_rudder", "area_projected_trans",
             "area_projected_lateral", *_IGNORED}
    unknown = [k for k in pp if k not in known] + [k for k in sw if k not in _SWITCHES]
    mapped = {"massx_nd": "m_x", "massy_nd": "m_y", "xvr_nd": "X_vr", "yv_nd": "Y_v",
              "yr_nd": "Y_r", "nv_nd": "N_v", "nr_nd": "N_r", "kt_coeff0": "k_0",
              "kt_coeff1": "k_1", "kt_coeff2": "k_2", "t_prop": "t_P", "w_prop_zero": "w_P0",
              "xp_prop_nd": "x_P", "t_rudder": "t_R", "ah_rudder": "a_H",
              "xh_rudder_nd": "x_H", "lr_rudder_nd": "l_R", "kx_rudder": "kappa",
              "epsilon_rudder": "epsilon", "gammaN_rudder": "gamma_R_minus",
              "gammaP_rudder": "gamma_R_plus"}
    special = {"IzzJzz_nd", "xuu_nd"}
    lost = []
    for key, value in mp.items():
        if key in mapped or key in special:
            continue
        if key in NOT_REPRESENTABLE or key.startswith(NOT_REPRESENTABLE_PREFIX):
            if value != 0.0:
                lost.append(key)
        else:
            unknown.append(key)
    if unknown:
        raise InputError(f"unknown entries {', '.join(unknown)} (not in the Miyauchi 2022 MMG "
                         "parameter format)", path=str(folder))
    if lost:
        raise InputError("the mmg family (MMG standard method) cannot represent "
                         f"{', '.join(lost)} (cross-flow drag hull, four-quadrant propeller and "
                         "its lateral force, reverse-flow rudder); give a ship file instead",
                         path=str(folder))
    length, draught = pp["lpp"], pp["draft"]
    lam = pp["lambda_rudder"]
    coeffs = {mapped[k]: v for k, v in mp.items() if k in mapped}
    coeffs["R0"] = -mp["xuu_nd"]
    coeffs["k_zz"] = 0.25
    coeffs["J_z"] = mp["IzzJzz_nd"] - pp["mass_nd"] * 0.25**2
    coeffs["x_R"] = pp["x_location_rudder"] / length
    coeffs["f_alpha"] = 6.13 * lam / (lam + 2.25)
    for key in ("X_vv", "X_rr", "X_vvvv", "Y_vvv", "Y_vvr", "Y_vrr", "Y_rrr", "N_vvv", "N_vvr",
                "N_vrr", "N_rrr"):
        coeffs.setdefault(key, 0.0)
    return {
        "schema_version": 1, "name": folder.name, "model": "mmg", "path": str(folder),
        "particulars": {"length_m": length, "beam_m": pp["breadth"], "draught_m": draught,
                        "displacement_m3": pp["mass_nd"] * 0.5 * length**2 * draught,
                        "lcg_m": pp["x_lcg"], "propeller_diameter_m": pp["dia_prop"],
                        "rudder_area_m2": pp["area_rudder"],
                        "rudder_height_m": math.sqrt(lam * pp["area_rudder"]),
                        "windage_frontal_area_m2": pp["area_projected_trans"],
                        "windage_lateral_area_m2": pp["area_projected_lateral"]},
        "service_speed_kn": 0.8,
        "actuators": {"rudder_max_deg": 35.0, "rudder_rate_degps": 20.0, "rudder_tau_s": 0.1,
                      "rps_max": 30.0, "rps_min": -30.0, "engine_tau_s": 1.0},
        "coefficients": coeffs, "integration": {"max_dt_s": 0.05},
        "mmg_folder": f"base model read from {folder}",
    }
