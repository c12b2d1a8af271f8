"""Matrix exponential and Van Loan discretisation in compiled loops over a stack of matrices
(the EKF's transition and process noise [seed 002, ch 4.4]; Van Loan 1978)."""

from __future__ import annotations

import math
from decimal import Decimal, getcontext

import numpy as np
import pytest

from trafficsim.estimation import linalg


def test_expm_stack_exact_cases() -> None:
    """Zero, diagonal, nilpotent and rotation generators (norms 1e-3 .. 300: every Pade degree
    and the scaling and squaring), and exp(A) exp(-A) = I."""
    M = np.zeros((6, 2, 2))
    M[1] = np.diag([0.3, -2.0])
    M[2] = [[0.0, 7.5], [0.0, 0.0]]
    for k, w in zip(range(3, 6), (1e-3, 3.0, 300.0), strict=True):
        M[k] = [[0.0, -w], [w, 0.0]]
    E = linalg.expm_stack(M)
    np.testing.assert_allclose(E[0], np.eye(2), atol=1e-15)
    np.testing.assert_allclose(E[1], np.diag(np.exp([0.3, -2.0])), rtol=1e-14)
    np.testing.assert_allclose(E[2], [[1.0, 7.5], [0.0, 1.0]], rtol=1e-14)
    for k, w in zip(range(3, 6), (1e-3, 3.0, 300.0), strict=True):
        c, s = math.cos(w), math.sin(w)
        np.testing.assert_allclose(E[k], [[c, -s], [s, c]], atol=1e-12 * max(1.0, w))
    rng = np.random.default_rng(0)
    A = rng.standard_normal((50, 8, 8)) * rng.uniform(0.01, 2.0, (50, 1, 1))
    Ep, Em = linalg.expm_stack(A), linalg.expm_stack(-A)
    cond = np.abs(Ep).max(axis=(1, 2)) * np.abs(Em).max(axis=(1, 2))  # rounding scale
    err = np.abs(Ep @ Em - np.eye(8)).max(axis=(1, 2))
    assert np.all(err < 1e-13 * cond)


def test_expm_stack_matches_scipy() -> None:
    sl = pytest.importorskip("scipy.linalg")
    rng = np.random.default_rng(1)
    for scale in (1e-3, 0.1, 1.0, 5.0, 50.0):
        M = rng.standard_normal((40, 8, 8)) * scale / 8
        ref = np.stack([sl.expm(m) for m in M])
        err = np.abs(linalg.expm_stack(M) - ref).max(axis=(1, 2)) / np.abs(ref).max(axis=(1, 2))
        assert err.max() < 1e-12, scale


def test_van_loan_closed_forms() -> None:
    """Scalar Ornstein-Uhlenbeck and the white-acceleration double integrator (exact Qd)."""
    dt = 1.7
    a, q = 0.35, 2.0
    A, Qd = linalg.van_loan(np.full((1, 1, 1), -a), np.full((1, 1, 1), q), dt)
    assert A[0, 0, 0] == pytest.approx(math.exp(-a * dt), rel=1e-14)
    assert Qd[0, 0, 0] == pytest.approx(q * (1 - math.exp(-2 * a * dt)) / (2 * a), rel=1e-13)
    F = np.array([[[0.0, 1.0], [0.0, 0.0]]])
    Qc = np.array([[[0.0, 0.0], [0.0, q]]])
    A, Qd = linalg.van_loan(F, Qc, dt)
    np.testing.assert_allclose(A[0], [[1.0, dt], [0.0, 1.0]], rtol=1e-14)
    np.testing.assert_allclose(Qd[0], q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]),
                               rtol=1e-13)


def test_block_van_loan_equals_the_full_block_exponential() -> None:
    """The block-wise evaluation for 8 states = the 16x16 exponential of Van Loan's matrix,
    including a process noise 1e-12 times F (relative accuracy kept, no balancing needed)."""
    rng = np.random.default_rng(2)
    n = 60
    F = rng.standard_normal((n, 8, 8)) * rng.uniform(0.01, 3.0, (n, 1, 1))
    L = rng.standard_normal((n, 8, 8))
    Qc = L @ L.transpose(0, 2, 1) * rng.choice([1e-12, 1e-4, 1.0], (n, 1, 1))
    dt = 1.3
    A, Qd = linalg.van_loan(F, Qc, dt)
    M = np.zeros((n, 16, 16))
    M[:, :8, :8] = -F * dt
    M[:, :8, 8:] = Qc * dt
    M[:, 8:, 8:] = F.transpose(0, 2, 1) * dt
    E = linalg.expm_stack(M)
    A_ref = E[:, 8:, 8:].transpose(0, 2, 1)
    Qd_ref = A_ref @ E[:, :8, 8:]
    scale_a = np.abs(A_ref).max(axis=(1, 2))
    scale_q = np.abs(Qd_ref).max(axis=(1, 2))
    assert (np.abs(A - A_ref).max(axis=(1, 2)) / scale_a).max() < 1e-11
    assert (np.abs(Qd - Qd_ref).max(axis=(1, 2)) / scale_q).max() < 1e-9
    np.testing.assert_allclose(Qd, Qd.transpose(0, 2, 1), rtol=0, atol=1e-15 * scale_q.max())


