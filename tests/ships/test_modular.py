"""The ``modular`` family with the Catfish ship file against what the thesis states [seed 002]."""

from __future__ import annotations

import copy
import dataclasses
import functools
from collections.abc import Mapping
from typing import Any

import numpy as np
import pytest

from trafficsim.errors import ShipLibraryError
from trafficsim.ships import base, modular
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, RUDDER, Actuators, Env, R, U, V
from trafficsim.ships.library import load_ship
from trafficsim.ships.manoeuvres import turning_circle
from trafficsim.ships.modular import (
    EQ410_ORDER,
    FAMILY,
    ModularParams,
    engine_rpm,
    linearised_F,
    rps_from_engine_rpm,
)
from trafficsim.units import from_kn, to_kn


def _catfish(**coefficients: float) -> dict[str, Any]:
    """The Catfish ship file as a private dict, with some coefficients overridden."""
    spec = copy.deepcopy(load_ship("catfish"))  # the library caches: never mutate its dicts
    spec["coefficients"].update(coefficients)
    return spec


def _substeps(spec: Mapping[str, Any], dt: float) -> int:
    return max(1, int(np.ceil(dt / spec["integration"]["max_dt_s"] - 1e-9)))


def _straight_speed_kn(spec: Mapping[str, Any], rpm: float, seconds: float = 300.0) -> float:
    """Speed after ``seconds`` from rest at constant engine ``rpm`` (engine lag included)."""
    params, act = FAMILY.build([spec]), Actuators.from_specs([spec])
    x = np.zeros((base.N_STATE, 1))
    cmd = rps_from_engine_rpm(params, np.array([rpm]))
    for _ in range(int(seconds)):
        x = base.step(FAMILY, params, act, x, np.zeros(1), cmd, Env(), 1.0, _substeps(spec, 1.0))
    return float(to_kn(x[U, 0]))


def _steady_diameters(spec: Mapping[str, Any], rudder_deg: float, speed_kn: float
                      ) -> tuple[float, float]:
    """Steady turning diameters (m) to starboard and to port (ITTC definition, manoeuvres)."""
    stbd = turning_circle(spec, rudder_deg=rudder_deg, speed_kn=speed_kn)[1]
    port = turning_circle(spec, rudder_deg=-rudder_deg, speed_kn=speed_kn)[1]
    return stbd["steady_diameter_m"], port["steady_diameter_m"]


@functools.cache
def _catfish_diameters(rudder_deg: float, speed_kn: float) -> tuple[float, float]:
    """``_steady_diameters`` of the unmodified ship file (shared by two tests)."""
    return _steady_diameters(_catfish(), rudder_deg, speed_kn)


# ------------------------------------------------------------------------------------ straight run

def test_straight_run_speeds_match_the_stated_speeds_at_2200_and_1100_rpm() -> None:
    """'Forward Speed @ 2200 rpm 8.9 knots, @ 1100 rpm 4.2 knots' [seed 002, ch 3.2].

    The thesis surge model (X_uu u^2 + X_nn n^2, with X_u = X_uuu = 0 in table 4.1) makes the steady
    speed proportional to rpm, but the stated speeds have the ratio 2.12 for twice the rpm: no
    proportional law can be closer than +-2.9 % at both, and the printed coefficients are at that
    optimum (8.65 and 4.32 kn). Tolerance 3.5 % of the stated speed: a wrong unit for n (rev/s
    instead of rad/s, or engine instead of screw speed) is off by a factor of 1.66 or more.
    """
    spec = _catfish()
    for rpm, stated in ((2200.0, 8.9), (1100.0, 4.2)):
        speed = _straight_speed_kn(spec, rpm)
        assert speed == pytest.approx(stated, rel=0.035), (rpm, speed)
    assert _straight_speed_kn(spec, 2200.0) < 8.9 < _straight_speed_kn(spec, 2300.0)


