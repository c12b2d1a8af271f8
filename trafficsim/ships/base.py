"""Common state layout, actuator dynamics and integrator shared by every model family.

State of ``n`` ships is one C-ordered array ``x`` of shape ``(N_STATE, n)``: each row is one
quantity for all ships (struct-of-arrays in one allocation, rows are contiguous views).

Rows (SI, radians):

=========  ==========================================================================
``NORTH``  north position of the reference point (midship), m, earth frame (NED)
``EAST``   east position, m
``PSI``    heading, rad, 0 = north, clockwise positive
``U``      surge velocity relative to the water, m/s, body x forward
``V``      sway velocity relative to the water, m/s, body y starboard
``R``      yaw rate, rad/s, positive = turning to starboard
``RUDDER`` actual rudder angle, rad, positive = helm that turns the ship to starboard
``RPS``    actual propeller speed, rev/s (negative = astern)
=========  ==========================================================================

Velocities are relative to the water, so a uniform steady current enters only the kinematics
(earth-frame velocity = body velocity rotated by heading + current): for an irrotational uniform
current this is exact (the relative-velocity formulation of Fossen 2011, ch. 10.3).

Steering gear and engine are first-order lags [seed 002, eqs 4.7-4.8]; the steering gear also has
a rate limit (IMO SOLAS II-1 reg. 29: 35 deg to 30 deg in 28 s gives about 2.3 deg/s).

A model family supplies only the hydrodynamics: a compiled scalar kernel
``accel(p, x, env) -> (du, dv, dr)``; :mod:`trafficsim.ships.kernels` integrates all ships of a
batch in one fused loop.
"""

from __future__ import annotations

import operator
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, Protocol

import numpy as np

from trafficsim.errors import ShipLibraryError
from trafficsim.jit import kernel

N_STATE = 8
NORTH, EAST, PSI, U, V, R, RUDDER, RPS = range(N_STATE)
STATE_NAMES = ("north_m", "east_m", "psi_rad", "u_mps", "v_mps", "r_radps", "rudder_rad", "rps")

RHO_WATER = 1025.0  # kg/m3, sea water
RHO_AIR = 1.225  # kg/m3


@dataclass(frozen=True)
class Env:
    """Environment seen by each ship, arrays of shape ``(n,)`` or scalars.

    Attributes:
        current_north_mps, current_east_mps: water velocity over ground, m/s (towards).
        wind_speed_mps: true wind speed, m/s.
        wind_from_rad: direction the true wind blows from, rad, 0 = from north.
    """

    current_north_mps: Any = 0.0
    current_east_mps: Any = 0.0
    wind_speed_mps: Any = 0.0
    wind_from_rad: Any = 0.0


def ground_velocity_body(x: np.ndarray, env: Env) -> tuple[np.ndarray, np.ndarray]:
    """Velocity over ground in the body frame, m/s: water-relative velocity plus current."""
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    ug = x[U] + env.current_north_mps * c + env.current_east_mps * s
    vg = x[V] - env.current_north_mps * s + env.current_east_mps * c
    return ug, vg


def apparent_wind(x: np.ndarray, env: Env) -> tuple[np.ndarray, np.ndarray]:
    """Apparent wind speed (m/s) and angle of attack (rad) in the body frame.

    The angle is the direction the apparent wind comes from, relative to the bow,
    0 = head wind, positive = from starboard (Fossen 2011, eq. 8.22 convention).
    """
    ug, vg = ground_velocity_body(x, env)
    # true wind velocity (towards) in earth frame, then body frame
    wn = -env.wind_speed_mps * np.cos(env.wind_from_rad)
    we = -env.wind_speed_mps * np.sin(env.wind_from_rad)
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    uw = wn * c + we * s
    vw = -wn * s + we * c
    ura, vra = ug - uw, vg - vw  # air velocity relative to the ship, seen from the ship
    return np.hypot(ura, vra), np.arctan2(vra, ura)


_COMPARE = {">": operator.gt, ">=": operator.ge, "<": operator.lt, "<=": operator.le}


