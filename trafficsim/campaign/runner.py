"""Run a chunk of a campaign's encounters as one struct-of-arrays batch.

:func:`run_chunk` draws encounters ``start .. stop - 1`` (:mod:`trafficsim.campaign.generator`),
simulates them together, and returns one row per encounter and ship pair. Each encounter's
random streams are keyed by its campaign index, and nothing couples the encounters of a batch,
so a row is the same whatever chunk, batch or worker computed it. An encounter whose state
stops being finite (a ship file whose model runs away) stands frozen from its last finite
state and its rows say so (``diverged``, ``diverged_at_s``); the others run on.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from trafficsim.batch import build_batch
from trafficsim.campaign.compliance import RULES, PairObserver
from trafficsim.campaign.generator import Encounter, classify, draw
from trafficsim.campaign.spec import CampaignSpec
from trafficsim.colregs.decider import Decider
from trafficsim.engine import Simulation, earth_velocity
from trafficsim.geometry import cpa
from trafficsim.ships.base import EAST, NORTH, PSI, U
from trafficsim.units import NM

#: the columns of a chunk's rows (and of ``encounters.parquet``), in order, with their Arrow
#: types; a chunk file of another schema is damaged and runs again (:mod:`.execute`)
COLUMNS: dict[str, str] = {
    "encounter": "int64", "encounter_type": "string", "pair_type": "string", "seed": "int64",
    **dict.fromkeys(("ship_i", "ship_j", "type_i", "type_j", "behaviour_i", "behaviour_j"),
                    "string"),
    **dict.fromkeys(("dcpa0_nm", "tcpa0_min", "range0_nm", "min_range_m", "t_cpa_s", "end_s"),
                    "double"),
    **dict.fromkeys(("cpa_passed", "collision", "domain_violation", "blind_spot"), "bool"),
    "blind_spot_role": "string", "diverged_at_s": "double", "diverged": "bool",
    **{f"{name}{side}": kind for side in ("_i", "_j") for name, kind in (
        ("manoeuvres", "string"), ("rules_fired", "string"), ("course_change_stbd_deg", "double"),
        ("course_change_port_deg", "double"), ("crossed_ahead", "bool"))},
    "graded_kind_i": "string", "graded_kind_j": "string",
    "graded_by_i": "string", "graded_by_j": "string",
    "compliance_i": "double", "compliance_j": "double",
    **{f"score_rule{r}": "double" for r in RULES},
}


def rules_path(spec: CampaignSpec) -> Path | None:
    """The spec's ``rules`` file (relative to the spec), None for the bundled rules."""
    if spec.rules is None:
        return None
    base = spec.path.parent if spec.path is not None else Path.cwd()
    return base / spec.rules


def prepare(spec: CampaignSpec, start: int, stop: int) -> tuple[list[Encounter], Simulation]:
    """Draw encounters ``start .. stop - 1`` and start their simulation as one batch."""
    cache: dict[str, Any] = {}
    encounters = [draw(spec, i, cache) for i in range(start, stop)]
    setups, envs = [], []
    for local, enc in enumerate(encounters):
        setups += [dataclasses.replace(s, encounter=local, stream_encounter=enc.index)
                   for s in enc.ships]
        envs.append(enc.env)
    batch = build_batch(setups, envs)
    decider = None
    if spec.policy == "colregs":
        decider = Decider.build(batch.behaviours, batch.pair_i, batch.pair_j, rules_path(spec),
                                spec.domain, spec.visibility_nm)
    sim = Simulation.start(batch, spec.dt_s, seed=spec.seed, decider=decider,
                           decision_period_s=spec.decision_period_s, domain=spec.domain,
                           isolate_divergence=True)
    return encounters, sim


def run_chunk(spec: CampaignSpec, start: int, stop: int) -> dict[str, Any]:
    """Simulate encounters ``start .. stop - 1``; columns of one row per encounter and pair.

    Returns a mapping of equal-length columns plus ``"_ship_steps"`` (ships times steps) and
    ``"_seconds"`` (wall time of the chunk).
    """
    t0 = time.perf_counter()
    encounters, sim = prepare(spec, start, stop)
    observer = PairObserver.start(sim)
    steps = round(spec.duration_s / spec.dt_s)
    longest = round(spec.longest_s / spec.dt_s)
    period = sim.decision_steps
    end_s = np.full(len(encounters), np.nan)  # when each encounter's figures were taken
    passed = np.zeros(sim.batch.pair_i.shape[0], dtype=bool)
    done = 0
    while done < longest:  # one observation per decision period (vectorised over all pairs)
        k = min(period - done % period, (steps if done < steps else longest) - done)
        sim.run(k)
        done += k
        observer.observe(sim)
        if done >= steps:
            live = sim.metrics.active
            passed[live] = cpa_passed(sim)[live]
            if _end_passed(sim, observer, passed, end_s):
                break
    end_s[np.isnan(end_s)] = sim.t_s
    return _rows(spec, encounters, sim, observer, passed, end_s, sim.batch.n_ships * done,
                 time.perf_counter() - t0)


