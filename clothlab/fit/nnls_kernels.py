"""Compiled (numba) fast path of :mod:`clothlab.fit.nnls`: weighted normal equations and every support of a
few columns, for many (design, channel) problems in one call.

For each problem p (design A (N, k), data y, weights w): G = A^T W^2 A, b = A^T W^2 y and t = y^T W^2 y in
one pass over the rows; columns scaled to unit norm; every support S of linearly independent columns (a
Cholesky pivot below :data:`PIVOT_MIN` marks a dependent one, which cannot be needed: an NNLS optimum exists on
an independent support) solved on its block and scored by the exact quadratic t - 2 x.b + x^T G x; the best
feasible one (or x = 0) wins.  Its sum of squares is then recomputed from the rows; a mismatch beyond
``check_rtol`` t returns status 1 (the caller re-solves that problem by QR).  Non-finite input: status 2.
Imported lazily (numba costs ~0.5 s to import); compiled code is cached on disk.
"""

from __future__ import annotations

import math

import numpy as np

from clothlab.models.jit import njit

PIVOT_MIN = 1e-12
"""Smallest squared Cholesky pivot (unit-norm columns) of a support treated as independent."""


@njit(cache=True)
def _support_solve(G, b, idx, m, L, x):
    """Solve G[idx, idx] x = b[idx] (m x m) by Cholesky into x[:m]; False when a pivot is below PIVOT_MIN."""
    for i in range(m):
        for j in range(i + 1):
            s = G[idx[i], idx[j]]
            for q in range(j):
                s -= L[i, q] * L[j, q]
            if i == j:
                if s <= PIVOT_MIN:
                    return False
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    for i in range(m):  # forward: L z = b
        s = b[idx[i]]
        for q in range(i):
            s -= L[i, q] * x[q]
        x[i] = s / L[i, i]
    for i in range(m - 1, -1, -1):  # back: L^T x = z
        s = x[i]
        for q in range(i + 1, m):
            s -= L[q, i] * x[q]
        x[i] = s / L[i, i]
    return True


@njit(cache=True, fastmath=True)
def _dot3(a, b, c):
    """sum_n a[n] b[n] c[n] (contiguous rows; the summation order is the compiler's)."""
    acc = 0.0
    for n in range(a.shape[0]):
        acc += a[n] * b[n] * c[n]
    return acc


@njit(cache=True, fastmath=True)
def _weighted_residual(cols, x, y, w):
    """sum_n (w[n] (sum_i cols[i, n] x[i] - y[n]))^2."""
    acc = 0.0
    k = cols.shape[0]
    for n in range(y.shape[0]):
        r = -y[n]
        for i in range(k):
            r += cols[i, n] * x[i]
        r *= w[n]
        acc += r * r
    return acc


@njit(cache=True)
def normal_equations_nnls(designs, which, channel, y, w, check_rtol):
    """Problems p: columns designs[which[p]] (k, N), data y[channel[p]] (N,), weights w[channel[p]] (or
    w[0] if w has one row); designs (J, k, N), y (C, N), w (C or 1, N), all C-contiguous.  Returns coef (P, k),
    sums of squares ||w (A coef - y)||^2 recomputed from the rows (P,), status (P,) int8: 0 ok, 1 check
    failed (re-solve), 2 non-finite input."""
    n_problems = which.shape[0]
    k = designs.shape[1]
    coef = np.zeros((n_problems, k))
    score = np.zeros(n_problems)
    status = np.zeros(n_problems, dtype=np.int8)
    G = np.empty((k, k))
    b = np.empty(k)
    scale = np.empty(k)
    L = np.empty((k, k))
    x = np.empty(k)
    idx = np.empty(k, dtype=np.int64)
    best = np.empty(k)
    shared_w = w.shape[0] == 1
    w2 = w * w
    ones = np.ones(y.shape[1])
    for p in range(n_problems):
        cols = designs[which[p]]
        c = channel[p]
        cw = 0 if shared_w else c
        yc, wc, w2c = y[c], w[cw], w2[cw]
        total = _dot3(yc, yc, w2c)
        for i in range(k):
            b[i] = _dot3(cols[i], yc, w2c)
            for j in range(i, k):
                G[i, j] = _dot3(cols[i], cols[j], w2c)
        finite = math.isfinite(total) and math.isfinite(_dot3(wc, wc, ones))
        for i in range(k):
            finite = finite and math.isfinite(b[i])
            for j in range(i, k):
                finite = finite and math.isfinite(G[i, j])
        if not finite:
            status[p] = 2
            continue
        for i in range(k):
            scale[i] = 1.0 / math.sqrt(G[i, i]) if G[i, i] > 0.0 else 0.0
        for i in range(k):
            b[i] *= scale[i]
            for j in range(i, k):
                G[i, j] *= scale[i] * scale[j]
                G[j, i] = G[i, j]
        best_score = total
        best[:] = 0.0
        for mask in range(1, 2**k):
            m = 0
            usable = True
            for i in range(k):
                if (mask >> i) & 1:
                    usable = usable and scale[i] > 0.0  # a zero column: the support without it fits the same
                    idx[m] = i
                    m += 1
            if not usable or not _support_solve(G, b, idx, m, L, x):
                continue
            feasible = True
            for i in range(m):
                feasible = feasible and x[i] >= 0.0
            if not feasible:
                continue
            s = total
            for i in range(m):
                gx = 0.0
                for j in range(m):
                    gx += G[idx[i], idx[j]] * x[j]
                s += x[i] * (gx - 2.0 * b[idx[i]])
            if s < best_score:
                best_score = s
                best[:] = 0.0
                for i in range(m):
                    best[idx[i]] = x[i] * scale[idx[i]]
        honest = _weighted_residual(cols, best, yc, wc)
        coef[p] = best
        score[p] = honest
        if not abs(honest - max(best_score, 0.0)) <= check_rtol * total:
            status[p] = 1
    return coef, score, status
