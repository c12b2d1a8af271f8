"""The fused step kernel: family dispatch, RK4 order, sub-steps, heading range, steering gear
and engine lags [seed 002, eqs 4.7-4.8]."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from tests.conftest import SHARED, packed_divisions, requires_avx
from trafficsim.ships import base, kernels
from trafficsim.ships.base import PSI, RPS, RUDDER, Actuators, Env, R, U, V
from trafficsim.ships.library import load_ship

#: a ship of each library family (modular, mmg, nomoto, response) and a second nomoto
SHIPS = ("catfish", "kvlcc2", "cargo", "bulk_carrier", "container")


def _table(names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Family codes, packed parameters (padded to one width) and actuator table."""
    specs = [load_ship(n) for n in names]
    fams = base.families()
    rows = [base.pack(fams[s["model"]].build([s]))[0] for s in specs]
    width = max(r.size for r in rows)
    P = np.zeros((len(rows), width))
    for i, r in enumerate(rows):
        P[i, : r.size] = r
    codes = np.array([kernels.FAMILY_CODE[s["model"]] for s in specs], dtype=np.int64)
    return codes, P, base.actuator_table(Actuators.from_specs(specs))


def _start(names: tuple[str, ...]) -> np.ndarray:
    """Straight ahead at 80 % of the service speed, on the propeller speed that holds it."""
    x = np.zeros((base.N_STATE, len(names)))
    for i, n in enumerate(names):
        spec = load_ship(n)
        fam = base.families()[spec["model"]]
        speed = 0.8 * spec["service_speed_kn"] * 1852.0 / 3600.0
        x[U, i] = speed
        x[RPS, i] = base.steady_rps_for_speed(fam, fam.build([spec]),
                                              Actuators.from_specs([spec]), np.array([speed]))[0]
        x[PSI, i] = 0.3 + i
    return x


def _run(codes: np.ndarray, P: np.ndarray, A: np.ndarray, x: np.ndarray, rudder: float,
         dt: float, steps: int, substeps: int = 1) -> np.ndarray:
    x = np.array(x, order="C")
    n = x.shape[1]
    env = base.env_table(Env(current_north_mps=0.3, current_east_mps=-0.2, wind_speed_mps=8.0,
                             wind_from_rad=1.0), n)
    for _ in range(steps):
        kernels.step_ships(codes, P, A, x, np.full(n, rudder), np.array(x[RPS]), env, dt,
                           np.full(n, substeps, dtype=np.int64))
    return x


def _angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs((a - b + math.pi) % (2.0 * math.pi) - math.pi)


def test_mixed_batch_equals_one_ship_at_a_time() -> None:
    """Ships of all families in one batch step exactly as each does alone (no ship sees
    another's parameters or state)."""
    codes, P, A = _table(SHIPS)
    x0 = _start(SHIPS)
    together = _run(codes, P, A, x0, math.radians(15.0), 1.0, 30)
    for i in range(len(SHIPS)):
        alone = _run(codes[i:i + 1], P[i:i + 1], A[i:i + 1], x0[:, i:i + 1],
                     math.radians(15.0), 1.0, 30)
        np.testing.assert_array_equal(together[:, i], alone[:, 0])


@pytest.mark.parametrize("ship", [s for s in SHIPS if load_ship(s)["model"] != "mmg"])
def test_rk4_error_falls_as_the_fourth_power_of_the_step(ship: str) -> None:
    """A 35 deg turn: halving the step divides the error by about 16 (steps of a tenth of
    the time the ship takes to sail its length and less). Not for the MMG family: its wake
    and flow-straightening coefficients switch on the sign of the drift angle at propeller
    and rudder, which a turn from straight ahead crosses, so no fixed-step method keeps its
    order there."""
    codes, P, A = _table((ship,))
    x0 = _start((ship,))
    x0[RUDDER] = math.radians(35.0)  # rudder already at its order: a smooth problem
    coarse = 0.1 * load_ship(ship)["particulars"]["length_m"] / x0[U, 0]
    t_end = 64 * coarse
    ref = _run(codes, P, A, x0, math.radians(35.0), coarse / 64.0, 64 * 64)
    errors = []
    for k in range(3):
        dt = coarse / 2**k
        x = _run(codes, P, A, x0, math.radians(35.0), dt, round(t_end / dt))
        pos = math.hypot(x[0, 0] - ref[0, 0], x[1, 0] - ref[1, 0])
        errors.append(pos)
    assert errors[0] > 0.0
    ratios = [errors[k] / errors[k + 1] for k in range(2)]
    assert all(10.0 < r < 24.0 for r in ratios), (errors, ratios)


