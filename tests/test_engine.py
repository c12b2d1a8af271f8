import numpy as np
import pytest

from trafficsim.batch import EncounterEnv, ShipSetup, build_batch
from trafficsim.engine import Simulation
from trafficsim.ships.base import EAST, NORTH, PSI, U, V
from trafficsim.ships.library import known_ships, load_ship
from trafficsim.units import from_kn

FULL_SCALE = [s for s in known_ships() if load_ship(s)["particulars"]["length_m"] > 20]


def _setup(name, type_, enc=0, north=0.0, east=0.0, heading=0.0, speed_kn=None, route=None):
    spec = load_ship(type_)
    speed = from_kn(speed_kn if speed_kn is not None else spec["service_speed_kn"])
    return ShipSetup(name, spec, enc, north, east, heading, speed,
                     np.zeros((0, 2)) if route is None else np.asarray(route, float))


def _run(ships, envs, seconds, dt=1.0):
    sim = Simulation.start(build_batch(ships, envs), dt)
    sim.run(int(seconds / dt))
    return sim


@pytest.mark.parametrize("type_", FULL_SCALE)
def test_straight_run_holds_heading_and_settles_at_the_ordered_speed(type_):
    spec = load_ship(type_)
    speed_kn = 0.8 * spec["service_speed_kn"]
    sim = _run([_setup("a", type_, heading=np.radians(30.0), speed_kn=speed_kn)],
               [EncounterEnv()], 1200)
    x = sim.batch.x
    assert abs(np.degrees(x[PSI, 0]) - 30.0) < 0.01
    assert abs(x[V, 0]) < 1e-6
    assert x[U, 0] == pytest.approx(from_kn(speed_kn), rel=0.02)


def test_route_is_followed_to_its_end():
    route = [[3000.0, 0.0], [6000.0, 3000.0], [6000.0, 9000.0]]
    sim = _run([_setup("a", "container", route=route)], [EncounterEnv()], 1800)
    assert sim.route.wp_index[0] == 3
    x = sim.batch.x
    assert abs(x[NORTH, 0] - 6000.0) < 150.0  # on the last leg's line
    assert x[EAST, 0] > 9000.0


def test_uniform_current_carries_a_ship_without_changing_its_water_speed():
    env = EncounterEnv(current_speed_mps=1.0, current_towards_rad=np.pi / 2)
    still = _run([_setup("a", "container")], [EncounterEnv()], 600)
    drift = _run([_setup("a", "container")], [env], 600)
    xs, xd = still.batch.x, drift.batch.x
    assert xd[EAST, 0] - xs[EAST, 0] == pytest.approx(600.0, abs=2.0)
    assert xd[U, 0] == pytest.approx(xs[U, 0], rel=1e-6)


def test_same_scenario_gives_identical_arrays():
    def once():
        ships = [_setup("a", "kvlcc2", route=[[4000.0, 1000.0]]),
                 _setup("b", "container", north=5000.0, heading=np.pi)]
        return _run(ships, [EncounterEnv(0.3, 1.0, 8.0, 2.0)], 300).batch.x.copy()

    assert np.array_equal(once(), once())


def test_a_ship_moves_the_same_alone_or_inside_a_big_mixed_batch():
    """Vectorised batch against a per-ship reference run (differential test)."""
    types = ["kvlcc2", "container", "cargo", "kvlcc2_l7", "catfish"]
    types = [t for t in types if t in known_ships()]
    env = EncounterEnv(0.5, 0.7, 6.0, 4.0)
    ships, alone = [], []
    for k, t in enumerate(types):
        route = [[2000.0 + 100 * k, 800.0], [4000.0, -500.0]]
        ships.append(_setup(f"s{k}", t, enc=k, heading=0.1 * k, route=route))
        alone.append(_run([_setup(f"s{k}", t, heading=0.1 * k, route=route)], [env], 200))
    batch_sim = _run(ships, [env] * len(types), 200)
    for k, ref in enumerate(alone):
        col = batch_sim.batch.names.index(f"s{k}")
        np.testing.assert_allclose(batch_sim.batch.x[:, col], ref.batch.x[:, 0], rtol=1e-9,
                                   atol=1e-9)


