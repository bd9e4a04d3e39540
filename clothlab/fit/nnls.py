"""Exact non-negative least squares for a few columns, vectorised over colour channels and parameter sets.

A fit eliminates the linear coefficients (kd, ks per channel and yarn type; the model's components enter
linearly) at every objective evaluation by solving, independently for each channel c,

    min_{x >= 0} || w_c * (A_c x - y_c) ||_2 ,   A_c (N, k), k <= 6 columns, N >> k rows.

Method (exact, no iteration): an NNLS optimum always exists whose support columns are linearly
independent, and on its support it is the unconstrained least-squares solution.  So the best of the
unconstrained solutions on all 2^k - 1 supports that are feasible (>= 0), or x = 0, is the NNLS optimum.
Fast path: the weighted normal equations G = A^T W^2 A, b = A^T W^2 y, y^T W^2 y per channel (one matrix
product over the N rows for all channels and sets), columns scaled to unit norm, every support solved on its
k x k block and scored by the exact quadratic ||W (A x - y)||^2 = y^T W^2 y - 2 x.b + x^T G x.  The winner's
sum of squares is then recomputed from the rows; where it disagrees with the quadratic (an ill-conditioned
support: cancellation in G) the channel is solved again by the careful path, a thin QR of [W A, W y]
scored by ||R x - q||^2 (conditioning of A, not of A^T A) with an SVD pseudo-inverse for exactly singular
supports.  A zero column gets coefficient 0.  ~0.05 ms for N = 1,575, k = 3, C = 3.
"""

from __future__ import annotations

from functools import cache

import numpy as np

MAX_COLUMNS = 6
_PINV_RTOL = 1e-12
_CHECK_RTOL = 1e-9
"""The fast path's winner is kept when its recomputed sum of squares matches the quadratic score within this
fraction of y^T W^2 y (else the channel goes through the QR path)."""


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


def _best_support(gram, rhs, scale, total, honest):
    """The careful path's NNLS optimum: gram (M, k, k) of unit-norm columns (unit pivot for a zero column),
    rhs (M, k), column scales (M, k), data norms (M,); every support solved (an exactly singular one by the
    pseudo-inverse of the masked R) and scored by ||R x - q||^2 with ``honest`` = (R (M, k+1, k), q (M, k+1)).
    Returns coef (M, k), score (M,)."""
    k = gram.shape[-1]
    masks, pair, outside = _supports(k)
    R, q = honest
    try:
        x_S = np.linalg.solve(gram[:, None] * pair + outside, (rhs[:, None] * masks)[..., None])[..., 0]
    except np.linalg.LinAlgError:
        R_S = R[:, None, :, :] * masks[None, :, None, :]  # (M, S, k+1, k)
        x_S = np.matmul(np.linalg.pinv(R_S, rtol=_PINV_RTOL), q[:, None, :, None])[..., 0]
    x_S *= masks  # exactly 0 outside the support
    resid = np.matmul(R[:, None], x_S[..., None])[..., 0] - q[:, None, :]
    objective = np.einsum("msk,msk->ms", resid, resid)
    objective = np.where((x_S >= 0).all(axis=2), objective, np.inf)
    best = np.argmin(objective, axis=1)
    rows = np.arange(len(best))
    score = objective[rows, best]
    coef = x_S[rows, best] * scale
    empty_better = total <= score  # the empty support, x = 0
    coef[empty_better] = 0.0
    return coef, np.where(empty_better, total, score)


def _scaled(gram, rhs):
    """Unit-norm columns: the scaled normal equations, column scales (zero columns: unit pivot, scale 0)."""
    k = gram.shape[-1]
    norms = np.sqrt(np.maximum(gram[:, np.arange(k), np.arange(k)], 0.0))
    scale = np.zeros_like(norms)
    np.divide(1.0, norms, out=scale, where=norms > 0)
    gram = gram * scale[:, :, None] * scale[:, None, :]
    gram[:, np.arange(k), np.arange(k)] += norms == 0
    return gram, rhs * scale, scale


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

    >>> A = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    >>> coef, norm = nnls_small(A, np.array([2.0, -1.0, 1.0]))  # unconstrained least squares: (2, -1)
    >>> (coef.round(6) + 0.0).tolist(), round(norm, 6)  # the best non-negative: x2 = 0, x1 = (2 + 1) / 2
    ([1.5, 0.0], 1.224745)
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

    if A.shape[2] == 1:
        designs, which = A[None, :, :, 0], np.zeros(n_channels, dtype=np.int64)
    else:
        designs, which = A.transpose(2, 0, 1), np.arange(n_channels, dtype=np.int64)  # (C, N, k)
    coef, score = _solve(designs, which, np.arange(n_channels, dtype=np.int64), y, w)
    residual_norm = np.sqrt(score)
    coef = coef.T
    if one_channel:
        return coef[:, 0], float(residual_norm[0])
    return coef, residual_norm


