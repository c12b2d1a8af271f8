"""Compiled dense linear algebra for small stacked matrices: the matrix exponential and Van Loan.

The matrix exponential of a stack of matrices by scaling and squaring with a Pade approximant of
degree 3, 5, 7, 9 or 13 chosen from the 1-norm (Higham 2005, "The scaling and squaring method for
the matrix exponential revisited", SIAM J. Matrix Anal. Appl. 26(4):1179-1193, algorithm 2.3 and
table 2.3), and the discrete transition and process noise of a linear system by Van Loan's method
(Van Loan 1978, IEEE Trans. Autom. Control 23(3):395-404), one compiled loop over the stack; used
by the EKF on the ship model [seed 002, eqs 4.13-4.16] (the thesis found the plain Maclaurin
series needs 50-70 terms, [seed 002, ch 4.4]).
"""

from __future__ import annotations

import math

import numpy as np

from trafficsim.jit import kernel


def _pade_coefficients(m: int) -> np.ndarray:
    """Coefficients of the [m/m] Pade numerator of exp: c_j = (2m-j)! m! / ((2m)! j! (m-j)!)."""
    f = math.factorial
    return np.array([f(2 * m - j) * f(m) / (f(2 * m) * f(j) * f(m - j)) for j in range(m + 1)])


_PADE = np.zeros((14, 14))
for _m in (3, 5, 7, 9, 13):
    _PADE[_m, : _m + 1] = _pade_coefficients(_m)
#: Higham (2005) table 2.3: largest 1-norm for which the [m/m] Pade approximant (no scaling) is
#: accurate to double precision, m = 3, 5, 7, 9, 13
_THETA = np.array([1.495585217958292e-2, 2.539398330063230e-1, 9.504178996162932e-1,
                   2.097847961257068e0, 5.371920351148152e0])


@kernel
def _mm8(A: np.ndarray, B: np.ndarray, out: np.ndarray, alpha: float, acc: bool,
         trans_b: bool) -> None:
    """:func:`_mm` for 8x8 matrices: one row of ``out`` in eight scalar accumulators (2.4x
    faster than the loop form: the row stays in registers); zero entries of A are skipped."""
    for i in range(8):
        if acc:
            s0, s1, s2, s3 = out[i, 0], out[i, 1], out[i, 2], out[i, 3]
            s4, s5, s6, s7 = out[i, 4], out[i, 5], out[i, 6], out[i, 7]
        else:
            s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
        for m in range(8):
            a = alpha * A[i, m]
            if a == 0.0:  # the filter's F has zero rows and columns (position, current)
                continue
            if trans_b:
                s0 += a * B[0, m]
                s1 += a * B[1, m]
                s2 += a * B[2, m]
                s3 += a * B[3, m]
                s4 += a * B[4, m]
                s5 += a * B[5, m]
                s6 += a * B[6, m]
                s7 += a * B[7, m]
            else:
                s0 += a * B[m, 0]
                s1 += a * B[m, 1]
                s2 += a * B[m, 2]
                s3 += a * B[m, 3]
                s4 += a * B[m, 4]
                s5 += a * B[m, 5]
                s6 += a * B[m, 6]
                s7 += a * B[m, 7]
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = s0, s1, s2, s3
        out[i, 4], out[i, 5], out[i, 6], out[i, 7] = s4, s5, s6, s7


@kernel
def _mm(A: np.ndarray, B: np.ndarray, out: np.ndarray, alpha: float, acc: bool,
        trans_b: bool) -> None:
    """out = alpha A op(B) (+ out if ``acc``), op(B) = B or B^T; square (k, k) matrices, ``out``
    distinct from A and B."""
    k = A.shape[0]
    if k == 8:
        _mm8(A, B, out, alpha, acc, trans_b)
        return
    if not acc:
        for i in range(k):
            for j in range(k):
                out[i, j] = 0.0
    for i in range(k):
        for m in range(k):
            a = alpha * A[i, m]
            if trans_b:
                for j in range(k):
                    out[i, j] += a * B[j, m]
            else:
                for j in range(k):
                    out[i, j] += a * B[m, j]