@dataclass(frozen=True)
class Limit:
    """Valid range of one ship-file number (bounds given are enforced; None: unbounded).

    Attributes:
        gt, ge, lt, le: exclusive and inclusive bounds.
        whole: the value must be a whole number.
        one_of: the value must be one of these.
        what: what the number is, for the message.
    """

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    whole: bool = False
    one_of: tuple[float, ...] = ()
    what: str = ""

    def problem(self, value: float) -> str | None:
        """What is wrong with ``value`` (``must be ..., got ...``), or None."""
        if self.one_of:
            ok = value in self.one_of
            want = f"one of {', '.join(f'{v:g}' for v in self.one_of)}"
        else:
            bounds = [(op, b) for op, b in ((">", self.gt), (">=", self.ge), ("<", self.lt),
                                            ("<=", self.le)) if b is not None]
            ok = all(_COMPARE[op](value, b) for op, b in bounds)
            ok = ok and (not self.whole or float(value).is_integer())
            want = " and ".join(f"{op} {b:g}" for op, b in bounds)
            if self.whole:
                want = f"a whole number {want}".rstrip()
        if ok:
            return None
        why = f" ({self.what})" if self.what else ""
        return f"must be {want}{why}, got {value:g}"


#: particulars any ship file may give, whatever its family (unused ones are checked too)
PARTICULAR_LIMITS: Mapping[str, Limit] = {
    "displacement_m3": Limit(gt=0, what="volume of displacement"),
    "propeller_diameter_m": Limit(gt=0, what="propeller diameter"),
    "propeller_pitch_ratio": Limit(gt=0, what="propeller pitch / diameter"),
    "rudder_area_m2": Limit(gt=0, what="rudder area"),
    "rudder_height_m": Limit(gt=0, what="rudder span"),
    "water_density_kgpm3": Limit(gt=0, what="water density"),
    "length_overall_m": Limit(gt=0, what="length overall"),
    "windage_frontal_area_m2": Limit(ge=0, what="frontal windage area"),
    "windage_lateral_area_m2": Limit(ge=0, what="lateral windage area"),
    "windage_superstructure_area_m2": Limit(ge=0, what="lateral area of the superstructure"),
    "windage_perimeter_m": Limit(gt=0, what="perimeter of the lateral windage"),
    "windage_centroid_from_bow_m": Limit(ge=0, what="distance of the windage centroid from "
                                                    "the bow"),
    "windage_mast_groups": Limit(ge=0, whole=True, what="number of mast groups"),
    "mass_kg": Limit(gt=0, what="mass"),
    "yaw_inertia_kgm2": Limit(gt=0, what="yaw moment of inertia"),
    "gear_ratio": Limit(gt=0, what="engine / propeller speed ratio"),
    "block_coefficient": Limit(gt=0, le=1, what="block coefficient"),
    "hull_separation_m": Limit(gt=0, what="distance between the hulls of a catamaran"),
}
#: every key a ship file's particulars may hold (``lcg_m`` within half the length of midship)
KNOWN_PARTICULARS = ("length_m", "beam_m", "draught_m", "lcg_m", *PARTICULAR_LIMITS)
#: limits shared by the families' coefficients of the same meaning
ADDED_MASS = Limit(ge=0, what="added mass, non-dimensional")
GYRADIUS = Limit(gt=0, lt=1, what="yaw radius of gyration / length")
THRUST_DEDUCTION = Limit(lt=1, what="thrust deduction fraction")
WAKE_FRACTION = Limit(lt=1, what="wake fraction; 1 - w_P0 scales the propeller inflow")
RUDDER_DRAG_DEDUCTION = Limit(lt=1, what="rudder drag deduction fraction")
BOLLARD_THRUST = Limit(gt=0, what="open-water thrust coefficient at J = 0")
FLOW_STRAIGHTENING = Limit(ge=0, what="flow-straightening coefficient")
WAKE_RATIO = Limit(gt=0, what="ratio of the rudder and propeller wakes")
LIFT_GRADIENT = Limit(gt=0, what="rudder lift gradient coefficient")


def limit_problems(family: ModelFamily, ship: Mapping[str, Any]) -> list[tuple[str, str]]:
    """Out-of-range numbers of a ship spec: ``(dotted key, message)`` pairs, in file order of
    sections (particulars, then coefficients, then the family's cross-checks)."""
    out = []
    for section, limits in (("particulars", PARTICULAR_LIMITS),
                            ("coefficients", family.limits)):
        values = ship.get(section, {})
        for key, value in values.items():
            limit = limits.get(key)
            problem = limit.problem(float(value)) if limit is not None else None
            if problem:
                out.append((f"{section}.{key}", problem))
    parts = ship.get("particulars", {})
    if "lcg_m" in parts and abs(float(parts["lcg_m"])) > 0.5 * float(parts["length_m"]):
        out.append(("particulars.lcg_m", f"must lie within half the length of midship "
                    f"(|lcg_m| <= {0.5 * float(parts['length_m']):g} m), got "
                    f"{float(parts['lcg_m']):g}"))
    if "windage_centroid_from_bow_m" in parts:
        loa = float(parts.get("length_overall_m", parts["length_m"]))
        if float(parts["windage_centroid_from_bow_m"]) > loa:
            out.append(("particulars.windage_centroid_from_bow_m",
                        f"must be <= the length overall ({loa:g} m), got "
                        f"{float(parts['windage_centroid_from_bow_m']):g}"))
    if "windage_superstructure_area_m2" in parts and "windage_lateral_area_m2" in parts:
        a_ss, a_l = (float(parts[k]) for k in ("windage_superstructure_area_m2",
                                                "windage_lateral_area_m2"))
        if a_ss > a_l:
            out.append(("particulars.windage_superstructure_area_m2",
                        f"must be <= windage_lateral_area_m2 ({a_l:g} m2, of which it is a "
                        f"part), got {a_ss:g}"))
    if not out:
        out.extend(family.cross_problems(ship))
    return out


