"""AIS class A position reports of other ships: schedule, noise, quantisation, latency, reception.

Every ship with a transponder broadcasts position reports (messages 1-3 of ITU-R M.1371-5,
annex 2) on its own schedule; every other ship of the encounter may receive them. Transmission
is per ship (one noisy report heard by all receivers alike), reception per directed pair
(:func:`trafficsim.sensors.radar.directed_pairs`).

Transmission (per ship, :func:`transmit`):

* Reporting interval of class A shipborne mobile equipment, ITU-R M.1371-5 annex 1, table 1
  (:func:`reporting_interval_s`): at anchor or moored and not faster than 3 kn, 3 min (faster:
  10 s); 0-14 kn, 10 s (3 1/3 s when changing course); 14-23 kn, 6 s (2 s when changing
  course); faster than 23 kn, 2 s. Speeds on a bin boundary take the slower rate (14 kn -> 10 s).
  "Changing course" is a rate of turn above 5 deg in 30 s, the threshold at which a class A
  station flags a turn in its ROT field without a rate-of-turn indicator (IMO guidelines for the
  installation of shipborne AIS, SN/Circ.227, ROT sensor input); configurable.
* The schedule is deterministic state: ``next_tx_s`` per ship. A report goes out on the first
  step at or after ``next_tx_s``; the next is one interval after the *scheduled* time (so the mean
  interval is exact whatever the step), and when the required interval shortens (the ship starts
  to turn or speeds up) the pending report is pulled forward to one new interval after the last
  one, as the station increases its rate at once; where that time has passed already, the
  report goes out now and the schedule restarts from it (no burst to catch up).
* The schedule follows the ship's true speed over ground and rate of turn (what the station's
  own sensors tell it; their noise would move a ship across a bin boundary only when it sails
  at a boundary speed).
* Content: the transmitting ship's GNSS position with white noise ``sigma_position_m`` per axis
  (the default 5 m per axis is 12 m horizontal at 95 %, a stand-alone GNSS receiver), its SOG
  and COG from the ground velocity with white noise ``sigma_velocity_mps`` per axis (so COG
  noise grows as speed falls, as a GNSS receiver's does), its gyro heading with
  ``sigma_heading_deg``. The ground velocity is the velocity through the water turned to the
  earth frame plus the current, worked out only for the ships that transmit.
* Quantisation of the message fields (ITU-R M.1371-5 annex 2, message 1 table): position in
  1/10000 min (latitude step 1852 m / 10000 = 0.1852 m north; longitude step 0.1852 cos(lat) m
  east, ``ref_latitude_deg``; the local frame's origin is taken on the grid), SOG in 0.1 kn
  (capped at 102.2 kn), COG in 0.1 deg, true heading in 1 deg. Values are rounded to the nearest
  step.
* Time stamp: the report carries the exact time of the position it holds (the step time of the
  transmission).

Reception (per directed pair, :func:`receive`): a report stamped ``t_r`` reaches the receivers
``latency_s`` (of the transmitting ship: GNSS fix age, slot wait and transmission, a deterministic
delay) later, i.e. on the first step at or after ``t_r + latency_s``; within ``max_range_nm`` of
the receiver (VHF line of sight) and with probability ``p_receive`` (slot collisions, fading).
If a long step makes several reports deliverable at once, only the newest is delivered (the
others are superseded). Each ship keeps its last ``AIS_BUFFER`` (9) reports in flight, so
latencies up to ``MAX_LATENCY_S`` (14 s) are exact at the highest rate and any step (a 2 s
reporter has at most ``(14 + 2) / 2 + 1 = 9`` reports in flight, with steps just under 2 s).

Draws, at need (:func:`trafficsim.noise.normal_from`): ``AIS_TX_NORMAL_DIMS`` standard normals
from the transmitting ship's stream (``ais`` purpose) per report sent (position north, east;
velocity north, east; heading) and ``AIS_RX_NORMAL_DIMS`` from the directed pair's stream
(``ais_rx``) per report that arrives at the receiver (the reception event, received when
``z < Phi^-1(p_receive)``; none when ``p_receive`` is 1). Nothing is drawn between reports.

Config keys (per ship; defaults in brackets): ``enabled`` [true] (transponder fitted),
``sigma_position_m`` [5.0], ``sigma_velocity_mps`` [0.1], ``sigma_heading_deg`` [0.5],
``latency_s`` [2.0], ``first_report_s`` [0.0], ``max_range_nm`` [20.0], ``p_receive`` [1.0],
``turn_rate_degps`` [5/30], ``ref_latitude_deg`` [0.0].

Upper bounds, generous limits no real transponder reaches: ``sigma_position_m`` at most 1 km
(the GNSS receivers' bound, :data:`trafficsim.sensors.gnss.MAX_SIGMA_M`), ``sigma_velocity_mps``
at most 10 m/s (about 20 kn), ``sigma_heading_deg`` at most 30 deg (a gyro is good to about
1 deg [seed 002, sec 2.9]), ``max_range_nm`` at most 200 NM (VHF reaches some 20-40 NM; ten
times that), ``turn_rate_degps`` at most 30 deg/s (no ship turns that fast: a higher threshold
never fires), ``latency_s`` at most ``MAX_LATENCY_S`` and ``p_receive`` at most 1.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from trafficsim.errors import InputError
from trafficsim.geometry import atan2, cos_sin, norm_side
from trafficsim.jit import kernel, prefetch
from trafficsim.noise import check_streams, normal_from
from trafficsim.sensors import KNOT_MPS, check_keys, column, flags, wrap_2pi, wrap_2pi_scalar
from trafficsim.sensors.radar import probit
from trafficsim.ships.base import EAST, NORTH, PSI, R, U, V

#: standard normals per report sent: position N, E; velocity N, E; heading
AIS_TX_NORMAL_DIMS = 5
#: standard normals per report arriving at a receiver: reception event
AIS_RX_NORMAL_DIMS = 1
AIS_PURPOSE = "ais"
#: reports kept in flight per ship
AIS_BUFFER = 9
#: the transmission loop prefetches the stream and buffer slot of the ship this far ahead
PREFETCH_AHEAD = 8

#: message 1-3 field resolutions (ITU-R M.1371-5 annex 2)
POSITION_STEP_M = 1852.0 / 10000.0  # 1/10000 min of latitude
SOG_STEP_MPS = 0.1 * KNOT_MPS
SOG_MAX_MPS = 102.2 * KNOT_MPS
COG_STEP_RAD = math.radians(0.1)
HEADING_STEP_RAD = math.radians(1.0)

#: ITU-R M.1371-5 annex 1 table 1, class A reporting intervals, s
INTERVAL_ANCHORED_S = 180.0
INTERVAL_SLOW_S = 10.0
INTERVAL_SLOW_TURNING_S = 10.0 / 3.0
INTERVAL_MEDIUM_S = 6.0
INTERVAL_FAST_S = 2.0
ANCHOR_SPEED_KN, SLOW_KN, MEDIUM_KN = 3.0, 14.0, 23.0
DEFAULT_TURN_RATE_DEGPS = 5.0 / 30.0
#: the longest latency delivered exactly (the buffer holds every report still in flight)
MAX_LATENCY_S = (AIS_BUFFER - 2) * INTERVAL_FAST_S

KEYS = ("enabled", "sigma_position_m", "sigma_velocity_mps", "sigma_heading_deg", "latency_s",
        "first_report_s", "max_range_nm", "p_receive", "turn_rate_degps", "ref_latitude_deg")
MAX_SIGMA_POSITION_M = 1000  # as a GNSS receiver's (gnss.MAX_SIGMA_M)
MAX_SIGMA_VELOCITY_MPS = 10  # about 20 kn
MAX_SIGMA_HEADING_DEG = 30  # a gyro is good to about 1 deg [seed 002, sec 2.9]
MAX_RANGE_NM = 200  # VHF line of sight is some 20-40 NM
MAX_TURN_RATE_DEGPS = 30  # no ship turns faster


@dataclass(frozen=True)
class AisParams:
    """Per-ship AIS parameters, ``(n,)`` arrays (the ship as transmitter and as receiver).

    Attributes:
        enabled: bool, transponder fitted and on.
        sigma_position_m: position noise per axis in the broadcast, m.
        sigma_velocity_mps: ground-velocity noise per axis behind SOG/COG, m/s.
        sigma_heading_rad: heading noise, rad.
        latency_s: delay from a report's time stamp to its reception, s.
        first_report_s: time of the first report, s.
        max_range_m: reception range of this ship as receiver, m.
        p_receive, z_receive: reception probability and ``Phi^-1(p_receive)``.
        turn_rate_radps: rate of turn above which the ship counts as changing course, rad/s.
        east_step_m: east quantisation step ``0.1852 cos(ref_latitude)``, m.
    """

    enabled: np.ndarray
    sigma_position_m: np.ndarray
    sigma_velocity_mps: np.ndarray
    sigma_heading_rad: np.ndarray
    latency_s: np.ndarray
    first_report_s: np.ndarray
    max_range_m: np.ndarray
    p_receive: np.ndarray
    z_receive: np.ndarray
    turn_rate_radps: np.ndarray
    east_step_m: np.ndarray


@dataclass(frozen=True)
class AisState:
    """Schedules and reports in flight.

    Attributes:
        next_tx_s: ``(n,)`` scheduled time of each ship's next report, s.
        last_tx_s: ``(n,)`` scheduled time of its last report, s (-inf before the first).
        head: ``(n,)`` int, buffer slot of the newest report.
        buf_t_s: ``(n, AIS_BUFFER)`` time stamps of the last reports, s (-inf = empty).
        buf: ``(n, AIS_BUFFER, 5)`` their fields: north_m, east_m, sog_mps, cog_rad, heading_rad.
        last_rx_s: ``(m,)`` time stamp of the last report consumed per directed pair, s.
    """

    next_tx_s: np.ndarray
    last_tx_s: np.ndarray
    head: np.ndarray
    buf_t_s: np.ndarray
    buf: np.ndarray
    last_rx_s: np.ndarray


@dataclass(frozen=True)
class AisReports:
    """Reports received this step, per directed pair ``(m,)`` (NaN where ``valid`` is false).

    Attributes:
        valid: bool, a report from the target was received this step.
        stamp_s: the report's time stamp (the time its position refers to), s.
        north_m, east_m: reported (quantised) position, m.
        sog_mps, cog_rad, heading_rad: reported SOG (m/s), COG and heading (rad, [0, 2 pi)).
        in_flight_s: the stamp of the oldest report of the target still on its way to the
            observer (sent, neither received nor lost yet), s; +inf when there is none, None
            when not known. A report received in a later step is stamped no earlier.
    """

    valid: np.ndarray
    stamp_s: np.ndarray
    north_m: np.ndarray
    east_m: np.ndarray
    sog_mps: np.ndarray
    cog_rad: np.ndarray
    heading_rad: np.ndarray
    in_flight_s: np.ndarray | None = None


def build(configs: Sequence[Mapping]) -> AisParams:
    """AIS parameters from per-ship config dicts (keys and defaults: module docstring)."""
    what = "ais"
    check_keys(configs, KEYS, what)
    p_receive = column(configs, "p_receive", 1.0, what, minimum=0.0)
    if np.any(p_receive > 1.0):
        raise InputError(f"must be <= 1, got {p_receive.max()}", key=f"{what}.p_receive")
    latency = column(configs, "latency_s", 2.0, what, minimum=0.0)
    if np.any(latency > MAX_LATENCY_S):
        raise InputError(f"latency_s must be <= {MAX_LATENCY_S:g} s, got {latency.max():g}",
                         key=f"{what}.latency_s")
    lat = column(configs, "ref_latitude_deg", 0.0, what, scale=math.pi / 180.0)
    if np.any(np.abs(lat) >= math.pi / 2):
        raise InputError("ref_latitude_deg must be inside (-90, 90)",
                         key=f"{what}.ref_latitude_deg")
    return AisParams(
        enabled=flags(configs, "enabled", what),
        sigma_position_m=column(configs, "sigma_position_m", 5.0, what, minimum=0.0,
                                maximum=MAX_SIGMA_POSITION_M),
        sigma_velocity_mps=column(configs, "sigma_velocity_mps", 0.1, what, minimum=0.0,
                                  maximum=MAX_SIGMA_VELOCITY_MPS),
        sigma_heading_rad=column(configs, "sigma_heading_deg", 0.5, what, scale=math.pi / 180.0,
                                 minimum=0.0, maximum=MAX_SIGMA_HEADING_DEG),
        latency_s=latency,
        first_report_s=column(configs, "first_report_s", 0.0, what),
        max_range_m=column(configs, "max_range_nm", 20.0, what, scale=1852.0, minimum=0.0,
                           maximum=MAX_RANGE_NM),
        p_receive=p_receive,
        z_receive=probit(p_receive),
        turn_rate_radps=column(configs, "turn_rate_degps", DEFAULT_TURN_RATE_DEGPS, what,
                               scale=math.pi / 180.0, minimum=0.0, maximum=MAX_TURN_RATE_DEGPS),
        east_step_m=POSITION_STEP_M * np.cos(lat),
    )


def init(params: AisParams, n_pairs: int) -> AisState:
    """Schedules before the first step (first report at ``first_report_s``), nothing in flight.

    Args:
        n_pairs: number ``m`` of directed pairs.
    """
    n = params.enabled.shape[0]
    return AisState(
        next_tx_s=params.first_report_s.astype(float).copy(),
        last_tx_s=np.full(n, -np.inf),
        head=np.zeros(n, dtype=np.int64),
        buf_t_s=np.full((n, AIS_BUFFER), -np.inf),
        buf=np.full((n, AIS_BUFFER, 5), np.nan),
        last_rx_s=np.full(int(n_pairs), -np.inf),
    )


def reporting_interval_s(sog_mps: np.ndarray, turning: np.ndarray,
                         anchored: np.ndarray | bool = False) -> np.ndarray:
    """Class A reporting interval, s, ITU-R M.1371-5 annex 1 table 1.

    Args:
        sog_mps: ``(n,)`` speed over ground, m/s.
        turning: ``(n,)`` bool, changing course.
        anchored: ``(n,)`` bool (or scalar), at anchor or moored (navigational status).
    """
    kn = np.asarray(sog_mps, dtype=float) / KNOT_MPS
    turning = np.asarray(turning, dtype=bool)
    slow = np.where(turning, INTERVAL_SLOW_TURNING_S, INTERVAL_SLOW_S)
    medium = np.where(turning, INTERVAL_FAST_S, INTERVAL_MEDIUM_S)
    under_way = np.where(kn > MEDIUM_KN, INTERVAL_FAST_S, np.where(kn > SLOW_KN, medium, slow))
    at_anchor = np.where(kn > ANCHOR_SPEED_KN, INTERVAL_SLOW_S, INTERVAL_ANCHORED_S)
    return np.where(np.asarray(anchored, dtype=bool), at_anchor, under_way)


def quantise_position(north_m: np.ndarray, east_m: np.ndarray,
                      east_step_m: np.ndarray | float = POSITION_STEP_M
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Position rounded to 1/10000 min of latitude (north) and longitude (east), m."""
    return (np.round(north_m / POSITION_STEP_M) * POSITION_STEP_M,
            np.round(east_m / east_step_m) * east_step_m)


