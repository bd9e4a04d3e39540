"""Plain scalar reference for the Irawan-Marschner reflectance integral (test use only).

Written straight from Irawan & Marschner, "Specular reflection from woven cloth" (ACM TOG 31(1), 2012),
sections 5-7.1, eqs. (1)-(10) and Algorithms 1-2, in their literal form, one direction pair at a time, with
the spine-curvature branches of sec. 5.4 completed where the paper's text leaves them incomplete (the
parameter of each conic, t(u), and the relation of a_hat, b_hat to L = l/2 - a sin umax).  It deliberately
shares no code with clothlab.models.irawan: the tests compare the two, equation by equation
(tests/test_irawan_kernels.py), integral by integral (tests/test_irawan_model.py) and under the same discrete
quadrature sums (tests/test_stability.py).

Conventions: yarn frame with z along the cloth normal, y along the yarn, x completing a right-handed basis;
wi, wo are unit 3-vectors with z > 0; all angles in radians; w, l in any common length unit (a = w/2).
The specular value omits k_s, the albedo and Seeliger's 1/(4 pi) constant.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy import integrate, special

__all__ = [
    "ReferenceAccuracyWarning",
    "discrete_sum",
    "filament_integrand",
    "phase",
    "specular_reference",
    "spine_radius",
    "staple_integrand",
]

_EPSREL = 1e-10
_EPSABS_SCALE = 1e-13
_LIMIT = 500
_SCAN_POINTS = 200  # grid per piece used to locate kinks and to estimate the integral's scale
_SECOND_PASS_SPLIT = 16


class ReferenceAccuracyWarning(UserWarning):
    """The reference quadrature could not confirm its requested tolerance (see the returned abserr)."""


# ----------------------------------------------------------------------------------------------- helpers


def _as_direction(vec, name):
    """A unit 3-vector with z > 0 as a tuple of floats; ValueError otherwise."""
    x, y, z = (float(c) for c in vec)
    norm = math.sqrt(x * x + y * y + z * z)
    if not (abs(norm - 1.0) < 1e-9 and z > 0.0):
        raise ValueError(f"{name} must be a unit 3-vector with z > 0, got {(x, y, z)} (norm {norm})")
    return x, y, z


def _dot(p, q):
    return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]


def _half_vector(wi, wo):
    """(unit half vector h, |wi + wo|)."""
    s = (wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2])
    norm = math.sqrt(_dot(s, s))
    return (s[0] / norm, s[1] / norm, s[2] / norm), norm


def _normal(u, v):
    """Surface normal n(u, v) = R_x(-u) R_y(v) (0, 0, 1) (sec. 5.2)."""
    return (math.sin(v), math.sin(u) * math.cos(v), math.cos(u) * math.cos(v))


def _seeliger(wi, wo, n):
    """Seeliger's law (eq. 8) without albedo and 1/(4 pi): ci cr / (ci + cr), cosines clamped at 0."""
    ci = max(_dot(wi, n), 0.0)
    cr = max(_dot(wo, n), 0.0)
    if ci + cr == 0.0:
        return 0.0
    return ci * cr / (ci + cr)


def _wrap_angle(x):
    """Wrap an angle to (-pi, pi]."""
    x = math.fmod(x, 2.0 * math.pi)
    if x > math.pi:
        x -= 2.0 * math.pi
    elif x <= -math.pi:
        x += 2.0 * math.pi
    return x


def _smoothstep(x):
    """Cubic smoothstep s(x) = 3x^2 - 2x^3 with x clamped to [0, 1] (eq. 9)."""
    x = min(max(x, 0.0), 1.0)
    return 3.0 * x * x - 2.0 * x * x * x


