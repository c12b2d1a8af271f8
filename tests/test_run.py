"""run.py: scenario setups in SI units, what the recorder keeps and when, run summaries and
run folders, and the end of a run whose state stops being finite."""

import json
import math
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from trafficsim import __version__
from trafficsim.batch import EncounterEnv, build_batch
from trafficsim.engine import Simulation
from trafficsim.errors import SimulationError
from trafficsim.io.scenario import load_scenario
from trafficsim.run import (
    raise_if_diverged,
    record_run,
    record_steps,
    run_scenario,
    run_summary,
    scenario_decider,
    scenario_setups,
    write_run,
)
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, RUDDER, R, U, V
from trafficsim.ships.library import LIBRARY_DIR, load_ship
from trafficsim.units import KN


def _ship(name, type_, north, east, heading, speed_kn=None, route=None,
          behaviour="keep_course", extra=""):
    text = (f"  - name: {name}\n    type: {type_}\n    north_m: {north}\n    east_m: {east}\n"
            f"    heading_deg: {heading}\n    behaviour: {behaviour}\n")
    if speed_kn is not None:
        text += f"    speed_kn: {speed_kn}\n"
    if route is not None:
        text += f"    route: {route}\n"
    return text + extra


def _scenario(tmp_path, ships, duration_s=20, dt_s=1.0, head=""):
    path = tmp_path / "s.yaml"
    path.write_text(f"schema_version: 1\nname: t\nduration_s: {duration_s}\ndt_s: {dt_s}\n"
                    f"{head}ships:\n" + "".join(ships))
    return load_scenario(path)


def _start(scn, isolate=False, record=True):
    ships, env = scenario_setups(scn)
    batch = build_batch(ships, [env])
    return Simulation.start(batch, scn.dt_s, scn.seed, scenario_decider(scn, batch, record),
                            scn.decision_period_s, scn.domain, isolate_divergence=isolate)


INSTRUMENTS = ("    filter: pv\n    sensors:\n      gnss: {sigma_m: 2.0}\n"
               "      compass: {kind: gyro, sigma_deg: 0.3}\n      radar: {}\n      ais: {}\n")
CURRENT_1KN_EAST = "seed: 4\nenvironment:\n  current: {speed_kn: 1.0, towards_deg: 90}\n"


def _instrumented(tmp_path, duration_s=60, other_behaviour="keep_course"):
    """own (cargo, 12 kn north) and other (container, 10 kn south, 500 m east of own's line)
    with DGPS, gyro, pv filter, radar and AIS, in a current of 1 kn towards east."""
    return _scenario(tmp_path, [
        _ship("own", "cargo", 0, 0, 0, 12, extra=INSTRUMENTS),
        _ship("other", "container", 3000, 500, 180, 10, behaviour=other_behaviour,
              extra=INSTRUMENTS)], duration_s, head=CURRENT_1KN_EAST)


def _wrapped(angle):
    return (angle + np.pi) % (2 * np.pi) - np.pi


# --- scenario setups -------------------------------------------------------------------------


def test_setups_convert_knots_and_degrees_to_si(tmp_path):
    scn = _scenario(tmp_path, [
        _ship("a", "cargo", 100, -200, 270, 12, route="[[1000, 2000], [3000, 4000]]"),
        _ship("b", "container", 5000, 0, 90, 7.5)],
        head="environment:\n  current: {speed_kn: 2, towards_deg: 90}\n"
             "  wind: {speed_mps: 10, from_deg: 45}\n")
    ships, env = scenario_setups(scn, encounter=3)
    a, b = ships
    assert (a.name, a.north_m, a.east_m) == ("a", 100.0, -200.0)
    assert a.heading_rad == pytest.approx(1.5 * math.pi, rel=1e-15)
    assert a.speed_mps == pytest.approx(12 * 1852 / 3600, rel=1e-15)
    assert b.heading_rad == pytest.approx(0.5 * math.pi, rel=1e-15)
    assert b.speed_mps == pytest.approx(7.5 * 1852 / 3600, rel=1e-15)
    np.testing.assert_array_equal(a.route_m, [[1000.0, 2000.0], [3000.0, 4000.0]])
    assert b.route_m.shape == (0, 2)
    assert [s.encounter for s in ships] == [3, 3]
    assert [s.ship_in_encounter for s in ships] == [0, 1]
    assert env.current_speed_mps == pytest.approx(2 * 1852 / 3600, rel=1e-15)
    assert env.current_towards_rad == pytest.approx(0.5 * math.pi, rel=1e-15)
    assert env.wind_speed_mps == 10.0  # already SI in the file
    assert env.wind_from_rad == pytest.approx(0.25 * math.pi, rel=1e-15)


