"""Fixed-interval RTS smoother [seed 001, eq 8] and body velocities from a track [eq 9]."""

from __future__ import annotations

import numpy as np
import pytest

from trafficsim.estimation import ca, smoother
from trafficsim.ships import manoeuvres
from trafficsim.ships.base import Env
from trafficsim.ships.library import load_ship

from .test_ca import T, assert_nees_chi_square, consistent_truth


def test_rts_equals_batch_least_squares() -> None:
    """The smoother's X(k|N) and P(k|N) equal the mean and covariance of the whole-record
    Gaussian posterior, solved as one linear least-squares problem (information form)."""
    rng = np.random.default_rng(3)
    m, n = 2, 7
    p = ca.CAParams.of(m, [2.0, 1.0], [3.0, 0.5], [0.05, 0.2], [1 / 30, 0.1])
    m0 = np.array([[0.0, 5.0, 0.0], [10.0, -1.0, 0.1]])
    p0 = np.array([np.diag([25.0, 4.0, 0.01]), np.diag([1.0, 1.0, 0.1])])
    z = m0[:, None, 0] + rng.normal(0.0, 5.0, (m, n))
    phi, q = ca.transition(p.dt_s), ca.process_noise(p)

    x = np.zeros((m, n, 3))
    cov = np.zeros((m, n, 3, 3))
    xp = np.full((m, n, 3), np.nan)
    pp = np.full((m, n, 3, 3), np.nan)
    x[:, 0], cov[:, 0] = ca.update(p, m0, p0, z[:, 0])[:2]
    for k in range(1, n):
        xp[:, k], pp[:, k] = ca.predict(p, x[:, k - 1], cov[:, k - 1])
        x[:, k], cov[:, k] = ca.update(p, xp[:, k], pp[:, k], z[:, k])[:2]
    sm = smoother.rts(x, cov, xp, pp, phi, first=0)

    h = np.array([1.0, 0.0, 0.0])
    for i in range(m):
        info = np.zeros((3 * n, 3 * n))
        rhs = np.zeros(3 * n)
        p0i = np.linalg.inv(p0[i])
        qi = np.linalg.inv(q[i])
        info[:3, :3] += p0i
        rhs[:3] += p0i @ m0[i]
        for k in range(n):
            b = slice(3 * k, 3 * k + 3)
            info[b, b] += np.outer(h, h) / p.sigma_meas[i] ** 2
            rhs[b] += h * z[i, k] / p.sigma_meas[i] ** 2
            if k + 1 < n:
                c = slice(3 * k + 3, 3 * k + 6)
                info[b, b] += phi[i].T @ qi @ phi[i]
                info[c, c] += qi
                info[b, c] -= phi[i].T @ qi
                info[c, b] -= qi @ phi[i]
        post_cov = np.linalg.inv(info)
        post_mean = post_cov @ rhs
        np.testing.assert_allclose(sm.x[i].ravel(), post_mean, rtol=1e-7, atol=1e-8)
        for k in range(n):
            b = slice(3 * k, 3 * k + 3)
            np.testing.assert_allclose(sm.p[i, k], post_cov[b, b], rtol=1e-6, atol=1e-12)


def test_smoother_beats_filter_and_its_covariance_is_honest() -> None:
    """Monte Carlo over 4000 runs of a truth drawn from the model (consistent start): the
    smoothed error variance is below the filtered one (mid-record position by about 4x), the
    smoother's P(k|N) matches the empirical error variance within 10 % (sampling error 2.2 %)
    and the position-velocity correlation within 0.05; at the end both coincide."""
    m, n = 4000, 60
    rng = np.random.default_rng(21)
    p = ca.CAParams.of(m, T, 3.0, 0.05, 1 / 30)
    truth = consistent_truth(p, n, rng)
    z = truth[:, :, 0] + 3.0 * rng.standard_normal((m, n))
    f = ca.run(p, z)
    s = smoother.smooth_ca(p, z)
    ef, es = f.x - truth, s.x - truth
    mid = n // 2
    assert np.all(es[:, mid].var(axis=0) < 0.7 * ef[:, mid].var(axis=0))
    assert es[:, mid, 0].var() < 0.3 * ef[:, mid, 0].var()
    for k in (1, 2, 10, mid, n - 2, n - 1):
        var = np.diagonal(s.p[0, k])
        np.testing.assert_allclose(es[:, k].var(axis=0), var, rtol=0.10, err_msg=f"k={k}")
        corr_emp = np.corrcoef(es[:, k, 0], es[:, k, 1])[0, 1]
        corr_model = s.p[0, k, 0, 1] / np.sqrt(var[0] * var[1])
        assert corr_emp == pytest.approx(corr_model, abs=0.05)
    np.testing.assert_allclose(s.x[:, -1], f.x[:, -1])
    np.testing.assert_allclose(s.p[:, -1], f.p[:, -1])


