"""Random encounters of a campaign, each reproducible from (campaign seed, encounter index).

An encounter is one own ship (ship 0, always following the campaign's policy) and one or more
other ships, each placed so that its DCPA and TCPA to the own ship at the start fall in the
spec's ranges: with relative velocity ``w = v_other - v_own``, TCPA ``T`` and DCPA ``D`` the
other ship starts at ``p = -w T + D n`` from the own ship, ``n`` a unit vector across ``w``
(either side). Its course relative to the own ship and its speed are drawn for the encounter
type, and a draw is kept only when it starts at least ``min_start_range_nm`` from the own ship
and its start geometry is of that type by the sectors of
COLREGS Rules 13-15 (``../shared/reference/colregs.md``) as the bundled ``rules/colregs.yaml``
reads them, so that the network sees the encounter the draw was meant to be: overtaking when
coming up faster from more than 22.5 degrees abaft the other's beam (relative bearing
112.5-247.5 degrees), head-on when nearly reciprocal (within 15 degrees, its
``reciprocal_deg``) and each ship sees the other ahead or nearly ahead (Rule 14(b); within 10
degrees of the bow, its ``head_on_bearing_deg``), crossing otherwise, give-way when the other
ship is on the own ship's starboard side. Head-on draws are within 6 degrees of reciprocal.
Keeping only such draws conditions the ship types and speeds on the geometry: the ships that
overtake, or are overtaken, are mostly the fast, or the slow, types (README, Campaigns).
In a multi-ship encounter each further ship must also leave the others placed before it that
much room (:func:`_clear_of`), so that no two ships start in a collision nobody can avoid.

Every ship sails a straight route along its initial course, long enough for the whole run.
With radar and AIS, each ship's radar first scans, and its transponder first reports, at a time
drawn within one scan period and one reporting interval (:func:`_phase`), so that the ships'
instruments are not in step, as at sea; these times come from a stream of their own (purpose
``"phase"``) and leave every other draw as it is. All other draws come from the encounter's own
stream (purpose ``"encounter"``), so encounter ``k`` is the same whatever the batch, chunk or
worker it runs in; the policy and the rogue share only decide what is done with the draws, so a
``no_avoidance`` baseline meets the very encounters of its ``colregs`` campaign.
"""

from __future__ import annotations

import bisect
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.batch import EncounterEnv, ShipSetup
from trafficsim.campaign.spec import ENCOUNTER_TYPES, CampaignSpec
from trafficsim.errors import InputError, ScenarioError
from trafficsim.navigation import merge_sensors
from trafficsim.noise import generator
from trafficsim.sensors import ais, radar
from trafficsim.ships.library import load_ship
from trafficsim.units import NM, from_kn

PAIR_TYPES = ENCOUNTER_TYPES[:-1]  # the types of one other ship
HEAD_ON_DEG = 6.0  # course difference from reciprocal of a head-on draw (Rule 14: "nearly")
RECIPROCAL_DEG = 15.0  # nearly reciprocal courses (180 - rules/colregs.yaml's reciprocal_deg)
HEAD_ON_BEARING_DEG = 10.0  # Rule 14(b): the other ship "ahead or nearly ahead" of each
ABAFT_LOW, ABAFT_HIGH = math.radians(112.5), math.radians(247.5)  # Rule 13(b) sector
ROGUES = ("turn_port", "late_action")
MAX_TRIES = 1000
TRIES_PER_SHIP = 100


class NoGeometryError(ScenarioError):
    """A draw found no start geometry of its encounter type in :data:`MAX_TRIES` tries."""


@dataclass(frozen=True)
class Encounter:
    """One drawn encounter: its ships (``encounter`` 0; the runner renumbers), environment,
    and the type of every other ship relative to the own ship."""

    index: int
    kind: str
    ships: list[ShipSetup]
    env: EncounterEnv
    pair_kinds: list[str]  # (n_ships - 1,) type of other ship k + 1
    dcpa_m: list[float]  # drawn start DCPA of every other ship
    tcpa_s: list[float]


def _wrap(angle: float) -> float:
    """Angle in [0, 2 pi)."""
    return angle % (2.0 * math.pi)


def _abaft(bearing: float) -> bool:
    """A relative bearing in the overtaking sector (more than 22.5 deg abaft the beam)."""
    return ABAFT_LOW < _wrap(bearing) < ABAFT_HIGH


