"""State layout, environment seen by ships, parameter packing, actuators (steering gear and
engine lags [seed 002, eqs 4.7-4.8]), the one-family step, steady rps and the family registry."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from trafficsim.errors import ShipLibraryError
from trafficsim.ships import base, kernels
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, RUDDER, Actuators, Env, R, U, V
from trafficsim.ships.library import load_ship
from trafficsim.units import from_kn


def _family(spec):
    return base.families()[spec["model"]]


def _rk4_factor(z):
    """Amplification of one classic RK4 step of y' = lambda y, z = lambda h."""
    return 1.0 + z + z * z / 2.0 + z**3 / 6.0 + z**4 / 24.0


# -- layout ----------------------------------------------------------------------------------


def test_state_rows_are_laid_out_as_documented():
    assert base.N_STATE == 8 == len(base.STATE_NAMES)
    assert tuple(range(8)) == (base.NORTH, base.EAST, base.PSI, base.U, base.V, base.R, base.RUDDER,
            base.RPS)
    assert base.STATE_NAMES == ("north_m", "east_m", "psi_rad", "u_mps", "v_mps", "r_radps",
                                "rudder_rad", "rps")


def test_env_table_rows_follow_the_env_fields_and_broadcast_scalars():
    env = Env(current_north_mps=0.3, current_east_mps=np.array([1.0, 2.0, 3.0]),
              wind_speed_mps=7.0, wind_from_rad=np.array([0.1, 0.2, 0.3]))
    out = base.env_table(env, 3)
    np.testing.assert_array_equal(out, [[0.3] * 3, [1.0, 2.0, 3.0], [7.0] * 3, [0.1, 0.2, 0.3]])
    np.testing.assert_array_equal(base.env_table(Env(), 2), np.zeros((4, 2)))  # calm default


def test_gather_ship_copies_one_column_of_state_and_environment():
    rng = np.random.default_rng(0)
    X, E = rng.normal(size=(8, 5)), rng.normal(size=(4, 5))
    x, env = np.empty(8), np.empty(4)
    base.gather_ship(X, E, 3, x, env)
    np.testing.assert_array_equal(x, X[:, 3])
    np.testing.assert_array_equal(env, E[:, 3])


# -- environment seen by ships ---------------------------------------------------------------


def test_ground_velocity_body_hand_cases():
    """Heading east at 5 m/s with a 1 m/s current towards north: the current comes from
    starboard, so it pushes the ship to port (v over ground -1); heading north, it adds to u."""
    x = np.zeros((base.N_STATE, 2))
    x[PSI] = [math.pi / 2, 0.0]
    x[U] = 5.0
    x[V] = [0.0, 0.5]
    ug, vg = base.ground_velocity_body(x, Env(current_north_mps=1.0))
    np.testing.assert_allclose(ug, [5.0, 6.0], atol=1e-15)
    np.testing.assert_allclose(vg, [-1.0, 0.5], atol=1e-15)


def test_ground_velocity_body_is_the_earth_velocity_turned_back_into_the_body_frame():
    """Different route, complex numbers (north + i east; body x + i y): the ground velocity
    is (u + i v) e^{i psi} + c over ground, and e^{-i psi} times that in the body frame."""
    rng = np.random.default_rng(1)
    n = 20
    x = np.zeros((base.N_STATE, n))
    x[PSI], x[U], x[V] = rng.uniform(0, 2 * np.pi, n), rng.normal(5, 3, n), rng.normal(0, 1, n)
    cn, ce = rng.normal(0, 1, n), rng.normal(0, 1, n)
    ug, vg = base.ground_velocity_body(x, Env(current_north_mps=cn, current_east_mps=ce))
    earth = (x[U] + 1j * x[V]) * np.exp(1j * x[PSI]) + (cn + 1j * ce)
    body = earth * np.exp(-1j * x[PSI])
    np.testing.assert_allclose(ug, body.real, atol=1e-12)
    np.testing.assert_allclose(vg, body.imag, atol=1e-12)


