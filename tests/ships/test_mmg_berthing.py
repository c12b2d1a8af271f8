"""The ``mmg_berthing`` family (Miyauchi et al. 2022 low-speed MMG model) on the Esso Osaka
model's MMG parameter folder, read at run time: the kernel against an independent scalar
transcription of its equations, the closed-form cross-flow integrals, physics sanity (rest,
straight run, turn, going astern), continuity across u = 0 and n = 0, the engine's batch step,
and the hull effects."""

from __future__ import annotations

import copy
import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.conftest import SHARED
from trafficsim import effects
from trafficsim.batch import build_batch
from trafficsim.engine import Simulation
from trafficsim.errors import InputError
from trafficsim.io.scenario import load_scenario
from trafficsim.run import scenario_setups
from trafficsim.ships import base
from trafficsim.ships.base import PSI, RPS, RUDDER, R, U, V
from trafficsim.ships.library import load_ship
from trafficsim.ships.mmg_berthing import FAMILY, J_FADE, J_RAMP, cross_flow

FOLDER = SHARED / "data" / "esso-osaka-mmg" / "python_module" / "input_csv"
pytestmark = pytest.mark.skipif(not FOLDER.is_dir(), reason="MMG parameter folder not present")


@pytest.fixture(scope="module")
def spec() -> dict[str, Any]:
    return load_ship(str(FOLDER))


def _accel(spec: dict[str, Any], states: np.ndarray) -> np.ndarray:
    """``(3, k)`` accelerations at ``states`` ``(k, 5)`` = u, v, r, n, delta."""
    states = np.atleast_2d(states)
    k = states.shape[0]
    x = np.zeros((base.N_STATE, k))
    x[U], x[V], x[R], x[RPS], x[RUDDER] = states.T
    params = FAMILY.build([spec] * k)
    return np.array(base.accelerations(FAMILY, params, x, base.Env()))


def _run(spec: dict[str, Any], seconds: float, rudder_rad: float, rps: float,
         speed: float = 0.0) -> np.ndarray:
    """State history ``(steps + 1, 8)`` with constant orders (engine lag from the spec)."""
    params, act = FAMILY.build([spec]), base.Actuators.from_specs([spec])
    x = np.zeros((base.N_STATE, 1))
    x[U] = speed
    rows = [x[:, 0].copy()]
    for _ in range(round(seconds / 0.5)):
        x = base.step(FAMILY, params, act, x, np.array([rudder_rad]), np.array([rps]),
                      base.Env(), 0.5, 5)
        rows.append(x[:, 0].copy())
    return np.array(rows)


# --- an independent scalar transcription of the module's equations, numerical cross-flow ---