class ModelFamily(Protocol):
    """A manoeuvring-model family: hydrodynamics only.

    The family module also defines the compiled scalar kernel ``accel(p, x, env) -> (du, dv, dr)``
    (see :mod:`trafficsim.ships.kernels`), where ``p`` is one row of :func:`pack` of the
    parameter object returned by :meth:`build`.
    """

    name: str
    supports_astern: bool
    #: coefficient name -> default value (None = required); the ship-file loader checks
    #: ``coefficients:`` against it, reporting unknown and missing keys with their line.
    coefficients: Mapping[str, float | None]
    #: valid ranges of coefficients whose range is physically clear (see :class:`Limit`)
    limits: Mapping[str, Limit]

    def cross_problems(self, ship: Mapping[str, Any]) -> list[tuple[str, str]]:
        """Problems between numbers of one ship spec: ``(dotted key, message)`` pairs."""

    def build(self, ships: Sequence[Mapping[str, Any]]) -> Any:
        """Frozen dataclass of ``(n,)`` float arrays from ship-file dicts (``particulars``,
        ``coefficients``); its field order is the kernel's parameter-row layout."""


def pack(params: Any) -> np.ndarray:
    """Parameter table ``(n, k)``: the fields of a family's parameter dataclass, in order."""
    return np.ascontiguousarray(
        np.stack([np.asarray(getattr(params, f.name), dtype=float) for f in fields(params)],
                 axis=1))


def env_table(env: Env, n: int) -> np.ndarray:
    """Environment rows ``(4, n)``: current north, east (m/s), wind speed (m/s), from (rad)."""
    out = np.empty((4, n))
    for k, f in enumerate(fields(env)):
        out[k] = getattr(env, f.name)
    return out


@dataclass(frozen=True)
class Actuators:
    """Steering gear and engine limits and lags, ``(n,)`` arrays.

    Attributes:
        rudder_max_rad: largest rudder angle either side.
        rudder_rate_radps: steering-gear rate limit.
        rudder_tau_s: first-order steering lag T_R [seed 002, eq 4.7].
        rps_max, rps_min: propeller speed limits (rps_min < 0 allows astern).
        engine_tau_s: first-order engine lag T_N [seed 002, eq 4.8].
    """

    rudder_max_rad: np.ndarray
    rudder_rate_radps: np.ndarray
    rudder_tau_s: np.ndarray
    rps_max: np.ndarray
    rps_min: np.ndarray
    engine_tau_s: np.ndarray

    @classmethod
    def from_specs(cls, ships: Sequence[Mapping[str, Any]]) -> Actuators:
        a = [s["actuators"] for s in ships]
        return cls(
            rudder_max_rad=np.radians(stack(a, "rudder_max_deg")),
            rudder_rate_radps=np.radians(stack(a, "rudder_rate_degps")),
            rudder_tau_s=stack(a, "rudder_tau_s"),
            rps_max=stack(a, "rps_max"),
            rps_min=stack(a, "rps_min"),
            engine_tau_s=stack(a, "engine_tau_s"),
        )


@kernel
def gather_ship(X: np.ndarray, E: np.ndarray, i: int, x: np.ndarray, env: np.ndarray) -> None:
    """Copy ship ``i``'s state column of ``X (8, n)`` into ``x (8,)`` and its environment
    column of ``E (4, n)`` into ``env (4,)`` (compiled loops over ships start with this)."""
    for j in range(8):
        x[j] = X[j, i]
    for j in range(4):
        env[j] = E[j, i]