def test_engine_rpm_conversion_uses_the_gear_ratio() -> None:
    """Engine/screw reduction 1.66:1 [seed 002, ch 3.2]: rps_max is 2500 engine rpm."""
    spec = _catfish()
    params = FAMILY.build([spec])
    assert engine_rpm(params, np.array([spec["actuators"]["rps_max"]]))[0] == pytest.approx(
        2500.0, rel=1e-3)
    assert rps_from_engine_rpm(params, engine_rpm(params, np.array([7.0])))[0] == pytest.approx(7.0)
    assert not FAMILY.supports_astern and spec["actuators"]["rps_min"] == 0.0


# ------------------------------------------------------------------------------------- turning

def test_positive_rudder_turns_to_starboard() -> None:
    """Project convention; the thesis' positive rudder turns to port (N_d < 0), flipped inside."""
    spec = _catfish()
    params, act = FAMILY.build([spec]), Actuators.from_specs([spec])
    x = np.zeros((base.N_STATE, 1))
    x[U], x[RPS] = from_kn(8.9), 22.0
    for _ in range(30):
        x = base.step(FAMILY, params, act, x, np.radians([5.0]), x[RPS].copy(), Env(), 1.0, 2)
    assert x[R, 0] > 0.0 and 0.0 < x[PSI, 0] < np.pi


def test_turning_circles_at_5_and_10_deg_match_figure_4_4() -> None:
    """Figs 4.4a/b compare model and vessel: 'RUN 7 RUDDER 5deg START SPEED 9.0kts' and
    'RUN 3 RUDDER 10deg START SPEED 8.8kts', drawn against a '100metres' bar. The text says
    'The turning circles for the model were compared with those of the trials and the coefficients
    fine-tuned until the vessel and model turning circles matched. The final results are considered
    acceptable for rudder angles up to 15 deg' [seed 002, ch 4.6], and the appended paper: 'Figure 1
    shows a comparison between simulated and actual turning circles at 9 knots, 5 deg starboard
    rudder' and 'It can be seen from Fig. 1 that the hydrodynamic modelling of the hull is quite
    accurate'.

    The diameters are not printed. The same group's transfer function for Catfish at 4.455 m/s
    (8.66 kn, within 0.35 kn of both runs), G3(s) = 0.3848 (s + 0.603) / (s (1 + 1.656 s)
    (s + 0.3874)) [seed 002, appended paper eq 13], has the yaw-rate gain K = 0.599 1/s, so its
    steady diameter 2U/(K delta) is 170 m at 5 deg and 85 m at 10 deg.
    Checks: at 5 deg each side within 25 % and the mean of both within 20 % of 170 m (the model
    gives 187 / 206 m: its own linear gain is 0.63 1/s, and the nonlinear and even rudder terms,
    kept because they give more than 10 % of the forces [ch 4.1], widen the circles and split the
    sides); at 10 deg the circle is between 0.5 and 0.7 of the 5 deg one (nearly linear below
    15 deg, as the thesis' validity statement implies; a linear model gives 0.5): 107 / 123 m.
    A rudder force scaled with U^2 alone (table 4.2's printed factor without the module's
    1 / U_cal) gives about 75 m at 5 deg: fails.
    """
    linear_5 = 2.0 / (0.599 * np.radians(5.0)) * 4.455
    stbd5, port5 = _catfish_diameters(5.0, 9.0)
    stbd10, port10 = _catfish_diameters(10.0, 8.8)
    for d in (stbd5, port5):
        assert d == pytest.approx(linear_5, rel=0.25), (stbd5, port5)
    assert 0.5 * (stbd5 + port5) == pytest.approx(linear_5, rel=0.20)
    for d5, d10 in ((stbd5, stbd10), (port5, port10)):
        assert 0.5 < d10 / d5 < 0.7, (d5, d10)