def test_substeps_equal_repeated_short_steps() -> None:
    """``m`` sub-steps of ``dt / m`` in one call = ``m`` calls of ``dt / m`` (up to the heading
    being wrapped between calls)."""
    codes, P, A = _table(SHIPS)
    x0 = _start(SHIPS)
    one = _run(codes, P, A, x0, math.radians(-20.0), 2.0, 10, substeps=8)
    many = _run(codes, P, A, x0, math.radians(-20.0), 0.25, 80)
    np.testing.assert_allclose(np.delete(one, PSI, axis=0), np.delete(many, PSI, axis=0),
                               rtol=1e-9, atol=1e-9)
    assert _angle_diff(one[PSI], many[PSI]).max() < 1e-12


def test_heading_stays_in_zero_two_pi() -> None:
    codes, P, A = _table(SHIPS)
    x = _start(SHIPS)
    for rudder in (35.0, -35.0):
        for _ in range(20):
            x = _run(codes, P, A, x, math.radians(rudder), 1.0, 10)
            assert np.all((x[PSI] >= 0.0) & (x[PSI] < 2.0 * math.pi))


def test_steering_gear_rate_limit_and_engine_lag() -> None:
    """From midships to a 35 deg order the rudder moves at the rate limit [seed 002, eq 4.7]
    and never beyond the order; the propeller speed follows a first-order lag [eq 4.8]."""
    codes, P, A = _table(("cargo",))
    x0 = _start(("cargo",))
    rate = A[0, kernels.RUDDER_RATE]
    x = _run(codes, P, A, x0, math.radians(35.0), 1.0, 1)
    assert x[RUDDER, 0] == pytest.approx(rate, rel=1e-12)  # still rate limited after 1 s
    x = _run(codes, P, A, x0, math.radians(35.0), 1.0, 200)
    assert x[RUDDER, 0] <= math.radians(35.0) and x[RUDDER, 0] > math.radians(34.9)
    tau, target = A[0, kernels.ENGINE_TAU], 0.5 * x0[RPS, 0]
    xe = np.array(x0, order="C")
    env = base.env_table(Env(), 1)
    for _ in range(10):
        kernels.step_ships(codes, P, A, xe, np.zeros(1), np.array([target]), env, 1.0,
                           np.ones(1, dtype=np.int64))
    expected = target + (x0[RPS, 0] - target) * math.exp(-10.0 / tau)
    assert xe[RPS, 0] == pytest.approx(expected, rel=1e-6)


def test_accelerations_equal_the_family_kernels() -> None:
    """The batch ``accelerations`` dispatches each ship to its family's ``accel``."""
    codes, P, A = _table(SHIPS)
    x = _run(codes, P, A, _start(SHIPS), math.radians(10.0), 1.0, 20)
    env = base.env_table(Env(wind_speed_mps=5.0, wind_from_rad=0.5), len(SHIPS))
    out = kernels.accelerations(codes, P, x, env)
    for i in range(len(SHIPS)):
        one = kernels.accel(codes[i], P[i], np.ascontiguousarray(x[:, i]),
                            np.ascontiguousarray(env[:, i]))
        np.testing.assert_array_equal(out[:, i], one)
    assert np.all(np.isfinite(out)) and np.any(out[2] != 0.0)
    assert np.all(np.abs(x[R]) > 0.0)


