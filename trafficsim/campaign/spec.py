"""Campaign spec files: the schema and :func:`load_spec`.

A campaign draws ``n_encounters`` random encounters and runs them all::

    schema_version: 1
    name: default                  # required, non-empty
    n_encounters: 1000             # 1 .. 10,000,000
    seed: 1                        # int >= 0; with the encounter index it fixes each encounter
    duration_s: 1800               # per encounter, > 0 and >= tcpa_min's upper end
    max_duration_s: 3600           # optional, default duration_s: an encounter runs on past
                                   #   duration_s until every pair has passed its closest point
    dt_s: 1.0                      # optional, default 1.0
    chunk_encounters: 500          # optional, default 500: encounters per chunk (memory,
                                   #   and the unit of work, of resuming and of the executors)
    policy: colregs                # colregs (every ship runs the rules) or no_avoidance
    rules: ../rules/colregs.yaml   # optional, relative to this file
    domain: coldwell               # ship domain of features and metrics
    decision_period_s: 10          # optional, a whole multiple of dt_s, <= duration_s; default
                                   #   10 s rounded to a whole number of steps
    encounter_types:               # relative weights (any subset; at least one > 0)
      head_on: 1
      crossing_give_way: 1         # the other ship crosses from the own ship's starboard side
      crossing_stand_on: 1         # ... from its port side
      overtaking: 1                # the own ship overtakes
      overtaken: 1                 # the own ship is overtaken
      multi: 1                     # 3 to 5 ships, each other ship of one of the types above
    multi_ships: [3, 5]            # ships in a multi-ship encounter (inclusive)
    dcpa_nm: [0.0, 1.0]            # DCPA of every other ship to the own ship at the start
    tcpa_min: [10, 30]             # TCPA at the start
    min_start_range_nm: 1.0        # optional, default 0: no other ship starts nearer the own
                                   #   ship (nor, in a multi-ship encounter, another's)
    ship_types: {cargo: 2, container: 1, tanker: 1, bulk_carrier: 1, ferry: 1, fishing: 1}
    speed_fraction: [0.6, 1.0]     # speed as a fraction of the type's service speed
    current_kn: [0.0, 1.0]         # uniform current, random direction
    wind_mps: [0.0, 15.0]          # uniform wind, random direction
    visibility_nm: 10              # below the rules' threshold, Rule 19 applies
    rogue_fraction: 0.05           # share of ships that break the rules (turn_port,
                                   #   late_action; never the own ship of an encounter)
    sensors:                       # optional; absent: perfect knowledge
      gnss_sigma_m: [1.0, 5.0]     # DGPS-like to coarse fixes
      compass_sigma_deg: [0.1, 0.5]
      radar: true                  # radar plots of the other ships
      ais: true                    # AIS transponders and receivers
      filter: pv                   # own-ship filter: pv or ekf

Every range is ``[low, high]`` with ``low <= high`` and is sampled uniformly.
"""

from __future__ import annotations

import difflib
import math
import os
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, PrivateAttr, ValidationInfo, field_validator, model_validator

from trafficsim.errors import ShipLibraryError
from trafficsim.io.scenario import (
    MAX_DT_S,
    MAX_DURATION_S,
    _within_duration,
    default_decision_period,
    known_schema_version,
    rules_file_errors,
)
from trafficsim.io.yamlio import (
    FieldError,
    Integer,
    Number,
    Strict,
    Text,
    collect_errors,
    load_yaml,
    raise_errors,
)

#: encounter types, in the order the generator and the reports use
ENCOUNTER_TYPES = ("head_on", "crossing_give_way", "crossing_stand_on", "overtaking",
                   "overtaken", "multi")

NonNegative = Annotated[Number, Field(ge=0.0)]


def _range(low: float, high: float) -> Any:
    """A ``[low, high]`` pair of numbers within the bounds ``low`` and ``high``."""
    bounded = Annotated[Number, Field(ge=low, le=high)]
    return tuple[bounded, bounded]


def _ordered(value: tuple[float, float]) -> tuple[float, float]:
    if value[0] > value[1]:
        raise ValueError(f"expected [low, high] with low <= high, got "
                         f"[{value[0]:g}, {value[1]:g}]")
    return value


