"""Fusion of GNSS receivers by weight matrices with cross-covariances [seed 003, eqs 2-6]."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trafficsim.estimation import fusion


def _random_spd(rng: np.random.Generator, n: int, d: int, scale: float = 1.0) -> np.ndarray:
    L = rng.standard_normal((n, d, d))
    return (L @ L.transpose(0, 2, 1) + 0.2 * np.eye(d)) * scale


def _min_eig(m: np.ndarray) -> np.ndarray:
    return np.linalg.eigvalsh(0.5 * (m + np.swapaxes(m, -1, -2)))[..., 0]


def test_without_cross_covariance_the_blue_is_eq_3() -> None:
    """Zero cross-covariances: the general weights = A_i = (sum P_jj^-1)^-1 P_ii^-1 [eq 3]."""
    rng = np.random.default_rng(0)
    n, k = 50, 3
    cov = _random_spd(rng, n * k, 2, 4.0).reshape(n, k, 2, 2)
    fixes = rng.normal(0, 10, (n, k, 2))
    sigma = fusion.joint_covariance(cov, 0.0)
    general = fusion.fuse(fixes, sigma)
    eq3 = fusion.fuse_uncorrelated(fixes, cov)
    np.testing.assert_allclose(general.weights, eq3.weights, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(general.position, eq3.position, rtol=1e-10)
    np.testing.assert_allclose(general.cov, eq3.cov, rtol=1e-10)
    np.testing.assert_allclose(general.weights.sum(axis=1), np.broadcast_to(np.eye(2), (n, 2, 2)),
                               atol=1e-12)


def test_fused_covariance_below_every_receiver_and_equal_to_the_blue_bound() -> None:
    """Random joint covariances with cross-covariances (k = 2..4 receivers): P_f <= P_ii for every
    receiver (matrix order), and any other unbiased weights (sum A_i = I) give a covariance
    >= P_f: P_f is the BLUE bound (e^T Sigma^-1 e)^-1. Monte Carlo: the fused error has
    covariance P_f and zero mean."""
    rng = np.random.default_rng(1)
    for k in (2, 3, 4):
        n = 400
        S = _random_spd(rng, n, 2 * k)
        fixes = np.zeros((n, k, 2))
        out = fusion.fuse(fixes, S)
        for i in range(k):
            Pii = S[:, 2 * i:2 * i + 2, 2 * i:2 * i + 2]
            assert np.all(_min_eig(Pii - out.cov) > -1e-10)
        W = rng.standard_normal((n, k, 2, 2))
        W[:, -1] = np.eye(2) - W[:, :-1].sum(axis=1)  # unbiased: weights sum to I
        Wflat = W.transpose(0, 2, 1, 3).reshape(n, 2, 2 * k)  # [A_1 ... A_k]
        cov_w = Wflat @ S @ Wflat.transpose(0, 2, 1)
        assert np.all(_min_eig(cov_w - out.cov) > -1e-10)
        E = np.tile(np.eye(2), (k, 1))
        bound = np.linalg.inv(E.T @ np.linalg.solve(S, np.broadcast_to(E, (n, 2 * k, 2))))
        np.testing.assert_allclose(out.cov, bound, rtol=1e-10)

    # Monte Carlo on one joint covariance
    k = 3
    S = _random_spd(np.random.default_rng(2), 1, 2 * k)[0]
    m = 200_000
    err = np.random.default_rng(3).multivariate_normal(np.zeros(2 * k), S, m).reshape(m, k, 2)
    truth = np.array([100.0, -50.0])
    out = fusion.fuse(truth + err, np.broadcast_to(S, (m, 2 * k, 2 * k)))
    e = out.position - truth
    np.testing.assert_allclose(e.mean(axis=0), 0.0, atol=4 * math.sqrt(S.max() / m))
    np.testing.assert_allclose(np.cov(e.T), out.cov[0], rtol=0.02, atol=0.01 * out.cov[0].max())


@pytest.mark.parametrize(("s1", "s2"), [(3.0, 3.0), (2.0, 5.0)])
def test_positive_cross_covariance_reduces_the_gain_from_fusion(s1: float, s2: float) -> None:
    """Two receivers with correlated errors (common-mode rho): the fused variance is
    s1^2 s2^2 (1 - rho^2)/(s1^2 + s2^2 - 2 rho s1 s2). For equal receivers it is s^2 (1 + rho)/2,
    growing with rho (no gain at all at rho = 1). For unequal ones (s1 < s2) it grows up to
    rho = s1/s2, where fusion gains nothing (variance s1^2: the better receiver alone), and falls
    beyond it (the worse receiver then gets a negative weight and cancels the common error).
    Eq 3 ignores the correlation: it claims too small a variance and is worse than the BLUE."""
    rng = np.random.default_rng(4)
    m = 100_000
    previous = 0.0
    for rho in (0.0, 0.3, 0.6, 0.9):
        cov = np.zeros((m, 2, 2, 2))
        cov[:, 0] = np.eye(2) * s1**2
        cov[:, 1] = np.eye(2) * s2**2
        sigma = fusion.joint_covariance(cov, rho)
        assert sigma[0, 0, 2] == pytest.approx(rho * s1 * s2)
        assert sigma[0, 0, 3] == 0.0
        L = np.linalg.cholesky(sigma[0])
        err = (rng.standard_normal((m, 4)) @ L.T).reshape(m, 2, 2)
        blue = fusion.fuse(err, sigma)
        eq3 = fusion.fuse_uncorrelated(err, cov)
        expected = fusion.two_receiver_variance(s1, s2, rho)
        assert blue.cov[0, 0, 0] == pytest.approx(expected, rel=1e-12)
        assert blue.cov[0, 0, 0] <= min(s1, s2) ** 2 + 1e-12
        if s1 == s2 or rho <= s1 / s2:
            assert blue.cov[0, 0, 0] >= previous
        previous = blue.cov[0, 0, 0]
        var_blue = blue.position.var(axis=0).mean()
        var_eq3 = eq3.position.var(axis=0).mean()
        assert var_blue == pytest.approx(expected, rel=0.02)
        claimed_eq3 = s1**2 * s2**2 / (s1**2 + s2**2)
        assert eq3.cov[0, 0, 0] == pytest.approx(claimed_eq3)
        w1 = s2**2 / (s1**2 + s2**2)
        true_eq3 = w1**2 * s1**2 + (1 - w1) ** 2 * s2**2 + 2 * w1 * (1 - w1) * rho * s1 * s2
        assert var_eq3 == pytest.approx(true_eq3, rel=0.02)
        assert true_eq3 >= expected - 1e-12
        if rho > 0:
            assert true_eq3 > claimed_eq3  # eq 3 is overconfident with correlated errors
    if s1 == s2:
        assert previous == pytest.approx(s1**2 * (1 + 0.9) / 2)
    else:
        assert fusion.two_receiver_variance(s1, s2, s1 / s2) == pytest.approx(s1**2)


def test_invalid_receivers_are_removed_exactly() -> None:
    """A receiver without a fix: the result is the BLUE of the others; none: flagged, NaN."""
    rng = np.random.default_rng(5)
    n, k = 30, 3
    S = _random_spd(rng, n, 2 * k)
    fixes = rng.normal(0, 5, (n, k, 2))
    valid = np.ones((n, k), dtype=bool)
    valid[:, 1] = False
    valid[0] = False
    out = fusion.fuse(fixes, S, valid)
    keep = [0, 1, 4, 5]
    sub = fusion.fuse(fixes[:, [0, 2]], S[:, keep][:, :, keep])
    np.testing.assert_allclose(out.position[1:], sub.position[1:], rtol=1e-10)
    np.testing.assert_allclose(out.cov[1:], sub.cov[1:], rtol=1e-10)
    np.testing.assert_array_equal(out.weights[1:, 1], 0.0)
    assert not out.valid[0] and out.valid[1:].all()
    assert np.isnan(out.position[0]).all() and np.isnan(out.cov[0]).all()
    single = fusion.fuse(fixes, S, np.eye(k, dtype=bool)[[0] * n])  # only receiver 0
    np.testing.assert_allclose(single.position, fixes[:, 0], rtol=1e-12)
    np.testing.assert_allclose(single.cov, S[:, :2, :2], rtol=1e-12)


def _local_filters(steps: int, n: int, R: tuple[float, float], q: float, dt: float,
                   rng: np.random.Generator):
    """Two local Kalman filters (1-D constant velocity, position sensors with variances R) on the
    SAME truth: their errors are correlated through the common process noise. Returns the last
    errors (n, 2 filters, 2 states) and the covariances P_11, P_22, P_12 from eq 4."""
    Phi = np.array([[1.0, dt], [0.0, 1.0]])
    Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    H = np.array([[1.0, 0.0]])
    Lq = np.linalg.cholesky(Q)
    truth = np.zeros((n, 2))
    est = np.zeros((2, n, 2))
    P = [np.eye(2) * 100.0, np.eye(2) * 100.0]
    P12 = np.eye(2) * 100.0  # both start from the same prior: fully correlated initial errors
    est[:] = truth + rng.standard_normal((n, 2)) @ np.linalg.cholesky(P[0]).T
    for _ in range(steps):
        truth = truth @ Phi.T + rng.standard_normal((n, 2)) @ Lq.T
        K = []
        for i in range(2):
            Pp = Phi @ P[i] @ Phi.T + Q
            Ki = Pp @ H.T / (H @ Pp @ H.T + R[i])
            z = truth[:, 0] + math.sqrt(R[i]) * rng.standard_normal(n)
            pred = est[i] @ Phi.T
            est[i] = pred + (z - pred[:, 0])[:, None] * Ki[:, 0]
            P[i] = (np.eye(2) - Ki @ H) @ Pp @ (np.eye(2) - Ki @ H).T + R[i] * Ki @ Ki.T
            K.append(Ki)
        P12 = fusion.cross_covariance_step(P12, Phi, Q, K[0], H, K[1], H)
    return np.stack([est[0] - truth, est[1] - truth], axis=1), P[0], P[1], P12


def test_eq_4_cross_covariance_of_local_filters_and_their_fusion() -> None:
    """[seed 003, eq 4] predicts the cross-covariance of two local filters' errors (Monte Carlo
    over 40 000 tracks); fusing the local estimates with the joint covariance [[P11, P12],
    [P21, P22]] gives an error covariance P_f below both, as measured; eq 3 (cross-covariance
    ignored) claims less than it achieves."""
    rng = np.random.default_rng(6)
    n = 40_000
    err, P11, P22, P12 = _local_filters(40, n, (4.0, 9.0), 0.05, 1.0, rng)
    emp12 = err[:, 0].T @ err[:, 1] / n
    np.testing.assert_allclose(emp12, P12, rtol=0.05, atol=0.02 * np.abs(P12).max())
    np.testing.assert_allclose(err[:, 0].T @ err[:, 0] / n, P11, rtol=0.05,
                               atol=0.02 * np.abs(P11).max())
    assert P12[0, 0] > 0.1 * math.sqrt(P11[0, 0] * P22[0, 0])  # clearly correlated
    # fuse the position components of the two local estimates
    S = np.array([[P11[0, 0], P12[0, 0]], [P12[0, 0], P22[0, 0]]])
    sigma = np.zeros((n, 4, 4))
    sigma[:, ::2, ::2] = S  # north components; the east ones are a copy here (decoupled)
    sigma[:, 1::2, 1::2] = S
    fixes = np.stack([err[:, :, 0], err[:, :, 0]], axis=-1)  # (n, 2 filters, 2)
    out = fusion.fuse(fixes, sigma)
    measured = out.position[:, 0].var()
    assert measured == pytest.approx(out.cov[0, 0, 0], rel=0.03)
    assert out.cov[0, 0, 0] < min(P11[0, 0], P22[0, 0])
    cov = np.zeros((n, 2, 2, 2))
    cov[:, 0] = np.eye(2) * P11[0, 0]
    cov[:, 1] = np.eye(2) * P22[0, 0]
    eq3 = fusion.fuse_uncorrelated(fixes, cov)
    assert eq3.cov[0, 0, 0] < out.cov[0, 0, 0]  # claims better than the optimum ...
    assert eq3.position[:, 0].var() > eq3.cov[0, 0, 0] * 1.05  # ... but does not deliver


def test_lever_arm_eq_5_and_heading_error_eq_6_with_the_papers_set_up() -> None:
    """The paper's receivers are 1 m apart (w = [0, 1]) [seed 003, ch 3]. Moving the second
    receiver's fix to the first: at heading 0 the second antenna is 1 m east (starboard) of the
    first, at heading 90 deg 1 m south. A heading error of 1 deg moves the result by
    2 * 1 m * sin(0.5 deg) = 0.01745 m [eq 6]."""
    ref = np.array([1000.0, 2000.0])
    for heading_deg, antenna in ((0.0, (1000.0, 2001.0)), (90.0, (999.0, 2000.0))):
        psi = math.radians(heading_deg)
        n_ref, e_ref = fusion.to_reference_point(np.array(antenna[0]), np.array(antenna[1]),
                                                 np.array(psi), 0.0, -1.0)
        assert n_ref == pytest.approx(ref[0], abs=1e-9)
        assert e_ref == pytest.approx(ref[1], abs=1e-9)
        wrong = fusion.to_reference_point(np.array(antenna[0]), np.array(antenna[1]),
                                          np.array(psi + math.radians(1.0)), 0.0, -1.0)
        shift = math.hypot(wrong[0] - ref[0], wrong[1] - ref[1])
        assert shift == pytest.approx(float(fusion.lever_arm_error_m(0.0, 1.0, math.radians(1))))
    assert float(fusion.lever_arm_error_m(0.0, 1.0, math.radians(1.0))) == pytest.approx(
        0.017453, abs=1e-6)


def test_fuse_receivers_on_board() -> None:
    """Three antennas at different places on board, exact fixes: the fused position is the
    reference point; sigma from the 95 % figures (half of them [seed 003, ch 2])."""
    params = fusion.build([
        {"receivers": [{"error95_m": 6.0, "offset_x_m": -10.0, "offset_y_m": 2.0},
                       {"sigma_m": 5.0, "offset_x_m": 20.0},
                       {"error95_m": 20.0, "offset_y_m": -3.0}], "correlation": 0.4},
        {"receivers": [{}]},
    ])
    np.testing.assert_allclose(params.sigma_m[0], [3.0, 5.0, 10.0])
    assert params.present.tolist() == [[True, True, True], [True, False, False]]
    assert params.sigma_m[1, 0] == fusion.RECEIVER_DEFAULTS["sigma_m"]
    psi = np.array([math.radians(35.0), math.radians(200.0)])
    ref = np.array([[500.0, -300.0], [10.0, 20.0]])
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    # antenna = reference - R(psi) w (w = antenna -> reference, body frame)
    ant_n = ref[:, :1] - (params.offset_x_m * c - params.offset_y_m * s)
    ant_e = ref[:, 1:] - (params.offset_y_m * c + params.offset_x_m * s)
    out = fusion.fuse_receivers(params, ant_n, ant_e, psi, np.ones((2, 3), dtype=bool))
    np.testing.assert_allclose(out.position, ref, atol=1e-9)
    assert out.valid.all()
    assert out.cov[1, 0, 0] == pytest.approx(25.0)
    assert out.cov[0, 0, 0] < 9.0
    with pytest.raises(ValueError, match="correlation"):
        fusion.build([{"correlation": 1.0}])
    with pytest.raises(ValueError, match="unknown receiver"):
        fusion.build([{"receivers": [{"sigma": 1.0}]}])


def test_joint_covariance_is_positive_definite_and_structured() -> None:
    rng = np.random.default_rng(7)
    n, k = 20, 3
    cov = _random_spd(rng, n * k, 2, 3.0).reshape(n, k, 2, 2)
    S = fusion.joint_covariance(cov, rng.uniform(0, 0.95, n))
    assert np.all(_min_eig(S) > 0)
    for i in range(k):
        np.testing.assert_allclose(S[:, 2 * i:2 * i + 2, 2 * i:2 * i + 2], cov[:, i], rtol=1e-12)
    np.testing.assert_allclose(S, S.transpose(0, 2, 1))


def test_fused_position_and_weights_equal_the_gls_closed_form() -> None:
    """With cross-covariances: x_f = (E^T S^-1 E)^-1 E^T S^-1 z by explicit inverses, weights
    [A_1 .. A_k] = P_f E^T S^-1 summing to I; NaN fixes and NaN covariance entries of invalid
    receivers change nothing (the result is the GLS of the valid ones)."""
    rng = np.random.default_rng(81)
    n, k = 40, 3
    S = _random_spd(rng, n, 2 * k, 3.0)
    z = rng.normal(0, 20, (n, k, 2))
    valid = rng.random((n, k)) < 0.7
    valid[:, 0] = True
    zz = np.where(valid[:, :, None], z, np.nan)
    v2 = np.repeat(valid, 2, axis=1)
    SS = np.where(v2[:, :, None] & v2[:, None, :], S, np.nan)
    out = fusion.fuse(zz, SS, valid)
    for i in range(n):
        sel = np.flatnonzero(v2[i])
        Si = np.linalg.inv(S[i][np.ix_(sel, sel)])
        E = np.tile(np.eye(2), (sel.size // 2, 1))
        Pf = np.linalg.inv(E.T @ Si @ E)
        W = Pf @ E.T @ Si
        np.testing.assert_allclose(out.cov[i], Pf, rtol=1e-9)
        np.testing.assert_allclose(out.position[i], W @ z[i][valid[i]].ravel(), rtol=1e-9,
                                   atol=1e-9)
        np.testing.assert_allclose(out.weights[i][valid[i]].transpose(1, 0, 2).reshape(2, -1),
                                   W, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out.weights.sum(axis=1), np.broadcast_to(np.eye(2), (n, 2, 2)),
                               atol=1e-12)
    assert np.all(np.isfinite(out.position)) and out.valid.all()


def test_fuse_uncorrelated_ignores_nan_in_invalid_slots() -> None:
    rng = np.random.default_rng(82)
    n, k = 20, 3
    cov = _random_spd(rng, n * k, 2, 4.0).reshape(n, k, 2, 2)
    z = rng.normal(0, 10, (n, k, 2))
    valid = np.ones((n, k), dtype=bool)
    valid[:, 2] = False
    cov_nan, z_nan = cov.copy(), z.copy()
    cov_nan[:, 2], z_nan[:, 2] = np.nan, np.nan
    a = fusion.fuse_uncorrelated(z_nan, cov_nan, valid)
    b = fusion.fuse_uncorrelated(z[:, :2], cov[:, :2])
    np.testing.assert_allclose(a.position, b.position, rtol=1e-12)
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-12)
    np.testing.assert_array_equal(a.weights[:, 2], 0.0)


def test_eq_4_with_i_equal_j_plus_k_r_k_is_the_joseph_covariance() -> None:
    """[seed 003, eq 4] for i = j plus K R K^T equals the textbook Joseph update of the
    predicted covariance, for any gain (optimal or not): checked on random 4-state filters."""
    rng = np.random.default_rng(83)
    n = 10
    P = _random_spd(rng, n, 4)
    Phi = np.eye(4) + rng.normal(0, 0.2, (n, 4, 4))
    Q = _random_spd(rng, n, 4, 0.1)
    H = rng.normal(0, 1, (n, 2, 4))
    R = _random_spd(rng, n, 2)
    K = rng.normal(0, 0.3, (n, 4, 2))
    got = fusion.cross_covariance_step(P, Phi, Q, K, H, K, H) + K @ R @ K.transpose(0, 2, 1)
    for i in range(n):
        M = Phi[i] @ P[i] @ Phi[i].T + Q[i]
        A = np.eye(4) - K[i] @ H[i]
        np.testing.assert_allclose(got[i], A @ M @ A.T + K[i] @ R[i] @ K[i].T, rtol=1e-10)
    # with the optimal gain this is the covariance of the local filter
    M = Phi @ P @ Phi.transpose(0, 2, 1) + Q
    Kopt = M @ H.transpose(0, 2, 1) @ np.linalg.inv(H @ M @ H.transpose(0, 2, 1) + R)
    joseph = fusion.cross_covariance_step(P, Phi, Q, Kopt, H, Kopt, H) + \
        Kopt @ R @ Kopt.transpose(0, 2, 1)
    np.testing.assert_allclose(joseph, M - Kopt @ H @ M, rtol=1e-8, atol=1e-10)


def test_single_receiver_and_empty_batch() -> None:
    """k = 1: the fused fix is the fix and P_f its covariance; n = 0 gives empty results."""
    rng = np.random.default_rng(84)
    S = _random_spd(rng, 5, 2)
    z = rng.normal(0, 10, (5, 1, 2))
    out = fusion.fuse(z, S)
    np.testing.assert_allclose(out.position, z[:, 0], rtol=1e-12)
    np.testing.assert_allclose(out.cov, S, rtol=1e-12)
    np.testing.assert_allclose(out.weights[:, 0], np.broadcast_to(np.eye(2), (5, 2, 2)),
                               atol=1e-12)
    empty = fusion.fuse(np.zeros((0, 2, 2)), np.zeros((0, 4, 4)))
    assert empty.position.shape == (0, 2) and empty.valid.shape == (0,)


def test_reference_point_round_trip_and_full_turn() -> None:
    """Moving antenna -> reference with w and back with -w is the identity; a heading of
    2 pi moves the fix exactly as 0 does; the move keeps the lever-arm length |w|."""
    rng = np.random.default_rng(85)
    n = 50
    north, east = rng.normal(0, 1e3, n), rng.normal(0, 1e3, n)
    psi = rng.uniform(0, 2 * np.pi, n)
    wx, wy = rng.normal(0, 30, n), rng.normal(0, 5, n)
    rn, re = fusion.to_reference_point(north, east, psi, wx, wy)
    np.testing.assert_allclose(np.hypot(rn - north, re - east), np.hypot(wx, wy), rtol=1e-12)
    bn, be = fusion.to_reference_point(rn, re, psi, -wx, -wy)
    np.testing.assert_allclose(bn, north, atol=1e-9)
    np.testing.assert_allclose(be, east, atol=1e-9)
    a = fusion.to_reference_point(north, east, np.zeros(n), wx, wy)
    b = fusion.to_reference_point(north, east, np.full(n, 2 * np.pi), wx, wy)
    np.testing.assert_allclose(a, b, atol=1e-9)


def test_joint_covariance_accepts_a_correlation_matrix() -> None:
    """An (n, k, k) correlation matrix with equal off-diagonals equals the scalar form; an
    unequal one puts rho_ij s_i s_j in block (i, j) for isotropic receivers."""
    n, k = 2, 3
    cov = np.zeros((n, k, 2, 2))
    sig = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    cov[..., 0, 0] = cov[..., 1, 1] = sig**2
    rho = np.full((n, k, k), 0.3)
    rho[:, np.arange(k), np.arange(k)] = 1.0
    np.testing.assert_allclose(fusion.joint_covariance(cov, rho),
                               fusion.joint_covariance(cov, 0.3))
    rho[:, 0, 2] = rho[:, 2, 0] = 0.7
    S = fusion.joint_covariance(cov, rho)
    np.testing.assert_allclose(S[:, 0:2, 4:6], 0.7 * (sig[:, 0] * sig[:, 2])[:, None, None]
                               * np.eye(2))
    np.testing.assert_allclose(S[:, 2:4, 4:6], 0.3 * (sig[:, 1] * sig[:, 2])[:, None, None]
                               * np.eye(2))


@pytest.mark.parametrize("cfg", [{"receivers": [{"sigma_m": float("nan")}]},
                                 {"receivers": [{"error95_m": float("nan")}]},
                                 {"correlation": float("nan")}])
def test_build_rejects_nan(cfg) -> None:
    with pytest.raises(ValueError):
        fusion.build([cfg])


def _random_joint(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """Joint covariances ``(n, 2k, 2k)`` of anisotropic receivers with a random correlation
    matrix (a Gram matrix of unit vectors, so positive definite)."""
    cov = np.empty((n, k, 2, 2))
    for i in range(n):
        for j in range(k):
            a = rng.normal(0.0, 2.0, (2, 2))
            cov[i, j] = a @ a.T + 0.5 * np.eye(2)
    v = rng.normal(size=(n, k, k + 2))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    rho = np.einsum("nik,njk->nij", v, v)
    return fusion.joint_covariance(cov, rho)


def test_fused_covariance_is_the_actual_error_covariance_and_below_each_receiver() -> None:
    """For correlated anisotropic receivers, sum_ij A_i Sigma_ij A_j^T (the actual covariance of
    the weighted mean) equals the reported P_f, and P_f <= P_ii in the Loewner order for every
    receiver; the eq-3 weights achieve a covariance at least P_f."""
    rng = np.random.default_rng(13)
    n, k = 20, 3
    sigma = _random_joint(rng, n, k)
    out = fusion.fuse(np.zeros((n, k, 2)), sigma)
    A = np.concatenate(list(np.moveaxis(out.weights, 1, 0)), axis=-1)  # (n, 2, 2k)
    actual = A @ sigma @ np.swapaxes(A, -1, -2)
    np.testing.assert_allclose(actual, out.cov, rtol=1e-9, atol=1e-12)
    for i in range(k):
        pii = sigma[:, 2 * i:2 * i + 2, 2 * i:2 * i + 2]
        assert np.linalg.eigvalsh(pii - out.cov).min() > -1e-9
    cov = np.stack([sigma[:, 2 * i:2 * i + 2, 2 * i:2 * i + 2] for i in range(k)], axis=1)
    eq3 = fusion.fuse_uncorrelated(np.zeros((n, k, 2)), cov)
    B = np.concatenate(list(np.moveaxis(eq3.weights, 1, 0)), axis=-1)
    eq3_actual = B @ sigma @ np.swapaxes(B, -1, -2)
    assert np.linalg.eigvalsh(eq3_actual - out.cov).min() > -1e-9


def test_blue_weights_beat_any_other_unbiased_weights() -> None:
    """Perturbing the weights by matrices that sum to zero (so they still sum to I) never lowers
    the trace of the actual error covariance: the weights minimise it [seed 003, ch 2]."""
    rng = np.random.default_rng(3)
    sigma = _random_joint(rng, 1, 3)[0]
    out = fusion.fuse(np.zeros((1, 3, 2)), sigma[None])
    W = out.weights[0]
    np.testing.assert_allclose(W.sum(axis=0), np.eye(2), atol=1e-12)
    best = np.trace(out.cov[0])
    for _ in range(200):
        d = rng.normal(0.0, 0.05, (3, 2, 2))
        d -= d.mean(axis=0)
        A = np.concatenate(list(W + d), axis=-1)
        assert np.trace(A @ sigma @ A.T) >= best - 1e-12


def test_vectorised_fusion_with_mixed_valid_equals_each_ship_with_its_valid_receivers() -> None:
    """Ships fused together with different invalid slots (NaN fixes there) equal each ship fused
    alone from the sub-matrix of Sigma of its valid receivers; a ship with none is NaN."""
    rng = np.random.default_rng(17)
    n, k = 5, 3
    sigma = _random_joint(rng, n, k)
    fixes = rng.normal(100.0, 10.0, (n, k, 2))
    valid = np.array([[1, 1, 1], [1, 0, 1], [0, 0, 1], [0, 1, 1], [0, 0, 0]], dtype=bool)
    fixes[~valid] = np.nan
    out = fusion.fuse(fixes, sigma, valid)
    for i in range(n - 1):
        idx = np.flatnonzero(np.repeat(valid[i], 2))
        alone = fusion.fuse(fixes[i:i + 1, valid[i]], sigma[i:i + 1][:, idx][:, :, idx])
        np.testing.assert_allclose(out.position[i], alone.position[0], rtol=1e-10)
        np.testing.assert_allclose(out.cov[i], alone.cov[0], rtol=1e-10)
        np.testing.assert_allclose(out.weights[i, valid[i]], alone.weights[0], atol=1e-12)
        assert np.all(out.weights[i, ~valid[i]] == 0.0)
    assert not out.valid[-1] and np.all(np.isnan(out.position[-1]))
    assert out.valid[:-1].all()


def test_identical_fixes_fuse_to_themselves_whatever_the_covariance() -> None:
    """The weights sum to I, so k equal fixes fuse to that fix (unbiasedness), for both the BLUE
    and eq 3."""
    rng = np.random.default_rng(23)
    sigma = _random_joint(rng, 4, 3)
    fix = rng.normal(0.0, 500.0, (4, 1, 2))
    fixes = np.repeat(fix, 3, axis=1)
    np.testing.assert_allclose(fusion.fuse(fixes, sigma).position, fix[:, 0], rtol=1e-9)
    cov = np.stack([sigma[:, 2 * i:2 * i + 2, 2 * i:2 * i + 2] for i in range(3)], axis=1)
    np.testing.assert_allclose(fusion.fuse_uncorrelated(fixes, cov).position, fix[:, 0],
                               rtol=1e-9)


def test_monte_carlo_fused_error_matches_the_reported_covariance() -> None:
    """Fixes with errors drawn from Sigma: the sample covariance of the fused error is P_f
    (about 3 % at 40 000 draws), and below the best single receiver's."""
    rng = np.random.default_rng(29)
    sigma1 = _random_joint(rng, 1, 3)[0]
    n = 40_000
    err = rng.multivariate_normal(np.zeros(6), sigma1, n).reshape(n, 3, 2)
    out = fusion.fuse(err, np.broadcast_to(sigma1, (n, 6, 6)))
    emp = out.position.T @ out.position / n
    np.testing.assert_allclose(emp, out.cov[0], rtol=0.05, atol=0.03 * out.cov[0, 0, 0])
    single = min(np.trace(sigma1[2 * i:2 * i + 2, 2 * i:2 * i + 2]) for i in range(3))
    assert np.trace(emp) < single


def test_build_error95_unknown_keys_and_missing_receivers() -> None:
    """error95_m gives sigma = half [seed 003, ch 2]; sigma_m wins over it; unknown receiver keys
    and non-positive sigma are refused; a ship without receivers has one at the reference."""
    p = fusion.build([{"receivers": [{"error95_m": 8.0}, {"sigma_m": 1.5, "error95_m": 8.0}]},
                      {}])
    np.testing.assert_allclose(p.sigma_m[0], [4.0, 1.5])
    assert p.present.tolist() == [[True, True], [True, False]]
    assert p.offset_x_m[1, 0] == 0.0 and p.correlation.tolist() == [0.0, 0.0]
    with pytest.raises(ValueError, match="sigmam"):
        fusion.build([{"receivers": [{"sigmam": 2.0}]}])
    with pytest.raises(ValueError, match="sigma_m"):
        fusion.build([{"receivers": [{"error95_m": 0.0}]}])
    with pytest.raises(ValueError, match="correlation"):
        fusion.build([{"correlation": 1.0}])