@pytest.mark.parametrize(("psi", "u", "cur_n", "wind", "wind_from", "speed", "angle"), [
    (0.0, 5.0, 0.0, 0.0, 0.0, 5.0, 0.0),  # own speed only: head wind
    (0.0, 5.0, 0.0, 10.0, 0.0, 15.0, 0.0),  # wind from ahead adds to it
    (0.0, 0.0, 0.0, 10.0, math.pi / 2, 10.0, math.pi / 2),  # from east = from starboard
    (math.pi / 2, 0.0, 0.0, 10.0, 0.0, 10.0, -math.pi / 2),  # heading east, from north: port
    (0.0, 5.0, 0.0, 5.0, math.pi / 2, 5.0 * math.sqrt(2), math.pi / 4),
    (0.0, 0.0, 2.0, 0.0, 0.0, 2.0, 0.0),  # carried north by the current: head wind
    (0.0, 0.0, 0.0, 10.0, math.pi, 10.0, math.pi),  # from astern
])
def test_apparent_wind_hand_cases(psi, u, cur_n, wind, wind_from, speed, angle):
    """Angle the apparent wind comes from, relative to the bow, positive from starboard
    (Fossen 2011, eq. 8.22 convention); the ship's speed over ground, current included,
    makes a head wind."""
    x = np.zeros((base.N_STATE, 1))
    x[PSI], x[U] = psi, u
    env = Env(current_north_mps=cur_n, wind_speed_mps=wind, wind_from_rad=wind_from)
    s, a = base.apparent_wind(x, env)
    assert s[0] == pytest.approx(speed, rel=1e-12)
    assert math.remainder(a[0] - angle, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)


# -- packing, actuators, lookups --------------------------------------------------------------


@dataclass(frozen=True)
class _Params:
    zeta: np.ndarray
    alpha: np.ndarray
    mid: np.ndarray


def test_pack_makes_columns_of_the_fields_in_declaration_order():
    p = _Params(zeta=np.array([1, 2]), alpha=np.array([3.5, 4.5]), mid=np.array([-1.0, 0.0]))
    out = base.pack(p)
    np.testing.assert_array_equal(out, [[1.0, 3.5, -1.0], [2.0, 4.5, 0.0]])
    assert out.dtype == np.float64 and out.flags.c_contiguous


def test_pack_of_a_family_matches_its_kernel_columns():
    """The nomoto kernel reads L from column 2 and rps_service from column 4."""
    spec = load_ship("cargo")
    row = base.pack(_family(spec).build([spec]))[0]
    assert row.size == 7
    assert row[2] == spec["particulars"]["length_m"]
    assert row[4] == spec["coefficients"]["rps_service"]


def test_actuators_from_specs_convert_degrees_and_the_table_follows_the_kernels():
    specs = [load_ship("cargo"), load_ship("kvlcc2_l7")]
    act = Actuators.from_specs(specs)
    a = [s["actuators"] for s in specs]
    np.testing.assert_allclose(act.rudder_max_rad, [d["rudder_max_deg"] * math.pi / 180 for d in a],
                               rtol=1e-15)
    np.testing.assert_allclose(act.rudder_rate_radps,
                               [d["rudder_rate_degps"] * math.pi / 180 for d in a], rtol=1e-15)
    table = base.actuator_table(act)
    assert table.shape == (2, 6)
    np.testing.assert_array_equal(table[:, kernels.RUDDER_MAX], act.rudder_max_rad)
    np.testing.assert_array_equal(table[:, kernels.RUDDER_RATE], act.rudder_rate_radps)
    np.testing.assert_array_equal(table[:, kernels.RUDDER_TAU], [d["rudder_tau_s"] for d in a])
    np.testing.assert_array_equal(table[:, kernels.RPS_MAX], [d["rps_max"] for d in a])
    np.testing.assert_array_equal(table[:, kernels.RPS_MIN], [d["rps_min"] for d in a])
    np.testing.assert_array_equal(table[:, kernels.ENGINE_TAU], [d["engine_tau_s"] for d in a])


