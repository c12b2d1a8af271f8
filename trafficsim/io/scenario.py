"""Scenario files: the schema and :func:`load_scenario`.

A scenario places one or more ships in an environment for a fixed duration::

    schema_version: 1              # required, must be 1
    name: head_on                  # required, non-empty
    description: "..."             # optional
    duration_s: 1800               # > 0, <= 30 days, a whole number of steps of dt_s
    dt_s: 1.0                      # optional, default 1.0; 0 < dt <= 60; dt <= duration
    seed: 1                        # optional int >= 0, default 0
    record_every_s: 5.0            # optional positive multiple of dt_s, <= duration_s
                                   #   (default: 1 s, rounded up to a whole number of steps;
                                   #   a period up to the default is fine in a shorter run)
    environment:                   # optional
      current: {speed_kn: 0.5, towards_deg: 90}   # 0 <= speed <= 10 kn, direction [0, 360)
      wind: {speed_mps: 10, from_deg: 45}          # 0 <= speed <= 60 m/s, direction [0, 360)
    ships:                         # required, at least one
      - name: own                  # required, unique within the scenario
        type: kvlcc2               # library name or path to a ship file (relative to this file)
        north_m: 0                 # required, within 1,000 km of the origin (flat local frame)
        east_m: 0                  # required, likewise (route points too)
        heading_deg: 0             # required, [0, 360)
        speed_kn: 12               # optional (default: the ship's service speed), [0, 60]
                                   #   and at most twice the service speed
        route: [[5000, 0], [9000, 3000]]   # optional [north_m, east_m] waypoints, none twice
                                   #   in a row; a lone point not at the start position
        behaviour: colregs         # optional: colregs (default), keep_course, turn_port,
                                   #   late_action (see trafficsim.colregs.decider)
        effects:                   # optional sim-to-real effects (trafficsim.effects), e.g.
          current: {north_mps: 0.3, east_mps: 0.0}
          steering_lag: {tau_s: 5, rate_degps: 2}
    rules: ../rules/colregs.yaml   # optional decision network (relative to this file);
                                   #   default: the bundled rules/colregs.yaml
    domain: coldwell               # optional ship domain: coldwell, goodwin, fujii, kijima
    visibility_nm: 10              # optional, default 10; below the rules' threshold the
                                   #   restricted-visibility mode (Rule 19) applies
    decision_period_s: 10          # optional, a whole multiple of dt_s, <= duration_s; default
                                   #   10 s rounded to a whole number of steps (dt_s 3: 9 s)

Ships whose hulls overlap at the start are refused, and so is what a run would refuse of a ship
with its ship file (:func:`_ship_errors`).

Values keep the file's units (knots, degrees); conversion to SI happens when the batch is built.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field, PrivateAttr, ValidationInfo, field_validator
from pydantic_core import PydanticCustomError

from trafficsim.errors import InputError, ScenarioError, ShipLibraryError
from trafficsim.io.yamlio import (
    Document,
    FieldError,
    Integer,
    Number,
    Strict,
    Text,
    collect_errors,
    load_yaml,
    raise_errors,
)

__all__ = [
    "MAX_DURATION_S",
    "SCHEMA_VERSION",
    "Current",
    "Environment",
    "Scenario",
    "ShipEntry",
    "Wind",
    "known_schema_version",
    "load_scenario",
]

SCHEMA_VERSION = 1
"""The scenario schema version this code reads."""

MAX_DURATION_S = 30 * 86400.0
"""Longest scenario accepted: 30 days, in seconds."""

DEFAULT_DECISION_PERIOD_S = 10.0
MAX_DT_S = 60.0
"""Longest time step accepted, in seconds."""

_MULTIPLE_TOL = 1e-9


def known_schema_version(version: int) -> int:
    """``version`` if this code reads it (scenario and campaign files share the version)."""
    if version != SCHEMA_VERSION:
        raise ValueError(f"unsupported schema_version {version}; this version of trafficsim "
                         f"reads schema_version {SCHEMA_VERSION}")
    return version

Direction = Annotated[Number, Field(ge=0.0, lt=360.0)]
"""A compass direction in degrees, clockwise from north, in [0, 360)."""

MAX_OFFSET_M = 1.0e6
"""Farthest position from the origin, each way: the earth frame is a flat local tangent plane
(north-east-down), a fair model of the earth over hundreds of kilometres, not thousands."""

Coordinate = Annotated[Number, Field(ge=-MAX_OFFSET_M, le=MAX_OFFSET_M)]
"""A north or east position in metres of the local frame."""


def _route_point(value: Any) -> Any:
    # A wrong count gets its own message: pydantic would say "Tuple should have at most 2 items".
    if isinstance(value, list | tuple) and len(value) != 2:
        raise PydanticCustomError(
            "route_point",
            "a route point is [north_m, east_m]: expected exactly 2 numbers, got {count}",
            {"count": len(value)})
    return value


RoutePoint = Annotated[tuple[Coordinate, Coordinate], BeforeValidator(_route_point)]
"""A waypoint ``(north_m, east_m)`` in metres."""


def _at_least_one_ship(value: Any) -> Any:
    # Checked before the items: pydantic's min_length counts only the items that validated.
    if isinstance(value, list | tuple) and not value:
        raise ValueError("expected at least one ship, got an empty list")
    return value


class Current(Strict):
    """Uniform surface current: ``speed_kn`` knots flowing towards ``towards_deg``."""

    speed_kn: Annotated[Number, Field(ge=0.0, le=10.0)]
    towards_deg: Direction


class Wind(Strict):
    """Uniform true wind: ``speed_mps`` m/s blowing from ``from_deg``."""

    speed_mps: Annotated[Number, Field(ge=0.0, le=60.0)]
    from_deg: Direction


class Environment(Strict):
    """Current and wind; either may be omitted (None = none)."""

    current: Current | None = None
    wind: Wind | None = None


class ShipEntry(Strict):
    """One ship of a scenario, in the file's units.

    ``speed_kn`` None means the ship's service speed. ``ship_file`` (the resolved ship file)
    is set by :func:`load_scenario`.
    """

    name: Text
    type: Text
    north_m: Coordinate
    east_m: Coordinate
    heading_deg: Direction
    speed_kn: Annotated[Number, Field(ge=0.0, le=60.0)] | None = None
    route: tuple[RoutePoint, ...] = ()
    sensors: dict[str, dict[str, Any]] | None = None
    filter: Literal["none", "pv", "ekf"] = "none"
    behaviour: Literal["colregs", "keep_course", "turn_port", "late_action"] = "colregs"
    effects: dict[str, Any] | None = None

    @field_validator("effects")
    @classmethod
    def _valid_effects(cls, effects: dict[str, Any] | None) -> dict[str, dict[str, float]] | None:
        if effects is None:
            return None
        from trafficsim import effects as registry

        try:
            return registry.check(effects)
        except InputError as err:
            loc = tuple((err.key or "").split(".")[1:])
            raise FieldError(err.message, loc=loc) from None

    @field_validator("route")
    @classmethod
    def _legs_have_length(cls, route: tuple[tuple[float, float], ...], info: ValidationInfo
                          ) -> tuple[tuple[float, float], ...]:
        for k in range(1, len(route)):
            if route[k] == route[k - 1]:
                raise FieldError(f"repeats route[{k - 1}] {list(route[k])}: a leg of no length "
                                 "has no course; give each point once", loc=(k,))
        start = (info.data.get("north_m"), info.data.get("east_m"))
        if len(route) == 1 and route[0] == start:
            raise FieldError(f"the only route point {list(route[0])} is the ship's start "
                             "position: there is no leg to follow (leave out route: to hold "
                             "the initial course)", loc=(0,))
        return route

    @field_validator("sensors")
    @classmethod
    def _valid_sensors(cls, sensors: dict[str, dict[str, Any]] | None
                       ) -> dict[str, dict[str, Any]] | None:
        if sensors is not None:
            validate_sensors(sensors)
        return sensors

    _ship_file: Path | None = PrivateAttr(default=None)

    @property
    def ship_file(self) -> Path | None:
        """Absolute path of the ship file that ``type`` names (None if not resolved)."""
        return self._ship_file


class Scenario(Strict):
    """A validated scenario file. See the module docstring for the format.

    After :func:`load_scenario`, ``path`` is the absolute path of the file and every
    ``ships[i].ship_file`` the resolved ship file.
    """

    schema_version: Integer
    name: Text
    description: str = ""
    duration_s: Annotated[Number, Field(gt=0.0, le=MAX_DURATION_S)]
    dt_s: Annotated[Number, Field(gt=0.0, le=MAX_DT_S, validate_default=True)] = 1.0
    # None (absent or empty) becomes the default in _default_recording, so it is always a float.
    record_every_s: Annotated[Number, Field(gt=0.0)] = Field(default=None, validate_default=True)
    seed: Annotated[Integer, Field(ge=0)] = 0
    environment: Environment = Field(default_factory=Environment)
    rules: Text | None = None
    domain: Literal["coldwell", "goodwin", "fujii", "kijima"] = "coldwell"
    visibility_nm: Annotated[Number, Field(gt=0.0, le=100.0)] = 10.0
    # None (absent or empty) becomes the default in _default_decision_period
    decision_period_s: Annotated[Number, Field(gt=0.0, le=600.0)] = Field(
        default=None, validate_default=True)
    ships: Annotated[tuple[ShipEntry, ...], BeforeValidator(_at_least_one_ship)]

    _path: Path | None = PrivateAttr(default=None)

    @property
    def path(self) -> Path | None:
        """Absolute path of the scenario file (None if not loaded from a file)."""
        return self._path

    @property
    def ship_files(self) -> tuple[Path | None, ...]:
        """Resolved ship file of every ship, in order."""
        return tuple(ship.ship_file for ship in self.ships)

    @field_validator("schema_version")
    @classmethod
    def _known_version(cls, version: int) -> int:
        return known_schema_version(version)

    @field_validator("dt_s")
    @classmethod
    def _dt_divides_duration(cls, dt: float, info: ValidationInfo) -> float:
        duration = info.data.get("duration_s")
        if duration is not None and dt > duration:
            raise ValueError(f"must not exceed duration_s ({duration:g} s), got {dt:g}")
        steps = None if duration is None else duration / dt
        if steps is not None and abs(steps - round(steps)) > 1e-6:  # (rounding: 1e-7 at 1e9)
            raise ValueError(f"duration_s ({duration:g} s) must be a whole multiple of dt_s "
                             f"({dt:g} s; 1 s when not given)")
        return dt

    @field_validator("record_every_s", mode="before")
    @classmethod
    def _default_recording(cls, every: Any, info: ValidationInfo) -> Any:
        # Default: 1 s rounded up to a whole number of steps (a 2 s step records every 2 s).
        if every is not None:
            return every
        dt = info.data.get("dt_s")
        return 1.0 if dt is None else max(1, math.ceil(1.0 / dt - _MULTIPLE_TOL)) * dt

    @field_validator("record_every_s")
    @classmethod
    def _whole_steps(cls, every: float, info: ValidationInfo) -> float:
        dt = info.data.get("dt_s")
        if dt is None:  # dt_s itself is invalid and already reported
            return every
        ratio = every / dt
        steps = round(ratio)
        if steps < 1 or abs(ratio - steps) > _MULTIPLE_TOL:
            nearest = max(1, steps) * dt
            raise ValueError(f"must be a whole multiple of dt_s ({dt:g} s), got {every:g}; "
                             f"e.g. {nearest:g}")
        _within_duration(every, info, max(1, math.ceil(1.0 / dt - _MULTIPLE_TOL)) * dt,
                         "only the start would be recorded")
        return every

    @field_validator("decision_period_s", mode="before")
    @classmethod
    def _default_decision_period(cls, period: Any, info: ValidationInfo) -> Any:
        return default_decision_period(period, info.data.get("dt_s"))

    @field_validator("decision_period_s")
    @classmethod
    def _decision_whole_steps(cls, period: float, info: ValidationInfo) -> float:
        dt = info.data.get("dt_s")
        if dt is not None:
            ratio = period / dt
            if round(ratio) < 1 or abs(ratio - round(ratio)) > _MULTIPLE_TOL:
                raise ValueError(f"must be a whole multiple of dt_s ({dt:g} s), got {period:g}")
        _within_duration(period, info, default_decision_period(None, dt),
                         "the ships would decide once, at the start")
        return period

    @field_validator("environment", mode="before")
    @classmethod
    def _empty_environment(cls, value: Any) -> Any:
        # "environment:" with everything below commented out means no environment.
        return {} if value is None else value

    @field_validator("ships")
    @classmethod
    def _unique_names(cls, ships: tuple[ShipEntry, ...]) -> tuple[ShipEntry, ...]:
        first: dict[str, int] = {}
        for index, ship in enumerate(ships):
            if ship.name in first:
                raise FieldError(f"duplicate ship name '{ship.name}' (already used by "
                                 f"ships[{first[ship.name]}]); names must be unique",
                                 loc=(index, "name"))
            first[ship.name] = index
        return ships


def _within_duration(period: float, info: ValidationInfo, default: float,
                     otherwise: str) -> None:
    """A period of the run (recording, deciding) must not exceed ``duration_s``, or its
    ``default`` when that is longer (a run shorter than the default period is fine)."""
    duration = info.data.get("duration_s")
    if duration is not None and period > max(duration, default) * (1.0 + _MULTIPLE_TOL):
        raise ValueError(f"must not exceed duration_s ({duration:g} s), got {period:g} "
                         f"({otherwise})")


def validate_sensors(sensors: dict[str, dict[str, Any]],
                     particulars: Mapping[str, float] | None = None) -> None:
    """Check a ``sensors:`` mapping by building its instruments (and, with the ship's
    ``particulars``, that its antennas and levers lie on board); errors point at the key."""
    from trafficsim.navigation import check_on_board, check_sensor_config

    try:
        check_sensor_config(sensors)
        if particulars is not None:
            check_on_board(sensors, {"particulars": particulars})
    except InputError as err:
        # sensors' own keys read "<sensor>[0].<setting>" (ship 0 of a batch of one) or
        # "<sensor>.<setting>": point at the deepest part of that path the file holds
        loc: list[str] = []
        node: Any = sensors
        for part in re.split(r"\[\d+\]|\.", err.key or ""):
            if not part:
                continue
            if not isinstance(node, dict) or part not in node:
                break
            loc.append(part)
            node = node[part]
        raise FieldError(err.message, loc=tuple(loc)) from None


def _find_ship_files(doc: Document, base_dir: Path
                     ) -> tuple[dict[int, Path], list[ScenarioError]]:
    """Resolve every ship's ``type`` in the raw data, so lookups are reported with the
    schema errors; ships whose ``type`` is not text are left to the schema."""
    from trafficsim.ships import library  # the library imports ship families: load lazily

    found: dict[int, Path] = {}
    errors: list[ScenarioError] = []
    ships = doc.data.get("ships")
    if not isinstance(ships, list):
        return found, errors
    for index, ship in enumerate(ships):
        kind = ship.get("type") if isinstance(ship, dict) else None
        if not isinstance(kind, str) or not kind.strip():
            continue
        try:
            found[index] = Path(library.find_ship(kind, base_dir))
        except ShipLibraryError as exc:
            message = exc.message if exc.path is None else str(exc)
            errors.append(doc.error(message, ("ships", index, "type")))
    return found, errors


def default_decision_period(period: Any, dt: float | None) -> Any:
    """``period`` as given; absent (None), the default 10 s rounded to a whole number of steps
    of ``dt`` (at least one)."""
    if period is not None:
        return period
    return DEFAULT_DECISION_PERIOD_S if dt is None else max(
        1, round(DEFAULT_DECISION_PERIOD_S / dt)) * dt


def rules_file_errors(doc: Document, base_dir: Path) -> list[ScenarioError]:
    """The ``rules:`` file of a scenario or campaign spec must exist (relative to the file),
    so that a wrong name is reported at its line before anything runs."""
    rules = doc.data.get("rules")
    if not isinstance(rules, str) or not rules.strip() or (base_dir / rules).is_file():
        return []
    return [doc.error(f"rules file not found: {base_dir / rules}", ("rules",))]


#: instrument settings the measurement effects add to, and the effect parameter that does
_EFFECT_OF_SETTING = {("gnss", "antenna_x_m"): ("lever_arm", "x_m"),
                      ("gnss", "antenna_y_m"): ("lever_arm", "y_m"),
                      ("compass", "bias_deg"): ("compass_bias", "bias_deg"),
                      ("compass", "deviation_deg"): ("compass_bias", "deviation_b_deg"),
                      ("ais", "latency_s"): ("ais_latency", "latency_s"),
                      ("navigation", "pv_sp_m2ps3"): ("gnss_lag", "tau_s")}


def _key_parts(key: str | None) -> list[str]:
    """``"ais[0].latency_s"`` -> ``["ais", "latency_s"]``."""
    return [p for p in re.split(r"\[\d+\]|\.", key or "") if p]


def _setting_error(doc: Document, index: int, ship: ShipEntry, err: InputError,
                   sensors: dict[str, dict[str, Any]]) -> ScenarioError:
    """An instrument error of a ship's configuration with its effects applied, located at the
    effect that set the value, or else at the ship's ``sensors`` (the deepest key it holds)."""
    from trafficsim.sensors.ais import MAX_LATENCY_S

    parts = _key_parts(err.key)
    found = _EFFECT_OF_SETTING.get(tuple(parts[:2]))
    if found is not None and found[0] in (ship.effects or {}):
        name, param = found
        loc = ("ships", index, "effects", name, param)
        value = ship.effects[name][param]  # type: ignore[index]
        if found == ("ais_latency", "latency_s"):
            own = float(sensors.get("ais", {}).get("latency_s", 2.0))
            return doc.error(f"expected 0 to {MAX_LATENCY_S - own:g} s (the ship's AIS latency "
                             f"{own:g} s plus this must be <= {MAX_LATENCY_S:g} s), got "
                             f"{value:g}", loc)
        return doc.error(f"{err.message} (the ship's {'.'.join(parts)} with this effect of "
                         f"{value:g})", loc)
    loc_parts: list[str] = []
    node: Any = ship.sensors or {}
    for part in parts:
        if not isinstance(node, dict) or part not in node:
            break
        loc_parts.append(part)
        node = node[part]
    where = ".".join(parts)
    message = err.message if where == ".".join(loc_parts) else f"{where}: {err.message}"
    return doc.error(message, ("ships", index, "sensors", *loc_parts))


