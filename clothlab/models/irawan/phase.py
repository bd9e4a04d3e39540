"""Circular phase function of the fibres (Irawan & Marschner 2012, sec. 6.5, eq. 7).

f_c = alpha + g(-wi.wo, beta),  g(cos x, b) = exp(b cos x) / (2 pi I0(b)).

g is evaluated as exp(b (cos x - 1)) / (2 pi i0e(b)) with scipy's exponentially scaled Bessel function
i0e(b) = exp(-b) I0(b), which cannot overflow for any b >= 0 (exp(b) / I0(b) is inf / inf in float64 for
b above ~709).  f_c depends on wi.wo only, so it factors out of the yarn integral of eq. 10 and is applied
outside the compiled kernels (numpy, vectorised over all directions).
"""

from __future__ import annotations

import numpy as np
from scipy.special import i0e


def von_mises(cos_x, beta):
    """g(cos x, beta) of eq. 7 [1/rad], normalised over the circle; stable for beta up to float64 range."""
    cos_x = np.clip(cos_x, -1.0, 1.0)
    return np.exp(beta * (cos_x - 1.0)) / (2.0 * np.pi * i0e(beta))  # eq. 7: g


def phase_function(wi, wo, alpha, beta):
    """f_c(wi, wo) = alpha + g(-wi.wo, beta) (eq. 7) [1/rad]; wi, wo (..., 3) unit vectors."""
    cos_x = -np.einsum("...k,...k->...", wi, wo)
    return alpha + von_mises(cos_x, beta)  # eq. 7