def _whole(value: float, step: float) -> bool:
    """Whether ``value`` is one or more whole steps of ``step``."""
    steps = value / step
    return abs(steps - round(steps)) <= 1e-9 and round(steps) >= 1


class Sensors(Strict):
    """Instrument quality ranges of every ship of the campaign."""

    gnss_sigma_m: _range(0.1, 500.0) = (1.0, 5.0)
    compass_sigma_deg: _range(0.0, 10.0) = (0.1, 0.5)
    radar: bool = True
    ais: bool = True
    filter: Literal["pv", "ekf"] = "pv"

    @field_validator("gnss_sigma_m", "compass_sigma_deg")
    @classmethod
    def _low_high(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _ordered(value)


class CampaignSpec(Strict):
    """A validated campaign spec; see the module docstring for the format."""

    schema_version: Integer
    name: Text
    description: str = ""
    n_encounters: Annotated[Integer, Field(ge=1, le=10_000_000)]
    seed: Annotated[Integer, Field(ge=0)] = 0
    duration_s: Annotated[Number, Field(gt=0.0, le=MAX_DURATION_S)]
    max_duration_s: Annotated[Number, Field(gt=0.0, le=MAX_DURATION_S)] | None = None
    dt_s: Annotated[Number, Field(gt=0.0, le=MAX_DT_S, validate_default=True)] = 1.0
    chunk_encounters: Annotated[Integer, Field(ge=1, le=1_000_000)] = 500
    policy: Literal["colregs", "no_avoidance"] = "colregs"
    rules: Text | None = None
    domain: Literal["coldwell", "goodwin", "fujii", "kijima"] = "coldwell"
    decision_period_s: Annotated[Number, Field(gt=0.0, le=600.0)] = Field(
        default=None, validate_default=True)
    encounter_types: dict[Literal[ENCOUNTER_TYPES], NonNegative] = Field(  # type: ignore[valid-type]
        default_factory=lambda: dict.fromkeys(ENCOUNTER_TYPES, 1.0))
    multi_ships: tuple[Annotated[Integer, Field(ge=3, le=5)],
                       Annotated[Integer, Field(ge=3, le=5)]] = (3, 5)
    dcpa_nm: _range(0.0, 10.0) = (0.0, 1.0)
    tcpa_min: _range(1.0, 120.0) = (10.0, 30.0)
    min_start_range_nm: Annotated[Number, Field(ge=0.0, le=20.0)] = 0.0
    ship_types: dict[Text, NonNegative] = Field(default_factory=lambda: {"cargo": 1.0})
    speed_fraction: _range(0.2, 1.2) = (0.6, 1.0)
    current_kn: _range(0.0, 5.0) = (0.0, 0.0)
    wind_mps: _range(0.0, 40.0) = (0.0, 0.0)
    visibility_nm: Annotated[Number, Field(gt=0.0, le=100.0)] = 10.0
    rogue_fraction: Annotated[Number, Field(ge=0.0, le=1.0)] = 0.0
    sensors: Sensors | None = None

    _path: Path | None = PrivateAttr(default=None)

    @property
    def longest_s(self) -> float:
        """The longest an encounter runs: ``max_duration_s``, else ``duration_s``."""
        return self.duration_s if self.max_duration_s is None else self.max_duration_s

    @property
    def path(self) -> Path | None:
        """Absolute path of the spec file (None if not loaded from a file)."""
        return self._path

    @field_validator("schema_version")
    @classmethod
    def _known_version(cls, version: int) -> int:
        return known_schema_version(version)

    @field_validator("multi_ships", "dcpa_nm", "tcpa_min", "speed_fraction", "current_kn",
                     "wind_mps")
    @classmethod
    def _low_high(cls, value: tuple[float, float]) -> tuple[float, float]:
        return _ordered(value)

    @field_validator("encounter_types", mode="before")
    @classmethod
    def _known_types(cls, weights: Any) -> Any:
        for kind in weights if isinstance(weights, dict) else ():
            if isinstance(kind, str) and kind not in ENCOUNTER_TYPES:
                close = difflib.get_close_matches(kind, ENCOUNTER_TYPES, n=1, cutoff=0.6)
                hint = (f"did you mean '{close[0]}'?" if close
                        else f"expected one of {', '.join(ENCOUNTER_TYPES)}")
                raise FieldError(f"unknown encounter type '{kind}' ({hint})", loc=(kind,))
        return weights

    @field_validator("encounter_types", "ship_types")
    @classmethod
    def _some_weight(cls, weights: dict[str, float]) -> dict[str, float]:
        if not weights or sum(weights.values()) <= 0.0:
            raise ValueError("expected at least one weight > 0")
        if not math.isfinite(sum(weights.values())):
            raise ValueError("expected weights whose sum is a finite number (they are relative: "
                             "1, 2, 3 will do)")
        return weights

    @field_validator("dt_s")
    @classmethod
    def _dt_divides_duration(cls, dt: float, info: ValidationInfo) -> float:
        duration = info.data.get("duration_s")
        if duration is not None and not _whole(duration, dt):
            raise ValueError(f"duration_s ({duration:g} s) must be a whole multiple of dt_s "
                             f"({dt:g} s; 1 s when not given)")
        return dt

    @field_validator("decision_period_s", mode="before")
    @classmethod
    def _default_decision_period(cls, period: Any, info: ValidationInfo) -> Any:
        return default_decision_period(period, info.data.get("dt_s"))

    @field_validator("decision_period_s")
    @classmethod
    def _dt_divides_period(cls, period: float, info: ValidationInfo) -> float:
        dt = info.data.get("dt_s")
        if dt is not None and not _whole(period, dt):
            raise ValueError(f"must be a whole multiple of dt_s ({dt:g} s), got {period:g}")
        _within_duration(period, info, default_decision_period(None, dt),
                         "the ships would decide once, at the start")
        return period

    @model_validator(mode="after")
    def _every_cpa_within_duration(self) -> CampaignSpec:
        # An encounter drawn with a start TCPA beyond the run ends before its CPA: its
        # "smallest range" would be the last step's, and every statistic meaningless.
        latest_s = 60.0 * self.tcpa_min[1]
        if self.duration_s < latest_s * (1.0 - 1e-9):
            raise FieldError(f"must be at least tcpa_min's upper end, {self.tcpa_min[1]:g} min "
                             f"= {latest_s:g} s, so that every encounter reaches its CPA "
                             f"(lengthen it or lower tcpa_min), got {self.duration_s:g}",
                             loc=("duration_s",))
        return self

    @model_validator(mode="after")
    def _max_duration_after_duration(self) -> CampaignSpec:
        cap = self.max_duration_s
        if cap is not None and cap < self.duration_s:
            raise FieldError(f"must be at least duration_s ({self.duration_s:g} s), got "
                             f"{cap:g}", loc=("max_duration_s",))
        if cap is not None and not _whole(cap, self.dt_s):
            raise FieldError(f"must be a whole multiple of dt_s ({self.dt_s:g} s; 1 s when not "
                             f"given), got {cap:g}", loc=("max_duration_s",))
        return self


def load_spec(path: str | os.PathLike[str]) -> CampaignSpec:
    """Load and check a campaign spec; every ship type must name a library ship or a file
    (relative to the spec).

    Raises:
        ScenarioError: located at the offending line; ``errors`` holds every problem found.
    """
    from trafficsim.ships import library  # the library imports ship families: load lazily

    doc = load_yaml(path)
    absolute = Path(os.path.abspath(path))
    spec, errors = collect_errors(doc, CampaignSpec)
    types = doc.data.get("ship_types")
    for kind in types if isinstance(types, dict) else ():
        if isinstance(kind, str) and kind.strip():
            try:
                library.find_ship(kind, absolute.parent)
            except ShipLibraryError as exc:
                message = exc.message if exc.path is None else str(exc)
                errors.append(doc.error(message, ("ship_types", kind)))
    errors += rules_file_errors(doc, absolute.parent)
    if errors:
        raise_errors(errors)
    assert spec is not None
    spec._path = absolute
    return spec
