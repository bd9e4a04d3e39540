"""Compiled (numba) box sums over periodic summed-area tables (:mod:`clothlab.footprint.sat`).

For footprint k: the four-corner difference I(x1, y1) - I(x0, y1) - I(x1, y0) + I(x0, y0) of the periodic
integral I(x, y) = B(rx, ry) + nx B(Ru, ry) + ny B(rx, Rv) + nx ny B(Ru, Rv) (bilinear B of the table;
x = nx Ru + rx, y = ny Rv + ry, texel units), for every column of the stacked tables at once.  Imported
lazily (numba); cached on disk.  Serial: one query is ~40 multiply-adds per column.
"""

from __future__ import annotations

import math

import numpy as np

from clothlab.models.jit import njit


@njit(cache=True, inline="always")
def _add_integral(stack, base, r_u, r_v, x, y, sign, out, k):
    width = r_u + 1
    nx = math.floor(x / r_u)
    ny = math.floor(y / r_v)
    rx = min(max(x - nx * r_u, 0.0), float(r_u))
    ry = min(max(y - ny * r_v, 0.0), float(r_v))
    i0 = min(int(math.floor(rx)), r_u - 1)
    j0 = min(int(math.floor(ry)), r_v - 1)
    a = rx - i0
    b = ry - j0
    row0 = base + j0 * width
    row1 = row0 + width
    last = base + r_v * width
    w00, w10, w01, w11 = (1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b
    for c in range(stack.shape[1]):
        bilinear = (w00 * stack[row0 + i0, c] + w10 * stack[row0 + i0 + 1, c]
                    + w01 * stack[row1 + i0, c] + w11 * stack[row1 + i0 + 1, c])
        column = (1.0 - b) * stack[row0 + r_u, c] + b * stack[row1 + r_u, c]  # B(Ru, ry)
        row = (1.0 - a) * stack[last + i0, c] + a * stack[last + i0 + 1, c]  # B(rx, Rv)
        out[k, c] += sign * (bilinear + nx * column + ny * row + nx * ny * stack[last + r_u, c])


@njit(cache=True)
def box_sums(stack, pair, r_u, r_v, x0, x1, y0, y1):
    """(N, C) box integrals (texel units) of the stacked tables ``stack`` (P (Rv + 1) (Ru + 1), C) for
    footprints [x0, x1] x [y0, y1] of pairs ``pair`` (N,)."""
    n = pair.shape[0]
    out = np.zeros((n, stack.shape[1]))
    size = (r_u + 1) * (r_v + 1)
    for k in range(n):
        base = pair[k] * size
        _add_integral(stack, base, r_u, r_v, x1[k], y1[k], 1.0, out, k)
        _add_integral(stack, base, r_u, r_v, x0[k], y1[k], -1.0, out, k)
        _add_integral(stack, base, r_u, r_v, x1[k], y0[k], -1.0, out, k)
        _add_integral(stack, base, r_u, r_v, x0[k], y0[k], 1.0, out, k)
    return out
