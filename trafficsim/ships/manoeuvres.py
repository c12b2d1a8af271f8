"""Standard manoeuvres (turning circle, zig-zag, crash stop), their indices and the IMO criteria.

Procedures follow the ITTC recommended procedure 7.5-04-02-01 (full-scale manoeuvring trials):
the ship approaches straight at steady speed, the manoeuvre is executed at t = 0 with the
propeller speed held, and indices are read off the track. Criteria are IMO MSC.137(76)
"Standards for ship manoeuvrability" (2002), paragraph 5.3.

Each function returns ``(track, indices)``: ``track`` is a dict of equal-length arrays in the
trial-data format (``t_s, north_m, east_m, heading_deg, rudder_deg, rpm, u_mps, v_mps, r_degps,
sog_kn, cog_deg``), ``indices`` a dict of floats (metres, seconds, degrees).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from trafficsim.errors import InputError, SimulationError
from trafficsim.ships import base
from trafficsim.ships.base import PSI, RPS, Actuators, Env, U
from trafficsim.units import from_kn, to_kn

Track = dict[str, np.ndarray]
#: time steps a manoeuvre accepts, s (below 1 ms the hours a manoeuvre may take are billions of
#: steps; above 60 s a step is longer than a large ship's turn takes to develop)
DT_RANGE_S = (1e-3, 60.0)
#: fastest approach a manoeuvre accepts, times the service speed (faster than the engine can
#: hold, the ship approaches at full power and slows; a fouled hull cannot hold its service
#: speed, say, and its trial is still wanted)
MAX_SPEED_FACTOR = 2.0
#: slowest approach, times the service speed (the models are made for speeds near it: the
#: ``nomoto`` family's yaw time constant stops scaling with speed below 10 % of it)
MIN_SPEED_FACTOR = 0.1
#: zig-zag heading changes accepted, deg (IMO MSC.137(76) asks for 10/10 and 20/20; below 1 deg
#: the rudder reverses within a time step, beyond 90 deg the manoeuvre is a turn, not a zig-zag)
ZIGZAG_HEADING_RANGE_DEG = (1.0, 90.0)


class _Ship:
    """One ship of any family stepped with open-loop commands (manoeuvres need no autopilot)."""

    def __init__(self, spec: Mapping[str, Any], speed_kn: float | None, env: Env) -> None:
        self.family = base.families()[spec["model"]]
        self.params = self.family.build([spec])
        self.act = Actuators.from_specs([spec])
        self.env = env
        self.length = float(spec["particulars"]["length_m"])
        self.name = str(spec.get("path") or spec["name"])
        speed = from_kn(speed_kn if speed_kn is not None else spec["service_speed_kn"])
        service = from_kn(spec["service_speed_kn"])
        if not speed >= MIN_SPEED_FACTOR * service:
            raise InputError(f"expected at least {MIN_SPEED_FACTOR:g} times the service speed "
                             f"of '{spec['name']}' ({spec['service_speed_kn']:g} kn), got "
                             f"{to_kn(speed):g} kn", key="speed_kn")
        if not speed <= MAX_SPEED_FACTOR * service:
            raise InputError(f"expected at most {MAX_SPEED_FACTOR:g} times the service speed "
                             f"of '{spec['name']}' ({spec['service_speed_kn']:g} kn), got "
                             f"{to_kn(speed):g} kn", key="speed_kn")
        self.rps0 = float(base.steady_rps_for_speed(self.family, self.params, self.act,
                                                    np.array([speed]))[0])
        rps_max = float(self.act.rps_max[0])
        if self._surge(speed, rps_max) < 0.0:  # full power slows her down
            raise InputError(f"expected a speed '{spec['name']}' can hold: at its largest "
                             f"propeller speed ({rps_max:g} rev/s) it makes "
                             f"{to_kn(self._top_speed(rps_max, speed)):.2f} kn, got "
                             f"{to_kn(speed):g} kn", key="speed_kn")
        self.max_dt = float(spec.get("integration", {}).get("max_dt_s", 1.0))
        self.x = np.zeros((base.N_STATE, 1))
        self.x[U] = speed
        self.x[RPS] = self.rps0
        self.speed0 = speed

    def _surge(self, speed: float, rps: float) -> float:
        """Straight-ahead surge acceleration at ``speed`` (m/s) and ``rps`` in calm water."""
        x = np.zeros((base.N_STATE, 1))
        x[U], x[RPS] = speed, rps
        return float(base.accelerations(self.family, self.params, x, Env())[0][0])

    def _top_speed(self, rps: float, above: float) -> float:
        """The steady straight speed at ``rps``, m/s, below ``above`` (which it cannot hold),
        by bisection on the surge balance."""
        low, high = 0.0, above
        for _ in range(60):
            mid = 0.5 * (low + high)
            low, high = (mid, high) if self._surge(mid, rps) > 0.0 else (low, mid)
        return low

    def check_rudder(self, rudder_deg: float) -> None:
        """Raise :class:`InputError` for a rudder angle beyond the steering gear's limit."""
        limit = float(np.degrees(self.act.rudder_max_rad[0]))
        if not abs(rudder_deg) <= limit + 1e-9:
            raise InputError(f"expected at most the ship's rudder limit, {limit:g} deg; got "
                             f"{abs(rudder_deg):g}", key="rudder_deg")

    def settle(self, seconds: float, dt: float) -> None:
        """Run straight with the approach rps until speed is steady."""
        for _ in range(int(seconds / dt)):
            self.advance(0.0, self.rps0, dt)
        self.check_finite("in the straight approach run")

    def check_finite(self, when: str) -> None:
        """Raise :class:`SimulationError` if the state is no longer finite (a ship model that
        runs away)."""
        if not np.isfinite(self.x).all():
            raise SimulationError(f"{self.name}: the ship's state became non-finite {when}; "
                                  "its model runs away (check the ship file's coefficients)")

    def advance(self, rudder_cmd_rad: float, rps_cmd: float, dt: float) -> None:
        sub = max(1, int(np.ceil(dt / self.max_dt - 1e-9)))
        self.x = base.step(self.family, self.params, self.act, self.x,
                           np.array([rudder_cmd_rad]), np.array([rps_cmd]), self.env, dt, sub)


