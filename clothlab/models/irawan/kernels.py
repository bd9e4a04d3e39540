"""Compiled (numba) kernels of the yarn integrals, equation by equation (Irawan & Marschner 2012, sec. 5-7).

The first half of this module holds one small helper per equation of the paper, named for what it
computes, with the paper's symbols and the equation number next to the line that implements it; every
helper is ``inline="always"``, so the loops of the second half compile to the same code as a hand-fused
kernel.  These helpers are the only implementation of each formula: the quadrature loops below, the
texture kernels (Algorithms 3-4), the breakpoints of the ``support`` rule (:mod:`.yarn`) and the
experimental ``split`` rule all call them.  The table "paper -> code" is in :mod:`clothlab.models.irawan`.

Conventions: yarn frame (z normal, y along the yarn, x across it), wi and wo unit vectors with z > 0,
angles in radians, w and l in one length unit, a = w / 2.  Values omit f_c (eq. 7, applied by the caller:
it depends on wi.wo only) and Seeliger's albedo and 1 / (4 pi) (absorbed into k_s).

Imported lazily (numba costs ~0.5 s to import).  Compiled code is cached on disk (``cache=True``); numba
does not see edits to another module's inlined helper, so the helpers live here with their callers.
Serial on purpose: numba's ``parallel=True`` thread pool made a 1,575-direction evaluation 10-40x slower
on a loaded 2-core machine (measured 0.7 ms serial vs 16-32 ms parallel); run fits in separate processes.
"""

from __future__ import annotations

import math

import numpy as np

from clothlab.models.jit import njit

# ------------------------------------------------------------------------ spine geometry (sec. 5.3-5.4)
# Written with numpy ufuncs so that the same functions serve scalars inside the kernels and arrays from
# Python (:mod:`clothlab.models.irawan.spine`).


@njit(cache=True, inline="always")
def axis_ratio(kappa, umax):
    """r_hat = 1 + kappa (1 + cot umax) (sec. 5.4); umax in radians."""
    return 1.0 + kappa * (1.0 + 1.0 / np.tan(umax))  # sec. 5.4: r_hat


@njit(cache=True, inline="always")
def half_length(w, l, umax):
    """L = l/2 - a sin umax, the spine's horizontal half extent (sec. 5.3); < 0 if w sin umax > l."""
    return 0.5 * l - 0.5 * w * np.sin(umax)  # sec. 5.3: L


@njit(cache=True, inline="always")
def spine_radius_factors(umax, kappa, w, l):
    """(scale, q) of R(u) = scale / (cos^2 u + q sin^2 u)^(3/2): scale = max(L, 0) sqrt(cot^2 umax + q),
    q = r_hat |r_hat| (sec. 5.4); the part of :func:`spine_radius` that does not depend on u."""
    r_hat = axis_ratio(kappa, umax)
    q = r_hat * np.abs(r_hat)
    cot = 1.0 / np.tan(umax)
    return np.maximum(half_length(w, l, umax), 0.0) * np.sqrt(np.maximum(cot * cot + q, 0.0)), q


@njit(cache=True, inline="always")
def spine_radius_at(c, s, scale, q):
    """R(u) from cos u, sin u and :func:`spine_radius_factors` (sec. 5.4)."""
    x = c * c + q * s * s
    return scale / (x * np.sqrt(x))  # sec. 5.4: R(u) (x^1.5 without a pow call, so loops vectorise)


@njit(cache=True, inline="always")
def spine_arc(umax, delta, shortened):
    """The half arc on which R(u) of a *filament* spine is evaluated (sec. 5.4 with eq. 9's smoothing).

    ``shortened`` False: umax, the paper's text (sec. 5.4 defines R(u) on the whole segment |u| <= umax;
    eq. 9 only fades A over the last delta umax).  ``shortened`` True: (1 - delta) umax, the Mitsuba 0.5/0.6
    ``irawan`` plugin's form (r_hat, L and t_max use the shortened arc and |u| is clamped to it, so
    R(u) = R((1 - delta) umax) on the faded ends).  Equal when delta = 0."""
    return (1.0 - delta) * umax if shortened else umax


@njit(cache=True, inline="always")
def spine_radius(u, umax, kappa, w, l):
    """R(u) = L sqrt(cot^2 umax + q) / (cos^2 u + q sin^2 u)^(3/2), q = r_hat |r_hat| (sec. 5.4).

    The ellipse, parabola and hyperbola branches of the paper in one form (derivation in
    :mod:`clothlab.models.irawan.spine`).  L < 0 (segment does not fit, sec. 5.3) is clamped to 0; u is
    clamped to [-umax, umax].
    """
    scale, q = spine_radius_factors(umax, kappa, w, l)
    u = np.minimum(np.maximum(u, -umax), umax)
    return spine_radius_at(np.cos(u), np.sin(u), scale, q)


# ------------------------------------------------------------------- the specular condition (sec. 6.3)


@njit(cache=True, inline="always")
def half_vector(wix, wiy, wiz, wox, woy, woz):
    """(h_x, h_y, h_z, |wi + wo|): h = (wi + wo) / |wi + wo|, the bisector of sec. 6.2; zeros if wo = -wi."""
    sx, sy, sz = wix + wox, wiy + woy, wiz + woz
    length = math.sqrt(sx * sx + sy * sy + sz * sz)
    if length <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return sx / length, sy / length, sz / length, length  # sec. 6.2: h


@njit(cache=True, inline="always")
def specular_v_terms(hx, hy, hz, sin_u, cos_u, cot_psi):
    """(rho, D, cos v, sin v) of eq. 3 without its checks (valid where rho > 0 and |D| <= 1; see
    :func:`specular_v`): branch-free, so loops over many directions vectorise."""
    b = hy * sin_u + hz * cos_u
    rho = math.sqrt(hx * hx + b * b)
    d = (hy * cos_u - hz * sin_u) * cot_psi / rho  # eq. 3: D
    root = math.sqrt(max(1.0 - d * d, 0.0))  # sin(arccos D)
    cos_v = (hx * d + b * root) / rho  # eq. 3: cos(atan2(-B, h_x) + arccos D)
    sin_v = (hx * root - b * d) / rho  # eq. 3: sin(atan2(-B, h_x) + arccos D)
    return rho, d, cos_v, sin_v


@njit(cache=True, inline="always")
def specular_v(hx, hy, hz, sin_u, cos_u, cot_psi):
    """v(wi, u, wo) of eq. 3 for a staple yarn, as (found, cos v, sin v).

    v = atan2(-B, h_x) + arccos(D),  B = h_y sin u + h_z cos u,  D = (h_y cos u - h_z sin u) cot psi / rho,
    rho = sqrt(h_x^2 + B^2).  Only the +arccos root has n.h >= 0 (sec. 6.3).  Evaluated without
    trigonometric calls: cos(atan2(-B, h_x)) = h_x / rho, sin(...) = -B / rho, sin(arccos D) = sqrt(1 - D^2).
    found is False when |D| > 1: no fibre tangent reflects wi into wo (sec. 6.3).
    """
    b = hy * sin_u + hz * cos_u
    if hx * hx + b * b <= 0.0:  # rho = 0
        return False, 0.0, 0.0
    rho, d, cos_v, sin_v = specular_v_terms(hx, hy, hz, sin_u, cos_u, cot_psi)
    if abs(d) > 1.0:
        return False, 0.0, 0.0
    return True, cos_v, sin_v


@njit(cache=True, inline="always")
def specular_u(hy, hz):
    """u(wi, v, wo) of eq. 4 for a filament yarn: atan2(-h_z, h_y) + pi/2 = atan(h_y / h_z) (h_z > 0), the
    root on the front of the yarn, -pi/2 < u < pi/2 (sec. 6.3)."""
    return math.atan(hy / hz)  # eq. 4


