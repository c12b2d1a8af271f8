"""The batch: struct-of-arrays state of all ships of all encounters, and its indices.

Every per-ship quantity is one array of shape ``(n_ships,)``; the dynamic state is the
``(N_STATE, n_ships)`` array of :mod:`trafficsim.ships.base`. Ships of different model families
share one batch: the compiled step kernel dispatches on ``family_code`` per ship, with the
family's parameters packed into one zero-padded row of ``params``.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trafficsim.sensors import wrap_2pi
from trafficsim.ships import base
from trafficsim.ships.base import PSI, RPS, Actuators, Env, U
from trafficsim.units import from_kn

#: speed fractions of the service speed at which the rps-for-speed table is tabulated
SPEED_TABLE_FRACTIONS = np.linspace(0.0, 1.25, 11)


@dataclass(frozen=True)
class ShipSetup:
    """One ship as placed in an encounter (SI units, radians).

    Attributes:
        route_m: ``(k, 2)`` waypoints north/east in metres (may be empty: hold course).
        ship_in_encounter: index within the encounter (keys the ship's random streams).
        sensors: instrument configs (ship-file defaults merged with scenario overrides).
        filter: own-ship filter, ``none`` (perfect knowledge), ``pv`` or ``ekf``.
        behaviour: collision-avoidance behaviour (:mod:`trafficsim.colregs.decider`).
        stream_encounter: the encounter's index where it keys random streams (a campaign's
            encounter index); None: ``encounter``.
    """

    name: str
    spec: Mapping[str, Any]
    encounter: int
    north_m: float
    east_m: float
    heading_rad: float
    speed_mps: float
    route_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    ship_in_encounter: int = 0
    sensors: Mapping[str, Any] = field(default_factory=dict)
    filter: str = "none"
    behaviour: str = "colregs"
    stream_encounter: int | None = None
    #: sim-to-real effects of this ship (:mod:`trafficsim.effects`; current and wind here, the
    #: others are already in ``spec`` and ``sensors``)
    effects: Mapping[str, Mapping[str, float]] = field(default_factory=dict)


@dataclass(frozen=True)
class EncounterEnv:
    """Uniform environment of one encounter (SI): current towards, wind from."""

    current_speed_mps: float = 0.0
    current_towards_rad: float = 0.0
    wind_speed_mps: float = 0.0
    wind_from_rad: float = 0.0


@dataclass
class Batch:
    """All ships of all encounters, struct-of-arrays.

    Shapes: ``n`` ships, ``P`` ship pairs (within encounters), ``W`` max waypoints.
    """

    names: list[str]
    types: list[str]
    encounter: np.ndarray  # (n,) int
    x: np.ndarray  # (N_STATE, n)
    family_code: np.ndarray  # (n,) int, see trafficsim.ships.kernels.FAMILY_CODE
    params: np.ndarray  # (n, k) packed model parameters, zero-padded to the widest family
    actuators: np.ndarray  # (n, 6) actuator table
    substeps_per_s: np.ndarray  # (n,) RK4 sub-steps per simulated second
    length_m: np.ndarray  # (n,)
    beam_m: np.ndarray  # (n,)
    kp: np.ndarray  # (n,) heading-controller gains
    kd_s: np.ndarray
    ki_per_s: np.ndarray
    rudder_max_rad: np.ndarray  # (n,)
    rps_table: np.ndarray  # (n, len(SPEED_TABLE_FRACTIONS)) steady rps at tabulated speeds
    service_speed_mps: np.ndarray  # (n,)
    env: Env  # per-ship (n,) arrays of the encounter environment
    env_rows: np.ndarray  # (4, n) the same, as the kernels take it
    waypoints: np.ndarray  # (n, W, 2) north/east, padded with the last waypoint
    n_waypoints: np.ndarray  # (n,) int
    pair_i: np.ndarray  # (P,) int, first ship of each pair
    pair_j: np.ndarray  # (P,) int, second ship (pair_i < pair_j, same encounter)
    n_encounters: int
    ship_in_encounter: np.ndarray  # (n,) int, keys the random streams
    stream_encounter: np.ndarray  # (n,) int, the encounter index that keys the random streams
    sensors: list[Mapping[str, Any]]  # per-ship instrument configs
    filters: list[str]  # per-ship own-ship filter
    specs: list[Mapping[str, Any]]  # per-ship ship files (the EKF runs the ship's own model)
    behaviours: list[str] = field(default_factory=list)  # per-ship collision avoidance
    t_s: float = 0.0

    @property
    def n_ships(self) -> int:
        return self.x.shape[1]

    def rps_for_speed(self, speed_mps: np.ndarray, ships: np.ndarray | None = None
                      ) -> np.ndarray:
        """Steady calm-water rps for ``speed_mps`` by linear interpolation in the table: of
        every ship (``speed_mps`` ``(n,)``), or of the ships with indices ``ships`` (``(k,)``,
        ``speed_mps`` theirs)."""
        rows = np.arange(self.n_ships) if ships is None else np.asarray(ships)
        service = self.service_speed_mps if ships is None else self.service_speed_mps[rows]
        frac = np.clip(speed_mps / service, 0.0, SPEED_TABLE_FRACTIONS[-1])
        pos = frac / (SPEED_TABLE_FRACTIONS[1] - SPEED_TABLE_FRACTIONS[0])
        k = np.minimum(pos.astype(np.int64), len(SPEED_TABLE_FRACTIONS) - 2)
        w = pos - k
        return (1.0 - w) * self.rps_table[rows, k] + w * self.rps_table[rows, k + 1]


def build_batch(ships: Sequence[ShipSetup], envs: Sequence[EncounterEnv]) -> Batch:
    """Assemble a batch from ship setups (kept in the given order) and encounter environments."""
    from trafficsim.ships.kernels import FAMILY_CODE

    fams = base.families()
    n = len(ships)
    specs = [s.spec for s in ships]
    x = np.zeros((base.N_STATE, n))
    x[base.NORTH] = [s.north_m for s in ships]
    x[base.EAST] = [s.east_m for s in ships]
    x[PSI] = wrap_2pi(np.array([s.heading_rad for s in ships], dtype=float))
    x[U] = [s.speed_mps for s in ships]

    codes = np.array([FAMILY_CODE[s["model"]] for s in specs], dtype=np.int64)
    tables: dict[int, np.ndarray] = {}
    rows: dict[int, np.ndarray] = {}
    rps_table = np.zeros((n, len(SPEED_TABLE_FRACTIONS)))
    for model, family in fams.items():  # build time: one pass per family present
        idx = np.flatnonzero(codes == FAMILY_CODE[model])
        if idx.size == 0:
            continue
        group = [specs[k] for k in idx]
        params = family.build(group)
        tables[model], rows[model] = base.pack(params), idx
        act = Actuators.from_specs(group)
        service = np.array([from_kn(s["service_speed_kn"]) for s in group])
        for k, frac in enumerate(SPEED_TABLE_FRACTIONS):
            rps_table[idx, k] = base.steady_rps_for_speed(family, params, act, frac * service)
    width = max(t.shape[1] for t in tables.values())
    packed = np.zeros((n, width))
    for model, table in tables.items():
        packed[rows[model], : table.shape[1]] = table

    service_speed = np.array([from_kn(s["service_speed_kn"]) for s in specs])
    batch_env = _ship_env(ships, envs)
    n_wp = np.array([len(s.route_m) for s in ships], dtype=np.int64)
    w = max(1, int(n_wp.max(initial=0)))
    waypoints = np.zeros((n, w, 2))
    for k, s in enumerate(ships):  # build time only, not on the step path
        if len(s.route_m):
            waypoints[k, : len(s.route_m)] = s.route_m
            waypoints[k, len(s.route_m):] = s.route_m[-1]
    enc = np.array([s.encounter for s in ships], dtype=np.int64)
    pi, pj = _pairs_within(enc)
    autopilot = [s.get("autopilot", {}) for s in specs]
    max_dt = np.array([float(s.get("integration", {}).get("max_dt_s", 1.0)) for s in specs])
    batch = Batch(
        names=[s.name for s in ships],
        types=[str(s.spec["name"]) for s in ships],
        encounter=enc,
        x=x,
        family_code=codes,
        params=packed,
        actuators=base.actuator_table(Actuators.from_specs(specs)),
        substeps_per_s=1.0 / max_dt,
        length_m=np.array([s["particulars"]["length_m"] for s in specs], dtype=float),
        beam_m=np.array([s["particulars"]["beam_m"] for s in specs], dtype=float),
        kp=base.stack(autopilot, "kp", 1.0),
        kd_s=base.stack(autopilot, "kd_s", 0.0),
        ki_per_s=base.stack(autopilot, "ki_per_s", 0.0),
        rudder_max_rad=np.radians([s["actuators"]["rudder_max_deg"] for s in specs]),
        rps_table=rps_table,
        service_speed_mps=service_speed,
        env=batch_env,
        env_rows=base.env_table(batch_env, n),
        waypoints=waypoints,
        n_waypoints=n_wp,
        pair_i=pi,
        pair_j=pj,
        n_encounters=len(envs),
        ship_in_encounter=np.array([s.ship_in_encounter for s in ships], dtype=np.int64),
        stream_encounter=np.array([s.encounter if s.stream_encounter is None
                                   else s.stream_encounter for s in ships], dtype=np.int64),
        sensors=[s.sensors for s in ships],
        filters=[s.filter for s in ships],
        behaviours=[s.behaviour for s in ships],
        specs=specs,
    )
    batch.x[RPS] = batch.rps_for_speed(batch.x[U])
    return batch


def _pairs_within(enc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All index pairs (i < j) within the same encounter (no n^2 memory for big batches)."""
    order = np.argsort(enc, kind="stable")
    bounds = np.flatnonzero(np.diff(enc[order])) + 1
    pi_list, pj_list = [], []
    for group in np.split(order, bounds):  # build time only, not on the step path
        g = np.sort(group)
        a, b = _upper_pairs(len(g))
        pi_list.append(g[a])
        pj_list.append(g[b])
    return np.concatenate(pi_list), np.concatenate(pj_list)