def _angles_in(candidates, lo, hi):
    """All angles c + 2 k pi (c in candidates, k integer) strictly inside (lo, hi)."""
    found = []
    for c in candidates:
        k_lo = math.ceil((lo - c) / (2.0 * math.pi)) - 1
        k_hi = math.floor((hi - c) / (2.0 * math.pi)) + 1
        for k in range(k_lo, k_hi + 1):
            x = c + 2.0 * math.pi * k
            if lo < x < hi:
                found.append(x)
    return found


# ----------------------------------------------------------------------------------- geometry (sec. 5)


def spine_radius(u, umax, kappa, w, l):
    """Radius of curvature R(u) of the yarn spine (sec. 5.3-5.4, the branches written out per conic).

    a = w/2, L = l/2 - a sin(umax), r_hat = 1 + kappa (1 + cot umax); branches on r_hat literally:
    r_hat == 1 circle, r_hat > 0 ellipse, r_hat == 0 parabola, r_hat < 0 hyperbola. Same length unit as w, l.
    Raises ValueError when the segment does not fit its rectangle (L <= 0), umax is not in (0, pi/2),
    kappa <= -1, or the hyperbola is not defined (|r_hat tan umax| >= 1).
    """
    u, umax, kappa, w, l = float(u), float(umax), float(kappa), float(w), float(l)
    if not 0.0 < umax < 0.5 * math.pi:
        raise ValueError(f"umax must be in (0, pi/2) rad, got {umax}")
    if not kappa > -1.0:
        raise ValueError(f"kappa must be > -1 (sec. 5.4), got {kappa}")
    a = 0.5 * w
    L = 0.5 * l - a * math.sin(umax)
    if not L > 0.0:
        raise ValueError(f"segment does not fit its rectangle: l/2 - (w/2) sin(umax) = {L} <= 0 (sec. 5.3)")
    r_hat = 1.0 + kappa * (1.0 + 1.0 / math.tan(umax))
    if r_hat == 1.0:  # circle
        return L / math.sin(umax)
    if r_hat > 0.0:  # ellipse
        t = math.atan(r_hat * math.tan(u))
        t_max = math.atan(r_hat * math.tan(umax))
        b = L / math.sin(t_max)
        a_hat = b / r_hat
        return (b**2 * math.cos(t) ** 2 + a_hat**2 * math.sin(t) ** 2) ** 1.5 / (a_hat * b)
    if r_hat == 0.0:  # parabola
        a_hat = L / (2.0 * math.tan(umax))
        return 2.0 * a_hat * (1.0 + math.tan(u) ** 2) ** 1.5
    # hyperbola; for kappa > -1, |r_hat tan umax| = (|kappa| (1 + cot umax) - 1) tan umax < 1 always holds
    if not abs(r_hat * math.tan(umax)) < 1.0:
        raise ValueError(
            f"hyperbolic spine undefined: |r_hat tan(umax)| = {abs(r_hat * math.tan(umax))} >= 1 "
            f"(kappa = {kappa}, umax = {umax})"
        )
    t = -math.atanh(r_hat * math.tan(u))
    t_max = -math.atanh(r_hat * math.tan(umax))
    b = L / math.sinh(t_max)
    a_hat = b / r_hat
    return -((b**2 * math.cosh(t) ** 2 + a_hat**2 * math.sinh(t) ** 2) ** 1.5) / (a_hat * b)


# ---------------------------------------------------------------------------------- integrands (sec. 6)


def _staple_v(u, h, psi):
    """Specular v(u) of eq. 3 with the +arccos(D) root, wrapped to (-pi, pi]; None when |D| > 1."""
    hx, hy, hz = h
    p = hy * math.sin(u) + hz * math.cos(u)
    q = hy * math.cos(u) - hz * math.sin(u)
    denom = math.sqrt(hx * hx + p * p)
    if denom == 0.0:
        return None
    d = q / denom / math.tan(psi)
    if not abs(d) <= 1.0:
        return None
    return _wrap_angle(math.atan2(-p, hx) + math.acos(d))