@kernel
def _lu_inplace(A: np.ndarray, piv: np.ndarray) -> None:
    """LU factorisation with partial pivoting in place (L unit lower, U upper; row ``i`` of the
    factors is row ``piv[i]`` of the original)."""
    k = A.shape[0]
    for i in range(k):
        piv[i] = i
    for col in range(k):
        p = col
        big = abs(A[col, col])
        for i in range(col + 1, k):
            if abs(A[i, col]) > big:
                big = abs(A[i, col])
                p = i
        if p != col:
            piv[col], piv[p] = piv[p], piv[col]
            for j in range(k):
                A[col, j], A[p, j] = A[p, j], A[col, j]
        inv = 1.0 / A[col, col]
        for i in range(col + 1, k):
            f = A[i, col] * inv
            A[i, col] = f
            for j in range(col + 1, k):
                A[i, j] -= f * A[col, j]


@kernel
def _lu_solve(LU: np.ndarray, piv: np.ndarray, B: np.ndarray, work: np.ndarray) -> None:
    """B <- A^-1 B from :func:`_lu_inplace` factors; ``work`` has B's shape."""
    k = LU.shape[0]
    nr = B.shape[1]
    for i in range(k):
        for j in range(nr):
            work[i, j] = B[piv[i], j]
    for i in range(k):  # forward: L y = P b (axpy rows: vectorises over the columns)
        for m in range(i):
            f = LU[i, m]
            for j in range(nr):
                work[i, j] -= f * work[m, j]
    for i in range(k - 1, -1, -1):  # back: U x = y
        for m in range(i + 1, k):
            f = LU[i, m]
            for j in range(nr):
                work[i, j] -= f * work[m, j]
        inv = 1.0 / LU[i, i]
        for j in range(nr):
            work[i, j] *= inv
    for i in range(k):
        for j in range(nr):
            B[i, j] = work[i, j]


@kernel
def _solve_inplace(A: np.ndarray, B: np.ndarray) -> None:
    """B <- A^-1 B (A is destroyed)."""
    piv = np.empty(A.shape[0], dtype=np.int64)
    work = np.empty_like(B)
    _lu_inplace(A, piv)
    _lu_solve(A, piv, B, work)