def test_turning_circle_keeps_its_size_at_every_approach_speed() -> None:
    """Rudder lift grows as U^2 (table 4.2's factor) and the hull's forces as U times the
    velocities, so a turn from 4.2 kn (the 1100 rpm speed [seed 002, ch 3.2]) has the shape of
    one from 8.9 kn: the same steady diameters. A rudder force growing only as U would make the
    4.2 kn circle about 40 % smaller."""
    for rudder_deg in (5.0, 15.0):
        slow, fast = _steady_diameters(_catfish(), rudder_deg, 4.2), _catfish_diameters(
            rudder_deg, 8.9)
        np.testing.assert_allclose(slow, fast, rtol=0.01)


def test_F_at_4455_mps_has_the_nomoto_time_constant_of_eq_8() -> None:
    """[seed 002, appended paper eq 8]: T2 = 2.581 s, "computed for a forward speed of 4.455
    m/s" (ch 9.4: "the major hull time constant of 2.6 seconds"). The sway-yaw block of F there
    has its slow pole at -1/T2 within 1 %. The model's own linearisation (eq 4.2's Coriolis
    term -m u r, which F's r column lacks) is slower: its slow pole lies below half of that."""
    spec = _catfish()
    params = FAMILY.build([spec])
    x = np.zeros((base.N_STATE, 1))
    x[U] = 4.455
    x[RPS] = base.steady_rps_for_speed(FAMILY, params, Actuators.from_specs([spec]), x[U])
    block = np.ix_([V, R], [V, R])
    slow = max(np.linalg.eigvals(linearised_F(params, x)[0][block]).real)
    assert -1.0 / slow == pytest.approx(2.581, rel=0.01)
    jac = _jacobian(params, x)[0][:, [V, R]][1:]
    assert 0.0 > max(np.linalg.eigvals(jac).real) > 0.5 * slow


def test_turning_is_asymmetric_as_the_thesis_states() -> None:
    """'Turning circles in opposite directions were of different diameters for equal, and opposite,
    rudder angles, due to rotation of both propellers in the same direction' [seed 002, ch 4.6].

    With the printed even rudder terms (Y_dd, N_dd) and the project's sign flip, starboard turns
    are the tighter ones (the thesis does not say which side): more than 5 % apart at 5 and 10 deg.
    """
    for rudder, speed in ((5.0, 9.0), (10.0, 8.8)):
        stbd, port = _catfish_diameters(rudder, speed)
        assert stbd < port
        assert (port - stbd) / (0.5 * (port + stbd)) > 0.05, (rudder, stbd, port)


def test_asymmetry_coefficients_zero_gives_a_mirror_symmetric_model() -> None:
    """With Y_dd = N_dd = N_ndd = 0 (and Y_n = N_n = 0) +rudder and -rudder give mirror tracks;
    the extra N_ndd n^2 d^2 term alone [seed 002, ch 4.6] breaks the symmetry again."""
    sym = _catfish(Y_dd=0.0, N_dd=0.0, N_ndd=0.0, Y_n=0.0, N_n=0.0)
    specs = [sym, sym]
    params, act = FAMILY.build(specs), Actuators.from_specs(specs)
    x = np.zeros((base.N_STATE, 2))
    x[U], x[RPS] = from_kn(8.9), 22.7
    rudder = np.radians([10.0, -10.0])
    for _ in range(200):
        x = base.step(FAMILY, params, act, x, rudder, x[RPS].copy(), Env(), 1.0, 2)
        np.testing.assert_allclose(x[[NORTH, U, RPS], 0], x[[NORTH, U, RPS], 1], rtol=1e-12)
        np.testing.assert_allclose(x[[EAST, V, R, RUDDER], 0], -x[[EAST, V, R, RUDDER], 1],
                                   rtol=1e-12, atol=1e-12)

    stbd, port = _steady_diameters(_catfish(Y_dd=0.0, N_dd=0.0, N_ndd=0.0), 10.0, 8.8)
    assert stbd == pytest.approx(port, rel=1e-6)
    # a positive n^2 d^2 moment pushes both turns to starboard: starboard tighter, port wider
    stbd_a, port_a = _steady_diameters(_catfish(Y_dd=0.0, N_dd=0.0, N_ndd=2.0), 10.0, 8.8)
    assert stbd_a < 0.95 * stbd and port_a > 1.05 * port


