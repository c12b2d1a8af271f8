"""Matrix exponential and Van Loan discretisation in compiled loops over a stack of matrices
(the EKF's transition and process noise [seed 002, ch 4.4]; Van Loan 1978)."""

from __future__ import annotations

import math

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