@njit(cache=True, inline="always")
def spine_normal_cosine(wy, wz, sin_u, cos_u):
    """w . n(u, 0) = w_y sin u + w_z cos u: the cosine to the normal on the spine's plane (sec. 5.2)."""
    return wy * sin_u + wz * cos_u  # sec. 5.2: w . n(u, 0)


@njit(cache=True, inline="always")
def normal_cosine(wx, w_n0, sin_v, cos_v):
    """w . n(u, v) = w_x sin v + (w . n(u, 0)) cos v,  n(u, v) = (sin v, sin u cos v, cos u cos v) (sec. 5.2)."""
    return wx * sin_v + w_n0 * cos_v  # sec. 5.2: w . n(u, v)


@njit(cache=True, inline="always")
def lit_arc(wx, w_n0):
    """The interval (lo, hi) of v in (-pi/2, pi/2) where w . n(u, v) > 0 (a clamped cosine of eq. 8 is
    non-zero); empty if lo >= hi.  Dividing by cos v > 0: w_x tan v + w . n(u, 0) > 0."""
    if wx == 0.0:
        return (-0.5 * math.pi, 0.5 * math.pi) if w_n0 > 0.0 else (0.0, 0.0)
    v0 = math.atan(-w_n0 / wx)  # w . n(u, v0) = 0
    if wx > 0.0:
        return v0, 0.5 * math.pi
    return -0.5 * math.pi, v0


@njit(cache=True, inline="always")
def staple_break_angles(hy, hz, psi, abs_sin_psi):
    """Four angles (each repeating with period pi in u) where the staple integrand of eq. 1 jumps.

    With rho = sqrt(h_y^2 + h_z^2) and gamma = atan2(h_z, h_y), eq. 3's support |D| <= 1 is exactly
    |cos(u + gamma)| <= |sin psi| / rho: its ends are u = -gamma +- arccos(|sin psi| / rho).  The visibility
    cut |v| = pi/2 (h . t = 0 with t = (0, cos(u -+ psi), -sin(u -+ psi))) is at u = +-psi - gamma + pi/2.
    """
    rho = math.sqrt(hy * hy + hz * hz)
    gamma = math.atan2(hz, hy)
    c0 = math.acos(min(abs_sin_psi / rho, 1.0)) if rho > 0.0 else 0.0  # eq. 3: |D| = 1
    return -gamma + c0, -gamma - c0, psi - gamma + 0.5 * math.pi, -psi - gamma + 0.5 * math.pi  # |v| = pi/2


# ------------------------------------------------------- geometry factor and attenuation (sec. 6.4-6.6)


@njit(cache=True, inline="always")
def volume_element(radius, a, cos_v):
    """a (R(u) + a cos v): the volume element at the yarn surface r = a (sec. 6.2), numerator of eqs. 5, 6."""
    return a * (radius + a * cos_v)  # sec. 6.2: a (R + a cos v)


@njit(cache=True, inline="always")
def seeliger(ci, cr):
    """A = c_i c_r / (c_i + c_r), Seeliger's law (eq. 8) without the albedo, cosines already positive."""
    return ci * cr / (ci + cr)  # eq. 8: A


@njit(cache=True, inline="always")
def staple_geometry_attenuation(volume, ci, cr, abs_sin_psi):
    """G_v A, the product of eq. 5 and eq. 8 in bounded form.

    Since c_i + c_r = |wi + wo| (n . h) on the specular curve, G_v A = a (R + a cos v) c_i c_r /
    (|sin psi| (c_i + c_r)^2): finite where n . h -> 0, although eq. 5 alone is not.
    """
    total = ci + cr
    return volume * ci * cr / (abs_sin_psi * total * total)  # eqs. 5 x 8


@njit(cache=True, inline="always")
def tangent_cross_h_x(hy, hz):
    """|(t x h)_x| of eq. 6 at eq. 4's u: t = (0, cos u, -sin u) gives h_z cos u + h_y sin u = sqrt(h_y^2 + h_z^2)."""
    return math.sqrt(hy * hy + hz * hz)  # eq. 6: |(t x h)_x|


