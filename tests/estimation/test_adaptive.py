"""Innovation-based adaptive estimation of R (Mehra / Myers-Tapley; the adaptive idea of
[seed 004]) alone and inside the ship EKF."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trafficsim.estimation import adaptive, ekf
from trafficsim.estimation.ekf import ZE, ZN
from trafficsim.ships import base
from trafficsim.ships.base import EAST, NORTH, PSI, RPS, RUDDER, Actuators, Env, U
from trafficsim.ships.library import load_ship
from trafficsim.units import from_kn


def chi2_bounds(dof: int, p: float = 0.95) -> tuple[float, float]:
    """Two-sided chi-square quantiles (Wilson-Hilferty; < 0.5 % error for dof >= 30)."""
    z = {0.95: 1.959963984540054, 0.99: 2.5758293035489}[p]
    c = 2.0 / (9.0 * dof)
    return (dof * (1 - c - z * math.sqrt(c)) ** 3, dof * (1 - c + z * math.sqrt(c)) ** 3)


def _spd(rng: np.random.Generator, n: int, m: int, scale: float) -> np.ndarray:
    L = rng.standard_normal((n, m, m))
    return (L @ L.transpose(0, 2, 1) / m + 0.5 * np.eye(m)) * scale


def test_window_estimate_is_unbiased_and_follows_a_step_change() -> None:
    """Synthetic innovations nu ~ N(b, H P H^T + R) with a bias b: after a full window the
    ship-averaged estimate equals R (the mean is removed, the H P H^T part subtracted); when R
    quadruples the estimate is exactly the new R (statistically) once the window holds only new
    innovations: after ``window_steps`` steps, and half-way in between."""
    rng = np.random.default_rng(0)
    n, m, w = 4000, 2, 40
    params = adaptive.build([{"window_steps": w}] * n, "gnss")
    R1 = _spd(rng, 1, m, 9.0)[0]
    R2 = 4.0 * R1
    hph = _spd(rng, n, m, 1.0)
    bias = rng.normal(0, 3.0, (n, m))
    state = adaptive.start(params, np.broadcast_to(np.eye(m), (n, m, m)))
    history = []
    for k in range(3 * w):
        R = R1 if k < 2 * w else R2
        L = np.linalg.cholesky(hph + R)
        nu = bias + np.einsum("nij,nj->ni", L, rng.standard_normal((n, m)))
        state = adaptive.step(params, state, nu, hph, np.ones(n, dtype=bool))
        history.append(state.R.mean(axis=0))
        if k == w // 2 - 2:  # fewer than min_samples (w / 2): still the prior
            np.testing.assert_array_equal(state.R, np.broadcast_to(np.eye(m), (n, m, m)))
    se = R1 * math.sqrt(2.0 / w / n) * 3 + 0.05  # 3 standard errors of the ship average
    np.testing.assert_allclose(history[2 * w - 1], R1, atol=se.max())
    np.testing.assert_allclose(history[3 * w - 1], R2, atol=4 * se.max())
    mid = history[2 * w + w // 2 - 1]
    assert 1.5 * R1[0, 0] < mid[0, 0] < 3.5 * R1[0, 0]  # half old, half new


def test_invalid_steps_and_per_ship_windows() -> None:
    """Invalid steps do not enter the sums; each ship's ring wraps at its own window; the running
    sums equal the direct Myers-Tapley estimate over each ship's last valid innovations."""
    rng = np.random.default_rng(1)
    n, m = 6, 1
    windows = [5, 8, 12, 5, 8, 12]
    params = adaptive.build([{"window_steps": w, "min_samples": 3, "floor_sigma_deg": 1e-3}
                             for w in windows], "compass")
    state = adaptive.start(params, np.full((n, 1, 1), 0.01))
    nus, hphs, valids = [], [], []
    for _ in range(40):
        nu = rng.normal(0, 0.1, (n, m))
        hph = rng.uniform(0.0, 0.002, (n, m, m))
        valid = rng.random(n) < 0.7
        state = adaptive.step(params, state, nu, hph, valid)
        nus.append(nu)
        hphs.append(hph)
        valids.append(valid)
    for i, w in enumerate(windows):
        sel = [k for k in range(40 - w, 40) if valids[k][i]]
        v = np.array([nus[k][i, 0] for k in sel])
        h = np.array([hphs[k][i, 0, 0] for k in sel])
        assert state.count[i] == len(sel)
        if len(sel) < 3:  # too few in the window: the last estimate is kept
            continue
        expected = max(v.var(ddof=1) - h.mean(), params.floor_var[i])
        assert state.R[i, 0, 0] == pytest.approx(expected, rel=1e-9)