def _scipy_track(code: int, p: np.ndarray, a: np.ndarray, x0: np.ndarray, rudder: float,
                 rps: float, env: np.ndarray, t_end: float) -> np.ndarray:
    """The same ship integrated by scipy (DOP853, tolerance 1e-11) with the rates written out
    from their definitions: the family's accelerations (``kernels.accel``), kinematics with
    the current, steering gear ``clip((clip(order, +-max) - delta) / T_R, +-rate)`` and engine
    ``(clip(order, min, max) - n) / T_N``."""
    from scipy.integrate import solve_ivp

    def rhs(t, y):
        du, dv, dr = kernels.accel(code, p, np.ascontiguousarray(y), env)
        c, s = math.cos(y[PSI]), math.sin(y[PSI])
        order = min(max(rudder, -a[kernels.RUDDER_MAX]), a[kernels.RUDDER_MAX])
        rate = min(max((order - y[RUDDER]) / a[kernels.RUDDER_TAU], -a[kernels.RUDDER_RATE]),
                   a[kernels.RUDDER_RATE])
        n = min(max(rps, a[kernels.RPS_MIN]), a[kernels.RPS_MAX])
        return [y[U] * c - y[4] * s + env[0], y[U] * s + y[4] * c + env[1], y[R], du, dv, dr,
                rate, (n - y[RPS]) / a[kernels.ENGINE_TAU]]

    sol = solve_ivp(rhs, (0.0, t_end), x0, method="DOP853", rtol=1e-11, atol=1e-11)
    return sol.y[:, -1]


@pytest.mark.parametrize("ship, rudder_deg, rps_factor", [
    ("cargo", 25.0, 1.1), ("kvlcc2", 25.0, 1.1), ("catfish", -20.0, 0.9),
    ("bulk_carrier", 50.0, 3.0), ("container", -35.0, -1.0), ("kvlcc2", -10.0, 0.5)])
def test_rk4_step_agrees_with_scipy_on_the_same_model(ship, rudder_deg, rps_factor) -> None:
    """After two ship lengths' time of a turn in current and wind, with orders beyond the
    limits in some cases (50 deg rudder, three times or reversed propeller speed), 100 RK4
    steps match scipy: positions to 2e-5 L, heading to 3e-5 rad, velocities to 1e-5 of the
    speed, yaw rate, rudder and propeller speed to 1e-6; with 400 steps the position error
    falls at least fourfold (integration error, not a different model)."""
    codes, P, A = _table((ship,))
    x0 = _start((ship,))
    x0[PSI] = 0.3
    length = load_ship(ship)["particulars"]["length_m"]
    t_end = 2.0 * length / x0[U, 0]
    env = base.env_table(Env(current_north_mps=0.3, current_east_mps=-0.2, wind_speed_mps=8.0,
                             wind_from_rad=1.0), 1)
    rudder, rps = math.radians(rudder_deg), rps_factor * x0[RPS, 0]
    ref = _scipy_track(codes[0], P[0], A[0], x0[:, 0].copy(), rudder, rps,
                       np.ascontiguousarray(env[:, 0]), t_end)
    errors = []
    for steps in (100, 400):
        x = np.array(x0, order="C")
        for _ in range(steps):
            kernels.step_ships(codes, P, A, x, np.array([rudder]), np.array([rps]), env,
                               t_end / steps, np.ones(1, dtype=np.int64))
        errors.append(math.hypot(x[0, 0] - ref[0], x[1, 0] - ref[1]))
        if steps == 100:
            got = x[:, 0].copy()
    assert errors[0] < 2e-5 * length and errors[1] < errors[0] / 4.0
    assert _angle_diff(got[PSI], ref[PSI]) < 3e-5
    np.testing.assert_allclose(got[[U, 4]], ref[[U, 4]], rtol=0, atol=1e-5 * x0[U, 0])
    np.testing.assert_allclose(got[[R, RUDDER, RPS]], ref[[R, RUDDER, RPS]], rtol=0, atol=1e-6)
    # orders beyond the limits: the rudder stays within its maximum, the engine its range
    assert abs(got[RUDDER]) <= A[0, kernels.RUDDER_MAX] + 1e-12
    assert A[0, kernels.RPS_MIN] - 1e-12 <= got[RPS] <= A[0, kernels.RPS_MAX] + 1e-12