@njit(cache=True, inline="always")
def smoothstep(x):
    """s(x) = 3 x^2 - 2 x^3 with x clamped to [0, 1]: the smooth step of eq. 9."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)  # eq. 9: s(x)


@njit(cache=True, inline="always")
def filament_fade(u, umax, delta):
    """1 - s((|u| - (1 - delta) umax) / (delta umax)), the factor A_s / A of eq. 9; 1 when delta = 0."""
    width = delta * umax
    if not width > 0.0:  # delta = 0, or so small that delta umax underflows: the unsmoothed limit (no fade)
        return 1.0
    return 1.0 - smoothstep((abs(u) - (1.0 - delta) * umax) / width)  # eq. 9


# ------------------------------------------------------------------ integrands (Algorithms 1-2)


@njit(cache=True, inline="always")
def staple_integrand(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, sin_u, cos_u, radius, cot_psi, abs_sin_psi, a):
    """(G_v A, cos v, sin v) at one u given sin u, cos u and R(u): Algorithm 1's integrand without f_c.

    Zero unless |D| <= 1 (eq. 3), |v| < pi/2 (the front of the yarn) and both cosines of eq. 8 are > 0.
    """
    found, cos_v, sin_v = specular_v(hx, hy, hz, sin_u, cos_u, cot_psi)  # eq. 3
    if not found or cos_v <= 0.0:
        return 0.0, cos_v, sin_v
    ci = normal_cosine(wix, spine_normal_cosine(wiy, wiz, sin_u, cos_u), sin_v, cos_v)  # wi . n, eq. 8
    cr = normal_cosine(wox, spine_normal_cosine(woy, woz, sin_u, cos_u), sin_v, cos_v)  # wo . n, eq. 8
    if ci <= 0.0 or cr <= 0.0:
        return 0.0, cos_v, sin_v
    return staple_geometry_attenuation(volume_element(radius, a, cos_v), ci, cr, abs_sin_psi), cos_v, sin_v


@njit(cache=True, inline="always")
def filament_direction(wix, wiy, wiz, wox, woy, woz, umax, delta):
    """The part of Algorithm 2's integrand that does not depend on v, as (ok, u, scale, c_i0, c_r0).

    u is eq. 4's specular inclination; scale = (1 - s(...)) / (|wi + wo| |(t x h)_x|), the fade of eq. 9
    over the denominator of eq. 6; c_0 = w . n(u, 0).  ok is False where the integrand vanishes for every v
    (back-facing, |u| >= umax: the highlight is off the segment, or fully faded).
    """
    hx, hy, hz, length = half_vector(wix, wiy, wiz, wox, woy, woz)
    if wiz <= 0.0 or woz <= 0.0 or length <= 0.0:
        return False, 0.0, 0.0, 0.0, 0.0
    u = specular_u(hy, hz)  # eq. 4
    if abs(u) >= umax:
        return False, u, 0.0, 0.0, 0.0
    fade = filament_fade(u, umax, delta)  # eq. 9
    cross = tangent_cross_h_x(hy, hz)  # eq. 6
    if fade <= 0.0 or cross <= 0.0:
        return False, u, 0.0, 0.0, 0.0
    su = math.sin(u)
    cu = math.cos(u)
    ci0 = spine_normal_cosine(wiy, wiz, su, cu)
    cr0 = spine_normal_cosine(woy, woz, su, cu)
    return True, u, fade / (length * cross), ci0, cr0


@njit(cache=True, inline="always")
def filament_integrand(wix, ci0, wox, cr0, sin_v, cos_v, a, radius):
    """a (R + a cos v) A at one v (eq. 6's numerator times eq. 8); 0 unless both cosines are > 0.
    Times the ``scale`` of :func:`filament_direction` it is Algorithm 2's integrand without f_c."""
    ci = normal_cosine(wix, ci0, sin_v, cos_v)
    cr = normal_cosine(wox, cr0, sin_v, cos_v)
    if ci <= 0.0 or cr <= 0.0:
        return 0.0
    return volume_element(radius, a, cos_v) * seeliger(ci, cr)  # eq. 6 numerator x eq. 8


# ------------------------------------------------------------------ quadrature loops (eqs. 1, 2, 10)


@njit(cache=True)
def staple_quadrature(wi, wo, nodes, weights, psi, umax, kappa, w, l):
    """sum_k weights[n, k] G_v A(nodes[n, k]) (eq. 1 without f_c) for each direction pair n (yarn frame).

    ``nodes`` / ``weights`` of shape (1, K) are shared by all directions: sin, cos and R are then computed
    once per node instead of once per (direction, node)."""
    n_dir = wi.shape[0]
    n_nodes = nodes.shape[1]
    shared = nodes.shape[0] == 1
    out = np.zeros(n_dir)
    cot_psi = math.cos(psi) / math.sin(psi)
    abs_sin_psi = abs(math.sin(psi))
    a = 0.5 * w
    su = np.empty(n_nodes)
    cu = np.empty(n_nodes)
    radius = np.empty(n_nodes)
    if shared:
        for k in range(n_nodes):
            su[k] = math.sin(nodes[0, k])
            cu[k] = math.cos(nodes[0, k])
            radius[k] = spine_radius(nodes[0, k], umax, kappa, w, l)
    for n in range(n_dir):
        wix, wiy, wiz = wi[n, 0], wi[n, 1], wi[n, 2]
        wox, woy, woz = wo[n, 0], wo[n, 1], wo[n, 2]
        hx, hy, hz, length = half_vector(wix, wiy, wiz, wox, woy, woz)
        if wiz <= 0.0 or woz <= 0.0 or length <= 0.0:
            continue
        row = 0 if shared else n
        acc = 0.0
        for k in range(n_nodes):
            wk = weights[row, k]
            if wk == 0.0:
                continue
            if shared:
                s, c, r = su[k], cu[k], radius[k]
            else:
                u = nodes[n, k]
                s, c, r = math.sin(u), math.cos(u), spine_radius(u, umax, kappa, w, l)
            acc += wk * staple_integrand(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, s, c, r, cot_psi, abs_sin_psi,
                                         a)[0]  # eq. 1
        out[n] = acc
    return out


@njit(cache=True)
def filament_quadrature(wi, wo, nodes, weights, umax, kappa, w, l, delta, on_arc, shortened):
    """sum_k weights[n, k] G_u A_s(nodes[n, k]) (eq. 2 without f_c) for each direction pair n (yarn frame).

    ``nodes`` / ``weights`` of shape (1, K) are shared by all directions (sin v, cos v computed once).
    ``on_arc``: the nodes are unit nodes in [0, 1] mapped per direction onto the closed-form arc where both
    clamped cosines of eq. 8 are positive (the only place the integrand is non-zero, and analytic inside).
    ``shortened``: R(u) on the arc of :func:`spine_arc` (the renderer's form) instead of the full one."""
    n_dir = wi.shape[0]
    n_nodes = nodes.shape[1]
    shared = nodes.shape[0] == 1
    out = np.zeros(n_dir)
    a = 0.5 * w
    arc = spine_arc(umax, delta, shortened)  # sec. 5.4: the arc R(u) is fitted to
    sv_shared = np.empty(n_nodes)
    cv_shared = np.empty(n_nodes)
    if shared and not on_arc:
        for k in range(n_nodes):
            sv_shared[k] = math.sin(nodes[0, k])
            cv_shared[k] = math.cos(nodes[0, k])
    for n in range(n_dir):
        wix, wox = wi[n, 0], wo[n, 0]
        ok, u, scale, ci0, cr0 = filament_direction(wix, wi[n, 1], wi[n, 2], wox, wo[n, 1], wo[n, 2], umax, delta)
        if not ok:
            continue
        radius = spine_radius(u, arc, kappa, w, l)  # |u| clamped to the arc
        row = 0 if shared else n
        acc = 0.0
        if on_arc:
            lo_i, hi_i = lit_arc(wix, ci0)
            lo_o, hi_o = lit_arc(wox, cr0)
            lo, hi = max(lo_i, lo_o), min(hi_i, hi_o)
            span = hi - lo
            if span <= 0.0:
                continue
            for k in range(n_nodes):
                v = lo + span * nodes[row, k]
                acc += weights[row, k] * filament_integrand(wix, ci0, wox, cr0, math.sin(v), math.cos(v), a, radius)
            acc *= span
        else:
            for k in range(n_nodes):
                wk = weights[row, k]
                if wk == 0.0:
                    continue
                if shared:
                    sv, cv = sv_shared[k], cv_shared[k]
                else:
                    sv, cv = math.sin(nodes[n, k]), math.cos(nodes[n, k])
                acc += wk * filament_integrand(wix, ci0, wox, cr0, sv, cv, a, radius)
        out[n] = acc * scale  # eq. 2
    return out


# ------------------------------------------------------------------ breakpoints of the support rule
# Where the staple integrand of eq. 1 jumps or kinks along u: the ends of eq. 3's support and the visibility
# cut (closed form, :func:`staple_break_angles`) and the zeros of the clamped cosines c_i, c_r of eq. 8 on the
# specular curve v(u) (roots of a quartic in tan u, :func:`cosine_zero_quartic`).  Between consecutive
# breakpoints the integrand is either 0 or smooth, so the rule tests each piece once (:func:`staple_lit_pieces`,
# parameter-free: once per direction set) and integrates the lit ones with Gauss-Legendre after the cosine end
# map (:func:`staple_support_sum`).

STAPLE_MAX_BREAKS = 40  # 2 ends + 20 closed-form candidates + up to 2 x (4 roots + 3 critical points)
COSINE_ZERO_TOL = 1e-6  # |c| at an accepted root of the quartic (spurious roots of the squaring are far larger)


@njit(cache=True, inline="always")
def quadratic_product(a0, a1, a2, b0, b1, b2):
    """Coefficients (t^0 .. t^4) of (a0 + a1 t + a2 t^2)(b0 + b1 t + b2 t^2)."""
    return a0 * b0, a0 * b1 + a1 * b0, a0 * b2 + a1 * b1 + a2 * b0, a1 * b2 + a2 * b1, a2 * b2


@njit(cache=True, inline="always")
def cosine_zero_quartic(hx, hy, hz, wx, wy, wz, cot_psi):
    """Coefficients (t^0 .. t^4) of Q(t), t = tan u, whose real roots contain every u where the clamped cosine
    w . n(u, v(u)) of eq. 8 crosses 0 on eq. 3's specular curve (w = wi or wo).

    On the curve h_x cos v - B sin v = E cot psi (eq. 3: D = cos(v - atan2(-B, h_x))), B = h_y sin u +
    h_z cos u, E = h_y cos u - h_z sin u; w . n = w_x sin v + P cos v = 0 with P = w . n(u, 0) (sec. 5.2) gives
    (sin v, cos v) = +-(-P, w_x) / sqrt(P^2 + w_x^2).  Eliminating v and squaring:
    (h_x w_x + B P)^2 = cot^2 psi E^2 (P^2 + w_x^2), homogeneous of degree 4 in (cos u, sin u); divided by
    cos^4 u it is Q(t) = 0.  Squaring adds roots on the other branch; callers keep the roots where w . n = 0."""
    a0, a1, a2 = hx * wx + hz * wz, hz * wy + hy * wz, hx * wx + hy * wy  # h_x w_x (1 + t^2) + B P
    p0, p1, p2, p3, p4 = quadratic_product(a0, a1, a2, a0, a1, a2)
    k2 = cot_psi * cot_psi
    r0, r1, r2, r3, r4 = quadratic_product(hy * hy, -2.0 * hy * hz, hz * hz,  # E^2
                                           wz * wz + wx * wx, 2.0 * wy * wz, wy * wy + wx * wx)  # P^2 + w_x^2 (1 + t^2)
    return p0 - k2 * r0, p1 - k2 * r1, p2 - k2 * r2, p3 - k2 * r3, p4 - k2 * r4


@njit(cache=True, inline="always")
def quartic_value(c0, c1, c2, c3, c4, t):
    """c0 + c1 t + c2 t^2 + c3 t^3 + c4 t^4 (Horner)."""
    return (((c4 * t + c3) * t + c2) * t + c1) * t + c0


@njit(cache=True, inline="always")
def bracketed_root(c0, c1, c2, c3, c4, a, b, fa):
    """The root in [a, b] of the quartic (monotone there, opposite signs at a and b; fa its value at a):
    Newton steps kept inside the shrinking bracket, bisection where a step leaves it."""
    x = 0.5 * (a + b)
    for _ in range(80):
        fx = quartic_value(c0, c1, c2, c3, c4, x)
        if fx == 0.0:
            return x
        if (fx < 0.0) == (fa < 0.0):
            a, fa = x, fx
        else:
            b = x
        slope = quartic_value(c1, 2.0 * c2, 3.0 * c3, 4.0 * c4, 0.0, x)
        step = x - fx / slope if slope != 0.0 else 0.5 * (a + b)
        if not a < step < b:
            step = 0.5 * (a + b)
        if abs(step - x) <= 1e-15 * (1.0 + abs(x)) or b - a <= 1e-15 * (1.0 + abs(x)):
            return step
        x = step
    return x


@njit(cache=True, inline="always")
def roots_between(c0, c1, c2, c3, c4, knots, n_knots, out, m):
    """Append to ``out[m:]`` the roots of the quartic between consecutive ``knots[:n_knots]`` (sorted; the
    quartic monotone between them) where it changes sign; returns the new count."""
    f_lo = quartic_value(c0, c1, c2, c3, c4, knots[0])
    for i in range(n_knots - 1):
        f_hi = quartic_value(c0, c1, c2, c3, c4, knots[i + 1])
        if f_lo == 0.0:
            out[m] = knots[i]
            m += 1
        elif f_lo * f_hi < 0.0:
            out[m] = bracketed_root(c0, c1, c2, c3, c4, knots[i], knots[i + 1], f_lo)
            m += 1
        f_lo = f_hi
    return m


@njit(cache=True, inline="always")
def quartic_roots(c0, c1, c2, c3, c4, lo, hi, knots, crit, out, m):
    """Append the real roots in [lo, hi) of c0 + ... + c4 t^4, and its critical points there, to ``out[m:]``;
    returns the new count.

    Isolation by derivatives: the roots of Q'' (closed form) split [lo, hi] where Q' is monotone, Q's critical
    points found there split it where Q is monotone, and each sign change is then bracketed (no root is missed,
    however close two roots are).  The critical points are candidates too: a double root of Q has no sign
    change, and the squaring of :func:`cosine_zero_quartic` turns a simple zero of the cosine into one where
    w_x = 0 (the caller keeps only candidates where the cosine is 0).  ``knots``, ``crit``: scratch arrays of
    >= 5 entries."""
    qa, qb, qc = 12.0 * c4, 6.0 * c3, 2.0 * c2  # Q''
    n_k = 0
    knots[n_k] = lo
    n_k += 1
    if qa != 0.0:
        disc = qb * qb - 4.0 * qa * qc
        if disc > 0.0:
            root = math.sqrt(disc)
            q = -0.5 * (qb + math.copysign(root, qb))  # the stable quadratic formula
            r1, r2 = q / qa, (qc / q if q != 0.0 else q / qa)
            for r in (min(r1, r2), max(r1, r2)):
                if lo < r < hi:
                    knots[n_k] = r
                    n_k += 1
    elif qb != 0.0 and lo < -qc / qb < hi:
        knots[n_k] = -qc / qb
        n_k += 1
    knots[n_k] = hi
    n_k += 1
    n_c = 1
    crit[0] = lo
    n_c = roots_between(c1, 2.0 * c2, 3.0 * c3, 4.0 * c4, 0.0, knots, n_k, crit, n_c)  # Q' = 0
    for i in range(1, n_c):
        t = crit[i]
        size = abs(c0) + abs(t) * (abs(c1) + abs(t) * (abs(c2) + abs(t) * (abs(c3) + abs(t) * abs(c4))))
        if abs(quartic_value(c0, c1, c2, c3, c4, t)) <= 1e-9 * size:  # Q touches 0 here: a double root
            out[m] = t
            m += 1
    crit[n_c] = hi
    n_c += 1
    return roots_between(c0, c1, c2, c3, c4, crit, n_c, out, m)


@njit(cache=True, inline="always")
def staple_breakpoints(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, psi, cot_psi, abs_sin_psi, umax, breaks,
                       knots, crit):
    """Sorted breakpoints of the staple integrand over [-umax, umax] into ``breaks``; returns their count.

    The ends, the closed-form jumps of :func:`staple_break_angles` (+ k pi) inside, and the zeros of c_i and
    c_r of eq. 8 on the specular curve (roots of :func:`cosine_zero_quartic`, kept where the cosine is 0 on the
    + root of eq. 3)."""
    m = 0
    breaks[m] = -umax
    m += 1
    for base in staple_break_angles(hy, hz, psi, abs_sin_psi):
        for k in range(-2, 3):
            b = base + k * math.pi
            if -umax < b < umax:
                breaks[m] = b
                m += 1
    t_lo, t_hi = math.tan(-umax), math.tan(umax)
    for d in ((wix, wiy, wiz), (wox, woy, woz)):
        c0, c1, c2, c3, c4 = cosine_zero_quartic(hx, hy, hz, d[0], d[1], d[2], cot_psi)  # eq. 8 on eq. 3
        first = m
        m = quartic_roots(c0, c1, c2, c3, c4, t_lo, t_hi, knots, crit, breaks, m)
        kept = first
        for i in range(first, m):
            t = breaks[i]
            cu = 1.0 / math.sqrt(1.0 + t * t)  # |u| < pi/2: cos u > 0
            su = t * cu
            found, cos_v, sin_v = specular_v(hx, hy, hz, su, cu, cot_psi)  # eq. 3
            if found and t_lo < t < t_hi and \
                    abs(normal_cosine(d[0], spine_normal_cosine(d[1], d[2], su, cu), sin_v, cos_v)) <= COSINE_ZERO_TOL:
                breaks[kept] = math.atan(t)
                kept += 1
        m = kept
    breaks[m] = umax
    m += 1
    for i in range(1, m):  # insertion sort of the few breakpoints
        x = breaks[i]
        j = i - 1
        while j >= 0 and breaks[j] > x:
            breaks[j + 1] = breaks[j]
            j -= 1
        breaks[j + 1] = x
    return m


ATAN_TERMS = 22
"""Terms of the arctangent series in :func:`arctan` (|t| <= tan(pi/8): the 22nd term is below 1e-17)."""


@njit(cache=True, inline="always")
def arctan(x):
    """atan x for any x from its Taylor series after two reductions (atan x = pi/2 - atan(1/x) for |x| > 1,
    atan t = pi/4 + atan((t - 1) / (t + 1)) for t > tan(pi/8)): plain arithmetic and selects, so loops over
    many directions vectorise (math.atan does not, without SVML); within a few ulp of math.atan."""
    a = abs(x)
    inverted = a > 1.0
    t = 1.0 / a if inverted else a
    shifted = t > 0.41421356237309503  # tan(pi/8)
    r = (t - 1.0) / (t + 1.0) if shifted else t
    r2 = r * r
    acc = 0.0
    for k in range(ATAN_TERMS - 1, -1, -1):
        acc = acc * r2 + (1.0 if k % 2 == 0 else -1.0) / (2 * k + 1)
    y = r * acc + (0.25 * math.pi if shifted else 0.0)
    y = 0.5 * math.pi - y if inverted else y
    return -y if x < 0.0 else y


@njit(cache=True, inline="always")
def sincos(x):
    """(sin x, cos x) for |x| <= pi/2 from their Taylor series to x^19 and x^20 (truncation error < 3e-16):
    plain arithmetic, so loops over many angles vectorise (math.sin / math.cos do not, without SVML)."""
    x2 = x * x
    s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362880.0 + x2 * (
        -1.0 / 39916800.0 + x2 * (1.0 / 6227020800.0 + x2 * (-1.0 / 1307674368000.0 + x2 * (
            1.0 / 355687428096000.0 + x2 * (-1.0 / 121645100408832000.0))))))))))
    c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0 + x2 * (
        -1.0 / 3628800.0 + x2 * (1.0 / 479001600.0 + x2 * (-1.0 / 87178291200.0 + x2 * (
            1.0 / 20922789888000.0 + x2 * (-1.0 / 6402373705728000.0 + x2 * (1.0 / 2432902008176640000.0))))))))))
    return s, c


