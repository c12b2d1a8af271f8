"""Ship domains: the zone around own ship that other ships should keep out of, for many pairs.

Frame: own ship's body frame, origin at own ship's reference point, ``x`` forward, ``y`` to
starboard, metres; a relative bearing is measured clockwise from the bow (``atan2(y, x)``).

Every domain here is a union of *pieces*: an ellipse (a circle being a special case) restricted to
a sector of relative bearings around own ship. The sectors of one domain cover the full circle,
each spans either the whole circle or at most 180 degrees (a bearing exactly on the edge between
two sectors belongs to the first clockwise from the bow), and every piece's ellipse contains own
ship; so the domain is star-shaped about own ship and along each bearing its boundary is one
distance. That structure gives closed forms for the three questions asked of a domain:

- :func:`boundary_distance_m`: distance to the boundary along a bearing (a ray meets an ellipse);
- :func:`contains`: whether a point is inside (the point's sector, then the ellipse inequality);
- :func:`time_to_entry_s`: the first time a point moving with constant relative velocity is inside.
  Over time, the point is inside a piece's ellipse on one interval (roots of a quadratic) and
  inside the piece's sector on another (two half-plane tests, each linear in time, since a sector
  spans at most 180 degrees); the earliest time in the intersection of the two with
  ``[0, horizon]``, minimised over pieces, is the entry time. This is the "ongoing look-ahead,
  extrapolating at regular intervals from current status" that the decision-network paper calls
  for [seed 002, appendix F, "Simulation of a marine guidance and expert collision avoidance
  system", analysis of simulation results, point 3], here exact and cheap enough for every pair at
  every decision step.

Domains (``L`` = own length; registry names in quotes). Sources as collected in the project's
reference notes (shared/reference/colregs.md section 3):

- ``"coldwell"``: Coldwell 1983, J. Navig. 36. Head-on and crossing encounters: ellipse with
  semi-axes 5.0 L (along) x 2.5 L (athwart) whose centre lies 1.1 L forward and 0.75 L to
  starboard of own ship, so it reaches 6.1 L ahead, 3.9 L astern, 3.25 L to starboard and 1.75 L
  to port (the ellipse's bounding box; along the bow line itself the boundary is at
  1.1 L + 5 L sqrt(1 - 0.3^2) = 5.87 L). Overtaking encounters: ellipse with semi-axes
  6.0 L x 1.75 L centred on own ship. The caller says which applies (``overtaking``).
- ``"goodwin"``: Goodwin 1975, J. Navig. 28(3):328-344, open sea (North Sea). Three circular
  sectors by relative bearing: starboard 0-112.5 deg radius 0.85 NM, astern 112.5-247.5 deg
  radius 0.45 NM, port 247.5-360 deg radius 0.70 NM. The sectors are the paper's; the radii are
  as commonly cited in the literature, not re-read in the original (one public implementation uses
  0.85 / 0.40 / 0.75 NM). Independent of ship length and speed.
- ``"fujii"``: Fujii & Tanaka 1971, J. Navig. 24. Ellipse centred on own ship, commonly cited as
  8 L along x 3.2 L athwart for open and narrow waters. These are taken as FULL axes, i.e.
  semi-axes 4 L x 1.6 L.
- ``"kijima"``: Kijima & Furukawa 2003, in the quaternion form of Wang 2013, J. Navig.
  66:265-281. Speed-dependent radii from the advance and tactical-diameter coefficients
  (``V`` = own speed in knots)::

      k_AD = 10^(0.3591 log10 V + 0.0952),   k_DT = 10^(0.5441 log10 V - 0.0795)
      R_fore = (1 + 1.34 sqrt(k_AD^2 + (k_DT/2)^2)) L,   R_aft = (1 + 0.67 sqrt(...)) L
      R_stbd = (0.2 + k_DT) L,                            R_port = (0.2 + 0.75 k_DT) L

  with Wang's shape parameter k = 2: four quarter-ellipses centred on own ship, one per quadrant,
  semi-axes R_fore or R_aft along x and R_stbd or R_port along y. At V = 0 both coefficients are
  0 (R_fore = R_aft = L, R_stbd = R_port = 0.2 L).

Public functions take ``kind`` (a registry name; a typo raises :class:`InputError` with
``key="domain"`` and a suggestion) and per-pair ``(m,)`` arrays (scalars broadcast); own length
must be positive. The per-pair work is compiled (``@kernel``) scalar code that
:mod:`trafficsim.colregs.features` calls directly.
"""

