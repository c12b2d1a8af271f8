"""Encounter geometry shared by metrics, instruments and the decision network: vectorised over
pairs, and scalar kernels for compiled loops."""

from __future__ import annotations

import math

import numpy as np
import shapely

from trafficsim.jit import inline_kernel, kernel

#: relative margin about a threshold outside which the squared norm decides a comparison of
#: ``hypot`` (whose error is below 1e-15) on its own
NORM_MARGIN = 1e-9


#: limits below this have squares near the subnormal range, where the squares do not decide
_SQUARE_SAFE = 1e-140


@kernel
def norm_side(a: float, b: float, limit: float, scale: float) -> int:
    """+1 if ``hypot(a, b) / scale`` is surely above ``limit`` (>= 0), -1 if surely below, 0
    within :data:`NORM_MARGIN` of it (or NaN, or a positive limit below 1e-140, whose square is
    near the subnormal range): the caller then evaluates the comparison itself (libm's
    ``hypot`` costs about 40 ns, the squares 5)."""
    s2 = a * a + b * b
    hi = limit * scale * (1.0 + NORM_MARGIN)
    if 0.0 < hi <= _SQUARE_SAFE:  # squares of this size lose precision (subnormal): undecided
        return 0
    if s2 > hi * hi:
        return 1
    lo = limit * scale * (1.0 - NORM_MARGIN)
    if s2 < lo * lo:
        return -1
    return 0


@kernel
def hypot_below(a: float, b: float, limit: float) -> bool:
    """``math.hypot(a, b) < limit``, as that expression evaluates, by the squares
    (:func:`norm_side`) wherever they decide it. Never true for a limit that is not positive
    (or NaN)."""
    if not limit > 0.0:
        return False
    side = norm_side(a, b, limit, 1.0)
    return side < 0 if side != 0 else math.hypot(a, b) < limit


#: turns up to this (rad) take their cosine and sine from series (:func:`turned`)
SERIES_TURN_RAD = 0.0625


@inline_kernel
def turned_by_series(c: float, s: float, d: float) -> tuple[float, float]:
    """:func:`turned` for ``|d| <= SERIES_TURN_RAD``: ``cos d`` and ``sin d`` from their Taylor
    series to ``d^8`` and ``d^9`` (truncation below 3e-19, under the rounding of a double).
    Branch-free, so that a loop calling it can be vectorised."""
    d2 = d * d
    cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0 - d2 * (1.0 / 720.0 - d2 * (1.0 / 40320.0))))
    sd = d * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0 - d2 * (1.0 / 5040.0
                                                              - d2 * (1.0 / 362880.0)))))
    return c * cd - s * sd, s * cd + c * sd


@inline_kernel
def turned(c: float, s: float, d: float) -> tuple[float, float]:
    """Cosine and sine of an angle ``d`` (rad) beyond one whose cosine and sine are ``c``,
    ``s``, by the angle-addition formulas. For ``|d| <= SERIES_TURN_RAD`` (a heading's change
    within a time step) ``cos d`` and ``sin d`` come from their series
    (:func:`turned_by_series`), several times cheaper than libm's ``cos`` and ``sin``; larger
    turns call them."""
    if abs(d) <= SERIES_TURN_RAD:
        return turned_by_series(c, s, d)
    cd, sd = math.cos(d), math.sin(d)
    return c * cd - s * sd, s * cd + c * sd


def _split_half_pi() -> tuple[float, float, float]:
    """pi/2 as three doubles: the leading 33 bits, the next 20 (so that their products with a
    whole number below 2^20 are exact) and the rest (pi - ``math.pi``, halved)."""
    bits = np.float64(math.pi / 2.0).view(np.uint64) & ~np.uint64((1 << 20) - 1)
    hi = float(bits.view(np.float64))
    return hi, math.pi / 2.0 - hi, 6.123233995736766e-17


_HALF_PI_HI, _HALF_PI_MID, _HALF_PI_LO = _split_half_pi()
#: angles up to this size (rad) are reduced exactly enough for :func:`cos_sin`
COS_SIN_MAX_RAD = 1.0e6


