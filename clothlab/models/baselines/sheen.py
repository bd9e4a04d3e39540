"""A fibre sheen term: the grazing, back-scattering glow of fibres standing out of the surface (issue 28 item 5).

The microfibre ("Charlie") distribution of Estevez & Kulla 2017, "Production friendly microfacet sheen BRDF"
(SIGGRAPH course), for fibres whose cross sections act as facets whose normals lie near the surface plane:

    D(h) = (2 + 1/r) sin(theta_h)^(1/r) / (2 pi),        r in (0, 1]: small r, sheen only at grazing h,

in the distribution-based BRDF of Ashikhmin & Premoze 2007, "Distribution-based BRDFs" (tech. report, Univ.
of Utah), whose denominator replaces the microfacet shadowing term for such a distribution:

    f_sheen(wi, wo) = D(h) / (4 (cos theta_i + cos theta_o - cos theta_i cos theta_o)).

h = (wi + wo) / |wi + wo|; theta_h is large when both directions are grazing and on the same side (the
retro-reflective sheen of velvet and pile fabrics, Lu et al. 1998, cited by Irawan & Marschner 2012 sec. 2).
D is normalised for every r: int D(h) cos(theta_h) dw_h = (2 + 1/r) int_0^(pi/2) sin^(1/r + 1) cos dtheta = 1
over the hemisphere of h; the component's absolute scale is its coefficient's.  f is symmetric in wi, wo
(reciprocal), non-negative, 0 for back-facing pairs, and depends on the azimuths only through h (isotropic).
The equation numbers of the two sources are not given: neither paper is in /work/shared/papers.

==========  ====  =========  =======  ==========================================================
parameter   unit  range      default  meaning
==========  ====  =========  =======  ==========================================================
sheen.r     1     [0.05, 1]  0.5      sheen roughness r of the microfibre distribution D
==========  ====  =========  =======  ==========================================================

One component, ``sheen`` (1/sr); its coefficient ``sheen`` (per channel) is solved linearly like kd and ks.
"""

from __future__ import annotations

import numpy as np

from clothlab.models.base import ISOTROPIC, Model, as_directions, front_facing
from clothlab.params import ParamSpec, ParamTable

SHEEN_PARAMS = ParamTable([
    ParamSpec("sheen.r", "1", (0.05, 1.0), (0.05, 1.0), 0.5, "linear",
              "sheen roughness r of the microfibre distribution (Estevez & Kulla 2017)"),
])


def sheen_lobe(wi: np.ndarray, wo: np.ndarray, r: float) -> np.ndarray:
    """f_sheen (1/sr, module docstring) at (N, 3) unit fabric-frame directions; 0 for back-facing pairs."""
    front = front_facing(wi, wo)
    h = wi + wo
    norm = np.linalg.norm(h, axis=1)
    cos_h = np.divide(h[:, 2], norm, out=np.ones(len(wi)), where=norm > 0)
    sin_h = np.sqrt(np.clip(1.0 - cos_h * cos_h, 0.0, 1.0))
    d = (2.0 + 1.0 / r) * sin_h ** (1.0 / r) / (2.0 * np.pi)
    ci, co = wi[:, 2], wo[:, 2]
    denominator = 4.0 * (ci + co - ci * co)
    return np.where(front, np.divide(d, denominator, out=np.zeros(len(wi)), where=denominator > 0), 0.0)


class SheenModel(Model):
    """The sheen lobe alone (module docstring): one parameter ``sheen.r``, one component ``sheen``; used as an
    added term (:mod:`clothlab.models.composite.terms`, kinds ``...+sheen``), not registered as a kind."""

    kind = "sheen"
    params = SHEEN_PARAMS
    component_names = ("sheen",)
    coefficient_meaning = "sheen: scale of the microfibre sheen lobe (Estevez & Kulla 2017)"
    default_free = ("sheen.r",)
    orientation_period = ISOTROPIC

    def _default_parameters(self) -> dict[str, float]:
        return {spec.name: float(spec.default) for spec in self.params}

    def _components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                    warn: bool = True) -> dict[str, np.ndarray]:
        """``sheen`` (1/sr) at (N, 3) fabric-frame directions (``normalised``, ``warn``: for the interface)."""
        p = self.resolve(params)
        wi, wo = as_directions(wi, wo)
        if need is not None and "sheen" not in need:
            return {}
        return {"sheen": sheen_lobe(wi, wo, p["sheen.r"])}