from __future__ import annotations

import difflib
import math

import numpy as np
from numpy.typing import ArrayLike

from trafficsim.errors import InputError
from trafficsim.jit import kernel
from trafficsim.units import KN, NM

#: registry of domain names; a domain's code in the compiled kernels is its index here
DOMAINS: tuple[str, ...] = ("coldwell", "fujii", "goodwin", "kijima")
COLDWELL, FUJII, GOODWIN, KIJIMA = range(4)

#: Goodwin 1975 sectors (relative bearing, deg) and radii (NM, as commonly cited)
GOODWIN_SECTORS = ((0.0, 112.5, 0.85), (112.5, 247.5, 0.45), (247.5, 360.0, 0.70))
_GW_C1, _GW_S1 = math.cos(math.radians(112.5)), math.sin(math.radians(112.5))
_GW_C2, _GW_S2 = math.cos(math.radians(247.5)), math.sin(math.radians(247.5))
_GW_IR0, _GW_IR1, _GW_IR2 = (1.0 / (r * NM) for _, _, r in GOODWIN_SECTORS)
_GW_REACH = max(r for _, _, r in GOODWIN_SECTORS) * NM
#: Kijima k_AD = exp(c ln V + d ln 10) (one log per ship instead of two powers)
_LN10 = math.log(10.0)
_INV_KN = 1.0 / KN


