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