def test_setups_default_to_the_service_speed_and_still_water(tmp_path):
    scn = _scenario(tmp_path, [_ship("a", "container", 0, 0, 0)])
    (a,), env = scenario_setups(scn)
    assert a.speed_mps == pytest.approx(load_ship("container")["service_speed_kn"] * KN)
    assert env == EncounterEnv()
    assert (env.current_speed_mps, env.wind_speed_mps) == (0.0, 0.0)


def test_a_decider_only_when_a_ship_decides_and_has_another_ship(tmp_path):
    alone = _scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, behaviour="colregs")])
    assert _start(alone).decider is None
    passive = _scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0), _ship("b", "cargo", 5000, 0, 180)])
    assert _start(passive).decider is None
    deciding = _scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, behaviour="colregs"),
                                    _ship("b", "cargo", 5000, 0, 180)])
    assert _start(deciding).decider.record is True
    assert _start(deciding, record=False).decider.record is False


@pytest.mark.parametrize("dt_s, every_s, steps", [
    (1.0, "record_every_s: 5.0\n", 5), (0.5, "record_every_s: 2.0\n", 4),
    (0.25, "", 4),  # default: 1 s
    (2.0, "", 1),  # default 1 s rounded up to one step
])
def test_record_steps_are_the_record_period_in_whole_steps(tmp_path, dt_s, every_s, steps):
    scn = _scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0)], 20, dt_s, head=every_s)
    assert record_steps(scn) == steps


# --- the recorder ----------------------------------------------------------------------------


def _pair(tmp_path, duration_s=20, dt_s=1.0, head=""):
    """Two ships on straight reciprocal courses 100 m apart abeam, 10 kn each, 2000 m apart."""
    return _scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, 10),
                                _ship("b", "container", 2000, 100, 180, 10)],
                     duration_s, dt_s, head)


@pytest.mark.parametrize("n_steps, every, dt_s", [
    (10, 1, 1.0), (10, 3, 1.0), (12, 4, 0.5), (10, 5, 1.0), (3, 5, 1.0), (1, 1, 1.0)])
