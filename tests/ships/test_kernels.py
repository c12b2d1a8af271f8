"""The fused step kernel: family dispatch, RK4 order, sub-steps, heading range, steering gear
and engine lags [seed 002, eqs 4.7-4.8]."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trafficsim.ships import base, kernels
from trafficsim.ships.base import PSI, RPS, RUDDER, Actuators, Env, R, U
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