def classify(own_psi: float, other_psi: float, rel_n: float, rel_e: float, own_speed: float,
             other_speed: float, *, own_course: float | None = None,
             mutual: bool = False) -> str:
    """Encounter type of the other ship at relative position ``(rel_n, rel_e)`` m, by the
    sectors of Rules 13-15 and the speeds (m/s) as ``rules/colregs.yaml`` reads them (both
    ships closing is assumed).

    ``own_psi`` is the own bow (bearings are taken from it) and ``other_psi`` the other ship's
    course (her aspect is taken from it); ``own_course`` (default ``own_psi``) is the own course
    of the reciprocal-course test. With ``mutual``, a crossing in which each ship sees the other
    on the same side (both to port or both to starboard) is ``"crossing_mutual"``, the
    network's ``mutual_crossing`` (Rule 14(c): in doubt, both keep out of the way); without it
    (the draws), such a crossing is give-way or stand-on by the own ship's side alone."""
    bearing = math.atan2(rel_e, rel_n) - own_psi  # of the other ship, from the own bow
    aspect = math.atan2(-rel_e, -rel_n) - other_psi  # of the own ship, from the other's bow
    if _abaft(aspect) and own_speed > other_speed:
        return "overtaking"
    if _abaft(bearing) and other_speed > own_speed:
        return "overtaken"
    own = own_psi if own_course is None else own_course
    reciprocal = abs(_wrap(other_psi - own) - math.pi) <= math.radians(RECIPROCAL_DEG)
    sector = math.radians(HEAD_ON_BEARING_DEG)
    if (reciprocal and abs(_wrap(bearing + math.pi) - math.pi) <= sector
            and abs(_wrap(aspect + math.pi) - math.pi) <= sector):
        return "head_on"
    starboard = _wrap(bearing) < math.pi
    if mutual and starboard == (_wrap(aspect) < math.pi):
        return "crossing_mutual"
    return "crossing_give_way" if starboard else "crossing_stand_on"


def _course_offset(kind: str, rng: np.random.Generator) -> float:
    """Other ship's course minus the own ship's, rad, drawn for ``kind``."""
    if kind == "head_on":
        return math.pi + math.radians(rng.uniform(-HEAD_ON_DEG, HEAD_ON_DEG))
    if kind == "crossing_give_way":
        return -math.radians(rng.uniform(15.0, 170.0))
    if kind == "crossing_stand_on":
        return math.radians(rng.uniform(15.0, 170.0))
    return math.radians(rng.uniform(-30.0, 30.0))  # overtaking either way


@functools.lru_cache(maxsize=64)
def _cdf(p: tuple[float, ...]) -> tuple[float, ...]:
    """Normalised cumulative weights, computed as ``rng.choice(len(p), p=p)`` computes them."""
    a = np.asarray(p, dtype=float)
    cdf = np.cumsum(a / a.sum())
    cdf /= cdf[-1]
    return tuple(cdf.tolist())


def _weighted(weights: dict[str, float], names: tuple[str, ...] | list[str],
              rng: np.random.Generator) -> str:
    """One of ``names`` with probability proportional to its weight: exactly the draw of
    ``rng.choice(len(names), p=p)`` (one uniform against the normalised cumulative weights),
    without its per-call validation and arrays."""
    cdf = _cdf(tuple(float(weights.get(n, 0.0)) for n in names))
    return names[bisect.bisect_right(cdf, rng.random())]


def _sensors(spec: CampaignSpec, rng: np.random.Generator) -> dict[str, Any]:
    s = spec.sensors
    if s is None:
        return {}
    out: dict[str, Any] = {"gnss": {"sigma_m": float(rng.uniform(*s.gnss_sigma_m))},
                           "compass": {"kind": "gyro",
                                       "sigma_deg": float(rng.uniform(*s.compass_sigma_deg))}}
    if s.radar:
        out["radar"] = {}
    if s.ais:
        out["ais"] = {}
    return out


def _route(north: float, east: float, psi: float, length_m: float) -> np.ndarray:
    return np.array([[north + length_m * math.cos(psi), east + length_m * math.sin(psi)]])


def _clear_of(placed: list[tuple[tuple[float, float], tuple[float, float]]],
              pos: tuple[float, float], vel: tuple[float, float], spec: CampaignSpec) -> bool:
    """Whether another ship starting at ``pos`` with velocity ``vel`` (m, m/s) leaves every
    other ship ``placed`` before it as much room as the spec gives the own ship: at least the
    spec's largest DCPA (or its least start range, if larger) apart at the start, and a pair
    closing to less than that DCPA no sooner than the spec's least TCPA (a multi-ship
    encounter must not start in a collision no one can avoid)."""
    room, least_s = NM * spec.dcpa_nm[1], 60.0 * spec.tcpa_min[0]
    start_room = max(room, NM * spec.min_start_range_nm)
    for (n, e), (vn, ve) in placed:
        pn, pe, dvn, dve = n - pos[0], e - pos[1], vn - vel[0], ve - vel[1]
        if math.hypot(pn, pe) < start_room:
            return False
        v2 = dvn * dvn + dve * dve
        t = -(pn * dvn + pe * dve) / v2 if v2 > 1e-12 else -1.0
        if 0.0 < t < least_s and abs(pn * dve - pe * dvn) < room * math.sqrt(v2):
            return False
    return True