def _written_out(spec: dict[str, Any], u: float, v: float, r: float, n: float,
                 delta: float) -> tuple[float, float, float]:
    """The equations of :mod:`trafficsim.ships.mmg_berthing` written out literally for one
    state outside its regularised bands (|J| < J_FADE, |J_s| > J_RAMP near u = 0), SI units,
    the cross-flow integrals by a fine trapezoidal rule."""
    c, p = spec["coefficients"], spec["particulars"]
    rho = p["water_density_kgpm3"]
    L, d, D = p["length_m"], p["draught_m"], p["propeller_diameter_m"]
    pitch = p["propeller_pitch_ratio"] * D
    m = rho * p["displacement_m3"]
    xg = p["lcg_m"]
    h1, h2 = 0.5 * rho * L * d, 0.5 * rho * L * L * d
    big_u = math.hypot(u, v)
    beta = math.atan2(v, u)
    xs = np.linspace(-L / 2, L / 2, 20001)
    wy = (v + c["C_rY"] * r * xs)
    wn = (v + c["C_rN"] * r * xs)
    y_cf = 0.5 * rho * d * c["C_D"] * np.trapezoid(np.abs(wy) * wy, xs)
    n_cf = 0.5 * rho * d * c["C_D"] * np.trapezoid(np.abs(wn) * wn * xs, xs)
    xh = h1 * ((c["X_0F"] + (c["X_0A"] - c["X_0F"]) * abs(beta) / math.pi) * u * big_u
               + c["X_vr"] * v * r * L)
    yh = h1 * (c["Y_v"] * v * abs(u) + c["Y_r"] * r * L * u) - y_cf
    nh = h2 * (c["N_v"] * v * u + c["N_r"] * r * L * abs(u)) - n_cf
    # propeller
    bp = (v + c["x_P"] * L * r) / big_u
    one_m_w = min(max(1 - (c["w_P0"] - c["tau_P"] * abs(bp) - c["C_P"] * bp * bp), 1e-12),
                  1.0) if u > 0 else 1.0
    js = u / (n * D)
    a = [c[f"a_P{i}"] for i in range(8)]
    b = [c[f"b_P{i}"] for i in range(8)]
    if n >= 0:
        j = one_m_w * js
        kt = c["k_0"] + c["k_1"] * j + c["k_2"] * j * j
        xp = (1 - c["t_P"]) * rho * n * n * D**4 * kt
        yp = npp = 0.0
        if u < 0:
            yp = h1 * (n * pitch) ** 2 * (a[5] * js**2 + a[6] * js + a[7])
            npp = h2 * (n * pitch) ** 2 * (b[5] * js**2 + b[6] * js + b[7])
    else:
        kt = c["c_P1"] + c["c_P2"] * js if js >= c["c_P3"] else c["c_P0"]
        xp = rho * n * n * D**4 * kt
        i0, j0 = (2, 3) if js < -0.35 else ((0, 1) if js <= -0.06 else (4, None))
        yp = h1 * (n * D) ** 2 * (a[i0] + (a[j0] * js if j0 else 0.0))
        npp = h2 * (n * D) ** 2 * (b[i0] + (b[j0] * js if j0 else 0.0))
    # rudder
    eta = D / p["rudder_height_m"]
    eps, kappa = c["epsilon"], c["k_x"] / c["epsilon"]
    up = one_m_w * u
    if n >= 0 and kt > 0:
        ur = eps * math.sqrt(eta * (up + kappa * (math.sqrt(up**2 + 8 * kt * (n * D) ** 2
                                                            / math.pi) - up)) ** 2
                             + (1 - eta) * up**2)
    elif u < 0:
        ur = u
    else:
        p1 = eps * up + n * D * c["k_x_reverse"] * math.sqrt(8 * abs(kt) / math.pi)
        sq = eta * math.copysign(p1**2, p1) + (1 - eta) * (eps * up) ** 2 + c["C_PR"] * u * u
        ur = math.copysign(math.sqrt(abs(sq)), sq)
    beta_r = -(v + c["l_R"] * L * r)
    vr = (c["gamma_R_plus"] if beta_r > 0 else c["gamma_R_minus"]) * beta_r
    fn = 0.5 * rho * p["rudder_area_m2"] * c["f_alpha"] * (ur**2 + vr**2) * math.sin(
        delta - math.atan2(vr, ur))
    a_h = c["a_H"]
    xr = -(1 - c["t_R"]) * fn * math.sin(delta)
    yr = -(1 + a_h) * fn * math.cos(delta)
    nr = -(c["x_R"] + a_h * c["x_H"]) * L * fn * math.cos(delta)
    mx, my, jz = c["m_x"] * h2, c["m_y"] * h2, c["J_z"] * h2 * L * L
    izz = m * (c["k_zz"] * L) ** 2 + xg * xg * m + jz
    X, Y, N = xh + xp + xr, yh + yp + yr, nh + npp + nr
    du = (X + (m + my) * v * r + xg * m * r * r) / (m + mx)
    mat = np.array([[m + my, xg * m], [xg * m, izz]])
    dv, dr = np.linalg.solve(mat, [Y - (m + mx) * u * r, N - xg * m * u * r])
    return du, float(dv), float(dr)


def test_kernel_matches_written_out_equations(spec: dict[str, Any]) -> None:
    rng = np.random.default_rng(4)
    states = np.column_stack([rng.uniform(-0.3, 0.5, 3000), rng.uniform(-0.1, 0.1, 3000),
                              rng.uniform(-0.15, 0.15, 3000), rng.uniform(-20, 20, 3000),
                              rng.uniform(-0.6, 0.6, 3000)])
    js = states[:, 0] / (states[:, 3] * spec["particulars"]["propeller_diameter_m"])
    regular = (np.abs(js) < J_FADE) & (np.abs(js) > J_RAMP)
    states = states[regular][:400]
    got = _accel(spec, states)
    want = np.array([_written_out(spec, *s) for s in states]).T
    scale = np.abs(want).max(axis=1, keepdims=True)
    assert np.all(np.abs(got - want) <= 1e-6 * scale)
    # every quadrant of (u, n) is in the sample
    assert len({(s[0] > 0, s[3] > 0) for s in states}) == 4