def staple_integrand(u, wi, wo, psi, umax, kappa, w, l):
    """Algorithm 1's StapleIntegrand without f_c: G_v (eq. 5) times A (eq. 8), at spine angle u [rad].

    Zero unless |D| <= 1 (eq. 3) and |v| < pi/2. Units of a*R (length^2) per unit of Seeliger's law.
    """
    wi = _as_direction(wi, "wi")
    wo = _as_direction(wo, "wo")
    return _staple_integrand(float(u), wi, wo, float(psi), float(umax), float(kappa), float(w), float(l))


def _staple_integrand(u, wi, wo, psi, umax, kappa, w, l):
    h, sum_norm = _half_vector(wi, wo)
    v = _staple_v(u, h, psi)
    if v is None or not abs(v) < 0.5 * math.pi:
        return 0.0
    n = _normal(u, v)
    attenuation = _seeliger(wi, wo, n)
    n_dot_h = _dot(n, h)
    if attenuation == 0.0 or n_dot_h <= 0.0:
        return 0.0
    a = 0.5 * w
    radius = spine_radius(u, umax, kappa, w, l)
    g_v = a * (radius + a * math.cos(v)) / (sum_norm * n_dot_h * abs(math.sin(psi)))
    return g_v * attenuation


def _filament_u(h):
    """Specular u of eq. 4: the root of atan2(-h_z, h_y) +- pi/2 with -pi/2 < u < pi/2 (None if neither)."""
    base = math.atan2(-h[2], h[1])
    for sign in (1.0, -1.0):
        u = _wrap_angle(base + sign * 0.5 * math.pi)
        if -0.5 * math.pi < u < 0.5 * math.pi:
            return u
    return None


def filament_integrand(v, wi, wo, umax, kappa, w, l, delta):
    """Algorithm 2's FilamentIntegrand without f_c: G_u (eq. 6) times A_s (eqs. 8, 9), at angle v [rad].

    Zero unless |u| < umax; delta in [0, 1) is the filament smoothing (0 = none).
    """
    wi = _as_direction(wi, "wi")
    wo = _as_direction(wo, "wo")
    return _filament_integrand(float(v), wi, wo, float(umax), float(kappa), float(w), float(l), float(delta))


def _filament_integrand(v, wi, wo, umax, kappa, w, l, delta):
    h, sum_norm = _half_vector(wi, wo)
    u = _filament_u(h)
    if u is None or not abs(u) < umax:
        return 0.0
    n = _normal(u, v)
    attenuation = _seeliger(wi, wo, n)
    if delta > 0.0:
        attenuation *= 1.0 - _smoothstep((abs(u) - (1.0 - delta) * umax) / (delta * umax))
    if attenuation == 0.0:
        return 0.0
    t = (0.0, math.cos(u), -math.sin(u))  # filament fibre tangent (psi = 0, sec. 5.2)
    t_cross_h_x = t[1] * h[2] - t[2] * h[1]
    a = 0.5 * w
    radius = spine_radius(u, umax, kappa, w, l)
    g_u = a * (radius + a * math.cos(v)) / (sum_norm * abs(t_cross_h_x))
    return g_u * attenuation


def phase(wi, wo, alpha, beta):
    """Circular phase function f_c (eq. 7): alpha + von Mises lobe at cos x = -wi.wo [1/rad].

    exp(beta cos x) / (2 pi I0(beta)) is evaluated as exp(beta (cos x - 1)) / (2 pi i0e(beta)).
    """
    cos_x = -_dot(_as_direction(wi, "wi"), _as_direction(wo, "wo"))
    beta = float(beta)
    return float(alpha) + math.exp(beta * (cos_x - 1.0)) / (2.0 * math.pi * float(special.i0e(beta)))


# ------------------------------------------------------------------------------ quadrature (eqs. 1, 2, 10)