def test_collision_is_detected_on_hulls_and_min_range_recorded():
    ships = [_setup("a", "container", north=-3000.0, speed_kn=12),
             _setup("b", "container", north=3000.0, heading=np.pi, speed_kn=12)]
    sim = _run(ships, [EncounterEnv()], 600)
    m = sim.metrics
    assert m.collision[0]
    assert m.dcpa0_m[0] == pytest.approx(0.0, abs=1e-6)
    assert m.tcpa0_s[0] == pytest.approx(6000.0 / (2 * from_kn(12)), rel=1e-9)
    # bows touch when the gap between centres equals one ship length
    t_touch = (6000.0 - load_ship("container")["particulars"]["length_m"]) / (2 * from_kn(12))
    assert m.t_collision_s[0] == pytest.approx(t_touch, abs=2.0)


def test_encounters_do_not_interact():
    ships = [_setup("a", "container", enc=0), _setup("b", "container", enc=1)]
    sim = Simulation.start(build_batch(ships, [EncounterEnv(), EncounterEnv()]), 1.0)
    assert sim.batch.pair_i.size == 0


def _runaway_spec() -> dict:
    """The library bulk carrier with its resistance coefficient a1 made a large thrust: its
    speed runs away and leaves the finite numbers within a minute."""
    spec = load_ship("bulk_carrier")
    return {**spec, "name": "runaway", "coefficients": {**spec["coefficients"], "a1": 1e-2}}


def _runaway_setup(name, enc, east=0.0):
    spec = _runaway_spec()
    return ShipSetup(name, spec, enc, 0.0, east, 0.0, from_kn(spec["service_speed_kn"]),
                     np.zeros((0, 2)))


def test_a_state_that_stops_being_finite_is_one_error_naming_ship_and_time():
    from trafficsim.errors import SimulationError

    sim = Simulation.start(build_batch([_runaway_setup("wild", 0)], [EncounterEnv()]), 1.0)
    with pytest.raises(SimulationError, match=r"non-finite at t = \d+ s for ships wild"):
        sim.run(600)


def test_isolated_divergence_freezes_that_encounter_and_leaves_the_others_alone():
    def calm(enc):
        return [_setup("a", "container", enc=enc), _setup("b", "cargo", enc=enc, north=3000.0)]

    alone = Simulation.start(build_batch(calm(0), [EncounterEnv(0.3, 1.0)]), 1.0)
    alone.run(300)
    wild = [_runaway_setup("wild", 0), _setup("near", "cargo", enc=0, east=2000.0)]
    sim = Simulation.start(build_batch(wild + calm(1), [EncounterEnv(), EncounterEnv(0.3, 1.0)]),
                           1.0, isolate_divergence=True)
    sim.run(300)
    np.testing.assert_array_equal(sim.batch.x[:, 2:], alone.batch.x)  # as if run alone
    t = sim.diverged_at_s
    assert 0.0 < t[0] < 120.0 and np.isnan(t[1])
    assert np.isfinite(sim.batch.x).all()
    frozen = sim.batch.x[:, :2].copy()
    sim.run(5)
    np.testing.assert_array_equal(sim.batch.x[:, :2], frozen)  # it stands where it stopped
    assert sim.diverged_at_s[0] == t[0]


def test_ships_overlapping_at_the_start_count_as_collided_and_inside_the_domain_at_zero():
    """The metrics take the state at t = 0 too: two hulls 10 m apart abeam overlap (beams
    of tens of metres) before any step, so collision and domain violation date from 0 s."""
    ships = [_setup("a", "container"), _setup("b", "container", east=10.0)]
    sim = Simulation.start(build_batch(ships, [EncounterEnv()]), 1.0)
    m = sim.metrics
    assert m.collision[0] and m.t_collision_s[0] == 0.0
    assert m.domain_violation[0] and m.t_domain_violation_s[0] == 0.0
    sim.run(5)
    assert m.t_collision_s[0] == 0.0 and m.t_domain_violation_s[0] == 0.0


