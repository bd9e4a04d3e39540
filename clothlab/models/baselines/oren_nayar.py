"""The Oren-Nayar rough diffuse reflector (``kind: oren-nayar``): Oren & Nayar 1994, "Generalization of
Lambert's reflectance model", SIGGRAPH: the qualitative model (eq. 30).

The surface is a collection of long symmetric V-cavities, each facet Lambertian, with facet slopes normally
distributed with zero mean and standard deviation sigma.  Eq. 30 gives the radiance for irradiance E0
cos(theta_i); divided by it, the BRDF is

    f_r(wi, wo) = (kd / pi) [A + B max(0, cos(phi_o - phi_i)) sin(alpha) tan(beta)],
    A = 1 - 0.5 sigma^2 / (sigma^2 + 0.33),   B = 0.45 sigma^2 / (sigma^2 + 0.09)

with alpha = max(theta_i, theta_o), beta = min(theta_i, theta_o), sigma in radians, kd the facet albedo
(rho of the paper).  Since sin(alpha) sin(beta) = sin(theta_i) sin(theta_o), the directional factor is
evaluated without angles as  max(0, cos(phi_o - phi_i)) sin(alpha) tan(beta) = max(0, wi_xy . wo_xy) /
max(cos theta_i, cos theta_o)  (no division by zero at the pole; symmetric in wi, wo, so f_r is reciprocal).

Why the qualitative model and not the full one (eqs. 27-29 with the interreflection term): the
interreflection term is proportional to rho^2, so the full model is not linear in the albedo and kd could
not be solved by non-negative least squares like every other coefficient; eq. 30 is the paper's own
simplification, linear in rho.  At sigma = 0, A = 1 and B = 0: Lambert's law.  Front-facing pairs only
(reflection; 0 where wi_z <= 0 or wo_z <= 0).

=========  ====  =======  =======  ================================================================
parameter  unit  range    default  meaning
=========  ====  =======  =======  ================================================================
sigma      deg   [0, 90)  20       roughness: standard deviation of the facet slope angle
=========  ====  =======  =======  ================================================================

One component, ``diffuse`` (1/sr, the bracket over pi; its albedo is below 1 for sigma > 0); its coefficient
kd (per channel) is the facet albedo.
"""

from __future__ import annotations

import numpy as np

from clothlab.models.base import ISOTROPIC, Model, as_directions, front_facing
from clothlab.params import ParamSpec, ParamTable

OREN_NAYAR_PARAMS = ParamTable([
    ParamSpec("sigma", "deg", (0.0, 90.0), (0.0, 60.0), 20.0, "linear",
              "roughness: standard deviation of the facet slope angle (Oren & Nayar 1994, eq. 30)",
              open_upper=True),
])


def oren_nayar_ab(sigma_deg: float) -> tuple[float, float]:
    """A and B of eq. 30 for the roughness sigma (degrees)."""
    s2 = np.deg2rad(sigma_deg) ** 2
    return 1.0 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)


class OrenNayarModel(Model):
    """Oren & Nayar's qualitative rough-diffuse model (eq. 30): one parameter sigma, one component."""

    kind = "oren-nayar"
    params = OREN_NAYAR_PARAMS
    parameter_concepts = {"diffuse roughness (Oren & Nayar eq. 30)": ("sigma",)}
    component_names = ("diffuse",)
    coefficient_meaning = "kd: facet albedo (rho of Oren & Nayar 1994, eq. 30)"
    default_free = ("sigma",)
    orientation_period = ISOTROPIC  # f_r depends on the azimuths only through phi_o - phi_i

    def _default_parameters(self) -> dict[str, float]:
        return {spec.name: float(spec.default) for spec in self.params}

    def _components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                    warn: bool = True) -> dict[str, np.ndarray]:
        """``diffuse`` (1/sr) = [A + B max(0, cos dphi) sin(alpha) tan(beta)] / pi at (N, 3) fabric-frame
        directions (eq. 30, module docstring); 0 for back-facing pairs.  ``normalised`` and ``warn`` are
        accepted for the interface (the component is kd's factor as the paper defines it; no warnings)."""
        p = self.resolve(params)
        wi, wo = as_directions(wi, wo)
        if need is not None and "diffuse" not in need:
            return {}
        a, b = oren_nayar_ab(p["sigma"])
        front = front_facing(wi, wo)
        cos_max = np.maximum(wi[:, 2], wo[:, 2])
        lateral = np.maximum(wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1], 0.0)
        factor = np.divide(lateral, cos_max, out=np.zeros(len(wi)), where=front)
        return {"diffuse": np.where(front, (a + b * factor) / np.pi, 0.0)}
