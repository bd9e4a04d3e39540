"""The Kang fabric shader ("Real-time level-of-detail fabric rendering", extending Kang 2010).

Modules: parameters (declarations), microfacet (eqs. 1-2, Schlick Fresnel, shadowing), yarn (eqs. 3-4,
ambient occlusion, per-yarn noise), lod (eq. 5, Algorithm 1), model (:class:`KangModel`).
"""

from clothlab.models.kang.model import KangModel
from clothlab.models.kang.parameters import KANG_ALTERNATING_PARAMS, KANG_PARAMS, default_parameters

__all__ = ["KANG_ALTERNATING_PARAMS", "KANG_PARAMS", "KangModel", "default_parameters"]
