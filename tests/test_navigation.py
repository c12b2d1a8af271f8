"""Ships steer on what their instruments and filters tell them; outcomes are measured on truth."""

import numpy as np
import pytest

from tests.conftest import SCENARIOS
from trafficsim.batch import EncounterEnv, ShipSetup, build_batch
from trafficsim.engine import Simulation
from trafficsim.errors import ScenarioError
from trafficsim.io.scenario import load_scenario
from trafficsim.ships.base import EAST, NORTH, PSI
from trafficsim.ships.library import load_ship
from trafficsim.units import from_kn

ROUTE = [[4000.0, 0.0], [8000.0, 3000.0], [8000.0, 9000.0]]
CURRENT = EncounterEnv(0.4, 1.0, 0.0, 0.0)


def _ship(name="a", k=0, sensors=None, filt="pv", route=ROUTE, north=0.0):
    spec = load_ship("container")
    return ShipSetup(name, spec, 0, north, 0.0, 0.0, from_kn(16.0),
                     np.asarray(route, float), ship_in_encounter=k, sensors=sensors or {},
                     filter=filt)


def _run(ships, seconds=1500, seed=3, env=CURRENT):
    sim = Simulation.start(build_batch(ships, [env]), 1.0, seed)
    truth, est, fixes = [], [], []
    for _ in range(seconds):
        sim.step()
        truth.append(sim.batch.x[[NORTH, EAST, PSI]].copy())
        est.append(sim.nav.est[[NORTH, EAST, PSI]].copy())
        fixes.append(np.stack([sim.nav.fix.north_m, sim.nav.fix.east_m]))
    return sim, np.array(truth), np.array(est), np.array(fixes)


def test_without_instruments_the_estimate_is_the_truth():
    sim = Simulation.start(build_batch([_ship(filt="none")], [EncounterEnv()]), 1.0)
    assert sim.nav is None


def test_pv_filter_beats_raw_fixes_and_the_ship_still_follows_its_route():
    sensors = {"gnss": {"sigma_m": 5.0}, "compass": {"sigma_deg": 0.5}}
    sim, truth, est, fixes = _run([_ship(sensors=sensors)])
    err_est = np.hypot(*(est[:, :2, 0] - truth[:, :2, 0]).T)
    err_fix = np.hypot(*(fixes[:, :, 0] - truth[:, :2, 0]).T)
    assert np.sqrt(np.mean(err_est[100:] ** 2)) < 0.6 * np.sqrt(np.mean(err_fix[100:] ** 2))
    heading_err = np.degrees((est[:, 2, 0] - truth[:, 2, 0] + np.pi) % (2 * np.pi) - np.pi)
    assert np.sqrt(np.mean(heading_err[100:] ** 2)) < 0.5
    assert sim.route.wp_index[0] >= 2  # steering on the estimate gets it round the route


def test_gross_errors_are_gated_out():
    sensors = {"gnss": {"sigma_m": 2.0, "gross_prob": 0.05, "gross_size_m": 200.0}}
    _, truth, est, fixes = _run([_ship(sensors=sensors)], seconds=800)
    gross = np.hypot(*(fixes[:, :, 0] - truth[:, :2, 0]).T) > 100.0
    assert gross.sum() > 20  # the test injects them
    err = np.hypot(*(est[:, :2, 0] - truth[:, :2, 0]).T)
    assert err[50:].max() < 10.0


def test_same_seed_same_run_and_a_ships_noise_ignores_other_ships():
    sensors = {"gnss": {"sigma_m": 3.0}, "compass": {"sigma_deg": 1.0}}
    _, _, _, f1 = _run([_ship(sensors=sensors)], seconds=200)
    _, _, _, f2 = _run([_ship(sensors=sensors)], seconds=200)
    _, _, _, f3 = _run([_ship(sensors=sensors), _ship("b", 1, sensors, north=5000.0)],
                       seconds=200)
    _, _, _, f4 = _run([_ship(sensors=sensors)], seconds=200, seed=4)
    np.testing.assert_array_equal(f1, f2)
    np.testing.assert_array_equal(f1[:, :, 0], f3[:, :, 0])
    assert not np.array_equal(f1, f4)


def test_bad_sensor_config_is_located_in_the_scenario(tmp_path):
    text = (SCENARIOS / "crossing_sensors.yaml").read_text().replace(
        "compass: {kind: gyro, sigma_deg: 0.3", "compass: {kind: gyro, sigma_dg: 0.3", 1)
    path = tmp_path / "s.yaml"
    path.write_text(text)
    line = next(k for k, t in enumerate(text.splitlines(), 1) if "sigma_dg" in t)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    assert f"s.yaml:{line}:" in str(err.value) and "sigma_dg" in str(err.value)


def test_unknown_filter_is_rejected(tmp_path):
    text = (SCENARIOS / "crossing_sensors.yaml").read_text().replace("filter: pv", "filter: kf", 1)
    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match="filter"):
        load_scenario(path)


def test_ekf_on_the_ship_model_estimates_the_unknown_current_and_beats_the_fixes():
    sensors = {"gnss": {"sigma_m": 5.0}, "compass": {"sigma_deg": 0.5}, "log": {"kind": "em"}}
    sim, truth, est, fixes = _run([_ship(sensors=sensors, filt="ekf")], seconds=900)
    err_est = np.hypot(*(est[:, :2, 0] - truth[:, :2, 0]).T)
    err_fix = np.hypot(*(fixes[:, :, 0] - truth[:, :2, 0]).T)
    assert np.sqrt(np.mean(err_est[200:] ** 2)) < 0.4 * np.sqrt(np.mean(err_fix[200:] ** 2))
    current = sim.nav.ekf_s.x[0, 6:8]  # north, east; the truth is 0.4 m/s towards 1 rad
    np.testing.assert_allclose(current, [0.4 * np.cos(1.0), 0.4 * np.sin(1.0)], atol=0.05)