PIECE_DOMAIN = 0.5 * math.pi - 1e-7  # the widest domain of the lit pieces (umax < 90 deg)


@njit(cache=True)
def staple_lit_pieces(wi, wo, psi, domain):
    """The lit pieces of the staple integrand (eq. 1) per direction pair (yarn frame), as (lo, hi), each (P, N):
    the intervals of u between consecutive :func:`staple_breakpoints` on [-domain, domain] (valid for every
    umax <= domain) on which the integrand is not 0 (one test at the midpoint decides: between breakpoints it
    is 0 everywhere or nowhere); P is the most any pair has, unused slots are empty (lo = hi = 0).  They depend
    on the directions and psi only, so a fit computes them once per direction set (:class:`.integrals.YarnTerms`).
    The cost grows with the domain (the quartic's roots are bracketed on [-tan domain, tan domain])."""
    n_dir = wi.shape[0]
    cot_psi = math.cos(psi) / math.sin(psi)
    abs_sin_psi = abs(math.sin(psi))
    breaks = np.empty(STAPLE_MAX_BREAKS)
    knots = np.empty(5)
    crit = np.empty(5)
    lo_all = np.zeros((STAPLE_MAX_BREAKS, n_dir))
    hi_all = np.zeros((STAPLE_MAX_BREAKS, n_dir))
    most = 1
    for n in range(n_dir):
        wix, wiy, wiz = wi[n, 0], wi[n, 1], wi[n, 2]
        wox, woy, woz = wo[n, 0], wo[n, 1], wo[n, 2]
        hx, hy, hz, length = half_vector(wix, wiy, wiz, wox, woy, woz)
        if wiz <= 0.0 or woz <= 0.0 or length <= 0.0:
            continue
        m = staple_breakpoints(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, psi, cot_psi, abs_sin_psi,
                               min(domain, PIECE_DOMAIN), breaks, knots, crit)
        count = 0
        for p in range(m - 1):
            a, b = breaks[p], breaks[p + 1]
            mid = 0.5 * (a + b)
            if b > a and staple_integrand(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, math.sin(mid), math.cos(mid),
                                          0.0, cot_psi, abs_sin_psi, 1.0)[0] > 0.0:  # R >= 0 only scales
                lo_all[count, n] = a
                hi_all[count, n] = b
                count += 1
        most = max(most, count)
    return lo_all[:most].copy(), hi_all[:most].copy()