def domain_code(kind: str) -> int:
    """Kernel code of domain ``kind``; an unknown name raises :class:`InputError`."""
    if isinstance(kind, str) and kind in DOMAINS:
        return DOMAINS.index(kind)
    close = difflib.get_close_matches(str(kind).lower(), DOMAINS, n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    raise InputError(f"unknown ship domain '{kind}'{hint}; known domains: {', '.join(DOMAINS)}",
                     key="domain")


# --------------------------------------------------------------------------------------------
# Compiled scalar pieces (one own ship, one other ship)
# --------------------------------------------------------------------------------------------

# The compiled helpers pass only scalars and tuples (no arrays), so calling them per pair costs no
# reference counting. ``prm`` is the per-own-ship 4-tuple made by ship_params.

@kernel
def ship_params(kind: int, length_m: float, speed_mps: float,
                overtaking: bool) -> tuple[float, float, float, float]:
    """The numbers that size domain ``kind`` for one own ship.

    Returns ``(cx, cy, 1/a, 1/b)`` (metres, 1/metres) for the one-ellipse domains (Coldwell,
    Fujii); reciprocal radii ``(1/R_fore, 1/R_aft, 1/R_stbd, 1/R_port)`` for Kijima; zeros for
    Goodwin (fixed radii).
    """
    iL = 1.0 / length_m
    if kind == COLDWELL:
        if overtaking:
            return 0.0, 0.0, iL / 6.0, iL / 1.75
        return 1.1 * length_m, 0.75 * length_m, 0.2 * iL, 0.4 * iL
    if kind == FUJII:
        return 0.0, 0.0, 0.25 * iL, iL / 1.6
    if kind == GOODWIN:
        return 0.0, 0.0, 0.0, 0.0
    # kijima; 10^(c log10 V + d) = exp(c ln V + d ln 10), which is 0 (not NaN) at V = 0
    v_kn = abs(speed_mps) * _INV_KN
    if v_kn > 0.0:
        ln_v = math.log(v_kn)
        k_ad = math.exp(0.3591 * ln_v + 0.0952 * _LN10)
        k_dt = math.exp(0.5441 * ln_v - 0.0795 * _LN10)
    else:
        k_ad = k_dt = 0.0
    s = math.sqrt(k_ad * k_ad + 0.25 * k_dt * k_dt)
    return (iL / (1.0 + 1.34 * s), iL / (1.0 + 0.67 * s), iL / (0.2 + k_dt),
            iL / (0.2 + 0.75 * k_dt))


@kernel
def reach_m(kind: int, prm: tuple[float, float, float, float]) -> float:
    """Radius of a circle about own ship that holds the whole domain, metres."""
    if kind == GOODWIN:
        return _GW_REACH
    if kind == KIJIMA:
        # k_AD, k_DT >= 0 make R_fore >= R_aft and R_stbd >= R_port
        return 1.0 / min(prm[0], prm[2])
    # an ellipse lies within |centre| + its larger semi-axis
    return math.sqrt(prm[0] * prm[0] + prm[1] * prm[1]) + 1.0 / min(prm[2], prm[3])


#: reach of the Coldwell (head-on and crossing) and Fujii domains per metre of ship length
_UNIT_REACH = (math.sqrt(1.1**2 + 0.75**2) + 1.0 / 0.2, 1.0 / 0.25)
#: relative margin of :func:`reach_bound_m` over :func:`reach_m` (rounding of either side)
_BOUND_MARGIN = 1e-6


@kernel
def reach_bound_m(kind: int, length_m: float) -> float:
    """An upper bound of :func:`reach_m` for a ship of length ``length_m`` at any speed (not
    overtaking; Goodwin's fixed reach; infinite for Kijima, whose domain grows with speed)
    with a relative margin far above rounding: a ship beyond it is outside the domain without
    sizing it."""
    if kind == GOODWIN:
        return _GW_REACH * (1.0 + _BOUND_MARGIN)
    if kind == KIJIMA:
        return math.inf
    return _UNIT_REACH[kind] * length_m * (1.0 + _BOUND_MARGIN)


@kernel
def n_pieces(kind: int) -> int:
    """Number of pieces of domain ``kind`` as :func:`piece` lists them (Kijima: see
    :func:`_kijima_entry`)."""
    return 3 if kind == GOODWIN else 1


@kernel
def piece(kind: int, k: int, prm: tuple[float, float, float, float]
          ) -> tuple[float, float, float, float, float, float, float, float, bool]:
    """Piece ``k`` (clockwise from the bow) of a Goodwin, Coldwell or Fujii domain.

    Returns ``(cx, cy, 1/a, 1/b, e1x, e1y, e2x, e2y, whole)``: ellipse centre and reciprocal
    semi-axes along x and y; unit vectors of the sector's first and last edge (exact along the
    body axes); ``whole`` when the sector is the full circle (edges unused).
    """
    if kind == GOODWIN:
        if k == 0:
            return 0.0, 0.0, _GW_IR0, _GW_IR0, 1.0, 0.0, _GW_C1, _GW_S1, False
        if k == 1:
            return 0.0, 0.0, _GW_IR1, _GW_IR1, _GW_C1, _GW_S1, _GW_C2, _GW_S2, False
        return 0.0, 0.0, _GW_IR2, _GW_IR2, _GW_C2, _GW_S2, 1.0, 0.0, False
    return prm[0], prm[1], prm[2], prm[3], 1.0, 0.0, 1.0, 0.0, True


@kernel
def covering(kind: int, prm: tuple[float, float, float, float], x: float,
             y: float) -> tuple[float, float, float, float]:
    """``(cx, cy, 1/a, 1/b)`` of the piece whose sector holds direction ``(x, y)``.

    Goodwin's sectors are tested with ``cross(e1, p) >= 0`` and ``cross(p, e2) >= 0`` (exact for
    sectors of at most 180 degrees, no angle needed); a direction exactly on an edge, and own
    ship's own position, belong to the first such sector clockwise from the bow. Kijima's
    quadrants follow from the signs of ``x`` and ``y``: on an axis the semi-axis that is not
    chosen is multiplied by zero, so the choice there does not matter.
    """
    if kind == KIJIMA:
        return 0.0, 0.0, prm[0] if x >= 0.0 else prm[1], prm[2] if y >= 0.0 else prm[3]
    if kind == GOODWIN:
        if y >= 0.0 and x * _GW_S1 - y * _GW_C1 >= 0.0:
            return 0.0, 0.0, _GW_IR0, _GW_IR0
        if _GW_C1 * y - _GW_S1 * x >= 0.0 and x * _GW_S2 - y * _GW_C2 >= 0.0:
            return 0.0, 0.0, _GW_IR1, _GW_IR1
        return 0.0, 0.0, _GW_IR2, _GW_IR2
    return prm


@kernel
def ray_distance(kind: int, prm: tuple[float, float, float, float], ux: float,
                 uy: float) -> float:
    """Distance from own ship to the boundary along the unit direction ``(ux, uy)`` (for any
    other direction vector, in units of its length).

    Positive root of ``((r ux - cx)/a)^2 + ((r uy - cy)/b)^2 = 1`` for the piece whose sector
    holds the direction; own ship is inside the ellipse (constant term <= 0), so one root is >= 0.
    """
    cx, cy, ia, ib = covering(kind, prm, ux, uy)
    ia2, ib2 = ia * ia, ib * ib
    A = ux * ux * ia2 + uy * uy * ib2
    B = -2.0 * (ux * cx * ia2 + uy * cy * ib2)
    C = cx * cx * ia2 + cy * cy * ib2 - 1.0
    sq = math.sqrt(max(B * B - 4.0 * A * C, 0.0))
    # each branch is the form of the same root that does not cancel
    if B <= 0.0:
        return (sq - B) / (2.0 * A)
    return -2.0 * C / (B + sq)


@kernel
def inside(kind: int, prm: tuple[float, float, float, float], x: float, y: float) -> bool:
    """Whether body-frame point ``(x, y)`` is inside (the boundary counts as inside)."""
    cx, cy, ia, ib = covering(kind, prm, x, y)
    dx, dy = (x - cx) * ia, (y - cy) * ib
    return dx * dx + dy * dy <= 1.0


@kernel
def _ellipse_times(x: float, y: float, vx: float, vy: float, cx: float, cy: float, ia: float,
                   ib: float) -> tuple[float, float]:
    """Times ``(t1, t2)`` between which ``(x + vx t, y + vy t)`` is inside the ellipse.

    ``A t^2 + B t + C <= 0`` in ellipse-scaled coordinates; ``(inf, -inf)`` (empty) if never,
    ``(-inf, inf)`` without relative motion inside.
    """
    dx, dy = (x - cx) * ia, (y - cy) * ib
    ux, uy = vx * ia, vy * ib
    A = ux * ux + uy * uy
    B = 2.0 * (dx * ux + dy * uy)
    C = dx * dx + dy * dy - 1.0
    if A > 0.0:
        D = B * B - 4.0 * A * C
        if D < 0.0:
            return math.inf, -math.inf
        # the two roots without cancellation
        q = -0.5 * (B + math.copysign(math.sqrt(D), B))
        t1 = q / A
        t2 = C / q if q != 0.0 else t1
        return min(t1, t2), max(t1, t2)
    if C <= 0.0:
        return -math.inf, math.inf
    return math.inf, -math.inf


@kernel
def _kijima_entry(prm: tuple[float, float, float, float], x: float, y: float, vx: float,
                  vy: float, horizon_s: float) -> float:
    """Entry time into the four quarter-ellipses, by time segments of constant quadrant.

    The track changes quadrant only where ``x`` or ``y`` changes sign (at most twice); within a
    segment one quarter-ellipse applies, so at most three quadratics are solved, in time order.
    """
    b1 = -x / vx if vx != 0.0 else math.inf
    b2 = -y / vy if vy != 0.0 else math.inf
    e1 = min(max(min(b1, b2), 0.0), horizon_s)
    e2 = min(max(max(b1, b2), 0.0), horizon_s)
    for seg in range(3):
        if seg == 0:
            a, b = 0.0, e1
        elif seg == 1:
            a, b = e1, e2
        else:
            a, b = e2, horizon_s
        if b < a:
            continue
        # signs inside the segment pick the quadrant (on an axis either choice is the same)
        tm = a + 0.5 * min(b - a, 1.0)
        xm, ym = x + vx * tm, y + vy * tm
        t1, t2 = _ellipse_times(x, y, vx, vy, 0.0, 0.0, prm[0] if xm >= 0.0 else prm[1],
                                prm[2] if ym >= 0.0 else prm[3])
        lo, hi = max(t1, a), min(t2, b)
        if lo <= hi:
            return lo
    return math.inf


@kernel
def entry_time(kind: int, prm: tuple[float, float, float, float], x: float, y: float,
               vx: float, vy: float, horizon_s: float) -> float:
    """Earliest ``t`` in ``[0, horizon]`` with ``(x + vx t, y + vy t)`` in a piece, else inf.

    Per piece, the ellipse gives ``A t^2 + B t + C <= 0``: the interval between the roots (all
    time or never without relative motion); each edge of a sector narrower than the circle gives a
    half-plane ``g0 + g1 t >= 0``, i.e. a half-line of times. Kijima's quadrants take a shortcut
    (:func:`_kijima_entry`). A start inside gives 0 up to rounding; callers pin that case with
    their inside test.
    """
    if not horizon_s >= 0.0:  # a negative (or NaN) look-ahead sees nothing ahead
        return math.inf
    # cheap rejection, the common case: the track misses the circle that holds the domain
    reach = reach_m(kind, prm)
    v2 = vx * vx + vy * vy
    t_near = min(max(-(x * vx + y * vy) / v2, 0.0), horizon_s) if v2 > 0.0 else 0.0
    nx, ny = x + vx * t_near, y + vy * t_near
    if nx * nx + ny * ny > reach * reach:
        return math.inf
    if kind == KIJIMA:
        return _kijima_entry(prm, x, y, vx, vy, horizon_s)
    best = math.inf
    last = n_pieces(kind) - 1
    for k in range(last + 1):
        cx, cy, ia, ib, e1x, e1y, e2x, e2y, whole = piece(kind, k, prm)
        lo, hi = _ellipse_times(x, y, vx, vy, cx, cy, ia, ib)
        lo, hi = max(lo, 0.0), min(hi, horizon_s)
        if not whole:
            # inside the sector: cross(e1, p) >= 0 and cross(p, e2) >= 0
            for e in range(2):
                if e == 0:
                    g0, g1 = e1x * y - e1y * x, e1x * vy - e1y * vx
                else:
                    g0, g1 = x * e2y - y * e2x, vx * e2y - vy * e2x
                # an edge belongs to the first sector clockwise from the bow (as in
                # covering): a point that stays on it is not in the piece after it
                shared = (e == 0 and k > 0) or (e == 1 and k == last and k > 0)
                if g1 > 0.0:
                    lo = max(lo, -g0 / g1)
                elif g1 < 0.0:
                    hi = min(hi, -g0 / g1)
                elif g0 < 0.0 or (shared and g0 == 0.0):
                    lo = math.inf
        if lo <= hi and lo < best:
            best = lo
    return best


# --------------------------------------------------------------------------------------------
# Compiled loops over pairs
# --------------------------------------------------------------------------------------------

@kernel
def _boundary_loop(kind: int, bearing: np.ndarray, length: np.ndarray, speed: np.ndarray,
                   overtaking: np.ndarray, out: np.ndarray) -> None:
    for i in range(out.size):
        prm = ship_params(kind, length[i], speed[i], overtaking[i])
        out[i] = ray_distance(kind, prm, math.cos(bearing[i]), math.sin(bearing[i]))


@kernel
def _contains_loop(kind: int, x: np.ndarray, y: np.ndarray, length: np.ndarray,
                   speed: np.ndarray, overtaking: np.ndarray, out: np.ndarray) -> None:
    for i in range(out.size):
        prm = ship_params(kind, length[i], speed[i], overtaking[i])
        out[i] = inside(kind, prm, x[i], y[i])


@kernel
def _entry_loop(kind: int, x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                length: np.ndarray, speed: np.ndarray, overtaking: np.ndarray,
                horizon: np.ndarray, out: np.ndarray) -> None:
    for i in range(out.size):
        prm = ship_params(kind, length[i], speed[i], overtaking[i])
        if inside(kind, prm, x[i], y[i]):
            out[i] = 0.0
        else:
            out[i] = entry_time(kind, prm, x[i], y[i], vx[i], vy[i], horizon[i])


# --------------------------------------------------------------------------------------------
# Public vectorised API
# --------------------------------------------------------------------------------------------

def _columns(*arrays: ArrayLike | None) -> list[np.ndarray]:
    """Broadcast to one 1-D shape; contiguous float64 (None -> False as bool, for overtaking)."""
    shape = np.broadcast_shapes(*(np.shape(a) for a in arrays if a is not None))
    if len(shape) > 1:
        raise InputError(f"expected (m,) arrays, got shape {shape}", key="pairs")
    shape = shape or (1,)
    out = []
    for a in arrays:
        if a is None:
            out.append(np.zeros(shape, dtype=np.bool_))
        else:
            arr = np.asarray(a)
            dtype = np.bool_ if arr.dtype == np.bool_ else np.float64
            out.append(np.ascontiguousarray(np.broadcast_to(arr.astype(dtype, copy=False), shape)))
    return out


def _shaped(out: np.ndarray, *inputs: ArrayLike | None) -> np.ndarray:
    """``out`` as a scalar-shaped array when every input was a scalar."""
    if all(np.ndim(a) == 0 for a in inputs if a is not None):
        return out.reshape(())
    return out


def boundary_distance_m(kind: str, bearing_rad: ArrayLike, length_m: ArrayLike,
                        speed_mps: ArrayLike, overtaking: ArrayLike | None = None) -> np.ndarray:
    """Distance from own ship to the boundary of its domain along a relative bearing.

    Args:
        kind: domain name (``coldwell``, ``fujii``, ``goodwin``, ``kijima``).
        bearing_rad: relative bearing, radians clockwise from own bow, ``(m,)`` (any range).
        length_m: own length, metres (> 0), ``(m,)``.
        speed_mps: own speed, m/s, ``(m,)`` (used by ``kijima``).
        overtaking: ``(m,)`` bool, overtaking encounter (used by ``coldwell``); None = all False.

    Returns:
        ``(m,)`` metres.
    """
    code = domain_code(kind)
    b, L, v, ov = _columns(bearing_rad, length_m, speed_mps, overtaking)
    out = np.empty(b.shape)
    _boundary_loop(code, b, L, v, ov.astype(np.bool_, copy=False), out)
    return _shaped(out, bearing_rad, length_m, speed_mps, overtaking)


def contains(kind: str, x_m: ArrayLike, y_m: ArrayLike, length_m: ArrayLike,
             speed_mps: ArrayLike, overtaking: ArrayLike | None = None) -> np.ndarray:
    """Whether the other ship's reference point is inside own ship's domain.

    Args:
        kind: domain name.
        x_m, y_m: other ship relative to own ship in own body frame (forward, starboard), metres,
            ``(m,)`` each.
        length_m, speed_mps, overtaking: as for :func:`boundary_distance_m`.

    Returns:
        ``(m,)`` bool; the boundary counts as inside.
    """
    code = domain_code(kind)
    x, y, L, v, ov = _columns(x_m, y_m, length_m, speed_mps, overtaking)
    out = np.empty(x.shape, dtype=np.bool_)
    _contains_loop(code, x, y, L, v, ov.astype(np.bool_, copy=False), out)
    return _shaped(out, x_m, y_m, length_m, speed_mps, overtaking)


def time_to_entry_s(kind: str, x_m: ArrayLike, y_m: ArrayLike, vx_mps: ArrayLike,
                    vy_mps: ArrayLike, length_m: ArrayLike, speed_mps: ArrayLike,
                    overtaking: ArrayLike | None, horizon_s: ArrayLike) -> np.ndarray:
    """First time the other ship is inside own domain if the present relative motion continues.

    The domain is fixed to own heading and the relative velocity is constant (straight tracks).

    Args:
        kind: domain name.
        x_m, y_m: other ship relative to own ship, body frame (forward, starboard), metres,
            ``(m,)``.
        vx_mps, vy_mps: other ship's velocity relative to own ship, body frame, m/s, ``(m,)``.
        length_m, speed_mps, overtaking: as for :func:`boundary_distance_m`.
        horizon_s: look-ahead, seconds, scalar or ``(m,)``.

    Returns:
        ``(m,)`` seconds: 0 if already inside, the entry time if it is at most ``horizon_s``,
        otherwise ``inf``.
    """
    code = domain_code(kind)
    x, y, vx, vy, L, v, ov, h = _columns(x_m, y_m, vx_mps, vy_mps, length_m, speed_mps,
                                         overtaking, horizon_s)
    out = np.empty(x.shape)
    _entry_loop(code, x, y, vx, vy, L, v, ov.astype(np.bool_, copy=False), h, out)
    return _shaped(out, x_m, y_m, vx_mps, vy_mps, length_m, speed_mps, overtaking, horizon_s)