def test_records_at_the_start_and_every_period(tmp_path, n_steps, every, dt_s):
    scn = _pair(tmp_path, 20, dt_s)
    sim = _start(scn)
    rec, _ = record_run(sim, n_steps, every)
    expected_times = dt_s * every * np.arange(n_steps // every + 1)
    assert rec.count == expected_times.size
    np.testing.assert_array_equal(rec.t[:rec.count], expected_times)
    assert sim.step_index == n_steps  # all steps taken, also those after the last record
    # the same states, orders taken from the engine's own run loop
    ref, states = _start(scn), []
    ref.run(n_steps, every, lambda s: states.append(
        (s.batch.x.copy(), s.course_order_rad.copy(), s.rudder_cmd_rad.copy())))
    assert len(states) == rec.count
    for k, (x, course, rudder) in enumerate(states):
        np.testing.assert_array_equal(rec.x[k], x)
        np.testing.assert_array_equal(rec.course_order[k], course)
        np.testing.assert_array_equal(rec.rudder_cmd[k], rudder)


def test_first_record_is_the_initial_state_at_t0(tmp_path):
    scn = _scenario(tmp_path, [_ship("a", "cargo", 100, -200, 270, 12)],
                    head="environment:\n  current: {speed_kn: 1, towards_deg: 0}\n")
    rec, _ = record_run(_start(scn), 5, 5)
    assert rec.t[0] == 0.0
    x0 = rec.x[0, :, 0]
    assert (x0[NORTH], x0[EAST]) == (100.0, -200.0)
    assert x0[PSI] == pytest.approx(1.5 * math.pi)
    assert (x0[U], x0[V]) == (pytest.approx(12 * KN), 0.0)
    # ground velocity: 12 kn west through the water plus 1 kn of current north
    np.testing.assert_allclose(rec.vel[0, :, 0], [1 * KN, -12 * KN], atol=1e-12)
    assert rec.course_order[0, 0] == pytest.approx(1.5 * math.pi)  # no route: keep heading
    for row in (NORTH, EAST, PSI, R):  # no instruments: the estimate is the truth
        assert rec.est[0, row, 0] == rec.x[0, row, 0]
    assert np.isnan(rec.meas[0]).all() and rec.tracks is None


def test_trajectory_columns_are_in_the_units_their_names_say(tmp_path):
    """10 s straight west at 12 kn through the water in 1 kn of current towards north."""
    scn = _scenario(tmp_path, [_ship("a", "cargo", 100, -200, 270, 12)],
                    head="environment:\n  current: {speed_kn: 1, towards_deg: 0}\n")
    sim = _start(scn)
    rec, _ = record_run(sim, 10, 10)
    col = rec.columns(sim.batch)
    assert col["t_s"].tolist() == [0.0, 10.0] and col["ship"] == ["a", "a"]
    assert col["encounter"].tolist() == [0, 0]
    np.testing.assert_allclose(col["north_m"], [100.0, 100.0 + 10 * KN], rtol=1e-12)
    np.testing.assert_allclose(col["east_m"], [-200.0, -200.0 - 120 * KN], rtol=1e-12)
    np.testing.assert_allclose(col["heading_deg"], 270.0, rtol=1e-12)
    np.testing.assert_allclose(col["course_order_deg"], 270.0, rtol=1e-12)
    np.testing.assert_allclose(col["u_mps"], 12 * KN, rtol=1e-12)
    np.testing.assert_allclose(col["sog_kn"], math.hypot(12.0, 1.0), rtol=1e-12)
    np.testing.assert_allclose(col["cog_deg"], 270.0 + math.degrees(math.atan(1 / 12)),
                               rtol=1e-12)
    rps = sim.batch.rps_for_speed(np.array([12 * KN]))[0]
    np.testing.assert_allclose(col["rpm"], 60.0 * rps, rtol=1e-9)
    np.testing.assert_allclose(col["r_degps"], 0.0, atol=1e-12)
    np.testing.assert_allclose(col["rudder_deg"], 0.0, atol=1e-12)
    np.testing.assert_allclose(col["rudder_cmd_deg"], 0.0, atol=1e-12)


def test_without_instruments_the_estimate_columns_repeat_the_truth(tmp_path):
    sim = _start(_scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, 12, route="[[2000, 1500]]"),
                                      _ship("b", "container", 3000, 0, 200)]))
    rec, _ = record_run(sim, 20, 5)
    col = rec.columns(sim.batch)
    assert len(col["t_s"]) == 2 * 5
    for est, truth in (("est_north_m", "north_m"), ("est_east_m", "east_m"),
                       ("est_heading_deg", "heading_deg"), ("est_r_degps", "r_degps"),
                       ("est_sog_kn", "sog_kn"), ("est_cog_deg", "cog_deg")):
        np.testing.assert_allclose(col[est], col[truth], rtol=1e-12, atol=1e-9, err_msg=est)
    assert np.isnan(col["gnss_north_m"]).all() and np.isnan(col["compass_heading_deg"]).all()
    assert not col["gnss_valid"].any()


def test_without_instruments_the_estimated_sog_and_cog_include_the_current(tmp_path):
    scn = _scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, 12)],
                    head="environment:\n  current: {speed_kn: 1, towards_deg: 90}\n")
    sim = _start(scn)
    rec, _ = record_run(sim, 10, 10)
    col = rec.columns(sim.batch)
    np.testing.assert_allclose(col["sog_kn"], math.hypot(12.0, 1.0), rtol=1e-12)
    np.testing.assert_allclose(col["est_sog_kn"], col["sog_kn"], rtol=1e-9)  # 12.0 vs 12.04
    np.testing.assert_allclose(col["est_cog_deg"], col["cog_deg"], atol=1e-9)  # 0 vs 4.76 deg


def test_on_record_is_called_after_each_record_with_that_record_made(tmp_path):
    seen = []
    rec, _ = record_run(_start(_pair(tmp_path)), 12, 4,
                        lambda r, sim: seen.append((r.count, float(r.t[r.count - 1]), sim.t_s)))
    assert seen == [(1, 0.0, 0.0), (2, 4.0, 4.0), (3, 8.0, 8.0), (4, 12.0, 12.0)]
    assert rec.count == 4


def test_wall_time_leaves_out_the_hook(tmp_path):
    hook_timed = 0.0

    def slow_hook(rec, sim):
        nonlocal hook_timed
        t0 = time.perf_counter()
        time.sleep(0.01)
        if sim.step_index >= 2:  # the records inside the timed steps 2 .. n
            hook_timed += time.perf_counter() - t0

    t0 = time.perf_counter()
    _, wall = record_run(_start(_pair(tmp_path)), 20, 1, slow_hook)
    elapsed = time.perf_counter() - t0
    assert hook_timed > 0.18
    assert 0.0 < wall <= elapsed - hook_timed