# ----------------------------------------------------------------------------------- stability

def test_one_hour_at_full_rudder_with_1s_steps_stays_finite_and_steady() -> None:
    """dt = 1 s for 1 h, full rudder either side at full power plus a third boat at rest with full
    rudder, with the ship file's sub-steps and without any."""
    spec = _catfish()
    params, act = FAMILY.build([spec] * 3), Actuators.from_specs([spec] * 3)
    for substeps in (_substeps(spec, 1.0), 1):
        x = np.zeros((base.N_STATE, 3))
        x[U, :2] = from_kn(8.9)
        rudder = np.radians([35.0, -35.0, 35.0])
        rps = np.array([spec["actuators"]["rps_max"]] * 2 + [0.0])
        history = []
        for _ in range(3600):
            x = base.step(FAMILY, params, act, x, rudder, rps, Env(), 1.0, substeps)
            history.append(x[[U, V, R]].copy())
        h = np.array(history)
        assert np.isfinite(h).all()
        assert (h[:, 0, :2] > 0).all() and (h[:, 0, :2] < 6.0).all()
        assert (np.abs(h[:, 1]) < 3.0).all() and (np.abs(h[:, 2]) < 0.5).all()
        # steady turn: the last 10 minutes do not change
        assert np.ptp(h[-600:], axis=0).max() < 1e-6
        assert h[-1, 2, 0] > 0.0 > h[-1, 2, 1]
        # the boat at rest stayed exactly at rest
        assert np.all(x[[NORTH, EAST, PSI, U, V, R, RPS], 2] == 0.0)


def test_at_rest_stays_at_rest() -> None:
    """No thrust, no speed: the rudder may move, the boat does not (all forces scale with U, n)."""
    spec = _catfish()
    params, act = FAMILY.build([spec]), Actuators.from_specs([spec])
    x = np.zeros((base.N_STATE, 1))
    assert all(np.all(a == 0.0) for a in base.accelerations(FAMILY, params, x, Env()))
    for _ in range(120):
        x = base.step(FAMILY, params, act, x, np.radians([35.0]), np.zeros(1), Env(), 1.0, 2)
    assert np.all(x[[NORTH, EAST, PSI, U, V, R, RPS]] == 0.0)
    assert x[RUDDER, 0] == pytest.approx(np.radians(35.0))
    assert all(np.all(a == 0.0) for a in base.accelerations(FAMILY, params, x, Env()))


def test_vectorised_ships_match_single_ships() -> None:
    """Different coefficient sets in one batch give the same accelerations as one by one."""
    rng = np.random.default_rng(1)
    specs = [_catfish(), _catfish(N_ndd=1.5, Y_n=3.0, N_n=-2.0), _catfish(Y_dd=0.0)]
    x = _random_states(rng, len(specs))
    together = np.array(base.accelerations(FAMILY, FAMILY.build(specs), x, Env()))
    for i, spec in enumerate(specs):
        alone = np.array(base.accelerations(FAMILY, FAMILY.build([spec]), x[:, i:i + 1], Env()))
        np.testing.assert_allclose(together[:, i], alone[:, 0], rtol=1e-13)


def test_packed_row_columns_are_the_params_fields_in_order() -> None:
    """The kernel reads its parameter row through the module's column constants: one per
    ModularParams field, in declaration order (the layout of ``base.pack``)."""
    names = [f.name for f in dataclasses.fields(ModularParams)]
    assert [getattr(modular, "_" + name.upper()) for name in names] == list(range(len(names)))
    params = FAMILY.build([_catfish(N_ndd=1.5, Y_n=3.0, N_n=-2.0)])
    row = base.pack(params)[0]
    assert row.shape == (len(names),)
    for name in names:
        assert row[getattr(modular, "_" + name.upper())] == getattr(params, name)[0], name


