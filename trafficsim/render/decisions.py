"""The decision each ship holds at a time, and the rule node that produced it.

A decision step records, per directed pair (ship, other ship), the path of rule nodes the
ship's network walked and the state it left: role, encounter, manoeuvre, course order
(``decisions.parquet``, :meth:`trafficsim.colregs.decider.Decider.records`). A frame shows one
pair per ship: the pair whose encounter asks a manoeuvre of the ship, else one in which it holds
a role, else any, the closest first. The node that produced the decision is the last node of the
path (where the walk stopped and set the action).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

#: manoeuvres that ask something of the ship (shown before a role without a manoeuvre)
ASKING = ("alter_course", "reduce_speed", "emergency")
#: columns of ``decisions.parquet`` a frame uses
COLUMNS = ("t_s", "ship", "other", "rules", "path", "decided_own_role", "decided_encounter",
           "decided_own_manoeuvre", "course_order_deg", "range_nm")


def words(name: str) -> str:
    """A vocabulary name as words (``give_way`` -> ``give way``)."""
    return name.replace("_", " ")


@dataclass(frozen=True)
class ShipDecision:
    """One ship's decision towards one other ship."""

    t_s: float
    other: str
    role: str
    encounter: str
    manoeuvre: str
    course_order_deg: float  # NaN: the ship follows its route
    node: str  # the rule node that produced the decision
    rules: str  # file name of the rules

    @property
    def has_role(self) -> bool:
        return self.role not in ("", "no_role")

    def line(self, ship: str) -> str:
        """``own -> TS2: give way, crossing; alter course to 030 deg  [colregs.yaml: node]``."""
        order = ("" if math.isnan(self.course_order_deg)
                 else f" to {round(self.course_order_deg) % 360:03d} deg")
        state = (f"{words(self.role)}, {words(self.encounter)}" if self.has_role
                 else "no role")
        return (f"{ship} -> {self.other}: {state}; {words(self.manoeuvre)}{order}  "
                f"[{self.rules}: {self.node}]")


def choose(cols: Mapping[str, Sequence[Any]], rows: Sequence[int] | np.ndarray
           ) -> dict[str, ShipDecision]:
    """Per ship, the pair shown among ``rows`` (the rows of one decision step)."""
    best: dict[str, tuple[tuple[int, float], ShipDecision]] = {}
    for r in rows:
        manoeuvre = str(cols["decided_own_manoeuvre"][r])
        role = str(cols["decided_own_role"][r])
        rank = 0 if manoeuvre in ASKING else 1 if role not in ("", "no_role") else 2
        closeness = float(cols["range_nm"][r])
        key = (rank, closeness if math.isfinite(closeness) else math.inf)
        ship = str(cols["ship"][r])
        if ship in best and best[ship][0] <= key:
            continue
        path = str(cols["path"][r])
        best[ship] = (key, ShipDecision(
            t_s=float(cols["t_s"][r]), other=str(cols["other"][r]), role=role,
            encounter=str(cols["decided_encounter"][r]), manoeuvre=manoeuvre,
            course_order_deg=float(cols["course_order_deg"][r]),
            node=path.rsplit(">", 1)[-1] if path else "", rules=Path(str(cols["rules"][r])).name))
    return {ship: d for ship, (_, d) in best.items()}


class DecisionSource(Protocol):
    def at(self, t_s: float) -> dict[str, ShipDecision]:
        """The decision each deciding ship holds at ``t_s`` (the last step at or before)."""
        ...


class DecisionTable:
    """Decisions of a finished run (the columns of ``decisions.parquet``, in time order)."""

    def __init__(self, cols: Mapping[str, Sequence[Any]]) -> None:
        self._cols = {k: np.asarray(v) for k, v in cols.items()}
        t = self._cols["t_s"].astype(float)
        self._times, self._first = np.unique(t, return_index=True)
        self._stop = np.append(self._first[1:], t.shape[0])
        if t.size and np.any(np.diff(t) < 0):
            raise ValueError("decision rows are not in time order")
        self._cache: dict[int, dict[str, ShipDecision]] = {}

    def at(self, t_s: float) -> dict[str, ShipDecision]:
        step = int(np.searchsorted(self._times, t_s + 1e-9, side="right")) - 1
        if step < 0:
            return {}
        if step not in self._cache:
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[step] = choose(self._cols, range(self._first[step], self._stop[step]))
        return self._cache[step]


class LiveDecisions:
    """Decisions of a running simulation: its decider's latest recorded step."""

    def __init__(self, decider: Any, names: Sequence[str]) -> None:
        self._decider = decider
        self._names = list(names)
        self._seen = -1
        self._last: dict[str, ShipDecision] = {}

    def at(self, t_s: float) -> dict[str, ShipDecision]:
        history = self._decider.history
        if len(history) != self._seen:
            self._seen = len(history)
            self._last = {}
            if history:
                latest = copy.copy(self._decider)  # shares the arrays; records() reads only
                latest.history = history[-1:]
                cols = latest.records(self._names)
                self._last = choose(cols, range(len(cols["ship"])))
        if self._last and next(iter(self._last.values())).t_s > t_s + 1e-9:
            return {}
        return self._last
