"""Experimental quadrature rule for the benchmark only: ``split`` (support pieces found inside the kernel).

Same integrands as :mod:`clothlab.models.irawan.kernels` (eqs. 3-9 of Irawan & Marschner 2012, called
through its compiled ``staple_value`` / ``spine_radius_scalar``), same breakpoints as the ``support`` rule
(:mod:`clothlab.models.irawan.yarn`), but:

* the breakpoints are computed per direction inside the compiled loop (no (N, P) numpy temporaries, no
  sort of 20 candidates per direction in numpy), which is where the ``support`` rule spends most of its time;
* pieces on which the integrand is identically zero are skipped: for staple yarns the support indicator
  |D| <= 1 and the visibility cut cos v > 0 are constant between consecutive breakpoints, so one test at the
  piece midpoint decides; for filament yarns the integrand is non-zero only where both clamped cosines
  c_i, c_r of eq. 8 are positive, a single interval of v (the intersection of two half circles with
  [-pi/2, pi/2], computed in closed form), so only that interval is integrated;
* filament pieces use plain Gauss-Legendre (the integrand is analytic inside and vanishes linearly at the
  ends); staple pieces keep the cosine end map of the ``support`` rule (square-root behaviour of v(u) at
  the support ends, eq. 3).

``n`` is the number of Gauss-Legendre nodes per non-zero piece.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from clothlab.models.irawan.kernels import spine_radius_scalar, staple_value


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
        sx, sy, sz = wix + wox, wiy + woy, wiz + woz
        length = math.sqrt(sx * sx + sy * sy + sz * sz)
        if wiz <= 0.0 or woz <= 0.0 or length <= 0.0:
            continue
        hx, hy, hz = sx / length, sy / length, sz / length
        rho = math.sqrt(hy * hy + hz * hz)
        gamma = math.atan2(hz, hy)
        c0 = math.acos(min(abs_sin_psi / rho, 1.0)) if rho > 0.0 else 0.0
        m = 0
        breaks[m] = -umax
        m += 1
        for base in (-gamma + c0, -gamma - c0, psi - gamma + 0.5 * math.pi, -psi - gamma + 0.5 * math.pi):
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
            sm, cm = math.sin(mid), math.cos(mid)
            b = hy * sm + hz * cm
            r = math.sqrt(hx * hx + b * b)
            if r <= 0.0:
                continue
            d = (hy * cm - hz * sm) * cot_psi / r
            if abs(d) > 1.0:
                continue
            root = math.sqrt(max(1.0 - d * d, 0.0))
            if (hx * d + b * root) / r <= 0.0:
                continue
            for k in range(t.shape[0]):
                u = lo + span * t[k]
                su, cu = math.sin(u), math.cos(u)
                radius = spine_radius_scalar(u, umax, kappa, w, l)
                acc += span * wt[k] * staple_value(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, su, cu, radius,
                                                   cot_psi, abs_sin_psi, a)
        out[n] = acc
    return out


def split_yarn_integral(wi, wo, *, psi, umax, kappa, w, l, delta=0.0, n=4, psi_threshold=1e-3):
    """I(wi, wo) of eq. 10 with the ``split`` rule; (N, 3) yarn-frame directions, angles in radians."""
    wi = np.ascontiguousarray(wi, dtype=np.float64)
    wo = np.ascontiguousarray(wo, dtype=np.float64)
    x, weights = np.polynomial.legendre.leggauss(int(n))
    t, wt = 0.5 * (x + 1.0), 0.5 * weights
    if abs(psi) >= psi_threshold:
        s = 0.5 * (1.0 - np.cos(np.pi * t))
        return _staple_split(wi, wo, s, wt * 0.5 * np.pi * np.sin(np.pi * t), float(psi), float(umax),
                             float(kappa), float(w), float(l))
    from clothlab.models.irawan.kernels import filament_quadrature

    # the filament half of this rule became the `support` rule's filament path (kernels.filament_quadrature)
    return filament_quadrature(wi, wo, t[None, :], wt[None, :], float(umax), float(kappa), float(w), float(l),
                               float(delta), True)