@kernel
def _expm_one(Ain: np.ndarray, out: np.ndarray, W: np.ndarray, pade: np.ndarray,
              theta: np.ndarray) -> None:
    """out = expm(Ain) for one (k, k) matrix; W is (7, k, k) workspace [Higham 2005, alg 2.3]."""
    k = Ain.shape[0]
    norm = 0.0
    for j in range(k):
        col = 0.0
        for i in range(k):
            col += abs(Ain[i, j])
        norm = max(norm, col)
    if not math.isfinite(norm):  # an infinite entry: no scaling makes the series converge
        out[:, :] = math.nan
        return
    s = 0
    m = 13
    for idx, deg in enumerate((3, 5, 7, 9)):
        if norm <= theta[idx]:
            m = deg
            break
    if m == 13 and norm > theta[4]:
        s = math.ceil(math.log2(norm / theta[4]))
    A, A2, A4, A6, U, V, T = W[0], W[1], W[2], W[3], W[4], W[5], W[6]
    sc = 0.5 ** s
    for i in range(k):
        for j in range(k):
            A[i, j] = Ain[i, j] * sc
    _mm(A, A, A2, 1.0, False, False)
    b = pade[m]
    if m == 13:
        _mm(A2, A2, A4, 1.0, False, False)
        _mm(A4, A2, A6, 1.0, False, False)
        for i in range(k):
            for j in range(k):
                T[i, j] = b[13] * A6[i, j] + b[11] * A4[i, j] + b[9] * A2[i, j]
        _mm(A6, T, U, 1.0, False, False)  # U <- A6 (b13 A6 + b11 A4 + b9 A2)
        for i in range(k):
            for j in range(k):
                T[i, j] = U[i, j] + b[7] * A6[i, j] + b[5] * A4[i, j] + b[3] * A2[i, j]
            T[i, i] += b[1]
        _mm(A, T, U, 1.0, False, False)
        for i in range(k):
            for j in range(k):
                T[i, j] = b[12] * A6[i, j] + b[10] * A4[i, j] + b[8] * A2[i, j]
        _mm(A6, T, V, 1.0, False, False)
        for i in range(k):
            for j in range(k):
                V[i, j] += b[6] * A6[i, j] + b[4] * A4[i, j] + b[2] * A2[i, j]
            V[i, i] += b[0]
    else:
        # powers A2, A4, A6 (A8 = A4 A4 for m = 9), then U = A sum_odd, V = sum_even
        if m >= 5:
            _mm(A2, A2, A4, 1.0, False, False)
        if m >= 7:
            _mm(A4, A2, A6, 1.0, False, False)
        for i in range(k):
            for j in range(k):
                T[i, j] = b[3] * A2[i, j]
                V[i, j] = b[2] * A2[i, j]
                if m >= 5:
                    T[i, j] += b[5] * A4[i, j]
                    V[i, j] += b[4] * A4[i, j]
                if m >= 7:
                    T[i, j] += b[7] * A6[i, j]
                    V[i, j] += b[6] * A6[i, j]
            T[i, i] += b[1]
            V[i, i] += b[0]
        if m == 9:
            _mm(A4, A4, A2, 1.0, False, False)  # A2 now holds A8
            for i in range(k):
                for j in range(k):
                    T[i, j] += b[9] * A2[i, j]
                    V[i, j] += b[8] * A2[i, j]
        _mm(A, T, U, 1.0, False, False)
    # solve (V - U) X = (V + U)
    for i in range(k):
        for j in range(k):
            T[i, j] = V[i, j] - U[i, j]
            out[i, j] = V[i, j] + U[i, j]
    _solve_inplace(T, out)
    for _ in range(s):
        _mm(out, out, T, 1.0, False, False)
        for i in range(k):
            for j in range(k):
                out[i, j] = T[i, j]


@kernel
def _expm_stack(M: np.ndarray, out: np.ndarray, pade: np.ndarray, theta: np.ndarray) -> None:
    k = M.shape[1]
    W = np.empty((7, k, k))
    for i in range(M.shape[0]):
        _expm_one(M[i], out[i], W, pade, theta)


def expm_stack(M: np.ndarray) -> np.ndarray:
    """Matrix exponential of each matrix of a stack ``(n, k, k)`` -> ``(n, k, k)``.

    Scaling and squaring with Pade degree 3..13 chosen from the 1-norm (Higham 2005, alg. 2.3);
    one compiled loop. Agrees with ``scipy.linalg.expm`` to ~1e-14 relative (tested).
    """
    M = np.ascontiguousarray(M, dtype=float)
    out = np.empty_like(M)
    _expm_stack(M, out, _PADE, _THETA)
    return out


@kernel
def _balance(G: np.ndarray, d: np.ndarray) -> None:
    """Diagonal balancing ``G <- D^-1 G D`` in place, ``d`` = diag(D) in powers of two.

    Parlett & Reinsch (1969) without permutations: each row/column pair is scaled by the power
    of two that best equalises its off-diagonal row and column 1-norms, sweeping until no scaling
    lowers their sum by 5 %. Powers of two keep the scaling exact. For the ship filter this
    brings the norm of ``F dt`` from ~5-10 (heading-to-position entries of the size of the speed,
    yaw-rate entries of the size of U/L) to ~1-4, saving Pade degree and squarings.
    """
    k = G.shape[0]
    for i in range(k):
        d[i] = 1.0
    for _ in range(20):
        done = True
        for i in range(k):
            c = 0.0
            r = 0.0
            for j in range(k):
                if j != i:
                    c += abs(G[j, i])
                    r += abs(G[i, j])
            if c == 0.0 or r == 0.0 or not math.isfinite(c + r):
                continue  # (an infinite entry: no power of two equalises the norms)
            # the power of two f that best equalises c f and r / f (LAPACK dgebal's loops)
            f = 1.0
            total = c + r
            while c < 0.5 * r:
                f *= 2.0
                c *= 2.0
                r *= 0.5
            while c >= 2.0 * r:
                f *= 0.5
                c *= 0.5
                r *= 2.0
            if c + r < 0.95 * total:
                done = False
                d[i] *= f
                for j in range(k):
                    G[j, i] *= f
                    G[i, j] /= f
        if done:
            break