@njit(cache=True, error_model="numpy")
def staple_support_sum(wi, wo, lo, hi, unit_nodes, unit_weights, psi, umax, kappa, w, l):
    """The ``support`` rule of eq. 1 (without f_c) per direction pair (yarn frame): each lit piece of
    :func:`staple_lit_pieces` (``lo``, ``hi``: (P, N)) clipped to [-umax, umax] and integrated with
    ``unit_nodes`` / ``unit_weights`` on [0, 1] (the cosine-mapped Gauss-Legendre rule,
    :func:`clothlab.models.irawan.quadrature.cosine_mapped_unit_rule`).

    The non-empty clipped pieces of all pairs form one work list (most pairs have one or two), evaluated with
    the list innermost and branch-free (the checks of eqs. 3 and 8 applied as a select, :func:`sincos` instead
    of library trigonometry), as :func:`staple_quadrature_sets`, so the loop vectorises."""
    n_dir = wi.shape[0]
    out = np.zeros(n_dir)
    cot_psi = math.cos(psi) / math.sin(psi)
    abs_sin_psi = abs(math.sin(psi))
    a = 0.5 * w
    scale, q = spine_radius_factors(umax, kappa, w, l)  # sec. 5.4
    n_items = 0
    for n in range(n_dir):
        for p in range(lo.shape[0]):
            if min(hi[p, n], umax) > max(lo[p, n], -umax):
                n_items += 1
    owner = np.empty(n_items, dtype=np.int64)
    start = np.empty(n_items)
    span = np.empty(n_items)
    hx = np.empty(n_items)
    hy = np.empty(n_items)
    hz = np.empty(n_items)
    wix, wiy, wiz = np.empty(n_items), np.empty(n_items), np.empty(n_items)
    wox, woy, woz = np.empty(n_items), np.empty(n_items), np.empty(n_items)
    m = 0
    for n in range(n_dir):
        for p in range(lo.shape[0]):
            first, last = max(lo[p, n], -umax), min(hi[p, n], umax)
            if last > first:
                owner[m], start[m], span[m] = n, first, last - first
                hx[m], hy[m], hz[m], _ = half_vector(wi[n, 0], wi[n, 1], wi[n, 2], wo[n, 0], wo[n, 1], wo[n, 2])
                wix[m], wiy[m], wiz[m] = wi[n, 0], wi[n, 1], wi[n, 2]
                wox[m], woy[m], woz[m] = wo[n, 0], wo[n, 1], wo[n, 2]
                m += 1
    acc = np.zeros(n_items)
    for k in range(unit_nodes.shape[0]):
        t, wt = unit_nodes[k], unit_weights[k]
        for m in range(n_items):
            su, cu = sincos(start[m] + span[m] * t)
            x = cu * cu + q * su * su
            radius = scale / (x * math.sqrt(x))  # sec. 5.4: R(u)
            rho, d, cos_v, sin_v = specular_v_terms(hx[m], hy[m], hz[m], su, cu, cot_psi)  # eq. 3
            ci = normal_cosine(wix[m], spine_normal_cosine(wiy[m], wiz[m], su, cu), sin_v, cos_v)  # eq. 8
            cr = normal_cosine(wox[m], spine_normal_cosine(woy[m], woz[m], su, cu), sin_v, cos_v)  # eq. 8
            g = staple_geometry_attenuation(volume_element(radius, a, cos_v), ci, cr, abs_sin_psi)  # eqs. 5 x 8
            lit = rho > 0.0 and abs(d) <= 1.0 and cos_v > 0.0 and ci > 0.0 and cr > 0.0
            acc[m] += wt * (g if lit else 0.0)  # eq. 1
    for m in range(n_items):
        out[owner[m]] += span[m] * acc[m]
    return out


