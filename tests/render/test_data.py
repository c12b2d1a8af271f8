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
