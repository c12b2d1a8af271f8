"""The step loop: guidance and autopilot on the estimate, dynamics per model family, metrics.

One :class:`Simulation` advances every ship of every encounter of a batch together with a fixed
step: guidance, the autopilot and the dynamics (:mod:`trafficsim.ships.kernels`) are compiled
loops over ships; nothing loops over ships in Python.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from trafficsim.batch import Batch
from trafficsim.colregs.decider import Decider
from trafficsim.control import autopilot, guidance
from trafficsim.errors import SimulationError
from trafficsim.jit import kernel
from trafficsim.metrics import PairMetrics
from trafficsim.navigation import Navigation
from trafficsim.observation import Observation, observes
from trafficsim.ships import base, kernels
from trafficsim.ships.base import EAST, NORTH, PSI, Env, R


def earth_velocity(x: np.ndarray, env: Env) -> np.ndarray:
    """Velocity over ground, ``(2, n)`` north/east m/s."""
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    return np.stack([x[base.U] * c - x[base.V] * s + env.current_north_mps,
                     x[base.U] * s + x[base.V] * c + env.current_east_mps])


def divergence_message(t_s: float, names: list[str]) -> str:
    """What to tell a user whose ships' state stopped being finite in the step to ``t_s``."""
    return (f"state became non-finite at t = {t_s:g} s for ships {', '.join(names[:5])}; "
            f"reduce dt_s or check the ship files")