def test_coefficient_present_default_and_required():
    ship = {"coefficients": {"K": 2}, "path": "/ships/x.yaml"}
    assert base.coefficient(ship, "K", None, "m") == 2.0
    assert isinstance(base.coefficient(ship, "K", None, "m"), float)
    assert base.coefficient(ship, "T", 1.5, "m") == 1.5
    assert base.coefficient({}, "T", 0.0, "m") == 0.0  # no coefficients section at all
    with pytest.raises(ShipLibraryError, match="missing required coefficient 'T'") as info:
        base.coefficient(ship, "T", None, "mmg")
    assert info.value.key == "coefficients.T" and info.value.path == "/ships/x.yaml"
    assert "'mmg'" in info.value.message


def test_particular_present_default_and_required():
    ship = {"particulars": {"length_m": 100}, "path": "p.yaml"}
    assert base.particular(ship, "length_m", {}, "m") == 100.0
    assert base.particular(ship, "beam_m", {"beam_m": 20.0}, "m") == 20.0
    with pytest.raises(ShipLibraryError, match="missing particular 'beam_m'") as info:
        base.particular(ship, "beam_m", {"beam_m": None}, "mmg")
    assert info.value.key == "particulars.beam_m" and info.value.path == "p.yaml"
    with pytest.raises(ShipLibraryError):
        base.particular(ship, "draught_m", {}, "mmg")  # not in defaults: required too


def test_stack_gathers_floats_with_an_optional_default():
    dicts = [{"a": 1, "b": 2.5}, {"a": 3}]
    out = base.stack(dicts, "a")
    np.testing.assert_array_equal(out, [1.0, 3.0])
    assert out.dtype == np.float64
    np.testing.assert_array_equal(base.stack(dicts, "b", 0.0), [2.5, 0.0])
    with pytest.raises(KeyError):
        base.stack(dicts, "b")


# -- accelerations and step -------------------------------------------------------------------


def test_accelerations_evaluate_the_family_equations():
    """cargo (nomoto) by hand from the nomoto module's equations (Nomoto et al. 1957 with
    Norrbin's cubic, Fossen 2011 ch. 7.2): T r' + r + n3 r^3 = K delta, K = K' u / L,
    T = T' L / u, n3 = n3' (L / u)^2 (u above half the service speed), dv = -v / T and
    du = (u_ss |u_ss| - u |u|) / (2 U T_u), u_ss = U n / n_service."""
    spec = load_ship("cargo")
    c, L = spec["coefficients"], spec["particulars"]["length_m"]
    big_u = from_kn(spec["service_speed_kn"])
    x = np.zeros((base.N_STATE, 2))
    x[U], x[V], x[R] = [6.0, 7.0], [0.3, -0.2], [0.01, -0.004]
    x[RUDDER], x[RPS], x[PSI] = [0.1, -0.05], [1.0, 1.6], [0.2, 4.0]
    du, dv, dr = base.accelerations(_family(spec), _family(spec).build([spec] * 2), x,
                                    Env(current_north_mps=0.5, wind_speed_mps=10.0))
    for k in range(2):
        u, v, r, d, n = x[U, k], x[V, k], x[R, k], x[RUDDER, k], x[RPS, k]
        t = c["T_prime"] * L / u
        gain = c["K_prime"] * u / L
        n3 = c["n3_prime"] * (L / u) ** 2
        u_ss = big_u * n / c["rps_service"]
        assert dr[k] == pytest.approx((gain * d - r - n3 * r**3) / t, rel=1e-12)
        assert dv[k] == pytest.approx(-v / t, rel=1e-12)
        surge = (u_ss * abs(u_ss) - u * abs(u)) / (2 * big_u * c["surge_tau_s"])
        assert du[k] == pytest.approx(surge, rel=1e-12)