@njit(cache=True)
def staple_break_table(wi, wo, psi, umax):
    """(N, STAPLE_MAX_BREAKS) sorted breakpoints of :func:`staple_breakpoints` per direction pair, padded with
    umax, and (N,) the number of lit pieces (for quad references and the benchmark's piece counts)."""
    n_dir = wi.shape[0]
    out = np.full((n_dir, STAPLE_MAX_BREAKS), umax)
    lit_pieces = np.zeros(n_dir, dtype=np.int64)
    cot_psi = math.cos(psi) / math.sin(psi)
    abs_sin_psi = abs(math.sin(psi))
    breaks = np.empty(STAPLE_MAX_BREAKS)
    knots = np.empty(5)
    crit = np.empty(5)
    for n in range(n_dir):
        wix, wiy, wiz = wi[n, 0], wi[n, 1], wi[n, 2]
        wox, woy, woz = wo[n, 0], wo[n, 1], wo[n, 2]
        hx, hy, hz, length = half_vector(wix, wiy, wiz, wox, woy, woz)
        out[n, 0] = -umax
        if wiz <= 0.0 or woz <= 0.0 or length <= 0.0:
            continue
        m = staple_breakpoints(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, psi, cot_psi, abs_sin_psi, umax, breaks,
                               knots, crit)
        for p in range(m):
            out[n, p] = breaks[p]
        for p in range(m - 1):
            mid = 0.5 * (breaks[p] + breaks[p + 1])
            if breaks[p + 1] > breaks[p] and staple_integrand(
                    wix, wiy, wiz, wox, woy, woz, hx, hy, hz, math.sin(mid), math.cos(mid), 0.0, cot_psi,
                    abs_sin_psi, 1.0)[0] > 0.0:
                lit_pieces[n] += 1
    return out, lit_pieces


@njit(cache=True)
def half_vectors(wi, wo):
    """Unit half vectors (N, 3) and |wi + wo| (N,) of (N, 3) directions (zeros for wo = -wi)."""
    n_dir = wi.shape[0]
    h = np.zeros((n_dir, 3))
    length = np.zeros(n_dir)
    for n in range(n_dir):
        h[n, 0], h[n, 1], h[n, 2], length[n] = half_vector(wi[n, 0], wi[n, 1], wi[n, 2], wo[n, 0], wo[n, 1], wo[n, 2])
    return h, length


@njit(cache=True)
def filament_break_candidates(wi, wo, h):
    """(N, 2) angles v where c_i or c_r of eq. 8 cross zero on the filament's specular curve (NaN: none)."""
    out = np.full((h.shape[0], 2), np.nan)
    for n in range(h.shape[0]):
        if h[n, 2] <= 0.0:
            continue
        u = specular_u(h[n, 1], h[n, 2])  # eq. 4
        su, cu = math.sin(u), math.cos(u)
        for j, d in enumerate((wi, wo)):
            c0 = spine_normal_cosine(d[n, 1], d[n, 2], su, cu)
            if d[n, 0] != 0.0:
                out[n, j] = math.atan(-c0 / d[n, 0])  # w . n(u, v) = 0
    return out


# ---------------------------------------------------------------------------------------------------------
# Pointwise kernels of the texture model (sec. 7.2, Algorithms 3-4): the integrand at one node per point
# *and* the position of the ideal specular point, which the texture needs for the band chi of eq. 12.


@njit(cache=True)
def staple_points(wi, wo, u, umax, psi, kappa, w, l):
    """G_v A at u[n] and the specular v(u) of eq. 3 (+ root) for each point n (Algorithm 3).

    wi, wo: (N, 3) or (1, 3) yarn-frame directions (one row: shared by all points); u, umax: (N,) radians.
    Returns (value, v): value 0 (and v 0) where |u| > umax, |D| > 1, |v| >= pi/2 or a cosine is <= 0.
    """
    n_pts = u.shape[0]
    value = np.zeros(n_pts)
    vpos = np.zeros(n_pts)
    shared = wi.shape[0] == 1
    cot_psi = math.cos(psi) / math.sin(psi)
    abs_sin_psi = abs(math.sin(psi))
    a = 0.5 * w
    for n in range(n_pts):
        row = 0 if shared else n
        wix, wiy, wiz = wi[row, 0], wi[row, 1], wi[row, 2]
        wox, woy, woz = wo[row, 0], wo[row, 1], wo[row, 2]
        hx, hy, hz, length = half_vector(wix, wiy, wiz, wox, woy, woz)
        if wiz <= 0.0 or woz <= 0.0 or length <= 0.0 or abs(u[n]) > umax[n]:
            continue
        su = math.sin(u[n])
        cu = math.cos(u[n])
        r = spine_radius(u[n], umax[n], kappa, w, l)
        g, cos_v, sin_v = staple_integrand(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, su, cu, r, cot_psi,
                                           abs_sin_psi, a)
        if g <= 0.0:
            continue
        value[n] = g
        vpos[n] = math.atan2(sin_v, cos_v)  # eq. 3: v
    return value, vpos


@njit(cache=True)
def filament_points(wi, wo, v, umax, kappa, w, l, delta, shortened):
    """G_u A_s at v[n] and the specular u of eq. 4 for each point n (Algorithm 4).

    wi, wo: (N, 3) or (1, 3) yarn-frame directions (one row: shared); v, umax: (N,) radians.
    Returns (value, u): value 0 where |v| > pi/2, |u| >= umax or a cosine is <= 0 (u is returned anyway).
    Same integrand as :func:`filament_quadrature` (eqs. 4, 6, 8, 9, bounded form; ``shortened`` as there).
    """
    n_pts = v.shape[0]
    value = np.zeros(n_pts)
    upos = np.zeros(n_pts)
    shared = wi.shape[0] == 1
    a = 0.5 * w
    for n in range(n_pts):
        row = 0 if shared else n
        wix, wox = wi[row, 0], wo[row, 0]
        ok, uu, scale, ci0, cr0 = filament_direction(wix, wi[row, 1], wi[row, 2], wox, wo[row, 1], wo[row, 2],
                                                     umax[n], delta)
        upos[n] = uu
        if not ok or abs(v[n]) > 0.5 * math.pi:
            continue
        radius = spine_radius(uu, spine_arc(umax[n], delta, shortened), kappa, w, l)
        value[n] = filament_integrand(wix, ci0, wox, cr0, math.sin(v[n]), math.cos(v[n]), a, radius) * scale
    return value, upos


# ---------------------------------------------------------------------------------------------------------
# A direction set's parameter-free terms (:meth:`clothlab.models.irawan.model.IrawanModel._at`).