def quantise_sog(sog_mps: np.ndarray) -> np.ndarray:
    """SOG rounded to 0.1 kn and capped at 102.2 kn, m/s."""
    return np.minimum(np.round(sog_mps / SOG_STEP_MPS), 1022.0) * SOG_STEP_MPS


def quantise_angle(angle_rad: np.ndarray, step_rad: float) -> np.ndarray:
    """Angle rounded to ``step_rad`` in [0, 2 pi), rad (COG: 0.1 deg, heading: 1 deg)."""
    n_steps = round(2.0 * math.pi / step_rad)
    return np.mod(np.round(wrap_2pi(angle_rad) / step_rad), n_steps) * step_rad


def transmit(params: AisParams, state: AisState, t_s: float, x_true: np.ndarray,
             current_ne_mps: np.ndarray, streams: np.ndarray,
             anchored: np.ndarray | None = None,
             inplace: bool = False) -> tuple[AisState, np.ndarray]:
    """Ships whose report is due at ``t_s`` broadcast it; schedules advance.

    One compiled loop over ships with the scalar forms of :func:`reporting_interval_s`,
    :func:`quantise_position`, :func:`quantise_sog` and :func:`quantise_angle`.

    Args:
        params: ``(n,)`` AIS parameters.
        state: schedules and reports in flight.
        t_s: time of this step, s.
        x_true: ``(8, n)`` true state of the broadcasting ships (position, heading, velocity
            through the water, yaw rate).
        current_ne_mps: ``(2, n)`` current at each ship, north and east, m/s.
        streams: ``(n, 4)`` uint64 random-stream states, one per ship, advanced in place by
            ``AIS_TX_NORMAL_DIMS`` numbers per report sent.
        anchored: optional ``(n,)`` bool navigational status "at anchor / moored".
        inplace: update ``state``'s arrays instead of copies (the engine's step path).

    Returns: the new state and ``sent`` (n,) bool.
    """
    n = x_true.shape[1]
    check_streams(streams, n)
    new = state if inplace else AisState(
        next_tx_s=state.next_tx_s.copy(), last_tx_s=state.last_tx_s.copy(),
        head=state.head.copy(), buf_t_s=state.buf_t_s.copy(), buf=state.buf.copy(),
        last_rx_s=state.last_rx_s)
    anchor = (np.zeros(n, dtype=bool) if anchored is None
              else _c(np.broadcast_to(anchored, (n,)), bool))
    sent = np.empty(n, dtype=bool)
    p = params
    _transmit((_c(p.enabled, bool), _c(p.sigma_position_m), _c(p.sigma_velocity_mps),
               _c(p.sigma_heading_rad), _c(p.turn_rate_radps), _c(p.east_step_m)),
              (new.next_tx_s, new.last_tx_s, new.head, new.buf_t_s, new.buf), float(t_s),
              _c(x_true), _c(current_ne_mps), streams, anchor, sent)
    return new, sent


