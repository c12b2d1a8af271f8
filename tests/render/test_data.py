"""Reading run folders for drawing, and the same data taken from a running simulation."""

import json
import math

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.render.conftest import Ship
from trafficsim.errors import InputError
from trafficsim.io.results import write_parquet
from trafficsim.render.data import live_data, load_run
from trafficsim.render.decisions import DecisionTable, LiveDecisions, choose
from trafficsim.run import run_scenario
from trafficsim.units import KN


def test_a_run_folder_becomes_arrays_per_record_and_ship(synthetic_run):
    run = synthetic_run([Ship("a", 10.0, 20.0, 90.0, speed_kn=10.0, route_m=[[0, 5000]]),
                         Ship("b", 0.0, 0.0, 0.0)], 7)
    data = load_run(run)
    assert data.ships.names == ["a", "b"] and data.count == 7 and data.record_every_s == 5.0
    assert data.north_m.shape == (7, 2)
    np.testing.assert_allclose(data.east_m[:, 0], 20.0 + 10.0 * KN * data.t_s)
    np.testing.assert_allclose(data.ve_mps[:, 0], 10.0 * KN)
    np.testing.assert_allclose(data.vn_mps[:, 0], 0.0, atol=1e-12)
    assert data.ships.routes[0].tolist() == [[0.0, 5000.0]] and data.ships.routes[1].shape == (0, 2)
    assert data.has_estimate.tolist() == [True, False]
    assert data.tracks is None and data.decisions is None


def test_faulty_run_folders_are_named(synthetic_run, tmp_path):
    with pytest.raises(InputError, match="no such folder"):
        load_run(tmp_path / "absent")
    with pytest.raises(InputError, match=r"no trajectories\.parquet"):
        load_run(tmp_path)
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0), Ship("b", 9.0, 0.0, 0.0)], 3)
    summary = json.loads((run / "summary.json").read_text())
    summary["ships"] = summary["ships"][::-1]  # rows no longer in the summary's ship order
    (run / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(InputError, match="one per record and ship"):
        load_run(run)
    for s in summary["ships"]:
        del s["route_m"]  # a summary.json of an older version
    (run / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(InputError, match="older trafficsim") as err:
        load_run(run)
    assert err.value.path.endswith("summary.json")
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0)], 3)
    table = pq.read_table(run / "trajectories.parquet").drop_columns(["est_north_m"])
    write_parquet(run / "trajectories.parquet", table.to_pydict())
    with pytest.raises(InputError, match="columns missing: est_north_m"):
        load_run(run)


def test_the_decision_shown_asks_something_else_holds_a_role_closest_first():
    cols = {"t_s": [10.0] * 4, "ship": ["a", "a", "a", "b"], "other": ["b", "c", "d", "a"],
            "rules": ["/x/colregs.yaml"] * 4, "path": ["assess>risk", "keep_clear",
                                                      "assess>risk>stand_on", ""],
            "decided_own_role": ["no_role", "give_way", "stand_on", "no_role"],
            "decided_encounter": ["no_encounter", "crossing", "head_on", "no_encounter"],
            "decided_own_manoeuvre": ["no_action", "alter_course", "keep", "no_action"],
            "course_order_deg": [math.nan, 35.0, math.nan, math.nan],
            "range_nm": [0.5, 3.0, 1.0, 0.5]}
    shown = choose(cols, range(4))
    assert shown["a"].other == "c" and shown["a"].node == "keep_clear"
    assert shown["a"].line("a") == ("a -> c: give way, crossing; alter course to 035 deg  "
                                    "[colregs.yaml: keep_clear]")
    cols["decided_own_manoeuvre"][1] = "keep"
    assert choose(cols, range(4))["a"].other == "d"  # both hold roles: the closer
    assert choose(cols, range(4))["b"].line("b") == "b -> a: no role; no action  [colregs.yaml: ]"
    table = DecisionTable({k: v * 2 if k != "t_s" else [10.0] * 4 + [20.0] * 4
                           for k, v in cols.items()})
    assert table.at(5.0) == {} and table.at(10.0)["a"].t_s == 10.0
    assert table.at(19.9)["a"].t_s == 10.0 and table.at(25.0)["a"].t_s == 20.0