def test_wall_time_leaves_out_the_first_step_and_its_records(tmp_path):
    def hook(rec, sim):
        if sim.step_index < 2:  # the record at t = 0 and after the first step
            time.sleep(0.1)

    _, wall = record_run(_start(_pair(tmp_path)), 20, 1, hook)
    assert 0.0 < wall < 0.1


def test_instruments_are_recorded_beside_the_truth(tmp_path):
    """DGPS sigma 2 m and a gyro of sigma 0.3 deg: the recorded fixes and compass readings
    scatter about the true state of the same time; the pv filter's estimate lies closer."""
    sim = _start(_instrumented(tmp_path))
    rec, _ = record_run(sim, 60, 1)
    k = rec.count
    assert k == 61
    x, meas, est = rec.x[:k], rec.meas[:k], rec.est[:k]
    assert (meas[:, 2] == 1.0).all()  # every fix valid
    fix_err = np.stack([meas[:, 0] - x[:, NORTH], meas[:, 1] - x[:, EAST]])
    assert 1.4 < fix_err[0].std() < 2.8 and 1.4 < fix_err[1].std() < 2.8
    assert abs(fix_err.mean()) < 0.5
    compass_err = np.degrees(_wrapped(meas[:, 3] - x[:, PSI]))
    assert 0.2 < compass_err.std() < 0.45
    est_err = np.hypot(est[:, NORTH] - x[:, NORTH], est[:, EAST] - x[:, EAST])
    fix_rms = np.sqrt(np.mean(fix_err[0] ** 2 + fix_err[1] ** 2))
    assert 0.0 < np.sqrt(np.mean(est_err**2)) < 0.75 * fix_rms
    col = rec.columns(sim.batch)
    np.testing.assert_array_equal(col["gnss_north_m"], meas[:, 0].ravel())
    assert col["gnss_valid"].all()


def test_tracks_hold_each_observers_prediction_of_the_target(tmp_path):
    sim = _start(_instrumented(tmp_path))
    rec, _ = record_run(sim, 60, 5)
    cols = rec.track_columns(sim)
    k = rec.count
    assert k == 13 and len(cols["t_s"]) == 2 * k
    assert cols["observer"][:2] == ["own", "other"] and cols["target"][:2] == ["other", "own"]
    names = sim.batch.names
    for row, (t, target) in enumerate(zip(cols["t_s"], cols["target"], strict=True)):
        j = names.index(target)
        assert t == rec.t[row // 2]
        assert cols["north_m"][row] == rec.x[row // 2, NORTH, j]
        assert cols["east_m"][row] == rec.x[row // 2, EAST, j]
    tracked = cols["tracked"]
    assert np.isnan(cols["track_north_m"][~tracked]).all()
    np.testing.assert_allclose(cols["error_m"][tracked], np.hypot(
        cols["track_north_m"] - cols["north_m"], cols["track_east_m"] - cols["east_m"])[tracked])
    # after a minute each ship tracks the other at its ground speed and course:
    # own 12 kn north + 1 kn east, other 10 kn south + 1 kn east
    assert tracked[-2:].all()
    own_sog, own_cog = math.hypot(12, 1), math.degrees(math.atan2(1, 12))
    other_sog, other_cog = math.hypot(10, 1), 180.0 - math.degrees(math.atan2(1, 10))
    np.testing.assert_allclose(cols["track_sog_kn"][-2:], [other_sog, own_sog], atol=0.5)
    np.testing.assert_allclose(cols["track_cog_deg"][-2:], [other_cog, own_cog], atol=2.0)
    assert (cols["error_m"][-2:] < 30.0).all()


def test_no_tracks_without_radar_or_ais(tmp_path):
    sim = _start(_pair(tmp_path))
    rec, _ = record_run(sim, 5, 1)
    assert rec.tracks is None and rec.track_columns(sim) is None


# --- summary ---------------------------------------------------------------------------------


def _summary(sim, n_steps, wall=1.0, timed=1, every_s=1.0, header=None):
    return run_summary(header or {"scenario": "t"}, sim, n_steps, wall, timed, every_s,
                       "coldwell")


def test_summary_pairs_in_closed_form(tmp_path):
    sim = _start(_pair(tmp_path))
    record_run(sim, 20, 5)
    (pair,) = _summary(sim, 20)["pairs"]
    closing = 20 * KN  # 10 kn each on reciprocal courses
    assert (pair["ship_a"], pair["ship_b"]) == ("a", "b")
    assert pair["dcpa_m"] == pytest.approx(100.0, rel=1e-9)
    assert pair["tcpa_s"] == pytest.approx(2000.0 / closing, rel=1e-9)
    # still closing at the end: the minimum range is the last one
    assert pair["min_range_m"] == pytest.approx(math.hypot(2000.0 - 20 * closing, 100.0),
                                                rel=1e-9)
    assert pair["t_min_range_s"] == 20.0
    assert pair["collision"] is False and math.isnan(pair["t_collision_s"])


def test_summary_reports_a_hull_overlap_collision(tmp_path):
    """cargo (L 160.93 m) and container (L 175 m) head-on on one line, 400 m apart, 10 kn each:
    the bows meet when the centres are (160.93 + 175) / 2 m apart."""
    sim = _start(_scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, 10),
                                      _ship("b", "container", 400, 0, 180, 10)], 40))
    record_run(sim, 40, 10)
    summary = _summary(sim, 40)
    (pair,) = summary["pairs"]
    touch_s = (400.0 - (160.93 + 175.0) / 2) / (20 * KN)
    assert pair["collision"] is True and summary["collisions"] == 1
    assert touch_s <= pair["t_collision_s"] < touch_s + 1.0  # found at the next step
    assert pair["domain_violation"] is True and summary["domain_violations"] == 1