@inline_kernel
def cos_sin(angle: float) -> tuple[float, float]:
    """Cosine and sine of ``angle`` (rad, ``|angle| <= COS_SIN_MAX_RAD``) within one unit in
    the last place of libm's, without a call: a loop that calls it can be vectorised (a libm
    call keeps it scalar). The angle is reduced by the nearest multiple ``k`` of pi/2 (pi/2 in
    three parts, the first two products exact: Cody and Waite, Software Manual for the
    Elementary Functions, 1980), the remainder ``|r| <= pi/4`` goes through the Taylor series
    to ``r^17`` and ``r^18`` (truncation below 1e-19), and ``k mod 4`` picks the quadrant.
    All arithmetic, selects included, is IEEE 754 double, so a vectorised loop gives the same
    bits as a scalar one."""
    k = np.rint(angle * (2.0 / math.pi))
    r = ((angle - k * _HALF_PI_HI) - k * _HALF_PI_MID) - k * _HALF_PI_LO
    r2 = r * r
    sr = r + r * r2 * (-1.0 / 6.0 + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0 + r2 * (
        1.0 / 362880.0 + r2 * (-1.0 / 39916800.0 + r2 * (1.0 / 6227020800.0 + r2 * (
            -1.0 / 1307674368000.0 + r2 * (1.0 / 355687428096000.0))))))))
    cr = 1.0 + r2 * (-0.5 + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40320.0 + r2 * (
        -1.0 / 3628800.0 + r2 * (1.0 / 479001600.0 + r2 * (-1.0 / 87178291200.0 + r2 * (
            1.0 / 20922789888000.0 + r2 * (-1.0 / 6402373705728000.0)))))))))
    quadrant = k - 4.0 * math.floor(0.25 * k)  # 0, 1, 2 or 3 (NaN for NaN): no integer casts
    odd = quadrant == 1.0 or quadrant == 3.0
    c, s = (sr, cr) if odd else (cr, sr)
    return (-c if quadrant == 1.0 or quadrant == 2.0 else c), (-s if quadrant >= 2.0 else s)


#: arctangent reduction: breakpoints tan(j pi / 12) and their angles, and the thresholds
#: tan((2 j - 1) pi / 24) between them (:func:`atan`)
_ATAN_POINTS = tuple(math.tan(j * math.pi / 12.0) for j in range(4))
_ATAN_ANGLES = tuple(j * math.pi / 12.0 for j in range(4))
_ATAN_SPLITS = tuple(math.tan((2 * j - 1) * math.pi / 24.0) for j in range(1, 4))


@inline_kernel
def atan(x: float) -> float:
    """Arctangent of ``x`` within two units in the last place of libm's, without a call (a
    loop that calls it can be vectorised). ``|x| > 1`` goes through ``pi/2 - atan(1/|x|)``;
    ``t`` in ``[0, 1]`` through ``atan t = j pi/12 + atan u``, ``u = (t - c_j) / (1 + t c_j)``
    with ``c_j = tan(j pi/12)`` the nearest breakpoint, so ``|u| <= tan(pi/24) = 0.132``,
    and ``atan u`` is its Taylor series to ``u^21`` (truncation below 1e-21). Selects, no
    branches. (:func:`atan2` takes one division where this takes two, but branches and is
    within 1e-15 rad rather than two units in the last place: it serves the scalar loops.)"""
    a = abs(x)
    big = a > 1.0
    t = 1.0 / a if big else a
    j1, j2, j3 = t > _ATAN_SPLITS[0], t > _ATAN_SPLITS[1], t > _ATAN_SPLITS[2]
    c = _ATAN_POINTS[3] if j3 else (_ATAN_POINTS[2] if j2 else (_ATAN_POINTS[1] if j1 else 0.0))
    base = _ATAN_ANGLES[3] if j3 else (_ATAN_ANGLES[2] if j2 else (_ATAN_ANGLES[1] if j1 else 0.0))
    u = (t - c) / (1.0 + t * c)
    u2 = u * u
    series = u + u * u2 * (-1.0 / 3.0 + u2 * (1.0 / 5.0 + u2 * (-1.0 / 7.0 + u2 * (
        1.0 / 9.0 + u2 * (-1.0 / 11.0 + u2 * (1.0 / 13.0 + u2 * (-1.0 / 15.0 + u2 * (
            1.0 / 17.0 + u2 * (-1.0 / 19.0 + u2 * (1.0 / 21.0))))))))))
    angle = base + series
    angle = math.pi / 2.0 - angle if big else angle
    return -angle if x < 0.0 else angle