@functools.lru_cache(maxsize=32)
def _upper_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n, k=1)`` (encounters of the same size share it)."""
    return np.triu_indices(n, k=1)


def _ship_env(ships: Sequence[ShipSetup], envs: Sequence[EncounterEnv]) -> Env:
    enc = np.array([s.encounter for s in ships], dtype=np.int64)
    cs = np.array([e.current_speed_mps for e in envs])[enc]
    ct = np.array([e.current_towards_rad for e in envs])[enc]
    env = Env(
        current_north_mps=cs * np.cos(ct),
        current_east_mps=cs * np.sin(ct),
        wind_speed_mps=np.array([e.wind_speed_mps for e in envs])[enc],
        wind_from_rad=np.array([e.wind_from_rad for e in envs])[enc],
    )
    if not any(s.effects.get("current") or s.effects.get("wind") for s in ships):
        return env
    from trafficsim import effects

    off = np.array([effects.environment_offset(s.effects) for s in ships])
    speed, from_rad = env.wind_speed_mps, env.wind_from_rad
    windy = np.any(off[:, 2:] != 0.0, axis=1)
    ws, wf = effects.add_wind(speed, from_rad, off[:, 2], off[:, 3])
    return Env(current_north_mps=env.current_north_mps + off[:, 0],
               current_east_mps=env.current_east_mps + off[:, 1],
               wind_speed_mps=np.where(windy, ws, speed),
               wind_from_rad=np.where(windy, wf, from_rad))