def _cargo_pair():
    specs = [load_ship("cargo"), load_ship("container")]
    fam = _family(specs[0])
    return fam, fam.build(specs), Actuators.from_specs(specs), specs


def test_step_at_constant_velocity_moves_each_ship_by_velocity_plus_current_times_dt():
    """Steady straight run (rps that holds u, rudder amidships): RK4 integrates a constant
    velocity exactly; scalar commands apply to every ship; the input state is left alone."""
    fam, params, act, specs = _cargo_pair()
    x = np.zeros((base.N_STATE, 2))
    x[NORTH], x[EAST] = [100.0, -50.0], [10.0, 20.0]
    x[PSI], x[U] = [0.6, 3.0], [6.0, 9.0]
    x[RPS] = [u / from_kn(s["service_speed_kn"]) * s["coefficients"]["rps_service"]
              for u, s in zip(x[U], specs, strict=True)]
    before = x.copy()
    env = Env(current_north_mps=0.3, current_east_mps=-0.2)
    out = base.step(fam, params, act, x, 0.0, x[RPS].copy(), env, 10.0, 3)
    np.testing.assert_array_equal(x, before)
    want_n = before[NORTH] + 10.0 * (before[U] * np.cos(before[PSI]) + 0.3)
    want_e = before[EAST] + 10.0 * (before[U] * np.sin(before[PSI]) - 0.2)
    np.testing.assert_allclose(out[NORTH], want_n, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out[EAST], want_e, rtol=0, atol=1e-9)
    rest = [PSI, U, V, R, RUDDER, RPS]
    np.testing.assert_allclose(out[rest], before[rest], rtol=1e-12, atol=1e-12)


def test_step_steering_gear_is_a_first_order_lag_integrated_by_rk4_substeps():
    """[seed 002, eq 4.7] below the rate limit: delta' = (delta_c - delta) / T_R. One RK4
    step of h multiplies the error by 1 + z + z^2/2 + z^3/6 + z^4/24 (z = -h / T_R), m
    sub-steps by its m-th power; a 0.01 rad order never reaches the 2.32 deg/s limit."""
    fam, params, act, _ = _cargo_pair()
    tau = act.rudder_tau_s
    assert np.all(tau == 1.0) and np.all(act.rudder_rate_radps > 0.01)
    x = np.zeros((base.N_STATE, 2))
    x[U] = 6.0
    cmd = np.array([0.01, -0.01])
    one = base.step(fam, params, act, x, cmd, 0.0, Env(), 2.0, 1)
    np.testing.assert_allclose(one[RUDDER], cmd * (1.0 - _rk4_factor(-2.0)), rtol=1e-12)
    np.testing.assert_allclose(one[RUDDER], cmd * 2.0 / 3.0, rtol=1e-12)
    fine = base.step(fam, params, act, x, cmd, 0.0, Env(), 2.0, 20)
    np.testing.assert_allclose(fine[RUDDER], cmd * (1.0 - _rk4_factor(-0.1) ** 20), rtol=1e-12)
    np.testing.assert_allclose(fine[RUDDER], cmd * (1.0 - math.exp(-2.0)), rtol=1e-6)


def test_step_engine_lags_towards_the_order_clipped_to_the_rps_limits():
    """[seed 002, eq 4.8]: n' = (clip(n_c, rps_min, rps_max) - n) / T_N; an order of 10 rps
    goes to rps_max, one of -10 rps to rps_min (astern limit of the ship file)."""
    fam, params, act, _ = _cargo_pair()
    x = np.zeros((base.N_STATE, 2))
    x[U], x[RPS] = 6.0, 1.0
    for order, limit in ((10.0, act.rps_max), (-10.0, act.rps_min)):
        out = base.step(fam, params, act, x, 0.0, order, Env(), 4.0, 8)
        factor = _rk4_factor(-0.5 / act.engine_tau_s) ** 8
        np.testing.assert_allclose(out[RPS], limit + (1.0 - limit) * factor, rtol=1e-12)
        np.testing.assert_allclose(out[RPS], limit + (1.0 - limit)
                                   * np.exp(-4.0 / act.engine_tau_s), rtol=1e-7)