# --- ground velocity and messages ------------------------------------------------------------


def test_earth_velocity_rotates_body_speed_and_adds_the_current():
    """u = 3, v = 1 m/s at heading 90 deg (east): over ground north = -v = -1, east = u = 3;
    at heading 0 and 2 pi the same north = u, east = v; the current adds component-wise."""
    from trafficsim.engine import earth_velocity
    from trafficsim.ships.base import N_STATE, Env

    x = np.zeros((N_STATE, 3))
    x[PSI] = [np.pi / 2, 0.0, 2 * np.pi]
    x[U] = 3.0
    x[V] = 1.0
    still = Env(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(earth_velocity(x, still), [[-1.0, 3.0, 3.0], [3.0, 1.0, 1.0]],
                               atol=1e-12)
    flowing = Env(np.array([0.5, 0.0, -0.2]), np.array([0.0, -0.7, 0.1]), np.zeros(3),
                  np.zeros(3))
    np.testing.assert_allclose(earth_velocity(x, flowing),
                               [[-0.5, 3.0, 2.8], [3.0, 0.3, 1.1]], atol=1e-12)


def test_divergence_message_names_at_most_five_ships_and_the_time():
    from trafficsim.engine import divergence_message

    names = [f"s{k}" for k in range(7)]
    assert divergence_message(12.0, names) == (
        "state became non-finite at t = 12 s for ships s0, s1, s2, s3, s4; reduce dt_s or "
        "check the ship files")
    assert "t = 0.5 s for ships only;" in divergence_message(0.5, ["only"])


# --- start and the run loop ------------------------------------------------------------------


def test_start_orders_the_initial_speed_and_heading_with_rk4_substeps_of_the_ship():
    """cargo integrates at most 1 s per RK4 sub-step: dt 2.5 s needs ceil(2.5) = 3 sub-steps,
    dt 1 s one, dt 0.25 s still one; the speed order is the initial speed and the propeller
    the steady rps for it."""
    for dt, substeps in ((2.5, 3), (1.0, 1), (0.25, 1)):
        batch = build_batch([_setup("a", "cargo", heading=1.0, speed_kn=9.0)], [EncounterEnv()])
        sim = Simulation.start(batch, dt)
        assert sim.substeps.tolist() == [substeps]
        assert sim.speed_order_mps[0] == from_kn(9.0)
        assert sim.course_order_rad[0] == pytest.approx(1.0)
        assert sim.rps_cmd[0] == pytest.approx(batch.rps_for_speed(np.array([from_kn(9.0)]))[0])
        assert sim.nav is None and sim.obs is None and sim.decider is None
        assert sim.t_s == 0.0 and sim.diverged_at_s is None and sim.first_diverged_s is None
        assert not sim.all_diverged


@pytest.mark.parametrize("n_steps, every, calls", [
    (10, 0, 1), (10, 1, 11), (10, 3, 4), (10, 5, 3), (10, 10, 2), (10, 11, 1), (0, 1, 1)])
def test_run_calls_back_at_the_start_and_after_every_every_steps(n_steps, every, calls):
    """1 + floor(n / every) calls (only the start for every = 0), at t = k every dt."""
    sim = Simulation.start(build_batch([_setup("a", "cargo")], [EncounterEnv()]), 0.5)
    seen = []
    sim.run(n_steps, every, lambda s: seen.append((s.t_s, s.step_index)))
    assert len(seen) == calls
    assert seen == [(0.5 * every * k, every * k) for k in range(calls)]
    assert sim.step_index == n_steps and sim.t_s == 0.5 * n_steps


def test_run_without_callback_steps_exactly_n_times():
    """A straight run at constant speed: 7 steps of 2 s move the ship 14 s x speed north."""
    sim = Simulation.start(build_batch([_setup("a", "cargo", speed_kn=10.0)], [EncounterEnv()]),
                           2.0)
    sim.run(7, every=3)
    assert sim.step_index == 7 and sim.t_s == 14.0
    assert sim.batch.x[NORTH, 0] == pytest.approx(14.0 * from_kn(10.0), rel=1e-12)


# --- collision-avoidance decisions -----------------------------------------------------------


def _meeting(sensors=None, filter_="none"):
    """cargo north from the origin, container south from 5 km north, 200 m east: head-on."""
    spec_a, spec_b = load_ship("cargo"), load_ship("container")
    extra = {} if sensors is None else {"sensors": sensors, "filter": filter_}
    return [ShipSetup("a", spec_a, 0, 0.0, 0.0, 0.0, from_kn(12.0), **extra),
            ShipSetup("b", spec_b, 0, 5000.0, 200.0, np.pi, from_kn(12.0), **extra)]


def _with_spy(batch):
    """A decider for ``batch`` whose decide() keeps the time and arguments of each call."""
    from trafficsim.colregs.decider import Decider

    d = Decider.build(batch.behaviours, batch.pair_i, batch.pair_j)
    calls = []
    original = d.decide

    def spy(t_s, own_state, own_vel, *rest):
        calls.append((t_s, own_state.copy(), own_vel.copy(), rest[1].copy()))
        return original(t_s, own_state, own_vel, *rest)

    d.decide = spy
    return d, calls


@pytest.mark.parametrize("dt, period, n_steps, times", [
    (1.0, 10.0, 35, [0, 10, 20, 30]),
    (3.0, 10.0, 10, [0, 9, 18, 27]),  # 10 / 3 rounds to 3 steps: every 9 s
    (0.5, 2.0, 9, [0, 2, 4]),
    (2.0, 0.5, 3, [0, 2, 4, 6]),  # shorter than a step: every step
    (1.0, 1.0, 3, [0, 1, 2, 3]),
])
def test_decisions_are_taken_every_decision_period_from_t0(dt, period, n_steps, times):
    batch = build_batch(_meeting(), [EncounterEnv()])
    d, calls = _with_spy(batch)
    sim = Simulation.start(batch, dt, decider=d, decision_period_s=period)
    sim.run(n_steps)
    assert [c[0] for c in calls] == pytest.approx(times)
    assert sim.decision_steps == max(1, round(period / dt))


def test_course_orders_of_the_decider_change_only_at_decision_steps():
    """Between decisions the decider's course order stands, and the engine's course order is
    the decider's wherever it set one (NaN: the route's)."""
    batch = build_batch(_meeting(), [EncounterEnv()])
    d, _ = _with_spy(batch)
    sim = Simulation.start(batch, 1.0, decider=d, decision_period_s=5.0)
    orders = []

    def look(s):
        override = s.decider.course_order_rad.copy()
        orders.append((s.step_index, override))
        set_ = ~np.isnan(override)
        np.testing.assert_array_equal(s.course_order_rad[set_], override[set_])

    sim.run(400, 1, look)
    assert not np.isnan(orders[0][1]).any()  # both turn away at the first decision
    changed = [k for (k, now), (_, before) in zip(orders[1:], orders[:-1], strict=True)
               if not np.array_equal(now, before, equal_nan=True)]
    assert changed  # back on route once past and clear
    assert all(k % 5 == 0 for k in changed)


def test_decisions_are_taken_on_the_estimate_not_the_truth():
    """With GNSS, compass and a pv filter the decider gets each ship's estimate and estimated
    ground velocity (which differ from the truth by the instrument noise)."""
    sensors = {"gnss": {"sigma_m": 3.0}, "compass": {"kind": "gyro", "sigma_deg": 0.5}}
    batch = build_batch(_meeting(sensors, "pv"), [EncounterEnv()])
    d, calls = _with_spy(batch)
    sim = Simulation.start(batch, 1.0, seed=3, decider=d, decision_period_s=10.0)
    sim.run(40)  # the last step (t = 40 s) is a decision step
    t, own, own_vel, _ = calls[-1]
    assert t == 40.0
    np.testing.assert_array_equal(own, sim.nav.est[[NORTH, EAST, PSI]])
    np.testing.assert_array_equal(own_vel, sim.nav.ground_velocity(batch.env))
    assert not np.array_equal(own[:2], sim.batch.x[[NORTH, EAST]])


def test_without_instruments_decisions_see_the_true_state_of_the_other_ship():
    """Perfect knowledge: the other ship's row is its true north, east and ground velocity."""
    from trafficsim.engine import earth_velocity

    env = EncounterEnv(0.4, 1.2)
    batch = build_batch(_meeting(), [env])
    d, calls = _with_spy(batch)
    sim = Simulation.start(batch, 1.0, decider=d, decision_period_s=10.0)
    sim.run(20)
    t, own, own_vel, other = calls[-1]
    x = sim.batch.x
    vel = earth_velocity(x, batch.env)
    assert t == 20.0
    np.testing.assert_array_equal(own, x[[NORTH, EAST, PSI]])
    np.testing.assert_array_equal(own_vel, vel)
    np.testing.assert_array_equal(other, np.concatenate([x[[NORTH, EAST]][:, d.tgt],
                                                         vel[:, d.tgt]]))


# --- determinism and independence of the batch ----------------------------------------------

SENSORS = {"gnss": {"sigma_m": 2.0}, "compass": {"kind": "gyro", "sigma_deg": 0.3},
           "radar": {}, "ais": {}}


def _instrumented(name, type_, enc, k, north, east, heading_deg, kn, stream):
    from trafficsim.navigation import merge_sensors

    spec = load_ship(type_)
    return ShipSetup(name, spec, enc, north, east, np.radians(heading_deg), from_kn(kn),
                     np.zeros((0, 2)), k, merge_sensors(spec.get("sensors"), SENSORS), "pv",
                     "colregs", stream)


def _enc_a(enc):
    """Head-on meeting with instruments, radar and AIS (campaign encounter 7)."""
    return [_instrumented("a0", "cargo", enc, 0, 0.0, 0.0, 0.0, 12.0, 7),
            _instrumented("a1", "container", enc, 1, 4000.0, 300.0, 180.0, 12.0, 7)]


def _enc_b(enc):
    """Crossing with instruments, radar and AIS (campaign encounter 3)."""
    return [_instrumented("b0", "tanker", enc, 0, 0.0, 0.0, 90.0, 10.0, 3),
            _instrumented("b1", "cargo", enc, 1, -3000.0, 3000.0, 0.0, 12.0, 3)]


ENV_A, ENV_B = EncounterEnv(0.3, 1.0, 5.0, 2.0), EncounterEnv(0.1, 2.0, 8.0, 0.5)


def _decide_and_run(ships, envs, seed=5, n_steps=120):
    from trafficsim.colregs.decider import Decider

    batch = build_batch(ships, envs)
    d = Decider.build(batch.behaviours, batch.pair_i, batch.pair_j)
    sim = Simulation.start(batch, 1.0, seed=seed, decider=d, decision_period_s=10.0)
    sim.run(n_steps)
    return sim


def _of(sim, names):
    cols = [sim.batch.names.index(n) for n in names]
    return (sim.batch.x[:, cols], sim.nav.est[:, cols], sim.decider.course_order_rad[cols])


def test_same_seed_same_arrays_with_instruments_tracks_and_decisions():
    one, two = _decide_and_run(_enc_a(0), [ENV_A]), _decide_and_run(_enc_a(0), [ENV_A])
    for p, q in zip(_of(one, ["a0", "a1"]), _of(two, ["a0", "a1"]), strict=True):
        np.testing.assert_array_equal(p, q)
    assert not np.isnan(one.decider.course_order_rad).all()  # the decider did act
    other = _decide_and_run(_enc_a(0), [ENV_A], seed=6)
    assert not np.array_equal(other.nav.est, one.nav.est)  # the seed keys the noise


@pytest.mark.parametrize("layout", ["after", "before", "interleaved"])
def test_an_encounter_gives_the_same_result_whatever_else_is_in_its_batch(layout):
    """Encounter A alone against A with encounter B after it, before it, or with the ships of
    the two interleaved: truth, estimate and decisions of A identical bit for bit."""
    alone = _decide_and_run(_enc_a(0), [ENV_A])
    if layout == "after":
        mixed = _decide_and_run(_enc_a(0) + _enc_b(1), [ENV_A, ENV_B])
    elif layout == "before":
        mixed = _decide_and_run(_enc_b(0) + _enc_a(1), [ENV_B, ENV_A])
    else:
        a, b = _enc_a(0), _enc_b(1)
        mixed = _decide_and_run([a[0], b[0], a[1], b[1]], [ENV_A, ENV_B])
    for p, q in zip(_of(alone, ["a0", "a1"]), _of(mixed, ["a0", "a1"]), strict=True):
        np.testing.assert_array_equal(p, q)


# --- divergence ------------------------------------------------------------------------------


def _wild(name, enc, a1, k=0, east=0.0):
    spec = load_ship("bulk_carrier")
    spec = {**spec, "name": "runaway", "coefficients": {**spec["coefficients"], "a1": a1}}
    return ShipSetup(name, spec, enc, 0.0, east, 0.0, from_kn(10.0), np.zeros((0, 2)), k)


def test_isolated_divergence_with_instruments_and_decisions_leaves_the_others_identical():
    """A runaway ship in encounter 0 (with a mate) next to the instrumented head-on encounter
    A: A runs as if alone (truth, estimate, decisions); only the runaway ship is flagged, and
    its whole encounter stands frozen at finite values."""
    from trafficsim.colregs.decider import Decider

    alone = _decide_and_run(_enc_a(0), [ENV_A], n_steps=60)
    ships = [_wild("w", 0, 1.0), _setup("mate", "cargo", enc=0, east=3000.0), *_enc_a(1)]
    batch = build_batch(ships, [EncounterEnv(), ENV_A])
    d = Decider.build(batch.behaviours, batch.pair_i, batch.pair_j)
    sim = Simulation.start(batch, 1.0, seed=5, decider=d, decision_period_s=10.0,
                           isolate_divergence=True)
    sim.run(60)
    for p, q in zip(_of(alone, ["a0", "a1"]), _of(sim, ["a0", "a1"]), strict=True):
        np.testing.assert_array_equal(p, q)
    assert sim.diverged_ships.tolist() == [True, False, False, False]
    assert sim.diverged_at_s[0] >= 0.0 and np.isnan(sim.diverged_at_s[1])
    assert sim.first_diverged_s == sim.diverged_at_s[0] and not sim.all_diverged
    assert np.isfinite(sim.batch.x).all()
    assert sim.substeps[:2].tolist() == [0, 0] and (sim.substeps[2:] > 0).all()


def test_encounters_diverging_at_different_times_are_each_frozen_at_their_own_time():
    """a1 = 1000 leaves the finite numbers in the second step, a1 = 1 in the third (found by
    running each alone); together each freezes at its own time, the first is reported."""
    def alone(a1):
        sim = Simulation.start(build_batch([_wild("w", 0, a1)], [EncounterEnv()]), 1.0,
                               isolate_divergence=True)
        sim.run(10)
        return float(sim.diverged_at_s[0]), sim.batch.x[:, 0].copy()

    t_fast, x_fast = alone(1e3)
    t_slow, x_slow = alone(1.0)
    assert t_fast < t_slow
    sim = Simulation.start(build_batch([_wild("slow", 0, 1.0), _wild("fast", 1, 1e3)],
                                       [EncounterEnv(), EncounterEnv()]), 1.0,
                           isolate_divergence=True)
    sim.run(10)
    assert sim.diverged_at_s.tolist() == [t_slow, t_fast]
    assert sim.first_diverged_s == t_fast and sim.all_diverged
    np.testing.assert_array_equal(sim.batch.x, np.stack([x_slow, x_fast], axis=1))


def test_without_isolation_the_error_names_every_ship_that_diverged_in_that_step():
    from trafficsim.errors import SimulationError

    ships = [_wild("w0", 0, 1e3), _setup("calm", "cargo", enc=1), _wild("w1", 2, 1e3)]
    sim = Simulation.start(build_batch(ships, [EncounterEnv()] * 3), 1.0)
    with pytest.raises(SimulationError, match=r"^state became non-finite at t = \d+ s for "
                                              r"ships w0, w1; reduce dt_s"):
        sim.run(10)