def test_cross_flow_closed_form() -> None:
    half = 1.5
    xs = np.linspace(-half, half, 200001)
    for a, b in [(0.05, 0.0), (0.0, 0.1), (0.02, 0.1), (-0.07, 0.03), (0.3, -0.05), (0, 0)]:
        w = a + b * xs
        assert cross_flow(a, b, half, False) == pytest.approx(
            np.trapezoid(np.abs(w) * w, xs), rel=1e-8, abs=1e-14)
        assert cross_flow(a, b, half, True) == pytest.approx(
            np.trapezoid(np.abs(w) * w * xs, xs), rel=1e-8, abs=1e-14)
    # pure sway: L v|v|; pure yaw: no force, moment b|b| L^4 / 32
    assert cross_flow(-0.1, 0.0, half, False) == pytest.approx(-3.0 * 0.01)
    assert cross_flow(0.0, 0.2, half, False) == pytest.approx(0.0, abs=1e-15)
    assert cross_flow(0.0, -0.2, half, True) == pytest.approx(-0.04 * 3.0**4 / 32)


def test_folder_ship_is_the_esso_osaka_model(spec: dict[str, Any]) -> None:
    """Mass and centre of gravity as the FRT-DS-ESSO data set states them (244.6 kg, 0.094 m):
    the folder's mass is non-dimensional with fresh water and its x_lcg is x_G / L."""
    p = spec["particulars"]
    assert spec["model"] == "mmg_berthing"
    assert p["water_density_kgpm3"] * p["displacement_m3"] == pytest.approx(244.6, abs=0.1)
    assert p["lcg_m"] == pytest.approx(0.094, abs=0.001)


def test_at_rest_no_force(spec: dict[str, Any]) -> None:
    rest = np.array([[0.0, 0.0, 0.0, 0.0, d] for d in (-0.6, 0.0, 0.3)])
    assert np.array_equal(_accel(spec, rest), np.zeros((3, 3)))


def test_straight_run_reaches_a_model_scale_speed(spec: dict[str, Any]) -> None:
    """10 rps from rest for 400 s (7 time constants of the surge): a steady 0.3-0.5 m/s
    (Froude number 0.06-0.09 for the 3 m model, between the 0.33 m/s the 10 rps zig-zags of the
    data reach and the 16.7 rps ones' 0.53 m/s), straight, the speed growing with the propeller
    speed."""
    runs = {n: _run(spec, 400.0, 0.0, n) for n in (8.0, 10.0, 12.0)}
    u = {n: run[-1, U] for n, run in runs.items()}
    assert 0.3 < u[10.0] < 0.5
    assert u[8.0] < u[10.0] < u[12.0]
    assert abs(runs[10.0][-1, U] - runs[10.0][-21, U]) < 0.01 * u[10.0]  # steady
    assert np.all(runs[10.0][:, [V, R, PSI]] == 0.0)


def test_positive_rudder_turns_to_starboard(spec: dict[str, Any]) -> None:
    run = _run(spec, 120.0, math.radians(20.0), 10.0, speed=0.35)
    assert run[-1, R] > 0.0 and run[-1, PSI] > math.radians(90.0)
    mirror = _run(spec, 120.0, math.radians(-20.0), 10.0, speed=0.35)
    assert mirror[-1, R] < 0.0


def test_astern_decelerates_and_goes_astern(spec: dict[str, Any]) -> None:
    ahead = _run(spec, 60.0, 0.0, 10.0, speed=0.35)
    params, act = FAMILY.build([spec]), base.Actuators.from_specs([spec])
    x = ahead[-1][:, None].copy()
    speeds = [x[U, 0]]
    for _ in range(240):  # full astern for 120 s with a little rudder
        x = base.step(FAMILY, params, act, x, np.array([0.1]), np.array([-15.0]), base.Env(),
                      0.5, 5)
        speeds.append(x[U, 0])
        assert np.all(np.isfinite(x))
    speeds = np.array(speeds)
    assert speeds[-1] < -0.05
    stop = int(np.argmax(speeds < 0.0))
    assert stop > 0 and np.all(np.diff(speeds[: stop]) < 0.0)  # decelerates until it stops


