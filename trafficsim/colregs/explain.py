"""Why a ship did what it did: the decisions of a run, node by node.

Reads ``decisions.parquet`` of a run folder (written by ``trafficsim run`` for scenarios whose
ships take decisions) and re-renders each recorded decision with
:func:`trafficsim.colregs.network.explain`: every visited node with its file and line, the test
as written with the feature values it saw, the action it set and the child it took.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from trafficsim.colregs import network
from trafficsim.colregs.vocabulary import FEATURES, VOCABULARY
from trafficsim.errors import InputError
from trafficsim.io.results import check_numeric, read_parquet

_STATE = ("decided_own_role", "decided_encounter", "decided_other_role", "decided_own_manoeuvre")


def _read(run_dir: Path) -> dict[str, np.ndarray]:
    path = run_dir / "decisions.parquet"
    if not run_dir.is_dir():
        raise InputError("no such folder (the output folder of 'trafficsim run' or "
                         "'trafficsim replay' was expected)", path=str(run_dir))
    if not path.is_file():
        raise InputError("no decisions recorded here (a run folder of a scenario in which some "
                         "ship takes collision-avoidance decisions was expected)",
                         path=str(path))
    table = read_parquet(path, "decisions file",
                         ("t_s", "ship", "other", "rules", "path", *_STATE, "course_order_deg",
                          *FEATURES))
    check_numeric(table, path, ("t_s", "course_order_deg", *FEATURES))
    return {c: np.asarray(table.column(c).to_pylist()) for c in table.column_names}


def _changes(cols: dict[str, np.ndarray], sel: np.ndarray) -> list[tuple[int, bool]]:
    """Rows of ``sel`` (one ship's decisions) at which, towards the same other ship, the role,
    encounter, expected role, manoeuvre or course order changed (the first row of each other
    ship included), each with whether a state other than the course order changed there."""
    out = []
    last: dict[str, tuple] = {}
    for k in sel:
        other = str(cols["other"][k])
        state = tuple(str(cols[c][k]) for c in _STATE)
        course = f"{cols['course_order_deg'][k]:.0f}"
        before = last.get(other)
        if before != (state, course):
            out.append((int(k), before is not None and before[0] != state))
            last[other] = (state, course)
    return out


def timeline(cols: dict[str, np.ndarray], ship: str) -> list[str]:
    """One line per decision step at which the ship's role, encounter or manoeuvre towards some
    other ship changed, or its course order changed."""
    lines = []
    for k, _ in _changes(cols, np.flatnonzero(cols["ship"] == ship)):
        course = ("route" if np.isnan(cols["course_order_deg"][k])
                  else f"{cols['course_order_deg'][k]:.0f} deg")
        lines.append(f"t = {cols['t_s'][k]:7.0f} s  {cols['other'][k]:>10}: role "
                     f"{cols[_STATE[0]][k]}, encounter {cols[_STATE[1]][k]}, manoeuvre "
                     f"{cols[_STATE[3]][k]}; course order {course}; "
                     f"range {cols['range_nm'][k]:.2f} NM, DCPA {cols['dcpa_nm'][k]:.2f} NM, "
                     f"TCPA {cols['tcpa_min'][k]:.1f} min")
    return lines


def explain_run(run_dir: Path, ship: str, at_s: float | None = None) -> str:
    """The account of ``ship``'s decisions in a run folder.

    Without ``at_s``: the timeline of its changes of role and manoeuvre, then the node-by-node
    explanation of the last change. With ``at_s``: the explanation of every pair's decision at
    the last decision step at or before ``at_s``.

    Raises:
        InputError: no decisions file, unknown ship, a time before the first decision or after
            the run's end (from its summary.json), a column of the wrong type, or a
            rules file changed since the run (its explanation would show other rules).
    """
    cols = _read(Path(run_dir))
    ships = sorted(set(cols["ship"].tolist()))
    if ship not in ships:
        raise InputError(f"ship {ship!r} took no decisions in {run_dir}; ships that did: "
                         f"{', '.join(ships) or 'none'}", key="--ship")
    sel = np.flatnonzero(cols["ship"] == ship)
    times = cols["t_s"][sel]
    out: list[str] = []
    if at_s is None:
        out.append(f"{ship}: decisions that changed something")
        out += ["  " + line for line in timeline(cols, ship)]
        changed = [k for k, state_changed in _changes(cols, sel) if state_changed]
        rows = sel[times == (cols["t_s"][changed[-1]] if changed else times[-1])]
    else:
        from trafficsim.render.data import read_summary

        # (the run's end is in its summary; a folder of decisions alone has no end to check)
        has_summary = (Path(run_dir) / "summary.json").is_file()
        end = read_summary(Path(run_dir)).get("duration_s") if has_summary else None
        if end is not None and at_s > end:
            raise InputError(f"the run ends at t = {end:g} s, before --at-s {at_s:g}",
                             key="--at-s")
        before = times[times <= at_s]
        if before.size == 0:
            raise InputError(f"the first decision is at t = {times.min():g} s, after "
                             f"--at-s {at_s:g}", key="--at-s")
        rows = sel[times == before.max()]
    nets: dict[str, tuple[network.Network, str]] = {}  # rules file -> network, its digest
    for k in rows:
        rules = str(cols["rules"][k])
        if rules not in nets:
            net = network.load(rules, VOCABULARY)
            nets[rules] = net, network.rules_digest(net.rules.files)
        net, digest = nets[rules]
        changed = InputError("changed since the run: the explanation would show rules the "
                             "ships did not decide by (restore the file, or run again)",
                             path=rules)
        if "rules_sha1" in cols and cols["rules_sha1"][k] != digest:
            raise changed
        names = [n for n in str(cols["path"][k]).split(">") if n]
        feats = np.array([float(cols[f][k]) for f in FEATURES])
        try:  # (a run folder of an older version: no digest, the replay is the test)
            text = network.explain(net, [net.node_index(n) for n in names], feats)
        except (KeyError, ValueError):
            raise changed from None
        out.append("")
        out.append(f"t = {cols['t_s'][k]:g} s, {ship} about {cols['other'][k]} "
                   f"({Path(rules).name}):")
        out.append(text)
    return "\n".join(out)
