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
    s = effects.apply_sensors({"gnss": {"sigma_m": 2.0}}, fx, 1.0)
    assert s["gnss"]["antenna_x_m"] == 50.0 and s["compass"]["bias_deg"] == 2.0
    assert s["ais"]["latency_s"] == 8.0  # added to the default 2 s
    assert s["navigation"]["pv_sp_m2ps3"] == pytest.approx(4.0 / 1e4)
    with pytest.raises(InputError, match="magnetic compass"):
        effects.apply_sensors({}, effects.check({"compass_bias": {"deviation_b_deg": 1.0}}), 1.0)


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


# ---------------------------------------------------------------------------------------------
# registry and config validation


def test_check_of_nothing_and_of_empty_entries_gives_the_off_values() -> None:
    """No mapping, an empty one, and ``name: {}`` / ``name: null`` entries: every key takes the
    off value of the registry; integers become floats."""
    assert effects.check(None) == {} and effects.check({}) == {}
    for name, eff in effects.REGISTRY.items():
        assert effects.check({name: {}}) == {name: eff.off()}
        assert effects.check({name: None}) == {name: eff.off()}
    out = effects.check({"ais_latency": {"latency_s": 3}})
    assert out["ais_latency"]["latency_s"] == 3.0
    assert type(out["ais_latency"]["latency_s"]) is float


@pytest.mark.parametrize("fx, key, match", [
    ({"current": 3}, "ships[0].effects.current", "expected a mapping"),
    ({"current": [1.0, 2.0]}, "ships[0].effects.current", "expected a mapping"),
    ({"current": {"north_mps": True}}, "ships[0].effects.current.north_mps", "finite number"),
    ({"current": {"north_mps": float("nan")}}, "ships[0].effects.current.north_mps",
     "finite number"),
    ({"wind": {"east_mps": float("inf")}}, "ships[0].effects.wind.east_mps", "finite number"),
    ({"wind": {"east_mps": None}}, "ships[0].effects.wind.east_mps", "finite number"),
    ({"current": {"nort_mps": 1.0}}, "ships[0].effects.current.nort_mps",
     "did you mean 'north_mps'"),
    ({"curent": {}}, "ships[0].effects.curent", "did you mean 'current'"),
    ({"gnss_lag": {"tau_s": -0.1}}, "ships[0].effects.gnss_lag.tau_s", "must be >= 0"),
    ({"steering_lag": {"tau_s": -1.0}}, "ships[0].effects.steering_lag.tau_s", "must be >= 0"),
    ({"steering_lag": {"rate_degps": 0.0}}, "ships[0].effects.steering_lag.rate_degps",
     "must be > 0"),
    ({"ais_latency": {"latency_s": -2.0}}, "ships[0].effects.ais_latency.latency_s",
     "must be >= 0"),
    ({"resistance": {"scale": -1.0}}, "ships[0].effects.resistance.scale", "must be > 0"),
    ({"shallow_water": {"draught_to_depth": 0.95}},
     "ships[0].effects.shallow_water.draught_to_depth", r"\[0, 0.95\)"),
    ({"shallow_water": {"draught_to_depth": -0.01}},
     "ships[0].effects.shallow_water.draught_to_depth", r"\[0, 0.95\)"),
])
def test_check_rejects_bad_entries_naming_the_key(fx, key, match) -> None:
    """Each documented refusal is an ``InputError`` whose key is ``where.effect[.key]``."""
    with pytest.raises(InputError, match=match) as info:
        effects.check(fx, where="ships[0].effects")
    assert info.value.key == key


def test_check_accepts_the_limits_of_the_ranges() -> None:
    """Zero lags and latencies are the off values; T/h just below 0.95 and a tiny positive
    rudder rate or resistance scale are inside the documented ranges."""
    out = effects.check({"gnss_lag": {"tau_s": 0}, "ais_latency": {"latency_s": 0.0},
                         "steering_lag": {"tau_s": 0.0, "rate_degps": 1e-6},
                         "resistance": {"scale": 1e-6},
                         "shallow_water": {"draught_to_depth": 0.9499}})
    assert out["shallow_water"]["draught_to_depth"] == 0.9499
    assert out["steering_lag"]["rate_degps"] == 1e-6


def test_check_refuses_an_integer_beyond_float_range_as_input_error() -> None:
    """A YAML integer of 400 digits is not a finite number: the documented ``InputError``."""
    with pytest.raises(InputError, match="finite number"):
        effects.check({"current": {"north_mps": 10**400}})