def _record(ship: _Ship, t: float, rows: list[np.ndarray]) -> None:
    rows.append(np.concatenate(([t], ship.x[:, 0])))


def _track(rows: list[np.ndarray], env: Env) -> Track:
    a = np.array(rows)
    t, n, e, psi, u, v, r, rud, rps = a.T
    x = a[:, 1:].T
    ug, vg = base.ground_velocity_body(x, env)
    sog = np.hypot(ug, vg)
    cog = np.mod(psi + np.arctan2(vg, ug), 2 * np.pi)
    return {
        "t_s": t, "north_m": n, "east_m": e, "heading_deg": np.degrees(psi),
        "rudder_deg": np.degrees(rud), "rpm": rps * 60.0, "u_mps": u, "v_mps": v,
        "r_degps": np.degrees(r), "sog_kn": to_kn(sog), "cog_deg": np.degrees(cog),
    }


def _auto_dt(ship: _Ship, dt: float | None, turns: bool = True) -> float:
    """Time step: given (within :data:`DT_RANGE_S`, and at most L/U for a manoeuvre that
    ``turns``), else 1 s capped at L/(20 U) so small models turn smoothly."""
    if dt is not None:
        if not DT_RANGE_S[0] <= dt <= DT_RANGE_S[1]:
            raise InputError(f"expected a time step from {DT_RANGE_S[0]:g} to "
                             f"{DT_RANGE_S[1]:g} s, got {dt:g}", key="dt_s")
        most = ship.length / max(ship.speed0, 0.1)
        if turns and dt > most:
            raise InputError(f"expected at most L/U = {most:.3g} s for this ship (a longer step "
                             f"skips its manoeuvring motion), got {dt:g}", key="dt_s")
        return dt
    return float(min(1.0, 0.05 * ship.length / max(ship.speed0, 0.1)))


def _crossing(t: np.ndarray, y: np.ndarray, level: float) -> float:
    """First time ``y`` reaches ``level`` (linear interpolation), NaN if never."""
    idx = np.nonzero(y >= level)[0]
    if idx.size == 0 or idx[0] == 0:
        return float("nan")
    i = idx[0]
    return float(np.interp(level, [y[i - 1], y[i]], [t[i - 1], t[i]]))


def _run(ship: _Ship, dt: float, t_max: float,
         command: Callable[[float, float], tuple[float, float] | None]) -> Track:
    """Step from t = 0 with ``command(t, heading_change) -> (rudder, rps)`` until it gives None."""
    rows: list[np.ndarray] = []
    t, unwrapped, last = 0.0, 0.0, float(ship.x[PSI, 0])
    _record(ship, t, rows)
    while t < t_max:
        cmd = command(t, unwrapped)
        if cmd is None:
            break
        ship.advance(cmd[0], cmd[1], dt)
        t += dt
        ship.check_finite(f"at t = {t:g} s")
        psi = float(ship.x[PSI, 0])
        unwrapped += (psi - last + np.pi) % (2 * np.pi) - np.pi
        last = psi
        _record(ship, t, rows)
    return _track(rows, ship.env)


