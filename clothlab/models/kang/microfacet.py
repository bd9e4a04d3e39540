"""The Ashikhmin-Shirley BRDF (paper eq. 1) with the anisotropic distribution of eq. 2.

Conventions.  ``p(h)`` of eq. 2 is the density of the half vector over solid angle (Ashikhmin & Shirley
2000): with its constant sqrt((x+1)(y+1)) / (2 pi), the integral of p(h) over the hemisphere is exactly 1.
The microfacet normal distribution in the usual sense is D(h) = p(h) / (h.n), normalised so that
the integral of D(h) (h.n) over the hemisphere is 1, and eq. 1,

    rho(k1, k2) = p(h) P(k1, k2, h) F(k.h) / (4 (k1.n) (k2.n) (n.h)) = D P F / (4 (k1.n)(k2.n)),

is the Torrance-Sparrow form.  P is the Ashikhmin-Shirley shadowing term
P = (n.h) min(k1.n, k2.n) / (k.h), which lies in [0, (n.h)^2]; it turns eq. 1 into the practical
rho = p(h) F / (4 (k.h) max(k1.n, k2.n)).  The specular albedo is then <= max F <= 1 for any x, y >= 0.

All directions are (..., 3) arrays in a frame whose z is the macro normal; distributions may be centred on a
tilted (perturbed) normal given with its tangent.
"""

from __future__ import annotations

import numpy as np


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def half_vector(wi, wo):
    """Unit half vector h = (wi + wo) / |wi + wo| (..., 3); zero where wi + wo = 0."""
    s = np.asarray(wi, dtype=np.float64) + np.asarray(wo, dtype=np.float64)
    norm = np.linalg.norm(s, axis=-1, keepdims=True)
    return np.divide(s, norm, out=np.zeros_like(s), where=norm > 0.0)


def phong_exponent(hx, hy, nx, ny):
    """Exponent x cos^2 phi + y sin^2 phi of eq. 2, phi the azimuth of h about the lobe normal."""
    sin2 = hx * hx + hy * hy
    return np.divide(nx * hx * hx + ny * hy * hy, sin2, out=np.zeros(np.broadcast(hx, sin2).shape),
                     where=sin2 > 1e-300)


def half_vector_pdf(h, nx, ny, normal=None, tangent=None):
    """Eq. 2: p(h) = sqrt((x+1)(y+1)) / (2 pi) (h.n)^(x cos^2 phi + y sin^2 phi), in 1/sr.

    ``normal`` (unit, default +z) is the lobe's normal; ``tangent`` (unit, perpendicular to it, default +x
    projected) gives phi = 0, the axis of exponent ``nx``.  Zero where h.n <= 0.
    """
    h = np.asarray(h, dtype=np.float64)
    if normal is None:
        hx, hy, hz = h[..., 0], h[..., 1], h[..., 2]
    else:
        bitangent = np.cross(normal, tangent)
        hx, hy, hz = _dot(h, tangent), _dot(h, bitangent), _dot(h, normal)
    e = phong_exponent(hx, hy, nx, ny)
    positive = hz > 0.0
    power = np.exp(e * np.log(np.where(positive, hz, 1.0)))
    scale = np.sqrt((np.asarray(nx) + 1.0) * (np.asarray(ny) + 1.0)) / (2.0 * np.pi)
    return np.where(positive, scale * power, 0.0)


def microfacet_distribution(h, nx, ny):
    """D(h) = p(h) / (h.n) about +z: the integral of D(h) (h.n) over the hemisphere is 1 (1/sr)."""
    h = np.asarray(h, dtype=np.float64)
    hz = h[..., 2]
    p = half_vector_pdf(h, nx, ny)
    return np.divide(p, hz, out=np.zeros_like(p), where=hz > 0.0)


def schlick_fresnel(cos_kh, f0):
    """Schlick's approximation F = F0 + (1 - F0) (1 - k.h)^5 (eq. 1, F)."""
    c = np.clip(cos_kh, 0.0, 1.0)
    return f0 + (1.0 - f0) * (1.0 - c) ** 5


def shadowing(cos_i, cos_o, cos_nh, cos_kh):
    """Ashikhmin-Shirley shadowing P = (n.h) min(k1.n, k2.n) / (k.h), in [0, 1] (eq. 1, P)."""
    num = cos_nh * np.minimum(cos_i, cos_o)
    return np.divide(num, cos_kh, out=np.zeros(np.broadcast(num, cos_kh).shape), where=cos_kh > 0.0)


def ashikhmin_shirley(wi, wo, pdf_h, f0):
    """Eq. 1 for half-vector density values ``pdf_h`` (eq. 2, any lobe normal), macro normal +z; 1/sr.

    Evaluated in the equivalent form p F / (4 (k.h) max(k1.n, k2.n)) (P / (n.h) in closed form), which
    stays finite where n.h -> 0.  Zero where wi.z <= 0 or wo.z <= 0.  Symmetric in wi, wo.
    """
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    cos_i, cos_o = wi[..., 2], wo[..., 2]
    h = half_vector(wi, wo)
    cos_kh = _dot(wi, h)
    visible = (cos_i > 0.0) & (cos_o > 0.0) & (cos_kh > 0.0)
    denom = 4.0 * cos_kh * np.maximum(cos_i, cos_o)
    value = np.divide(pdf_h * schlick_fresnel(cos_kh, f0), denom,
                      out=np.zeros(np.broadcast(pdf_h, denom).shape), where=visible & (denom > 0.0))
    return np.where(visible, value, 0.0)