def test_live_data_and_decisions_match_the_run_folder(tiny_scenario, tmp_path):
    seen = {}

    def hook(rec, sim):
        if "data" not in seen:
            seen["data"] = live_data(rec, sim, "tiny", 5.0, 400.0)
            seen["live"] = LiveDecisions(sim.decider, sim.batch.names)
            seen["decisions"] = []
        k = rec.count - 1
        data = seen["data"]
        seen["decisions"].append(seen["live"].at(float(rec.t[k])))
        seen.setdefault("rows", []).append(
            (data.north_m[k].copy(), data.vn_mps[k].copy(), data.gnss_north_m[k].copy(),
             data.tracks.north_m[k].copy()))

    run_scenario(tiny_scenario(), tmp_path / "out", hook)
    disk = load_run(tmp_path / "out")
    assert disk.decisions is not None and disk.tracks is not None
    for k, (north, vn, gnss, track) in enumerate(seen["rows"]):
        np.testing.assert_allclose(north, disk.north_m[k], rtol=0, atol=1e-9)
        np.testing.assert_allclose(vn, disk.vn_mps[k], rtol=0, atol=1e-9)
        np.testing.assert_allclose(gnss, disk.gnss_north_m[k], rtol=0, atol=1e-9)
        np.testing.assert_allclose(track, disk.tracks.north_m[k], rtol=0, atol=1e-9)
        live, stored = seen["decisions"][k], disk.decisions.at(float(disk.t_s[k]))
        assert {s: (d.t_s, d.line(s)) for s, d in live.items()} == {
            s: (d.t_s, d.line(s)) for s, d in stored.items()}
    assert any(d.get("own") and d["own"].has_role for d in seen["decisions"])
    assert seen["data"].has_estimate.tolist() == disk.has_estimate.tolist() == [True, False]


def _edit_summary(run, edit):
    path = run / "summary.json"
    summary = json.loads(path.read_text())
    edit(summary)
    path.write_text(json.dumps(summary))


def test_optional_summary_keys_have_their_fallbacks(synthetic_run):
    """Without record_every_s, duration_s, scenario and domain in summary.json: the interval
    is the first time step of the table (5 s), the duration its last time (4 records: 15 s),
    the name the folder's, the domain Coldwell's."""
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0), Ship("b", 900.0, 0.0, 0.0)], 4)

    def strip(s):
        for key in ("record_every_s", "duration_s", "scenario", "domain", "pairs"):
            del s[key]

    _edit_summary(run, strip)
    data = load_run(run)
    assert data.record_every_s == 5.0 and data.duration_s == 15.0
    assert data.name == run.name and data.domain == "coldwell"
    assert data.collisions.t_s.shape == (0,)
    one = synthetic_run([Ship("a", 0.0, 0.0, 0.0)], 1)
    _edit_summary(one, strip)
    assert load_run(one).record_every_s == 1.0  # a single record: no step to infer


def test_collisions_keep_a_collision_at_time_zero(synthetic_run):
    """Pairs map to ship indices by name; a collision at t = 0 is a time (not 'never'); a pair
    without collision, or flagged without a time, is NaN."""
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0), Ship("b", 10.0, 0.0, 0.0),
                         Ship("c", 20.0, 0.0, 0.0)], 3)

    def collide(s):
        s["pairs"][0].update(collision=True, t_collision_s=0.0)  # a-b
        s["pairs"][1].update(collision=False, t_collision_s=None)  # a-c
        s["pairs"][2].update(collision=True, t_collision_s=None)  # b-c

    _edit_summary(run, collide)
    c = load_run(run).collisions
    assert c.ship_a.tolist() == [0, 0, 1] and c.ship_b.tolist() == [1, 2, 2]
    assert c.t_s[0] == 0.0 and np.isnan(c.t_s[1]) and np.isnan(c.t_s[2])


def test_a_pair_naming_an_unknown_ship_is_refused(synthetic_run):
    """A pair whose ship is not in summary.json's ships would otherwise be drawn on ship 0."""
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0), Ship("b", 10.0, 0.0, 0.0)], 3)
    _edit_summary(run, lambda s: s["pairs"][0].update(ship_b="z"))
    with pytest.raises(InputError, match="pairs: ship_b 'z' is not one of the ships") as err:
        load_run(run)
    assert err.value.path == str(run / "summary.json")


def test_summary_missing_or_damaged_names_the_file(synthetic_run, tmp_path):
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0)], 3)
    (run / "summary.json").write_text("{not json")
    with pytest.raises(InputError, match="unreadable") as err:
        load_run(run)
    assert err.value.path == str(run / "summary.json")
    (run / "summary.json").unlink()
    with pytest.raises(InputError, match="missing") as err:
        load_run(run)
    assert err.value.path == str(run / "summary.json")
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        load_run(tmp_path / "file")
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0)], 3)
    (run / "trajectories.parquet").write_bytes(b"PAR1 damaged")
    with pytest.raises(InputError, match="unreadable") as err:
        load_run(run)
    assert err.value.path == str(run / "trajectories.parquet")