def receive(params: AisParams, state: AisState, t_s: float, obs: np.ndarray, tgt: np.ndarray,
            x_true: np.ndarray, streams: np.ndarray, inplace: bool = False,
            out: AisReports | None = None) -> tuple[AisState, AisReports]:
    """Reports of each target that reach each observer at ``t_s`` (one compiled loop over
    pairs).

    Args:
        obs, tgt: ``(m,)`` int receiving and transmitting ship indices.
        x_true: ``(8, n)`` true states (for the reception range).
        streams: ``(m, 4)`` uint64 random-stream states, one per pair, advanced in place by
            ``AIS_RX_NORMAL_DIMS`` numbers per report that arrives.
        inplace: update ``state.last_rx_s`` itself instead of a copy (the engine's step path).
        out: the reports this function returned at the last step, to be overwritten and
            returned (the engine's step path): only the pairs that receive a report now or
            received one then are written.
    """
    m = obs.shape[0]
    check_streams(streams, m)
    last_rx = state.last_rx_s if inplace else state.last_rx_s.copy()
    reports = out if out is not None else AisReports(
        valid=np.zeros(m, dtype=bool), stamp_s=np.full(m, np.nan), north_m=np.full(m, np.nan),
        east_m=np.full(m, np.nan), sog_mps=np.full(m, np.nan), cog_rad=np.full(m, np.nan),
        heading_rad=np.full(m, np.nan), in_flight_s=np.empty(m))
    p = params
    _receive((_c(p.enabled, bool), _c(p.latency_s), _c(p.max_range_m), _c(p.z_receive)),
             _c(state.buf_t_s), _c(state.buf), _c(state.head, np.int64), last_rx, float(t_s),
             _c(obs, np.int64), _c(tgt, np.int64), _c(x_true), streams,
             (reports.valid, reports.stamp_s, reports.north_m, reports.east_m, reports.sog_mps,
              reports.cog_rad, reports.heading_rad, reports.in_flight_s))
    new = state if inplace else AisState(
        next_tx_s=state.next_tx_s, last_tx_s=state.last_tx_s, head=state.head,
        buf_t_s=state.buf_t_s, buf=state.buf, last_rx_s=last_rx)
    return new, reports


