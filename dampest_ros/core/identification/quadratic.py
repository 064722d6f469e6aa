"""Quadratic programmes of least squares: min θᵀAθ − 2bᵀθ from normal equations, possibly
singular (rank-revealing), with some parameters held, and under linear inequalities E β ≥ h.

The batch fit, the structure search and the projection of the online estimate onto the
dissipativity constraint (:mod:`dampest_ros.core.identification.dissipative`) solve with these.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

FloatArray = NDArray[np.float64]


def rank_solve(A: FloatArray, b: FloatArray, tol: float = 1e-10
               ) -> tuple[FloatArray, NDArray[np.int64]]:
    """Solve A x = b for a symmetric PSD A that may be singular, never raising.

    Cholesky when A is clearly positive definite; otherwise a rank-revealing QR with column
    pivoting: columns whose pivot |R_kk| falls below ``tol`` · |R_00| depend (to that
    tolerance) on the columns chosen before them and are held at 0.

    Parameters
    ----------
    A : ndarray, shape (p, p)
        Normal-equation matrix, best with a unit diagonal (scale the columns first).
    b : ndarray, shape (p,)
    tol : float
        Relative pivot tolerance (A is a Gram matrix: 1e-10 is a column condition of 1e5).

    Returns
    -------
    x : ndarray, shape (p,)
    dropped : ndarray of int
        Indices of the columns held at 0, in the order QR found them dependent.
    """
    p = len(b)
    x = np.zeros(p)
    if p == 0:
        return x, np.zeros(0, dtype=np.int64)
    try:
        c = linalg.cho_factor(A)
        if np.min(np.abs(np.diag(c[0]))) ** 2 > tol * max(float(np.max(np.diag(A))), 1e-300):
            return np.asarray(linalg.cho_solve(c, b), dtype=float), np.zeros(0, dtype=np.int64)
    except (linalg.LinAlgError, ValueError):
        pass
    _, R, piv = linalg.qr(A, pivoting=True, mode="economic")
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > tol * max(float(d[0]), 1e-300))) if np.isfinite(d).all() else 0
    keep = np.sort(piv[:rank])
    if rank:
        x[keep] = linalg.lstsq(A[np.ix_(keep, keep)], b[keep])[0]
    return x, np.asarray(piv[rank:], dtype=np.int64)


def constrained_quadratic(H: FloatArray, g: FloatArray, E: FloatArray, h: FloatArray
                          ) -> FloatArray | None:
    """argmin βᵀHβ − 2gᵀβ subject to E β ≥ h; None when no β satisfies the constraints.

    Lawson & Hanson's reduction (Solving Least Squares Problems, ch. 23): with H = RᵀR and
    z = Rβ − R⁻ᵀg the problem is the least-distance programme min ‖z‖ subject to
    G z ≥ f (G = E R⁻¹, f = h − G R⁻ᵀg), whose solution is z = −ρ_{1:r}/ρ_{r+1} with
    ρ = [Gᵀ; fᵀ] u − e_{r+1} and u ≥ 0 the non-negative least-squares solution: exact,
    no step sizes or tolerances to tune.

    Parameters
    ----------
    H : ndarray, shape (r, r)
        Symmetric positive definite (eigenvalues below 1e-12 of the largest are raised).
    g : ndarray, shape (r,)
    E : ndarray, shape (m, r)
    h : ndarray, shape (m,)

    Returns
    -------
    ndarray, shape (r,), or None
    """
    from scipy import optimize  # slow to import: only where a constraint binds

    lam, V = np.linalg.eigh(H)
    lam = np.maximum(lam, 1e-12 * max(float(lam.max()), 1e-300))
    R_inv = V / np.sqrt(lam)  # R = √Λ Vᵀ, R⁻¹ = V Λ^{-1/2}
    d = R_inv.T @ g  # Rᵀd = g
    G = E @ R_inv
    f = h - G @ d
    # each constraint row scaled to unit length: the same feasible set, better conditioned
    norm = np.linalg.norm(G, axis=1)
    keep = norm > 0
    G, f = G[keep] / norm[keep, None], f[keep] / norm[keep]
    if np.any(~keep & (h > 0)):
        return None  # 0 ≥ h_k > 0
    M = np.vstack([G.T, f[None, :]])
    e = np.zeros(M.shape[0])
    e[-1] = 1.0
    u = optimize.nnls(M, e, maxiter=50 * M.shape[1])[0]
    rho = M @ u - e
    if abs(rho[-1]) < 1e-12:
        return None
    z = -rho[:-1] / rho[-1]
    return np.asarray(R_inv @ (z + d), dtype=float)


def solve_normal(A: FloatArray, b: FloatArray, free: NDArray[np.bool_], fixed: FloatArray,
           lower: FloatArray | None = None, basis: FloatArray | None = None,
           power: FloatArray | None = None) -> FloatArray:
    """Minimise θᵀAθ − 2bᵀθ over the free parameters, the others held at ``fixed``.

    Parameters
    ----------
    A : ndarray, shape (p, p)
    b : ndarray, shape (p,)
    free : ndarray of bool, shape (p,)
    fixed : ndarray, shape (p,)
        Values of the parameters that are not free.
    lower : ndarray, shape (p,), optional
        Lower bounds (−inf: none).
    basis : ndarray, shape (p_free, r), optional
        θ_free = T β: only the directions T spans are estimated, the rest of θ_free is 0 in
        them (minimum norm). Default: the column scaling, T = diag(1/√diag A_free).
    power : ndarray, shape (m, p), optional
        Rows g_k with νᵀD(ν)ν = g_kᵀθ at m velocities; the solution keeps g_kᵀθ ≥ 0.
    """
    theta = fixed.copy()
    if not free.any():
        return theta
    Af = A[np.ix_(free, free)]
    bf = b[free] - A[np.ix_(free, ~free)] @ fixed[~free]
    T = basis if basis is not None else np.diag(1.0 / np.sqrt(np.maximum(np.diag(Af),
                                                                         1e-300)))
    H, g = T.T @ Af @ T, T.T @ bf  # column-scaled: well conditioned across units
    beta = rank_solve(H, g)[0]
    rows, h = [], []
    if lower is not None and np.isfinite(lower[free]).any():
        fin = np.isfinite(lower[free])
        rows.append(T[fin])  # θ_free = Tβ ≥ lower
        h.append(lower[free][fin])
    if power is not None and len(power):
        rows.append(power[:, free] @ T)  # g_kᵀθ ≥ 0 with the fixed part moved right
        h.append(-power[:, ~free] @ fixed[~free])
    if rows:
        E, hh = np.vstack(rows), np.concatenate(h)
        slack = 1e-12 * (np.abs(E) @ np.abs(beta) + np.abs(hh))
        if np.any(E @ beta < hh - slack):
            bounded = constrained_quadratic(H, g, E, hh)
            beta = beta if bounded is None else bounded
    theta[free] = T @ beta
    if lower is not None:
        # the active bounds exactly (the reduction meets them to rounding)
        theta[free] = np.maximum(theta[free], lower[free])
    return theta
