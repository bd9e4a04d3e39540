"""Circular phase function of the fibres (Irawan & Marschner 2012, eq. 7).

f_c = alpha + g(-wi.wo, beta),  g(cos x, b) = exp(b cos x) / (2 pi I0(b)).

g is evaluated as exp(b (cos x - 1)) / (2 pi i0e(b)) with scipy's exponentially scaled Bessel function
i0e(b) = exp(-b) I0(b), which cannot overflow for any b >= 0 (numerics.md item 4).
"""

from __future__ import annotations

import numpy as np
from scipy.special import i0e


def von_mises(cos_x, beta):
    """g(cos x, beta) of eq. 7, normalised over the circle; stable for beta up to float64 range."""
    cos_x = np.clip(cos_x, -1.0, 1.0)
    return np.exp(beta * (cos_x - 1.0)) / (2.0 * np.pi * i0e(beta))


def phase_function(wi, wo, alpha, beta):
    """f_c(wi, wo) = alpha + g(-wi.wo, beta) (eq. 7); wi, wo (..., 3) unit vectors."""
    cos_x = -np.einsum("...k,...k->...", wi, wo)
    return alpha + von_mises(cos_x, beta)