def test_mmg_berthing_step_agrees_with_scipy() -> None:
    """The Esso Osaka ``mmg_berthing`` model (read from its parameter folder) at slow speed,
    also against scipy."""
    folder = SHARED / "data" / "esso-osaka-mmg" / "python_module" / "input_csv"
    if not folder.is_dir():
        pytest.skip("MMG parameter folder not present")
    spec = load_ship(str(folder))
    fam = base.families()["mmg_berthing"]
    codes = np.array([kernels.FAMILY_CODE["mmg_berthing"]])
    P = base.pack(fam.build([spec]))
    A = base.actuator_table(Actuators.from_specs([spec]))
    x0 = np.zeros((base.N_STATE, 1))
    x0[U], x0[RPS], x0[PSI] = 0.4, 10.0, 1.0
    env = base.env_table(Env(current_north_mps=0.02, wind_speed_mps=2.0, wind_from_rad=2.0), 1)
    t_end = 30.0
    ref = _scipy_track(codes[0], P[0], A[0], x0[:, 0].copy(), math.radians(20.0), 12.0,
                       np.ascontiguousarray(env[:, 0]), t_end)
    x = np.array(x0, order="C")
    for _ in range(300):
        kernels.step_ships(codes, P, A, x, np.array([math.radians(20.0)]), np.array([12.0]),
                           env, t_end / 300, np.ones(1, dtype=np.int64))
    assert math.hypot(x[0, 0] - ref[0], x[1, 0] - ref[1]) < 1e-4
    assert _angle_diff(x[PSI, 0], ref[PSI]) < 1e-5
    np.testing.assert_allclose(x[[U, 4, R, RUDDER, RPS], 0], ref[[U, 4, R, RUDDER, RPS]],
                               atol=1e-6)


def test_substeps_converge_to_scipy_and_one_substep_is_one_step() -> None:
    """Sub-stepping refines the same RK4: the error against scipy of one step of 20 s falls
    with 1, 2, 4, 8 sub-steps, by about 16 per halving once resolved; ``substeps = 1`` is a
    single plain step."""
    codes, P, A = _table(("bulk_carrier",))
    x0 = _start(("bulk_carrier",))
    x0[RUDDER] = math.radians(20.0)
    env = base.env_table(Env(), 1)
    ref = _scipy_track(codes[0], P[0], A[0], x0[:, 0].copy(), math.radians(20.0),
                       x0[RPS, 0], np.ascontiguousarray(env[:, 0]), 20.0)
    errors = []
    for m in (1, 2, 4, 8):
        x = np.array(x0, order="C")
        kernels.step_ships(codes, P, A, x, np.array([math.radians(20.0)]), np.array(x0[RPS]),
                           env, 20.0, np.array([m]))
        errors.append(math.hypot(x[0, 0] - ref[0], x[1, 0] - ref[1]))
    assert errors[0] > errors[1] > errors[2] > errors[3] > 0.0
    assert 8.0 < errors[2] / errors[3] < 32.0


def test_an_empty_batch_steps_and_a_port_turn_wraps_through_north() -> None:
    """No ships: nothing to do and no error. A port turn from heading 0.05 rad crosses north:
    the heading wraps to just below 2 pi, continuous with the unwrapped heading of a
    run from 0.05 + 2 pi."""
    codes, P, A = _table(("cargo",))
    empty = np.zeros((base.N_STATE, 0))
    kernels.step_ships(codes[:0], P[:0], A[:0], empty, np.zeros(0), np.zeros(0),
                       np.zeros((4, 0)), 1.0, np.zeros(0, dtype=np.int64))
    assert kernels.accelerations(codes[:0], P[:0], empty, np.zeros((4, 0))).shape == (3, 0)
    x0 = _start(("cargo",))
    x0[PSI], x0[RUDDER], x0[R] = 0.05, math.radians(-35.0), -0.01
    env = base.env_table(Env(), 1)
    a = np.array(x0, order="C")
    b = np.array(x0, order="C")
    b[PSI] += 2 * math.pi
    for _ in range(10):
        for x in (a, b):
            kernels.step_ships(codes, P, A, x, np.array([math.radians(-35.0)]),
                               np.array(x0[RPS]), env, 1.0, np.ones(1, dtype=np.int64))
    assert math.pi < a[PSI, 0] < 2 * math.pi
    assert _angle_diff(a[PSI], b[PSI])[0] < 1e-12
    np.testing.assert_allclose(a[[0, 1, U, R]], b[[0, 1, U, R]], rtol=0, atol=1e-9)