def test_kernel_called_directly_matches_base_accelerations() -> None:
    """``accel`` on one packed row and one state gives what ``base.accelerations`` gives."""
    rng = np.random.default_rng(5)
    params = FAMILY.build([_catfish(N_ndd=1.5, Y_n=3.0, N_n=-2.0)] * 4)
    x = _random_states(rng, 4)
    rows = base.pack(params)
    together = np.array(base.accelerations(FAMILY, params, x, Env()))
    for i in range(4):
        alone = modular.accel(rows[i], np.ascontiguousarray(x[:, i]), np.zeros(4))
        np.testing.assert_array_equal(np.array(alone), together[:, i])


def test_current_and_wind_do_not_enter_the_accelerations() -> None:
    """u, v are relative to the water and the wind coefficients are 0 [seed 002, tables
    4.1-4.3]: the environment changes only the kinematics (base), not du, dv, dr."""
    rng = np.random.default_rng(11)
    specs = [_catfish()] * 20
    params = FAMILY.build(specs)
    x = _random_states(rng, 20)
    calm = np.array(base.accelerations(FAMILY, params, x, Env()))
    env = Env(current_north_mps=0.5, current_east_mps=-0.3, wind_speed_mps=15.0,
              wind_from_rad=rng.uniform(0, 2 * np.pi, 20))
    np.testing.assert_array_equal(np.array(base.accelerations(FAMILY, params, x, env)), calm)


def test_missing_particulars_are_reported() -> None:
    spec = _catfish()
    del spec["particulars"]["yaw_inertia_kgm2"]
    with pytest.raises(ShipLibraryError, match="yaw_inertia_kgm2"):
        FAMILY.build([spec])


# ------------------------------------------------------------------------------ linearised F

def _random_states(rng: np.random.Generator, n: int) -> np.ndarray:
    x = np.zeros((base.N_STATE, n))
    x[NORTH], x[EAST] = rng.uniform(-500, 500, (2, n))
    x[PSI] = rng.uniform(0, 2 * np.pi, n)
    x[U] = rng.uniform(0.5, 5.0, n)
    x[V] = rng.uniform(-1.0, 1.0, n)
    x[R] = rng.uniform(-0.3, 0.3, n)
    x[RUDDER] = rng.uniform(-0.6, 0.6, n)
    x[RPS] = rng.uniform(0.0, 25.0, n)
    return x