# --- reference values from scipy, closed forms and algebraic identities ---------------------

def _rel_err(a: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Largest entry error of each matrix relative to its largest reference entry."""
    return np.abs(a - ref).max(axis=(-2, -1)) / np.abs(ref).max(axis=(-2, -1))


@pytest.mark.parametrize("k", [1, 2, 3, 5, 8, 12])
def test_expm_stack_matches_scipy_for_every_size(k: int) -> None:
    """The 8x8 product kernel and the general loop alike: random matrices of norms 0.01..20
    (every Pade degree, with and without squarings) agree with scipy's expm."""
    sl = pytest.importorskip("scipy.linalg")
    rng = np.random.default_rng(10 + k)
    M = rng.standard_normal((30, k, k)) * rng.uniform(0.01, 20.0, (30, 1, 1)) / math.sqrt(k)
    ref = np.stack([sl.expm(m) for m in M])
    assert _rel_err(linalg.expm_stack(M), ref).max() < 1e-11


def test_expm_stack_at_the_pade_degree_thresholds() -> None:
    """1-norms a hair below and above every threshold of Higham's table (degree 3..13) and the
    first scaling boundaries theta13 * 2^s agree with scipy, and across each threshold
    exp((1 + e) X) = exp((1 - e) X) exp(2 e X) (commuting) holds to rounding: no jump where the
    degree or the number of squarings changes."""
    sl = pytest.importorskip("scipy.linalg")
    rng = np.random.default_rng(11)
    base = rng.standard_normal((5, 5))
    base /= np.abs(base).sum(axis=0).max()  # 1-norm 1
    norms = [t * f for t in [*linalg._THETA, linalg._THETA[4] * 2, linalg._THETA[4] * 8]
             for f in (1 - 1e-9, 1 + 1e-9)]
    M = np.stack([base * v for v in norms])
    np.testing.assert_allclose(np.abs(M).sum(axis=1).max(axis=1), norms, rtol=1e-14)
    E = linalg.expm_stack(M)
    ref = np.stack([sl.expm(m) for m in M])
    assert _rel_err(E, ref).max() < 1e-13
    below, above = E[0::2], E[1::2]
    step = 2e-9 * M[0::2] / (1 - 1e-9)
    assert _rel_err(above, below @ (np.eye(5) + step + step @ step / 2)).max() < 1e-13


def _expm_decimal(M: np.ndarray, squarings: int = 12, terms: int = 40) -> np.ndarray:
    """exp(M) in 60-digit decimal arithmetic: Taylor series of M / 2^s, squared s times."""
    getcontext().prec = 60
    k = M.shape[0]
    A = [[Decimal(float(v)) / Decimal(2) ** squarings for v in row] for row in M]

    def mul(X: list, Y: list) -> list:
        return [[sum(X[i][m] * Y[m][j] for m in range(k)) for j in range(k)] for i in range(k)]

    E = [[Decimal(int(i == j)) for j in range(k)] for i in range(k)]
    T = [row[:] for row in E]
    for n in range(1, terms):
        T = [[t / n for t in row] for row in mul(T, A)]
        E = [[E[i][j] + T[i][j] for j in range(k)] for i in range(k)]
    for _ in range(squarings):
        E = mul(E, E)
    return np.array([[float(v) for v in row] for row in E])


def test_expm_stack_against_high_precision_arithmetic() -> None:
    """3x3 matrices of 1-norm 0.1..40 against a 60-digit Taylor/squaring reference: within a
    few units of rounding of the result's largest entry (tighter than scipy's own 5e-13 on
    some of these)."""
    rng = np.random.default_rng(18)
    M = rng.standard_normal((12, 3, 3)) * np.geomspace(0.05, 15.0, 12)[:, None, None]
    E = linalg.expm_stack(M)
    for i in range(M.shape[0]):
        assert _rel_err(E[i], _expm_decimal(M[i])) < 2e-14, i


@pytest.mark.parametrize("b", [1.0, 1e3, 1e6])
def test_expm_stack_of_a_non_normal_triangular_matrix(b: float) -> None:
    """exp([[a, b], [0, c]]) = [[e^a, b (e^a - e^c) / (a - c)], [0, e^c]] (divided difference):
    a coupling up to 1e6 (1-norm 1e6: 18 squarings) keeps the diagonal to rounding relative to
    the norm of the result and the coupling to 1e-10 (the squarings of a non-normal matrix
    cost digits)."""
    a, c = -1.0, -2.5
    E = linalg.expm_stack(np.array([[[a, b], [0.0, c]]]))[0]
    exact = np.array([[math.exp(a), b * (math.exp(a) - math.exp(c)) / (a - c)],
                      [0.0, math.exp(c)]])
    assert E[1, 0] == 0.0
    np.testing.assert_allclose(np.diag(E), np.diag(exact), rtol=0,
                               atol=1e-15 * np.abs(exact).max())
    assert E[0, 1] == pytest.approx(exact[0, 1], rel=1e-10)


def test_expm_stack_identities() -> None:
    """det exp(A) = exp(tr A); exp(A^T) = exp(A)^T; exp(2A) = exp(A)^2; exp(S A S^-1) =
    S exp(A) S^-1; a block-diagonal matrix exponentiates block by block."""
    rng = np.random.default_rng(12)
    A = rng.standard_normal((20, 4, 4)) * rng.uniform(0.05, 2.0, (20, 1, 1))
    E = linalg.expm_stack(A)
    np.testing.assert_allclose(np.linalg.det(E), np.exp(np.trace(A, axis1=1, axis2=2)),
                               rtol=1e-12)
    np.testing.assert_allclose(linalg.expm_stack(A.transpose(0, 2, 1)), E.transpose(0, 2, 1),
                               rtol=1e-12, atol=1e-14)
    assert _rel_err(linalg.expm_stack(2 * A), E @ E).max() < 1e-12
    S = rng.standard_normal((20, 4, 4)) + 3 * np.eye(4)
    Si = np.linalg.inv(S)
    assert _rel_err(linalg.expm_stack(S @ A @ Si), S @ E @ Si).max() < 1e-11
    B = np.zeros((20, 8, 8))
    B[:, :4, :4], B[:, 4:, 4:] = A, -A
    EB = linalg.expm_stack(B)
    assert _rel_err(EB[:, :4, :4], E).max() < 1e-13
    assert _rel_err(EB[:, 4:, 4:], linalg.expm_stack(-A)).max() < 1e-13
    assert np.all(EB[:, :4, 4:] == 0.0) and np.all(EB[:, 4:, :4] == 0.0)


def test_expm_stack_each_matrix_independent_of_the_stack() -> None:
    """The compiled loop reuses one workspace: every matrix's result is bit-identical alone, in
    the stack and in the reversed stack (small and large norms mixed, so a smaller degree
    follows a larger one); the input is left as it was; integer and non-contiguous input."""
    rng = np.random.default_rng(13)
    M = rng.standard_normal((12, 8, 8)) * np.array([1e-3, 30.0] * 6)[:, None, None]
    keep = M.copy()
    E = linalg.expm_stack(M)
    np.testing.assert_array_equal(M, keep)
    np.testing.assert_array_equal(linalg.expm_stack(M[::-1])[::-1], E)
    for i in (0, 1, 11):
        np.testing.assert_array_equal(linalg.expm_stack(M[i:i + 1])[0], E[i])
    np.testing.assert_array_equal(linalg.expm_stack(M.transpose(0, 2, 1)),
                                  linalg.expm_stack(np.ascontiguousarray(M.transpose(0, 2, 1))))
    rot = np.array([[[0, 1], [-1, 0]]])
    np.testing.assert_allclose(linalg.expm_stack(rot)[0],
                               [[math.cos(1), math.sin(1)], [-math.sin(1), math.cos(1)]],
                               rtol=1e-14)
    assert linalg.expm_stack(np.zeros((0, 3, 3))).shape == (0, 3, 3)


def test_expm_stack_nan_matrix_stays_its_own() -> None:
    """A NaN entry makes that matrix's exponential NaN and leaves its neighbours exact."""
    M = np.zeros((3, 2, 2))
    M[0] = M[2] = [[0.0, 1.0], [0.0, 0.0]]
    M[1, 0, 0] = np.nan
    E = linalg.expm_stack(M)
    assert np.isnan(E[1]).all()
    np.testing.assert_array_equal(E[0], [[1.0, 1.0], [0.0, 1.0]])
    np.testing.assert_array_equal(E[2], E[0])


def test_expm_stack_inf_matrix_stays_its_own() -> None:
    """Like NaN: an infinite entry gives a non-finite exponential for that matrix only."""
    M = np.zeros((3, 2, 2))
    M[1, 0, 1] = np.inf
    E = linalg.expm_stack(M)
    assert not np.isfinite(E[1]).all()
    np.testing.assert_array_equal(E[0], np.eye(2))
    np.testing.assert_array_equal(E[2], np.eye(2))


@pytest.mark.parametrize("k", [3, 8])
@pytest.mark.parametrize("acc", [False, True])
@pytest.mark.parametrize("trans_b", [False, True])
def test_mm_matches_numpy(k: int, acc: bool, trans_b: bool) -> None:
    """out = alpha A op(B) (+ out): the unrolled 8x8 kernel (which skips zero entries of A)
    and the general loop against numpy, with zero rows and columns in A as in the filter."""
    rng = np.random.default_rng(14)
    A, B, C = rng.standard_normal((3, k, k))
    A[1, :] = 0.0
    A[:, 2] = 0.0
    out = C.copy()
    linalg._mm(A, B, out, -0.7, acc, trans_b)
    ref = -0.7 * A @ (B.T if trans_b else B) + (C if acc else 0.0)
    np.testing.assert_allclose(out, ref, rtol=1e-13, atol=1e-14)
    if not acc:
        assert np.all(out[1] == 0.0)


def _hilbert(k: int) -> np.ndarray:
    i = np.arange(k)
    return 1.0 / (i[:, None] + i[None, :] + 1.0)


def test_lu_factors_reconstruct_the_permuted_matrix() -> None:
    """Partial pivoting: L (unit lower) U = rows ``piv`` of A, |L| <= 1, ``piv`` a permutation;
    a zero leading pivot (a permutation matrix) needs the row swap."""
    rng = np.random.default_rng(15)
    for A in (rng.standard_normal((6, 6)), np.array([[0.0, 1.0], [1.0, 0.0]]), _hilbert(5)):
        k = A.shape[0]
        LU = A.copy()
        piv = np.empty(k, dtype=np.int64)
        linalg._lu_inplace(LU, piv)
        L = np.tril(LU, -1) + np.eye(k)
        U = np.triu(LU)
        assert sorted(piv) == list(range(k))
        assert np.abs(L).max() <= 1.0
        np.testing.assert_allclose(L @ U, A[piv], rtol=0, atol=1e-14 * np.abs(A).max())


@pytest.mark.parametrize("k, nr", [(1, 1), (4, 1), (6, 6), (8, 3), (8, 8)])
def test_solve_inplace_matches_numpy(k: int, nr: int) -> None:
    """B <- A^-1 B for random systems (several right-hand sides) agrees with numpy.linalg.solve;
    on the ill-conditioned Hilbert matrix (cond ~ 1e7 .. 1e10) the residual stays at rounding."""
    rng = np.random.default_rng(16 + k)
    A = rng.standard_normal((k, k)) + 0.5 * np.eye(k)
    B = rng.standard_normal((k, nr))
    X = B.copy()
    linalg._solve_inplace(A.copy(), X)
    np.testing.assert_allclose(X, np.linalg.solve(A, B), rtol=1e-10, atol=1e-12)
    H = _hilbert(min(k, 7))
    Bh = B[: H.shape[0]]
    Xh = Bh.copy()
    linalg._solve_inplace(H.copy(), Xh)
    resid = np.abs(H @ Xh - Bh).max()
    assert resid < 1e-14 * np.abs(H).max() * np.abs(Xh).max() * H.shape[0] ** 2


def test_balance_is_an_exact_power_of_two_similarity() -> None:
    """G <- D^-1 G D bit for bit with D = diag(d) of powers of two, the diagonal untouched;
    a badly scaled matrix gets its off-diagonal row+column norms far closer; a matrix with a
    zero row (the filter's position states) leaves that state unscaled."""
    rng = np.random.default_rng(17)
    k = 6
    s = 10.0 ** rng.uniform(-4, 4, k)
    G0 = rng.standard_normal((k, k)) * s[:, None] / s[None, :]
    G = G0.copy()
    d = np.empty(k)
    linalg._balance(G, d)
    mant, _ = np.frexp(d)
    np.testing.assert_array_equal(mant, 0.5)
    np.testing.assert_array_equal(G, G0 * d[None, :] / d[:, None])
    np.testing.assert_array_equal(np.diag(G), np.diag(G0))

    def spread(M: np.ndarray) -> float:
        off = np.abs(M - np.diag(np.diag(M)))
        return float(off.sum(axis=0).max() + off.sum(axis=1).max())

    assert spread(G) < 1e-3 * spread(G0)
    Z = G0.copy()
    Z[2] = 0.0
    d = np.empty(k)
    linalg._balance(Z, d)
    assert d[2] == 1.0


def _van_loan_ref(F: np.ndarray, Qc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Van Loan (1978) with scipy's expm of the full 2k x 2k matrix."""
    sl = pytest.importorskip("scipy.linalg")
    k = F.shape[0]
    M = np.zeros((2 * k, 2 * k))
    M[:k, :k], M[:k, k:], M[k:, k:] = -F * dt, Qc * dt, F.T * dt
    E = sl.expm(M)
    A = E[k:, k:].T
    return A, A @ E[:k, k:]


@pytest.mark.parametrize("k", [1, 2, 3, 5, 8, 10])
def test_van_loan_matches_scipy_for_badly_scaled_systems(k: int) -> None:
    """States of scales 1e-2..1e2 apart (the balancing's case) and a random SPD Qc: A and Qd
    agree with scipy's exponential of Van Loan's full matrix and A with expm(F dt)."""
    sl = pytest.importorskip("scipy.linalg")
    rng = np.random.default_rng(20 + k)
    n, dt = 12, 0.7
    D = 10.0 ** rng.uniform(-2, 2, (n, k))
    F = 0.3 * rng.standard_normal((n, k, k)) * D[:, :, None] / D[:, None, :]
    L = rng.standard_normal((n, k, k))
    Qc = L @ L.transpose(0, 2, 1)
    A, Qd = linalg.van_loan(F, Qc, dt)
    for i in range(n):
        A_ref, Qd_ref = _van_loan_ref(F[i], Qc[i], dt)
        assert _rel_err(A[i], A_ref) < 1e-10
        assert _rel_err(A[i], sl.expm(F[i] * dt)) < 1e-10
        assert _rel_err(Qd[i], Qd_ref) < 1e-10


def test_van_loan_of_a_diagonal_system_in_closed_form() -> None:
    """F = diag(f): A = diag(exp(f dt)), Qd_ij = Qc_ij (exp((f_i + f_j) dt) - 1) / (f_i + f_j)
    (Qc_ij dt where f_i + f_j = 0), with zero rows (integrator states) and f_i = -f_j."""
    f = np.array([0.0, -0.4, 0.4, -3.0, 0.0, 1.2])
    k = f.size
    rng = np.random.default_rng(21)
    L = rng.standard_normal((k, k))
    Qc = L @ L.T
    dt = 2.3
    A, Qd = linalg.van_loan(np.diag(f)[None], Qc[None], dt)
    np.testing.assert_allclose(A[0], np.diag(np.exp(f * dt)), rtol=1e-14, atol=1e-15)
    s = f[:, None] + f[None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        gain = np.where(s == 0.0, dt, np.expm1(s * dt) / s)
    np.testing.assert_allclose(Qd[0], Qc * gain, rtol=1e-12)


def test_van_loan_semigroup_linearity_and_symmetry() -> None:
    """Two steps of dt are one of 2 dt: A(2dt) = A(dt)^2, Qd(2dt) = Qd(dt) + A Qd(dt) A^T;
    Qd is linear in Qc, exactly symmetric and positive semi-definite."""
    rng = np.random.default_rng(22)
    n, k, dt = 15, 8, 0.9
    F = rng.standard_normal((n, k, k)) * rng.uniform(0.05, 2.0, (n, 1, 1))
    L1, L2 = rng.standard_normal((2, n, k, k))
    Q1, Q2 = L1 @ L1.transpose(0, 2, 1), L2 @ L2.transpose(0, 2, 1)
    A, Qd = linalg.van_loan(F, Q1, dt)
    A2, Qd2 = linalg.van_loan(F, Q1, 2 * dt)
    assert _rel_err(A2, A @ A).max() < 1e-11
    assert _rel_err(Qd2, Qd + A @ Qd @ A.transpose(0, 2, 1)).max() < 1e-10
    _, Qd_b = linalg.van_loan(F, Q2, dt)
    _, Qd_ab = linalg.van_loan(F, 2.0 * Q1 - 0.5 * Q2, dt)
    assert _rel_err(Qd_ab, 2.0 * Qd - 0.5 * Qd_b).max() < 1e-11
    np.testing.assert_array_equal(Qd, Qd.transpose(0, 2, 1))
    w = np.linalg.eigvalsh(Qd)
    assert np.all(w > -1e-12 * w.max(axis=1, keepdims=True))


def test_van_loan_trivial_inputs_and_broadcast_qc() -> None:
    """dt = 0 gives A = I, Qd = 0; Qc = 0 gives Qd = 0 exactly; F = 0 gives Qd = Qc dt; one
    (k, k) Qc broadcasts to every ship; every ship's result is bit-identical alone."""
    rng = np.random.default_rng(23)
    n, k = 5, 4
    F = rng.standard_normal((n, k, k)) * np.array([1e-3, 0.1, 1.0, 10.0, 50.0])[:, None, None]
    L = rng.standard_normal((k, k))
    Qc = L @ L.T
    A, Qd = linalg.van_loan(F, Qc, 0.0)
    np.testing.assert_array_equal(A, np.broadcast_to(np.eye(k), (n, k, k)))
    np.testing.assert_array_equal(Qd, 0.0)
    A, Qd = linalg.van_loan(F, np.zeros((n, k, k)), 1.5)
    np.testing.assert_array_equal(Qd, 0.0)
    _, Qd = linalg.van_loan(np.zeros((1, k, k)), Qc, 1.5)
    np.testing.assert_allclose(Qd[0], Qc * 1.5, rtol=1e-15)
    A_b, Qd_b = linalg.van_loan(F, Qc, 1.5)
    A_s, Qd_s = linalg.van_loan(F, np.broadcast_to(Qc, (n, k, k)).copy(), 1.5)
    np.testing.assert_array_equal(A_b, A_s)
    np.testing.assert_array_equal(Qd_b, Qd_s)
    for i in (4, 0, 2):
        A_i, Qd_i = linalg.van_loan(F[i:i + 1], Qc, 1.5)
        np.testing.assert_array_equal(A_i[0], A_b[i])
        np.testing.assert_array_equal(Qd_i[0], Qd_b[i])
    A_r, Qd_r = linalg.van_loan(F[::-1], Qc, 1.5)
    np.testing.assert_array_equal(A_r[::-1], A_b)
    np.testing.assert_array_equal(Qd_r[::-1], Qd_b)


def test_van_loan_nan_ship_stays_its_own() -> None:
    """A NaN in one ship's F gives that ship NaN and leaves the others bit-identical."""
    rng = np.random.default_rng(24)
    F = rng.standard_normal((3, 3, 3))
    A, Qd = linalg.van_loan(F, np.eye(3), 1.0)
    F[1, 0, 2] = np.nan
    A_n, Qd_n = linalg.van_loan(F, np.eye(3), 1.0)
    assert np.isnan(A_n[1]).all() and np.isnan(Qd_n[1]).all()
    for i in (0, 2):
        np.testing.assert_array_equal(A_n[i], A[i])
        np.testing.assert_array_equal(Qd_n[i], Qd[i])


_INF_CHILD = """
import sys
import numpy as np
from trafficsim.estimation import linalg
linalg.van_loan(np.zeros((2, 2, 2)), np.eye(2), 1.0)  # (compiled for the types below)
print("ready", flush=True)
F = np.zeros((2, 2, 2))
F[1, 0, 1], F[1, 1, 0] = np.inf, 1.0
try:
    A, Qd = linalg.van_loan(F, np.eye(2), 1.0)
    print("finite" if np.isfinite(A[1]).all() else "nonfinite", flush=True)
except Exception as exc:
    print("raised", type(exc).__name__, flush=True)
"""


def test_van_loan_with_an_infinite_entry_returns() -> None:
    """An infinite entry in one ship's F (a diverged estimate) must give a non-finite result
    for that ship, not hang the compiled loop: run in a child process with a time limit."""
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-c", _INF_CHILD], stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "ready"
        try:
            proc.wait(timeout=3.0)
        except subprocess.TimeoutExpired:
            pytest.fail("van_loan did not return within 3 s")
        # (read through the same reader: the answer may have come with "ready" in one read)
        out = proc.stdout.read()
        assert out.strip() == "nonfinite"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