@njit(cache=True, error_model="numpy")
def direction_set(wi, wo, nodes, weights, on_arc, warp, weft):
    """A new direction set's parameter-free terms in one compiled call (:meth:`clothlab.models.irawan.model.
    IrawanModel._at`): (cos_x (N,), front (N,), kept (2, N, 3), ok (2, N), moments (2, 6, N)) of (N, 3)
    fabric-frame pairs: -wi . wo, the argument of eq. 7's lobe; whether both directions are above the surface
    (wi_z > 0 and wo_z > 0); copies of wi and wo, the direction set a model keeps to recognise it
    (:func:`same_pairs`); and, for the segment types asked for (``warp``, ``weft``; the other's rows are left
    unset, and ok and moments have no rows when neither is asked for), the filament moments of
    :func:`filament_moments` (row 0 the warp's, row 1 the weft's).  The input is read once and both yarn types'
    moments come from the same columns (the weft frame (-y, x, z) is the warp's with the columns swapped and x
    negated), so a filament parameter set's new directions cost one call instead of three (issue 27)."""
    n_dir = wi.shape[0]
    cos_x = np.empty(n_dir)
    front = np.empty(n_dir, dtype=np.bool_)
    kept = np.empty((2, n_dir, 3))
    rows = 2 if warp or weft else 0  # no moments asked for (a staple fit): nothing allocated for them
    ok = np.empty((rows, n_dir), dtype=np.bool_)
    moments = np.empty((rows, 6, n_dir))
    if not (warp or weft):
        for n in range(n_dir):
            ix, iy, iz, ox, oy, oz = wi[n, 0], wi[n, 1], wi[n, 2], wo[n, 0], wo[n, 1], wo[n, 2]
            kept[0, n, 0], kept[0, n, 1], kept[0, n, 2] = ix, iy, iz
            kept[1, n, 0], kept[1, n, 1], kept[1, n, 2] = ox, oy, oz
            # eq. 7: -wi . wo, summed x, z, then y: the order of numpy's einsum, the previous form (same values)
            cos_x[n] = -((ix * ox + iz * oz) + iy * oy)
            front[n] = iz > 0.0 and oz > 0.0
        return cos_x, front, kept, ok, moments
    columns = np.empty((8, n_dir))  # wi x, y, z, wo x, y, z, then w . n(u, 0) of wi and wo (filament_moments)
    xi, yi, zi, xo, yo, zo = columns[0], columns[1], columns[2], columns[3], columns[4], columns[5]
    for n in range(n_dir):
        ix, iy, iz, ox, oy, oz = wi[n, 0], wi[n, 1], wi[n, 2], wo[n, 0], wo[n, 1], wo[n, 2]
        kept[0, n, 0], kept[0, n, 1], kept[0, n, 2] = ix, iy, iz
        kept[1, n, 0], kept[1, n, 1], kept[1, n, 2] = ox, oy, oz
        cos_x[n] = -((ix * ox + iz * oz) + iy * oy)  # eq. 7, as above
        front[n] = iz > 0.0 and oz > 0.0
        xi[n], yi[n], zi[n], xo[n], yo[n], zo[n] = ix, iy, iz, ox, oy, oz
    if warp:
        _filament_moments_of(xi, yi, zi, xo, yo, zo, 1.0, nodes, weights, on_arc, ok[0], moments[0], columns[6],
                             columns[7])
    if weft:  # weft frame: x' = -y, y' = x (clothlab.frames.to_yarn_frame)
        _filament_moments_of(yi, xi, zi, yo, xo, zo, -1.0, nodes, weights, on_arc, ok[1], moments[1], columns[6],
                             columns[7])
    return cos_x, front, kept, ok, moments


@njit(cache=True)
def same_pairs(kept_wi, kept_wo, wi, wo):
    """Whether (wi, wo) equal (kept_wi, kept_wo) element by element (shapes and values; NaN never equal); a
    branch-free pass over the elements (it vectorises), the second array only when the first agrees."""
    if kept_wi.shape != wi.shape or kept_wo.shape != wo.shape:
        return False
    for x, y in ((kept_wi.ravel(), wi.ravel()), (kept_wo.ravel(), wo.ravel())):
        equal = True
        for i in range(x.shape[0]):
            equal &= x[i] == y[i]
        if not equal:
            return False
    return True


# ---------------------------------------------------------------------------------------------------------
# Many parameter sets at once (the posterior evaluates every walker of an ensemble half in one call).


@njit(cache=True, error_model="numpy")
def filament_moments(wi, wo, nodes, weights, on_arc, weft):
    """The parameter-free part of eq. 2 for each direction pair n, as (ok (N,), moments (6, N)): moments rows
    u, inv, s0, s1, cos u, sin u.

    ``wi``, ``wo``: (N, 3) *fabric*-frame directions, taken into the yarn frame here (``weft``: the weft frame
    (x', y', z') = (-y, x, z) of :func:`clothlab.frames.to_yarn_frame`; else the warp's, the fabric frame), so a
    new direction set costs no yarn-frame copies.  For a filament yarn eq. 4 fixes u per direction, so the
    clamped cosines of eq. 8 and the lit arc depend on the directions alone; Algorithm 2's sum is then
    inv (a R(u) s0 + a^2 s1) fade(u)  with  s0 = sum_k w_k A(v_k), s1 = sum_k w_k cos(v_k) A(v_k) (eq. 6
    numerator a (R + a cos v) times eq. 8) and inv = 1 / (|wi + wo| |(t x h)_x|).  ok is False where the
    integrand vanishes whatever the parameters (back-facing, degenerate h); the cuts |u| < umax and the fade of
    eq. 9 are applied by the caller (:func:`filament_from_moments`).  cos u, sin u of eq. 4's u from the half
    vector without trigonometry (h_z > 0: cos u = h_z / sqrt(h_y^2 + h_z^2), sin u = h_y / sqrt(h_y^2 + h_z^2)).
    ``nodes`` / ``weights`` (1, K) as in :func:`filament_quadrature` (``on_arc``: unit nodes on the lit arc).
    Without ``on_arc`` (the fixed rules) the nodes are the same for every direction: sin v, cos v are computed
    once per node and the loop over the directions is innermost and branch-free (the checks of eq. 8 applied
    as a select), so it vectorises; each direction's sum runs over the nodes in order.  The same loops serve
    :func:`direction_set` (both yarn types from one read of the directions): :func:`_filament_moments_of`."""
    n_dir = wi.shape[0]
    ok = np.empty(n_dir, dtype=np.bool_)
    out = np.empty((6, n_dir))
    columns = np.empty((8, n_dir))  # the yarn-frame columns, then w . n(u, 0) of wi and wo
    ix, iy = (1, 0) if weft else (0, 1)
    for n in range(n_dir):  # the x' column un-negated: the weft's sign is applied to sin v (_filament_moments_of)
        columns[0, n], columns[1, n], columns[2, n] = wi[n, ix], wi[n, iy], wi[n, 2]
        columns[3, n], columns[4, n], columns[5, n] = wo[n, ix], wo[n, iy], wo[n, 2]
    _filament_moments_of(columns[0], columns[1], columns[2], columns[3], columns[4], columns[5],
                         -1.0 if weft else 1.0, nodes, weights, on_arc, ok, out, columns[6], columns[7])
    return ok, out