def test_magnitude_is_zero_when_off_and_a_norm_otherwise() -> None:
    """Off values have size 0; current (3, 4) m/s is 5 m/s; compass (1, 2, 2) deg is 3 deg;
    resistance measures ``|scale - 1|``; a lag its time constant."""
    for eff in effects.REGISTRY.values():
        assert eff.magnitude(eff.off()) == 0.0
    reg = effects.REGISTRY
    assert reg["current"].magnitude({"north_mps": 3.0, "east_mps": -4.0}) == pytest.approx(5.0)
    assert reg["compass_bias"].magnitude({"bias_deg": 1.0, "deviation_b_deg": 2.0,
                                          "deviation_c_deg": -2.0}) == pytest.approx(3.0)
    assert reg["resistance"].magnitude({"scale": 0.7}) == pytest.approx(0.3)
    assert reg["steering_lag"].magnitude({"tau_s": 4.0, "rate_degps": 2.0}) == 4.0
    assert effects.PER_RUN == ("current", "wind")


@pytest.mark.parametrize("length, speed", [(3.0, None), (320.0, None), (320.0, 8.0),
                                           (3.0, 0.6)])
def test_start_grids_lie_inside_the_fit_bounds(length, speed) -> None:
    """Every starting point of every effect's grid is within its bounds, with one column per
    parameter; the lever-arm bounds are the fractions of the length times the length."""
    for name, eff in effects.REGISTRY.items():
        lo, hi, start = effects.bounds(name, length)
        grid = effects.start_grid(name, length, speed)
        assert grid.ndim == 2 and grid.shape[1] == len(eff.params)
        assert np.all(grid >= lo - 1e-12) and np.all(grid <= hi + 1e-12), name
        assert np.all(lo <= start) and np.all(start <= hi), name
    lo, hi, _ = effects.bounds("lever_arm", length)
    np.testing.assert_allclose(lo, [-0.5 * length, -0.25 * length])
    np.testing.assert_allclose(hi, [0.5 * length, 0.25 * length])


