"""Exact non-negative least squares for a few columns, vectorised over colour channels.

A fit eliminates the linear coefficients (kd, ks per channel and yarn type; the model's components enter
linearly) at every objective evaluation by solving, independently for each channel c,

    min_{x >= 0} || w_c * (A_c x - y_c) ||_2 ,   A_c (N, k), k <= 6 columns, N >> k rows.

Method (exact, no iteration): an NNLS optimum always exists whose support columns are linearly
independent, and on its support it is the unconstrained least-squares solution.  So the best of the
unconstrained solutions on all 2^k - 1 supports that are feasible (>= 0), or x = 0, is the NNLS optimum.
Each channel's weighted design [W A, W y] is reduced once by a thin QR to its (k+1) x (k+1) triangular
factor, so the work per support is independent of N and every candidate is scored by the honest sum of
squares ||R x - q||^2 (conditioning of A, not of A^T A, in the score).  Columns are scaled to unit norm;
a zero column gets coefficient 0; an exactly singular support falls back to an SVD pseudo-inverse.
~0.3 ms for N = 1,575, k = 3, C = 3.
"""

from __future__ import annotations

from functools import cache

import numpy as np

MAX_COLUMNS = 6
_PINV_RTOL = 1e-12


@cache
def _supports(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every non-empty support of k columns: masks (S, k) (row j: bit i of j+1 selects column i),
    pair masks (S, k, k) and unit pivots outside the support (S, k, k)."""
    codes = np.arange(1, 2**k)[:, None]
    masks = ((codes >> np.arange(k)) & 1).astype(np.float64)
    pair = masks[:, :, None] * masks[:, None, :]
    outside = np.eye(k) * (1.0 - masks)[:, :, None]
    for array in (masks, pair, outside):
        array.flags.writeable = False
    return masks, pair, outside


def nnls_small(A, y, w=None) -> tuple[np.ndarray, np.ndarray]:
    """Solve min_{x >= 0} ||w (A x - y)||_2 per channel, exactly.

    Parameters
    ----------
    A : (N, k) design shared by all channels, or (N, k, C) one per channel; 1 <= k <= 6.
    y : (N, C) data (or (N,) for one channel).
    w : (N, C) or (N,) row weights, or None for 1.

    Returns
    -------
    coef : (k, C) non-negative coefficients ((k,) if y was 1-D).
    residual_norm : (C,) ||w (A coef - y)||_2 per channel (a float if y was 1-D).

    A channel whose A, y or w hold non-finite values gets NaN coefficients and a NaN residual (so an
    objective built on it becomes non-finite and the optimiser applies its penalty); no warning is raised.
    """
    y = np.asarray(y, dtype=np.float64)
    one_channel = y.ndim == 1
    if one_channel:
        y = y[:, None]
    if y.ndim != 2:
        raise ValueError(f"y must have shape (N, C) or (N,), got {y.shape}")
    n_rows, n_channels = y.shape
    A = np.asarray(A, dtype=np.float64)
    if A.ndim == 2:
        A = A[:, :, None]
    if A.ndim != 3 or A.shape[0] != n_rows or A.shape[2] not in (1, n_channels):
        raise ValueError(f"A must have shape (N, k) or (N, k, C) with N = {n_rows}, C = {n_channels}; "
                         f"got {A.shape}")
    k = A.shape[1]
    if not 1 <= k <= MAX_COLUMNS:
        raise ValueError(f"nnls_small handles 1..{MAX_COLUMNS} columns, got {k}")
    w = np.ones((n_rows, 1)) if w is None else np.asarray(w, dtype=np.float64)
    if w.ndim == 1:
        w = w[:, None]
    if w.ndim != 2 or w.shape[0] != n_rows or w.shape[1] not in (1, n_channels):
        raise ValueError(f"w must have shape (N, C) or (N,) like y {y.shape}, got {w.shape}")

    # Weighted augmented design [W A, W y] per channel, laid out (C, k+1, N) so that each channel's
    # (N, k+1) matrix is column-major for LAPACK; then its triangular factor R_aug (C, k+1, k+1), with
    # ||W (A x - y)||^2 = ||R_aug[:, :k] x - R_aug[:, k]||^2 for every x.
    wT = w.T
    aug = np.empty((n_channels, k + 1, n_rows))
    np.multiply(wT[:, None, :], A.transpose(2, 1, 0), out=aug[:, :k])
    np.multiply(wT, y.T, out=aug[:, k])
    R_aug = np.linalg.qr(aug.transpose(0, 2, 1), mode="r")
    bad = ~np.isfinite(R_aug).all(axis=(1, 2))
    if bad.any():
        R_aug[bad] = 0.0
    R, q = R_aug[:, :, :k], R_aug[:, :, k]

    # Unit-norm columns (the column norms of R are those of W A); zero columns stay zero.
    norms = np.sqrt(np.einsum("cmk,cmk->ck", R, R))
    scale = np.zeros_like(norms)
    np.divide(1.0, norms, out=scale, where=norms > 0)
    R_scaled = R * scale[:, None, :]

    # Least squares on every support S at once.  Fast path: the normal equations of the k x k system with
    # the columns outside S replaced by unit pivots (so x_j = 0 there); an exactly singular support falls
    # back to the SVD pseudo-inverse of the masked R.  Either way each candidate's objective is the honest
    # sum of squares ||R x - q||^2, so an inaccurate solve can only lose, never win, the comparison.
    masks, pair, outside = _supports(k)
    gram = np.matmul(R_scaled.transpose(0, 2, 1), R_scaled)  # (C, k, k)
    gram[:, np.arange(k), np.arange(k)] += norms == 0  # unit pivot for a zero column: x_j = 0
    rhs = np.matmul(R_scaled.transpose(0, 2, 1), q[:, :, None])  # (C, k, 1)
    try:
        x_S = np.linalg.solve(gram[:, None] * pair + outside, rhs[:, None] * masks[:, :, None])[..., 0]
    except np.linalg.LinAlgError:
        R_S = R_scaled[:, None, :, :] * masks[None, :, None, :]  # (C, n_supports, k+1, k)
        x_S = np.matmul(np.linalg.pinv(R_S, rtol=_PINV_RTOL), q[:, None, :, None])[..., 0]
    x_S *= masks  # exactly 0 outside the support
    resid = np.matmul(R_scaled[:, None], x_S[..., None])[..., 0] - q[:, None, :]
    objective = np.einsum("csm,csm->cs", resid, resid)
    objective = np.where((x_S >= 0).all(axis=2), objective, np.inf)
    best = np.argmin(objective, axis=1)
    channel = np.arange(n_channels)
    best_objective = objective[channel, best]
    coef = x_S[channel, best] * scale
    empty_better = np.einsum("cm,cm->c", q, q) <= best_objective  # the empty support, x = 0
    coef[empty_better] = 0.0
    residual_norm = np.sqrt(np.where(empty_better, np.einsum("cm,cm->c", q, q), best_objective))
    coef[bad] = np.nan
    residual_norm[bad] = np.nan
    coef = coef.T
    if one_channel:
        return coef[:, 0], float(residual_norm[0])
    return coef, residual_norm
