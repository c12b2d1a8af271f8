"""Sim-to-real effects in the engine: registry checks, scenario switch, zero effect when off,
each effect's term against its definition, replay steering gear against the engine's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from trafficsim import effects
from trafficsim.batch import build_batch
from trafficsim.engine import Simulation
from trafficsim.errors import InputError
from trafficsim.identify import replay
from trafficsim.io.scenario import load_scenario
from trafficsim.run import scenario_setups
from trafficsim.ships import base, kernels
from trafficsim.ships.library import load_ship

SCENARIO = """schema_version: 1
name: fx
duration_s: 120
dt_s: 1.0
{environment}
ships:
  - name: own
    type: kvlcc2
    north_m: 0
    east_m: 0
    heading_deg: 30
    behaviour: keep_course
{effects}
"""


def _run(tmp_path: Path, name: str, environment: str = "", fx: str = "") -> np.ndarray:
    path = tmp_path / f"{name}.yaml"
    path.write_text(SCENARIO.format(environment=environment, effects=fx))
    scn = load_scenario(path)
    setups, env = scenario_setups(scn)
    sim = Simulation.start(build_batch(setups, [env]), scn.dt_s)
    sim.run(120)
    return sim.batch.x.copy()


def test_check_fills_off_values_and_rejects_typos() -> None:
    out = effects.check({"current": {"north_mps": 0.3}, "resistance": None})
    assert out == {"current": {"north_mps": 0.3, "east_mps": 0.0}, "resistance": {"scale": 1.0}}
    with pytest.raises(InputError, match="did you mean 'lever_arm'") as info:
        effects.check({"lever_arms": {}})
    assert info.value.key == "effects.lever_arms"
    with pytest.raises(InputError, match="expected a finite number"):
        effects.check({"current": {"north_mps": "fast"}})
    with pytest.raises(InputError, match="must be > 0"):
        effects.check({"resistance": {"scale": 0.0}})


def test_current_effect_equals_scenario_current(tmp_path: Path) -> None:
    speed = 0.8 * 1852 / 3600
    a = _run(tmp_path, "env", "environment:\n  current: {speed_kn: 0.8, towards_deg: 90}")
    b = _run(tmp_path, "fx", fx=f"    effects:\n      current: {{north_mps: 0.0, "
             f"east_mps: {speed!r}}}")
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_effects_off_change_nothing(tmp_path: Path) -> None:
    plain = _run(tmp_path, "plain")
    off = _run(tmp_path, "off", fx="    effects:\n      current: {}\n      wind: {}\n"
               "      propeller_asymmetry: {}\n      resistance: {scale: 1.0}\n"
               "      shallow_water: {}")
    assert np.array_equal(plain, off)


def test_hull_effects_act(tmp_path: Path) -> None:
    plain = _run(tmp_path, "plain")
    slow = _run(tmp_path, "slow", fx="    effects:\n      resistance: {scale: 1.5}")
    assert slow[base.U, 0] < plain[base.U, 0] - 0.1
    # a neutral-rudder offset turns a ship at zero rudder to the offset's side
    spec = effects.apply_spec(load_ship("kvlcc2"), {"propeller_asymmetry":
                                                     {"rudder_offset_deg": 2.0}})
    fam = base.families()["mmg"]
    x = np.zeros((8, 1))
    x[base.U] = 7.0
    x[base.RPS] = 1.5
    _, _, dr = base.accelerations(fam, fam.build([spec]), x, base.Env())
    _, _, dr0 = base.accelerations(fam, fam.build([load_ship("kvlcc2")]), x, base.Env())
    assert dr0[0] == 0.0 and dr[0] > 0.0
    # shallow water: Kijima's factor 1/(1-xi)^n - xi, > 1 and growing with T/h
    f = [effects.shallow_water_factor(xi, spec) for xi in (0.0, 0.3, 0.6, 0.8)]
    assert f[0] == 1.0 and 1.0 < f[1] < f[2] < f[3]


def test_sensor_effects_set_instruments() -> None:
    fx = effects.check({"lever_arm": {"x_m": 50.0}, "compass_bias": {"bias_deg": 2.0},
                        "ais_latency": {"latency_s": 6.0}, "gnss_lag": {"tau_s": 10.0}})
    s = effects.apply_sensors({"gnss": {"sigma_m": 2.0}}, fx)
    assert s["gnss"]["antenna_x_m"] == 50.0 and s["compass"]["bias_deg"] == 2.0
    assert s["ais"]["latency_s"] == 6.0
    assert s["navigation"]["pv_sp_m2ps3"] == pytest.approx(4.0 / 1e4)
    with pytest.raises(InputError, match="magnetic compass"):
        effects.apply_sensors({}, effects.check({"compass_bias": {"deviation_b_deg": 1.0}}))


def test_measure_lever_arm_and_latency() -> None:
    n = 50
    t = np.arange(n) * 2.0
    truth = np.zeros((1, 1, n, 6))
    truth[..., 2] = 0.01 * t  # turning at r = 0.01 rad/s, 5 m/s
    truth[..., 3] = 5.0
    truth[..., 5] = 0.01
    fx = effects.check({"lever_arm": {"x_m": 40.0, "y_m": 0.0}})
    m = effects.measure(truth, np.array([2.0]), [fx])
    psi = truth[0, 0, :, 2]
    np.testing.assert_allclose(m["north"][0, 0], 40.0 * np.cos(psi), atol=1e-12)
    np.testing.assert_allclose(m["east"][0, 0], 40.0 * np.sin(psi), atol=1e-12)
    # the antenna's apparent sway is r x_a (false drift angle proportional to the yaw rate)
    np.testing.assert_allclose(m["v"][0, 0], 0.01 * 40.0, atol=1e-12)
    lat = effects.check({"ais_latency": {"latency_s": 3.0}})
    ml = effects.measure(truth, np.array([2.0]), [lat])
    np.testing.assert_allclose(ml["psi"][0, 0, 2:], psi[2:] - 0.03, atol=1e-12)
    # true start undoes both
    x0 = np.zeros((8, 1))
    x0[0], x0[2], x0[3], x0[5] = 40.0, 0.0, 5.0, 0.01
    back = effects.true_start(x0, fx)
    assert back[0, 0] == pytest.approx(0.0) and back[4, 0] == pytest.approx(-0.4)


def test_replay_steering_gear_matches_engine() -> None:
    """The replay's steering lag behind a logged rudder order is the engine's steering gear."""
    spec = load_ship("kvlcc2")
    fx = effects.check({"steering_lag": {"tau_s": 6.0, "rate_degps": 1.5}})
    ship = effects.apply_spec(spec, fx)
    fam = base.families()["mmg"]
    params = fam.build([ship])
    act = base.Actuators.from_specs([ship])
    n, dt = 120, 1.0
    order = np.radians(np.where(np.arange(n) < 10, 0.0, np.where(np.arange(n) < 70, 20.0,
                                                                 -20.0)))
    x = np.zeros((8, 1))
    x[base.U], x[base.RPS] = 7.5, 1.6
    track = [x[:6, 0].copy()]
    code = np.array([kernels.FAMILY_CODE["mmg"]])
    for k in range(n - 1):
        kernels.step_ships(code, base.pack(params), base.actuator_table(act), x,
                           np.array([order[k]]), np.array([1.6]), np.zeros((4, 1)), dt,
                           np.full(1, 50))
        track.append(x[:6, 0].copy())
    track = np.array(track)
    inputs = np.zeros((1, n, 2))
    # zero-order-hold order as the engine sees it: repeat each value on a 1/50 s grid is
    # unnecessary; a step held over the interval equals first-order hold of a staircase
    inputs[0, :, 0] = order
    inputs[0, :, 1] = 1.6
    win = replay.Windows(np.array(np.vstack([track[0][:, None], np.zeros((2, 1))])), inputs,
                         np.zeros((1, n, 4)), np.array([dt]), np.array([n]),
                         np.zeros((1, n, 6)), np.zeros(1, dtype=np.int64), np.zeros(1), ("a",))
    rows = replay.model_rows([spec])
    out, _ = replay.simulate(rows, win, steering=np.array([effects.steering(fx)]))
    off, _ = replay.simulate(rows, win)
    err_on = np.abs(out[0, 0, :, 2] - track[:, 2]).max()
    err_off = np.abs(off[0, 0, :, 2] - track[:, 2]).max()
    assert err_on < 0.1 * err_off
    assert err_on < np.radians(1.0)
