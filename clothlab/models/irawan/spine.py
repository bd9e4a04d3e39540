"""Radius of curvature R(u) of a yarn segment's spine (Irawan & Marschner 2012, sec. 5.3-5.4).

The paper gives R(u) in three branches (ellipse r_hat > 0, parabola r_hat = 0, hyperbola r_hat < 0) with
r_hat = 1 + kappa (1 + cot umax) (sec. 5.4).  With a = w/2 and L = l/2 - a sin(umax) (sec. 5.3) all three
reduce to one expression in q = r_hat |r_hat| (derivation: substitute tan t = r_hat tan u, resp.
tanh t = -r_hat tan u, and eliminate a_hat, b_hat):

    R(u) = L sqrt(cot^2 umax + q) / (cos^2 u + q sin^2 u)^(3/2)

q = 1 gives the circle L / sin umax, q = 0 the parabola L cot(umax) / cos^3 u.  The form is continuous
(indeed smooth) in kappa across r_hat = 0, so fits may cross it, where the paper's branch formulas are
ill-conditioned; and it satisfies the spine-extent identity  integral_0^umax R(u) cos u du = L  for every q
(checked in the tests).  It is defined while cot^2 umax + q > 0, which holds exactly for kappa > -1 (the
paper's range; at kappa = -1 the hyperbola branch's atanh reaches +-1).

A segment that violates w sin(umax) < l (sec. 5.3) is mapped to its limit L = 0 (R = 0: the tightest bend
that fits); the model warns about it (:func:`clothlab.models.irawan.model.geometry_warnings`).  R is
defined on |u| <= umax only; u outside is clamped (callers mask those contributions anyway).

The functions are the compiled ones the integrand kernels inline (:mod:`clothlab.models.irawan.kernels`,
the only implementation); they accept scalars or numpy arrays.  Importing this module imports numba.
"""

from __future__ import annotations

from clothlab.models.irawan.kernels import axis_ratio, half_length, spine_radius

__all__ = ["axis_ratio", "half_length", "spine_radius"]