def cpa_passed(sim: Simulation) -> np.ndarray:
    """Per pair, whether its smallest range so far is its closest approach: the ships are
    opening, or on their present courses and speeds over ground they would pass no closer than
    they have been (the CPA of straight-line motion, measured on true states)."""
    b, m = sim.batch, sim.metrics
    pi, pj = b.pair_i, b.pair_j
    v = earth_velocity(b.x, b.env)
    # (errors ignored: a diverged encounter's frozen state may overflow; it ends anyway)
    with np.errstate(all="ignore"):
        dcpa, tcpa = cpa(b.x[NORTH, pj] - b.x[NORTH, pi], b.x[EAST, pj] - b.x[EAST, pi],
                         v[0, pj] - v[0, pi], v[1, pj] - v[1, pi])
    return (tcpa <= 0.0) | (dcpa >= m.min_range_m)


def _end_passed(sim: Simulation, observer: PairObserver, passed: np.ndarray,
                end_s: np.ndarray) -> bool:
    """End the encounters whose pairs have all passed their CPA (or that diverged): their
    figures stay as they are now (``end_s``) while the batch runs on. Whether every encounter
    has ended."""
    b = sim.batch
    enc_of_pair = b.encounter[b.pair_i]
    open_pair = np.zeros(end_s.shape[0], dtype=bool)
    open_pair[enc_of_pair[~passed]] = True
    ending = np.isnan(end_s) & (~open_pair | np.isfinite(sim.diverged_at_s))
    end_s[ending] = sim.t_s
    stop = ending[enc_of_pair]
    sim.metrics.active[stop] = False
    observer.active[np.concatenate([stop, stop])] = False
    return not np.isnan(end_s).any()


def _rows(spec: CampaignSpec, encounters: list, sim: Simulation, observer: PairObserver,
          passed: np.ndarray, end_s: np.ndarray, ship_steps: int,
          seconds: float) -> dict[str, Any]:
    b, m = sim.batch, sim.metrics
    pi, pj = b.pair_i, b.pair_j
    enc_of_pair = b.encounter[pi]
    # a divergence after an encounter's end is not its own (another encounter kept the
    # batch running)
    diverged_at = np.where(sim.diverged_at_s <= end_s, sim.diverged_at_s, np.nan)
    first = np.searchsorted(b.encounter, np.arange(len(encounters)))  # ship 0 of each
    slot_i, slot_j = pi - first[enc_of_pair], pj - first[enc_of_pair]
    x0 = observer.x0
    pair_kind = []
    for p in range(pi.shape[0]):
        enc = encounters[enc_of_pair[p]]
        if slot_i[p] == 0:
            pair_kind.append(enc.pair_kinds[slot_j[p] - 1])
        else:
            a, c = pi[p], pj[p]
            pair_kind.append(classify(x0[PSI, a], x0[PSI, c], x0[NORTH, c] - x0[NORTH, a],
                                      x0[EAST, c] - x0[EAST, a], x0[U, a], x0[U, c]))
    blind = [""] * pi.shape[0]  # the role both ships held, first time it happened
    if sim.decider is not None:
        index = {(int(a), int(c)): p for p, (a, c) in enumerate(zip(pi, pj, strict=True))}
        for spot in sim.decider.blind_spots:
            if spot.from_s > end_s[b.encounter[spot.ship]]:
                continue
            p = index[(min(spot.ship, spot.other), max(spot.ship, spot.other))]
            blind[p] = blind[p] or spot.role
    graded_kind, graded_by = observer.graded_kinds()
    scores = observer.scores(graded_kind)
    half = pi.shape[0]
    names = np.array(b.names, dtype=object)
    behaviours = np.array(b.behaviours, dtype=object)
    types = np.array(b.types, dtype=object)
    rows: dict[str, Any] = {
        "encounter": np.array([encounters[e].index for e in enc_of_pair], dtype=np.int64),
        "encounter_type": [encounters[e].kind for e in enc_of_pair],
        "pair_type": pair_kind,
        "seed": np.full(pi.shape[0], spec.seed, dtype=np.int64),
        "ship_i": names[pi].tolist(),
        "ship_j": names[pj].tolist(),
        "type_i": types[pi].tolist(),
        "type_j": types[pj].tolist(),
        "behaviour_i": behaviours[pi].tolist(),
        "behaviour_j": behaviours[pj].tolist(),
        "dcpa0_nm": m.dcpa0_m / NM,
        "tcpa0_min": m.tcpa0_s / 60.0,
        "range0_nm": np.hypot(x0[NORTH, pj] - x0[NORTH, pi], x0[EAST, pj] - x0[EAST, pi]) / NM,
        "min_range_m": m.min_range_m,
        "t_cpa_s": m.t_min_range_s,
        "end_s": end_s[enc_of_pair],
        "cpa_passed": passed,
        "collision": m.collision,
        "domain_violation": m.domain_violation,
        "blind_spot": np.array([b != "" for b in blind]),
        "blind_spot_role": blind,
        "diverged_at_s": diverged_at[enc_of_pair],
        "diverged": np.isfinite(diverged_at[enc_of_pair]),
        **observer.columns(),
        "graded_kind_i": graded_kind[:half], "graded_kind_j": graded_kind[half:],
        "graded_by_i": graded_by[:half], "graded_by_j": graded_by[half:],
        **scores,
    }
    rows["_ship_steps"] = ship_steps
    rows["_seconds"] = seconds
    return rows


def compliant(rows: dict[str, Any]) -> np.ndarray:
    """Pairs whose two ships both run the rules (no rogue, no keep-course ship)."""
    return ((np.array(rows["behaviour_i"], dtype=object) == "colregs")
            & (np.array(rows["behaviour_j"], dtype=object) == "colregs"))