# -- steady rps -------------------------------------------------------------------------------


def test_steady_rps_for_speed_inverts_the_nomoto_surge_law_and_caps_at_rps_max():
    """u_ss = U_service n / n_service (nomoto module); cargo.yaml's rps_max gives 20 kn, so
    22 kn is out of reach and returns rps_max."""
    spec = load_ship("cargo")
    fam, n = _family(spec), 5
    speeds = from_kn(np.array([3.0, 7.5, 15.0, 19.0, 22.0]))
    out = base.steady_rps_for_speed(fam, fam.build([spec] * n), Actuators.from_specs([spec] * n),
                                    speeds)
    want = speeds / from_kn(15.0) * spec["coefficients"]["rps_service"]
    np.testing.assert_allclose(out[:4], want[:4], rtol=1e-12)
    assert want[4] > spec["actuators"]["rps_max"]
    assert out[4] == pytest.approx(spec["actuators"]["rps_max"], rel=1e-12)


def test_steady_rps_for_speed_wants_one_speed_per_ship():
    """The compiled loop reads one parameter row per speed: more speeds than ships would read
    past the tables, so it is refused."""
    spec = load_ship("cargo")
    fam = _family(spec)
    with pytest.raises(ValueError, match="one speed per ship"):
        base.steady_rps_for_speed(fam, fam.build([spec]), Actuators.from_specs([spec]),
                                  np.full(4, 5.0))


def test_steady_rps_for_speed_of_the_response_model_is_the_root_of_its_surge_balance():
    """[seed 001, eq 2] straight ahead: a1 u|u| + 60 a8 u n + 3600 a9 n^2 = 0 (n in rev/s),
    whose positive root gives u = 0.0781 m/s per rpm (response module docstring)."""
    spec = load_ship("bulk_carrier")
    c, fam = spec["coefficients"], _family(spec)
    a1, a8, a9 = c["a1"], 60.0 * c["a8"], 3600.0 * c["a9"]
    speeds = np.array([1.0, 4.37, 6.0])
    out = base.steady_rps_for_speed(fam, fam.build([spec] * 3), Actuators.from_specs([spec] * 3),
                                    speeds)
    want = speeds * (-a8 + math.sqrt(a8 * a8 - 4.0 * a9 * a1)) / (2.0 * a9)
    np.testing.assert_allclose(out, want, rtol=1e-12)
    np.testing.assert_allclose(speeds / (60.0 * out), 0.0781, rtol=1e-3)


def test_steady_rps_for_speed_zeroes_the_mmg_surge_acceleration():
    """kvlcc2 (MMG) at 40 % and 100 % of the service speed: du vanishes at the returned rps
    and has opposite signs 0.1 % either side (checked by ``accelerations``, not bisection)."""
    spec = load_ship("kvlcc2")
    fam = _family(spec)
    speeds = np.array([0.4, 1.0]) * from_kn(spec["service_speed_kn"])
    params2 = fam.build([spec] * 2)
    out = base.steady_rps_for_speed(fam, params2, Actuators.from_specs([spec] * 2), speeds)
    assert np.all(out > 0.0) and np.all(out < spec["actuators"]["rps_max"])
    params6 = fam.build([spec] * 6)
    x = np.zeros((base.N_STATE, 6))
    x[U] = np.tile(speeds, 3)
    x[RPS] = np.concatenate([out, out * 1.001, out * 0.999])
    du, _, _ = base.accelerations(fam, params6, x, Env())
    assert np.all(du[2:4] > 0.0) and np.all(du[4:6] < 0.0)
    assert np.all(np.abs(du[:2]) < 1e-6 * np.minimum(du[2:4], -du[4:6]))


# -- registry ---------------------------------------------------------------------------------