def step(params: AisParams, state: AisState, t_s: float, obs: np.ndarray, tgt: np.ndarray,
         x_true: np.ndarray, current_ne_mps: np.ndarray, tx_streams: np.ndarray,
         rx_streams: np.ndarray,
         anchored: np.ndarray | None = None, inplace: bool = False,
         out: AisReports | None = None) -> tuple[AisState, AisReports]:
    """One step: broadcast the reports that are due, then deliver those that have arrived.

    Arguments as in :func:`transmit` (``tx_streams``) and :func:`receive` (``rx_streams``). A
    report with zero latency is received in the step it is sent.
    """
    state, _ = transmit(params, state, t_s, x_true, current_ne_mps, tx_streams, anchored,
                        inplace)
    return receive(params, state, t_s, obs, tgt, x_true, rx_streams, inplace, out)


def _c(a: np.ndarray, dtype: type = float) -> np.ndarray:
    """``a`` as a C-contiguous array (one compiled specialisation for every caller)."""
    return np.ascontiguousarray(a, dtype=dtype)


_MIN_INTERVAL_S = min(INTERVAL_ANCHORED_S, INTERVAL_SLOW_S, INTERVAL_SLOW_TURNING_S,
                      INTERVAL_MEDIUM_S, INTERVAL_FAST_S)
