"""Lambert's ideal diffuse reflector (``kind: lambert``): the simplest baseline beside the cloth models.

    f_r(wi, wo) = kd / pi      for front-facing pairs (wi_z > 0 and wo_z > 0), 0 otherwise

One component, ``diffuse`` = 1/pi (unit albedo); its coefficient kd (per channel) is the albedo and is solved
linearly by the fit.  The model has no non-linear parameter, so a fit of it frees nothing (``fit.free: []``).

=========  ====  =====  =======  =======
parameter  unit  range  default  meaning
=========  ====  =====  =======  =======
(none)
=========  ====  =====  =======  =======
"""

from __future__ import annotations

import numpy as np

from clothlab.models.base import ISOTROPIC, Model, as_directions, front_facing
from clothlab.params import ParamTable


class LambertModel(Model):
    """Lambert's law: a constant BRDF 1/pi times the albedo kd (no parameters, no options)."""

    kind = "lambert"
    params = ParamTable([])
    component_names = ("diffuse",)
    coefficient_meaning = "kd: diffuse albedo (Lambert)"
    default_free = ()
    orientation_period = ISOTROPIC  # f_r does not depend on the azimuths

    def _default_parameters(self) -> dict[str, float]:
        return {}

    def _components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                    warn: bool = True) -> dict[str, np.ndarray]:
        """``diffuse`` = 1/pi (1/sr) at front-facing pairs of the (N, 3) fabric-frame directions, else 0.

        ``normalised`` and ``warn`` are accepted for the interface: the component already has unit albedo
        and raises no warnings."""
        self.resolve(params)  # validates: the model has no parameter, so any name is unknown
        wi, wo = as_directions(wi, wo)
        if need is not None and "diffuse" not in need:
            return {}
        return {"diffuse": np.where(front_facing(wi, wo), 1.0 / np.pi, 0.0)}