def nnls_sets(designs, y, w=None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nnls_small` for J designs at once (e.g. one per posterior walker): designs (J, N, k) shared by
    the channels of y (N, C), weights w (N, C) or (N,).  Returns coef (J, k, C) and residual norms (J, C)."""
    designs = np.asarray(designs, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if y.ndim != 2 or designs.ndim != 3 or designs.shape[1] != y.shape[0]:
        raise ValueError(f"designs must be (J, N, k) and y (N, C) with the same N; got {designs.shape}, {y.shape}")
    if not 1 <= designs.shape[2] <= MAX_COLUMNS:
        raise ValueError(f"nnls_sets handles 1..{MAX_COLUMNS} columns, got {designs.shape[2]}")
    n_sets, (n_rows, n_channels) = designs.shape[0], y.shape
    w = np.ones((n_rows, 1)) if w is None else np.asarray(w, dtype=np.float64)
    w = w[:, None] if w.ndim == 1 else w
    if w.shape[0] != n_rows or w.shape[1] not in (1, n_channels):
        raise ValueError(f"w must have shape (N, C) or (N,) like y {y.shape}, got {w.shape}")
    problems = np.arange(n_sets * n_channels, dtype=np.int64)
    coef, score = _solve(designs, problems // n_channels, problems % n_channels, y, w)
    return (coef.reshape(n_sets, n_channels, -1).transpose(0, 2, 1),
            np.sqrt(score).reshape(n_sets, n_channels))


def _solve(designs, which, channel, y, w):
    """Problems p: design designs[which[p]] (N, k), data y[:, channel[p]], weights w[:, channel[p]] (or w[:, 0]).
    The compiled normal-equations path, then the QR path for the problems whose check failed.  Returns
    coef (P, k) (NaN for non-finite input) and sums of squares (P,)."""
    from clothlab.fit import nnls_kernels

    coef, score, status = nnls_kernels.normal_equations_nnls(
        np.ascontiguousarray(designs.transpose(0, 2, 1)), which, channel, np.ascontiguousarray(y.T),
        np.ascontiguousarray(w.T), _CHECK_RTOL)
    retry = np.flatnonzero(status == 1)
    for p in retry:  # rare: an ill-conditioned support or cancellation in the quadratic score
        c = channel[p]
        coef[p], score[p] = (v[0] for v in _careful(designs[which[p]][:, :, None], y[:, [c]],
                                                      w[:, [c if w.shape[1] > 1 else 0]]))
    bad = status == 2
    coef[bad] = np.nan
    score[bad] = np.nan
    return coef, score


def _careful(A, y, w):
    """The QR path for the channels of y (N, C'): coefficients (C', k) and sums of squares (C',)."""
    n_rows, n_channels = y.shape
    k = A.shape[1]
    # Weighted augmented design [W A, W y] per channel, laid out (C, k+1, N) so that each channel's
    # (N, k+1) matrix is column-major for LAPACK; then its triangular factor R_aug (C, k+1, k+1), with
    # ||W (A x - y)||^2 = ||R_aug[:, :k] x - R_aug[:, k]||^2 for every x.
    wT = w.T
    aug = np.empty((n_channels, k + 1, n_rows))
    np.multiply(wT[:, None, :], A.transpose(2, 1, 0), out=aug[:, :k])
    np.multiply(wT, y.T, out=aug[:, k])
    R_aug = np.linalg.qr(aug.transpose(0, 2, 1), mode="r")
    R, q = R_aug[:, :, :k], R_aug[:, :, k]
    gram = np.matmul(R.transpose(0, 2, 1), R)
    rhs = np.matmul(R.transpose(0, 2, 1), q[:, :, None])[..., 0]
    gs, rs, scale = _scaled(gram, rhs)
    return _best_support(gs, rs, scale, np.einsum("cm,cm->c", q, q), (R * scale[:, None, :], q))