_COG_STEPS = float(round(2.0 * math.pi / COG_STEP_RAD))
_HEADING_STEPS = float(round(2.0 * math.pi / HEADING_STEP_RAD))


@kernel
def _faster_than(vn: float, ve: float, kn: float) -> bool:
    """``hypot(vn, ve) / KNOT_MPS > kn``, as that expression evaluates."""
    side = norm_side(vn, ve, kn, KNOT_MPS)
    return side > 0 if side != 0 else math.hypot(vn, ve) / KNOT_MPS > kn


@kernel
def _interval(vn: float, ve: float, turning: bool, anchored: bool) -> float:
    """:func:`reporting_interval_s` of one ship with ground velocity ``(vn, ve)``, s."""
    if anchored:
        return INTERVAL_SLOW_S if _faster_than(vn, ve, ANCHOR_SPEED_KN) else INTERVAL_ANCHORED_S
    if _faster_than(vn, ve, MEDIUM_KN):
        return INTERVAL_FAST_S
    if _faster_than(vn, ve, SLOW_KN):
        return INTERVAL_FAST_S if turning else INTERVAL_MEDIUM_S
    return INTERVAL_SLOW_TURNING_S if turning else INTERVAL_SLOW_S


#: relative and absolute (m/s) widening of the speed-over-ground bracket of a ship in a current
_BRACKET = 1e-12