def test_summary_ships_in_metres_and_compass_degrees(tmp_path):
    sim = _start(_scenario(tmp_path, [
        _ship("a", "cargo", 100, -200, 270, 12),
        _ship("b", "container", 0, 0, 5, route="[[2000, -2000], [4000, -4000]]",
              behaviour="turn_port")], 120))
    record_run(sim, 120, 10)
    a, b = _summary(sim, 120)["ships"]
    assert (a["name"], a["type"], a["behaviour"]) == ("a", "cargo", "keep_course")
    assert (b["name"], b["type"], b["behaviour"]) == ("b", "container", "turn_port")
    assert a["north_m"] == pytest.approx(100.0, abs=1e-9)
    assert a["east_m"] == pytest.approx(-200.0 - 120 * 12 * KN, rel=1e-12)
    assert a["heading_deg"] == pytest.approx(270.0, rel=1e-12)
    # b turned to port through north towards its route (bearing 315): a compass heading
    assert 290.0 < b["heading_deg"] < 360.0
    assert b["heading_deg"] == pytest.approx(math.degrees(sim.batch.x[PSI, 1]) % 360.0)
    for s, spec in ((a, load_ship("cargo")), (b, load_ship("container"))):
        assert s["length_m"] == spec["particulars"]["length_m"]
        assert s["beam_m"] == spec["particulars"]["beam_m"]
    assert a["route_m"] == [] and b["route_m"] == [[2000.0, -2000.0], [4000.0, -4000.0]]
    assert b["route_done"] is False


def test_summary_route_done_once_the_last_waypoint_is_passed(tmp_path):
    sim = _start(_scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, 10, route="[[300, 0]]")], 60))
    record_run(sim, 60, 10)
    assert _summary(sim, 60)["ships"][0]["route_done"] is True


def test_summary_header_rates_and_metadata(tmp_path):
    sim = _start(_pair(tmp_path))
    record_run(sim, 10, 5)
    header = {"scenario": "t", "scenario_file": "s.yaml", "seed": 0, "duration_s": 10.0,
              "dt_s": 1.0}
    summary = _summary(sim, 10, wall=2.0, timed=9, every_s=5.0, header=header)
    assert list(summary)[:5] == list(header)
    assert {k: summary[k] for k in header} == header
    assert summary["n_ships"] == 2 and summary["n_steps"] == 10
    assert summary["record_every_s"] == 5.0 and summary["wall_time_s"] == 2.0
    assert summary["ship_steps_per_s"] == pytest.approx(2 * 9 / 2.0)
    assert summary["domain"] == "coldwell"
    assert summary["blind_spots"] == [] and summary["diverged_at_s"] is None
    assert summary["versions"]["trafficsim"] == __version__
    assert summary["versions"]["numpy"] == np.__version__


# --- run folders -----------------------------------------------------------------------------


def test_write_run_without_instruments_or_decisions(tmp_path):
    sim = _start(_pair(tmp_path))
    rec, wall = record_run(sim, 20, 5)
    summary = _summary(sim, 20, wall)
    out = tmp_path / "nested" / "out"
    write_run(out, rec, sim, summary)
    assert sorted(p.name for p in out.iterdir()) == ["summary.json", "trajectories.parquet"]
    table = pq.read_table(out / "trajectories.parquet").to_pydict()
    assert table["t_s"] == [0.0, 0.0, 5.0, 5.0, 10.0, 10.0, 15.0, 15.0, 20.0, 20.0]
    assert table["ship"] == ["a", "b"] * 5
    np.testing.assert_allclose(table["north_m"][-2:], [20 * 10 * KN, 2000 - 20 * 10 * KN],
                               rtol=1e-12)
    stored = json.loads((out / "summary.json").read_text())
    assert stored["pairs"][0]["t_collision_s"] is None  # NaN is written as null
    assert stored["pairs"][0]["dcpa_m"] == summary["pairs"][0]["dcpa_m"]
    assert stored["n_steps"] == 20 and stored["ships"][1]["heading_deg"] == 180.0


