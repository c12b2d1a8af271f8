"""CA Kalman filter of seed 001 (eqs 6-7 and the printed initial conditions)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are

from trafficsim.estimation import ca
from trafficsim.estimation.gating import chi2_quantile

T = 2.0  # the paper's sampling period [seed 001, 4.1]


def consistent_truth(params: ca.CAParams, n: int, rng: np.random.Generator,
                     v0: float = 5.0) -> np.ndarray:
    """Tracks ``(m, n, 3)`` drawn from the filter's own model, started so that the error of the
    printed initial conditions has exactly the printed covariance P(2): zero acceleration and
    constant velocity between samples 0 and 1, model process noise from sample 1 on."""
    m = params.m
    phi = ca.transition(params.dt_s)
    chol = np.linalg.cholesky(ca.process_noise(params))
    x = np.zeros((m, n, 3))
    x[:, 0] = [0.0, v0, 0.0]
    x[:, 1] = [v0 * T, v0, 0.0]
    for k in range(2, n):
        w = np.einsum("mij,mj->mi", chol, rng.standard_normal((m, 3)))
        x[:, k] = np.einsum("mij,mj->mi", phi, x[:, k - 1]) + w
    return x


def assert_nees_chi_square(x: np.ndarray, p: np.ndarray, truth: np.ndarray, samples) -> None:
    """The NEES ``e^T P^-1 e`` of estimates ``x`` ``(m, N, 3)`` with covariances ``p``
    ``(m, N, 3, 3)`` against ``truth``, summed over the series and ``samples``, lies in the
    99 % interval of its chi-square distribution (3 dof a sample and series)."""
    from scipy import stats

    total = 0.0
    for k in samples:
        e = x[:, k] - truth[:, k]
        total += np.einsum("mi,mi->", e, np.linalg.solve(p[:, k], e[..., None])[..., 0])
    dof = 3 * len(samples) * x.shape[0]
    assert stats.chi2.ppf(0.005, dof) < total < stats.chi2.ppf(0.995, dof)


def test_matrices_as_printed() -> None:
    p = ca.CAParams.of(2, [2.0, 0.5], 3.0, [0.05, 0.1], [1 / 30, 0.2])
    phi = ca.transition(p.dt_s)
    np.testing.assert_allclose(phi[0], [[1, 2, 2], [0, 1, 2], [0, 0, 1]])
    np.testing.assert_allclose(phi[1], [[1, 0.5, 0.125], [0, 1, 0.5], [0, 0, 1]])
    q = ca.process_noise(p)
    q0 = 2 * (1 / 30) * 0.05**2
    np.testing.assert_allclose(q[0] / q0, [[32 / 20, 16 / 8, 8 / 6], [16 / 8, 8 / 3, 4 / 2],
                                           [8 / 6, 4 / 2, 2]])
    assert np.all(np.linalg.eigvalsh(q) > 0)


def test_q_is_integrated_white_jerk() -> None:
    """Q of eq 6 = int_0^T Phi(s) G q G^T Phi(s)^T ds with G = [0 0 1]^T, q = 2 alpha sigma_a^2
    (the claim of the module docstring), by the trapezoid rule."""
    p = ca.CAParams.of(1, T, 1.0, 0.3, 0.1)
    s = np.linspace(0.0, T, 4001)
    col = ca.transition(s)[:, :, 2]  # Phi(s) G
    integrand = col[:, :, None] * col[:, None, :] * (2 * 0.1 * 0.3**2)
    np.testing.assert_allclose(np.trapezoid(integrand, s, axis=0), ca.process_noise(p)[0],
                               rtol=1e-6)


def test_initial_conditions_as_printed() -> None:
    p = ca.CAParams.of(1, T, 3.0, 0.05, 1 / 30)
    x, pp = ca.initial_state(p, np.array([10.0]), np.array([20.0]))
    np.testing.assert_allclose(x[0], [20.0, 5.0, 0.0])
    np.testing.assert_allclose(pp[0], [[9, 4.5, 0], [4.5, 4.5, 0], [0, 0, 0]])


def test_build_repeats_axes_ship_major() -> None:
    p = ca.build([{"sigma_m": 1.0}, {"sigma_m": 2.0, "dt_s": 1.0}], axes=2)
    np.testing.assert_allclose(p.sigma_meas, [1, 1, 2, 2])
    np.testing.assert_allclose(p.dt_s, [2, 2, 1, 1])
    np.testing.assert_allclose(p.sigma_acc, ca.DEFAULTS["sigma_acc_mps2"])
    with pytest.raises(ValueError):
        ca.build([{"sigma_m": 0.0}])


def test_missing_or_rejected_measurement_keeps_prediction() -> None:
    p = ca.CAParams.of(3, T, 3.0, 0.05, 1 / 30)
    x, pp = ca.initial_state(p, np.zeros(3), np.full(3, 10.0))
    xp, ppp = ca.predict(p, x, pp)
    up = ca.update(p, xp, ppp, np.array([25.0, np.nan, 25.0]),
                   accept=np.array([True, True, False]))
    np.testing.assert_array_equal(up.x[1:], xp[1:])
    np.testing.assert_array_equal(up.p[1:], ppp[1:])
    assert up.x[0, 0] != xp[0, 0] and up.p[0, 0, 0] < ppp[0, 0, 0]
    assert np.isnan(up.innovation[1]) and up.innovation[2] == pytest.approx(5.0)


def test_restart_moves_position_keeps_velocity() -> None:
    p = ca.CAParams.of(2, T, 3.0, 0.05, 1 / 30)
    x = np.array([[0.0, 5.0, 0.1], [0.0, 5.0, 0.1]])
    pp = np.tile(np.eye(3), (2, 1, 1)) * 4.0 + 1.0
    x2, p2 = ca.restart(p, x, pp, np.array([500.0, 500.0]), np.array([True, False]))
    np.testing.assert_allclose(x2[0], [500.0, 5.0, 0.1])
    np.testing.assert_allclose(p2[0], [[9, 0, 0], [0, 5, 1], [0, 1, 5]])
    np.testing.assert_array_equal(x2[1], x[1])


def test_unbiased_and_nis_on_constant_acceleration_track() -> None:
    """Noisy fixes of a constant-acceleration track (no process noise in the truth).

    After the start-up transient (the printed P(2) asserts zero acceleration with zero variance,
    so the filter must learn the true 0.05 m/s^2 through Q, about 30 samples), the mean error of
    position, velocity and acceleration over 2000 runs is within 4 standard errors of zero, and
    the time-averaged NIS of each run is checked against its two-sided 95 % chi-square interval
    (Bar-Shalom, Li & Kirubarajan 2001, 5.4). The Q of eq 6 overbounds a truth with no jerk at
    all, so the NIS sits a little below 1 (0.90 here): at most 2.5 % of runs may lie above the
    interval and at least 85 % inside it (the exact two-sided test is the next one).
    """
    m, n, burn = 2000, 150, 40
    rng = np.random.default_rng(11)
    p = ca.CAParams.of(m, T, 3.0, 0.05, 1 / 30)
    t = np.arange(n) * T
    truth = np.stack([5.0 * t + 0.025 * t**2, 5.0 + 0.05 * t, np.full(n, 0.05)], axis=-1)
    z = truth[None, :, 0] + 3.0 * rng.standard_normal((m, n))
    f = ca.run(p, z)
    assert np.all(np.isnan(f.x[:, 0])) and np.all(np.isfinite(f.x[:, 1:]))
    err = f.x - truth[None]
    for k in (burn, 80, n - 1):
        se = err[:, k].std(axis=0) / np.sqrt(m)
        assert np.all(np.abs(err[:, k].mean(axis=0)) < 4 * se), (k, err[:, k].mean(axis=0), se)

    nis = f.innovation[:, burn:] ** 2 / f.innovation_var[:, burn:]
    dof = nis.shape[1]
    lo, hi = chi2_quantile(0.025, dof) / dof, chi2_quantile(0.975, dof) / dof
    anis = nis.mean(axis=1)
    assert np.mean(anis >= hi) <= 0.025  # never overconfident: 0.6 % of runs above (2.5 % ideal)
    assert np.mean((anis > lo) & (anis < hi)) >= 0.85  # 87 % inside (95 % ideal, rest below)
    assert 0.85 < anis.mean() < 1.0


def test_nis_chi_square_when_truth_follows_the_model() -> None:
    """With a truth drawn from the filter's own model the filter is exactly consistent: the NIS
    summed over 1000 runs and all 98 update steps is chi-square with 98 000 degrees of freedom
    and must lie inside its two-sided 99 % interval (about +-0.8 % of the mean). A filter using
    a 5 % wrong measurement noise fails this test."""
    m, n = 1000, 100
    rng = np.random.default_rng(12)
    p = ca.CAParams.of(m, T, 3.0, 0.05, 1 / 30)
    truth = consistent_truth(p, n, rng)
    z = truth[:, :, 0] + 3.0 * rng.standard_normal((m, n))

    def total_nis(params: ca.CAParams) -> tuple[float, int]:
        f = ca.run(params, z)
        nis = f.innovation[:, 2:] ** 2 / f.innovation_var[:, 2:]
        return float(nis.sum()), nis.size

    s, dof = total_nis(p)
    assert chi2_quantile(0.005, dof) < s < chi2_quantile(0.995, dof)
    s_bad, _ = total_nis(ca.CAParams.of(m, T, 3.0 * 0.95, 0.05, 1 / 30))
    assert s_bad > chi2_quantile(0.995, dof)

    # the filter covariance matches the empirical error covariance at a late step
    f = ca.run(p, z)
    e = f.x[:, -1] - truth[:, -1]
    np.testing.assert_allclose(e.var(axis=0), np.diagonal(f.p[0, -1]), rtol=0.15)


# ---------------------------------------------------------------- textbook filter, edge cases


def _textbook_run(params: ca.CAParams, z: np.ndarray) -> dict[str, np.ndarray]:
    """Plain matrix Kalman filter per series (explicit inverse, Joseph update) from the printed
    initial conditions; NaN measurements are skipped (prediction kept)."""
    m, n = z.shape
    out = {k: np.full((m, n, 3), np.nan) for k in ("x", "xp")}
    out.update({k: np.full((m, n, 3, 3), np.nan) for k in ("p", "pp")})
    out.update({k: np.full((m, n), np.nan) for k in ("nu", "s")})
    H = np.array([[1.0, 0.0, 0.0]])
    for i in range(m):
        T, r = params.dt_s[i], params.sigma_meas[i] ** 2
        qc = 2.0 * params.alpha_per_s[i] * params.sigma_acc[i] ** 2
        F = np.array([[1.0, T, T * T / 2], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
        Q = qc * np.array([[T**5 / 20, T**4 / 8, T**3 / 6], [T**4 / 8, T**3 / 3, T**2 / 2],
                           [T**3 / 6, T**2 / 2, T]])
        x = np.array([z[i, 1], (z[i, 1] - z[i, 0]) / T, 0.0])
        P = np.array([[r, r / T, 0.0], [r / T, 2 * r / T**2, 0.0], [0.0, 0.0, 0.0]])
        out["x"][i, 1], out["p"][i, 1] = x, P
        for k in range(2, n):
            x, P = F @ x, F @ P @ F.T + Q
            out["xp"][i, k], out["pp"][i, k] = x, P
            S = float((H @ P @ H.T)[0, 0]) + r
            nu = z[i, k] - x[0]
            out["nu"][i, k], out["s"][i, k] = nu, S
            if np.isfinite(nu):
                K = P @ H.T / S
                x = x + K[:, 0] * nu
                A = np.eye(3) - K @ H
                P = A @ P @ A.T + r * K @ K.T
            out["x"][i, k], out["p"][i, k] = x, P
    return out


def test_run_equals_a_joseph_form_textbook_filter_with_gaps() -> None:
    """Six series with different T, sigma_R, sigma_a and alpha, random measurements with 20 %
    missing: filtered and predicted states and covariances, innovations and their variances
    all equal the textbook filter (1e-9)."""
    rng = np.random.default_rng(51)
    m, n = 6, 40
    p = ca.CAParams.of(m, rng.uniform(0.5, 3, m), rng.uniform(0.5, 5, m),
                       rng.uniform(0.01, 0.3, m), rng.uniform(0.01, 0.2, m))
    z = np.cumsum(rng.normal(0, 5, (m, n)), axis=1)
    z[:, 2:][rng.random((m, n - 2)) < 0.2] = np.nan
    f = ca.run(p, z)
    ref = _textbook_run(p, z)
    for got, key in ((f.x, "x"), (f.p, "p"), (f.x_pred, "xp"), (f.p_pred, "pp"),
                     (f.innovation, "nu"), (f.innovation_var, "s")):
        np.testing.assert_allclose(got, ref[key], rtol=1e-9, atol=1e-9, err_msg=key)
    assert np.all(np.isnan(f.x_pred[:, :2])) and np.all(np.isnan(f.x[:, 0]))


def test_gain_converges_to_the_discrete_riccati_solution() -> None:
    """After 400 samples the CA filter's gain ``P(k|k-1) H^T / S`` equals the one from scipy's
    DARE solver for the same F, H, Q, R (T = 2 s and 0.5 s)."""
    p = ca.CAParams.of(2, [2.0, 0.5], [3.0, 1.0], [0.05, 0.2], [1 / 30, 0.1])
    f = ca.run(p, np.zeros((2, 400)))
    phi, q = ca.transition(p.dt_s), ca.process_noise(p)
    H = np.array([[1.0, 0.0, 0.0]])
    for i in range(2):
        r = p.sigma_meas[i] ** 2
        M = solve_discrete_are(phi[i].T, H.T, q[i], np.array([[r]]))
        k_dare = M[:, 0] / (M[0, 0] + r)
        k_run = f.p_pred[i, -1, :, 0] / f.innovation_var[i, -1]
        np.testing.assert_allclose(k_run, k_dare, rtol=1e-6)


def test_zero_process_noise_is_the_least_squares_straight_line() -> None:
    """sigma_a = 0 (allowed: Q = 0) with the printed start, which is the exact posterior of a
    line through the first two samples: the filter is then recursive least squares, so after
    sample k its position and velocity are the straight line fitted to samples 0..k by
    ``np.polyfit``, evaluated at sample k, and the acceleration stays 0."""
    rng = np.random.default_rng(52)
    n, T = 25, 2.0
    t = np.arange(n) * T
    z = 30.0 + 4.0 * t + rng.normal(0, 3.0, n)
    p = ca.CAParams.of(1, T, 3.0, 0.0, 1 / 30)
    f = ca.run(p, z[None])
    for k in (1, 2, 7, n - 1):
        slope, icpt = np.polyfit(t[:k + 1], z[:k + 1], 1)
        np.testing.assert_allclose(f.x[0, k, :2], [icpt + slope * t[k], slope], rtol=1e-9)
        assert f.x[0, k, 2] == 0.0
        A = np.stack([np.ones(k + 1), t[:k + 1] - t[k]], axis=1)
        np.testing.assert_allclose(f.p[0, k, :2, :2], 9.0 * np.linalg.inv(A.T @ A), rtol=1e-9)


def test_two_samples_only_and_bad_starts() -> None:
    """N = 2: the record is the initial conditions and nothing else; one sample, or a missing
    first or second sample, cannot start the filter."""
    p = ca.CAParams.of(1, T, 3.0, 0.05, 1 / 30)
    f = ca.run(p, np.array([[10.0, 20.0]]))
    np.testing.assert_allclose(f.x[0, 1], [20.0, 5.0, 0.0])
    assert np.all(np.isnan(f.innovation))
    for z in ([[1.0]], [[np.nan, 1.0, 2.0]], [[1.0, np.inf, 2.0]]):
        with pytest.raises(ValueError, match="first two"):
            ca.run(p, np.array(z))


def test_restart_ignores_masked_series_without_a_measurement() -> None:
    """A restart requested where the measurement is NaN keeps that series as it was."""
    p = ca.CAParams.of(2, T, 3.0, 0.05, 1 / 30)
    x = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    cov = np.tile(np.eye(3) + 0.5, (2, 1, 1))
    x2, p2 = ca.restart(p, x, cov, np.array([np.nan, 9.0]), np.array([True, True]))
    np.testing.assert_array_equal(x2[0], x[0])
    np.testing.assert_array_equal(p2[0], cov[0])
    assert x2[1, 0] == 9.0 and p2[1, 0, 0] == 9.0 and p2[1, 0, 1] == 0.0
    assert x[1, 0] == 4.0  # inputs untouched


def test_build_keeps_the_ship_order_and_accepts_zero_process_noise() -> None:
    p = ca.build([{"sigma_acc_mps2": 0.0, "alpha_per_s": 0.0}, {"dt_s": 0.5}])
    np.testing.assert_array_equal(p.sigma_acc, [0.0, 0.05])
    np.testing.assert_array_equal(p.alpha_per_s, [0.0, 1 / 30])
    np.testing.assert_array_equal(ca.process_noise(p)[0], 0.0)
    for bad in ({"dt_s": 0.0}, {"sigma_acc_mps2": -0.1}, {"alpha_per_s": -1.0}):
        with pytest.raises(ValueError):
            ca.build([bad])


@pytest.mark.parametrize("key", ["dt_s", "sigma_m", "sigma_acc_mps2", "alpha_per_s"])
def test_build_rejects_nan(key: str) -> None:
    with pytest.raises(ValueError):
        ca.build([{key: float("nan")}])


def test_run_vectorised_over_series_with_own_parameters_equals_one_series_at_a_time() -> None:
    """Series with different T, sigma_R, sigma_a and alpha, and gaps at different samples,
    filtered together equal each series filtered alone."""
    rng = np.random.default_rng(21)
    p = ca.CAParams.of(4, [2.0, 1.0, 0.5, 3.0], [3.0, 1.0, 0.2, 5.0], [0.05, 0.2, 0.0, 0.1],
                       [1 / 30, 0.1, 0.5, 0.0])
    z = np.cumsum(rng.normal(0.0, 4.0, (4, 60)), axis=1)
    z[0, 10:15] = np.nan
    z[2, 30] = np.nan
    z[3, 2:] = np.nan
    together = ca.run(p, z)
    for i in range(4):
        one = ca.CAParams(p.dt_s[i:i + 1], p.sigma_meas[i:i + 1], p.sigma_acc[i:i + 1],
                          p.alpha_per_s[i:i + 1])
        alone = ca.run(one, z[i:i + 1])
        for a, b in zip(together, alone, strict=True):
            np.testing.assert_allclose(a[i], b[0], rtol=1e-12, atol=1e-12)


def test_gap_predicts_only_and_the_innovation_is_nan_there() -> None:
    """At a missing sample the estimate is Phi times the previous one and P the predicted one;
    the innovation there is NaN, elsewhere it is Z - H X(k|k-1)."""
    p = ca.CAParams.of(1, T, 2.0, 0.1, 0.1)
    z = np.array([[0.0, 10.0, 21.0, np.nan, np.nan, 52.0, 60.0]])
    r = ca.run(p, z)
    phi = ca.transition(p.dt_s)[0]
    for k in (3, 4):
        np.testing.assert_allclose(r.x[0, k], phi @ r.x[0, k - 1], rtol=1e-14)
        np.testing.assert_allclose(r.p[0, k], r.p_pred[0, k], rtol=1e-14)
        assert np.isnan(r.innovation[0, k])
    for k in (2, 5, 6):
        assert r.innovation[0, k] == pytest.approx(z[0, k] - r.x_pred[0, k, 0])
        assert r.innovation_var[0, k] == pytest.approx(r.p_pred[0, k, 0, 0] + 4.0)
    # the variance of the position grows through the gap and drops at the next fix
    assert r.p[0, 3, 0, 0] < r.p[0, 4, 0, 0]
    assert r.p[0, 5, 0, 0] < r.p[0, 4, 0, 0]


def test_nees_on_the_filters_own_model_is_chi_square() -> None:
    """Truth drawn from the model with the printed start: the NEES of X(k) over many independent
    series at a few well separated samples lies in the 99 % chi-square interval (3 dof)."""
    rng = np.random.default_rng(8)
    p = ca.CAParams.of(400, T, 3.0, 0.2, 0.1)
    truth = consistent_truth(p, 81, rng)
    z = truth[..., 0] + rng.normal(0.0, 3.0, truth.shape[:2])
    r = ca.run(p, z)
    assert_nees_chi_square(r.x, r.p, truth, (20, 50, 80))


def test_update_with_a_rejected_finite_measurement_reports_its_innovation_only() -> None:
    """A finite measurement rejected by ``accept`` leaves the prediction and its covariance, but
    its innovation and variance are still reported (for the gate's statistics)."""
    p = ca.CAParams.of(2, T, 1.0, 0.1, 0.1)
    xp = np.array([[5.0, 1.0, 0.0], [7.0, -1.0, 0.1]])
    pp = np.broadcast_to(np.diag([4.0, 1.0, 0.1]), (2, 3, 3)).copy()
    up = ca.update(p, xp, pp, np.array([9.0, 8.0]), accept=np.array([False, True]))
    np.testing.assert_array_equal(up.x[0], xp[0])
    np.testing.assert_array_equal(up.p[0], pp[0])
    np.testing.assert_allclose(up.innovation, [4.0, 1.0])
    np.testing.assert_allclose(up.innovation_var, [5.0, 5.0])
    # accepted: gain P H^T / S = [4, 0, 0] / 5 (diagonal P), position 7 + 0.8 * 1
    np.testing.assert_allclose(up.x[1], [7.8, -1.0, 0.1])
    np.testing.assert_allclose(up.p[1], np.diag([0.8, 1.0, 0.1]))