@kernel
def _interval_in_current(u: float, v: float, cn: float, ce: float, turning: bool,
                         anchored: bool) -> float:
    """:func:`_interval` of a ship sailing ``(u, v)`` through a current ``(cn, ce)`` without
    its heading: the speed over ground lies within the current's speed of the speed through
    the water, and where that whole bracket falls in one bin of the table (intervals do not
    grow with speed) that bin's interval is the answer; -1 when the bracket spans a boundary."""
    through, drift = math.sqrt(u * u + v * v), math.sqrt(cn * cn + ce * ce)
    lo = (through - drift) * (1.0 - _BRACKET) - _BRACKET
    hi = (through + drift) * (1.0 + _BRACKET) + _BRACKET
    fast = _interval(hi, 0.0, turning, anchored)
    return fast if _interval(max(lo, 0.0), 0.0, turning, anchored) == fast else -1.0


#: relative margin below a speed threshold within which :func:`_surely_keeps` leaves the
#: decision to the exact interval
_KEEP_MARGIN = 1e-9


@kernel
def _surely_keeps(u: float, v: float, cn: float, ce: float, gap: float) -> bool:
    """Whether a ship sailing ``(u, v)`` through a current ``(cn, ce)``, not turning and not
    at anchor, surely has an interval no shorter than ``gap`` (``next_tx - last_tx``, in
    ``(INTERVAL_FAST_S, INTERVAL_SLOW_S]``): intervals shrink only with speed, below 14 kn
    (23 kn for a gap up to ``INTERVAL_MEDIUM_S``) none is shorter, and the speed over ground is
    at most the speed through the water plus the current's. A cheap test ahead of
    :func:`_interval_in_current`; False leaves the answer to it."""
    limit = (SLOW_KN if gap > INTERVAL_MEDIUM_S else MEDIUM_KN) * KNOT_MPS * (1.0 - _KEEP_MARGIN)
    limit -= math.sqrt(cn * cn + ce * ce)  # (still water: less zero, the limit itself)
    return (limit > 0.0) & (u * u + v * v < limit * limit)