@kernel
def _van_loan_one(F: np.ndarray, Qc: np.ndarray, dt: float, W: np.ndarray, d: np.ndarray,
                  piv: np.ndarray, pade: np.ndarray, theta: np.ndarray, A_out: np.ndarray,
                  Qd_out: np.ndarray) -> None:
    """A = expm(F dt), Qd = int_0^dt expm(F t) Qc expm(F t)^T dt for one ship (Van Loan 1978).

    Van Loan's ``expm(M)``, ``M = [[-G, Q], [0, G^T]]`` (``G = F dt``, ``Q = Qc dt``), by scaling
    and squaring with a Pade approximant (Higham 2005, degree 3, 5, 7, 9 or 13 from the norm),
    evaluated block by block: every polynomial in ``M`` is block upper triangular with diagonal
    blocks ``p(-G)`` and ``p(G^T) = p(G)^T``, so only the top-left blocks (powers of G) and the
    top-right blocks (linear in Q) are formed, with 8x8 products (about a third of the work on
    the 16x16 matrix). With ``U``, ``V`` the odd and even Pade parts (top-left ``Ut = -U(G)``,
    ``Vt = V(G)``, top-right ``Uy``, ``Vy``), solving ``(V - U) X = V + U`` block-wise gives::

        A_s  = (Vt + Ut)^-1 (Vt - Ut)                       = r_m(G_s) ~ expm(G_s)
        Qd_s = (Vt + Ut)^-1 ((Vy + Uy) - (Vy - Uy) A_s^T)    = A_s X_12

    and the squarings double the step: ``Qd(2h) = Qd(h) + A(h) Qd(h) A(h)^T``, ``A(2h) = A(h)^2``.
    Before all this ``G`` is balanced (:func:`_balance`): ``expm(D^-1 G D) = D^-1 expm(G) D``, and
    the balanced problem has ``Q' = D^-1 Q D^-1``, ``Qd = D Qd' D``. The top-right computations
    are linear in Q, so their rounding errors are relative to Q, not to G: no balancing of Q
    against G is needed. Degree and scaling come from the larger of the 1- and inf-norms of the
    balanced G (the 1-norm of ``blockdiag(-G, G^T)``) and ``theta`` of Higham's table 2.3.

    Args:
        W: ``(18, k, k)`` workspace; d: ``(k,)`` float workspace; piv: ``(k,)`` int64
            workspace; pade: ``(14, 14)`` Pade coefficients by degree; theta: the 5 thresholds.
    """
    k = F.shape[0]
    G, Q, G2, G4, G6, Y2, Y4, Y6 = W[0], W[1], W[2], W[3], W[4], W[5], W[6], W[7]
    Tt, Ty, Ut, Uy, Vt, Vy, C, T2 = W[8], W[9], W[10], W[11], W[12], W[13], W[14], W[15]
    G8, Y8 = W[16], W[17]
    for i in range(k):
        for j in range(k):
            G[i, j] = F[i, j] * dt
    _balance(G, d)
    n1 = 0.0
    ninf = 0.0
    for j in range(k):
        c1 = 0.0
        ci = 0.0
        for i in range(k):
            c1 += abs(G[i, j])
            ci += abs(G[j, i])
        n1 = max(n1, c1)
        ninf = max(ninf, ci)
    norm = max(n1, ninf)
    if not math.isfinite(norm):  # an infinite entry: no scaling makes the series converge
        A_out[:, :] = math.nan
        Qd_out[:, :] = math.nan
        return
    m = 13
    for idx, deg in enumerate((3, 5, 7, 9)):
        if norm <= theta[idx]:
            m = deg
            break
    s = 0
    if m == 13 and norm > theta[4]:
        s = math.ceil(math.log2(norm / theta[4]))
    sc = 0.5**s
    for i in range(k):
        for j in range(k):
            G[i, j] *= sc
            Q[i, j] = Qc[i, j] * dt * sc / (d[i] * d[j])
    b = pade[m]
    # even powers of M: top-left G^2j, top-right Y_2j
    _mm(G, G, G2, 1.0, False, False)
    _mm(G, Q, Y2, -1.0, False, False)
    _mm(Q, G, Y2, 1.0, True, True)  # Y2 = -G Q + Q G^T
    if m >= 5:
        _mm(G2, G2, G4, 1.0, False, False)
        _mm(G2, Y2, Y4, 1.0, False, False)
        _mm(Y2, G2, Y4, 1.0, True, True)  # Y4 = G2 Y2 + Y2 G2^T
    if m >= 7:
        _mm(G4, G2, G6, 1.0, False, False)
        _mm(G4, Y2, Y6, 1.0, False, False)
        _mm(Y4, G2, Y6, 1.0, True, True)  # Y6 = G4 Y2 + Y4 G2^T
    if m == 13:
        # W1 = b13 M6 + b11 M4 + b9 M2; Wd = M6 W1 + b7 M6 + b5 M4 + b3 M2 + b1 I (in Vt, Vy)
        for i in range(k):
            for j in range(k):
                Tt[i, j] = b[13] * G6[i, j] + b[11] * G4[i, j] + b[9] * G2[i, j]
                Ty[i, j] = b[13] * Y6[i, j] + b[11] * Y4[i, j] + b[9] * Y2[i, j]
        _mm(G6, Tt, Vt, 1.0, False, False)
        _mm(G6, Ty, Vy, 1.0, False, False)
        _mm(Y6, Tt, Vy, 1.0, True, True)  # bottom-right of W1 is Tt^T
        for i in range(k):
            for j in range(k):
                Vt[i, j] += b[7] * G6[i, j] + b[5] * G4[i, j] + b[3] * G2[i, j]
                Vy[i, j] += b[7] * Y6[i, j] + b[5] * Y4[i, j] + b[3] * Y2[i, j]
            Vt[i, i] += b[1]
        # U = M Wd: top-left -G Wt, top-right -G Wy + Q Wt^T
        _mm(G, Vt, Ut, -1.0, False, False)
        _mm(G, Vy, Uy, -1.0, False, False)
        _mm(Q, Vt, Uy, 1.0, True, True)
        # V = M6 (b12 M6 + b10 M4 + b8 M2) + b6 M6 + b4 M4 + b2 M2 + b0 I
        for i in range(k):
            for j in range(k):
                Tt[i, j] = b[12] * G6[i, j] + b[10] * G4[i, j] + b[8] * G2[i, j]
                Ty[i, j] = b[12] * Y6[i, j] + b[10] * Y4[i, j] + b[8] * Y2[i, j]
        _mm(G6, Tt, Vt, 1.0, False, False)
        _mm(G6, Ty, Vy, 1.0, False, False)
        _mm(Y6, Tt, Vy, 1.0, True, True)
        for i in range(k):
            for j in range(k):
                Vt[i, j] += b[6] * G6[i, j] + b[4] * G4[i, j] + b[2] * G2[i, j]
                Vy[i, j] += b[6] * Y6[i, j] + b[4] * Y4[i, j] + b[2] * Y2[i, j]
            Vt[i, i] += b[0]
    else:
        if m == 9:
            _mm(G6, G2, G8, 1.0, False, False)
            _mm(G6, Y2, Y8, 1.0, False, False)
            _mm(Y6, G2, Y8, 1.0, True, True)  # Y8 = G6 Y2 + Y6 G2^T
        # Wd = sum_odd b_j M^(j-1) in Tt, Ty; V = sum_even b_j M^j in Vt, Vy
        for i in range(k):
            for j in range(k):
                Tt[i, j] = b[3] * G2[i, j]
                Ty[i, j] = b[3] * Y2[i, j]
                Vt[i, j] = b[2] * G2[i, j]
                Vy[i, j] = b[2] * Y2[i, j]
                if m >= 5:
                    Tt[i, j] += b[5] * G4[i, j]
                    Ty[i, j] += b[5] * Y4[i, j]
                    Vt[i, j] += b[4] * G4[i, j]
                    Vy[i, j] += b[4] * Y4[i, j]
                if m >= 7:
                    Tt[i, j] += b[7] * G6[i, j]
                    Ty[i, j] += b[7] * Y6[i, j]
                    Vt[i, j] += b[6] * G6[i, j]
                    Vy[i, j] += b[6] * Y6[i, j]
                if m == 9:
                    Tt[i, j] += b[9] * G8[i, j]
                    Ty[i, j] += b[9] * Y8[i, j]
                    Vt[i, j] += b[8] * G8[i, j]
                    Vy[i, j] += b[8] * Y8[i, j]
            Tt[i, i] += b[1]
            Vt[i, i] += b[0]
        _mm(G, Tt, Ut, -1.0, False, False)
        _mm(G, Ty, Uy, -1.0, False, False)
        _mm(Q, Tt, Uy, 1.0, True, True)
    # A_s = (Vt + Ut)^-1 (Vt - Ut)
    for i in range(k):
        for j in range(k):
            C[i, j] = Vt[i, j] + Ut[i, j]
            A_out[i, j] = Vt[i, j] - Ut[i, j]
    _lu_inplace(C, piv)
    _lu_solve(C, piv, A_out, T2)
    # Qd_s = (Vt + Ut)^-1 ((Vy + Uy) - (Vy - Uy) A_s^T)
    for i in range(k):
        for j in range(k):
            Tt[i, j] = Vy[i, j] - Uy[i, j]
            Qd_out[i, j] = Vy[i, j] + Uy[i, j]
    _mm(Tt, A_out, Qd_out, -1.0, True, True)
    _lu_solve(C, piv, Qd_out, T2)
    for _ in range(s):
        _mm(A_out, Qd_out, Tt, 1.0, False, False)
        _mm(Tt, A_out, Qd_out, 1.0, True, True)  # Qd += A Qd A^T
        _mm(A_out, A_out, T2, 1.0, False, False)
        for i in range(k):
            for j in range(k):
                A_out[i, j] = T2[i, j]
    # undo the balancing: A = D A' D^-1, Qd = D Qd' D; exact symmetry
    for i in range(k):
        for j in range(k):
            A_out[i, j] *= d[i] / d[j]
    for i in range(k):
        Qd_out[i, i] *= d[i] * d[i]
        for j in range(i + 1, k):
            sym = 0.5 * (Qd_out[i, j] + Qd_out[j, i]) * d[i] * d[j]
            Qd_out[i, j] = sym
            Qd_out[j, i] = sym