def _jacobian(params: Any, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Central-difference Jacobian of (du, dv, dr) w.r.t. the state, ``(n, 3, 8)``."""
    n = x.shape[1]
    jac = np.zeros((n, 3, base.N_STATE))
    for j in range(base.N_STATE):
        xp, xm = x.copy(), x.copy()
        xp[j] += eps
        xm[j] -= eps
        fp = np.array(base.accelerations(FAMILY, params, xp, Env()))
        fm = np.array(base.accelerations(FAMILY, params, xm, Env()))
        jac[:, :, j] = ((fp - fm) / (2 * eps)).T
    return jac


def test_F_times_state_reproduces_the_model() -> None:
    """Appendix D's F is a state-dependent factorisation: F(x) x is the derivative, exactly."""
    rng = np.random.default_rng(7)
    spec = _catfish(N_ndd=1.5, Y_n=3.0, N_n=-2.0)
    params = FAMILY.build([spec] * 40)
    x = _random_states(rng, 40)
    F = linearised_F(params, x)
    assert F.shape == (40, base.N_STATE, base.N_STATE)
    fx = np.einsum("nij,jn->in", F, x)
    du, dv, dr = base.accelerations(FAMILY, params, x, Env())
    np.testing.assert_allclose(fx[[U, V, R]], np.array([du, dv, dr]), rtol=1e-11, atol=1e-12)
    c, s = np.cos(x[PSI]), np.sin(x[PSI])
    np.testing.assert_allclose(fx[NORTH], x[U] * c - x[V] * s, rtol=1e-12)
    np.testing.assert_allclose(fx[EAST], x[U] * s + x[V] * c, rtol=1e-12)
    np.testing.assert_allclose(fx[PSI], x[R])
    np.testing.assert_allclose(fx[RUDDER], -x[RUDDER] / spec["actuators"]["rudder_tau_s"])
    np.testing.assert_allclose(fx[RPS], -x[RPS] / spec["actuators"]["engine_tau_s"])


def test_F_matches_the_finite_difference_jacobian_where_appendix_D_is_exact() -> None:
    """At straight running (v = r = rudder = 0, any u and rps) appendix D's entries are the
    Jacobian's in the rudder, u, v and rps columns of the v and r rows and the rudder, v and r
    columns of the u row. The two known differences are checked too: the r column lacks the
    Coriolis term -m u (appendix D puts -m u r in the u column), and the quadratic X_uu, X_nn
    entries are half the Jacobian's."""
    rng = np.random.default_rng(3)
    n = 30
    spec = _catfish(N_ndd=1.5, Y_n=3.0, N_n=-2.0)
    params = FAMILY.build([spec] * n)
    x = _random_states(rng, n)
    x[[V, R, RUDDER]] = 0.0
    F = linearised_F(params, x)[:, [U, V, R], :]
    jac = _jacobian(params, x)
    tol = {"rtol": 1e-6, "atol": 1e-8}
    for row, cols in ((1, [RUDDER, U, V, RPS]), (2, [RUDDER, U, V, RPS]), (0, [RUDDER, V, R])):
        np.testing.assert_allclose(F[:, row, cols], jac[:, row, cols], **tol)
    # r column: Jacobian = F + the Coriolis term through the sway/yaw mass matrix
    m22, m33, yrd, nvd = params.m22, params.m33, params.y_rdot, params.n_vdot
    det = m22 * m33 - yrd * nvd
    fy = -params.mass * x[U]
    np.testing.assert_allclose(jac[:, 1, R] - F[:, 1, R], m33 * fy / det, **tol)
    np.testing.assert_allclose(jac[:, 2, R] - F[:, 2, R], nvd * fy / det, **tol)
    np.testing.assert_allclose(jac[:, 0, U], 2 * F[:, 0, U], **tol)
    np.testing.assert_allclose(jac[:, 0, RPS], 2 * F[:, 0, RPS], **tol)


def test_F_reproduces_the_thesis_matrix_eq_9_9_at_8_9_kn() -> None:
    """Eq 9.9 [seed 002] (Catfish, 'forward speed of 4.5 m/s'): X2 = 0.004, X4 = -0.138,
    Y1 = 0.573, Y6 = -0.308, Y8 = 1, N1 = -0.273, N6 = -0.092, N8 = -1.444, T_R = 1, T_N = 2 s.
    With the module's table readings all entries agree within 0.5 % (or the printed rounding) at
    8.9 kn, the 2200 rpm speed; n is in rad/s there and the rudder sign is flipped here. A rudder
    force scaled with U^2 alone (as table 4.2 prints, without the module's 1 / U_cal) would make
    Y1 and N1 4.4 times too large."""
    spec = _catfish()
    params = FAMILY.build([spec])
    x = np.zeros((base.N_STATE, 1))
    x[U] = from_kn(8.9)
    x[RPS] = base.steady_rps_for_speed(FAMILY, params, Actuators.from_specs([spec]), x[U])
    F = linearised_F(params, x)[0]
    order = list(EQ410_ORDER)
    # change of state variables to the thesis' rudder sign and n in rad/s: T F T^-1
    scale = np.diag([-1.0, 2 * np.pi, 1, 1, 1, 1, 1, 1])
    thesis = scale @ F[np.ix_(order, order)] @ np.linalg.inv(scale)
    expected = {(0, 0): -1.0, (1, 1): -0.5, (3, 1): 0.004, (3, 3): -0.138, (5, 0): 0.573,
                (5, 5): -0.308, (5, 7): 1.0, (7, 0): -0.273, (7, 5): -0.092, (7, 7): -1.444}
    for (i, j), value in expected.items():
        # the printed rounding (half a unit of the last digit) or 0.5 %: the exact speed of eq 9.9
        # is not known (8.9 kn = 4.579 m/s fits all entries best); Y8 is printed as '1'
        tol = 0.0005 if (i, j) != (5, 7) else 0.005
        assert thesis[i, j] == pytest.approx(value, abs=max(tol, 0.005 * abs(value))), (i, j)
    structural_zeros = [(3, 0), (3, 5), (3, 7), (5, 3), (7, 3), (5, 1), (7, 1)]
    for i, j in structural_zeros:
        assert thesis[i, j] == pytest.approx(0.0, abs=1e-12)


def test_ship_file_is_a_copy_safe_plain_mapping() -> None:
    """build() does not modify the ship dicts (they are shared, cached by the library)."""
    spec = _catfish()
    before = copy.deepcopy(spec)
    FAMILY.build([spec])
    assert spec == before


# ------------------------------------------------------ independent evaluation of eqs 4.1-4.9

def _thesis_accelerations(spec: Mapping[str, Any], x: np.ndarray) -> np.ndarray:
    """Eqs 4.1-4.6 evaluated from the ship file's printed coefficients with the module table's
    factors (0.5 rho times the powers of L and U, the rudder terms' U^2 over U_cal = 8.9 kn),
    rudder d = -RUDDER (thesis + = port) and n = 2 pi RPS (shaft rad/s); the sway/yaw mass
    matrix solved by numpy. ``(3, n)``."""
    c, p = spec["coefficients"], spec["particulars"]
    h, L, m, Iz = 0.5 * 1025.0, p["length_m"], p["mass_kg"], p["yaw_inertia_kgm2"]
    u_cal = 8.9 * 1852.0 / 3600.0
    out = np.zeros((3, x.shape[1]))
    for i in range(x.shape[1]):
        u, v, r = x[U, i], x[V, i], x[R, i]
        d, n = -x[RUDDER, i], 2 * np.pi * x[RPS, i]
        Us = np.hypot(u, v)
        rudder = Us**2 / u_cal
        X = (c["X_uu"] * u * abs(u) + c["X_vv"] * h * L**2 * v**2
             + c["X_nn"] * n * abs(n) + c["X_dd"] * h * L**2 * rudder * d**2 + m * v * r)
        Y = (c["Y_v"] * h * L**2 * Us * v + c["Y_r"] * h * L**3 * Us * r
             + c["Y_vvv"] * h * L**2 / Us * v**3 + c["Y_rvv"] * h * L**3 / Us * r * v**2
             + h * L**2 * rudder * (c["Y_d"] * d + c["Y_dd"] * d**2 + c["Y_ddd"] * d**3)
             + c["Y_n"] * n - m * u * r)
        N = (c["N_v"] * h * L**3 * Us * v + c["N_r"] * h * L**4 * Us * r
             + c["N_vvv"] * h * L**3 / Us * v**3 + c["N_rvv"] * h * L**4 / Us * r * v**2
             + h * L**3 * rudder * (c["N_d"] * d + c["N_dd"] * d**2 + c["N_ddd"] * d**3)
             + c["N_n"] * n + c["N_ndd"] * n**2 * d**2)
        M = np.array([[m - c["Y_vdot"] * h * L**3, -c["Y_rdot"] * h * L**4],
                      [-c["N_vdot"] * h * L**4, Iz - c["N_rdot"] * h * L**5]])
        dv, dr = np.linalg.solve(M, [Y, N])
        out[:, i] = X / (m - c["X_udot"] * h * L**3), dv, dr
    return out


def test_kernel_equals_the_thesis_equations_evaluated_from_the_printed_coefficients() -> None:
    """Random states, with the optional Y_n, N_n, N_ndd switched on: the compiled kernel gives
    what eqs 4.1-4.6 give when the printed coefficients are dimensionalised by hand."""
    rng = np.random.default_rng(21)
    spec = _catfish(N_ndd=1.5, Y_n=3.0, N_n=-2.0)
    x = _random_states(rng, 25)
    got = np.array(base.accelerations(FAMILY, FAMILY.build([spec] * 25), x, Env()))
    np.testing.assert_allclose(got, _thesis_accelerations(spec, x), rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize("rpm, knots", [(1100.0, 4.32), (2200.0, 8.65), (2500.0, 9.83)])
def test_steady_speed_is_the_closed_form_of_the_surge_balance(rpm: float, knots: float) -> None:
    """Straight ahead X_uu u^2 + X_nn n^2 = 0: u = n sqrt(X_nn / -X_uu) with n = 2 pi rpm /
    (60 x 1.66); the module docstring's 4.32, 8.65 and 9.83 kn. steady_rps_for_speed returns the
    same rpm for that speed (2500 rpm is a hair above rps_max = 25.1 rev/s = 2499.96 rpm, so
    there it returns rps_max, as documented), and the accelerations vanish there."""
    spec = _catfish()
    c = spec["coefficients"]
    params, act = FAMILY.build([spec]), Actuators.from_specs([spec])
    n = 2 * np.pi * rpm / (60.0 * 1.66)
    u = n * np.sqrt(c["X_nn"] / -c["X_uu"])
    assert to_kn(u) == pytest.approx(knots, abs=0.006)
    rps = base.steady_rps_for_speed(FAMILY, params, act, np.array([u]))
    want = min(rpm / (60.0 * 1.66), spec["actuators"]["rps_max"])
    assert rps[0] == pytest.approx(want, rel=1e-9)
    x = np.zeros((base.N_STATE, 1))
    x[U], x[RPS] = u, rpm / (60.0 * 1.66)
    du, dv, dr = base.accelerations(FAMILY, params, x, Env())
    assert abs(du[0]) < 1e-12 and dv[0] == 0.0 and dr[0] == 0.0


def test_symmetric_coefficients_give_mirrored_accelerations_at_any_state() -> None:
    """With the even terms Y_dd = N_dd = N_ndd = 0 and Y_n = N_n = 0, reflecting the state
    (v, r, rudder -> -v, -r, -rudder) reflects dv, dr and keeps du, at every state, not only
    along one track."""
    rng = np.random.default_rng(4)
    sym = _catfish(Y_dd=0.0, N_dd=0.0, N_ndd=0.0, Y_n=0.0, N_n=0.0)
    params = FAMILY.build([sym] * 30)
    x = _random_states(rng, 30)
    xm = x.copy()
    xm[[V, R, RUDDER]] *= -1.0
    a = np.array(base.accelerations(FAMILY, params, x, Env()))
    b = np.array(base.accelerations(FAMILY, params, xm, Env()))
    np.testing.assert_allclose(b[0], a[0], rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(b[1:], -a[1:], rtol=1e-13, atol=1e-15)


def test_even_rudder_terms_make_the_printed_model_asymmetric() -> None:
    """With the printed Y_dd, N_dd the yaw acceleration from +d and -d at the same speed
    differs by twice the even part: dr(+) + dr(-) = 2 (even moment through the mass matrix)."""
    spec = _catfish()
    params = FAMILY.build([spec] * 2)
    x = np.zeros((base.N_STATE, 2))
    x[U] = from_kn(8.9)
    x[RUDDER] = [0.2, -0.2]
    _, dv, dr = base.accelerations(FAMILY, params, x, Env())
    c, p = spec["coefficients"], params
    h, L = 0.5 * 1025.0, spec["particulars"]["length_m"]
    Us, d2 = from_kn(8.9), 0.04
    fy, fn = h * L**2 * Us * c["Y_dd"] * d2, h * L**3 * Us * c["N_dd"] * d2
    det = p.m22[0] * p.m33[0] - p.y_rdot[0] * p.n_vdot[0]
    assert dr[0] + dr[1] == pytest.approx(2 * (p.n_vdot[0] * fy + p.m22[0] * fn) / det, rel=1e-9)
    assert dv[0] + dv[1] == pytest.approx(2 * (p.m33[0] * fy + p.y_rdot[0] * fn) / det, rel=1e-9)
