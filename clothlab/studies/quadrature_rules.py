"""Experimental quadrature rule for the benchmark only: ``split`` (support pieces found inside the kernel).

Same integrands as the model (the equation helpers of :mod:`clothlab.models.irawan.kernels`: eqs. 3-9 of
Irawan & Marschner 2012) and the same breakpoints as the ``support`` rule (``staple_break_angles``), but:

* the breakpoints are computed per direction inside the compiled loop (no (N, P) numpy temporaries, no
  sort of 20 candidates per direction in numpy), which is where the ``support`` rule spends most of its time;
* pieces on which the integrand is identically zero are skipped: for staple yarns the support indicator
  |D| <= 1 of eq. 3 and the visibility cut cos v > 0 are constant between consecutive breakpoints, so one
  test at the piece midpoint decides;
* staple pieces keep the cosine end map of the ``support`` rule (square-root behaviour of v(u) at the
  support ends, eq. 3).  The filament half of this rule became the ``support`` rule's filament path
  (Gauss-Legendre on the arc where both clamped cosines of eq. 8 are positive), which it calls.

``n`` is the number of Gauss-Legendre nodes per non-zero piece.  Numba caches this module's kernel by this
file only: after editing an inlined helper in ``kernels``, clear the cache (``__pycache__/*.nbi``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from clothlab.models.irawan.kernels import (
    half_vector,
    specular_v,
    spine_radius,
    staple_break_angles,
    staple_integrand,
)
from clothlab.models.irawan.quadrature import cosine_mapped_unit_rule, unit_rule


@njit(cache=True)
def _staple_split(wi, wo, t, wt, psi, umax, kappa, w, l):
    n_dir = wi.shape[0]
    out = np.zeros(n_dir)
    cot_psi = math.cos(psi) / math.sin(psi)
    abs_sin_psi = abs(math.sin(psi))
    a = 0.5 * w
    breaks = np.empty(22)
    for n in range(n_dir):
        wix, wiy, wiz = wi[n, 0], wi[n, 1], wi[n, 2]
        wox, woy, woz = wo[n, 0], wo[n, 1], wo[n, 2]
        hx, hy, hz, length = half_vector(wix, wiy, wiz, wox, woy, woz)
        if wiz <= 0.0 or woz <= 0.0 or length <= 0.0:
            continue
        m = 0
        breaks[m] = -umax
        m += 1
        for base in staple_break_angles(hy, hz, psi, abs_sin_psi):
            for k in range(-2, 3):
                b = base + k * math.pi
                if -umax < b < umax:
                    breaks[m] = b
                    m += 1
        breaks[m] = umax
        m += 1
        # insertion sort of the few breakpoints
        for i in range(1, m):
            x = breaks[i]
            j = i - 1
            while j >= 0 and breaks[j] > x:
                breaks[j + 1] = breaks[j]
                j -= 1
            breaks[j + 1] = x
        acc = 0.0
        for p in range(m - 1):
            lo, hi = breaks[p], breaks[p + 1]
            span = hi - lo
            if span <= 0.0:
                continue
            mid = 0.5 * (lo + hi)
            found, cos_v, _ = specular_v(hx, hy, hz, math.sin(mid), math.cos(mid), cot_psi)  # eq. 3
            if not found or cos_v <= 0.0:  # outside the support or on the back of the yarn on this piece
                continue
            for k in range(t.shape[0]):
                u = lo + span * t[k]
                radius = spine_radius(u, umax, kappa, w, l)
                acc += span * wt[k] * staple_integrand(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, math.sin(u),
                                                       math.cos(u), radius, cot_psi, abs_sin_psi, a)[0]
        out[n] = acc
    return out


def split_yarn_integral(wi, wo, *, psi, umax, kappa, w, l, delta=0.0, n=4, psi_threshold=1e-3):
    """I(wi, wo) of eq. 10 with the ``split`` rule; (N, 3) yarn-frame directions, angles in radians."""
    wi = np.ascontiguousarray(wi, dtype=np.float64)
    wo = np.ascontiguousarray(wo, dtype=np.float64)
    if abs(psi) >= psi_threshold:
        s, ws = cosine_mapped_unit_rule(int(n))
        return _staple_split(wi, wo, s, ws, float(psi), float(umax), float(kappa), float(w), float(l))
    from clothlab.models.irawan.kernels import filament_quadrature

    t, wt = unit_rule("gauss", int(n))
    return filament_quadrature(wi, wo, t[None, :], wt[None, :], float(umax), float(kappa), float(w), float(l),
                               float(delta), True, False)