def test_steady_rps_is_the_nomoto_closed_form_and_saturates() -> None:
    """Nomoto surge is at rest when ``u = U_s n / n_s``, so the steady propeller speed is
    ``n_s u / U_s``; a speed beyond the engine gives ``rps_max``; the found rps holds the
    speed (zero surge acceleration) for the other families."""
    spec = load_ship("cargo")
    fam = base.families()["nomoto"]
    params, act = fam.build([spec] * 4), Actuators.from_specs([spec] * 4)
    us = spec["service_speed_kn"] * 1852.0 / 3600.0
    speeds = np.array([0.2, 0.5, 1.0, 1.3]) * us
    got = base.steady_rps_for_speed(fam, params, act, speeds)
    np.testing.assert_allclose(got, spec["coefficients"]["rps_service"] * speeds / us,
                               rtol=1e-12)
    fast = base.steady_rps_for_speed(fam, fam.build([spec]), Actuators.from_specs([spec]),
                                     np.array([2.0 * us]))
    assert fast[0] == pytest.approx(spec["actuators"]["rps_max"], rel=1e-12)
    for name in ("kvlcc2", "bulk_carrier", "catfish"):
        s = load_ship(name)
        f = base.families()[s["model"]]
        speed = 0.7 * s["service_speed_kn"] * 1852.0 / 3600.0
        n = base.steady_rps_for_speed(f, f.build([s]), Actuators.from_specs([s]),
                                      np.array([speed]))
        x = np.zeros((base.N_STATE, 1))
        x[U], x[RPS] = speed, n[0]
        du, _, _ = base.accelerations(f, f.build([s]), x, Env())
        assert abs(du[0]) < 1e-9


def test_heading_a_hair_west_of_north_wraps_below_two_pi() -> None:
    """From north with a yaw rate of -1e-19 rad/s the heading after a step is -1e-19 rad,
    whose remainder modulo 2 pi rounds to 2 pi itself: the wrapped heading must still lie in
    [0, 2 pi) (as :func:`trafficsim.sensors.wrap_2pi` guarantees)."""
    codes, P, A = _table(("cargo",))
    x = np.array(_start(("cargo",)), order="C")
    x[PSI], x[R] = 0.0, -1e-19
    kernels.step_ships(codes, P, A, x, np.zeros(1), np.array(x[RPS]), base.env_table(Env(), 1),
                       1.0, np.ones(1, dtype=np.int64))
    assert 0.0 <= x[PSI, 0] < 2.0 * math.pi


def _states(names: tuple[str, ...], copies: int, rng: np.random.Generator) -> tuple:
    """``copies`` ships of each of ``names`` in random states, with their tables: headings
    round the circle (and just either side of north), yaw rates and rudders up to fast turns."""
    codes, P, A = _table(names)
    idx = np.tile(np.arange(len(names)), copies)
    x = _start(names)[:, idx]
    n = idx.size
    x[PSI] = rng.uniform(0.0, 2.0 * math.pi, n)
    x[PSI, :8] = [0.0, 1e-19, np.nextafter(2.0 * math.pi, 0.0), 1e-3, 6.28, 3.0, 0.5, 2.0]
    x[R] = rng.uniform(-0.05, 0.05, n)
    x[R, :8] = [-1e-19, -1e-3, 1e-3, -0.01, 0.03, 0.07, -0.07, 0.0]
    x[RUDDER] = rng.uniform(-0.6, 0.6, n)
    x[U] *= rng.uniform(0.0, 1.3, n)
    x[V] = rng.uniform(-0.5, 0.5, n)
    return codes[idx], P[idx], A[idx], np.array(x, order="C")


@pytest.mark.parametrize("substeps", [1, 3])
def test_vectorised_step_equals_the_scalar_step_to_the_bit(substeps: int) -> None:
    """With the column tables, Nomoto and response-model ships go through the vectorised loop
    and the rest (MMG, modular, several sub-steps, fast turns, frozen ships) through the
    scalar one: every number equals that of the scalar loop alone, over a run of steps of
    every family mixed, turning both ways through north."""
    rng = np.random.default_rng(3)
    codes, P, A, x0 = _states(SHIPS, 60, rng)
    n = codes.size
    sub = np.full(n, substeps, dtype=np.int64)
    sub[::17] = 0  # frozen (a diverged encounter): left as it is
    env = base.env_table(Env(current_north_mps=0.4, current_east_mps=-0.3, wind_speed_mps=9.0,
                             wind_from_rad=2.0), n)
    tables = kernels.vector_tables(codes, P, A)
    assert tables is not None and tables[0].shape == (6, n) and tables[1].shape == (17, n)
    vec, ref = x0.copy(), x0.copy()
    for step in range(40):
        rudder = rng.uniform(-0.6, 0.6, n)
        rps = x0[RPS] * rng.uniform(0.5, 1.1, n)
        kernels.step_ships(codes, P, A, vec, rudder, rps, env, 1.0, sub, tables)
        kernels.step_ships(codes, P, A, ref, rudder, rps, env, 1.0, sub)
        np.testing.assert_array_equal(vec, ref, err_msg=f"step {step}")
    assert np.isfinite(vec).all()
    assert np.all((vec[PSI] >= 0.0) & (vec[PSI] < 2.0 * math.pi))