def test_first_sample_is_the_backward_prediction() -> None:
    rng = np.random.default_rng(4)
    p = ca.CAParams.of(3, T, 3.0, 0.05, 1 / 30)
    z = np.arange(20)[None, :] * 10.0 + rng.normal(0.0, 3.0, (3, 20))
    s = smoother.smooth_ca(p, z)
    back = np.einsum("mij,mj->mi", np.linalg.inv(ca.transition(p.dt_s)), s.x[:, 1])
    np.testing.assert_allclose(s.x[:, 0], back)
    assert np.all(np.isfinite(s.p[:, 0])) and np.all(s.p[:, 0, 0, 0] > s.p[:, 1, 0, 0])


def test_drift_sign_convention() -> None:
    """Heading north, moving 10 deg to starboard of it: beta = +10 deg and v > 0 (starboard)."""
    t = np.arange(60) * T
    course = np.radians(10.0)
    out = smoother.body_velocities(5.0 * t * np.cos(course), 5.0 * t * np.sin(course),
                                   np.zeros_like(t), T)
    np.testing.assert_allclose(out["drift_rad"], course, atol=1e-9)
    np.testing.assert_allclose(out["u_mps"], 5.0 * np.cos(course), atol=1e-9)
    np.testing.assert_allclose(out["v_mps"], 5.0 * np.sin(course), atol=1e-9)
    np.testing.assert_allclose(out["speed_mps"], 5.0, atol=1e-9)
    np.testing.assert_allclose(out["r_radps"], 0.0, atol=1e-12)


@pytest.fixture(scope="module")
def kvlcc2_turn() -> dict[str, np.ndarray]:
    """KVLCC2 35 deg starboard turning circle (360 deg), truth at 1 s, resampled at T = 2 s."""
    track, _ = manoeuvres.turning_circle(load_ship("kvlcc2"), 35.0, dt=1.0, turns_deg=360.0)
    return {k: v[::2] for k, v in track.items()}