#: atan(w) = w + w s P(s) with s = w^2 for |w| <= tan(pi/8): coefficients of P (ascending) from
#: a least-squares Chebyshev fit of degree 9 made for this function; within 5e-16 rad of atan
_ATAN_P = (-0.3333333333333615, 0.20000000000716178, -0.14285714342138997, 0.1111111301933719,
           -0.09090936282868968, 0.07692291193467717, -0.06660746235832808,
           0.057962791232318185, -0.04660571794469063, 0.024962770517444693)
_A0, _A1, _A2, _A3, _A4, _A5, _A6, _A7, _A8, _A9 = _ATAN_P
_TAN_PI_8 = math.tan(math.pi / 8.0)
_PI_4, _PI_2 = math.pi / 4.0, math.pi / 2.0


@kernel
def atan2(y: float, x: float) -> float:
    """``atan2(y, x)`` in [-pi, pi] to within about 1e-15 rad, several times faster than libm's.

    The three angles per pair dominated the decision features' pair loop with the library
    function (it also serves the radar's bearings and the AIS course). Reduction: the
    octant by symmetry, then ``atan(z) = pi/4 + atan((z - 1)/(z + 1))`` above tan(pi/8), so the
    polynomial :data:`_ATAN_P` only sees ``|w| <= tan(pi/8)``. Written with selects rather than
    branches: the octant of random geometry is unpredictable, and mispredicted branches cost more
    than the arithmetic. ``(0, 0)`` gives 0, the sign of the result is the sign bit of ``y`` (as
    ``math.copysign``), NaN gives NaN.
    """
    if math.isnan(x) or math.isnan(y):
        return math.nan
    ax, ay = abs(x), abs(y)
    mx, mn = max(ax, ay), min(ax, ay)
    if mx == 0.0:
        return 0.0
    far = 1.0 if mn > _TAN_PI_8 * mx else 0.0
    w = (mn - far * mx) / (mx + far * mn)
    s = w * w
    # Estrin's scheme: a shorter chain of dependent operations than Horner's
    s2 = s * s
    s4 = s2 * s2
    p = ((_A0 + _A1 * s) + s2 * (_A2 + _A3 * s)
         + s4 * ((_A4 + _A5 * s) + s2 * (_A6 + _A7 * s)) + s4 * s4 * (_A8 + _A9 * s))
    r = far * _PI_4 + (w + w * s * p)
    r = _PI_2 - r if ay > ax else r
    r = math.pi - r if x < 0.0 else r
    return math.copysign(r, y)


def cpa(rel_north_m: np.ndarray, rel_east_m: np.ndarray, rel_vn_mps: np.ndarray,
        rel_ve_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance and time to the closest point of approach for straight-line motion.

    Args: relative position and velocity of the other ship, ``(P,)`` each (metres, m/s).
    Returns: ``dcpa_m`` (>= 0) and ``tcpa_s`` (negative when the closest point is past).
    """
    v2 = rel_vn_mps**2 + rel_ve_mps**2
    safe = np.where(v2 > 1e-12, v2, 1.0)
    tcpa = np.where(v2 > 1e-12, -(rel_north_m * rel_vn_mps + rel_east_m * rel_ve_mps) / safe, 0.0)
    dn = rel_north_m + rel_vn_mps * tcpa
    de = rel_east_m + rel_ve_mps * tcpa
    return np.hypot(dn, de), tcpa


#: hull outline in units of (length, beam): stern corners, shoulders, bow point
_HULL = np.array([[-0.5, -0.5], [0.3, -0.5], [0.5, 0.0], [0.3, 0.5], [-0.5, 0.5], [-0.5, -0.5]])


def hull_outlines(north_m: np.ndarray, east_m: np.ndarray, heading_rad: np.ndarray,
                  length_m: np.ndarray, beam_m: np.ndarray) -> np.ndarray:
    """Hull outlines (pointed-bow pentagons) in north/east metres, shape ``(k, 6, 2)`` (closed)."""
    bx = _HULL[None, :, 0] * length_m[:, None]  # body x forward
    by = _HULL[None, :, 1] * beam_m[:, None]  # body y starboard
    c, s = np.cos(heading_rad)[:, None], np.sin(heading_rad)[:, None]
    return np.stack([north_m[:, None] + bx * c - by * s, east_m[:, None] + bx * s + by * c], axis=2)


def hulls_overlap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether hull outlines ``a[k]`` and ``b[k]`` (each ``(k, 6, 2)``) intersect, ``(k,)`` bool."""
    if a.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    return shapely.intersects(shapely.polygons(a), shapely.polygons(b))