@kernel
def _van_loan_stack(F: np.ndarray, Qc: np.ndarray, dt: float, pade: np.ndarray,
                    theta: np.ndarray, A_out: np.ndarray, Qd_out: np.ndarray) -> None:
    k = F.shape[1]
    W = np.empty((18, k, k))
    d = np.empty(k)
    piv = np.empty(k, dtype=np.int64)
    for i in range(F.shape[0]):
        _van_loan_one(F[i], Qc[i], dt, W, d, piv, pade, theta, A_out[i], Qd_out[i])


def van_loan(F: np.ndarray, Qc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Discrete transition and process noise of ``x' = F x + w``, ``E[w w^T] = Qc delta``.

    Args:
        F: ``(n, k, k)`` continuous state matrices (1/s).
        Qc: ``(n, k, k)`` spectral densities (state unit squared per second).
        dt: step, s.

    Returns:
        ``A = expm(F dt)`` [seed 002, eq 4.14] and ``Qd`` (both ``(n, k, k)``): Van Loan's
        ``expm([[-F, Qc], [0, F^T]] dt)`` per ship, evaluated block-wise (:func:`_van_loan_one`).
    """
    F = np.ascontiguousarray(F, dtype=float)
    Qc = np.ascontiguousarray(np.broadcast_to(Qc, F.shape), dtype=float)
    A = np.empty_like(F)
    Qd = np.empty_like(F)
    _van_loan_stack(F, Qc, float(dt), _PADE, _THETA, A, Qd)
    return A, Qd
