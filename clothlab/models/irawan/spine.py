"""Radius of curvature R(u) of a yarn segment's spine (Irawan & Marschner 2012, sec. 5.3-5.4).

The paper gives R(u) in three branches (ellipse r_hat > 0, parabola r_hat = 0, hyperbola r_hat < 0) with
r_hat = 1 + kappa (1 + cot umax) (sec. 5.4).  With a = w/2 and L = l/2 - a sin(umax) (sec. 5.3) all three
reduce to one expression in q = r_hat |r_hat| (derivation: substitute tan t = r_hat tan u, resp.
tanh t = -r_hat tan u, and eliminate a_hat, b_hat):

    R(u) = L sqrt(cot^2 umax + q) / (cos^2 u + q sin^2 u)^(3/2)

q = 1 gives the circle L / sin umax, q = 0 the parabola L cot(umax) / cos^3 u.  The form is continuous
(indeed smooth) in kappa across r_hat = 0, so fits may cross it (numerics.md item 2), and it satisfies
the spine-extent identity  integral_0^umax R(u) cos u du = L  for every q (checked in the tests).  It is
defined while cot^2 umax + q > 0, which holds exactly for kappa > -1 (the paper's range; numerics.md item 1).
"""

from __future__ import annotations

import numpy as np


def axis_ratio(kappa, umax):
    """r_hat = 1 + kappa (1 + cot umax) (sec. 5.4); umax in radians."""
    return 1.0 + kappa * (1.0 + 1.0 / np.tan(umax))


def half_length(w, l, umax):
    """L = l/2 - (w/2) sin umax, the spine's horizontal half extent (sec. 5.3); negative if the segment
    does not fit its rectangle (w sin umax >= l)."""
    return 0.5 * l - 0.5 * w * np.sin(umax)


def spine_radius(u, umax, kappa, w, l):
    """R(u) for spine curvature ``kappa`` (sec. 5.4), u and umax in radians, w and l in the same length unit.

    A segment that violates w sin(umax) < l (sec. 5.3) is mapped to its limit L = 0 (R = 0: the tightest
    bend that fits); the caller warns about it (:func:`clothlab.models.irawan.model.geometry_warnings`).
    R is defined on |u| <= umax only; u outside is clamped (callers mask those contributions anyway).
    """
    r_hat = axis_ratio(kappa, umax)
    q = r_hat * np.abs(r_hat)
    cot = 1.0 / np.tan(umax)
    scale = np.maximum(half_length(w, l, umax), 0.0) * np.sqrt(np.maximum(cot * cot + q, 0.0))
    u = np.clip(u, -umax, umax)
    c = np.cos(u)
    s = np.sin(u)
    return scale / (c * c + q * s * s) ** 1.5
