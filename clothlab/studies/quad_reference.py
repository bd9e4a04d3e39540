"""Reference values of the yarn integral f_c I_j (Irawan & Marschner 2012, sec. 5, eq. 10) by
scipy.integrate.quad, the yardstick of the quadrature benchmarks.

The compiled integrand of :mod:`clothlab.models.irawan.kernels` is integrated node by node per direction
pair, with breakpoints at the closed-form support ends and visibility cuts (epsrel 1e-10), and multiplied by
the phase function (eq. 7).
"""

from __future__ import annotations

import math
import warnings

import numpy as np


def quad_reference(wi, wo, params, kind):
    """f_c I_j by scipy.integrate.quad per direction pair, integrating the compiled integrand node by node."""
    from scipy.integrate import quad

    from clothlab.frames import to_yarn_frame
    from clothlab.models.irawan import kernels
    from clothlab.models.irawan.model import PSI_FILAMENT_THRESHOLD
    from clothlab.models.irawan.phase import phase_function
    from clothlab.models.irawan.yarn import _filament_breaks, half_vectors, staple_breaks

    psi = math.radians(params[f"{kind}.psi"])
    umax = math.radians(params[f"{kind}.umax"])
    kappa, w, l, delta = params[f"{kind}.kappa"], params[f"{kind}.w"], params[f"{kind}.l"], params["delta"]
    lw, lo = to_yarn_frame(wi, kind), to_yarn_frame(wo, kind)
    staple = abs(psi) >= PSI_FILAMENT_THRESHOLD
    h, _ = half_vectors(lw, lo)
    breaks = staple_breaks(lw, lo, psi, umax)[0] if staple else _filament_breaks(lw, lo, h)
    one = np.ones((1, 1))
    out = np.zeros(len(wi))
    for n in range(len(wi)):
        a, b = lw[n:n + 1], lo[n:n + 1]
        if staple:
            def f(u, a=a, b=b):
                return kernels.staple_quadrature(a, b, np.array([[u]]), one, psi, umax, kappa, w, l)[0]
        else:
            def f(v, a=a, b=b):
                return kernels.filament_quadrature(a, b, np.array([[v]]), one, umax, kappa, w, l, delta, False,
                                                   False)[0]
        edges = np.unique(breaks[n])
        total = 0.0
        for lo_, hi_ in zip(edges[:-1], edges[1:], strict=True):
            total += quad(f, lo_, hi_, epsabs=0.0, epsrel=1e-10, limit=200)[0]
        out[n] = total
    return out * phase_function(wi, wo, params["alpha"], params["beta"])


def converged_reference(wi, wo, params, kind) -> tuple[np.ndarray, int]:
    """f_c I_j per direction by :func:`quad_reference`; where quad raises an IntegrationWarning the
    ``adaptive`` rule's value is used instead.  Returns the values and the number of such directions."""
    from scipy.integrate import IntegrationWarning

    from clothlab.models.irawan.model import Quadrature, yarn_specular

    out = np.empty(len(wi))
    warned = []
    for n in range(len(wi)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", IntegrationWarning)
            out[n] = quad_reference(wi[n:n + 1], wo[n:n + 1], params, kind)[0]
        if any(issubclass(c.category, IntegrationWarning) for c in caught):
            warned.append(n)
    if warned:
        idx = np.array(warned)
        out[idx] = yarn_specular(wi[idx], wo[idx], params, kind, Quadrature("adaptive", 8))
    return out, len(warned)
