"""Building a batch from ship setups: order, pairs, per-ship tables, environment, stream keys,
and the steady-rps table behind ``Batch.rps_for_speed``."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from trafficsim.batch import SPEED_TABLE_FRACTIONS, EncounterEnv, ShipSetup, build_batch
from trafficsim.ships import base, kernels
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, Env, U
from trafficsim.ships.library import load_ship
from trafficsim.units import from_kn


def _setup(name, ship, enc=0, north=0.0, east=0.0, heading=0.0, speed=None, **kw):
    spec = load_ship(ship) if isinstance(ship, str) else ship
    speed = from_kn(spec["service_speed_kn"]) if speed is None else speed
    return ShipSetup(name, spec, enc, north, east, heading, speed, **kw)


def _batch(ships, n_enc=None):
    n_enc = 1 + max(s.encounter for s in ships) if n_enc is None else n_enc
    return build_batch(ships, [EncounterEnv()] * n_enc)


def _brute_pairs(enc):
    return {(i, j) for i, j in itertools.combinations(range(len(enc)), 2) if enc[i] == enc[j]}


# -- order and per-ship arrays ---------------------------------------------------------------


def test_ships_keep_the_given_order_in_every_per_ship_array():
    ships = [_setup("d", "cargo", enc=1, north=10.0, east=-1.0, speed=3.0, filter="pv"),
             _setup("a", "kvlcc2", enc=0, north=20.0, east=-2.0, speed=4.0, behaviour="x",
                    sensors={"gnss": {"sigma_m": 2.0}}),
             _setup("c", "catfish", enc=1, north=30.0, east=-3.0, speed=2.0),
             _setup("b", "bulk_carrier", enc=0, north=40.0, east=-4.0, speed=5.0)]
    b = _batch(ships)
    assert b.n_ships == 4 and b.x.shape == (base.N_STATE, 4)
    assert b.names == ["d", "a", "c", "b"]
    assert b.types == ["cargo", "kvlcc2", "catfish", "bulk_carrier"]
    np.testing.assert_array_equal(b.encounter, [1, 0, 1, 0])
    np.testing.assert_array_equal(b.x[NORTH], [10.0, 20.0, 30.0, 40.0])
    np.testing.assert_array_equal(b.x[EAST], [-1.0, -2.0, -3.0, -4.0])
    np.testing.assert_array_equal(b.x[U], [3.0, 4.0, 2.0, 5.0])
    assert all(b.specs[k] is s.spec for k, s in enumerate(ships))
    assert b.filters == ["pv", "none", "none", "none"]
    assert b.behaviours == ["colregs", "x", "colregs", "colregs"]
    assert b.sensors[1] == {"gnss": {"sigma_m": 2.0}} and b.sensors[0] == {}
    codes = [kernels.FAMILY_CODE[m] for m in ("nomoto", "mmg", "modular", "response")]
    np.testing.assert_array_equal(b.family_code, codes)


def test_state_starts_with_zero_sway_yaw_rate_and_rudder():
    b = _batch([_setup("a", "kvlcc2", heading=1.0), _setup("b", "cargo", heading=2.0)])
    np.testing.assert_array_equal(b.x[[base.V, base.R, base.RUDDER]], 0.0)
    assert b.x.flags.c_contiguous and b.t_s == 0.0


def test_heading_is_wrapped_into_zero_two_pi():
    headings = [-math.pi / 2, 7.0, 2 * math.pi, 0.25]
    b = _batch([_setup(f"s{k}", "cargo", heading=h) for k, h in enumerate(headings)])
    np.testing.assert_allclose(b.x[PSI], [1.5 * math.pi, 7.0 - 2 * math.pi, 0.0, 0.25],
                               rtol=0, atol=1e-15)


def test_heading_just_below_zero_wraps_to_zero_not_two_pi():
    """np.mod(-1e-17, 2 pi) rounds to 2 pi itself, outside [0, 2 pi); the stored heading is 0."""
    assert np.mod(-1e-17, 2 * math.pi) == 2 * math.pi
    b = _batch([_setup("a", "cargo", heading=-1e-17)])
    assert b.x[PSI, 0] == 0.0


def test_particulars_gains_and_service_speed_come_from_each_ship_file():
    b = _batch([_setup("a", "catfish"), _setup("b", "kvlcc2")])
    for k, name in enumerate(("catfish", "kvlcc2")):
        spec = load_ship(name)
        assert b.length_m[k] == spec["particulars"]["length_m"]
        assert b.beam_m[k] == spec["particulars"]["beam_m"]
        assert b.service_speed_mps[k] == pytest.approx(spec["service_speed_kn"] * 1852 / 3600,
                                                       rel=1e-15)
        assert b.rudder_max_rad[k] == pytest.approx(
            spec["actuators"]["rudder_max_deg"] * math.pi / 180, rel=1e-15)
    # catfish.yaml: kp 0.8, kd_s 0.8, no ki_per_s; kvlcc2.yaml: kp 3, kd_s 150, ki_per_s 0
    np.testing.assert_array_equal(b.kp, [0.8, 3.0])
    np.testing.assert_array_equal(b.kd_s, [0.8, 150.0])
    np.testing.assert_array_equal(b.ki_per_s, [0.0, 0.0])


def test_autopilot_gains_default_when_the_spec_has_no_autopilot():
    spec = {k: v for k, v in load_ship("cargo").items() if k != "autopilot"}
    b = _batch([_setup("a", spec)])
    assert (b.kp[0], b.kd_s[0], b.ki_per_s[0]) == (1.0, 0.0, 0.0)


def test_substeps_per_s_is_the_inverse_of_the_ship_files_max_dt():
    """catfish 0.5 s, kvlcc2_l7 0.25 s, cargo 1 s (ship files); 0.1 s by hand; 1 s if absent."""
    cargo = load_ship("cargo")
    fine = {**cargo, "integration": {"max_dt_s": 0.1}}
    bare = {k: v for k, v in cargo.items() if k != "integration"}
    b = _batch([_setup("a", "catfish"), _setup("b", "kvlcc2_l7"), _setup("c", cargo),
                _setup("d", fine), _setup("e", bare)])
    np.testing.assert_allclose(b.substeps_per_s, [2.0, 4.0, 1.0, 10.0, 1.0], rtol=1e-15)


# -- pairs -----------------------------------------------------------------------------------


def test_pairs_are_every_i_less_than_j_within_an_encounter_and_nothing_else():
    enc = [3, 3, 1, 3, 1, 0, 2, 3, 1]
    b = _batch([_setup(f"s{k}", "cargo", enc=e) for k, e in enumerate(enc)])
    pairs = list(zip(b.pair_i.tolist(), b.pair_j.tolist(), strict=True))
    assert len(pairs) == len(set(pairs))  # no pair twice
    assert set(pairs) == _brute_pairs(enc)
    assert len(pairs) == math.comb(4, 2) + math.comb(3, 2)  # encounter 3 and encounter 1
    assert np.all(b.pair_i < b.pair_j)
    np.testing.assert_array_equal(b.encounter[b.pair_i], b.encounter[b.pair_j])


def test_separate_encounters_and_lone_ships_give_empty_integer_pair_arrays():
    for ships in ([_setup("a", "cargo")],
                  [_setup("a", "cargo", enc=0), _setup("b", "cargo", enc=1)]):
        b = _batch(ships)
        assert b.pair_i.size == 0 and b.pair_j.size == 0
        assert b.pair_i.dtype.kind == "i" and b.pair_j.dtype.kind == "i"  # usable as indices
        assert b.x[:, b.pair_i].shape == (base.N_STATE, 0)


def test_n_encounters_counts_the_environments_given():
    b = build_batch([_setup("a", "cargo", enc=0), _setup("b", "cargo", enc=2)],
                    [EncounterEnv()] * 3)
    assert b.n_encounters == 3


# -- per-ship tables -------------------------------------------------------------------------


def test_params_rows_are_each_ships_own_packed_parameters_zero_padded():
    """Mixed families: row i is ``pack(family.build([spec_i]))`` followed by zeros up to the
    widest family (built here one ship at a time, not per family group)."""
    types = ["catfish", "cargo", "kvlcc2", "bulk_carrier", "container", "cargo"]
    b = _batch([_setup(f"s{k}", t) for k, t in enumerate(types)])
    fams = base.families()
    rows = []
    for t in types:
        spec = load_ship(t)
        rows.append(base.pack(fams[spec["model"]].build([spec]))[0])
    assert b.params.shape == (len(types), max(r.size for r in rows))
    for k, row in enumerate(rows):
        np.testing.assert_array_equal(b.params[k, : row.size], row)
        np.testing.assert_array_equal(b.params[k, row.size:], 0.0)
    np.testing.assert_array_equal(b.params[1], b.params[5])


def test_actuator_columns_follow_the_kernels_layout():
    types = ["cargo", "catfish", "kvlcc2_l7"]
    b = _batch([_setup(f"s{k}", t) for k, t in enumerate(types)])
    assert b.actuators.shape == (3, 6)
    for k, t in enumerate(types):
        a = load_ship(t)["actuators"]
        row = b.actuators[k]
        assert row[kernels.RUDDER_MAX] == pytest.approx(math.radians(a["rudder_max_deg"]))
        assert row[kernels.RUDDER_RATE] == pytest.approx(math.radians(a["rudder_rate_degps"]))
        assert row[kernels.RUDDER_TAU] == a["rudder_tau_s"]
        assert row[kernels.RPS_MAX] == a["rps_max"]
        assert row[kernels.RPS_MIN] == a["rps_min"]
        assert row[kernels.ENGINE_TAU] == a["engine_tau_s"]


def test_waypoints_are_padded_with_each_routes_last_waypoint():
    r3 = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    r1 = np.array([[7.0, 8.0]])
    b = _batch([_setup("a", "cargo", route_m=r1), _setup("b", "cargo"),
                _setup("c", "cargo", route_m=r3)])
    assert b.waypoints.shape == (3, 3, 2)
    np.testing.assert_array_equal(b.n_waypoints, [1, 0, 3])
    np.testing.assert_array_equal(b.waypoints[0], [[7.0, 8.0]] * 3)
    np.testing.assert_array_equal(b.waypoints[1], 0.0)
    np.testing.assert_array_equal(b.waypoints[2], r3)


def test_without_routes_the_waypoint_table_keeps_one_column():
    b = _batch([_setup("a", "cargo"), _setup("b", "cargo")])
    assert b.waypoints.shape == (2, 1, 2)
    np.testing.assert_array_equal(b.n_waypoints, [0, 0])


def test_stream_keys_default_to_the_encounter_and_take_the_campaign_index():
    b = _batch([_setup("a", "cargo", enc=0, ship_in_encounter=0),
                _setup("b", "cargo", enc=0, ship_in_encounter=1, stream_encounter=417),
                _setup("c", "cargo", enc=1, ship_in_encounter=0),
                _setup("d", "cargo", enc=1, ship_in_encounter=1, stream_encounter=0)])
    np.testing.assert_array_equal(b.stream_encounter, [0, 417, 1, 0])
    np.testing.assert_array_equal(b.ship_in_encounter, [0, 1, 0, 1])
    assert b.stream_encounter.dtype.kind == "i" and b.ship_in_encounter.dtype.kind == "i"


# -- environment -----------------------------------------------------------------------------


def test_each_ship_sees_its_own_encounters_environment():
    """Current 'towards' turned into north/east components by hand; wind copied as given."""
    envs = [EncounterEnv(1.0, math.pi / 2, 5.0, 1.0),  # current towards east
            EncounterEnv(2.0, math.pi, 0.0, 0.0),  # towards south
            EncounterEnv(0.5, math.radians(60.0), 12.0, 3.0)]
    b = build_batch([_setup("a", "cargo", enc=2), _setup("b", "cargo", enc=0),
                     _setup("c", "cargo", enc=1), _setup("d", "cargo", enc=2)], envs)
    np.testing.assert_allclose(b.env.current_north_mps, [0.25, 0.0, -2.0, 0.25], atol=1e-15)
    np.testing.assert_allclose(b.env.current_east_mps,
                               [0.25 * math.sqrt(3), 1.0, 0.0, 0.25 * math.sqrt(3)], atol=1e-15)
    np.testing.assert_array_equal(b.env.wind_speed_mps, [12.0, 5.0, 0.0, 12.0])
    np.testing.assert_array_equal(b.env.wind_from_rad, [3.0, 1.0, 0.0, 3.0])
    rows = np.array([b.env.current_north_mps, b.env.current_east_mps, b.env.wind_speed_mps,
                     b.env.wind_from_rad])
    np.testing.assert_array_equal(b.env_rows, rows)


def test_current_and_wind_effects_add_to_the_encounter_environment_of_that_ship_only():
    """Wind 6 m/s from north (air moving south) plus an air velocity 8 m/s towards east is air
    moving (-6, 8): 10 m/s, from the direction of (6, -8), i.e. 2 pi - atan2(8, 6)."""
    fx = {"current": {"north_mps": 0.2, "east_mps": -0.1},
          "wind": {"north_mps": 0.0, "east_mps": 8.0}}
    ships = [_setup("a", "cargo", enc=0, effects=fx), _setup("b", "cargo", enc=0),
             _setup("c", "cargo", enc=1, effects={"current": {"north_mps": 0.5,
                                                              "east_mps": 0.0}})]
    b = build_batch(ships, [EncounterEnv(0.0, 0.0, 6.0, 0.0), EncounterEnv(1.0, 0.0, 3.0, 1.0)])
    np.testing.assert_allclose(b.env.current_north_mps, [0.2, 0.0, 1.5], atol=1e-15)
    np.testing.assert_allclose(b.env.current_east_mps, [-0.1, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(b.env.wind_speed_mps, [10.0, 6.0, 3.0], rtol=1e-15)
    np.testing.assert_allclose(b.env.wind_from_rad, [2 * math.pi - math.atan2(8.0, 6.0), 0.0,
                                                     1.0], rtol=1e-15)
    np.testing.assert_array_equal(b.env_rows[0], b.env.current_north_mps)
    np.testing.assert_array_equal(b.env_rows[3], b.env.wind_from_rad)


# -- steady rps table and rps_for_speed -------------------------------------------------------


def _response_rps_per_mps(spec):
    """Straight-ahead balance of [seed 001, eq 2] with v = r = delta = 0:
    a1 u|u| + a8' u n + a9' n^2 = 0 (SI: a8' = 60 a8, a9' = 3600 a9, n in rev/s), so for u > 0
    n = u (-a8' + sqrt(a8'^2 - 4 a9' a1)) / (2 a9')."""
    c = spec["coefficients"]
    a1, a8, a9 = c["a1"], 60.0 * c["a8"], 3600.0 * c["a9"]
    return (-a8 + math.sqrt(a8 * a8 - 4.0 * a9 * a1)) / (2.0 * a9)


def test_rps_table_is_the_closed_form_steady_rps_capped_at_rps_max():
    """Nomoto: u_ss = U_service n / n_service (nomoto module), so n = frac n_service; response:
    linear in u by the root above. Beyond rps_max the table holds rps_max: container, rps_max
    gives 24 kn of 22, so fractions 1.125 and 1.25; bulk carrier, u = 0.0781 m/s per rpm
    [seed 001] tops out at 95 rpm = 7.42 m/s = 1.11 of service, the same two."""
    types = ["cargo", "container", "bulk_carrier"]
    b = _batch([_setup(f"s{k}", t) for k, t in enumerate(types)])
    assert b.rps_table.shape == (3, len(SPEED_TABLE_FRACTIONS))
    np.testing.assert_allclose(SPEED_TABLE_FRACTIONS, np.arange(11) * 0.125, rtol=0, atol=1e-15)
    for k, t in enumerate(types):
        spec = load_ship(t)
        speeds = SPEED_TABLE_FRACTIONS * from_kn(spec["service_speed_kn"])
        if spec["model"] == "nomoto":
            want = SPEED_TABLE_FRACTIONS * spec["coefficients"]["rps_service"]
        else:
            want = speeds * _response_rps_per_mps(spec)
        want = np.minimum(want, spec["actuators"]["rps_max"])
        np.testing.assert_allclose(b.rps_table[k], want, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b.rps_table[1, -2:], 1.965, rtol=1e-12)
    assert b.rps_table[1, -3] < 1.965
    np.testing.assert_allclose(b.rps_table[2, -2:], 1.5833, rtol=1e-12)
    assert b.rps_table[2, -3] < 1.5833


def test_rps_table_and_initial_rps_are_for_calm_water():
    """kvlcc2 has windage: a 20 m/s head wind and a current leave the table unchanged."""
    ships = [_setup("a", "kvlcc2")]
    calm = build_batch(ships, [EncounterEnv()])
    windy = build_batch(ships, [EncounterEnv(1.0, 0.5, 20.0, 0.0)])
    np.testing.assert_array_equal(windy.rps_table, calm.rps_table)
    assert windy.x[RPS, 0] == calm.x[RPS, 0]


def test_initial_rps_holds_the_initial_speed():
    """Nomoto and response by closed form (off the table's grid: linear, so interpolation is
    exact); kvlcc2 (MMG) by its surge balance: du vanishes at the batch's rps and changes sign
    1 % either side. kvlcc2.yaml: self-propulsion at 15.5 kn is 1.75 rps."""
    cargo, bulk, kv = load_ship("cargo"), load_ship("bulk_carrier"), load_ship("kvlcc2")
    u_cargo = 0.8 * from_kn(cargo["service_speed_kn"])
    u_bulk = from_kn(9.3)
    b = _batch([_setup("a", cargo, speed=u_cargo), _setup("b", bulk, speed=u_bulk),
                _setup("c", kv)])
    assert b.x[RPS, 0] == pytest.approx(0.8 * cargo["coefficients"]["rps_service"], rel=1e-12)
    assert b.x[RPS, 1] == pytest.approx(u_bulk * _response_rps_per_mps(bulk), rel=1e-12)
    assert b.x[RPS, 2] == pytest.approx(1.75, abs=0.005)
    fam = base.families()["mmg"]
    x = np.zeros((base.N_STATE, 3))
    x[U] = b.x[U, 2]
    x[RPS] = b.x[RPS, 2] * np.array([1.0, 1.01, 0.99])
    du, _, _ = base.accelerations(fam, fam.build([kv] * 3), x, Env())
    assert du[1] > 0.0 > du[2]
    assert abs(du[0]) < 1e-6 * min(du[1], -du[2])


def test_rps_for_speed_interpolates_the_table_linearly_and_clamps_at_its_ends():
    """Against ``np.interp`` on an arbitrary table (frac < 0 -> first entry, > 1.25 -> last)."""
    b = _batch([_setup("a", "cargo"), _setup("b", "kvlcc2"), _setup("c", "catfish")])
    rng = np.random.default_rng(3)
    b.rps_table = np.cumsum(rng.uniform(0.1, 2.0, b.rps_table.shape), axis=1)
    for frac in (-0.5, 0.0, 0.1, 0.3, 0.5, 0.999, 1.0, 1.2, 1.25, 1.3, 4.0):
        speed = frac * b.service_speed_mps
        want = [np.interp(frac, SPEED_TABLE_FRACTIONS, row) for row in b.rps_table]
        np.testing.assert_allclose(b.rps_for_speed(speed), want, rtol=1e-12)


def test_rps_for_speed_takes_a_different_speed_per_ship():
    b = _batch([_setup("a", "cargo"), _setup("b", "container")])
    fr = np.array([0.3, 0.7])
    got = b.rps_for_speed(fr * b.service_speed_mps)
    rps_service = [load_ship(t)["coefficients"]["rps_service"] for t in ("cargo", "container")]
    np.testing.assert_allclose(got, fr * rps_service, rtol=1e-12)


def test_rps_for_speed_of_some_ships_is_theirs_of_the_whole_batch():
    """Given ship indices (in any order), the speeds are theirs and the answer the whole
    batch's at those ships, to the bit."""
    b = _batch([_setup("a", "cargo"), _setup("b", "kvlcc2"), _setup("c", "container")])
    speed = np.array([0.4, 1.1, 0.8]) * b.service_speed_mps
    ships = np.array([2, 0])
    np.testing.assert_array_equal(b.rps_for_speed(speed[ships], ships),
                                  b.rps_for_speed(speed)[ships])


