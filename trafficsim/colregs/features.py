"""Encounter features for every directed (own ship, other ship) pair, from estimated states.

The decision network tests these features, by name, in a rules file, so each name carries its unit
and the values are in that unit (nautical miles, degrees, minutes, knots). Inputs are SI; a pair is
``(own, other)``: the caller gathers own-ship values by observer index, so one call covers every
pair of every encounter (one compiled loop, no Python loop over pairs). Angles are in degrees in
(-180, 180], positive = starboard / clockwise.

Own course over ground is the direction of own estimated velocity, or own heading below 0.1 m/s
(where the velocity direction is noise). The other ship's course over ground is the direction of its
estimated velocity; below 0.1 m/s it is taken equal to own course, so a stopped target is treated as
lying parallel to own ship (it is approached like a vessel being overtaken, and is never head-on or
crossing on aspect alone).

An unknown state (NaN in any position, velocity or own heading of the pair, e.g. no track of the
other ship) makes every feature of the pair NaN except ``visibility_nm``, so that every
comparison a rules file makes on them is false.

Vocabulary, in the order of :data:`NAMES` (p = other minus own position, v = other minus own
velocity; CPA formulas from the project's reference notes, shared/reference/colregs.md section 4):

``range_nm``
    [0, inf) NM. Distance between the reference points, ``|p|``.
``bearing_deg``
    (-180, 180] deg. Relative bearing of the other ship from own bow (own heading), the angle
    beta of colregs.md folded to (-180, 180].
``bearing_abs_deg``
    [0, 180] deg. ``|bearing_deg|`` (sector tests: ``bearing_abs_deg > 112.5`` = abaft own beam
    by more than 22.5 deg, COLREG Rule 13).
``aspect_deg``
    (-180, 180] deg. Relative bearing of own ship seen from the other ship's course over ground
    (alpha of colregs.md): 0 = own ship dead ahead of the other, +90 = on its starboard beam.
``aspect_abs_deg``
    [0, 180] deg. ``|aspect_deg|``.
``course_diff_deg``
    (-180, 180] deg. Other's course over ground minus own course over ground (180 = reciprocal).
``course_diff_abs_deg``
    [0, 180] deg. ``|course_diff_deg|`` (Rule 14: reciprocal or nearly reciprocal courses).
``dcpa_nm``
    [0, inf) NM. Distance at the closest point of approach, straight tracks: ``|p x v| / |v|``;
    equals ``range_nm`` with no relative motion.
``tcpa_min``
    (-inf, inf] min. Time to the closest point of approach, ``-(p . v) / |v|^2``; negative when
    the CPA is past, +inf with no relative motion (``|v|^2 <= 1e-12 m^2/s^2``).
``bcr_nm``
    (-inf, inf] NM. Bow-crossing range: where the other ship crosses own bow line (the line through
    own ship along own heading), as distance along the heading; > 0 means it crosses ahead, < 0
    astern. +inf when the other never crosses the line (relative speed across it at most
    1e-6 m/s, e.g. a reciprocal or parallel course).
``bct_min``
    (-inf, inf] min. Time of that crossing; negative when it is past, +inf when it never crosses.
    Rules should pair ``bcr_nm`` tests with a ``bct_min`` window.
``speed_ratio``
    [0, inf]. Other's speed over ground / own speed over ground; +inf when own ship is stopped
    (below 1e-6 m/s) and the other is not, 1 when both are.
``own_speed_kn``, ``other_speed_kn``
    [0, inf) kn. Speeds over ground.
``domain_nm``
    (0, inf) NM. Distance from own ship to the boundary of own ship domain (module
    :mod:`trafficsim.colregs.domains`, fixed to own heading, sized by own length and speed over
    ground) along the line of sight to the other ship (along the bow at zero range). The
    encounter counts as *overtaking* for the Coldwell domain when, per COLREG Rule 13, one ship
    lies more than 22.5 deg abaft the other's beam (relative bearing beyond 112.5 deg from the
    bow, or from the course over ground for the other ship) and is the faster of the two over
    ground ("coming up with" her):
    ``(bearing_abs_deg > 112.5 and other faster) or (aspect_abs_deg > 112.5 and own faster)``.
``range_to_domain_nm``
    (-inf, inf) NM. ``range_nm - domain_nm``; negative inside the domain.
``time_to_domain_min``
    [0, inf] min. First time the other ship is inside own domain if both keep their present
    velocities (domain fixed to own heading; relative velocity taken in own body frame): 0 if
    already inside (exactly when ``range_to_domain_nm <= 0``), +inf if not within the
    look-ahead ``horizon_s``. The ongoing look-ahead of
    [seed 002, appendix F, "Simulation of a marine guidance and expert collision avoidance
    system", analysis of simulation results, point 3].
``predicted_domain_entry``
    {0, 1}. 1.0 when ``time_to_domain_min`` is finite (entry within the horizon).
``visibility_nm``
    [0, inf) NM. Visibility at own ship, as passed in (Rule 19 tests).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from trafficsim.colregs import domains
from trafficsim.errors import InputError
from trafficsim.geometry import atan2, cos_sin
from trafficsim.jit import kernel
from trafficsim.units import KN, NM

#: feature names, in the row order of :attr:`Features.values`
NAMES: tuple[str, ...] = (
    "range_nm",
    "bearing_deg",
    "bearing_abs_deg",
    "aspect_deg",
    "aspect_abs_deg",
    "course_diff_deg",
    "course_diff_abs_deg",
    "dcpa_nm",
    "tcpa_min",
    "bcr_nm",
    "bct_min",
    "speed_ratio",
    "own_speed_kn",
    "other_speed_kn",
    "domain_nm",
    "range_to_domain_nm",
    "time_to_domain_min",
    "predicted_domain_entry",
    "visibility_nm",
)

#: feature name -> row
INDEX: dict[str, int] = {name: i for i, name in enumerate(NAMES)}

_ANGLE, _ABS_ANGLE, _NON_NEGATIVE = (-180.0, 180.0), (0.0, 180.0), (0.0, math.inf)
#: the values each bounded feature takes (the module docstring; ``tcpa_min``, ``bcr_nm``,
#: ``bct_min`` and ``range_to_domain_nm`` take any), so that a rules file's test no value
#: satisfies is refused (:attr:`trafficsim.colregs.rulefile.Vocabulary.feature_ranges`)
RANGES: dict[str, tuple[float, float]] = {
    "range_nm": _NON_NEGATIVE, "bearing_deg": _ANGLE, "bearing_abs_deg": _ABS_ANGLE,
    "aspect_deg": _ANGLE, "aspect_abs_deg": _ABS_ANGLE, "course_diff_deg": _ANGLE,
    "course_diff_abs_deg": _ABS_ANGLE, "dcpa_nm": _NON_NEGATIVE, "speed_ratio": _NON_NEGATIVE,
    "own_speed_kn": _NON_NEGATIVE, "other_speed_kn": _NON_NEGATIVE,
    "domain_nm": _NON_NEGATIVE, "time_to_domain_min": _NON_NEGATIVE,
    "predicted_domain_entry": (0.0, 1.0), "visibility_nm": _NON_NEGATIVE}

(RANGE, BEARING, BEARING_ABS, ASPECT, ASPECT_ABS, COURSE_DIFF, COURSE_DIFF_ABS, DCPA, TCPA, BCR,
 BCT, SPEED_RATIO,
 OWN_SPEED, OTHER_SPEED, DOMAIN, RANGE_TO_DOMAIN, TIME_TO_DOMAIN, DOMAIN_ENTRY,
 VISIBILITY) = range(len(NAMES))

#: below this speed over ground (m/s) a velocity direction is not trusted as a course
COURSE_MIN_SPEED_MPS = 0.1
#: Rule 13: more than 22.5 deg abaft the beam
ABAFT_BEAM_DEG = 112.5
#: relative speed squared (m^2/s^2) at or below which there is no relative motion
#: (the threshold of trafficsim.geometry.cpa)
STILL_V2 = 1e-12
#: relative speed across own bow line (m/s) at or below which the other never crosses it (the
#: rounding of a reciprocal course would otherwise give arbitrary crossings)
STILL_ACROSS_MPS = 1e-6
#: speed (m/s) below which a ship counts as stopped for the speed ratio
STOPPED_MPS = 1e-6

_DEG = 180.0 / math.pi
# unit conversions as multiplications (a division costs several times more in the pair loop)
_PER_NM, _PER_KN, _PER_MIN = 1.0 / NM, 1.0 / KN, 1.0 / 60.0


def feature_index(name: str) -> int:
    """Row of feature ``name``; an unknown name raises :class:`InputError` with a suggestion."""
    if isinstance(name, str) and name in INDEX:
        return INDEX[name]
    close = difflib.get_close_matches(str(name), NAMES, n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    raise InputError(f"unknown feature '{name}'{hint}; known features: {', '.join(NAMES)}",
                     key="feature")


@dataclass(frozen=True)
class Features:
    """Features of ``m`` directed pairs.

    Attributes:
        values: ``(len(NAMES), m)`` float64; row ``i`` is feature ``NAMES[i]``.
    """

    values: np.ndarray

    def __getitem__(self, name: str) -> np.ndarray:
        """The ``(m,)`` row of feature ``name`` (a view)."""
        return self.values[feature_index(name)]

    @property
    def n_pairs(self) -> int:
        """Number of pairs ``m``."""
        return self.values.shape[1]

    def as_dict(self) -> dict[str, np.ndarray]:
        """Name -> ``(m,)`` view, for reports and explanations."""
        return {name: self.values[i] for i, name in enumerate(NAMES)}


@kernel
def _deg(angle_rad: float) -> float:
    """Radians from an atan2 to degrees in (-180, 180] (an atan2 may return exactly -pi)."""
    d = angle_rad * _DEG
    return d + 360.0 if d <= -180.0 else d


@kernel
def _features_loop(kind: int, own_n: np.ndarray, own_e: np.ndarray, own_vn: np.ndarray,
                   own_ve: np.ndarray, hdg: np.ndarray, own_len: np.ndarray,
                   oth_n: np.ndarray, oth_e: np.ndarray, oth_vn: np.ndarray,
                   oth_ve: np.ndarray, visibility: np.ndarray, horizon_s: float,
                   out: np.ndarray) -> None:
    for i in range(own_n.size):
        pn, pe = oth_n[i] - own_n[i], oth_e[i] - own_e[i]
        vn, ve = oth_vn[i] - own_vn[i], oth_ve[i] - own_ve[i]
        if math.isnan(pn + pe + vn + ve + hdg[i]):
            # an unknown state (no track) gives unknown features: every test on them is false
            out[:, i] = math.nan
            out[VISIBILITY, i] = visibility[i]
            continue
        ch, sh = cos_sin(hdg[i])
        # own body frame (x forward, y starboard): the domain and the bow line turn with heading
        x, y = ch * pn + sh * pe, ch * pe - sh * pn
        vx, vy = ch * vn + sh * ve, ch * ve - sh * vn
        rng = math.sqrt(pn * pn + pe * pe)
        own_sog = math.sqrt(own_vn[i] * own_vn[i] + own_ve[i] * own_ve[i])
        oth_sog = math.sqrt(oth_vn[i] * oth_vn[i] + oth_ve[i] * oth_ve[i])

        # unit vectors of the courses over ground, with the fallbacks of the module docstring
        if own_sog < COURSE_MIN_SPEED_MPS:
            own_cn, own_ce = ch, sh
        else:
            inv = 1.0 / own_sog
            own_cn, own_ce = own_vn[i] * inv, own_ve[i] * inv
        if oth_sog < COURSE_MIN_SPEED_MPS:
            oth_cn, oth_ce = own_cn, own_ce
        else:
            inv = 1.0 / oth_sog
            oth_cn, oth_ce = oth_vn[i] * inv, oth_ve[i] * inv

        bearing = atan2(y, x)
        # own ship lies at -p from the other: cross and dot of the other's course with -p
        aspect = _deg(atan2(oth_ce * pn - oth_cn * pe, -(oth_cn * pn + oth_ce * pe)))
        bearing_deg = _deg(bearing)
        out[RANGE, i] = rng * _PER_NM
        out[BEARING, i] = bearing_deg
        out[BEARING_ABS, i] = abs(bearing_deg)
        out[ASPECT, i] = aspect
        out[ASPECT_ABS, i] = abs(aspect)
        out[COURSE_DIFF, i] = _deg(atan2(own_cn * oth_ce - own_ce * oth_cn,
                                         own_cn * oth_cn + own_ce * oth_ce))
        out[COURSE_DIFF_ABS, i] = abs(out[COURSE_DIFF, i])

        # CPA [colregs.md section 4]; DCPA from the cross product (no cancellation near CPA)
        v2 = vn * vn + ve * ve
        if v2 > STILL_V2:
            out[TCPA, i] = -(pn * vn + pe * ve) / v2 * _PER_MIN
            out[DCPA, i] = abs(pn * ve - pe * vn) / math.sqrt(v2) * _PER_NM
        else:
            out[TCPA, i] = math.inf
            out[DCPA, i] = rng * _PER_NM

        # bow-line crossing [colregs.md section 4]: t_bc = -(e_perp . p)/(e_perp . v) = -y/vy
        if abs(vy) > STILL_ACROSS_MPS:
            t_bc = -y / vy
            out[BCT, i] = t_bc * _PER_MIN
            out[BCR, i] = (x + vx * t_bc) * _PER_NM
        else:
            out[BCT, i] = math.inf
            out[BCR, i] = math.inf

        if own_sog >= STOPPED_MPS:
            out[SPEED_RATIO, i] = oth_sog / own_sog
        else:
            out[SPEED_RATIO, i] = math.inf if oth_sog >= STOPPED_MPS else 1.0
        out[OWN_SPEED, i] = own_sog * _PER_KN
        out[OTHER_SPEED, i] = oth_sog * _PER_KN

        # Rule 13: one ship more than 22.5 deg abaft the other's beam and the faster of the two
        overtaking = ((abs(bearing_deg) > ABAFT_BEAM_DEG and oth_sog > own_sog)
                      or (abs(aspect) > ABAFT_BEAM_DEG and own_sog > oth_sog))
        prm = domains.ship_params(kind, own_len[i], own_sog, overtaking)
        if rng > 0.0:  # (along (x, y) itself: the sector of a point on an edge is inside's)
            dom = rng * domains.ray_distance(kind, prm, x, y)
        else:
            dom = domains.ray_distance(kind, prm, 1.0, 0.0)
        out[DOMAIN, i] = dom * _PER_NM
        out[RANGE_TO_DOMAIN, i] = (rng - dom) * _PER_NM
        # inside exactly when range_to_domain_nm <= 0, so the two features never disagree
        t_in = 0.0 if rng <= dom else domains.entry_time(kind, prm, x, y, vx, vy, horizon_s)
        out[TIME_TO_DOMAIN, i] = t_in * _PER_MIN
        out[DOMAIN_ENTRY, i] = 1.0 if t_in < math.inf else 0.0
        out[VISIBILITY, i] = visibility[i]


def pair_features(own_north_m: ArrayLike, own_east_m: ArrayLike, own_vn_mps: ArrayLike,
                  own_ve_mps: ArrayLike, own_heading_rad: ArrayLike, own_length_m: ArrayLike,
                  oth_north_m: ArrayLike, oth_east_m: ArrayLike, oth_vn_mps: ArrayLike,
                  oth_ve_mps: ArrayLike, oth_length_m: ArrayLike, domain: str,
                  visibility_nm: ArrayLike, horizon_s: float,
                  out: np.ndarray | None = None) -> Features:
    """Encounter features of ``m`` directed pairs (see the module docstring for the vocabulary).

    Args:
        own_north_m, own_east_m: own estimated position, metres, ``(m,)`` each.
        own_vn_mps, own_ve_mps: own estimated velocity over ground, north/east, m/s, ``(m,)``.
        own_heading_rad: own heading, radians (0 = north, clockwise), ``(m,)``.
        own_length_m: own length, metres (> 0), ``(m,)``; sizes the domain.
        oth_north_m, oth_east_m: other ship's estimated position, metres, ``(m,)``.
        oth_vn_mps, oth_ve_mps: other ship's estimated velocity over ground, m/s, ``(m,)``.
        oth_length_m: other ship's length, metres, ``(m,)``; checked for shape, not used by the
            present vocabulary (own domain is sized by own length).
        domain: ship-domain name (``coldwell``, ``fujii``, ``goodwin``, ``kijima``).
        visibility_nm: visibility, NM, scalar or ``(m,)``.
        horizon_s: look-ahead for the domain entry, seconds.
        out: optional C-contiguous ``(len(NAMES), m)`` float64 array to write the values into
            (the returned features' ``values`` are then ``out``).

    Returns:
        :class:`Features` with ``values`` of shape ``(len(NAMES), m)``.

    Raises:
        InputError: unknown domain name, or per-pair arrays of different shapes.
    """
    code = domains.domain_code(domain)
    cols = [np.ascontiguousarray(a, dtype=np.float64) for a in (
        own_north_m, own_east_m, own_vn_mps, own_ve_mps, own_heading_rad, own_length_m,
        oth_north_m, oth_east_m, oth_vn_mps, oth_ve_mps, oth_length_m)]
    shape = cols[0].shape
    if len(shape) != 1 or any(c.shape != shape for c in cols):
        raise InputError("pair_features needs (m,) arrays of one length for every per-pair "
                         f"argument, got shapes {[c.shape for c in cols]}", key="pairs")
    vis = np.ascontiguousarray(np.broadcast_to(np.asarray(visibility_nm, dtype=np.float64),
                                               shape))
    if out is None:
        out = np.empty((len(NAMES), shape[0]))
    elif (out.shape != (len(NAMES), shape[0]) or out.dtype != np.float64
          or not out.flags.c_contiguous):
        raise ValueError(f"out must be a C-contiguous float64 array of shape "
                         f"{(len(NAMES), shape[0])}, got {out.shape} {out.dtype}")
    _features_loop(code, *cols[:10], vis, float(horizon_s), out)
    return Features(out)