def _noisy_body_velocities(tr: dict[str, np.ndarray], k: int, seed: int
                           ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """``body_velocities`` of ``k`` noise realisations of the turn (fixes sigma 1 m per axis,
    compass sigma 0.2 deg) and the true ``u, v, r``."""
    rng = np.random.default_rng(seed)
    n = tr["t_s"].size
    north = tr["north_m"] + rng.normal(0.0, 1.0, (k, n))
    east = tr["east_m"] + rng.normal(0.0, 1.0, (k, n))
    psi = np.radians(tr["heading_deg"]) + rng.normal(0.0, np.radians(0.2), (k, n))
    truth = {"u_mps": tr["u_mps"], "v_mps": tr["v_mps"], "r_radps": np.radians(tr["r_degps"])}
    return smoother.body_velocities(north, east, psi, T), truth


def test_body_velocities_recover_turning_circle(kvlcc2_turn: dict[str, np.ndarray]) -> None:
    """From position fixes (sigma 1 m per axis) and compass (sigma 0.2 deg) every 2 s, 50 noise
    realisations at once: over the turn (first and last 10 s left out) the RMS errors are below
    0.06 m/s in u and v (truth spans 8 -> 3 m/s and 0 -> 1.6 m/s), 5e-4 rad/s (0.03 deg/s) in r
    (truth up to 0.011 rad/s), and the mean over realisations (bias, the smoother's lag on the
    rudder step) below 0.03 m/s and 2.5e-4 rad/s."""
    tr = kvlcc2_turn
    k, n = 50, tr["t_s"].size
    out, truth = _noisy_body_velocities(tr, k, seed=8)
    inner = slice(5, -5)
    rms_tol = {"u_mps": 0.06, "v_mps": 0.06, "r_radps": 5e-4}
    bias_tol = {"u_mps": 0.03, "v_mps": 0.03, "r_radps": 2.5e-4}
    for key, true in truth.items():
        err = (out[key] - true)[:, inner]
        assert np.sqrt(np.mean(err**2)) < rms_tol[key], key
        assert np.abs(err.mean(axis=0)).max() < bias_tol[key], key
    assert out["u_mps"].shape == (k, n)


def test_body_velocities_subtract_current() -> None:
    """With a 0.5 m/s current towards east the track drifts; given the current, u and v come
    out relative to the water as in the simulator's state; ignoring it errs by about 0.5 m/s."""
    env = Env(current_east_mps=0.5)
    tr, _ = manoeuvres.turning_circle(load_ship("kvlcc2"), 35.0, dt=2.0, env=env,
                                      turns_deg=180.0)
    out = smoother.body_velocities(tr["north_m"], tr["east_m"], np.radians(tr["heading_deg"]),
                                   2.0, current_east_mps=0.5)
    inner = slice(5, -5)
    assert np.abs(out["u_mps"] - tr["u_mps"])[inner].max() < 0.03
    assert np.abs(out["v_mps"] - tr["v_mps"])[inner].max() < 0.03
    naive = smoother.body_velocities(tr["north_m"], tr["east_m"], np.radians(tr["heading_deg"]),
                                     2.0)
    err = np.hypot(naive["u_mps"] - tr["u_mps"], naive["v_mps"] - tr["v_mps"])[inner]
    assert np.allclose(err, 0.5, atol=0.03)


def test_body_velocity_uncertainty_is_honest(kvlcc2_turn: dict[str, np.ndarray]) -> None:
    """The reported standard deviations of u, v, r match the spread of the errors over 200
    noise realisations to within a factor 1.6 over the turn (ends left out)."""
    out, truth = _noisy_body_velocities(kvlcc2_turn, 200, seed=21)
    inner = slice(5, -5)
    for key, true in truth.items():
        spread = np.sqrt(np.mean((out[key] - true) ** 2, axis=0))[inner]
        sigma = np.mean(out["sigma_" + key], axis=0)[inner]
        ratio = np.median(spread / sigma)
        assert 1 / 1.6 < ratio < 1.6, (key, ratio)


def test_gaps_in_the_heading_are_bridged() -> None:
    """A heading record crossing north with missing samples: unwrapped over the finite samples,
    so the yaw rate after the gap is right (np.unwrap would turn the rest into NaN)."""
    t = np.arange(200) * T
    rate = np.radians(0.5)
    heading = np.mod(np.radians(350.0) + rate * t, 2 * np.pi)
    heading[50:56] = np.nan
    unwrapped = smoother.unwrap_finite(heading)
    ok = np.isfinite(unwrapped)
    np.testing.assert_allclose(unwrapped[ok], np.radians(350.0) + rate * t[ok], atol=1e-12)
    out = smoother.body_velocities(10.0 * t, 0.0 * t, heading, T)
    np.testing.assert_allclose(out["r_radps"][3:-3], rate, atol=1e-6)
    assert np.all(np.isfinite(out["sigma_r_radps"]))
    assert out["sigma_psi_rad"][53] > out["sigma_psi_rad"][100]  # less certain in the gap


def _batch_posterior_two_point_start(p: ca.CAParams, z: np.ndarray, i: int
                                     ) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian posterior of series ``i`` of the CA model as one least-squares problem.

    Unknowns: position and velocity at sample 1 (acceleration 0 there, as the printed start
    asserts) and the full state at samples 2..N-1. Measurements z(0) = s(1) - T u(1) + n (the
    constant-velocity step behind the printed start) and z(k) = s(k) + n for k >= 1 (NaN
    skipped); process equations x(k+1) - Phi x(k) ~ N(0, Q). Returns means ``(N, 3)`` and
    covariances ``(N, 3, 3)`` for samples 1..N-1 (sample 0 NaN)."""
    n = z.shape[1]
    T, r = p.dt_s[i], p.sigma_meas[i] ** 2
    phi, q = ca.transition(p.dt_s)[i], ca.process_noise(p)[i]
    qi = np.linalg.inv(q)
    dim = 2 + 3 * (n - 2)

    def sel(k: int) -> np.ndarray:
        s_k = np.zeros((3, dim))
        if k == 1:
            s_k[0, 0] = s_k[1, 1] = 1.0
        else:
            s_k[:, 2 + 3 * (k - 2):5 + 3 * (k - 2)] = np.eye(3)
        return s_k

    info = np.zeros((dim, dim))
    rhs = np.zeros(dim)
    h0 = np.zeros(dim)
    h0[0], h0[1] = 1.0, -T
    info += np.outer(h0, h0) / r
    rhs += h0 * z[i, 0] / r
    for k in range(1, n):
        if np.isfinite(z[i, k]):
            h = sel(k)[0]
            info += np.outer(h, h) / r
            rhs += h * z[i, k] / r
        if k + 1 < n:
            d = sel(k + 1) - phi @ sel(k)
            info += d.T @ qi @ d
    cov = np.linalg.inv(info)
    mean = cov @ rhs
    xs = np.full((n, 3), np.nan)
    ps = np.full((n, 3, 3), np.nan)
    for k in range(1, n):
        xs[k] = sel(k) @ mean
        ps[k] = sel(k) @ cov @ sel(k).T
    return xs, ps


def test_smooth_ca_equals_the_batch_posterior_with_gaps() -> None:
    """``smooth_ca`` (printed start, RTS from sample 1) equals the whole-record posterior of the
    same model solved as one least-squares problem, for three series with different settings
    and missing samples (also the last one)."""
    rng = np.random.default_rng(61)
    m, n = 3, 12
    p = ca.CAParams.of(m, [2.0, 1.0, 0.5], [3.0, 0.5, 1.0], [0.05, 0.2, 1.0], [1 / 30, 0.1, 0.3])
    z = np.cumsum(rng.normal(0, 4, (m, n)), axis=1)
    z[0, [4, 5, n - 1]] = np.nan
    z[2, 6] = np.nan
    s = smoother.smooth_ca(p, z)
    for i in range(m):
        xs, ps = _batch_posterior_two_point_start(p, z, i)
        np.testing.assert_allclose(s.x[i, 1:], xs[1:], rtol=1e-7, atol=1e-8)
        np.testing.assert_allclose(s.p[i, 1:], ps[1:], rtol=1e-6, atol=1e-10)


def test_smooth_ca_with_zero_process_noise_is_the_least_squares_line() -> None:
    """sigma_a = 0: the whole record is one straight line, so every smoothed sample from 1 on
    is the least-squares line through all samples (np.polyfit) and the velocity its slope."""
    rng = np.random.default_rng(62)
    n, T = 15, 2.0
    t = np.arange(n) * T
    z = 5.0 + 3.0 * t + rng.normal(0, 2.0, n)
    s = smoother.smooth_ca(ca.CAParams.of(1, T, 2.0, 0.0, 1 / 30), z[None])
    slope, icpt = np.polyfit(t, z, 1)
    np.testing.assert_allclose(s.x[0, 1:, 0], icpt + slope * t[1:], rtol=1e-9)
    np.testing.assert_allclose(s.x[0, 1:, 1], slope, rtol=1e-9)


def test_rts_leaves_samples_before_first_nan_and_keeps_the_last() -> None:
    """``first = 3``: samples 0-2 stay NaN, the last sample is the filtered one."""
    rng = np.random.default_rng(63)
    p = ca.CAParams.of(2, T, 3.0, 0.05, 1 / 30)
    f = ca.run(p, np.cumsum(rng.normal(0, 3, (2, 10)), axis=1))
    out = smoother.rts(f.x, f.p, f.x_pred, f.p_pred, ca.transition(p.dt_s), first=3)
    assert np.all(np.isnan(out.x[:, :3])) and np.all(np.isnan(out.p[:, :3]))
    assert np.all(np.isfinite(out.x[:, 3:]))
    np.testing.assert_array_equal(out.x[:, -1], f.x[:, -1])
    np.testing.assert_array_equal(out.p[:, -1], f.p[:, -1])


def test_unwrap_finite_edge_cases() -> None:
    """Rows are independent; an all-NaN row stays NaN; one sample is unchanged; crossings of
    north in both directions are unwrapped (350 -> 10 deg is +20, 10 -> 350 is -20)."""
    a = np.radians(np.array([[350.0, 10.0, np.nan, 30.0],
                             [10.0, 350.0, 330.0, np.nan],
                             [np.nan] * 4]))
    out = smoother.unwrap_finite(a)
    np.testing.assert_allclose(np.degrees(out[0]), [350.0, 370.0, np.nan, 390.0])
    np.testing.assert_allclose(np.degrees(out[1]), [10.0, -10.0, -30.0, np.nan])
    assert np.all(np.isnan(out[2]))
    np.testing.assert_array_equal(smoother.unwrap_finite(np.array([5.0])), [5.0])
    assert np.isnan(a[0, 2]) and a[0, 1] == np.radians(10.0)  # input untouched


def test_body_velocities_rows_equal_single_records_and_rotation_identities() -> None:
    """A (2, N) call equals two (N,) calls; u^2 + v^2 is the squared water velocity
    |ground velocity - current|^2 (a rotation); speed = hypot(vn, ve); drift = course - psi
    wrapped to [-pi, pi)."""
    rng = np.random.default_rng(64)
    n = 40
    t = np.arange(n) * T
    north = np.stack([4.0 * t, -2.0 * t + 0.01 * t**2]) + rng.normal(0, 1, (2, n))
    east = np.stack([1.0 * t, 3.0 * t]) + rng.normal(0, 1, (2, n))
    psi = np.stack([np.full(n, 0.3), np.mod(2.0 + 0.01 * t, 2 * np.pi)])
    cur = np.array([0.2, -0.4])
    both = smoother.body_velocities(north, east, psi, T, current_north_mps=cur,
                                    current_east_mps=cur[::-1])
    for i in range(2):
        one = smoother.body_velocities(north[i], east[i], psi[i], T,
                                       current_north_mps=cur[i], current_east_mps=cur[1 - i])
        for key, value in one.items():
            np.testing.assert_allclose(both[key][i], value, rtol=1e-12, atol=1e-12, err_msg=key)
    wn = both["vn_mps"] - cur[:, None]
    we = both["ve_mps"] - cur[::-1, None]
    np.testing.assert_allclose(both["u_mps"] ** 2 + both["v_mps"] ** 2, wn**2 + we**2,
                               rtol=1e-12)
    np.testing.assert_allclose(both["speed_mps"], np.hypot(both["vn_mps"], both["ve_mps"]))
    d = np.mod(both["course_rad"] - both["psi_rad"] + np.pi, 2 * np.pi) - np.pi
    np.testing.assert_allclose(np.angle(np.exp(1j * (both["drift_rad"] - d))), 0.0, atol=1e-12)
    assert np.all(np.abs(both["drift_rad"]) <= np.pi)


def test_rts_vectorised_over_series_equals_one_series_at_a_time() -> None:
    """Series with their own parameters and gaps smoothed together equal each smoothed alone
    (the batched solve and its pseudo-inverse fallback act per series)."""
    rng = np.random.default_rng(4)
    p = ca.CAParams.of(3, [2.0, 1.0, 0.5], [3.0, 1.0, 0.5], [0.05, 0.3, 0.1], [1 / 30, 0.1, 1.0])
    z = np.cumsum(rng.normal(0.0, 3.0, (3, 50)), axis=1)
    z[1, 20:24] = np.nan
    together = smoother.smooth_ca(p, z)
    for i in range(3):
        one = ca.CAParams(p.dt_s[i:i + 1], p.sigma_meas[i:i + 1], p.sigma_acc[i:i + 1],
                          p.alpha_per_s[i:i + 1])
        alone = smoother.smooth_ca(one, z[i:i + 1])
        np.testing.assert_allclose(together.x[i], alone.x[0], rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(together.p[i], alone.p[0], rtol=1e-10, atol=1e-12)


def test_smoothed_nees_on_the_filters_own_model_is_chi_square() -> None:
    """Truth drawn from the filter's model: the NEES of X(k|N) over many series at separated
    samples (early, middle and last) lies in the 99 % chi-square interval (3 dof each)."""
    rng = np.random.default_rng(9)
    p = ca.CAParams.of(400, T, 3.0, 0.2, 0.1)
    truth = consistent_truth(p, 61, rng)
    z = truth[..., 0] + rng.normal(0.0, 3.0, truth.shape[:2])
    s = smoother.smooth_ca(p, z)
    assert_nees_chi_square(s.x, s.p, truth, (3, 30, 60))


def test_smoothed_covariance_never_exceeds_the_filtered_one_and_ends_equal() -> None:
    """P(k|N) <= P(k) in the Loewner order at every sample (more data never hurts), with
    equality at the last sample; smoothed covariances are symmetric."""
    rng = np.random.default_rng(2)
    p = ca.CAParams.of(2, T, [3.0, 1.0], [0.05, 0.5], 0.1)
    z = np.cumsum(rng.normal(0.0, 2.0, (2, 40)), axis=1)
    z[0, 15:20] = np.nan
    f = ca.run(p, z)
    s = smoother.smooth_ca(p, z)
    np.testing.assert_array_equal(s.p[:, -1], f.p[:, -1])
    np.testing.assert_allclose(s.p, np.swapaxes(s.p, -1, -2), rtol=1e-13, atol=1e-15)
    diff = f.p[:, 1:] - s.p[:, 1:]
    eig = np.linalg.eigvalsh(0.5 * (diff + np.swapaxes(diff, -1, -2)))
    assert eig.min() > -1e-9 * np.abs(f.p[:, 1:]).max()


def test_rts_of_a_scalar_random_walk_equals_the_two_filter_formula() -> None:
    """For a scalar random walk the smoothed variance at k is the harmonic combination of the
    forward filter's P(k) and a backward information filter over the later samples
    (Fraser-Potter): 1/P(k|N) = 1/P(k) + 1/B(k), B from the samples after k predicted back."""
    q, r, n = 0.5, 2.0, 12
    z = np.linspace(0.0, 5.0, n) + np.sin(np.arange(n))
    x = np.zeros((1, n, 1))
    pf = np.zeros((1, n, 1, 1))
    xp = np.full((1, n, 1), np.nan)
    pp = np.full((1, n, 1, 1), np.nan)
    x[0, 0, 0], pf[0, 0, 0, 0] = z[0], r
    for k in range(1, n):
        xp[0, k, 0], pp[0, k, 0, 0] = x[0, k - 1, 0], pf[0, k - 1, 0, 0] + q
        g = pp[0, k, 0, 0] / (pp[0, k, 0, 0] + r)
        x[0, k, 0] = xp[0, k, 0] + g * (z[k] - xp[0, k, 0])
        pf[0, k, 0, 0] = (1 - g) * pp[0, k, 0, 0]
    s = smoother.rts(x, pf, xp, pp, np.ones((1, 1, 1)))
    for k in range(n - 1):
        info, mean_info = 0.0, 0.0  # backward filter over samples k+1..n-1, at time k
        for j in range(n - 1, k, -1):
            info, mean_info = info + 1 / r, mean_info + z[j] / r
            var = 1 / info + q  # predicted one step back
            info, mean_info = 1 / var, (mean_info / info) / var
        ps = 1 / (1 / pf[0, k, 0, 0] + info)
        xs = ps * (x[0, k, 0] / pf[0, k, 0, 0] + mean_info)
        assert s.p[0, k, 0, 0] == pytest.approx(ps, rel=1e-12)
        assert s.x[0, k, 0] == pytest.approx(xs, rel=1e-12, abs=1e-12)


def test_unwrap_finite_of_an_empty_record_is_empty_like_numpy_unwrap() -> None:
    """An empty 1-D record unwraps to an empty record, as np.unwrap does."""
    assert np.unwrap(np.zeros(0)).shape == (0,)
    assert smoother.unwrap_finite(np.zeros(0)).shape == (0,)


def test_course_is_below_two_pi_for_a_tiny_westward_velocity() -> None:
    """A northward track drifting 1e-17 m per sample west: the course is north, in [0, 2 pi)
    like every course of the package (:func:`trafficsim.sensors.wrap_2pi`)."""
    k = np.arange(20.0)
    out = smoother.body_velocities(3.0 * k, -1e-17 * k, np.zeros(20), 1.0)
    assert np.all(out["ve_mps"] < 0.0)
    assert np.all((out["course_rad"] >= 0.0) & (out["course_rad"] < 2 * np.pi))