def test_families_are_registered_under_their_names_and_match_the_kernel_codes():
    fams = base.families()
    assert set(fams) == set(kernels.FAMILY_CODE)
    assert all(f.name == name for name, f in fams.items())
    assert fams["nomoto"].supports_astern and not fams["response"].supports_astern


def test_register_adds_a_family_and_returns_it(monkeypatch):
    monkeypatch.setattr(base, "_REGISTRY", dict(base._REGISTRY))

    class Dummy:
        name = "dummy"
        supports_astern = False

        def __init__(self):
            self.coefficients = {}

    d = Dummy()
    assert base.register(d) is d
    assert base.families()["dummy"] is d
    assert "mmg" in base.families()


# -- steady rps against scipy, bisection precision, sub-steps ----------------------------------


@pytest.mark.parametrize("name", ["catfish", "kvlcc2", "bulk_carrier", "cargo"])
def test_steady_rps_for_speed_equals_brentq_on_the_surge_acceleration(name):
    """scipy's brentq on du(u, n) = 0 (v = r = rudder = 0, calm water), evaluated through
    ``accelerations``, gives the rps the compiled bisection returns, at 30, 60 and 90 % of the
    service speed (all reachable for these ships)."""
    from scipy.optimize import brentq

    spec = load_ship(name)
    fam = _family(spec)
    speeds = np.array([0.3, 0.6, 0.9]) * from_kn(spec["service_speed_kn"])
    got = base.steady_rps_for_speed(fam, fam.build([spec] * 3), Actuators.from_specs([spec] * 3),
                                    speeds)
    params1 = fam.build([spec])

    def du(n, u):
        x = np.zeros((base.N_STATE, 1))
        x[U], x[RPS] = u, n
        return base.accelerations(fam, params1, x, Env())[0][0]

    for u, g in zip(speeds, got, strict=True):
        root = brentq(du, 0.0, spec["actuators"]["rps_max"], args=(u,), xtol=1e-15, rtol=1e-15)
        assert g == pytest.approx(root, rel=1e-10, abs=1e-12)


def test_steady_rps_bisection_precision_follows_the_iteration_count():
    """``iters`` halvings of [0, rps_max] leave the midpoint within rps_max / 2^(iters + 1)
    of the root; 0 iterations give rps_max / 2 exactly."""
    spec = load_ship("cargo")
    fam = _family(spec)
    params, act = fam.build([spec]), Actuators.from_specs([spec])
    speed = np.array([from_kn(11.0)])
    exact = 11.0 / 15.0 * spec["coefficients"]["rps_service"]
    rmax = spec["actuators"]["rps_max"]
    assert base.steady_rps_for_speed(fam, params, act, speed, iters=0)[0] == 0.5 * rmax
    for iters in (1, 5, 12, 30):
        got = base.steady_rps_for_speed(fam, params, act, speed, iters=iters)[0]
        assert abs(got - exact) <= rmax / 2 ** (iters + 1) + 1e-15


def test_step_with_substeps_equals_that_many_shorter_steps():
    """``step(dt, substeps=m)`` is m RK4 steps of dt/m: the same state as m calls with dt/m
    (a heading kept away from the 0/2 pi wrap)."""
    spec = load_ship("catfish")
    fam = _family(spec)
    params, act = fam.build([spec] * 2), Actuators.from_specs([spec] * 2)
    x0 = np.zeros((base.N_STATE, 2))
    x0[PSI], x0[U], x0[RPS] = 1.0, [3.0, 4.0], [15.0, 20.0]
    cmd_r, cmd_n = np.radians([20.0, -10.0]), np.array([18.0, 22.0])
    one = base.step(fam, params, act, x0, cmd_r, cmd_n, Env(), 2.0, substeps=4)
    many = x0.copy()
    for _ in range(4):
        many = base.step(fam, params, act, many, cmd_r, cmd_n, Env(), 0.5, substeps=1)
    np.testing.assert_allclose(one, many, rtol=1e-13, atol=1e-13)