@njit(cache=True, inline="always")
def _filament_moments_of(xi, yi, zi, xo, yo, zo, sign, nodes, weights, on_arc, ok, out, ci0, cr0):
    """The loops of :func:`filament_moments` on yarn-frame columns whose x' is ``sign`` times ``xi`` / ``xo``
    (the weft's x' = -y): writes ``ok`` (N,) and ``out`` (6, N), using ``ci0``, ``cr0`` (N,) as scratch.  The
    sign is applied to sin v and in the per-direction arc as sign x: (sign x) sin v = x (sign sin v) exactly, so
    the values are those of the negated column."""
    n_dir = ok.shape[0]
    n_nodes = nodes.shape[1]
    u_out, inv, s0, s1, cu_out, su_out = out[0], out[1], out[2], out[3], out[4], out[5]
    for n in range(n_dir):  # branch-free (selects) on contiguous columns, so it vectorises
        wiy, wiz, woy, woz = yi[n], zi[n], yo[n], zo[n]
        # h = s / |s| with s = wi + wo (sec. 6.2); |(t x h)_x| = sqrt(h_y^2 + h_z^2) (eq. 6), so
        # |wi + wo| |(t x h)_x| = r = sqrt(s_y^2 + s_z^2), and u, cos u, sin u follow from s_y, s_z alone
        sy, sz = wiy + woy, wiz + woz
        r = math.sqrt(sy * sy + sz * sz)
        inv_r = 1.0 / r
        good = (wiz > 0.0) & (woz > 0.0) & (r > 0.0)  # else back-facing or degenerate: 0
        u = arctan(sy / sz)  # eq. 4: u = atan(h_y / h_z), h_z > 0
        cu = sz * inv_r  # cos u
        su = sy * inv_r  # sin u
        ok[n] = good
        u_out[n] = u if good else 0.0
        inv[n] = inv_r if good else 0.0
        cu_out[n] = cu if good else 1.0
        su_out[n] = su if good else 0.0
        ci0[n] = spine_normal_cosine(wiy, wiz, su, cu) if good else 0.0
        cr0[n] = spine_normal_cosine(woy, woz, su, cu) if good else 0.0
        s0[n] = 0.0
        s1[n] = 0.0
    if not on_arc:
        for k in range(n_nodes):
            wk = weights[0, k]
            if wk == 0.0:
                continue
            v = nodes[0, k]
            cv = math.cos(v)
            sv = sign * math.sin(v)  # sec. 5.2's x' sin v with x' = sign x
            for n in range(n_dir):
                ci = normal_cosine(xi[n], ci0[n], sv, cv)
                cr = normal_cosine(xo[n], cr0[n], sv, cv)
                g = wk * seeliger(ci, cr)  # eq. 8
                lit = ok[n] and ci > 0.0 and cr > 0.0
                s0[n] += g if lit else 0.0
                s1[n] += g * cv if lit else 0.0
        return
    for n in range(n_dir):
        if not ok[n]:
            continue
        wix, wox = sign * xi[n], sign * xo[n]
        lo_i, hi_i = lit_arc(wix, ci0[n])
        lo_o, hi_o = lit_arc(wox, cr0[n])
        lo = max(lo_i, lo_o)
        span = min(hi_i, hi_o) - lo
        acc0 = 0.0
        acc1 = 0.0
        for k in range(n_nodes if span > 0.0 else 0):
            wk = weights[0, k]
            if wk == 0.0:
                continue
            v = lo + span * nodes[0, k]
            cv = math.cos(v)
            sv = math.sin(v)
            ci = normal_cosine(wix, ci0[n], sv, cv)
            cr = normal_cosine(wox, cr0[n], sv, cv)
            if ci <= 0.0 or cr <= 0.0:
                continue
            g = wk * seeliger(ci, cr)  # eq. 8
            acc0 += g
            acc1 += g * cv
        s0[n] = acc0 * span
        s1[n] = acc1 * span


@njit(cache=True, error_model="numpy")
def staple_quadrature_sets(wi, wo, unit_nodes, unit_weights, psi, umax, kappa, w, l):
    """:func:`staple_quadrature` with the fixed rule ``unit_nodes`` / ``unit_weights`` (K,) on [0, 1] mapped
    onto [-umax_j, umax_j] for each parameter set j: (J, N) sums (eq. 1 without f_c).

    The same integrand as :func:`staple_integrand`, evaluated for every direction at one node (loop over
    directions innermost, branch-free with the checks of eqs. 3 and 8 applied as a select, numpy's error model),
    so the compiler vectorises it (measured ~5x faster than the per-direction loop).  Nodes and weights are
    formed as :func:`clothlab.models.irawan.quadrature.interval_rule` forms them and every direction's sum runs
    over the nodes in order, so row j equals :func:`staple_quadrature` at set j bit for bit."""
    n_sets = psi.shape[0]
    n_dir = wi.shape[0]
    n_nodes = unit_nodes.shape[0]
    out = np.zeros((n_sets, n_dir))
    hx = np.empty(n_dir)
    hy = np.empty(n_dir)
    hz = np.empty(n_dir)
    front = np.zeros(n_dir, dtype=np.bool_)
    for n in range(n_dir):
        hx[n], hy[n], hz[n], length = half_vector(wi[n, 0], wi[n, 1], wi[n, 2], wo[n, 0], wo[n, 1], wo[n, 2])
        front[n] = wi[n, 2] > 0.0 and wo[n, 2] > 0.0 and length > 0.0
    wix, wiy, wiz = wi[:, 0].copy(), wi[:, 1].copy(), wi[:, 2].copy()
    wox, woy, woz = wo[:, 0].copy(), wo[:, 1].copy(), wo[:, 2].copy()
    for j in range(n_sets):
        lo, hi = -umax[j], umax[j]
        cot_psi = math.cos(psi[j]) / math.sin(psi[j])
        abs_sin_psi = abs(math.sin(psi[j]))
        a = 0.5 * w[j]
        acc = out[j]
        for k in range(n_nodes):
            node = lo + (hi - lo) * unit_nodes[k]
            wk = (hi - lo) * unit_weights[k]
            if wk == 0.0:
                continue
            su = math.sin(node)
            cu = math.cos(node)
            radius = spine_radius(node, umax[j], kappa[j], w[j], l[j])
            for n in range(n_dir):
                rho, d, cos_v, sin_v = specular_v_terms(hx[n], hy[n], hz[n], su, cu, cot_psi)  # eq. 3
                ci = normal_cosine(wix[n], spine_normal_cosine(wiy[n], wiz[n], su, cu), sin_v, cos_v)  # eq. 8
                cr = normal_cosine(wox[n], spine_normal_cosine(woy[n], woz[n], su, cu), sin_v, cos_v)  # eq. 8
                g = staple_geometry_attenuation(volume_element(radius, a, cos_v), ci, cr, abs_sin_psi)  # eqs. 5 x 8
                lit = front[n] and rho > 0.0 and abs(d) <= 1.0 and cos_v > 0.0 and ci > 0.0 and cr > 0.0
                acc[n] += wk * (g if lit else 0.0)  # eq. 1
    return out


@njit(cache=True, error_model="numpy")
def filament_from_moments(ok, moments, umax, kappa, w, l, delta, shortened):
    """(J, N) filament I_j (eq. 2) from ``ok`` and the moments of :func:`filament_moments` for J parameter sets
    (umax in radians): inv fade(u) (a R(u) s0 + a^2 s1), zero where |u| >= umax or the fade of
    eq. 9 is 0.  Branch-free over the directions (the cuts applied as a select), so the loop vectorises.
    ``shortened``: R on the arc of :func:`spine_arc`, |u| clamped to it."""
    n_sets = umax.shape[0]
    n_dir = ok.shape[0]
    u, inv, s0, s1, cu, su = moments[0], moments[1], moments[2], moments[3], moments[4], moments[5]
    out = np.zeros((n_sets, n_dir))
    for j in range(n_sets):
        a = 0.5 * w[j]
        arc = spine_arc(umax[j], delta[j], shortened)
        scale, q = spine_radius_factors(arc, kappa[j], w[j], l[j])  # sec. 5.4
        c_arc, s_arc = math.cos(arc), math.sin(arc)
        row = out[j]
        for n in range(n_dir):
            fade = filament_fade(u[n], umax[j], delta[j])  # eq. 9
            inside = abs(u[n]) <= arc  # R is even in u: |u| clamped to the arc
            radius = spine_radius_at(cu[n] if inside else c_arc, su[n] if inside else s_arc, scale, q)  # R(u)
            value = inv[n] * fade * (a * radius * s0[n] + a * a * s1[n])  # eq. 2 (eq. 6 numerator x eq. 8)
            row[n] = value if ok[n] and abs(u[n]) < umax[j] and fade > 0.0 else 0.0
    return out
