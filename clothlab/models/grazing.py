"""Grazing-angle factors of a surface's specular reflection: Fresnel reflectance and shadowing-masking
(issue 28 item 5), applied to the specular components of any kind by :mod:`clothlab.models.composite.terms`.

Fresnel (Schlick 1994, "An inexpensive BRDF model for physically-based rendering", Computer Graphics Forum
13(3), eq. 24): the reflectance of a dielectric of index eta at incidence angle theta_d,

    F(cos theta_d) = F0 + (1 - F0) (1 - cos theta_d)^5,      F0 = ((eta - 1) / (eta + 1))^2.

At a yarn's highlight the fibre surface mirrors wi into wo, so its local normal is the half vector h and
the incidence angle is theta_d with cos theta_d = wi . h (the Irawan-Marschner model has no Fresnel term:
Irawan & Marschner 2012, sec. 6.5-7.1, the constants are absorbed into k_s).

Shadowing-masking (Smith; the GGX form of Walter, Marschner, Li & Torrance 2007, "Microfacet models for
refraction through rough surfaces", EGSR, eq. 34), separable in the two directions (their eq. 23):

    G1(w) = 2 / (1 + sqrt(1 + alpha^2 tan^2 theta_w)),        G(wi, wo) = G1(wi) G1(wo),

for the fabric's surface of yarn crowns seen as a rough surface of RMS slope ~ alpha (alpha = 0: G = 1).  IM
sec. 7.1 ignores shadowing and masking; their Fig. 14 shows the darkening it causes on denim at grazing view.

By default ``smith.alpha`` is 0 (no shadowing: Fresnel alone); kinds ``...+fresnel-smith`` free it, kinds
``...+fresnel-eta`` free ``fresnel.eta`` instead.  The factor
applied to a specular component is F(wi . h) / F0 * G(wi, wo): 1 at normal incidence on a smooth
surface, so a coefficient keeps its meaning there (F0 taken out: the absolute scale is the coefficient's).
Both factors are symmetric in wi, wo, so a reciprocal model stays reciprocal.

=============  ====  ==========  =======  ==========================================================
parameter      unit  range       default  meaning
=============  ====  ==========  =======  ==========================================================
fresnel.eta    1     [1.01, 3]   1.55     refractive index of the fibre (polyester 1.57-1.64, cotton ~1.53)
smith.alpha    1     [0, 2]      0        GGX roughness of the shadowing surface (Walter et al. eq. 34)
=============  ====  ==========  =======  ==========================================================
"""

from __future__ import annotations

import numpy as np

from clothlab.params import ParamSpec, ParamTable

GRAZING_PARAMS = ParamTable([
    ParamSpec("fresnel.eta", "1", (1.01, 3.0), (1.2, 2.0), 1.55, "linear",
              "refractive index of the fibre in Schlick's Fresnel approximation (Schlick 1994, eq. 24)"),
    ParamSpec("smith.alpha", "1", (0.0, 2.0), (0.0, 1.5), 0.0, "linear",
              "GGX roughness of the Smith shadowing-masking (Walter et al. 2007, eq. 34); 0: none"),
])
#: what a fit frees by default: nothing for Fresnel alone (the refractive index stays at its physical value, no
#: shadowing: smith.alpha 0); the shadowing roughness for Fresnel with shadowing-masking
FRESNEL_FREE = ()
FRESNEL_SMITH_FREE = ("smith.alpha",)
#: the refractive index freed (kinds ``...+fresnel-eta``: the grazing rise's strength fitted, docs/select.md)
FRESNEL_ETA_FREE = ("fresnel.eta",)


def schlick_fresnel(cos_d: np.ndarray, eta: float) -> np.ndarray:
    """Schlick's Fresnel reflectance (Schlick 1994, eq. 24) at cos theta_d (clipped to [0, 1])."""
    f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    return f0 + (1.0 - f0) * (1.0 - np.clip(cos_d, 0.0, 1.0)) ** 5


def smith_g1(cos_t: np.ndarray, alpha: float) -> np.ndarray:
    """The GGX Smith masking G1 (Walter et al. 2007, eq. 34) at cos theta (0 at or below the horizon)."""
    c = np.clip(cos_t, 0.0, 1.0)
    tan2 = np.divide(1.0 - c * c, c * c, out=np.full_like(c, np.inf), where=c > 0)
    return np.where(c > 0, 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * tan2)), 0.0)


def grazing_factor(wi: np.ndarray, wo: np.ndarray, eta: float, alpha: float) -> np.ndarray:
    """F(wi . h) / F0 * G1(wi) G1(wo) (module docstring) at (N, 3) unit directions; 0 where wi + wo = 0."""
    h = wi + wo
    norm = np.linalg.norm(h, axis=1)
    cos_d = np.divide(np.einsum("ij,ij->i", wi, h), norm, out=np.zeros(len(wi)), where=norm > 0)
    f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    return schlick_fresnel(cos_d, eta) / f0 * smith_g1(wi[:, 2], alpha) * smith_g1(wo[:, 2], alpha)