def test_vector_tables_only_for_the_vectorised_families() -> None:
    """No table for a batch without Nomoto or response-model ships; as many parameter columns
    as the widest of those present has; a single family steps the same either way."""
    codes, P, A = _table(("kvlcc2", "catfish"))
    assert kernels.vector_tables(codes, P, A) is None
    rng = np.random.default_rng(4)
    codes, P, A, x0 = _states(("container",), 50, rng)
    tables = kernels.vector_tables(codes, P, A)
    assert tables is not None
    assert tables[0].shape == (6, 50) and tables[1].shape == (7, 50)
    codes2, P2, A2 = _table(("bulk_carrier", "kvlcc2"))
    assert kernels.vector_tables(codes2, P2, A2)[1].shape == (17, 2)
    env = base.env_table(Env(), 50)
    sub = np.ones(50, dtype=np.int64)
    vec, ref = x0.copy(), x0.copy()
    kernels.step_ships(codes, P, A, vec, x0[RUDDER], x0[RPS], env, 1.0, sub, tables)
    kernels.step_ships(codes, P, A, ref, x0[RUDDER], x0[RPS], env, 1.0, sub)
    np.testing.assert_array_equal(vec, ref)


def _mask(codes, tables, x, sub) -> np.ndarray:
    """The ships the vectorised loops leave to the scalar one, on a copy of ``x``."""
    scalar = np.ones(codes.size, dtype=bool)
    fn = kernels._vectorised_nomoto if tables[1].shape[0] == 7 else kernels._vectorised_mixed
    fn(codes, tables[1], tables[0], x.copy(), x[RUDDER], x[RPS],
       base.env_table(Env(), codes.size), 1.0, sub, scalar)
    return scalar


def test_the_vectorised_loops_leave_the_exceptions_to_the_scalar_one() -> None:
    """Other families, several sub-steps, frozen ships, a stage turning past the series' reach
    and a heading far outside [0, 2 pi) go to the scalar loop; the rest do not."""
    rng = np.random.default_rng(6)
    codes, P, A, x = _states(SHIPS, 4, rng)
    tables = kernels.vector_tables(codes, P, A)
    x[R] = 0.01
    x[R, 7] = 0.07  # cargo: past the series at dt 1 s
    x[PSI, 8] = 3e6  # bulk carrier: beyond the reduction of cos_sin
    sub = np.ones(codes.size, dtype=np.int64)
    sub[[12, 13]] = [2, 0]  # cargo with two sub-steps, bulk carrier frozen
    scalar = _mask(codes, tables, x, sub)
    vectorised = np.isin(codes, [kernels.NOMOTO_CODE, kernels.RESPONSE_CODE])
    expected = ~vectorised
    expected[[7, 8, 12, 13]] = True
    np.testing.assert_array_equal(scalar, expected)


@requires_avx
def test_the_nomoto_loop_is_vectorised() -> None:
    """The compiler turns the Nomoto loop into packed divisions of four or eight ships per
    instruction (ymm or zmm registers; two-wide could be scalar code paired): the run-time
    overlap tests it needs are allowed (trafficsim.jit). Compiled afresh, since cached code
    cannot be inspected."""
    rng = np.random.default_rng(5)
    codes, P, A, x = _states(("container",), 8, rng)
    tables = kernels.vector_tables(codes, P, A)
    assert tables is not None
    fn = numba.njit(error_model="numpy")(kernels._vectorised_nomoto.py_func)
    fn(codes, tables[1], tables[0], x, x[RUDDER], x[RPS], base.env_table(Env(), codes.size), 1.0,
       np.ones(codes.size, dtype=np.int64), np.ones(codes.size, dtype=bool))
    assert packed_divisions(fn.inspect_asm(fn.signatures[0]))
