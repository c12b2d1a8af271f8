"""The ship library: ship files by type name (``trafficsim/ships/library/<type>.yaml``) or by path.

A ship file holds particulars, actuator limits and the coefficients of one model family; its format
is documented in the README ("Ship files"). Loading validates the file and checks ``coefficients``
against the family's declared coefficient names, so a typo is reported with its line, and every
number whose valid range is physically clear (positive masses, lengths, areas and time constants,
fractions below 1, whole mast counts: :data:`trafficsim.ships.base.PARTICULAR_LIMITS` and the
family's ``limits``) against that range, each out-of-range value at its line.

A path may also name an MMG parameter folder (``MMG_params.csv`` and its two companions, the
format of Miyauchi et al. 2022): it is read at run time as an ``mmg_berthing`` ship
(:mod:`trafficsim.diagnose.mmgfolder`).
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import math
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from trafficsim.errors import ScenarioError, ShipLibraryError
from trafficsim.io.yamlio import (
    FieldError,
    Strict,
    load_yaml,
    parse_loc,
    raise_errors,
    validate,
)

LIBRARY_DIR = Path(__file__).parent / "library"
#: the file that makes a folder an MMG parameter folder
MMG_FOLDER_MARKER = "MMG_params.csv"
#: the windage areas of the wind loads, given both or neither
WINDAGE_AREAS = ("windage_lateral_area_m2", "windage_frontal_area_m2")


class Particulars(Strict):
    length_m: float = Field(ge=0.5, le=600)  # (from tank models up; sets time steps)
    beam_m: float = Field(gt=0, le=100)
    draught_m: float = Field(gt=0, le=40)
    model_config = Strict.model_config | {"extra": "allow"}

    @model_validator(mode="before")
    @classmethod
    def _numbers(cls, data: Any) -> Any:
        if isinstance(data, dict):
            from trafficsim.ships.base import KNOWN_PARTICULARS

            for key in data:
                if key not in KNOWN_PARTICULARS:
                    close = difflib.get_close_matches(str(key), KNOWN_PARTICULARS, n=1)
                    hint = (f" (did you mean '{close[0]}'?)" if close else
                            f"; known particulars: {', '.join(KNOWN_PARTICULARS)}")
                    raise FieldError(f"unknown key '{key}'{hint}", loc=(key,))
            for key, value in data.items():
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise FieldError(f"expected a number, got {value!r}", loc=(key,))
                if not math.isfinite(value):
                    raise FieldError(f"expected a finite number, got {value!r}", loc=(key,))
            given = [k for k in WINDAGE_AREAS if k in data]
            if len(given) == 1:  # (one alone would mean no wind at all, trafficsim.ships.wind)
                missing = next(k for k in WINDAGE_AREAS if k not in given)
                raise FieldError(f"{given[0]} is given without {missing}; wind loads need both "
                                 "areas (give neither for a ship without wind)", loc=(given[0],))
        return data


class ActuatorSpec(Strict):
    rudder_max_deg: float = Field(gt=0, le=90)
    rudder_rate_degps: float = Field(gt=0, le=90)
    rudder_tau_s: float = Field(gt=0, le=60)
    rps_max: float = Field(gt=0, le=100)
    rps_min: float = Field(ge=-100, le=0)
    engine_tau_s: float = Field(gt=0, le=600)


class AutopilotSpec(Strict):
    kp: float = Field(default=1.0, gt=0, le=20)
    kd_s: float = Field(default=0.0, ge=0, le=1000)
    ki_per_s: float = Field(default=0.0, ge=0, le=1)


class IntegrationSpec(Strict):
    max_dt_s: float = Field(default=1.0, ge=0.001, le=60)  # (a step is dt / max_dt_s sub-steps)


class ShipFile(Strict):
    schema_version: Literal[1]
    name: str = Field(min_length=1)
    description: str = ""
    source: str = ""
    model: str
    particulars: Particulars
    service_speed_kn: float = Field(gt=0, le=60)
    actuators: ActuatorSpec
    coefficients: dict[str, float]
    autopilot: AutopilotSpec = AutopilotSpec()
    integration: IntegrationSpec = IntegrationSpec()
    #: default instruments of this ship type (see trafficsim.navigation); scenarios override
    sensors: dict[str, dict[str, Any]] = Field(default_factory=dict)

    @field_validator("sensors")
    @classmethod
    def _valid_sensors(cls, sensors: dict[str, dict[str, Any]],
                       info: ValidationInfo) -> dict[str, dict[str, Any]]:
        from trafficsim.io.scenario import validate_sensors

        hull = info.data.get("particulars")  # (absent when the particulars are invalid)
        validate_sensors(sensors, None if hull is None else {"length_m": hull.length_m,
                                                              "beam_m": hull.beam_m})
        return sensors


def known_ships() -> list[str]:
    """Type names of the bundled ships."""
    return sorted(p.stem for p in LIBRARY_DIR.glob("*.yaml"))


def find_ship(type_or_path: str, base_dir: Path | None = None) -> Path:
    """Resolve a ship type name or a ship-file path to an absolute file path.

    A value with a path separator or a ``.yaml``/``.yml`` suffix is a path (relative to
    ``base_dir``, default the working directory); anything else is a library type name.
    """
    looks_like_path = "/" in type_or_path or type_or_path.endswith((".yaml", ".yml"))
    if looks_like_path:
        p = Path(type_or_path)
        if not p.is_absolute() and base_dir is not None:
            p = base_dir / p
        if p.is_dir() and (p / MMG_FOLDER_MARKER).is_file():
            return p.resolve()
        if not p.is_file():
            raise ShipLibraryError(f"ship file '{type_or_path}' not found (looked at {p}; a "
                                   f"folder must hold the {MMG_FOLDER_MARKER} of an MMG "
                                   "parameter folder)")
        return p.resolve()
    p = LIBRARY_DIR / f"{type_or_path}.yaml"
    if p.is_file():
        return p
    names = known_ships()
    close = difflib.get_close_matches(type_or_path, names, n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    raise ShipLibraryError(
        f"unknown ship '{type_or_path}'{hint}; known ships: {', '.join(names)}; "
        "or give a path to a ship file")


def load_ship(type_or_path: str, base_dir: Path | None = None,
              flag: str | None = None) -> dict[str, Any]:
    """Load and validate a ship file; returns it as a plain dict (plus ``path``), the caller's
    own: files are parsed once and cached (read again once changed on disk), and each call gets
    a deep copy, so changing what it returns changes nothing for the next caller.

    ``flag``: the command-line flag that named the ship, for the message of an unknown one."""
    try:
        found = find_ship(type_or_path, base_dir)
    except ShipLibraryError as err:
        if flag is None:
            raise
        raise ShipLibraryError(err.message, key=flag) from None
    return copy.deepcopy(_load_cached(str(found), _stamp(found)))


def _stamp(path: Path) -> str:
    """Digest of a ship file's bytes (of every file of a parameter folder, with their names): a
    file rewritten since it was cached is a new cache key, however soon and whatever its size."""
    digest = hashlib.blake2b(digest_size=16)
    for f in sorted(path.iterdir()) if path.is_dir() else [path]:
        if f.is_file():
            digest.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return digest.hexdigest()


@lru_cache(maxsize=256)
def _load_cached(path: str, stamp: str) -> dict[str, Any]:
    """The validated ship file at ``path`` (``stamp``: :func:`_stamp`, part of the key only)."""
    from trafficsim.ships.base import families, limit_problems

    if Path(path).is_dir():
        from trafficsim.diagnose.mmgfolder import read_folder

        return read_folder(Path(path))  # its errors name the folder's file, line and key
    try:
        ship = validate(Path(path), ShipFile)
    except ScenarioError as err:  # same located message, as the ship-file error it is
        raise _as_ship_error(err) from None
    fams = families()
    doc = load_yaml(Path(path))
    if ship.model not in fams:
        close = difflib.get_close_matches(ship.model, list(fams), n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ShipLibraryError(
            f"unknown model family '{ship.model}'{hint}; expected one of {', '.join(sorted(fams))}",
            path=path, line=doc.line_of(("model",)), key="model")
    declared = fams[ship.model].coefficients
    coeffs = dict(ship.coefficients)
    for name in coeffs:
        if name not in declared:
            close = difflib.get_close_matches(name, list(declared), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ShipLibraryError(
                f"unknown coefficient '{name}' for model '{ship.model}'{hint}",
                path=path, line=doc.line_of(("coefficients", name)), key=f"coefficients.{name}")
    for name, default in declared.items():
        if name not in coeffs:
            if default is None:
                raise ShipLibraryError(
                    f"missing required coefficient '{name}' for model '{ship.model}'",
                    path=path, line=doc.line_of(("coefficients",)), key="coefficients")
            coeffs[name] = default
    out = ship.model_dump()
    out["coefficients"] = coeffs
    out["path"] = path
    problems = limit_problems(fams[ship.model], out)
    if problems:  # (every one, for 'trafficsim validate')
        try:
            raise_errors([ScenarioError(message, path=path, line=doc.line_of(parse_loc(key)),
                                        key=key) for key, message in problems])
        except ScenarioError as err:
            raise _as_ship_error(err) from None
    return out


def _as_ship_error(err: ScenarioError) -> ShipLibraryError:
    out = ShipLibraryError(err.message, path=err.path, line=err.line, key=err.key)
    out.errors = [ShipLibraryError(e.message, path=e.path, line=e.line, key=e.key)
                  for e in getattr(err, "errors", [err])]
    return out