def test_write_run_adds_tracks_and_decisions_when_there_are_any(tmp_path):
    scn = _instrumented(tmp_path, 30, other_behaviour="colregs")
    for record, files in ((True, ["decisions.parquet", "summary.json", "tracks.parquet",
                                  "trajectories.parquet"]),
                          (False, ["summary.json", "tracks.parquet", "trajectories.parquet"])):
        sim = _start(scn, record=record)
        rec, wall = record_run(sim, 30, 5)
        out = tmp_path / f"out_{record}"
        write_run(out, rec, sim, _summary(sim, 30, wall))
        assert sorted(p.name for p in out.iterdir()) == files
    traj = pq.read_table(out / "trajectories.parquet").to_pydict()
    tracks = pq.read_table(out / "tracks.parquet").to_pydict()
    assert len(tracks["t_s"]) == 2 * 7
    # the target's true position beside each track is the trajectories' row of that ship
    truth = {(t, s): (n, e) for t, s, n, e in zip(traj["t_s"], traj["ship"], traj["north_m"],
                                                   traj["east_m"], strict=True)}
    for t, s, n, e in zip(tracks["t_s"], tracks["target"], tracks["north_m"], tracks["east_m"],
                          strict=True):
        assert truth[(t, s)] == (n, e)
    decisions = pq.read_table(tmp_path / "out_True" / "decisions.parquet").to_pydict()
    assert set(decisions["ship"]) == {"other"}  # only the ship that decides
    assert {0.0, 10.0, 20.0, 30.0} <= set(decisions["t_s"])  # every decision period


def test_run_scenario_records_every_record_period_with_a_fractional_step(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("schema_version: 1\nname: half\nduration_s: 10\ndt_s: 0.5\n"
                    "record_every_s: 2.0\nseed: 7\nships:\n"
                    + _ship("a", "cargo", 0, 0, 90, 10))
    summary = run_scenario(path, tmp_path / "out")
    assert summary["n_steps"] == 20 and summary["record_every_s"] == 2.0
    assert (summary["scenario"], summary["seed"], summary["dt_s"]) == ("half", 7, 0.5)
    assert summary["scenario_file"] == str(path)
    table = pq.read_table(tmp_path / "out" / "trajectories.parquet").to_pydict()
    assert table["t_s"] == [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
    np.testing.assert_allclose(table["east_m"], 10 * KN * np.array(table["t_s"]), rtol=1e-12)


# --- a run whose state stops being finite ----------------------------------------------------


def _runaway(tmp_path, n_steps=40):
    """A bulk carrier whose resistance pushes: it accelerates without bound and its state
    overflows after some seconds."""
    ship = (LIBRARY_DIR / "bulk_carrier.yaml").read_text()
    assert "  a1: -1.4347e-4\n" in ship
    (tmp_path / "runaway.yaml").write_text(ship.replace("  a1: -1.4347e-4\n", "  a1: 1.0e-2\n"))
    return _scenario(tmp_path, [_ship("a", "runaway.yaml", 0, 0, 0)], n_steps)


def _diverge_step(tmp_path):
    """The step k whose state is not finite, and the last finite state (at step k - 1)."""
    sim = _start(_runaway(tmp_path), isolate=True)
    rec, _ = record_run(sim, 40, 1)
    k = round(float(sim.diverged_at_s[0]) / sim.dt) + 1
    assert 2 < k < 40 and np.isfinite(rec.x[k - 1]).all()
    return k, rec.x[k - 1].copy()


def test_a_diverging_run_ends_its_record_with_the_frozen_state(tmp_path):
    k, last_finite = _diverge_step(tmp_path)
    sim = _start(_runaway(tmp_path), isolate=True)
    rec, _ = record_run(sim, 40, 40)  # records planned at 0 and 40 only
    assert sim.all_diverged and sim.step_index == k  # stopped stepping
    assert rec.count == 2 and rec.t[1] == k * sim.dt == sim.diverged_at_s[0] + sim.dt
    np.testing.assert_array_equal(rec.x[1], last_finite)
    np.testing.assert_array_equal(sim.batch.x, last_finite)  # frozen there


@pytest.mark.parametrize("case", ["every step", "record step", "last step"])
def test_a_diverging_run_ends_its_record_at_the_step_that_diverged(tmp_path, case):
    k, last_finite = _diverge_step(tmp_path)
    n_steps, every = {"every step": (40, 1), "record step": (40, k),
                      "last step": (k, k - 2)}[case]
    sim = _start(_runaway(tmp_path, n_steps), isolate=True)
    rec, _ = record_run(sim, n_steps, every)
    assert sim.step_index == k
    assert rec.t[rec.count - 1] == k * sim.dt
    np.testing.assert_array_equal(rec.x[rec.count - 1], last_finite)


def test_raise_if_diverged_names_ships_time_and_folder(tmp_path):
    k, _ = _diverge_step(tmp_path)
    sim = _start(_runaway(tmp_path), isolate=True)
    record_run(sim, 40, 5)
    with pytest.raises(SimulationError) as err:
        raise_if_diverged(sim, tmp_path / "o")
    assert str(err.value) == (f"state became non-finite at t = {k} s for ships a; reduce dt_s "
                              f"or check the ship files (the run up to then is in "
                              f"{tmp_path / 'o'})")
    summary = _summary(sim, 40)
    assert summary["diverged_at_s"] == (k - 1) * sim.dt
    finite = _start(_pair(tmp_path), isolate=True)
    record_run(finite, 5, 5)
    raise_if_diverged(finite, tmp_path / "o")  # nothing to report
    assert _summary(finite, 5)["diverged_at_s"] is None


def test_rudder_and_rpm_columns_are_the_state_in_degrees_and_per_minute(tmp_path):
    """Rudder and propeller rows: a turning ship's rudder angle in degrees, rpm = 60 rps."""
    sim = _start(_scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, 12, route="[[500, 2000]]")]))
    rec, _ = record_run(sim, 20, 20)
    col = rec.columns(sim.batch)
    np.testing.assert_allclose(col["rudder_deg"][-1], math.degrees(rec.x[1, RUDDER, 0]))
    np.testing.assert_allclose(col["rpm"][-1], 60.0 * rec.x[1, RPS, 0])
    assert col["rudder_deg"][-1] > 1.0  # turning to starboard towards the waypoint
    np.testing.assert_allclose(col["rudder_cmd_deg"][-1], math.degrees(rec.rudder_cmd[1, 0]))