def test_current_and_wind_grids_are_circles_of_the_documented_radii() -> None:
    """Centre plus 8 directions on each radius: 0.03 U and 0.075 U for current, 1.25 U and
    3.1 U for wind; 0.25/0.6 and 10/25 m/s without a speed."""
    for name, speed, radii in (("current", 10.0, (0.3, 0.75)), ("wind", 10.0, (12.5, 31.0)),
                               ("current", None, (0.25, 0.6)), ("wind", None, (10.0, 25.0))):
        grid = effects.start_grid(name, 100.0, speed)
        assert grid.shape == (17, 2)
        np.testing.assert_array_equal(grid[0], [0.0, 0.0])
        r = np.hypot(grid[1:, 0], grid[1:, 1])
        np.testing.assert_allclose(np.sort(r), np.repeat(radii, 8), rtol=1e-12)
        ang = np.mod(np.arctan2(grid[1:9, 1], grid[1:9, 0]), 2 * np.pi)
        np.testing.assert_allclose(np.sort(ang), np.arange(8) * np.pi / 4, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# hull and steering


def test_shallow_water_factor_against_kijimas_formula_by_hand() -> None:
    """KVLCC2: C_B = 312600 / (320 x 58 x 20.8) = 0.80974, n = 0.40 x 0.80974 x 58 / 20.8 =
    0.90318, so at T/h = 0.5 the factor is 1 / 0.5^0.90318 - 0.5 = 1.87018 - 0.5 = 1.37018.
    Without a displacement C_B is 0.8."""
    spec = load_ship("kvlcc2")
    assert effects.shallow_water_factor(0.5, spec) == pytest.approx(1.37018, rel=2e-5)
    box = {"particulars": {"length_m": 100.0, "beam_m": 20.0, "draught_m": 8.0}}
    n = 0.40 * 0.8 * 20.0 / 8.0  # = 0.8
    assert effects.shallow_water_factor(0.6, box) == pytest.approx(1.0 / 0.4**n - 0.6)
    # continuous at deep water, and growing without bound towards T/h = 1
    assert effects.shallow_water_factor(1e-9, spec) == pytest.approx(1.0, abs=1e-8)
    assert effects.shallow_water_factor(0.94, spec) > 10.0 * effects.shallow_water_factor(0.3,
                                                                                          spec)


def test_apply_spec_scales_exactly_the_documented_coefficients() -> None:
    """Resistance scales R0 only; the asymmetry adds to ``delta_0`` in radians; shallow water
    multiplies Y_v, Y_r, N_v, N_r and m_y by the factor and leaves the cubic terms; the input
    spec is not changed."""
    spec = load_ship("kvlcc2")
    spec["coefficients"]["delta_0"] = 0.01
    before = dict(spec["coefficients"])
    fx = effects.check({"resistance": {"scale": 1.5},
                        "propeller_asymmetry": {"rudder_offset_deg": -2.0},
                        "shallow_water": {"draught_to_depth": 0.5}})
    out = effects.apply_spec(spec, fx)
    assert spec["coefficients"] == before
    f = effects.shallow_water_factor(0.5, spec)
    c = out["coefficients"]
    changed = {"R0": 1.5 * before["R0"], "delta_0": 0.01 + np.radians(-2.0)}
    changed |= {k: f * before[k] for k in ("Y_v", "Y_r", "N_v", "N_r", "m_y")}
    for key, value in before.items():
        assert c[key] == pytest.approx(changed.get(key, value), rel=1e-14), key
    assert out["actuators"] == spec["actuators"]


def test_apply_spec_berthing_scales_both_resistance_coefficients() -> None:
    """``mmg_berthing``: one resistance coefficient ahead and one astern, both scaled."""
    spec = {"name": "b", "model": "mmg_berthing",
            "coefficients": {"X_0F": 0.02, "X_0A": 0.03, "Y_v": -0.3}}
    out = effects.apply_spec(spec, effects.check({"resistance": {"scale": 2.0}}))
    assert out["coefficients"]["X_0F"] == pytest.approx(0.04)
    assert out["coefficients"]["X_0A"] == pytest.approx(0.06)
    assert out["coefficients"]["Y_v"] == -0.3 and spec["coefficients"]["X_0F"] == 0.02


@pytest.mark.parametrize("ship", ["cargo", "bulk_carrier", "catfish"])
@pytest.mark.parametrize("name", ["resistance", "propeller_asymmetry", "shallow_water"])
def test_hull_effects_are_refused_for_families_without_hull_terms(ship, name) -> None:
    with pytest.raises(InputError, match="mmg and mmg_berthing") as info:
        effects.apply_spec(load_ship(ship), effects.check({name: {}}))
    assert info.value.key == f"effects.{name}"


def test_steering_lag_sets_the_gear_and_an_off_lag_changes_nothing() -> None:
    """``tau_s > 0`` sets the steering gear's lag and rate (capped at 90 deg/s), on any
    family; ``tau_s = 0`` leaves it; measurement-only effects leave the spec as it was."""
    spec = load_ship("cargo")
    out = effects.apply_spec(spec, effects.check({"steering_lag": {"tau_s": 4.0,
                                                                   "rate_degps": 120.0}}))
    assert out["actuators"]["rudder_tau_s"] == 4.0 and out["actuators"]["rudder_rate_degps"] == 90.0
    assert spec["actuators"]["rudder_tau_s"] == 1.0
    assert effects.steering(effects.check({"steering_lag": {"tau_s": 4.0, "rate_degps": 3.0}})
                            ) == pytest.approx((4.0, np.radians(3.0)))
    off = effects.check({"steering_lag": {"tau_s": 0.0, "rate_degps": 3.0}})
    assert effects.apply_spec(spec, off)["actuators"] == spec["actuators"]
    assert effects.steering(off) == (0.0, 0.0) and effects.steering({}) == (0.0, 0.0)
    fx = effects.check({"lever_arm": {"x_m": 3.0}, "gnss_lag": {"tau_s": 5.0}})
    assert effects.apply_spec(spec, fx) == spec


def test_neutral_rudder_offset_is_a_rudder_angle_added_for_the_hull() -> None:
    """The hull feels ``delta + delta_0``: with the offset, accelerations at rudder ``d`` are
    those of the plain ship at rudder ``d + offset`` (any state)."""
    plain = load_ship("kvlcc2")
    shifted = effects.apply_spec(plain, effects.check({"propeller_asymmetry":
                                                       {"rudder_offset_deg": 3.0}}))
    fam = base.families()["mmg"]
    rng = np.random.default_rng(5)
    x = np.zeros((8, 6))
    x[base.U] = rng.uniform(3.0, 7.0, 6)
    x[base.V] = rng.uniform(-0.5, 0.5, 6)
    x[base.R] = rng.uniform(-0.005, 0.005, 6)
    x[base.RUDDER] = np.radians(rng.uniform(-30.0, 30.0, 6))
    x[base.RPS] = rng.uniform(0.8, 1.8, 6)
    moved = x.copy()
    moved[base.RUDDER] += np.radians(3.0)
    a = base.accelerations(fam, fam.build([shifted] * 6), x, base.Env())
    b = base.accelerations(fam, fam.build([plain] * 6), moved, base.Env())
    np.testing.assert_allclose(np.array(a), np.array(b), rtol=1e-10, atol=1e-15)


# ---------------------------------------------------------------------------------------------
# environment and instruments


def test_environment_offset_and_wind_addition() -> None:
    """Offsets in the documented order; a true wind of 10 m/s from north (air moving south)
    plus an air velocity of 10 m/s north is calm; calm plus 10 m/s towards east is a wind from
    west (270 deg); adding then subtracting an air velocity gives the wind back."""
    fx = effects.check({"current": {"east_mps": 0.5}, "wind": {"north_mps": -3.0}})
    np.testing.assert_array_equal(effects.environment_offset(fx), [0.0, 0.5, -3.0, 0.0])
    np.testing.assert_array_equal(effects.environment_offset({}), np.zeros(4))
    speed, frm = effects.add_wind(np.array([10.0]), np.array([0.0]), 10.0, 0.0)
    assert speed[0] == pytest.approx(0.0, abs=1e-12)
    speed, frm = effects.add_wind(np.array([0.0]), np.array([0.0]), 0.0, 10.0)
    assert speed[0] == pytest.approx(10.0) and frm[0] == pytest.approx(1.5 * np.pi)
    rng = np.random.default_rng(2)
    s0, f0 = rng.uniform(0.0, 20.0, 50), rng.uniform(0.0, 2 * np.pi, 50)
    n, e = rng.normal(0.0, 5.0, 50), rng.normal(0.0, 5.0, 50)
    s1, f1 = effects.add_wind(s0, f0, n, e)
    s2, f2 = effects.add_wind(s1, f1, -n, -e)
    np.testing.assert_allclose(s2, s0, atol=1e-12)
    assert np.all((f1 >= 0.0) & (f1 < 2 * np.pi))
    np.testing.assert_allclose(np.cos(f2 - f0), 1.0, atol=1e-12)


def test_apply_sensors_copies_and_sets_each_instrument() -> None:
    """Instrument configs are copied; a zero GNSS lag sets no filter; the lag uses the GNSS
    sigma (default 2 m) and the step: ``S_p = sigma^2 dt / tau^4``; compass deviation becomes
    ``[0, B, C, 0, 0]`` on a magnetic compass without one."""
    sensors = {"gnss": {"sigma_m": 3.0}, "compass": {"kind": "magnetic"}}
    fx = effects.check({"compass_bias": {"bias_deg": 1.0, "deviation_b_deg": 2.0,
                                         "deviation_c_deg": -1.0},
                        "gnss_lag": {"tau_s": 3.0}, "lever_arm": {"x_m": 5.0, "y_m": -1.0}})
    out = effects.apply_sensors(sensors, fx, 1.0)
    assert sensors == {"gnss": {"sigma_m": 3.0}, "compass": {"kind": "magnetic"}}
    assert out["compass"]["deviation_deg"] == [0.0, 2.0, -1.0, 0.0, 0.0]
    assert out["navigation"]["pv_sp_m2ps3"] == pytest.approx(9.0 / 81.0)
    assert (out["gnss"]["antenna_x_m"], out["gnss"]["antenna_y_m"]) == (5.0, -1.0)
    assert "navigation" not in effects.apply_sensors({}, effects.check({"gnss_lag": {}}), 1.0)
    assert effects.apply_sensors({}, effects.check({"gnss_lag": {"tau_s": 2.0}}), 0.5)[
        "navigation"]["pv_sp_m2ps3"] == pytest.approx(4.0 * 0.5 / 16.0)


def test_gnss_lag_gains_depend_on_dt_over_tau_only() -> None:
    """The documented promise of ``pv_sp``: tracking index ``(dt / tau)^2`` whatever sigma, so
    a receiver sampled at 10 Hz with tau = 1 s has the gains of one at 1 Hz with tau = 10 s
    (and the lag, in seconds, of the effect does not depend on the sampling interval)."""
    from trafficsim.estimation import pv

    k1 = pv.steady_state_gain(2.0, effects.pv_sp(10.0, 2.0, 1.0), 1.0)
    k2 = pv.steady_state_gain(2.0, effects.pv_sp(1.0, 2.0, 0.1), 0.1)
    assert k2[0] == pytest.approx(k1[0], rel=1e-9)
    assert k2[1] * 0.1 == pytest.approx(k1[1] * 1.0, rel=1e-9)


def _riccati_alpha_beta(sigma: float, sp: float, dt: float) -> tuple[float, float]:
    """Steady gains of the constant-velocity filter by iterating its Riccati recursion
    (continuous white-noise acceleration Q), ``(alpha, beta = K_v dt)``."""
    F = np.array([[1.0, dt], [0.0, 1.0]])
    Q = sp * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    P = np.eye(2) * 100.0
    for _ in range(3000):
        M = F @ P @ F.T + Q
        K = M[:, 0] / (M[0, 0] + sigma**2)
        P = M - np.outer(K, M[0])
    return float(K[0]), float(K[1] * dt)


def test_measure_gnss_lag_against_the_alpha_beta_steady_state() -> None:
    """No lag at constant velocity (the filter starts converged on the truth); under a
    constant acceleration ``a`` the position lags ``(1 - alpha) a dt^2 / beta`` and the
    velocity ``a dt (alpha / beta - 1/2)`` (steady state of the alpha-beta recursion)."""
    n, dt, tau, a = 200, 1.0, 5.0, 0.05
    t = np.arange(n) * dt
    fx = effects.check({"gnss_lag": {"tau_s": tau}})
    straight = np.zeros((1, 1, n, 6))
    straight[..., 0], straight[..., 1] = 4.0 * t * np.cos(0.3), 4.0 * t * np.sin(0.3)
    straight[..., 2], straight[..., 3] = 0.3, 4.0
    m = effects.measure(straight, np.array([dt]), [fx])
    np.testing.assert_allclose(m["north"][0, 0], straight[0, 0, :, 0], atol=1e-9)
    np.testing.assert_allclose(m["sog"][0, 0], 4.0, atol=1e-12)
    np.testing.assert_allclose(m["cog"][0, 0], 0.3, atol=1e-12)
    accel = np.zeros((1, 1, n, 6))
    accel[..., 0], accel[..., 3] = 0.5 * a * t**2, a * t
    m = effects.measure(accel, np.array([dt]), [fx])
    alpha, beta = _riccati_alpha_beta(1.0, effects.pv_sp(tau, 1.0, dt), dt)
    lag_p = accel[0, 0, -1, 0] - m["north"][0, 0, -1]
    lag_v = accel[0, 0, -1, 3] - m["u"][0, 0, -1]
    assert lag_p == pytest.approx((1 - alpha) * a * dt**2 / beta, rel=1e-6)
    assert lag_v == pytest.approx(a * dt * (alpha / beta - 0.5), rel=1e-6)


def _truth(w: int, n: int, seed: int, turning: bool = True) -> np.ndarray:
    """Random replayed truths ``(1, w, n, 6)`` sampled at 1 s (constant body velocities)."""
    rng = np.random.default_rng(seed)
    out = np.zeros((1, w, n, 6))
    psi0 = rng.uniform(0.0, 2 * np.pi, w)
    u, v = rng.uniform(2.0, 8.0, w), rng.normal(0.0, 0.3, w)
    r = rng.normal(0.0, 0.01, w) if turning else np.zeros(w)
    t = np.arange(n)
    for i in range(w):
        psi = psi0[i] + r[i] * t
        out[0, i, :, 2] = np.mod(psi, 2 * np.pi)
        out[0, i, :, 3], out[0, i, :, 4], out[0, i, :, 5] = u[i], v[i], r[i]
        out[0, i, :, 0] = rng.normal(0, 100) + np.cumsum(u[i] * np.cos(psi) - v[i] * np.sin(psi))
        out[0, i, :, 1] = rng.normal(0, 100) + np.cumsum(u[i] * np.sin(psi) + v[i] * np.cos(psi))
    return out


def _measured_state(m: dict, j: int) -> np.ndarray:
    x = np.zeros((8, m["north"].shape[1]))
    for k, key in enumerate(("north", "east", "psi", "u", "v", "r")):
        x[k] = m[key][0, :, j]
    return x


def test_true_start_undoes_measure_for_lever_arm_bias_and_current() -> None:
    """``measure`` then ``true_start`` returns the truth: antenna lever arm, compass bias and
    current (effect plus a per-window current) are each inverted exactly, on turning ships."""
    truth = _truth(6, 3, 1)
    cur = np.random.default_rng(3).normal(0.0, 0.4, (6, 2))
    fx = effects.check({"lever_arm": {"x_m": 30.0, "y_m": -4.0},
                        "compass_bias": {"bias_deg": 3.0},
                        "current": {"north_mps": 0.4, "east_mps": -0.7}})
    m = effects.measure(truth, np.ones(6), [fx], current_ne=cur)
    back = effects.true_start(_measured_state(m, 1), fx, current_ne=(cur[:, 0], cur[:, 1]))
    want = truth[0, :, 1, :].T
    np.testing.assert_allclose(back[:6], want, rtol=0, atol=1e-9)


def test_true_start_leaves_latency_to_the_replay() -> None:
    """With report latency the measured state at a sample is the truth ``latency`` earlier:
    ``true_start`` undoes the lever arm and the compass bias but moves nothing forward in time
    (the replay starts ``latency`` earlier instead, ``diagnose.fit``)."""
    truth = _truth(5, 12, 4, turning=False)
    fx = effects.check({"ais_latency": {"latency_s": 2.5}, "lever_arm": {"x_m": 10.0},
                        "compass_bias": {"bias_deg": -2.0}})
    m = effects.measure(truth, np.ones(5), [fx])
    back = effects.true_start(_measured_state(m, 6), fx)
    earlier = 0.5 * (truth[0, :, 3, :] + truth[0, :, 4, :])  # the truth 2.5 samples before
    np.testing.assert_allclose(back[:6], earlier.T[:6], rtol=0, atol=1e-9)


def test_true_start_undoes_compass_deviation() -> None:
    """The compass error is ``A + B sin psi + C cos psi`` at the TRUE heading (as ``measure``
    and the compass model apply it); undoing it must give the true heading back, not the
    first-order guess ``psi_m - d(psi_m)`` (0.4 deg off for 5 deg deviation)."""
    truth = _truth(8, 2, 5)
    fx = effects.check({"compass_bias": {"bias_deg": 1.0, "deviation_b_deg": 5.0,
                                         "deviation_c_deg": -4.0}})
    m = effects.measure(truth, np.ones(8), [fx])
    back = effects.true_start(_measured_state(m, 0), fx)
    np.testing.assert_allclose(back[2], truth[0, :, 0, 2], rtol=0, atol=1e-9)


def test_compass_error_is_bias_plus_deviation_curve() -> None:
    """``A + B sin psi + C cos psi`` (degrees in, radians out)."""
    psi = np.linspace(0.0, 2 * np.pi, 9)
    got = effects.compass_error(psi, {"bias_deg": 2.0, "deviation_b_deg": 3.0,
                                      "deviation_c_deg": -1.0})
    want = np.radians(2.0 + 3.0 * np.sin(psi) - 1.0 * np.cos(psi))
    np.testing.assert_allclose(got, want, atol=1e-15)
    got = effects.compass_error(psi, {"bias_deg": -1.5, "deviation_b_deg": 0.0,
                                      "deviation_c_deg": 0.0})
    np.testing.assert_allclose(got, np.radians(-1.5), atol=1e-15)


def test_measure_without_effects_reports_the_truth_over_ground() -> None:
    """No effect: position and heading are the truth; body velocities over ground are the
    water velocities plus the window's current turned into the body frame; SOG and COG by
    hand; COG in [0, 2 pi)."""
    truth = _truth(4, 5, 6)
    cur = np.array([[0.5, 0.0], [0.0, -0.5], [0.3, 0.3], [0.0, 0.0]])
    m = effects.measure(truth, np.ones(4), [{}], current_ne=cur)
    psi, u, v = truth[0, :, :, 2], truth[0, :, :, 3], truth[0, :, :, 4]
    vn = u * np.cos(psi) - v * np.sin(psi) + cur[:, 0:1]
    ve = u * np.sin(psi) + v * np.cos(psi) + cur[:, 1:2]
    np.testing.assert_array_equal(m["north"][0], truth[0, :, :, 0])
    np.testing.assert_array_equal(m["psi"][0], psi)
    np.testing.assert_allclose(m["sog"][0], np.hypot(vn, ve), atol=1e-12)
    np.testing.assert_allclose(m["u"][0], vn * np.cos(psi) + ve * np.sin(psi), atol=1e-12)
    np.testing.assert_allclose(np.cos(m["cog"][0] - np.arctan2(ve, vn)), 1.0, atol=1e-12)
    assert np.all((m["cog"] >= 0.0) & (m["cog"] < 2 * np.pi))


def test_measure_of_several_models_equals_each_model_alone() -> None:
    """The vectorised path over ``k`` models gives each model what it gives alone, whatever
    effects the others have (lag, latency, lever arm, current per model and window)."""
    n, w = 40, 3
    one = _truth(w, n, 7)
    truth = np.repeat(one, 3, axis=0)
    values = [effects.check({"gnss_lag": {"tau_s": 4.0}, "current": {"north_mps": 0.2}}),
              effects.check({"ais_latency": {"latency_s": 1.5}, "lever_arm": {"y_m": 2.0}}),
              {}]
    dt = np.array([1.0, 0.5, 2.0])
    cur = np.random.default_rng(8).normal(0.0, 0.3, (3, w, 2))
    together = effects.measure(truth, dt, values, current_ne=cur)
    for i in range(3):
        alone = effects.measure(one, dt, [values[i]], current_ne=cur[i:i + 1])
        for key, val in alone.items():
            np.testing.assert_allclose(together[key][i], val[0], rtol=0, atol=1e-12,
                                       err_msg=key)


def test_measure_latency_across_north_keeps_the_heading_continuous() -> None:
    """A ship turning through north at 0.01 rad/s, reported 2.5 s late: every reported
    heading is the true one 0.025 rad earlier (modulo a turn), as COG already is."""
    n = 60
    t = np.arange(n, dtype=float)
    truth = np.zeros((1, 1, n, 6))
    truth[..., 2] = np.mod(-0.3 + 0.01 * t, 2 * np.pi)
    truth[..., 3], truth[..., 5] = 5.0, 0.01
    m = effects.measure(truth, np.array([1.0]), [effects.check({"ais_latency":
                                                               {"latency_s": 2.5}})])
    want = -0.3 + 0.01 * (t - 2.5)
    np.testing.assert_allclose(np.cos(m["cog"][0, 0] - want), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.cos(m["psi"][0, 0] - want), 1.0, atol=1e-12)


def test_delay_shifts_by_whole_and_fractional_samples() -> None:
    """A whole-sample shift is the series moved along (the start extrapolated linearly from
    the first two samples); a linear series is delayed exactly by any shift; zero shift is
    the identity; a single sample stays what it is."""
    rng = np.random.default_rng(9)
    s = rng.normal(size=(2, 3, 20))
    out = effects.delay(s, np.full((2, 3), 3.0))
    np.testing.assert_allclose(out[..., 3:], s[..., :-3], atol=1e-15)
    np.testing.assert_allclose(out[..., 0], s[..., 0] - 3.0 * (s[..., 1] - s[..., 0]),
                               atol=1e-12)
    lin = 2.0 + 0.7 * np.arange(20.0)[None, None, :] * np.ones((2, 3, 1))
    shift = rng.uniform(0.0, 25.0, (2, 3))
    np.testing.assert_allclose(effects.delay(lin, shift), lin - 0.7 * shift[..., None],
                               atol=1e-12)
    np.testing.assert_allclose(effects.delay(s, np.zeros((2, 3))), s, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(effects.delay(np.full((1, 1, 1), 4.0), np.full((1, 1), 2.0)),
                                  np.full((1, 1, 1), 4.0))
    # half a sample between two values is their mean
    np.testing.assert_allclose(effects.delay(s, np.full((2, 3), 0.5))[..., 1:],
                               0.5 * (s[..., 1:] + s[..., :-1]), atol=1e-15)


def test_wind_effect_equals_scenario_wind(tmp_path: Path) -> None:
    """A true wind of 12 m/s from 045 deg is air moving towards 225 deg: the effect
    ``wind: {north_mps: -12 cos 45, east_mps: -12 sin 45}`` gives the same run, and the wind
    does change the run."""
    comp = -12.0 * float(np.cos(np.radians(45.0)))
    a = _run(tmp_path, "env", "environment:\n  wind: {speed_mps: 12, from_deg: 45}")
    b = _run(tmp_path, "fx", fx=f"    effects:\n      wind: {{north_mps: {comp!r}, "
             f"east_mps: {comp!r}}}")
    plain = _run(tmp_path, "plain")
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
    assert np.abs(a[:6] - plain[:6]).max() > 1e-3


def test_measured_signatures_of_current_lever_arm_bias_and_latency() -> None:
    """The residual signatures of the reference table, from ``measure`` on straight runs at
    several headings and speeds: current adds ``Vc cos(psi - beta_c)`` to the surge over
    ground and ``Vc sin(beta_c - psi)`` to the sway; a lever arm moves the position by
    ``R(psi) r_a`` (averaging to zero over a circle of headings) and no velocity while
    ``r = 0``; a compass bias turns COG - heading by ``-bias`` whatever the speed and moves
    no position; latency puts the position ``U dt`` behind along the track."""
    n, w = 12, 16
    psi = np.linspace(0.0, 2 * np.pi, w, endpoint=False)
    speed = np.linspace(1.0, 9.0, w)
    t = np.arange(n, dtype=float)
    truth = np.zeros((1, w, n, 6))
    truth[0, :, :, 2] = psi[:, None]
    truth[0, :, :, 3] = speed[:, None]
    truth[0, :, :, 0] = (speed * np.cos(psi))[:, None] * t
    truth[0, :, :, 1] = (speed * np.sin(psi))[:, None] * t
    dt = np.ones(w)
    vc, beta = 0.7, np.radians(60.0)
    m = effects.measure(truth, dt, [effects.check({"current": {
        "north_mps": vc * np.cos(beta), "east_mps": vc * np.sin(beta)}})])
    np.testing.assert_allclose(m["u"][0, :, 0] - speed, vc * np.cos(psi - beta), atol=1e-12)
    np.testing.assert_allclose(m["v"][0, :, 0], vc * np.sin(beta - psi), atol=1e-12)
    m = effects.measure(truth, dt, [effects.check({"lever_arm": {"x_m": 20.0, "y_m": 3.0}})])
    dn = m["north"][0, :, 0] - truth[0, :, 0, 0]
    de = m["east"][0, :, 0] - truth[0, :, 0, 1]
    np.testing.assert_allclose(dn, 20.0 * np.cos(psi) - 3.0 * np.sin(psi), atol=1e-12)
    np.testing.assert_allclose(de, 20.0 * np.sin(psi) + 3.0 * np.cos(psi), atol=1e-12)
    assert abs(dn.mean()) < 1e-12 and abs(de.mean()) < 1e-12
    np.testing.assert_allclose(m["sog"][0, :, 0], speed, atol=1e-12)
    m = effects.measure(truth, dt, [effects.check({"compass_bias": {"bias_deg": 2.0}})])
    drift = np.angle(np.exp(1j * (m["cog"][0] - m["psi"][0])))
    np.testing.assert_allclose(drift, np.radians(-2.0), atol=1e-12)
    np.testing.assert_array_equal(m["north"][0], truth[0, :, :, 0])
    m = effects.measure(truth, dt, [effects.check({"ais_latency": {"latency_s": 3.0}})])
    along = ((truth[0, :, :, 0] - m["north"][0]) * np.cos(psi)[:, None]
             + (truth[0, :, :, 1] - m["east"][0]) * np.sin(psi)[:, None])
    np.testing.assert_allclose(along, 3.0 * speed[:, None] * np.ones(n), atol=1e-9)


def test_measurement_effects_off_leave_the_ships_own_instruments() -> None:
    """"Every effect has an off value at which it changes nothing": a ship whose GNSS antenna
    is 40 m aft, whose gyro reads 0.5 deg high and whose AIS reports 2 s late keeps those
    instruments when the measurement effects are switched on at their off values (as a zero
    ``gnss_lag`` or ``steering_lag`` already leaves them)."""
    sensors = {"gnss": {"sigma_m": 2.0, "antenna_x_m": -40.0, "antenna_y_m": 1.0},
               "compass": {"kind": "gyro", "bias_deg": 0.5}, "ais": {"latency_s": 2.0},
               "navigation": {"pv_sp_m2ps3": 0.02}}
    off = effects.check({"lever_arm": {}, "compass_bias": {}, "ais_latency": {},
                         "gnss_lag": {}})
    assert effects.apply_sensors(sensors, off, 1.0) == sensors


def test_measurement_effects_add_to_the_ships_own_instruments() -> None:
    """An antenna 40 m aft plus a lever-arm effect of 10 m forward is 30 m aft; a gyro 0.5 deg
    high plus a 1 deg bias reads 1.5 deg high; a magnetic compass's own deviation gets the
    effect's B and C added; AIS latency adds to the ship's 3 s."""
    sensors = {"gnss": {"sigma_m": 2.0, "antenna_x_m": -40.0},
               "compass": {"kind": "magnetic", "bias_deg": 0.5,
                           "deviation_deg": [0.1, 1.0, 2.0, 0.3, 0.4]},
               "ais": {"latency_s": 3.0}}
    fx = effects.check({"lever_arm": {"x_m": 10.0}, "ais_latency": {"latency_s": 1.5},
                        "compass_bias": {"bias_deg": 1.0, "deviation_b_deg": -0.5,
                                         "deviation_c_deg": 1.0}})
    out = effects.apply_sensors(sensors, fx, 1.0)
    assert out["gnss"]["antenna_x_m"] == -30.0 and out["gnss"]["antenna_y_m"] == 0.0
    assert out["compass"]["bias_deg"] == 1.5
    assert out["compass"]["deviation_deg"] == [0.1, 0.5, 3.0, 0.3, 0.4]
    assert out["ais"]["latency_s"] == 4.5
    assert sensors["gnss"]["antenna_x_m"] == -40.0  # the caller's config is untouched