def _ships(spec: CampaignSpec, pair_kinds: list[str], types: list[str],
           ship: Any, rng: np.random.Generator
           ) -> tuple[list[ShipSetup], list[float], list[float]] | None:
    """Own ship and the other ships of one encounter; None when some other ship finds no
    geometry of its type in :data:`TRIES_PER_SHIP` draws (the caller draws the own ship anew)."""
    own_type = _weighted(spec.ship_types, types, rng)
    own_speed = from_kn(ship(own_type)["service_speed_kn"]) * rng.uniform(*spec.speed_fraction)
    own_psi = rng.uniform(0.0, 2.0 * math.pi)
    reach = 1.5 * spec.duration_s
    behaviour = "colregs" if spec.policy == "colregs" else "keep_course"
    setups = [ShipSetup("own", ship(own_type), 0, 0.0, 0.0, own_psi, own_speed,
                        _route(0.0, 0.0, own_psi, own_speed * reach + NM), 0,
                        merge_sensors(ship(own_type).get("sensors"), _sensors(spec, rng)),
                        spec.sensors.filter if spec.sensors else "none", behaviour)]
    dcpas, tcpas = [], []
    placed: list[tuple[tuple[float, float], tuple[float, float]]] = []  # other ships so far
    for k, pair_kind in enumerate(pair_kinds, start=1):
        for _ in range(TRIES_PER_SHIP):
            type_ = _weighted(spec.ship_types, types, rng)
            speed = from_kn(ship(type_)["service_speed_kn"]) * rng.uniform(*spec.speed_fraction)
            psi = _wrap(own_psi + _course_offset(pair_kind, rng))
            dcpa = NM * rng.uniform(*spec.dcpa_nm) * (1.0 if rng.random() < 0.5 else -1.0)
            tcpa = 60.0 * rng.uniform(*spec.tcpa_min)
            wn = speed * math.cos(psi) - own_speed * math.cos(own_psi)
            we = speed * math.sin(psi) - own_speed * math.sin(own_psi)
            w = math.hypot(wn, we)
            if w < 0.5:  # too slow a closing for the TCPA range to mean anything
                continue
            rel_n = -wn * tcpa - dcpa * we / w
            rel_e = -we * tcpa + dcpa * wn / w
            vel = (speed * math.cos(psi), speed * math.sin(psi))
            if (classify(own_psi, psi, rel_n, rel_e, own_speed, speed) == pair_kind
                    and math.hypot(rel_n, rel_e) >= NM * spec.min_start_range_nm
                    and _clear_of(placed, (rel_n, rel_e), vel, spec)):
                break
        else:
            return None
        placed.append(((rel_n, rel_e), vel))
        # (drawn whatever the policy and share, so that they change nothing else)
        u, rogue_kind = rng.random(), int(rng.integers(len(ROGUES)))
        rogue = spec.policy == "colregs" and u < spec.rogue_fraction
        who = ROGUES[rogue_kind] if rogue else behaviour
        setups.append(ShipSetup(f"ship{k}", ship(type_), 0, rel_n, rel_e, psi, speed,
                                _route(rel_n, rel_e, psi, speed * reach + NM), k,
                                merge_sensors(ship(type_).get("sensors"), _sensors(spec, rng)),
                                spec.sensors.filter if spec.sensors else "none", who))
        dcpas.append(abs(dcpa))
        tcpas.append(tcpa)
    return setups, dcpas, tcpas