def _sign_change_roots(func, lo, hi, n):
    """Roots of a continuous func in (lo, hi) found by sign changes on an n-point grid plus brentq."""
    from scipy import optimize

    xs = np.linspace(lo, hi, n + 1)
    vals = [func(float(x)) for x in xs]
    roots = []
    for x0, x1, f0, f1 in zip(xs[:-1], xs[1:], vals[:-1], vals[1:], strict=True):
        if f0 is None or f1 is None:
            continue
        if f0 == 0.0 and lo < x0 < hi:
            roots.append(float(x0))
        elif f0 * f1 < 0.0:
            roots.append(optimize.brentq(func, float(x0), float(x1), xtol=1e-15, rtol=1e-15))
    return roots


def _staple_breakpoints(wi, wo, psi, umax):
    """Points in (-umax, umax) where the staple integrand jumps or kinks.

    Support |D| <= 1  <=>  |h_y cos u - h_z sin u| <= |sin psi|  <=>  |cos(u + gamma)| <= |sin psi| / rho,
    with rho = sqrt(h_y^2 + h_z^2), gamma = atan2(h_z, h_y) (using |h| = 1 in D's denominator).
    |v| = pi/2: t = (0, cos(u -+ psi), -sin(u -+ psi)), so h.t = 0 at u = +-psi - gamma + pi/2 + k pi.
    Kinks: where wi.n or wo.n (on the specular curve) change sign, located numerically.
    """
    h, _ = _half_vector(wi, wo)
    rho = math.hypot(h[1], h[2])
    gamma = math.atan2(h[2], h[1])
    s = abs(math.sin(psi)) / rho
    points = []
    if s < 1.0:
        c = math.acos(s)
        points += _angles_in([c - gamma, -c - gamma, math.pi - c - gamma, c - math.pi - gamma], -umax, umax)
    for sign in (1.0, -1.0):
        base = sign * psi - gamma + 0.5 * math.pi
        points += _angles_in([base, base + math.pi], -umax, umax)
    edges = sorted({-umax, umax, *points})
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        mid = 0.5 * (lo + hi)
        if _staple_v(mid, h, psi) is None:
            continue
        for direction in (wi, wo):

            def cosine(u, direction=direction):
                v = _staple_v(u, h, psi)
                return None if v is None else _dot(direction, _normal(u, v))

            points += _sign_change_roots(cosine, lo, hi, _SCAN_POINTS)
    return sorted({p for p in points if -umax < p < umax})


def _filament_breakpoints(wi, wo):
    """v in (-pi/2, pi/2) where wi.n or wo.n cross zero (n.w = w_x sin v + (w_y sin u + w_z cos u) cos v)."""
    h, _ = _half_vector(wi, wo)
    u = _filament_u(h)
    if u is None:
        return []
    points = []
    for direction in (wi, wo):
        c = direction[1] * math.sin(u) + direction[2] * math.cos(u)
        root = math.atan2(-c, direction[0])  # tan v = -c / w_x
        points += _angles_in([root, root + math.pi], -0.5 * math.pi, 0.5 * math.pi)
    return sorted(set(points))


def _quad_once(func, lo, hi, epsabs, points=None):
    """One scipy quad call: (value, abserr, trusted)."""
    out = integrate.quad(
        func, lo, hi, epsabs=epsabs, epsrel=_EPSREL, limit=_LIMIT, points=points or None, full_output=1
    )
    return out[0], out[1], len(out) == 3