@kernel
def _quantise_angle(angle_rad: float, step_rad: float, n_steps: float) -> float:
    """:func:`quantise_angle` of one angle (``n_steps`` = 2 pi / step, a whole number; the
    rounded step count lies in ``[0, n_steps]``, so its modulo is one comparison)."""
    q = np.rint(wrap_2pi_scalar(angle_rad) / step_rad)
    return (q - n_steps if q >= n_steps else q) * step_rad


@kernel
def _transmit(params: tuple, state: tuple, t_s: float, x_true: np.ndarray, current: np.ndarray,
              streams: np.ndarray, anchored: np.ndarray, sent: np.ndarray) -> None:
    """Schedule, content and buffer of every ship's report (module docstring), in place.

    ``params``: ``(enabled, sigma_position_m, sigma_velocity_mps, sigma_heading_rad,
    turn_rate_radps, east_step_m)``; ``state``: ``(next_tx_s, last_tx_s, head, buf_t_s, buf)``
    of :class:`AisState`.
    """
    enabled, sp, sv, sh, turn_rate, east_step = params
    next_tx, last_tx, head, buf_t, buf = state
    n = x_true.shape[1]
    # the ships whose schedule surely stays as it is, in a loop without branches that the
    # compiler vectorises (most ships at most steps)
    quiet = np.empty(n, dtype=np.bool_)
    for i in range(n):
        # no interval can pull the pending report before next_tx, and it is not due (most
        # steps of fast ships; always without a transponder)
        settled = (not math.isfinite(last_tx[i])) | (last_tx[i] + _MIN_INTERVAL_S >= next_tx[i])
        due = enabled[i] & (t_s >= next_tx[i] - 1e-9)
        # or not due and not pulled forward by a shorter interval
        gap = next_tx[i] - last_tx[i]
        keeps = ((t_s < next_tx[i] - 1e-9) & (not anchored[i]) & (gap <= INTERVAL_SLOW_S)
                 & (abs(x_true[R, i]) <= turn_rate[i])
                 & _surely_keeps(x_true[U, i], x_true[V, i], current[0, i], current[1, i], gap))
        quiet[i] = (settled & (not due)) | keeps
    # the few ships that may send are scattered: ask for their stream and buffer slot early
    streams_flat, buf_t_flat, buf_flat = streams.reshape(-1), buf_t.reshape(-1), buf.reshape(-1)
    for i in range(n):
        f = i + PREFETCH_AHEAD
        if f < n and not quiet[f]:
            slot = f * AIS_BUFFER + (head[f] + 1) % AIS_BUFFER
            prefetch(streams_flat, 4 * f)
            prefetch(buf_t_flat, slot)
            prefetch(buf_flat, 5 * slot)
            prefetch(buf_flat, 5 * slot + 4)
        if quiet[i]:
            sent[i] = False
            continue
        u, v, psi = x_true[U, i], x_true[V, i], x_true[PSI, i]
        cn, ce = current[0, i], current[1, i]
        still = cn == 0.0 and ce == 0.0  # speed over ground = speed through the water
        turning, anchor = abs(x_true[R, i]) > turn_rate[i], anchored[i]
        vn = ve = 0.0
        ground = False  # ground velocity worked out
        if still:
            interval = _interval(u, v, turning, anchor)
        else:
            interval = _interval_in_current(u, v, cn, ce, turning, anchor)
            if interval < 0.0:  # near a bin boundary: the ground velocity decides
                c, s = cos_sin(psi)
                vn, ve, ground = u * c - v * s + cn, u * s + v * c + ce, True
                interval = _interval(vn, ve, turning, anchor)
        # a shorter required interval pulls the pending report forward
        pending = next_tx[i]
        if math.isfinite(last_tx[i]) and last_tx[i] + interval < pending:
            pending = last_tx[i] + interval
        sent[i] = enabled[i] and t_s >= pending - 1e-9
        if not sent[i]:
            next_tx[i] = pending
            continue
        nxt = pending + interval
        if nxt <= t_s + 1e-9:  # the schedule fell behind (a shorter interval, pulled into the
            next_tx[i], last_tx[i] = t_s + interval, t_s  # past): it restarts from now
        else:
            next_tx[i], last_tx[i] = nxt, pending
        if not ground:
            c, s = cos_sin(psi)
            vn, ve = u * c - v * s + cn, u * s + v * c + ce
        z_n, z_e = normal_from(streams, i), normal_from(streams, i)
        z_vn, z_ve, z_h = normal_from(streams, i), normal_from(streams, i), normal_from(streams, i)
        vn += sv[i] * z_vn
        ve += sv[i] * z_ve
        sog = math.sqrt(vn * vn + ve * ve)  # (hypot: 20 ns more; equal to the 0.1 kn step)
        h = (head[i] + 1) % AIS_BUFFER
        head[i] = h
        buf_t[i, h] = t_s
        n_q = np.rint((x_true[NORTH, i] + sp[i] * z_n) / POSITION_STEP_M)
        e_q = np.rint((x_true[EAST, i] + sp[i] * z_e) / east_step[i])
        buf[i, h, 0] = n_q * POSITION_STEP_M
        buf[i, h, 1] = e_q * east_step[i]
        sog_q = np.rint(sog / SOG_STEP_MPS)
        buf[i, h, 2] = (1022.0 if sog_q > 1022.0 else sog_q) * SOG_STEP_MPS
        buf[i, h, 3] = _quantise_angle(atan2(ve, vn), COG_STEP_RAD, _COG_STEPS)
        buf[i, h, 4] = _quantise_angle(psi + sh[i] * z_h, HEADING_STEP_RAD, _HEADING_STEPS)