@dataclass
class Simulation:
    """A running batch. Orders (course from guidance, speed) and controller memory per ship."""

    batch: Batch
    dt: float
    speed_order_mps: np.ndarray
    route: guidance.RouteState
    metrics: PairMetrics
    integral: np.ndarray
    course_order_rad: np.ndarray
    rudder_cmd_rad: np.ndarray
    rps_cmd: np.ndarray
    substeps: np.ndarray  # (n,) RK4 sub-steps per time step
    #: the parameter tables column by column for the vectorised step (None: no ship of a
    #: vectorised family)
    vector_tables: tuple[np.ndarray, np.ndarray] | None
    nav: Navigation | None = None  # instruments and filters; None = perfect knowledge
    obs: Observation | None = None  # radar, AIS and tracks of other ships
    decider: Decider | None = None  # collision avoidance; None = every ship follows its route
    decision_steps: int = 10  # steps between decisions
    route_speed_mps: np.ndarray | None = None  # (n,) speed of each ship on its route
    step_index: int = 0
    #: per encounter, the time from which it stood frozen after its state stopped being finite
    #: (NaN: it has not); only with ``isolate_divergence``, else the first such step raises
    diverged_at_s: np.ndarray | None = None
    diverged_ships: np.ndarray | None = None  # (n,) bool: the ships whose state did
    _x_good: np.ndarray | None = None  # the last all-finite state, kept to freeze from

    @classmethod
    def start(cls, batch: Batch, dt: float, seed: int = 0, decider: Decider | None = None,
              decision_period_s: float = 10.0, domain: str = "coldwell",
              isolate_divergence: bool = False) -> Simulation:
        """Start at t = 0; ``seed`` keys every random stream (instruments); ``decider`` takes
        the collision-avoidance decisions every ``decision_period_s`` (a multiple of ``dt``);
        ``domain`` is the ship-domain model of the domain-violation metric.

        A step that leaves a ship's state not finite raises :class:`SimulationError`, or, with
        ``isolate_divergence`` (campaigns: one bad encounter must not end the others), freezes
        every ship of that ship's encounter at its last finite state and records the time in
        :attr:`diverged_at_s`; the other encounters run on unchanged."""
        x = batch.x
        n = batch.n_ships
        speed = x[base.U].copy()
        sim = cls(
            batch=batch,
            dt=dt,
            speed_order_mps=speed,
            route=guidance.RouteState.start(x[NORTH], x[EAST], x[PSI]),
            metrics=PairMetrics.start(x[[NORTH, EAST]], earth_velocity(x, batch.env),
                                      batch.pair_i, batch.pair_j, domain),
            integral=np.zeros(n),
            course_order_rad=x[PSI].copy(),
            rudder_cmd_rad=np.zeros(n),
            rps_cmd=batch.rps_for_speed(speed),
            substeps=np.maximum(1, np.ceil(dt * batch.substeps_per_s - 1e-9)).astype(np.int64),
            vector_tables=kernels.vector_tables(batch.family_code, batch.params,
                                               batch.actuators),
        )
        if any(f != "none" for f in batch.filters) or any(batch.sensors):
            sim.nav = Navigation.build(batch.sensors, batch.filters, x, seed,
                                       batch.stream_encounter, batch.ship_in_encounter, dt,
                                       batch.specs)
        if observes(batch.sensors):
            sim.obs = Observation.build(batch.sensors, batch.pair_i, batch.pair_j, seed,
                                        batch.stream_encounter, batch.ship_in_encounter)
        sim.metrics.accumulate(x, batch.length_m, batch.beam_m, batch.pair_i, batch.pair_j, 0.0)
        sim.decider = decider
        sim.decision_steps = max(1, round(decision_period_s / dt))
        sim.route_speed_mps = speed.copy()
        if isolate_divergence:
            sim.diverged_at_s = np.full(batch.n_encounters, np.nan)
            sim.diverged_ships = np.zeros(n, dtype=bool)
            sim._x_good = x.copy()
        sim._navigate_and_control()
        return sim

    @property
    def t_s(self) -> float:
        return self.step_index * self.dt

    def _navigate_and_control(self) -> None:
        """Measure and estimate at the current time, then set the orders for the next step.

        Decisions are taken on the estimate (perfect knowledge without instruments), so truth,
        measurements, estimate and orders of one time all refer to that time.
        """
        b, x = self.batch, self.batch.x
        est = x if self.nav is None else self.nav.update(x, b.env)
        if self.obs is not None:
            self.obs.update(x, est, b.env_rows[:2], self.t_s)
        self.course_order_rad = guidance.desired_course(
            self.route, b.waypoints, b.n_waypoints, est[NORTH], est[EAST], b.length_m)
        if self.decider is not None:
            if self.step_index % self.decision_steps == 0:
                self._decide(est)
            override = self.decider.course_order_rad
            self.course_order_rad = np.where(np.isnan(override), self.course_order_rad,
                                             override)
        self.rudder_cmd_rad = autopilot.rudder_command(
            self.course_order_rad, est[PSI], est[R], self.integral, b.kp, b.kd_s, b.ki_per_s,
            b.rudder_max_rad, self.dt)

    def _decide(self, est: np.ndarray) -> None:
        """Collision-avoidance decisions on what each ship knows: its own estimate and, per
        directed pair, its track of the other ship (the truth where it has no radar or AIS)."""
        b, x, d = self.batch, self.batch.x, self.decider
        true_vel = earth_velocity(x, b.env) if self.nav is None or self.obs is None else None
        own_vel = true_vel if self.nav is None else self.nav.ground_velocity(b.env)
        if self.obs is not None:  # (NaN where a pair has no track)
            other = np.ascontiguousarray(self.obs.predicted_tracks(self.t_s)[0].T)
        else:
            other = np.concatenate([x[[NORTH, EAST]][:, d.tgt], true_vel[:, d.tgt]])
        factor_before = d.speed_factor.copy()
        d.decide(self.t_s, est[[NORTH, EAST, PSI]], own_vel, b.length_m, other,
                 self.course_order_rad, self.route_speed_mps)
        changed = np.flatnonzero(d.speed_factor != factor_before)
        if changed.size:
            self.speed_order_mps = self.route_speed_mps * d.speed_factor
            rps = self.rps_cmd.copy()
            rps[changed] = b.rps_for_speed(self.speed_order_mps[changed], changed)
            self.rps_cmd = rps

    def step(self) -> None:
        """Advance all ships by one time step with the current orders, then navigate."""
        b, x, dt = self.batch, self.batch.x, self.dt
        kernels.step_ships(b.family_code, b.params, b.actuators, x, self.rudder_cmd_rad,
                           self.rps_cmd, b.env_rows, dt, self.substeps, self.vector_tables)
        self.step_index += 1
        good = self._x_good
        if not _finite_kept(x, x if good is None else good, good is not None):
            self._diverged(np.flatnonzero(~np.isfinite(x).all(axis=0)))
            if good is not None:
                np.copyto(good, x)
        self.metrics.accumulate(x, b.length_m, b.beam_m, b.pair_i, b.pair_j, self.t_s)
        self._navigate_and_control()

    def _diverged(self, bad: np.ndarray) -> None:
        """Ships ``bad`` left the finite numbers in the step just taken: raise, or freeze their
        encounters at the state before it (``substeps`` 0: the step kernel leaves them)."""
        b = self.batch
        if self.diverged_at_s is None or self._x_good is None or self.diverged_ships is None:
            raise SimulationError(divergence_message(self.t_s, [b.names[k] for k in bad]))
        frozen = np.isin(b.encounter, b.encounter[bad])
        b.x[:, frozen] = self._x_good[:, frozen]
        self.substeps[frozen] = 0
        self.diverged_at_s[np.unique(b.encounter[bad])] = self.t_s - self.dt
        self.diverged_ships[bad] = True

    @property
    def first_diverged_s(self) -> float | None:
        """Time of the last finite state of the first encounter that diverged (None: none
        did, or not ``isolate_divergence``)."""
        if self.diverged_at_s is None or not np.isfinite(self.diverged_at_s).any():
            return None
        return float(np.nanmin(self.diverged_at_s))

    @property
    def all_diverged(self) -> bool:
        """Whether every encounter stands frozen (only with ``isolate_divergence``)."""
        return self.diverged_at_s is not None and bool(np.isfinite(self.diverged_at_s).all())

    def run(self, n_steps: int, every: int = 0,
            callback: Callable[[Simulation], None] | None = None) -> None:
        """Run ``n_steps``; call ``callback`` at the start and after every ``every`` steps."""
        if callback is not None:
            callback(self)
        for k in range(1, n_steps + 1):
            self.step()
            if callback is not None and every and k % every == 0:
                callback(self)


@kernel
def _finite_kept(x: np.ndarray, kept: np.ndarray, keep: bool) -> bool:
    """Whether every number of ``x`` is finite; if so and ``keep``, ``x`` is copied into
    ``kept`` (the state to freeze a diverging encounter at: the one before its step). One
    pass to test and one to copy while ``x`` is in the cache the step just wrote it to."""
    finite = True
    for r in range(x.shape[0]):
        for i in range(x.shape[1]):
            finite &= abs(x[r, i]) < math.inf
    if finite and keep:
        for r in range(x.shape[0]):
            for i in range(x.shape[1]):
                kept[r, i] = x[r, i]
    return finite
