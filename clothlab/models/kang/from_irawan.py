"""A scene's Irawan-Marschner fabric as the Kang shader (the ``kang-*`` shaders of a scene without
``fabric.kang.fit``): the same weave, Kang's parameters as given (its defaults otherwise), and the IM
coefficients per yarn type - kd_warp = kd_weft = kd, ks_warp and ks_weft kept (Kang's point components carry
a diffuse and a specular colour per yarn type, sec. 4.2.1).  Reached through
:func:`clothlab.models.registry.from_irawan`."""

from __future__ import annotations

from clothlab.models.components import per_yarn_coefficients
from clothlab.models.kang.model import KangModel


def from_irawan(weave, coefficients: dict, params: dict | None = None):
    """(KangModel for ``weave``, its resolved parameters ``params``, the IM ``coefficients`` per yarn type)."""
    model = KangModel.from_config(weave)
    return model, model.resolve(params), per_yarn_coefficients(coefficients)
