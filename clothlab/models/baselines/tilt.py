"""A tilted sample plane: the measured BRDF of a flat sample whose normal is not the table's z axis
(issue 28 item 5; docs/select.md, "Residual diagnostics of the default winners").

A gonioreflectometer reduces a radiance L to a BRDF with the irradiance of the *nominal* geometry,
E0 cos theta_i.  If the sample's own normal n is tilted by tau from the nominal z axis, the sample sees the
directions wi' = T^-1 wi, wo' = T^-1 wo (T: the rotation taking z to n) and receives E0 (n . wi), so the table
holds

    f_table(wi, wo) = f(T^-1 wi, T^-1 wo) (n . wi) / cos theta_i                                       (1)

(the definition of the BRDF, Nicodemus et al. 1977, NBS Monograph 160, eq. 1 - dL_r = f_r dE_i - with the
irradiance dE_i = L_i (n . wi) dw_i of the tilted surface).  Any model whose reflectance has a symmetry the
tilt breaks shows it: a woven model is unchanged by a half turn about the normal (period 180 deg), an isotropic
one by any turn, but (1) is not - a direction on the side the normal leans toward is less grazing than the
same polar angle on the other side (the in-plane CUReT pairs related by a half turn and reciprocity differ by
up to 28 %, the darker side the same on both shared fabrics).

The tilt is given by the components of the tilt vector, tau = sqrt(tilt.x^2 + tilt.y^2) toward azimuth
atan2(tilt.y, tilt.x), in the frame the model is evaluated in (:mod:`clothlab.models.composite.terms` applies
it in the weave's frame, so its table azimuth is that plus ``orientation``).  Components (not polar angles)
keep the parameters determined at tau = 0, where an azimuth would have no effect.

==========  ====  ==========  =======  ==========================================================
parameter   unit  range       default  meaning
==========  ====  ==========  =======  ==========================================================
tilt.x      deg   [-10, 10]   0        x component of the sample normal's tilt (fit bounds +-5 deg)
tilt.y      deg   [-10, 10]   0        y component of the sample normal's tilt (fit bounds +-5 deg)
==========  ====  ==========  =======  ==========================================================
"""

from __future__ import annotations

import numpy as np

from clothlab.params import ParamSpec, ParamTable

TILT_PARAMS = ParamTable([
    ParamSpec("tilt.x", "deg", (-10.0, 10.0), (-5.0, 5.0), 0.0, "linear",
              "x component of the tilt of the sample's normal from the table's z axis (eq. 1)"),
    ParamSpec("tilt.y", "deg", (-10.0, 10.0), (-5.0, 5.0), 0.0, "linear",
              "y component of the tilt of the sample's normal from the table's z axis (eq. 1)"),
])
TILT_FREE = ("tilt.x", "tilt.y")


def tilted_normal(tilt_x: float, tilt_y: float) -> np.ndarray:
    """The sample's normal n (3,) for the tilt vector (deg): tau = |(tilt_x, tilt_y)| toward its azimuth."""
    tau = np.radians(np.hypot(tilt_x, tilt_y))
    phi = np.arctan2(tilt_y, tilt_x)
    return np.array([np.sin(tau) * np.cos(phi), np.sin(tau) * np.sin(phi), np.cos(tau)])


def to_sample_frame(wi: np.ndarray, wo: np.ndarray, tilt_x: float, tilt_y: float):
    """(wi', wo', factor) of eq. (1): the (N, 3) unit directions in the tilted sample's frame (T^-1 w, T the
    rotation about z x n by tau, Rodrigues' formula) and the irradiance factor (n . wi) / cos theta_i, 0 where
    the tilted surface faces away from wi or wo.  No tilt: the directions themselves and factor 1."""
    n = tilted_normal(tilt_x, tilt_y)
    if n[2] == 1.0:
        return wi, wo, np.ones(len(wi))
    axis = np.array([-n[1], n[0], 0.0]) / np.hypot(n[0], n[1])  # z x n, normalised
    c, s = n[2], np.hypot(n[0], n[1])  # cos tau, sin tau

    def inverse(w):  # rotation by -tau about the axis
        return w * c - np.cross(axis, w) * s + np.outer(w @ axis, axis) * (1.0 - c)

    cos_true = wi @ n
    front = (wi[:, 2] > 0) & (cos_true > 0) & (wo @ n > 0)
    factor = np.divide(cos_true, wi[:, 2], out=np.zeros(len(wi)), where=front)
    return inverse(wi), inverse(wo), factor