def coefficient(ship: Mapping[str, Any], key: str, default: float | None, model: str) -> float:
    """Coefficient ``key`` of a ship spec (``default`` where absent; None: required)."""
    value = ship.get("coefficients", {}).get(key, default)
    if value is None:
        raise ShipLibraryError(f"missing required coefficient '{key}' for model '{model}'",
                               path=ship.get("path"), key=f"coefficients.{key}")
    return float(value)


def particular(ship: Mapping[str, Any], key: str, defaults: Mapping[str, float | None],
               model: str) -> float:
    """Particular ``key`` of a ship spec (``defaults[key]`` where absent; None: required)."""
    parts = ship["particulars"]
    if key in parts:
        return float(parts[key])
    default = defaults.get(key)
    if default is None:
        raise ShipLibraryError(f"missing particular '{key}' required by model '{model}'",
                               path=ship.get("path"), key=f"particulars.{key}")
    return float(default)


def stack(dicts: Sequence[Mapping[str, Any]], key: str, default: float | None = None) -> np.ndarray:
    """Gather ``key`` from each dict into a float array ``(n,)``."""
    if default is None:
        return np.array([float(d[key]) for d in dicts], dtype=float)
    return np.array([float(d.get(key, default)) for d in dicts], dtype=float)


def accelerations(family: ModelFamily, params: Any, x: np.ndarray, env: Env
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Body-frame accelerations ``du, dv, dr`` (each ``(n,)``) of ships of one family."""
    from trafficsim.ships import kernels

    n = x.shape[1]
    codes = np.full(n, kernels.FAMILY_CODE[family.name], dtype=np.int64)
    out = kernels.accelerations(codes, pack(params), np.ascontiguousarray(x, dtype=float),
                                env_table(env, n))
    return out[0], out[1], out[2]


def step(family: ModelFamily, params: Any, act: Actuators, x: np.ndarray,
         rudder_cmd_rad: np.ndarray, rps_cmd: np.ndarray, env: Env, dt: float,
         substeps: int = 1) -> np.ndarray:
    """Advance ships of one family by ``dt`` seconds (RK4); returns the new ``(N_STATE, n)`` state.

    Commands are held constant over the step (zero-order hold). The batch engine calls the
    compiled kernel directly for all families at once; this is the one-family entry point.
    """
    from trafficsim.ships import kernels

    n = x.shape[1]
    xn = np.array(x, dtype=float, order="C")
    kernels.step_ships(np.full(n, kernels.FAMILY_CODE[family.name], dtype=np.int64),
                       pack(params), actuator_table(act),
                       xn, np.broadcast_to(np.asarray(rudder_cmd_rad, float), (n,)).copy(),
                       np.broadcast_to(np.asarray(rps_cmd, float), (n,)).copy(),
                       env_table(env, n), float(dt), np.full(n, substeps, dtype=np.int64))
    return xn


def actuator_table(act: Actuators) -> np.ndarray:
    """Actuator table ``(n, 6)`` in the column order of :mod:`trafficsim.ships.kernels`."""
    return pack(act)


def steady_rps_for_speed(family: ModelFamily, params: Any, act: Actuators,
                         speed_mps: np.ndarray, iters: int = 60) -> np.ndarray:
    """Propeller speed giving steady straight-ahead ``speed_mps`` in calm water, ``(n,)``.

    Bisection on the surge balance du(u, n) = 0 with v = r = rudder = 0, one compiled loop
    over ships. Speeds the engine cannot reach return ``rps_max``.
    """
    from trafficsim.ships import kernels

    speed = np.ascontiguousarray(speed_mps, dtype=float)
    n = speed.shape[0]
    table = pack(params)
    rps_max = np.ascontiguousarray(act.rps_max, dtype=float)
    if speed.ndim != 1 or table.shape[0] != n or rps_max.shape != (n,):
        # (the compiled loop does not check its indices)
        raise ValueError(f"one speed per ship: {table.shape[0]} ships' parameters, "
                         f"{rps_max.shape[0]} actuators and speeds of shape {speed.shape}")
    out = np.empty(n)
    kernels.steady_rps(np.full(n, kernels.FAMILY_CODE[family.name], dtype=np.int64),
                       table, speed, rps_max, env_table(Env(), n), int(iters), out)
    return out


_REGISTRY: dict[str, ModelFamily] = {}


def register(family: ModelFamily) -> ModelFamily:
    """Register a model family under ``family.name``."""
    _REGISTRY[family.name] = family
    return family


def families() -> dict[str, ModelFamily]:
    """All registered model families by name."""
    from trafficsim.ships import (  # noqa: F401  (registration)
        mmg,
        mmg_berthing,
        modular,
        nomoto,
        response,
    )

    return dict(_REGISTRY)