# --- end to end: what run_scenario writes -----------------------------------------------------


def test_run_scenario_writes_a_summary_equal_to_the_one_it_returns(tmp_path):
    """summary.json is the returned summary (NaN written as null), trajectories hold one row
    per ship and record, the record period being the scenario's."""
    path = tmp_path / "s.yaml"
    path.write_text("schema_version: 1\nname: pair\nduration_s: 30\nrecord_every_s: 5\n"
                    "ships:\n" + _ship("a", "cargo", 0, 0, 0, 10)
                    + _ship("b", "container", 2000, 100, 180, 10))
    summary = run_scenario(path, tmp_path / "out")
    stored = json.loads((tmp_path / "out" / "summary.json").read_text())

    def nan_to_none(value):
        if isinstance(value, float) and math.isnan(value):
            return None
        if isinstance(value, dict):
            return {k: nan_to_none(v) for k, v in value.items()}
        if isinstance(value, list):
            return [nan_to_none(v) for v in value]
        return value

    assert stored == nan_to_none(summary)
    table = pq.read_table(tmp_path / "out" / "trajectories.parquet").to_pydict()
    assert table["t_s"] == [t for t in (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0) for _ in "ab"]
    assert not (tmp_path / "out" / "decisions.parquet").exists()  # keep_course: no decider