def _ship_errors(doc: Document, scenario: Scenario, ship_files: dict[int, Path]
                 ) -> list[ScenarioError]:
    """What a run would refuse in the ships together with their ship files: a speed beyond
    twice the service speed, effects the ship's model has no terms for or that carry an
    instrument beyond its range, instruments the ship's filter cannot use, and ships whose
    hulls overlap at the start."""
    import numpy as np

    from trafficsim import effects as registry
    from trafficsim.geometry import hull_outlines, hulls_overlap
    from trafficsim.navigation import check_sensor_config, merge_sensors
    from trafficsim.ships.library import load_ship
    from trafficsim.ships.manoeuvres import MAX_SPEED_FACTOR

    errors: list[ScenarioError] = []
    hulls: dict[int, tuple[float, float]] = {}
    for index, ship in enumerate(scenario.ships):
        try:
            spec = load_ship(str(ship_files[index]))
        except InputError:  # (reported with the ship file)
            continue
        p = spec["particulars"]
        hulls[index] = float(p["length_m"]), float(p["beam_m"])
        service = float(spec["service_speed_kn"])
        if ship.speed_kn is not None and ship.speed_kn > MAX_SPEED_FACTOR * service:
            errors.append(doc.error(
                f"expected at most {MAX_SPEED_FACTOR:g} times the service speed of "
                f"'{spec['name']}' ({service:g} kn), got {ship.speed_kn:g} kn",
                ("ships", index, "speed_kn")))
        found = ship.effects or {}
        offset = found.get("propeller_asymmetry", {}).get("rudder_offset_deg", 0.0)
        most = float(spec["actuators"]["rudder_max_deg"])
        if abs(offset) >= most:
            errors.append(doc.error(
                f"expected a neutral rudder angle within the steering gear's +-{most:g} deg, "
                f"got {offset:g}",
                ("ships", index, "effects", "propeller_asymmetry", "rudder_offset_deg")))
            continue
        sensors = merge_sensors(spec.get("sensors"), ship.sensors)
        try:
            if sensors or ship.filter != "none":
                check_sensor_config(sensors, ship.filter, spec)
        except InputError as err:
            errors.append(_setting_error(doc, index, ship, err, {}))
            continue
        try:
            registry.apply_spec(spec, found)
            applied = registry.apply_sensors(sensors, found, scenario.dt_s)
        except InputError as err:
            errors.append(doc.error(err.message, ("ships", index, *_key_parts(err.key))))
            continue
        if found:
            try:
                check_sensor_config(applied, ship.filter, spec)
            except InputError as err:
                errors.append(_setting_error(doc, index, ship, err, sensors))
    done = sorted(hulls)
    if len(done) > 1:
        ships = [scenario.ships[k] for k in done]
        north = np.array([s.north_m for s in ships])
        east = np.array([s.east_m for s in ships])
        size = np.array([hulls[k] for k in done])
        outline = hull_outlines(north, east, np.radians([s.heading_deg for s in ships]),
                                size[:, 0], size[:, 1])
        reach = 0.5 * size.sum(axis=1)
        for j in range(1, len(done)):  # the cheap test first: within reach of each other
            near = np.flatnonzero(np.hypot(north[:j] - north[j], east[:j] - east[j])
                                  < reach[:j] + reach[j])
            hit = near[hulls_overlap(outline[near], np.repeat(outline[j:j + 1], near.size, 0))]
            if hit.size:
                other = ships[int(hit[0])].name
                errors.append(doc.error(
                    f"ship '{ships[j].name}' starts where its hull overlaps that of '{other}' "
                    "(a collision at t = 0); start the ships apart",
                    ("ships", done[j], "north_m")))
    return errors


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Load and validate a scenario file, resolving every ship's ``type`` to a ship file.

    Args:
        path: the scenario YAML file.

    Returns:
        The :class:`Scenario`, with ``path`` and ``ships[i].ship_file`` set (absolute).

    Raises:
        ScenarioError: located at the offending line; ``errors`` holds every problem found
            (schema errors and unknown ship types together).
    """
    doc = load_yaml(path)
    absolute = Path(os.path.abspath(path))
    scenario, errors = collect_errors(doc, Scenario)
    ship_files, lookup_errors = _find_ship_files(doc, absolute.parent)
    errors += lookup_errors + rules_file_errors(doc, absolute.parent)
    if errors:
        raise_errors(errors)
    assert scenario is not None
    errors = _ship_errors(doc, scenario, ship_files)
    if errors:
        raise_errors(errors)
    for index, ship in enumerate(scenario.ships):
        ship._ship_file = ship_files[index]
    scenario._path = absolute
    return scenario