@kernel
def _receive(params: tuple, buf_t: np.ndarray, buf: np.ndarray, head: np.ndarray,
             last_rx: np.ndarray, t_s: float, obs: np.ndarray, tgt: np.ndarray,
             x_true: np.ndarray, streams: np.ndarray, out: tuple) -> None:
    """Newest arrived report per pair, reception range and probability (module docstring);
    ``last_rx`` advances in place. ``params``: ``(enabled, latency_s, max_range_m,
    z_receive)``; ``out``: the arrays of :class:`AisReports`, NaN where ``valid`` is false
    (kept so: a pair that received nothing now is written only if it did before)."""
    enabled, latency, max_range, z_receive = params
    valid, stamp, north, east, sog, cog, heading, in_flight = out
    for k in range(obs.shape[0]):
        i, j = obs[k], tgt[k]
        # newest report stamped after the last one consumed that has arrived by now; none
        # when the target's newest is consumed already. The ring holds the reports newest
        # first from ``head`` back, so those on their way (one latency per sender) come
        # first and the first arrived one is the newest: the walk stops there.
        slot, newest, oldest_out = 0, -math.inf, math.inf
        s = head[j]
        for _ in range(AIS_BUFFER):
            st = buf_t[j, s]
            if not st > last_rx[k]:
                break
            if st + latency[j] <= t_s + 1e-9:
                slot, newest = s, st
                break
            oldest_out = st
            s = s - 1 if s > 0 else AIS_BUFFER - 1
        in_flight[k] = oldest_out
        ok = False
        if math.isfinite(newest):
            last_rx[k] = newest  # consumed whether heard or not
            if enabled[i] and (z_receive[i] == math.inf or normal_from(streams, k) < z_receive[i]):
                dn, de = x_true[NORTH, j] - x_true[NORTH, i], x_true[EAST, j] - x_true[EAST, i]
                side = norm_side(dn, de, max_range[i], 1.0)
                ok = side < 0 if side != 0 else math.hypot(dn, de) <= max_range[i]
        was = valid[k]
        valid[k] = ok
        if ok:
            stamp[k] = newest
            north[k], east[k], sog[k] = buf[j, slot, 0], buf[j, slot, 1], buf[j, slot, 2]
            cog[k], heading[k] = buf[j, slot, 3], buf[j, slot, 4]
        elif was:
            stamp[k] = north[k] = east[k] = sog[k] = cog[k] = heading[k] = math.nan