def draw(spec: CampaignSpec, index: int, ships_cache: dict[str, Any] | None = None,
         kind: str | None = None) -> Encounter:
    """Encounter ``index`` of the campaign (see the module docstring); ``kind`` forces its type
    (the draws that follow then differ from the campaign's encounter ``index``).

    Raises:
        NoGeometryError: no start geometry of the type found.
    """
    rng = generator(spec.seed, index, 0, "encounter")
    cache = {} if ships_cache is None else ships_cache
    base_dir = spec.path.parent if spec.path is not None else None

    def ship(type_: str) -> Any:
        if type_ not in cache:
            cache[type_] = load_ship(type_, base_dir)
        return cache[type_]

    types = list(spec.ship_types)
    drawn_kind = _weighted(spec.encounter_types, ENCOUNTER_TYPES, rng)
    forced = kind is not None
    kind = kind or drawn_kind
    if kind == "multi":
        n_other = int(rng.integers(spec.multi_ships[0], spec.multi_ships[1] + 1)) - 1
        weights = {k: w for k, w in spec.encounter_types.items() if k != "multi"}
        if sum(weights.values()) <= 0.0:
            weights = dict.fromkeys(PAIR_TYPES, 1.0)
        pair_kinds = [_weighted(weights, PAIR_TYPES, rng) for _ in range(n_other)]
    else:
        pair_kinds = [kind]
    for _ in range(MAX_TRIES):  # the own ship again if she cannot meet every other ship
        drawn = _ships(spec, pair_kinds, types, ship, rng)
        if drawn is not None:
            break
    else:
        raise _no_geometry(spec, kind, pair_kinds, "" if forced else f"encounter {index}: ")
    setups, dcpas, tcpas = drawn
    _phase(setups, generator(spec.seed, index, 0, "phase"))
    env = EncounterEnv(from_kn(rng.uniform(*spec.current_kn)), rng.uniform(0.0, 2.0 * math.pi),
                       rng.uniform(*spec.wind_mps), rng.uniform(0.0, 2.0 * math.pi))
    return Encounter(index, kind, setups, env, pair_kinds, dcpas, tcpas)


def _phase(setups: list[ShipSetup], rng: np.random.Generator) -> None:
    """Each ship's first radar scan and first AIS report at a time of its own within one scan
    period and one reporting interval (at its start speed, on a straight course): the ships'
    radars turn and their transponders send unsynchronised, as at sea."""
    intervals = ais.reporting_interval_s(np.array([s.speed_mps for s in setups]),
                                         np.zeros(len(setups), dtype=bool))
    for s, interval in zip(setups, intervals.tolist(), strict=True):
        radar_u, ais_u = rng.random(), rng.random()
        sensors = s.sensors
        if "radar" in sensors and "scan_phase_s" not in sensors["radar"]:
            period = float(sensors["radar"].get("scan_period_s", radar.DEFAULT_SCAN_PERIOD_S))
            sensors["radar"]["scan_phase_s"] = radar_u * period
        if "ais" in sensors and "first_report_s" not in sensors["ais"]:
            sensors["ais"]["first_report_s"] = ais_u * interval


def _no_geometry(spec: CampaignSpec, kind: str, pair_kinds: list[str], what: str
                 ) -> NoGeometryError:
    """The error of a draw that found no start geometry, at ``encounter_types.KIND`` of the
    spec file (located here: it may be raised in a worker process)."""
    from trafficsim.io.yamlio import locate

    hint = ""
    if kind in ("overtaking", "overtaken"):
        hint = ("; the overtaking ship must be the faster: give speed_fraction a range, or "
                "ship types of different service speeds")
    err = NoGeometryError(
        f"{what}no geometry for {', '.join(pair_kinds)} in {MAX_TRIES} draws with these ship "
        f"types, speeds, DCPA and TCPA ranges"
        + (f" and min_start_range_nm {spec.min_start_range_nm:g}" if spec.min_start_range_nm
           else "") + hint,
        path=None if spec.path is None else str(spec.path), key=f"encounter_types.{kind}")
    locate(err)
    return err


def drawing_errors(spec: CampaignSpec) -> list[NoGeometryError]:
    """Draw one encounter of every type the spec weights, as the campaign draws them; the
    errors of the types that find no start geometry (a geometry so rare that a draw seldom
    finds it may fail here, and would fail in the campaign too)."""
    cache: dict[str, Any] = {}
    errors = []
    for kind in ENCOUNTER_TYPES:
        if spec.encounter_types.get(kind, 0.0) > 0.0:
            try:
                draw(spec, 0, cache, kind)
            except NoGeometryError as err:
                errors.append(err)
    return errors


def ship_errors(spec: CampaignSpec) -> list[InputError]:
    """The errors of the ships the spec's ``ship_types`` name, each loaded and its model family
    built as the campaign builds them (located in the ship file)."""
    from trafficsim.ships.base import families

    base_dir = spec.path.parent if spec.path is not None else None
    errors = []
    for type_ in spec.ship_types:
        try:
            ship = load_ship(type_, base_dir)
            families()[ship["model"]].build([ship])
        except InputError as err:
            errors.append(err)
    return errors


def spec_errors(spec: CampaignSpec) -> list[InputError]:
    """What a campaign of a schema-valid spec would stumble on once running: its ship files
    (:func:`ship_errors`), then encounter types no draw can place (:func:`drawing_errors`)."""
    return ship_errors(spec) or list(drawing_errors(spec))
