"""A scene's Irawan-Marschner fabric as the fabric surface model (the ``surface-*`` shaders of a scene whose
fabric is not of kind surface): the same weave, the surface model's parameters as given (its defaults
otherwise), and the IM coefficients per yarn type - kd_warp = kd_weft = kd, ks_warp and ks_weft kept (Chen,
Wang & Wang 2024, eq. 1: a diffuse and a specular albedo per yarn type).  Reached through
:func:`clothlab.models.registry.from_irawan`."""

from __future__ import annotations

from clothlab.models.components import per_yarn_coefficients
from clothlab.models.surface.model import SurfaceModel


def from_irawan(weave, coefficients: dict, params: dict | None = None):
    """(SurfaceModel for ``weave``, its resolved parameters ``params``, the IM ``coefficients`` per yarn type)."""
    model = SurfaceModel.from_config(weave)
    return model, model.resolve(params), per_yarn_coefficients(coefficients)
