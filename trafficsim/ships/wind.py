"""Wind loads on a ship's windage from Isherwood's (1972) regression, as a compiled per-ship kernel.

Isherwood, R. M. (1972), "Wind resistance of merchant ships", Trans. RINA 115, 327-338: for each
apparent-wind angle 0, 10, ..., 180 deg the coefficients are linear regressions on the windage
particulars,

    C_X = -(A0 + A1 2 A_L/L^2 + A2 2 A_F/B^2 + A3 L/B + A4 S/L + A5 C/L + A6 M)
    C_Y =   B0 + B1 2 A_L/L^2 + B2 2 A_F/B^2 + B3 L/B + B4 S/L + B5 C/L + B6 A_SS/A_L
    C_N =   C0 + C1 2 A_L/L^2 + C2 2 A_F/B^2 + C3 L/B + C4 S/L + C5 C/L

    X_A = 1/2 rho_a V_A^2 A_F C_X,  Y_A = 1/2 rho_a V_A^2 A_L C_Y,  N_A = 1/2 rho_a V_A^2 A_L L C_N

with L the length overall, B the beam, A_F / A_L the frontal / lateral projected windage areas,
A_SS the lateral area of the superstructure, S the perimeter of the lateral projection (without
the waterline and slender bodies), C the distance of the lateral-area centroid from the bow and M
the number of distinct mast groups. The table below is Isherwood's regression table as
transcribed in the Marine Systems Simulator toolbox of T. I. Fossen (``isherwood72.m``) and,
independently, in a public Python wind-coefficient module; the two agree number for number.
Between the 10 deg table angles the coefficients are interpolated linearly.

Signs. Isherwood's table is written for wind from one side; in Fossen's convention (angle
positive for wind from PORT) C_Y > 0 pushes the ship to starboard and C_N > 0 turns the bow to
starboard, i.e. away from the wind when the windage centroid is forward of midship
(C/L < ~0.5). Here the angle is that of :func:`trafficsim.ships.base.apparent_wind` (positive
= wind from STARBOARD; :func:`loads1` repeats its arithmetic for one ship inside the compiled
kernel), so the side force and moment take the sign ``-sign(angle)``:
Y(-angle) = -Y(angle), N(-angle) = -N(angle), X(-angle) = X(angle).

Zero wind, zero load. A ship under way in still air already feels a head "wind" of its own speed;
that still-air drag is part of the calm-water resistance the hull model is calibrated for (the
self-propulsion point), so what is returned is the INCREMENT over the still-air load:
``F(apparent wind) - F(own-motion wind)``, continuous in the wind speed and exactly zero (not
computed) when the true wind speed is zero.

Layout. The loads are a compiled scalar kernel :func:`loads1` for one ship, used inside the
``mmg`` kernel; its windage row ``w`` holds the per-ship columns :data:`WINDAGE_FIELDS` (the
Isherwood regressors and the dynamic-pressure areas). Because the regression is linear in the
table entries only the interpolation in angle and a 7-term dot product remain at run time.
:func:`wind_loads` and :func:`coefficients` are vectorised conveniences over many ships.

Windage particulars (in the ship file's ``particulars``, all optional; a ship without
``windage_lateral_area_m2`` and ``windage_frontal_area_m2`` feels no wind; a ship file giving
one of the two without the other is refused when it is read):

==================================  =====================================================
``length_overall_m``                L (default ``length_m``)
``windage_frontal_area_m2``         A_F
``windage_lateral_area_m2``         A_L
``windage_superstructure_area_m2``  A_SS (default 0)
``windage_perimeter_m``             S (default L, i.e. a flat deck line)
``windage_centroid_from_bow_m``     C (default L/2)
``windage_mast_groups``             M (default 0)
==================================  =====================================================
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from trafficsim.jit import kernel
from trafficsim.ships.base import PSI, RHO_AIR, Env, U, V, env_table, gather_ship

#: Table angles, degrees (Isherwood 1972, Table; 10 deg steps from head to stern wind).
ANGLES_DEG = np.arange(0.0, 181.0, 10.0)
_STEP_RAD = np.radians(10.0)

# Isherwood (1972) regression coefficients, rows = ANGLES_DEG.
# Longitudinal force: A0 A1 A2 A3 A4 A5 A6 (C_X carries an overall minus sign, see module doc).
_A = np.array([
    [2.152, -5.00, 0.243, -0.164, 0.000, 0.00, 0.000],
    [1.714, -3.33, 0.145, -0.121, 0.000, 0.00, 0.000],
    [1.818, -3.97, 0.211, -0.143, 0.000, 0.00, 0.033],
    [1.965, -4.81, 0.243, -0.154, 0.000, 0.00, 0.041],
    [2.333, -5.99, 0.247, -0.190, 0.000, 0.00, 0.042],
    [1.726, -6.54, 0.189, -0.173, 0.348, 0.00, 0.048],
    [0.913, -4.68, 0.000, -0.104, 0.482, 0.00, 0.052],
    [0.457, -2.88, 0.000, -0.068, 0.346, 0.00, 0.043],
    [0.341, -0.91, 0.000, -0.031, 0.000, 0.00, 0.032],
    [0.355, 0.00, 0.000, 0.000, -0.247, 0.00, 0.018],
    [0.601, 0.00, 0.000, 0.000, -0.372, 0.00, -0.020],
    [0.651, 1.29, 0.000, 0.000, -0.582, 0.00, -0.031],
    [0.564, 2.54, 0.000, 0.000, -0.748, 0.00, -0.024],
    [-0.142, 3.58, 0.000, 0.047, -0.700, 0.00, -0.028],
    [-0.677, 3.64, 0.000, 0.069, -0.529, 0.00, -0.032],
    [-0.723, 3.14, 0.000, 0.064, -0.475, 0.00, -0.032],
    [-2.148, 2.56, 0.000, 0.081, 0.000, 1.27, -0.027],
    [-2.707, 3.97, -0.175, 0.126, 0.000, 1.81, 0.000],
    [-2.529, 3.76, -0.174, 0.128, 0.000, 1.55, 0.000],
])
# Lateral force: B0 B1 B2 B3 B4 B5 B6.
_B = np.array([
    [0.000, 0.00, 0.000, 0.000, 0.000, 0.00, 0.00],
    [0.096, 0.22, 0.000, 0.000, 0.000, 0.00, 0.00],
    [0.176, 0.71, 0.000, 0.000, 0.000, 0.00, 0.00],
    [0.225, 1.38, 0.000, 0.023, 0.000, -0.29, 0.00],
    [0.329, 1.82, 0.000, 0.043, 0.000, -0.59, 0.00],
    [1.164, 1.26, 0.121, 0.000, -0.242, -0.95, 0.00],
    [1.163, 0.96, 0.101, 0.000, -0.177, -0.88, 0.00],
    [0.916, 0.53, 0.069, 0.000, 0.000, -0.65, 0.00],
    [0.844, 0.55, 0.082, 0.000, 0.000, -0.54, 0.00],
    [0.889, 0.00, 0.138, 0.000, 0.000, -0.66, 0.00],
    [0.799, 0.00, 0.155, 0.000, 0.000, -0.55, 0.00],
    [0.797, 0.00, 0.151, 0.000, 0.000, -0.55, 0.00],
    [0.996, 0.00, 0.184, 0.000, -0.212, -0.66, 0.34],
    [1.014, 0.00, 0.191, 0.000, -0.280, -0.69, 0.44],
    [0.784, 0.00, 0.166, 0.000, -0.209, -0.53, 0.38],
    [0.536, 0.00, 0.176, -0.029, -0.163, 0.00, 0.27],
    [0.251, 0.00, 0.106, -0.022, 0.000, 0.00, 0.00],
    [0.125, 0.00, 0.046, -0.012, 0.000, 0.00, 0.00],
    [0.000, 0.00, 0.000, 0.000, 0.000, 0.00, 0.00],
])
# Yaw moment: C0 C1 C2 C3 C4 C5.
_C = np.array([
    [0.0000, 0.000, 0.0000, 0.0000, 0.0000, 0.000],
    [0.0596, 0.061, 0.0000, 0.0000, 0.0000, -0.074],
    [0.1106, 0.204, 0.0000, 0.0000, 0.0000, -0.170],
    [0.2258, 0.245, 0.0000, 0.0000, 0.0000, -0.380],
    [0.2017, 0.457, 0.0000, 0.0067, 0.0000, -0.472],
    [0.1759, 0.573, 0.0000, 0.0118, 0.0000, -0.523],
    [0.1925, 0.480, 0.0000, 0.0115, 0.0000, -0.546],
    [0.2133, 0.315, 0.0000, 0.0081, 0.0000, -0.526],
    [0.1827, 0.254, 0.0000, 0.0053, 0.0000, -0.443],
    [0.2627, 0.000, 0.0000, 0.0000, 0.0000, -0.508],
    [0.2102, 0.000, -0.0195, 0.0000, 0.0335, -0.492],
    [0.1567, 0.000, -0.0258, 0.0000, 0.0497, -0.457],
    [0.0801, 0.000, -0.0311, 0.0000, 0.0740, -0.396],
    [-0.0189, 0.000, -0.0488, 0.0101, 0.1128, -0.420],
    [0.0256, 0.000, -0.0422, 0.0100, 0.0889, -0.463],
    [0.0552, 0.000, -0.0381, 0.0109, 0.0689, -0.476],
    [0.0881, 0.000, -0.0306, 0.0091, 0.0366, -0.415],
    [0.0851, 0.000, -0.0122, 0.0025, 0.0000, -0.220],
    [0.0000, 0.000, 0.0000, 0.0000, 0.0000, 0.000],
])


#: Per-ship windage columns, in the order of the windage row ``w`` of :func:`loads1`.
WINDAGE_FIELDS = ("wind_al", "wind_af", "wind_lb", "wind_sl", "wind_cl", "wind_masts",
                  "wind_ss", "wind_qx", "wind_qy", "wind_qn")
_AL, _AF, _LB, _SL, _CL, _MASTS, _SS, _QX, _QY, _QN = range(10)
_LAST = ANGLES_DEG.size - 1 - 1e-9  # keeps the upper interpolation row inside the table


@dataclass(frozen=True)
class WindParams:
    """Windage columns of ``n`` ships, ``(n,)`` each (see :data:`WINDAGE_FIELDS`).

    Attributes:
        wind_al, wind_af, wind_lb, wind_sl, wind_cl: Isherwood regressors 2 A_L/L^2,
            2 A_F/B^2, L/B, S/L, C/L.
        wind_masts: M, number of mast groups.
        wind_ss: A_SS / A_L.
        wind_qx, wind_qy, wind_qn: 1/2 rho_a A_F, 1/2 rho_a A_L (kg/m), 1/2 rho_a A_L L (kg);
            all zero for a ship without windage (no wind load).
    """

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


def _windage(p: Mapping[str, Any]) -> tuple[float, ...]:
    """Windage particulars of one ship with their documented defaults."""
    loa = float(p.get("length_overall_m", p["length_m"]))
    beam = float(p["beam_m"])
    a_f = float(p.get("windage_frontal_area_m2", 0.0))
    a_l = float(p.get("windage_lateral_area_m2", 0.0))
    a_ss = float(p.get("windage_superstructure_area_m2", 0.0))
    perim = float(p.get("windage_perimeter_m", loa))
    c_bow = float(p.get("windage_centroid_from_bow_m", 0.5 * loa))
    masts = float(p.get("windage_mast_groups", 0.0))
    return loa, beam, a_f, a_l, a_ss, perim, c_bow, masts


def build(ships: Sequence[Mapping[str, Any]]) -> WindParams:
    """Windage columns for ``ships`` (parsed ship-file dicts, windage in ``particulars``)."""
    cols = np.array([_windage(s["particulars"]) for s in ships], dtype=float).reshape(-1, 8).T
    loa, beam, a_f, a_l, a_ss, perim, c_bow, masts = cols
    has = (a_f > 0.0) & (a_l > 0.0)
    half = 0.5 * RHO_AIR
    return WindParams(
        wind_al=2.0 * a_l / loa**2, wind_af=2.0 * a_f / beam**2, wind_lb=loa / beam,
        wind_sl=perim / loa, wind_cl=c_bow / loa, wind_masts=masts,
        wind_ss=np.where(has, a_ss / np.where(has, a_l, 1.0), 0.0),
        wind_qx=np.where(has, half * a_f, 0.0), wind_qy=np.where(has, half * a_l, 0.0),
        wind_qn=np.where(has, half * a_l * loa, 0.0))


def rows(params: WindParams) -> np.ndarray:
    """Windage rows ``(n, 10)`` (the ``w`` argument of :func:`loads1` for each ship)."""
    return np.ascontiguousarray(np.stack([getattr(params, f.name) for f in fields(params)],
                                         axis=1))


@kernel
def _at(i: int, w: np.ndarray) -> tuple[float, float, float]:
    """Isherwood C_X, C_Y, C_N (wind from port) of the ship ``w`` at table row ``i``."""
    a, b, c = _A[i], _B[i], _C[i]
    cx = -(a[0] + a[1] * w[_AL] + a[2] * w[_AF] + a[3] * w[_LB] + a[4] * w[_SL] + a[5] * w[_CL]
           + a[6] * w[_MASTS])
    cy = (b[0] + b[1] * w[_AL] + b[2] * w[_AF] + b[3] * w[_LB] + b[4] * w[_SL] + b[5] * w[_CL]
          + b[6] * w[_SS])
    cn = c[0] + c[1] * w[_AL] + c[2] * w[_AF] + c[3] * w[_LB] + c[4] * w[_SL] + c[5] * w[_CL]
    return cx, cy, cn


@kernel
def coefficients1(w: np.ndarray, angle: float) -> tuple[float, float, float]:
    """Wind coefficients of ONE ship in this package's body axes.

    Args:
        w: ``float64[10]`` windage row (:data:`WINDAGE_FIELDS`).
        angle: apparent-wind angle, rad, 0 = head wind, positive = from starboard (any
            angle: wrapped to [-pi, pi) first, so 350 deg is 10 deg from port).

    Returns:
        ``C_X`` (+ ahead), ``C_Y`` (+ to starboard), ``C_N`` (+ bow to starboard); C_Y and C_N
        are odd in the angle, C_X even. Linear interpolation between the 10 deg table angles.
    """
    if abs(angle) > math.pi:
        angle = (angle + math.pi) % (2.0 * math.pi) - math.pi
    pos = min(abs(angle) * (1.0 / _STEP_RAD), _LAST)
    i = int(pos)
    f = pos - i
    x0, y0, n0 = _at(i, w)
    x1, y1, n1 = _at(i + 1, w)
    # the table is for wind from port; our positive angle is from starboard
    side = -1.0 if angle > 0.0 else (1.0 if angle < 0.0 else 0.0)
    return x0 + f * (x1 - x0), side * (y0 + f * (y1 - y0)), side * (n0 + f * (n1 - n0))


@kernel
def loads1(w: np.ndarray, x: np.ndarray, env: np.ndarray) -> tuple[float, float, float]:
    """Wind force and moment on ONE ship over its still-air load, body frame.

    Args:
        w: ``float64[10]`` windage row (:data:`WINDAGE_FIELDS`).
        x: ``float64[8]`` state in the ``base`` layout.
        env: ``float64[4]`` (current north, current east, wind speed, wind from) as in
            :func:`trafficsim.ships.base.env_table`.

    Returns:
        ``X_A`` (N, + ahead), ``Y_A`` (N, + to starboard), ``N_A`` (N m, + bow to starboard);
        exactly zero when the true wind speed is zero or the ship has no windage.
    """
    ws = env[2]
    if ws == 0.0 or w[_QY] == 0.0:
        return 0.0, 0.0, 0.0
    c, s = math.cos(x[PSI]), math.sin(x[PSI])
    ug = x[U] + env[0] * c + env[1] * s  # velocity over ground, body frame
    vg = x[V] - env[0] * s + env[1] * c
    wn = -ws * math.cos(env[3])  # true wind velocity (towards), earth frame
    we = -ws * math.sin(env[3])
    ura = ug - (wn * c + we * s)  # air velocity relative to the ship (base.apparent_wind)
    vra = vg - (-wn * s + we * c)
    q1 = ura * ura + vra * vra
    q0 = ug * ug + vg * vg  # still air: the air moves against the ship's own velocity
    x1, y1, n1 = coefficients1(w, math.atan2(vra, ura))
    x0, y0, n0 = coefficients1(w, math.atan2(vg, ug))
    return (w[_QX] * (x1 * q1 - x0 * q0), w[_QY] * (y1 * q1 - y0 * q0),
            w[_QN] * (n1 * q1 - n0 * q0))


@kernel
def _coefficients_all(W: np.ndarray, angles: np.ndarray) -> np.ndarray:
    out = np.empty((3, angles.shape[0]))
    for i in range(angles.shape[0]):
        out[0, i], out[1, i], out[2, i] = coefficients1(W[i], angles[i])
    return out


@kernel
def _loads_all(W: np.ndarray, X: np.ndarray, E: np.ndarray) -> np.ndarray:
    n = X.shape[1]
    out = np.empty((3, n))
    x = np.empty(8)
    env = np.empty(4)
    for i in range(n):
        gather_ship(X, E, i, x, env)
        out[0, i], out[1, i], out[2, i] = loads1(W[i], x, env)
    return out


def coefficients(params: WindParams, angle_rad: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`coefficients1` for ``n`` ships at ``angle_rad`` (ships and angles broadcast
    together, e.g. one ship at many angles) -> C_X, C_Y, C_N."""
    W = rows(params)
    angles = np.atleast_1d(np.asarray(angle_rad, dtype=float))
    m = np.broadcast_shapes((W.shape[0],), angles.shape)[0]
    out = _coefficients_all(np.ascontiguousarray(np.broadcast_to(W, (m, W.shape[1]))),
                            np.ascontiguousarray(np.broadcast_to(angles, (m,))))
    return out[0], out[1], out[2]


def wind_loads(params: WindParams, x: np.ndarray, env: Env
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`loads1` for ``n`` ships: state ``(N_STATE, n)`` -> X_A, Y_A (N), N_A (N m)."""
    n = x.shape[1]
    out = _loads_all(rows(params), np.ascontiguousarray(x, dtype=float), env_table(env, n))
    return out[0], out[1], out[2]