# -- more per-ship tables ---------------------------------------------------------------------


def test_ships_of_one_family_keep_their_own_coefficients_and_actuators():
    """Two cargo variants and a container in one nomoto group: each params row is the
    ship's own K', T', n3' (column order of NomotoParams), each actuator row its own limits."""
    cargo = load_ship("cargo")
    fast = {**cargo, "coefficients": {**cargo["coefficients"], "K_prime": 2.0, "n3_prime": 5.0},
            "actuators": {**cargo["actuators"], "rudder_max_deg": 25.0}}
    b = _batch([_setup("a", cargo), _setup("b", fast), _setup("c", "container")])
    np.testing.assert_array_equal(b.params[:, 0], [3.858, 2.0,
                                                   load_ship("container")["coefficients"]
                                                   ["K_prime"]])
    np.testing.assert_array_equal(b.params[:, 6], [72.06, 5.0,
                                                   load_ship("container")["coefficients"]
                                                   .get("n3_prime", 0.0)])
    np.testing.assert_allclose(b.actuators[:, kernels.RUDDER_MAX],
                               np.radians([35.0, 25.0, load_ship("container")["actuators"]
                                           ["rudder_max_deg"]]), rtol=1e-15)
    np.testing.assert_allclose(b.rudder_max_rad[:2], np.radians([35.0, 25.0]), rtol=1e-15)