def test_estimate_is_clamped_positive_definite() -> None:
    """Innovations smaller than H P H^T would give a negative variance: clamped to the floor."""
    n = 3
    params = adaptive.build([{"window_steps": 5, "min_samples": 3}] * n, "gnss")
    state = adaptive.start(params, np.broadcast_to(np.eye(2) * 4.0, (n, 2, 2)))
    rng = np.random.default_rng(2)
    for _ in range(5):
        state = adaptive.step(params, state, rng.normal(0, 0.01, (n, 2)),
                              np.broadcast_to(np.eye(2) * 100.0, (n, 2, 2)), np.ones(n, bool))
    np.testing.assert_allclose(state.R, np.broadcast_to(np.eye(2) * 0.1**2, (n, 2, 2)),
                               rtol=1e-9)
    with pytest.raises(ValueError, match="group"):
        adaptive.build([{}], "radar")
    with pytest.raises(ValueError, match="unknown"):
        adaptive.build([{"floor_sigma_m": 1.0}], "compass")


def _ekf_run(adapt: bool, n: int = 300, steps: int = 600, window: int = 60, seed: int = 3
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Catfish ships zig-zagging; GNSS noise 5 m per axis, 10 m from half-time on.

    Returns per step: mean NIS over ships (4 dof), ship-mean estimated GNSS variance (m2) and the
    ship-mean GNSS-only NIS (2 dof)."""
    spec = load_ship("catfish")
    family = base.families()["modular"]
    specs = [spec] * n
    fp = family.build(specs)
    act = Actuators.from_specs(specs)
    model = ekf.ShipModel.from_specs(specs)
    rng = np.random.default_rng(seed)
    x = np.zeros((base.N_STATE, n))
    x[PSI] = rng.uniform(0, 2 * np.pi, n)
    x[U] = from_kn(7.0)
    rps = base.steady_rps_for_speed(family, fp, act, x[U])
    x[RPS] = rps
    ang = rng.uniform(0, 2 * np.pi, n)
    cur = 0.3 * np.cos(ang), 0.3 * np.sin(ang)
    p = ekf.build([{"gnss_sigma_m": 5.0, "compass_sigma_deg": 1.0, "log_sigma_mps": 0.1}] * n)
    ap = adaptive.build([{"window_steps": window}] * n, "gnss")
    ast = adaptive.start(ap, np.broadcast_to(np.eye(2) * 25.0, (n, 2, 2)))
    st = ekf.initial_state(p, x[NORTH] + 5 * rng.standard_normal(n),
                           x[EAST] + 5 * rng.standard_normal(n), x[PSI], x[U])
    period = rng.uniform(60, 180, n)
    phase = rng.uniform(0, 1, n)
    nis, r_est, nis_g = [], [], []
    for k in range(steps):
        sig = 5.0 if k < steps // 2 else 10.0
        rudder_cmd = np.radians(10.0) * np.sign(np.sin(2 * np.pi * (k / period + phase)))
        meas = x[RUDDER].copy(), x[RPS].copy()
        x = base.step(family, fp, act, x, rudder_cmd, rps, Env(*cur), 1.0, 2)
        st = ekf.predict(p, model, st, *meas, 1.0, rudder_cmd_rad=rudder_cmd, rps_cmd=rps)
        z = np.stack([x[NORTH] + sig * rng.standard_normal(n),
                      x[EAST] + sig * rng.standard_normal(n),
                      x[PSI] + math.radians(1.0) * rng.standard_normal(n),
                      x[U] + 0.1 * rng.standard_normal(n)], axis=1)
        mask = np.ones((n, 4), dtype=bool)
        R = ekf.measurement_covariance(p, gnss_cov_m2=ast.R if adapt else None)
        st, inn = ekf.update(p, st, z, mask, R)
        g_nu, g_hph, g_valid = adaptive.innovation_group(inn.nu, inn.hph, mask, (ZN, ZE))
        ast = adaptive.step(ap, ast, g_nu, g_hph, g_valid)
        S_g = inn.S[:, :2, :2]
        nis_g.append(np.einsum("ni,ni->n", g_nu, np.linalg.solve(S_g, g_nu[..., None])[..., 0])
                     .mean())
        nis.append(inn.nis.mean())
        r_est.append(np.trace(ast.R, axis1=1, axis2=2).mean() / 2)
    return np.array(nis), np.array(r_est), np.array(nis_g)


@pytest.fixture(scope="module")
def runs() -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    return {"adaptive": _ekf_run(True), "fixed": _ekf_run(False)}


def test_ekf_estimated_R_follows_the_doubled_gnss_noise(runs: dict) -> None:
    """GNSS sigma 5 m -> 10 m at t = 300 s; window 60 steps: the estimated variance is 25 m2
    before and 100 m2 from one window after the change (10 % tolerance, 300 ships)."""
    _, r_est, _ = runs["adaptive"]
    assert r_est[200:300].mean() == pytest.approx(25.0, rel=0.1)
    assert r_est[299] == pytest.approx(25.0, rel=0.1)
    assert r_est[300 + 60] == pytest.approx(100.0, rel=0.1)
    assert r_est[360:].mean() == pytest.approx(100.0, rel=0.1)
    assert 40.0 < r_est[330] < 85.0  # half a window: on its way


def test_nis_returns_inside_its_bounds(runs: dict) -> None:
    """NIS (4 dof, averaged over 300 ships) inside the 95 % chi-square bounds before the change
    and again one window after it with adaptation; without, it stays far above (the GNSS
    innovations are 4x larger than the filter believes: their 2-dof NIS averages 8, not 2)."""
    n = 300
    lo, hi = chi2_bounds(4 * n)
    nis, _, nis_g = runs["adaptive"]
    nis_fixed, _, nis_g_fixed = runs["fixed"]
    for series, sl in ((nis, slice(100, 300)), (nis, slice(360, 600)),
                       (nis_fixed, slice(100, 300))):
        inside = np.mean((series[sl] * n > lo) & (series[sl] * n < hi))
        assert inside > 0.85, (sl, inside)
    assert np.mean(nis[301:310] * n > hi) > 0.8  # the change was felt
    assert np.all(nis_fixed[320:] * n > hi)
    assert nis_g_fixed[360:].mean() == pytest.approx(2 * 4.0, rel=0.1)
    # slightly above 2 (2.10 here): R_hat from 60 samples scatters by ~18 % per ship, and a
    # scattered denominator raises the mean of nu^2 / R_hat (Jensen)
    assert nis_g[360:].mean() == pytest.approx(2.0, rel=0.08)


# --- the running-sum window against a brute-force window, and the helpers -------------------

def _clamp_ref(R: np.ndarray, floor: float) -> np.ndarray:
    """Eigenvalues of the symmetric part raised to ``floor`` (general eigensolver)."""
    S = 0.5 * (R + R.T)
    w, V = np.linalg.eig(S)
    w, V = w.real, V.real
    V = V / np.linalg.norm(V, axis=0)
    return (V * np.maximum(w, floor)) @ V.T


def test_running_sums_equal_a_brute_force_window_every_step() -> None:
    """Two-dimensional group, per-ship windows and min_samples, biased innovations, one in three
    steps invalid (NaN innovations there), floors that clamp some ships: at every step each
    ship's R is the Myers-Tapley estimate over its last ``window_steps`` steps' valid
    innovations, clamped; the previous R while fewer than ``min_samples`` are in the window."""
    rng = np.random.default_rng(30)
    n, m, steps = 5, 2, 70
    windows = [3, 4, 7, 10, 10]
    mins = [2, 3, 4, 5, 10]
    floors = [1e-3, 1.0, 1e-3, 2.0, 1e-3]
    params = adaptive.build([{"window_steps": w, "min_samples": k, "floor_sigma_m": f}
                             for w, k, f in zip(windows, mins, floors, strict=True)], "gnss")
    R0 = _spd(rng, n, m, 3.0)
    state = adaptive.start(params, R0)
    expected = R0.copy()
    history: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for _ in range(steps):
        nu = rng.normal(0.0, 2.0, (n, m)) + np.array([[10.0, -4.0]])
        hph = _spd(rng, n, m, 0.5)
        valid = rng.random(n) < 0.67
        nu[~valid] = np.nan
        hph[~valid] = np.nan
        state = adaptive.step(params, state, nu, hph, valid)
        history.append((nu, hph, valid))
        for i, w in enumerate(windows):
            sel = [h for h in history[-w:] if h[2][i]]
            assert state.count[i] == len(sel)
            if len(sel) >= mins[i]:
                v = np.array([h[0][i] for h in sel])
                C = np.cov(v.T, ddof=1) - np.mean([h[1][i] for h in sel], axis=0)
                expected[i] = _clamp_ref(C, floors[i] ** 2)
            np.testing.assert_allclose(state.R[i], expected[i], rtol=1e-9, atol=1e-12)
            assert state.head[i] == len(history) % w
    assert np.isfinite(state.sum_nunu).all()


def test_step_leaves_the_previous_state_untouched() -> None:
    """step returns a new state: the one passed in (buffers, sums, R) is not changed, so a
    caller may keep it (e.g. to retry a step)."""
    rng = np.random.default_rng(31)
    params = adaptive.build([{"window_steps": 4, "min_samples": 2}] * 3, "compass")
    state = adaptive.start(params, np.full((3, 1, 1), 0.01))
    for _ in range(6):
        state = adaptive.step(params, state, rng.normal(0, 0.1, (3, 1)),
                              np.full((3, 1, 1), 1e-4), np.ones(3, bool))
    copies = [np.copy(a) for a in state]
    adaptive.step(params, state, rng.normal(0, 5.0, (3, 1)), np.full((3, 1, 1), 1e-4),
                  np.ones(3, bool))
    for a, b in zip(state, copies, strict=True):
        np.testing.assert_array_equal(a, b)


def test_estimate_is_invariant_to_a_bias_and_scales_with_the_innovations() -> None:
    """The mean is removed: a constant bias per ship leaves R unchanged; innovations times c
    with H P H^T times c^2 give R times c^2 (floors far below)."""
    rng = np.random.default_rng(32)
    n, m, w = 4, 2, 12
    params = adaptive.build([{"window_steps": w, "floor_sigma_m": 1e-6}] * n, "gnss")
    nus = rng.normal(0.0, 3.0, (w, n, m))
    hphs = _spd(rng, w * n, m, 0.2).reshape(w, n, m, m)
    bias = rng.uniform(-50, 50, (n, m))

    def run(scale: float, offset: np.ndarray) -> np.ndarray:
        s = adaptive.start(params, np.broadcast_to(np.eye(m), (n, m, m)))
        for k in range(w):
            s = adaptive.step(params, s, scale * nus[k] + offset, scale**2 * hphs[k],
                              np.ones(n, bool))
        return s.R

    R = run(1.0, np.zeros((n, m)))
    np.testing.assert_allclose(run(1.0, bias), R, rtol=1e-9)
    np.testing.assert_allclose(run(3.0, np.zeros((n, m))), 9.0 * R, rtol=1e-12)


def test_a_window_without_valid_steps_keeps_the_last_estimate() -> None:
    """While invalid steps push the valid ones out, R follows the shrinking window down to
    min_samples (3: the variance of the last three), then stays there; the empty window has
    count 0 and zero sums; new valid innovations rebuild R from scratch."""
    rng = np.random.default_rng(33)
    params = adaptive.build([{"window_steps": 5, "min_samples": 3}], "log")
    state = adaptive.start(params, np.full((1, 1, 1), 0.5))
    old = rng.normal(0, 0.3, 5)
    for v in old:
        state = adaptive.step(params, state, np.full((1, 1), v), np.zeros((1, 1, 1)),
                              np.ones(1, bool))
    for _ in range(5):
        state = adaptive.step(params, state, np.full((1, 1), np.nan), np.full((1, 1, 1), np.nan),
                              np.zeros(1, bool))
    assert state.count[0] == 0
    assert state.R[0, 0, 0] == pytest.approx(np.var(old[-3:], ddof=1), rel=1e-9)
    np.testing.assert_allclose(state.sum_nu, 0.0, atol=1e-15)
    np.testing.assert_allclose(state.sum_nunu, 0.0, atol=1e-15)
    new = [0.1, -0.2, 0.4]
    for v in new:
        state = adaptive.step(params, state, np.full((1, 1), v), np.zeros((1, 1, 1)),
                              np.ones(1, bool))
    assert state.R[0, 0, 0] == pytest.approx(np.var(new, ddof=1), rel=1e-12)


@pytest.mark.parametrize("m", [1, 2, 3])
def test_clamp_spd_raises_only_the_small_eigenvalues(m: int) -> None:
    """Eigenvalues become max(lambda, floor) with the eigenvectors kept: a matrix already above
    its floor is returned (symmetrised) unchanged; the result is symmetric; for m = 1 the
    floor is a plain maximum."""
    rng = np.random.default_rng(34 + m)
    n = 50
    A = rng.standard_normal((n, m, m))
    S = 0.5 * (A + A.transpose(0, 2, 1))
    floor = rng.uniform(0.0, 1.0, n)
    out = adaptive.clamp_spd(A, floor)
    for i in range(n):
        np.testing.assert_allclose(out[i], _clamp_ref(A[i], floor[i]), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(out, out.transpose(0, 2, 1), rtol=0, atol=1e-14)
    w = np.linalg.eigvalsh(out)
    assert np.all(w >= floor[:, None] * (1 - 1e-10) - 1e-14)
    big = S + (np.abs(np.linalg.eigvalsh(S)).max(axis=1) + 2.0)[:, None, None] * np.eye(m)
    np.testing.assert_allclose(adaptive.clamp_spd(big, floor), big, rtol=1e-12)


def test_innovation_group_slices_the_group_and_needs_all_its_components() -> None:
    """nu, the H P H^T block and validity of components (0, 1) and (2,) of a 4-measurement
    record, by explicit indexing; a ship missing one GNSS axis has no valid GNSS group."""
    rng = np.random.default_rng(35)
    n = 6
    nu = rng.standard_normal((n, 4))
    hph = rng.standard_normal((n, 4, 4))
    mask = np.ones((n, 4), dtype=bool)
    mask[1, 0] = False
    mask[2, 1] = False
    mask[3, 2] = False
    g_nu, g_hph, g_ok = adaptive.innovation_group(nu, hph, mask, (0, 1))
    np.testing.assert_array_equal(g_nu, nu[:, :2])
    np.testing.assert_array_equal(g_hph, hph[:, :2, :2])
    np.testing.assert_array_equal(g_ok, [True, False, False, True, True, True])
    c_nu, c_hph, c_ok = adaptive.innovation_group(nu, hph, mask, (2,))
    np.testing.assert_array_equal(c_nu, nu[:, 2:3])
    np.testing.assert_array_equal(c_hph, hph[:, 2:3, 2:3])
    np.testing.assert_array_equal(c_ok, [True, True, True, False, True, True])
    r_nu, r_hph, _ = adaptive.innovation_group(nu, hph, mask, (3, 0))
    np.testing.assert_array_equal(r_hph[:, 0, 1], hph[:, 3, 0])
    np.testing.assert_array_equal(r_nu[:, 0], nu[:, 3])


def test_build_defaults_units_and_per_ship_values() -> None:
    """Defaults: window 60, min_samples max(3, window // 2), floors 0.1 m, 0.05 deg (in rad),
    0.01 m/s, squared; per-ship values kept in order."""
    p = adaptive.build([{}, {"window_steps": 3}, {"window_steps": 7},
                        {"window_steps": 10, "min_samples": 10, "floor_sigma_deg": 2.0}],
                       "compass")
    np.testing.assert_array_equal(p.window_steps, [60, 3, 7, 10])
    np.testing.assert_array_equal(p.min_samples, [30, 3, 3, 10])
    np.testing.assert_allclose(p.floor_var[:3], math.radians(0.05) ** 2, rtol=1e-15)
    assert p.floor_var[3] == pytest.approx(math.radians(2.0) ** 2, rel=1e-15)
    assert adaptive.build([{}], "gnss").floor_var[0] == pytest.approx(0.01, rel=1e-15)
    assert adaptive.build([{}], "log").floor_var[0] == pytest.approx(1e-4, rel=1e-15)
    assert adaptive.build([], "gnss").window_steps.shape == (0,)


@pytest.mark.parametrize("cfg, match", [
    ({"window_steps": 2}, "window_steps"),
    ({"window_steps": 5, "min_samples": 1}, "min_samples"),
    ({"window_steps": 5, "min_samples": 6}, "min_samples"),
    ({"floor_sigma_m": 0.0}, "floor_sigma_m"),
    ({"floor_sigma_m": -1.0}, "floor_sigma_m"),
    ({"floor_sigma_deg": 1.0}, "unknown"),
    ({"window": 10}, "unknown"),
    ({"window_steps": 86_401}, "window_steps must be <= 86400, got 86401"),
    ({"floor_sigma_m": 1000.5}, "floor_sigma_m must be <= 1000, got 1000.5"),
])
def test_build_rejects_bad_settings_naming_the_key(cfg: dict, match: str) -> None:
    """Bad values and keys of another group are refused with the key in the message, even
    when only one ship of several is wrong."""
    with pytest.raises(ValueError, match=match):
        adaptive.build([{}, cfg], "gnss")


@pytest.mark.parametrize(("group", "key", "most"), [
    ("gnss", "floor_sigma_m", 1000), ("compass", "floor_sigma_deg", 30),
    ("log", "floor_sigma_mps", 5)])
def test_floor_and_window_are_bounded_as_the_instruments(group: str, key: str,
                                                         most: float) -> None:
    """The floor at most the instrument's own noise bound, the window at most a day of 1 s
    steps: the bounds themselves are accepted, beyond is refused naming the key."""
    p = adaptive.build([{key: most, "window_steps": 86_400}], group)
    assert p.window_steps[0] == 86_400
    with pytest.raises(ValueError, match=f"{key} must be <= {most}, got {most + 1}"):
        adaptive.build([{}, {key: most + 1.0}], group)


def test_estimate_converges_to_a_correlated_anisotropic_r_of_an_optimal_filter() -> None:
    """A 2-D random-walk Kalman filter with the true (correlated, anisotropic) R: over a long
    window the Myers-Tapley estimate from its innovations and H P- H^T is that R, to the
    sampling error of about 2 000 innovations (averaged over 20 independent ships)."""
    rng = np.random.default_rng(31)
    n, steps, q = 20, 2000, 0.3
    R = np.array([[4.0, 1.5], [1.5, 2.0]])
    LR = np.linalg.cholesky(R)
    params = adaptive.build([{"window_steps": steps}] * n, "gnss")
    st = adaptive.start(params, np.broadcast_to(np.eye(2), (n, 2, 2)))
    truth = np.zeros((n, 2))
    x = np.zeros((n, 2))
    P = np.broadcast_to(np.eye(2) * 10.0, (n, 2, 2)).copy()
    for _ in range(steps):
        truth += rng.normal(0.0, math.sqrt(q), (n, 2))
        z = truth + rng.standard_normal((n, 2)) @ LR.T
        Pm = P + q * np.eye(2)
        nu = z - x
        S = Pm + R
        K = Pm @ np.linalg.inv(S)
        x = x + np.einsum("nij,nj->ni", K, nu)
        P = Pm - K @ Pm
        st = adaptive.step(params, st, nu, Pm, np.ones(n, bool))
    mean_R = st.R.mean(axis=0)
    # the sample covariance of S (about 6 m^2 per entry) over 40 000 innovations: +-0.1 m^2
    np.testing.assert_allclose(mean_R, R, atol=0.15)
    np.testing.assert_allclose(st.R, np.swapaxes(st.R, -1, -2))


def test_vectorised_ships_with_own_settings_equal_each_ship_alone() -> None:
    """Ships with different windows, min_samples, floors and invalid steps stepped together give
    each ship's estimate as when it runs alone (the shared buffer is as long as the longest
    window)."""
    rng = np.random.default_rng(37)
    cfgs = [{"window_steps": 5, "min_samples": 2, "floor_sigma_m": 0.5},
            {"window_steps": 12}, {"window_steps": 3, "min_samples": 3, "floor_sigma_m": 2.0}]
    n = len(cfgs)
    both = adaptive.build(cfgs, "gnss")
    st = adaptive.start(both, np.broadcast_to(np.eye(2) * 9.0, (n, 2, 2)))
    alone = [adaptive.build([c], "gnss") for c in cfgs]
    sts = [adaptive.start(a, np.eye(2)[None] * 9.0) for a in alone]
    for k in range(40):
        nu = rng.normal(0.0, 3.0, (n, 2))
        hph = np.broadcast_to(np.diag([0.5, 0.2]), (n, 2, 2)) * (1 + 0.1 * k)
        valid = rng.random(n) > 0.3
        st = adaptive.step(both, st, nu, hph, valid)
        for i in range(n):
            sts[i] = adaptive.step(alone[i], sts[i], nu[i:i + 1], hph[i:i + 1], valid[i:i + 1])
            np.testing.assert_allclose(st.R[i], sts[i].R[0], rtol=1e-9, atol=1e-12)


def test_scalar_group_estimate_by_hand() -> None:
    """A compass group (m = 1), window 4, min 3: after innovations 1, 2, 6 (H P H^T 0.5 each)
    the estimate is var([1, 2, 6]) - 0.5 = 7 - 0.5; after five steps the window holds
    [2, 6, 3, 5]: var 10/3 minus the mean H P H^T."""
    p = adaptive.build([{"window_steps": 4, "min_samples": 3, "floor_sigma_deg": 0.01}],
                       "compass")
    st = adaptive.start(p, np.full((1, 1, 1), 9.0))
    hph = [0.5, 0.5, 0.5, 1.0, 1.5]
    for i, v in enumerate([1.0, 2.0]):
        st = adaptive.step(p, st, np.array([[v]]), np.array([[[hph[i]]]]), np.array([True]))
        assert st.R[0, 0, 0] == 9.0  # prior kept until 3 samples
    st = adaptive.step(p, st, np.array([[6.0]]), np.array([[[0.5]]]), np.array([True]))
    # mean 3, squares 4 + 1 + 9 = 14, / 2 = 7
    assert st.R[0, 0, 0] == pytest.approx(7.0 - 0.5)
    for v, h in ((3.0, 1.0), (5.0, 1.5)):
        st = adaptive.step(p, st, np.array([[v]]), np.array([[[h]]]), np.array([True]))
    # window [2, 6, 3, 5]: mean 4, squares 4 + 4 + 1 + 1 = 10, / 3; H P H^T mean 3.5 / 4
    assert st.R[0, 0, 0] == pytest.approx(10.0 / 3.0 - 3.5 / 4.0)
    # a huge H P H^T drives the estimate to the floor, in rad^2
    st = adaptive.step(p, st, np.array([[4.0]]), np.array([[[1e6]]]), np.array([True]))
    assert st.R[0, 0, 0] == pytest.approx(math.radians(0.01) ** 2)


def test_build_rejects_unknown_group_and_keys_of_another_group() -> None:
    """A floor key of another group is an unknown key; an unknown group is refused."""
    with pytest.raises(ValueError, match="floor_sigma_m"):
        adaptive.build([{"floor_sigma_m": 1.0}], "compass")
    with pytest.raises(ValueError, match="group"):
        adaptive.build([{}], "radar")
    p = adaptive.build([{"window_steps": 7}], "log")
    assert p.min_samples.tolist() == [3] and p.floor_var[0] == pytest.approx(1e-4)


def test_empty_batch_starts_and_steps() -> None:
    """No ships: start and step give empty states, as the filters feeding them do."""
    p = adaptive.build([], "gnss")
    st = adaptive.start(p, np.zeros((0, 2, 2)))
    st = adaptive.step(p, st, np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0, bool))
    assert st.R.shape == (0, 2, 2)