def _along_across(track: Track) -> tuple[np.ndarray, np.ndarray]:
    """Track in the approach frame: along the initial heading and to its starboard, metres."""
    psi0 = np.radians(track["heading_deg"][0])
    dn = track["north_m"] - track["north_m"][0]
    de = track["east_m"] - track["east_m"][0]
    along = dn * np.cos(psi0) + de * np.sin(psi0)
    across = -dn * np.sin(psi0) + de * np.cos(psi0)
    return along, across


def turning_circle(spec: Mapping[str, Any], rudder_deg: float = 35.0,
                   speed_kn: float | None = None, dt: float | None = None,
                   env: Env | None = None, turns_deg: float = 540.0
                   ) -> tuple[Track, dict[str, float]]:
    """Turning circle: rudder ``rudder_deg`` (positive = starboard) at t = 0, run ``turns_deg``.

    Indices (ITTC 7.5-04-02-01): advance and transfer at 90 deg heading change, tactical diameter
    (transfer at 180 deg), steady turning diameter (distance between the track points at 360 and
    540 deg change), speed loss ratio (steady speed / approach speed), times to 90 and 180 deg.
    """
    env = env or Env()
    ship = _Ship(spec, speed_kn, env)
    ship.check_rudder(rudder_deg)
    step = _auto_dt(ship, dt)
    ship.settle(60.0, step)
    rud = np.radians(rudder_deg)
    rps0 = ship.rps0
    t_max = 3600.0 * 6

    def command(t: float, change: float) -> tuple[float, float] | None:
        return None if abs(change) >= np.radians(turns_deg) else (rud, rps0)

    track = _run(ship, step, t_max, command)
    along, across = _along_across(track)
    side = np.sign(rudder_deg) or 1.0
    change = np.unwrap(np.radians(track["heading_deg"])) - np.radians(track["heading_deg"][0])
    change = np.degrees(change) * side
    t = track["t_s"]
    t90, t180 = _crossing(t, change, 90.0), _crossing(t, change, 180.0)
    t360, t540 = _crossing(t, change, 360.0), _crossing(t, change, 540.0)

    def at(tt: float, y: np.ndarray) -> float:
        return float(np.interp(tt, t, y)) if np.isfinite(tt) else float("nan")

    steady = float("nan")
    if np.isfinite(t360) and np.isfinite(t540):
        steady = float(np.hypot(at(t360, track["north_m"]) - at(t540, track["north_m"]),
                                at(t360, track["east_m"]) - at(t540, track["east_m"])))
    sog = from_kn(track["sog_kn"])
    indices = {
        "advance_m": at(t90, along),
        "transfer_m": abs(at(t90, across)),
        "tactical_diameter_m": abs(at(t180, across)),
        "steady_diameter_m": steady,
        "speed_loss_ratio": float(sog[-1] / sog[0]),
        "time_to_90_s": t90,
        "time_to_180_s": t180,
        "length_m": ship.length,
        "approach_speed_kn": float(to_kn(sog[0])),
        "rudder_deg": float(rudder_deg),
    }
    return track, indices


def zigzag(spec: Mapping[str, Any], rudder_deg: float = 10.0, heading_deg: float | None = None,
           speed_kn: float | None = None, dt: float | None = None, env: Env | None = None,
           reversals: int = 4) -> tuple[Track, dict[str, float]]:
    """Zig-zag ``rudder_deg``/``heading_deg`` (e.g. 10/10, 20/20), first rudder to starboard
    (a negative ``rudder_deg``: to port, the mirror image; the indices are then measured to
    port, so a symmetric ship gives the same ones; the sign of ``heading_deg`` is not used).

    Indices (ITTC 7.5-04-02-01): initial turning time (execute to first reversal), distance run
    by then in ship lengths (IMO initial turning ability), first and second overshoot angles.
    """
    env = env or Env()
    heading_deg = rudder_deg if heading_deg is None else heading_deg
    ship = _Ship(spec, speed_kn, env)
    ship.check_rudder(rudder_deg)
    if not abs(rudder_deg) > 0.0:
        raise InputError(f"expected an angle other than 0, got {rudder_deg:g}", key="rudder_deg")
    low, high = ZIGZAG_HEADING_RANGE_DEG
    if not low <= abs(heading_deg) <= high:
        raise InputError(f"expected a heading change from {low:g} to {high:g} deg, got "
                         f"{abs(heading_deg):g}", key="heading_deg")
    side = 1.0 if rudder_deg > 0.0 else -1.0  # first rudder to starboard (+1) or port
    heading_deg = abs(heading_deg)
    step = _auto_dt(ship, dt)
    ship.settle(60.0, step)
    rud, lim, rps0 = np.radians(abs(rudder_deg)), np.radians(heading_deg), ship.rps0
    state = {"sign": side, "reversals": 0, "t_rev": []}

    def command(t: float, change: float) -> tuple[float, float] | None:
        sgn = state["sign"]
        if sgn * change >= lim:
            state["sign"] = -sgn
            state["reversals"] += 1
            state["t_rev"].append(t)
        if state["reversals"] > reversals:
            return None
        return state["sign"] * rud, rps0

    track = _run(ship, step, 3600.0 * 3, command)
    t = track["t_s"]
    change = side * np.degrees(np.unwrap(np.radians(track["heading_deg"]))
                               - np.radians(track["heading_deg"][0]))  # towards the first side
    t_rev = state["t_rev"]
    first = second = float("nan")
    if len(t_rev) >= 2:
        seg = (t >= t_rev[0]) & (t <= t_rev[1])
        first = float(change[seg].max() - heading_deg)
    if len(t_rev) >= 3:
        seg = (t >= t_rev[1]) & (t <= t_rev[2])
        second = float(-change[seg].min() - heading_deg)
    t_init = _crossing(t, change, heading_deg)
    dist = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(track["north_m"]),
                                                     np.diff(track["east_m"])))))
    indices = {
        "initial_turning_time_s": t_init,
        "initial_turning_distance_L": float(np.interp(t_init, t, dist) / ship.length)
        if np.isfinite(t_init) else float("nan"),
        "first_overshoot_deg": first,
        "second_overshoot_deg": second,
        "length_m": ship.length,
        "approach_speed_kn": float(track["sog_kn"][0]),
        "rudder_deg": float(rudder_deg),
        "heading_deg": float(heading_deg),
    }
    return track, indices