def _integrate(func, lo, hi, breakpoints):
    """Integral of func over [lo, hi] with breakpoints; second, finer pass if quad reports trouble.

    Returns (value, abserr); warns ReferenceAccuracyWarning when even the second pass is not trusted.
    """
    edges = [lo, *breakpoints, hi]
    rough = 0.0
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        step = (b - a) / _SCAN_POINTS
        rough += sum(abs(func(a + (k + 0.5) * step)) for k in range(_SCAN_POINTS)) * step
    epsabs = _EPSABS_SCALE * rough
    value, abserr, trusted = _quad_once(func, lo, hi, epsabs, breakpoints)
    if trusted:
        return value, abserr
    value, abserr, trusted = 0.0, 0.0, True
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sub = np.linspace(a, b, _SECOND_PASS_SPLIT + 1)
        for c, d in zip(sub[:-1], sub[1:], strict=True):
            part, err, ok = _quad_once(func, float(c), float(d), epsabs / _SECOND_PASS_SPLIT)
            value += part
            abserr += err
            trusted = trusted and ok
    if not trusted or abserr > max(epsabs, 1e-8 * abs(value)):
        warnings.warn(
            f"reference quadrature not converged: value {value!r}, abserr {abserr!r}",
            ReferenceAccuracyWarning,
            stacklevel=3,
        )
    return value, abserr


def specular_reference(wi, wo, *, psi, umax, kappa, w, l, alpha, beta, delta, psi_threshold):
    """Specular reflectance f_{r,s}(wi, wo) of one yarn type (eq. 10), without k_s: (value, abserr).

    f_c (eq. 7) times the integral over u in [-umax, umax] of the staple integrand (eq. 1) when
    |psi| >= psi_threshold, else over v in [-pi/2, pi/2] of the filament integrand (eq. 2, Algorithm 2).
    Angles in radians; w, l in a common length unit.
    """
    wi = _as_direction(wi, "wi")
    wo = _as_direction(wo, "wo")
    psi, umax, kappa, w, l, delta = (float(x) for x in (psi, umax, kappa, w, l, delta))
    spine_radius(0.0, umax, kappa, w, l)  # validates the geometry before integrating
    f_c = phase(wi, wo, alpha, beta)
    if abs(psi) >= psi_threshold:

        def integrand(u):
            return _staple_integrand(u, wi, wo, psi, umax, kappa, w, l)

        value, abserr = _integrate(integrand, -umax, umax, _staple_breakpoints(wi, wo, psi, umax))
    else:

        def integrand(v):
            return _filament_integrand(v, wi, wo, umax, kappa, w, l, delta)

        half_pi = 0.5 * math.pi
        value, abserr = _integrate(integrand, -half_pi, half_pi, _filament_breakpoints(wi, wo))
    return f_c * value, f_c * abserr


def rule_nodes(rule, n, lo, hi):
    """Nodes and weights of the n-node ``trapezoid`` (both ends included) or ``gauss`` (Gauss-Legendre) rule
    over [lo, hi], computed here independently of clothlab."""
    if rule == "trapezoid":
        nodes = np.linspace(lo, hi, n)
        weights = np.full(n, (hi - lo) / (n - 1))
        weights[[0, -1]] *= 0.5
        return nodes, weights
    if rule == "gauss":
        x, wx = np.polynomial.legendre.leggauss(n)
        return lo + (hi - lo) * 0.5 * (x + 1.0), 0.5 * (hi - lo) * wx
    raise ValueError(f"unknown rule {rule!r}")


def discrete_sum(wi, wo, *, staple, rule, n, psi, umax, kappa, w, l, delta):
    """sum_k w_k (integrand at node k) of eq. 1 over u in [-umax, umax] (``staple``) or of eq. 2 over v in
    [-pi/2, pi/2], with the literal integrands, without f_c: what a fixed-node quadrature of the model must
    return exactly (to round-off).  Back-facing pairs give 0."""
    wi = tuple(float(c) for c in wi)
    wo = tuple(float(c) for c in wo)
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return 0.0
    if staple:
        nodes, weights = rule_nodes(rule, n, -umax, umax)
        return sum(wk * _staple_integrand(float(x), wi, wo, psi, umax, kappa, w, l)
                   for x, wk in zip(nodes, weights, strict=True))
    nodes, weights = rule_nodes(rule, n, -0.5 * math.pi, 0.5 * math.pi)
    return sum(wk * _filament_integrand(float(x), wi, wo, umax, kappa, w, l, delta)
               for x, wk in zip(nodes, weights, strict=True))