def test_catfish_rps_table_is_linear_in_speed_with_the_surge_balance_slope():
    """Modular family: X_uu u^2 + X_nn (2 pi n)^2 = 0, so n = u / (2 pi sqrt(X_nn / -X_uu)),
    capped at rps_max = 25.1 (9.83 kn is 1.105 of the 8.9 kn service speed); the initial rps
    of a ship at 6 kn is that of 6 kn (the interpolation of a linear table is exact)."""
    spec = load_ship("catfish")
    c = spec["coefficients"]
    slope = 1.0 / (2 * math.pi * math.sqrt(c["X_nn"] / -c["X_uu"]))
    b = _batch([_setup("a", "catfish", speed=from_kn(6.0))])
    want = np.minimum(SPEED_TABLE_FRACTIONS * from_kn(8.9) * slope, 25.1)
    np.testing.assert_allclose(b.rps_table[0], want, rtol=1e-12, atol=1e-12)
    assert b.x[RPS, 0] == pytest.approx(from_kn(6.0) * slope, rel=1e-12)


def test_rps_for_speed_clamps_astern_and_very_fast_speeds_to_the_table_ends():
    """Speeds below 0 give the 0-speed entry (0 rps), above 1.25 of service the last entry."""
    b = _batch([_setup("a", "cargo"), _setup("b", "container")])
    np.testing.assert_allclose(b.rps_for_speed(np.array([-3.0, -0.1])), b.rps_table[:, 0],
                               rtol=0, atol=0)
    np.testing.assert_allclose(b.rps_for_speed(5.0 * b.service_speed_mps), b.rps_table[:, -1],
                               rtol=1e-15)
    assert np.all(b.rps_table[:, 0] < 1e-12)


def test_routes_given_as_lists_are_padded_like_arrays():
    """A route as a list of [north, east] pairs is stored and padded with its last point."""
    b = _batch([_setup("a", "cargo", route_m=[[0.0, 1.0], [2.0, 3.0]]),
                _setup("b", "cargo", route_m=np.array([[9.0, 9.0], [8.0, 8.0], [7.0, 7.0],
                                                       [6.0, 6.0]]))])
    assert b.waypoints.shape == (2, 4, 2)
    np.testing.assert_array_equal(b.waypoints[0], [[0.0, 1.0], [2.0, 3.0], [2.0, 3.0],
                                                   [2.0, 3.0]])
    np.testing.assert_array_equal(b.n_waypoints, [2, 4])


def test_substeps_per_s_for_a_non_integer_ratio():
    """max_dt_s = 0.3 s: 1 / 0.3 sub-steps per second (the engine rounds per step)."""
    cargo = load_ship("cargo")
    b = _batch([_setup("a", {**cargo, "integration": {"max_dt_s": 0.3}})])
    assert b.substeps_per_s[0] == pytest.approx(1.0 / 0.3, rel=1e-15)