def test_continuous_across_zero_speed_and_zero_propeller(spec: dict[str, Any]) -> None:
    """No jump where the quadrants meet (u = 0, n = 0); the published model's propeller side
    force, thrust and rudder inflow jump there by 1-5 % of the accelerations below."""
    eps = 1e-9
    vs, rs, ds = (-0.03, 0.0, 0.04), (-0.05, 0.0, 0.08), (-0.3, 0.0, 0.4)
    across_u = [(s * eps, v, r, n, d) for n, v, r, d in
                itertools.product((-15.0, -5.0, 5.0, 15.0), vs, rs, ds) for s in (1, -1)]
    across_n = [(u, v, r, s * eps, d) for u, v, r, d in
                itertools.product((-0.2, -0.05, 0.05, 0.3), vs, rs, ds) for s in (1, -1)]
    for states in (across_u, across_n):
        acc = _accel(spec, np.array(states))
        scale = np.abs(acc).max(axis=1)
        assert np.all(scale > 0.005)
        jump = np.abs(acc[:, 0::2] - acc[:, 1::2]).max(axis=1)
        assert np.all(jump < 1e-5 * scale)


def test_scenario_ship_from_the_folder(tmp_path: Path) -> None:
    """The folder as a scenario ship's type, next to a KVLCC2, in the engine's batch step."""
    path = tmp_path / "berth.yaml"
    path.write_text(f"""schema_version: 1
name: berth
duration_s: 60
dt_s: 1.0
ships:
  - name: model
    type: {FOLDER.resolve()}
    north_m: 0
    east_m: 0
    heading_deg: 0
    speed_kn: 0.6
    behaviour: keep_course
  - name: tanker
    type: kvlcc2
    north_m: 5000
    east_m: 5000
    heading_deg: 180
    behaviour: keep_course
""")
    scn = load_scenario(path)
    setups, env = scenario_setups(scn)
    sim = Simulation.start(build_batch(setups, [env]), scn.dt_s)
    sim.run(60)
    x = sim.batch.x
    assert np.all(np.isfinite(x))
    assert x[base.NORTH, 0] == pytest.approx(0.6 * 1852 / 3600 * 60, rel=0.1)
    assert abs(x[base.EAST, 0]) < 0.5


def test_hull_effects(spec: dict[str, Any]) -> None:
    fouled = effects.apply_spec(spec, effects.check({"resistance": {"scale": 1.5}}))
    assert _run(fouled, 150.0, 0.0, 10.0)[-1, U] < _run(spec, 150.0, 0.0, 10.0)[-1, U] - 0.02
    assert fouled["coefficients"]["X_0A"] == pytest.approx(1.5 * spec["coefficients"]["X_0A"])
    offset = effects.apply_spec(spec, effects.check({"propeller_asymmetry":
                                                     {"rudder_offset_deg": 2.0}}))
    straight = np.array([[0.35, 0.0, 0.0, 10.0, 0.0]])
    assert _accel(spec, straight)[2, 0] == 0.0 and _accel(offset, straight)[2, 0] > 0.0
    shallow = effects.apply_spec(spec, effects.check({"shallow_water":
                                                      {"draught_to_depth": 0.6}}))
    f = effects.shallow_water_factor(0.6, spec)
    assert f > 1.0
    for key in ("Y_v", "Y_r", "N_v", "N_r", "m_y"):
        assert shallow["coefficients"][key] == pytest.approx(f * spec["coefficients"][key])
    # shallow water damps the turn
    turn, turn_shallow = (_run(s, 60.0, math.radians(20.0), 10.0, speed=0.35)[-1, R]
                          for s in (spec, shallow))
    assert 0.0 < turn_shallow < turn
    nomoto = copy.deepcopy(load_ship("catfish"))
    with pytest.raises(InputError, match="mmg and mmg_berthing"):
        effects.apply_spec(nomoto, effects.check({"resistance": {"scale": 1.2}}))