def test_three_ships_give_three_pairs_each_with_its_closed_form_cpa(tmp_path):
    """a (0, 0) north 10 kn, b (3000, 500) south 10 kn, c (1000, -2000) east 8 kn, all holding
    course: DCPA and TCPA of each pair from the relative position d and velocity w,
    tcpa = -d.w / |w|^2, dcpa = |d + w tcpa|."""
    scn = _scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, 10),
                               _ship("b", "container", 3000, 500, 180, 10),
                               _ship("c", "cargo", 1000, -2000, 90, 8)], 30)
    sim = _start(scn)
    record_run(sim, 30, 10)
    pairs = _summary(sim, 30)["pairs"]
    pos = {"a": (0.0, 0.0), "b": (3000.0, 500.0), "c": (1000.0, -2000.0)}
    vel = {"a": (10 * KN, 0.0), "b": (-10 * KN, 0.0), "c": (0.0, 8 * KN)}
    assert [(p["ship_a"], p["ship_b"]) for p in pairs] == [("a", "b"), ("a", "c"), ("b", "c")]
    for p in pairs:
        i, j = p["ship_a"], p["ship_b"]
        d = np.subtract(pos[j], pos[i])
        w = np.subtract(vel[j], vel[i])
        tcpa = -d @ w / (w @ w)
        assert p["tcpa_s"] == pytest.approx(tcpa, rel=1e-9)
        assert p["dcpa_m"] == pytest.approx(np.hypot(*(d + w * tcpa)), rel=1e-9)
        # 30 s of straight running: every range still closes, the last one is the least
        assert p["min_range_m"] == pytest.approx(np.hypot(*(d + 30.0 * w)), rel=1e-9)


def test_decisions_are_recorded_every_decision_period_of_the_scenario(tmp_path):
    """decision_period_s 20 with dt 0.5: decision steps at 0, 20, 40, 60 s of a 70 s run, for
    both (colregs) ships and about the other."""
    path = tmp_path / "s.yaml"
    path.write_text("schema_version: 1\nname: d\nduration_s: 70\ndt_s: 0.5\n"
                    "decision_period_s: 20\nships:\n"
                    + _ship("a", "cargo", 0, 0, 0, 12, behaviour="colregs")
                    + _ship("b", "container", 5000, 200, 180, 12, behaviour="colregs"))
    run_scenario(path, tmp_path / "out")
    dec = pq.read_table(tmp_path / "out" / "decisions.parquet").to_pydict()
    assert dec["t_s"] == [0.0, 0.0, 20.0, 20.0, 40.0, 40.0, 60.0, 60.0]
    assert dec["ship"] == ["a", "b"] * 4 and dec["other"] == ["b", "a"] * 4


def test_a_scenarios_rules_file_is_found_relative_to_the_scenario(tmp_path):
    from trafficsim.colregs.decider import RULES_DIR

    (tmp_path / "sub").mkdir()
    rules = tmp_path / "sub" / "mine.yaml"
    rules.write_text((RULES_DIR / "colregs.yaml").read_text())
    scn = _scenario(tmp_path, [_ship("a", "cargo", 0, 0, 0, behaviour="colregs"),
                               _ship("b", "cargo", 5000, 0, 180)], head="rules: sub/mine.yaml\n")
    decider = _start(scn).decider
    assert [Path(n.rules.path).resolve() for n in decider.networks] == [rules.resolve()]


def _first_step_runaway(tmp_path, n_steps):
    """The bulk carrier with a1 = 1e100: its state leaves the finite numbers in the first step
    (the last finite state is the start, t = 0)."""
    ship = (LIBRARY_DIR / "bulk_carrier.yaml").read_text()
    (tmp_path / "runaway.yaml").write_text(ship.replace("  a1: -1.4347e-4\n", "  a1: 1.0e+100\n"))
    return _scenario(tmp_path, [_ship("a", "runaway.yaml", 0, 0, 0)], n_steps)


@pytest.mark.parametrize("every", [1, 5])
def test_a_run_diverging_in_its_first_step_ends_its_record_at_that_step(tmp_path, every):
    sim = _start(_first_step_runaway(tmp_path, 20), isolate=True)
    rec, _ = record_run(sim, 20, every)
    assert sim.diverged_at_s[0] == 0.0  # the premise: non-finite after step 1
    assert sim.step_index == 1  # stopped stepping, as for a later divergence
    assert rec.t[: rec.count].tolist() == [0.0, 1.0]
    np.testing.assert_array_equal(rec.x[1], rec.x[0])  # frozen at the start


@pytest.mark.parametrize("duration", ["10.6", "2.5"])
def test_the_time_simulated_is_the_scenario_duration(tmp_path, duration):
    """A duration that is not a whole number of steps must be refused (located at duration_s)
    or simulated as reported: the last record (every step) at the reported duration."""
    from trafficsim.errors import InputError

    path = tmp_path / "s.yaml"
    path.write_text(f"schema_version: 1\nname: d\nduration_s: {duration}\nships:\n"
                    + _ship("a", "cargo", 0, 0, 0, 10))
    try:
        summary = run_scenario(path, tmp_path / "out")
    except InputError as err:
        assert "duration_s" in str(err)
        return
    t = pq.read_table(tmp_path / "out" / "trajectories.parquet").column("t_s").to_pylist()
    assert t[-1] == summary["duration_s"] == summary["n_steps"] * summary["dt_s"]
