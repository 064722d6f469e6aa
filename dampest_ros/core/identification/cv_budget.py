"""How many terms the data support: blocked cross-validation in time and the one-standard-error
rule on its curve.

The data are cut into F contiguous time folds; the samples within ``guard`` of a boundary
between folds belong to none (:func:`guarded_folds`), so that the low-pass of the regression,
whose impulse response is shorter than the guard, carries nothing of a held-out fold into the
folds that predict it. Each fold is predicted by the least-squares fit on the others
(:func:`fold_errors`). Along a path of nested models (the terms in the order a search added
them), the chosen size is the smallest whose held-out error exceeds the best's by no more than
one standard error of the best's (:func:`one_se_size`; Hastie,
Tibshirani & Friedman 2009, §7.10): a term stays only when its gain is larger than the
uncertainty of the held-out error itself, and the path's order (the search's and the library's,
simplest and physically named first) decides among sizes the data cannot tell apart.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Guard between folds in periods of the regression's low-pass cutoff: at 2 / f_c the
#: zero-phase filter's impulse response is below 1e-4 of its peak (its tail energy below 1e-8).
GUARD_PERIODS = 2.0


#: Held-out errors of two candidates closer than this (relative) are a tie, taken by the order
#: of the candidates (row, then library order; an element drag before its mirror pair):
#: candidates that explain the same part of the data (columns equal given the terms already
#: in, or a column the data leave at zero) score equal up to rounding, and rounding must not
#: decide the structure (a log read from a bag and from its CSV export differ by 1e-11 and chose
#: different terms).
TIE_RTOL = 1e-9


def first_best(score: FloatArray) -> int:
    """The first index whose ``score`` is within :data:`TIE_RTOL` of the smallest."""
    low = float(score.min())
    return int(np.flatnonzero(score <= low + TIE_RTOL * abs(low))[0])


def guarded_folds(n: int, folds: int, guard: int) -> NDArray[np.int64]:
    """The contiguous time fold (0..folds−1) of each of n samples, −1 for the ``guard``
    samples on each side of a boundary between two folds, shape (n,)."""
    k = np.arange(n)
    fold = np.minimum((k * folds) // max(n, 1), folds - 1)
    if guard > 0 and folds > 1:
        # boundary b sits at the first sample of fold b: ⌈b n / F⌉
        edges = -((-np.arange(1, folds) * n) // folds)
        d = k[:, None] - edges[None, :]
        # the last ``guard`` samples before a boundary and the first ``guard`` after it
        near = ((d >= -guard) & (d < guard)).any(axis=1)
        fold = np.where(near, -1, fold)
    return fold.astype(np.int64)


def scaled_lstsq(G: FloatArray, B: FloatArray, rcond: float = 1e-13) -> FloatArray:
    """Minimum-norm least squares of symmetric positive semi-definite normal equations
    G x = B, several at once, each column-scaled to a unit diagonal first.

    Parameters
    ----------
    G : ndarray, shape (..., k, k)
    B : ndarray, shape (..., k) or (..., k, m)
    rcond : float
        Eigenvalues of the scaled G at most ``rcond`` times its largest count as zero (as
        the singular values of ``numpy.linalg.lstsq``). A column with a zero diagonal (the
        data leave it at zero) gets a zero entry.

    Returns
    -------
    ndarray, shape of B
    """
    vector = B.ndim == G.ndim - 1
    Bm = B[..., None] if vector else B
    g = np.diagonal(G, axis1=-2, axis2=-1)
    # D = diag(1/√G_jj), 0 for a column the data leave at zero (its entry is then 0)
    d = np.divide(1.0, np.sqrt(np.maximum(g, 0.0)), out=np.zeros(g.shape), where=g > 0)
    # D G D y = D B, x = D y: the scaled matrix has a unit diagonal (or a zero one)
    w, V = np.linalg.eigh(G * d[..., :, None] * d[..., None, :])
    keep = np.abs(w) > rcond * np.abs(w).max(axis=-1, initial=0.0, keepdims=True)
    inv = np.where(keep, 1.0 / np.where(keep, w, 1.0), 0.0)
    # y = V Λ⁺ Vᵀ D B
    y = V @ (inv[..., :, None] * (np.swapaxes(V, -1, -2) @ (Bm * d[..., :, None])))
    x = y * d[..., :, None]
    return x[..., 0] if vector else x


def fold_fits(A: FloatArray, b: FloatArray, cols: Sequence[int] | NDArray[np.int64]
              ) -> FloatArray:
    """The least-squares fit of each fold's complement: θ_{−f} on the columns ``cols``.

    Parameters
    ----------
    A : ndarray, shape (F, m, m)
    b : ndarray, shape (F, m)
        Per-fold normal equations (ΦᵀΦ, Φᵀy).
    cols : sequence of int
        The columns of the model.

    Returns
    -------
    ndarray, shape (F, len(cols))
    """
    S = np.asarray(cols, dtype=np.int64)
    A, b = A[:, S[:, None], S], b[:, S]
    # all folds but f: the sum less fold f
    return scaled_lstsq(A.sum(0) - A, b.sum(0) - b)


def fold_errors(A: FloatArray, b: FloatArray, c: FloatArray, cols: Sequence[int] | NDArray[np.int64]
                ) -> FloatArray:
    """Held-out residual sum of squares of each fold, predicted from the other folds' fit.

    Parameters
    ----------
    A : ndarray, shape (F, m, m)
    b : ndarray, shape (F, m)
    c : ndarray, shape (F,)
        Per-fold normal equations of one force row (ΦᵀΦ, Φᵀy, yᵀy).
    cols : sequence of int
        The columns of the model.

    Returns
    -------
    ndarray, shape (F,)
        ‖y_f − Φ_f θ_{−f}‖² (N² or N²m²).
    """
    S = np.asarray(cols, dtype=np.int64)
    if not len(S):
        return np.array(c, dtype=float)
    theta = fold_fits(A, b, S)
    Af, bf = A[:, S[:, None], S], b[:, S]
    # ‖y − Φθ‖² on fold f = c − 2 bᵀθ + θᵀAθ
    return np.asarray(c - 2.0 * np.einsum("fk,fk->f", bf, theta)
                      + np.einsum("fk,fkl,fl->f", theta, Af, theta))


def one_se_size(errors: FloatArray) -> int:
    """The smallest model of a nested path within one standard error of the best.

    Parameters
    ----------
    errors : ndarray, shape (K + 1, F)
        Held-out RSS per fold of the path's models with 0..K added terms.

    Returns
    -------
    int
        The number of added terms k: the smallest with Σ_f e_kf ≤ Σ_f e_bf + √F · s_b, b the
        model of least held-out RSS and s_b the standard deviation of its e_bf over folds.
    """
    total = errors.sum(axis=1)
    best = int(np.argmin(total))
    F = errors.shape[1]
    # standard error of Σ_f e_bf: √F times the scatter of one fold's error
    se = np.sqrt(F) * float(np.std(errors[best], ddof=1)) if F > 1 else 0.0
    return int(np.flatnonzero(total <= total[best] + se)[0])
