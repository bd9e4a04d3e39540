"""Kang's point shader behind the texture-model interface (:mod:`clothlab.models.base`).

:class:`KangTexture` evaluates :meth:`KangModel.point_components` at texture points (u, v): full yarn
detail without a footprint, the eq. 5 blend with one, and Algorithm 1 (adaptive prefiltering) when a view
distance is given too.  ``noise=False`` switches the per-yarn intensity noise off (parameter ``noise`` = 0).
"""

from __future__ import annotations

import numpy as np

from clothlab.models.base import ModelTexture
from clothlab.models.components import combine


class KangTexture(ModelTexture):
    """The texture model of a :class:`~clothlab.models.kang.model.KangModel` (it filters itself: eq. 5)."""

    component_attribute = "point_component_names"

    def _components(self, u, v, wi, wo, params: dict | None = None, *, need=None, noise: bool = True,
                    normalised: bool = True, warn: bool = True, footprint=None,
                    view_distance=None) -> dict[str, np.ndarray]:
        """Point components (1/sr, (N,)) at texture points u, v (tiles) for (N, 3) direction pairs;
        ``footprint`` (tiles) and ``view_distance`` as :meth:`KangModel.point_components`.  ``normalised``
        and ``warn`` exist for interface parity (the components are in albedo units, no warnings)."""
        p = self.model.resolve(params)
        if not noise:
            p = {**p, "noise": 0.0}
        comps = self.model.point_components(u, v, wi, wo, p, footprint, view_distance=view_distance)
        return comps if need is None else {k: c for k, c in comps.items() if k in need}

    def evaluate(self, u, v, wi, wo, coefficients: dict, params: dict | None = None, *,
                 noise: bool = True) -> np.ndarray:
        """f_r (N, C) = sum_k coefficients[k] * component_k at texture points (full yarn detail)."""
        return combine(self.components(u, v, wi, wo, params, noise=noise), coefficients)