def _write_tracks(run, n_records, pairs, sog_kn=10.0, cog_deg=90.0):
    m = len(pairs)
    write_parquet(run / "tracks.parquet", {
        "t_s": np.repeat(np.arange(n_records) * 5.0, m),
        "observer": [p[0] for p in pairs] * n_records,
        "target": [p[1] for p in pairs] * n_records,
        "tracked": np.tile([True, False][:m], n_records),
        "track_north_m": np.arange(n_records * m, dtype=float),
        "track_east_m": -np.arange(n_records * m, dtype=float),
        "track_sog_kn": np.full(n_records * m, sog_kn),
        "track_cog_deg": np.full(n_records * m, cog_deg)})


def test_tracks_file_becomes_record_by_pair_arrays(synthetic_run):
    """Rows one per record and observer-target pair (record-major, as ``trafficsim run``
    writes them): the pair order comes from the first record; a track of 10 kn on a course
    of 090 moves 10 * 1852 / 3600 m/s east and nothing north."""
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0), Ship("b", 900.0, 0.0, 0.0)], 4)
    _write_tracks(run, 4, [("a", "b"), ("b", "a")])
    tr = load_run(run).tracks
    assert tr.observer.tolist() == [0, 1] and tr.target.tolist() == [1, 0]
    assert tr.north_m.shape == (4, 2)
    np.testing.assert_array_equal(tr.north_m[2], [4.0, 5.0])  # rows 4, 5 of the file
    np.testing.assert_array_equal(tr.east_m[3], [-6.0, -7.0])
    np.testing.assert_allclose(tr.ve_mps, 10.0 * KN)
    np.testing.assert_allclose(tr.vn_mps, 0.0, atol=1e-12)
    assert tr.tracked.tolist() == [[True, False]] * 4


def test_damaged_tracks_file_is_named(synthetic_run):
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0), Ship("b", 900.0, 0.0, 0.0)], 4)
    _write_tracks(run, 3, [("a", "b"), ("b", "a")])  # 6 rows for 4 records
    with pytest.raises(InputError, match="one row per record") as err:
        load_run(run)
    assert err.value.path == str(run / "tracks.parquet")
    _write_tracks(run, 4, [("a", "zed")])
    with pytest.raises(InputError, match="unknown ship 'zed'") as err:
        load_run(run)
    assert err.value.path == str(run / "tracks.parquet")


def test_a_radar_with_no_other_ship_gives_an_empty_tracks_table_that_loads(tmp_path):
    """A lone ship with radar writes a tracks file without rows: it loads as no pairs."""
    scenario = tmp_path / "lone.yaml"
    scenario.write_text("schema_version: 1\nname: lone\nduration_s: 20\nrecord_every_s: 5\n"
                        "ships:\n  - {name: own, type: cargo, north_m: 0, east_m: 0, "
                        "heading_deg: 0, filter: pv, sensors: {radar: {}}}\n")
    run_scenario(scenario, tmp_path / "out")
    assert pq.read_table(tmp_path / "out" / "tracks.parquet").num_rows == 0
    tracks = load_run(tmp_path / "out").tracks
    assert tracks.observer.shape == (0,) and tracks.north_m.shape == (5, 0)
    assert tracks.tracked.shape == (5, 0)


def test_has_estimate_is_a_difference_beyond_a_micrometre(synthetic_run):
    """A ship's estimate counts as a filter's only if it leaves the truth by more than 1e-6 m
    somewhere: rounding noise of 1e-9 m is still 'the truth'."""
    run = synthetic_run([Ship("a", 0.0, 0.0, 0.0), Ship("b", 900.0, 0.0, 0.0)], 3)
    table = pq.read_table(run / "trajectories.parquet").to_pydict()
    table["est_north_m"] = [v + (1e-9 if s == "a" else 0.0)
                            for v, s in zip(table["north_m"], table["ship"], strict=True)]
    table["est_east_m"] = [v + (2e-6 if (s == "b" and t == 5.0) else 0.0)
                           for v, s, t in zip(table["east_m"], table["ship"], table["t_s"],
                                              strict=True)]
    write_parquet(run / "trajectories.parquet", table)
    data = load_run(run)
    assert data.has_estimate.tolist() == [False, True]
    assert data.gnss_valid.dtype == bool and data.gnss_valid.all()
