"""An MMG parameter folder (``principal_particulars.csv``, ``MMG_params.csv``,
``model_switch.csv``, the format published with the Esso Osaka berthing model of Miyauchi et al.
2022) read at run time as an ``mmg_berthing`` ship spec (:mod:`trafficsim.ships.mmg_berthing`);
nothing of it is stored in the project.

Every entry is either mapped or listed below as ignored; anything else, a missing entry, a
repeated one, a value that is not a number, a row with more cells than its header, a switch the
family does not implement, a byte that is not UTF-8 or a value outside the range the family's
ship files are held to (:func:`trafficsim.ships.base.limit_problems`, located at the entry that
gives it) is one :class:`~trafficsim.errors.InputError` naming the file, the line and the key.

``principal_particulars.csv`` (``parameter,value``):

==========================  ================================================================
lpp, breadth, draft         length_m, beam_m, draught_m
mass_nd (m / (1/2 rho L^2   displacement_m3 = mass_nd L^2 d / 2 (with the folder's density the
d))                         mass is right: 244.6 kg for the Esso Osaka model)
rho_fresh                   water_density_kgpm3 (mass and every hydrodynamic force)
x_lcg (x_G / L)             lcg_m = x_lcg L (0.094 m for the Esso Osaka model, as its data set
                            states)
dia_prop, pitchr            propeller_diameter_m, propeller_pitch_ratio
area_rudder, lambda_rudder  rudder_area_m2; rudder_height_m = sqrt(lambda A_R); coefficient
(H_R^2 / A_R)               f_alpha = 6.13 lambda / (lambda + 2.25) (Fujii)
x_location_rudder (m)       coefficient x_R = x / L
area_projected_trans,       windage_frontal_area_m2, windage_lateral_area_m2,
area_projected_lateral, AOD windage_superstructure_area_m2 (Isherwood's A_SS)
LCW (centroid of A_L ahead  windage_centroid_from_bow_m = L / 2 - LCW
of midship, m)
maxtickness_rudder          ignored: Lindenburg's rudder force only (switch_fn = 2, refused)
rho_air, LCBR, HBR, HC,     ignored: Fujiwara's wind regressors; the base runs without wind
SBW, Lz                     (the wind is a candidate effect of the diagnosis, with Isherwood's
                            loads on the areas above and 1.225 kg/m3 air)
==========================  ================================================================

``MMG_params.csv`` (``parameter,params_init,params_min,params_max``; ``params_init`` is the
model, ``params_min``/``params_max`` the ranges of [M22]'s parameter search, ignored):

=====================================  =======================================================
massx_nd, massy_nd                     m_x, m_y
IzzJzz_nd ((I_zG + J_z) / (1/2 rho     J_z = IzzJzz_nd - mass_nd k_zz^2 with k_zz = 0.25 (only
L^4 d))                                the sum enters the motion equations)
xuu_nd, coeff_drag_aft                 X_0F, X_0A (resistance ahead and astern)
coeff_drag_fore                        must equal xuu_nd: both are X_0F (the published
                                       simulator takes X_0F from xuu_nd)
xvr_nd, yv_nd, yr_nd, nv_nd, nr_nd     X_vr, Y_v, Y_r, N_v, N_r
coeff_drag_sway, cry_cross_flow,       C_D, C_rY, C_rN (cross-flow drag)
crn_cross_flow
kt_coeff0..2, t_prop, w_prop_zero,     k_0..k_2, t_P, w_P0, tau_P, C_P, x_P
tau_prop, coeff_cp_prop, xp_prop_nd
ai_coeff_prop0..7, bi_coeff_prop0..7,  a_P0..a_P7, b_P0..b_P7, c_P0..c_P3 (propeller side
ci_coeff_prop0..3                      force, moment and astern thrust)
t_rudder, ah_rudder, xh_rudder_nd,     t_R, a_H, x_H, l_R, k_x, k_x_reverse, epsilon, C_PR
lr_rudder_nd, kx_rudder,
kx_rudder_reverse, epsilon_rudder,
cpr_rudder
gammaN_rudder, gammaP_rudder           gamma_R_plus, gamma_R_minus (module doc of the family)
Jmin, alpha_prop                       ignored: second thrust model only (switch_prop_x = 2,
                                       refused)
coeff_urudder_zero                     ignored: second astern rudder inflow only (switch_ur =
                                       2, refused)
XX0, XX1, XX3, XX5, YY1, YY3, YY5,     ignored if present: Fujiwara's wind coefficients
NN1, NN2, NN3
=====================================  =======================================================

``model_switch.csv`` (``model,value``): ``switch_prop_x`` must be 1 (Hachii's astern thrust),
``switch_fn`` 1 (Fujii) and ``switch_ur`` 1 (Kitagawa); ``switch_prop_y``, ``switch_prop_n``,
``switch_rudder`` (0 or 1) become the coefficients ``switch_prop_y``, ``switch_prop_n``,
``switch_rudder_astern``; ``switch_wind`` and ``switch_windtype`` are ignored (base without
wind, as above).

Not in the folder (choices, as in ``tests/identify/data/esso_base.yaml``): service speed
0.4 m/s (the approach speed of the turning tests at 10 rps), rudder 35 deg at 24 deg/s with a
0.1 s lag, propeller speed within +-20 rps with a 0.5 s lag (the data's range), RK4 steps of at
most 0.25 s (replays of the FRT-DS-ESSO runs with 0.3 s and with 0.01 s steps agree to 1 mm and
0.01 deg), Isherwood's windage perimeter and mast groups at their defaults.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any

from trafficsim.errors import InputError

FILES = ("principal_particulars.csv", "MMG_params.csv", "model_switch.csv")
_HEADERS = {FILES[0]: ("parameter", "value"),
            FILES[1]: ("parameter", "params_init", "params_min", "params_max"),
            FILES[2]: ("model", "value")}

_PARTICULARS = ("lpp", "breadth", "draft", "mass_nd", "x_lcg", "rho_fresh", "dia_prop", "pitchr",
                "area_rudder", "lambda_rudder", "x_location_rudder", "area_projected_trans",
                "area_projected_lateral", "AOD", "LCW")
_PARTICULARS_IGNORED = ("maxtickness_rudder", "rho_air", "LCBR", "HBR", "HC", "SBW", "Lz")

#: MMG_params.csv entry -> mmg_berthing coefficient
_COEFFICIENTS = {
    "massx_nd": "m_x", "massy_nd": "m_y", "xuu_nd": "X_0F", "coeff_drag_aft": "X_0A",
    "xvr_nd": "X_vr", "yv_nd": "Y_v", "yr_nd": "Y_r", "nv_nd": "N_v", "nr_nd": "N_r",
    "coeff_drag_sway": "C_D", "cry_cross_flow": "C_rY", "crn_cross_flow": "C_rN",
    "kt_coeff0": "k_0", "kt_coeff1": "k_1", "kt_coeff2": "k_2", "t_prop": "t_P",
    "w_prop_zero": "w_P0", "tau_prop": "tau_P", "coeff_cp_prop": "C_P", "xp_prop_nd": "x_P",
    **{f"ai_coeff_prop{i}": f"a_P{i}" for i in range(8)},
    **{f"bi_coeff_prop{i}": f"b_P{i}" for i in range(8)},
    **{f"ci_coeff_prop{i}": f"c_P{i}" for i in range(4)},
    "t_rudder": "t_R", "ah_rudder": "a_H", "xh_rudder_nd": "x_H", "lr_rudder_nd": "l_R",
    "kx_rudder": "k_x", "kx_rudder_reverse": "k_x_reverse", "epsilon_rudder": "epsilon",
    "cpr_rudder": "C_PR", "gammaN_rudder": "gamma_R_plus", "gammaP_rudder": "gamma_R_minus",
}
_PARAMS_OTHER = ("IzzJzz_nd", "coeff_drag_fore")
#: read if present, not used (module doc)
_PARAMS_IGNORED = ("Jmin", "alpha_prop", "coeff_urudder_zero", "XX0", "XX1", "XX3", "XX5",
                   "YY1", "YY3", "YY5", "NN1", "NN2", "NN3")

#: switch -> (values accepted, coefficient it sets or None, what the other values would be)
_SWITCHES: dict[str, tuple[tuple[float, ...], str | None, str]] = {
    "switch_prop_x": ((1.0,), None, "2 is the second thrust model, not implemented"),
    "switch_prop_y": ((0.0, 1.0), "switch_prop_y", ""),
    "switch_prop_n": ((0.0, 1.0), "switch_prop_n", ""),
    "switch_rudder": ((0.0, 1.0), "switch_rudder_astern", ""),
    "switch_fn": ((1.0,), None, "2 is Lindenburg's rudder force, not implemented"),
    "switch_ur": ((1.0,), None, "2 is the second astern rudder inflow, not implemented"),
    "switch_wind": ((0.0, 1.0), None, ""),
    "switch_windtype": ((1.0, 2.0, 3.0, 4.0), None, ""),
}
K_ZZ = 0.25
IGNORED = (*_PARTICULARS_IGNORED, *_PARAMS_IGNORED, "switch_wind", "switch_windtype",
           "params_min", "params_max")


class _Table:
    """One CSV of the folder: values by key with their line numbers."""

    def __init__(self, folder: Path, name: str) -> None:
        self.path = folder / name
        if not self.path.is_file():
            raise InputError(f"missing {name} in the MMG parameter folder (expected "
                             f"{', '.join(FILES)})", path=str(folder))
        data = self.path.read_bytes()
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            line = data.count(b"\n", 0, exc.start) + 1
            raise InputError(f"file is not UTF-8 text (byte 0x{data[exc.start]:02X}); save it "
                             "as UTF-8", path=str(self.path), line=line) from None
        rows = list(csv.reader(io.StringIO(text, newline="")))
        header = tuple(c.strip() for c in rows[0]) if rows else ()
        if header != _HEADERS[name]:
            raise InputError(f"expected the header {','.join(_HEADERS[name])}, got "
                             f"{','.join(header) or 'nothing'}", path=str(self.path), line=1)
        self.values: dict[str, float] = {}
        self.lines: dict[str, int] = {}
        for line, row in enumerate(rows[1:], start=2):
            if not row or not "".join(row).strip():
                continue
            key = row[0].strip()
            if any(cell.strip() for cell in row[len(header):]):
                raise InputError(f"expected at most {len(header)} columns "
                                 f"({','.join(header)}), got {len(row)}",
                                 path=str(self.path), line=line, key=key or None)
            if key in self.values:
                raise InputError(f"'{key}' given twice (first on line {self.lines[key]})",
                                 path=str(self.path), line=line, key=key)
            try:
                value = float(row[1])
            except (ValueError, IndexError):
                got = row[1].strip() if len(row) > 1 else "nothing"
                raise InputError(f"expected a number in column 2, got {got!r}",
                                 path=str(self.path), line=line, key=key) from None
            if not math.isfinite(value):
                raise InputError(f"expected a finite number, got {value}",
                                 path=str(self.path), line=line, key=key)
            self.values[key] = value
            self.lines[key] = line

    def check_keys(self, required: tuple[str, ...], allowed: tuple[str, ...]) -> None:
        for key, line in self.lines.items():
            if key not in required and key not in allowed:
                raise InputError(f"unknown entry (not in the MMG parameter folder format of "
                                 f"Miyauchi et al. 2022; expected one of "
                                 f"{', '.join((*required, *allowed))})",
                                 path=str(self.path), line=line, key=key)
        for key in required:
            if key not in self.values:
                raise InputError("missing entry", path=str(self.path), key=key)

    def error(self, key: str, message: str) -> InputError:
        return InputError(message, path=str(self.path), line=self.lines.get(key), key=key)

    def positive(self, key: str) -> float:
        value = self.values[key]
        if value <= 0.0:
            raise self.error(key, f"must be > 0, got {value:g}")
        return value


def read_folder(folder: Path) -> dict[str, Any]:
    """The folder as an ``mmg_berthing`` ship spec (module doc), or one InputError."""
    folder = Path(folder)
    pp = _Table(folder, FILES[0])
    mp = _Table(folder, FILES[1])
    sw = _Table(folder, FILES[2])
    pp.check_keys(_PARTICULARS, _PARTICULARS_IGNORED)
    mp.check_keys((*_COEFFICIENTS, *_PARAMS_OTHER), _PARAMS_IGNORED)
    sw.check_keys(tuple(_SWITCHES), ())

    coeffs: dict[str, float] = {}
    for key, (allowed, target, other) in _SWITCHES.items():
        value = sw.values[key]
        if value not in allowed:
            why = f" ({other})" if other else ""
            raise sw.error(key, f"expected one of {', '.join(f'{a:g}' for a in allowed)}, got "
                                f"{value:g}{why}")
        if target is not None:
            coeffs[target] = value

    length, draught = pp.positive("lpp"), pp.positive("draft")
    mass_nd = pp.positive("mass_nd")
    for key in ("breadth", "rho_fresh", "dia_prop", "pitchr", "area_rudder", "lambda_rudder"):
        pp.positive(key)
    coeffs.update({target: mp.values[key] for key, target in _COEFFICIENTS.items()})
    fore, xuu = mp.values["coeff_drag_fore"], mp.values["xuu_nd"]
    if not math.isclose(fore, xuu, rel_tol=1e-9, abs_tol=1e-12):
        raise mp.error("coeff_drag_fore", f"differs from xuu_nd ({xuu:g}, line "
                                          f"{mp.lines['xuu_nd']}): both are the resistance "
                                          f"coefficient ahead X_0F")
    coeffs["k_zz"] = K_ZZ
    coeffs["J_z"] = mp.values["IzzJzz_nd"] - mass_nd * K_ZZ**2
    if coeffs["J_z"] < 0.0:
        raise mp.error("IzzJzz_nd", f"{mp.values['IzzJzz_nd']:g} is below the hull's own yaw "
                                    f"inertia mass_nd k_zz^2 = {mass_nd * K_ZZ**2:g}")
    for key in ("epsilon_rudder",):
        if mp.values[key] <= 0.0:
            raise mp.error(key, f"must be > 0, got {mp.values[key]:g}")
    lam = pp.values["lambda_rudder"]
    coeffs["f_alpha"] = 6.13 * lam / (lam + 2.25)
    coeffs["x_R"] = pp.values["x_location_rudder"] / length
    coeffs["delta_0"] = 0.0
    present = [k for k in IGNORED if k in pp.values or k in mp.values or k in sw.values]
    spec = {
        "schema_version": 1, "name": folder.name, "model": "mmg_berthing",
        "description": f"MMG parameter folder {folder} (Miyauchi et al. 2022 format), read at "
                       "run time",
        "source": "the folder's CSV files; mapping in trafficsim/diagnose/mmgfolder.py",
        "path": str(folder),
        "particulars": {
            "length_m": length, "beam_m": pp.values["breadth"], "draught_m": draught,
            "displacement_m3": mass_nd * 0.5 * length**2 * draught,
            "water_density_kgpm3": pp.values["rho_fresh"],
            "lcg_m": pp.values["x_lcg"] * length,
            "propeller_diameter_m": pp.values["dia_prop"],
            "propeller_pitch_ratio": pp.values["pitchr"],
            "rudder_area_m2": pp.values["area_rudder"],
            "rudder_height_m": math.sqrt(lam * pp.values["area_rudder"]),
            "windage_frontal_area_m2": pp.values["area_projected_trans"],
            "windage_lateral_area_m2": pp.values["area_projected_lateral"],
            "windage_superstructure_area_m2": pp.values["AOD"],
            "windage_centroid_from_bow_m": 0.5 * length - pp.values["LCW"]},
        "service_speed_kn": 0.4 * 3600.0 / 1852.0,
        "actuators": {"rudder_max_deg": 35.0, "rudder_rate_degps": 24.0, "rudder_tau_s": 0.1,
                      "rps_max": 20.0, "rps_min": -20.0, "engine_tau_s": 0.5},
        "coefficients": coeffs,
        "autopilot": {"kp": 3.0, "kd_s": 12.0, "ki_per_s": 0.0},
        "integration": {"max_dt_s": 0.25},
        "sensors": {},
        "mmg_folder": (f"base model: the MMG parameter folder {folder} (family mmg_berthing, "
                       "Miyauchi et al. 2022), read at run time; ignored entries: "
                       f"{', '.join(present)}, params_min/params_max"),
    }
    _check_limits(spec, {FILES[0]: pp, FILES[1]: mp, FILES[2]: sw})
    return spec


#: spec key -> (file, entry, how the entry gives it) for the model's range checks
_SOURCES: dict[str, tuple[str, str, str]] = {
    **{f"particulars.{target}": (FILES[0], key, how) for target, key, how in (
        ("length_m", "lpp", ""), ("beam_m", "breadth", ""), ("draught_m", "draft", ""),
        ("displacement_m3", "mass_nd", " = mass_nd lpp^2 draft / 2"),
        ("water_density_kgpm3", "rho_fresh", ""), ("lcg_m", "x_lcg", " = x_lcg lpp"),
        ("propeller_diameter_m", "dia_prop", ""), ("propeller_pitch_ratio", "pitchr", ""),
        ("rudder_area_m2", "area_rudder", ""),
        ("rudder_height_m", "lambda_rudder", " = sqrt(lambda_rudder area_rudder)"),
        ("windage_frontal_area_m2", "area_projected_trans", ""),
        ("windage_lateral_area_m2", "area_projected_lateral", ""),
        ("windage_superstructure_area_m2", "AOD", ""),
        ("windage_centroid_from_bow_m", "LCW", " = lpp / 2 - LCW"))},
    **{f"coefficients.{target}": (FILES[1], key, "") for key, target in _COEFFICIENTS.items()},
    "coefficients.J_z": (FILES[1], "IzzJzz_nd", f" = IzzJzz_nd - mass_nd {K_ZZ:g}^2"),
    "coefficients.f_alpha": (FILES[0], "lambda_rudder",
                             " = 6.13 lambda_rudder / (lambda_rudder + 2.25)"),
    "coefficients.x_R": (FILES[0], "x_location_rudder", " = x_location_rudder / lpp"),
    **{f"coefficients.{target}": (FILES[2], key, "") for key, (_, target, _) in _SWITCHES.items()
       if target is not None},
}


def _check_limits(spec: dict[str, Any], tables: dict[str, _Table]) -> None:
    """The ranges the ``mmg_berthing`` family's ship files are held to, each located at the
    entry that gives the value."""
    from trafficsim.ships.base import families, limit_problems

    problems = limit_problems(families()["mmg_berthing"], spec)
    if not problems:
        return
    key, message = problems[0]
    if key not in _SOURCES:  # (a value the folder does not give: one of the choices above)
        raise InputError(f"{key}: {message}", path=str(tables[FILES[0]].path.parent))
    name, entry, how = _SOURCES[key]
    raise tables[name].error(entry, f"{key.split('.', 1)[1]}{how}: {message}")