def crash_stop(spec: Mapping[str, Any], speed_kn: float | None = None, dt: float | None = None,
               env: Env | None = None) -> tuple[Track, dict[str, float]]:
    """Crash stop ahead-to-astern: full astern (``rps_min``) at t = 0, rudder amidships.

    Indices: track reach (distance along the path until the ship is dead in the water), head reach
    (along the approach heading), lateral deviation and time to stop.
    """
    env = env or Env()
    ship = _Ship(spec, speed_kn, env)
    if not ship.family.supports_astern or ship.act.rps_min[0] >= 0.0:
        raise InputError(f"ship '{spec['name']}' ({spec['model']} model) cannot go astern: "
                         "a crash stop needs a model that supports astern thrust")
    step = _auto_dt(ship, dt, turns=False)
    ship.settle(60.0, step)
    astern = float(ship.act.rps_min[0])

    def command(t: float, change: float) -> tuple[float, float] | None:
        return None if (t > 5.0 and ship.x[U, 0] <= 0.0) else (0.0, astern)

    track = _run(ship, step, 3600.0 * 2, command)
    along, across = _along_across(track)
    dist = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(track["north_m"]),
                                                     np.diff(track["east_m"])))))
    indices = {
        "track_reach_m": float(dist[-1]),
        "head_reach_m": float(along[-1]),
        "lateral_deviation_m": float(abs(across[-1])),
        "time_to_stop_s": float(track["t_s"][-1]),
        "length_m": ship.length,
        "approach_speed_kn": float(track["sog_kn"][0]),
    }
    return track, indices


def imo_criteria(kind: str, indices: Mapping[str, float]) -> dict[str, dict[str, Any]]:
    """IMO MSC.137(76) para 5.3 criteria for a manoeuvre's indices.

    Returns ``{criterion: {"value": v, "limit": lim, "pass": bool}}`` with lengths in ship
    lengths, angles in degrees. The overshoot limits depend on L/V (seconds), V the approach
    speed in m/s.
    """
    L = indices["length_m"]
    out: dict[str, dict[str, Any]] = {}

    def add(name: str, value: float, limit: float) -> None:
        out[name] = {"value": value, "limit": limit, "pass": bool(value <= limit)}

    if kind == "turning":
        add("advance_L", indices["advance_m"] / L, 4.5)
        add("tactical_diameter_L", indices["tactical_diameter_m"] / L, 5.0)
    elif kind == "zigzag":
        l_over_v = L / from_kn(indices["approach_speed_kn"])
        rud, head = abs(indices["rudder_deg"]), indices["heading_deg"]  # either side first
        if rud == 10 and head == 10:
            add("initial_turning_distance_L", indices["initial_turning_distance_L"], 2.5)
            add("first_overshoot_deg", indices["first_overshoot_deg"],
                float(np.clip(5.0 + 0.5 * l_over_v, 10.0, 20.0)))
            add("second_overshoot_deg", indices["second_overshoot_deg"],
                float(np.clip(17.5 + 0.75 * l_over_v, 25.0, 40.0)))
        elif rud == 20 and head == 20:
            add("first_overshoot_deg", indices["first_overshoot_deg"], 25.0)
    elif kind == "crash-stop":
        add("track_reach_L", indices["track_reach_m"] / L, 15.0)
    return out


