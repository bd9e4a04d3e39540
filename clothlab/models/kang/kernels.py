"""Compiled (numba) kernel of Kang's tile average: E[ao p(h; n_p)] over the perturbation rectangle of eqs. 3-4.

Why the integrand is a function of the half vector alone.  In eq. 1 as evaluated here (rho = p(h) F(k.h) /
(4 (k.h) max(k1.n, k2.n)), :mod:`.microfacet`) the Fresnel term and the denominator use the macro normal;
only the eq. 2 density p(h; n_p) depends on the perturbed normal n_p.  So, per yarn type,

    E[ao rho] = G(wi, wo) A(h),   G = F(k.h) / (4 (k.h) max(k1.n, k2.n)),
    A(h) = 1 / (4 c_y c_f) * int_{-c_y}^{c_y} int_{-c_f}^{c_f} n_p.z p(h; n_p(da, dl)) d(dl) d(da),

with n_p = (da, dl, sqrt(1 - da^2 - dl^2)) in the yarn frame (eqs. 3-4) and ao = n_p.z (sec. 4.2.2).  The lobe
frame of eq. 2 about n_p has closed forms: t = (x - da n_p) / s and b = n_p x t = (0, n_z, -dl) / s with
s = sqrt(1 - da^2), so h.t = (h_x - da h.n) / s and h.b = (h_y n_z - h_z dl) / s.

The rule (:func:`peak_tile_average`).  A depends on (|h_x|, |h_y|, h_z) only (the rectangle is symmetric).
Across (outer, in da): Gauss-Legendre after the tan map x = mu + lam tan u (lam = 2 widths; the nodes' tans by
angle addition, one per symmetric pair), centred on the highest reachable h.n_p (h_x, or the edge's
conditional peak when |h_y| > c_f), width hyz / sqrt(nx), on the *lit* interval only: the lobe is 0 where
h.n_p <= 0 (eq. 2 needs h.n > 0), and {da: max over dl of h.n_p > 0} is an interval (h.n_p is concave), cut at
|da| = hyz or at the root of a quadratic on the edge (:func:`_lit_across`) - integrating across that kink is
what limited the previous rule at grazing h_x (0.22 % on wool-gabardine).  Where the along lobe's peak enters
the rectangle inside the across range (a step in the across integrand at da = +-da_c) the across axis is split
there.  Along (inner, per across node): with n_p = (da, s sin beta, s cos beta), s = sqrt(1 - da^2), the lobe
is a function of psi = beta - beta0 (beta0 = atan2(h_y, h_z)): h.n_p = h_x da + s hyz cos psi,
h.b = hyz sin psi, h.t = h_x s - da hyz cos psi, and ao d(dl) = n_z^2 d(psi) with n_z = s cos beta (no square
root: the ambient occlusion is analytic in psi, so no node term for it), of width 1 / (hyz sqrt(ny)) in psi
whatever h_z (in dl it shrinks with h_z).  The substitution t = tan(psi / 2) makes sin psi, cos psi rational:
no trigonometry per node; the range is dl in [-c_f, c_f] (|beta| <= asin(c_f / s)) cut to the lit part
cos psi > -h_x da / (s hyz).  The nodes in t come from the sin map x = mu + lam v / sqrt(1 - v^2) (v = sin u
of the tan map: a square root per node), split at t = 0 where nx > ny puts two peaks at h.t = 0.  Node
counts: 2 + ceil(2 r_a + 0.5 x (growth of the along range in lobe widths)) across and 2 + ceil(1.5 (r_t +
sqrt(nx) da hyz (1 - cos psi_max))) along (r = half the interval in lobe widths), at most ``most`` per piece;
1 on an axis whose curvature and curvature / width are both < 1e-3.  Measured accuracy: docs/kang.md.

The previous rule (:func:`previous_peak_tile_average`, kept for the bench's side-by-side timing) integrated
dl directly with a tan per node and 2 + ceil(1.5 r + 4 c) nodes per axis over the whole rectangle.

Serial on purpose, as :mod:`clothlab.models.irawan.kernels` (numba's thread pool is slower on a loaded
2-core machine).  Imported lazily; compiled code cached on disk.
"""

from __future__ import annotations

import math

import numpy as np

from clothlab.models.jit import njit

#: scale of the map in units of the lobe's first-order width: lam = LAM_WIDTHS * sigma.
LAM_WIDTHS = 2.0
#: an axis [-c, c] with both c and c / sigma below R_SINGLE gets one node (its centre).
R_SINGLE = 1e-3
#: node count of an axis spanning r lobe widths (half its length / sigma): NODES_BASE + ceil(k r), k =
#: NODES_PER_WIDTH_ALONG (along, in t = tan(psi / 2)) or NODES_PER_WIDTH_ACROSS (across, in da), at most ``most``.
NODES_BASE = 2
NODES_PER_WIDTH_ALONG = 1.5
NODES_PER_ALONG_SHIFT = 0.5
NODES_PER_WIDTH_ACROSS = 2.0
#: map of the across axis (:func:`_mapped_rule`): tan (True) or sin; the along axis takes the sin map
#: (:func:`_sin_map_nodes`, finished in :func:`peak_tile_average`'s loop over all along nodes)
TAN_ACROSS = True
#: the previous rule's constants (:func:`previous_peak_tile_average`): 2 + ceil(NODES_PER_WIDTH r +
#: NODES_PER_CURVATURE c) per axis in dl / da.
NODES_PER_WIDTH = 1.5
NODES_PER_CURVATURE = 4.0


@njit(cache=True, inline="always")
def _axis_count(c, sigma, most):
    """Nodes for an axis [-c, c] holding a lobe of width sigma (module constants; 1 when c = 0)."""
    if c <= 0.0:
        return 1
    r = c / sigma
    if r < R_SINGLE and c < R_SINGLE:
        return 1
    return min(most, 2 + int(math.ceil(NODES_PER_WIDTH * r + NODES_PER_CURVATURE * c)))


@njit(cache=True, inline="always")
def _axis_nodes(mu, sigma, c, count, gl_x, gl_w, out_x, out_w):
    """``count`` nodes / weights (summing to the mean over [-c, c]) of the tan-mapped Gauss-Legendre rule
    centred on mu with width sigma; ``gl_x[count]``, ``gl_w[count]``: the count-node rule on [-1, 1]."""
    if count == 1:
        out_x[0] = 0.0
        out_w[0] = 1.0
        return
    lam = LAM_WIDTHS * sigma
    if lam >= 64.0 * c:  # lobe far wider than the interval: the map is linear there; plain Gauss-Legendre
        for k in range(count):
            out_x[k] = c * gl_x[count, k]
            out_w[k] = gl_w[count, k]
        return
    ua = math.atan((-c - mu) / lam)
    ub = math.atan((c - mu) / lam)
    half = 0.5 * (ub - ua)
    mid = 0.5 * (ub + ua)
    for k in range(count):
        t = math.tan(mid + half * gl_x[count, k])
        out_x[k] = min(max(mu + lam * t, -c), c)
        # dx = lam sec^2 u du; mean over [-c, c]: / (2 c); gl_w sums to 1 over [-1, 1], i.e. du = 2 half gl_w
        out_w[k] = gl_w[count, k] * half * lam * (1.0 + t * t) / c


@njit(cache=True, inline="always")
def _lobe(hx, hy, hz, da, dl, inv_s, nx, ny):
    """n_p.z (h.n_p)^(nx cos^2 phi + ny sin^2 phi) (eq. 2 without its constant, times ao, sec. 4.2.2)."""
    nz2 = 1.0 - da * da - dl * dl
    nz = math.sqrt(nz2) if nz2 > 0.0 else 0.0
    cz = hx * da + hy * dl + hz * nz  # h.n_p
    if cz <= 0.0:
        return 0.0
    tx = (hx - da * cz) * inv_s  # h.t
    ty = (hy * nz - hz * dl) * inv_s  # h.b
    sin2 = tx * tx + ty * ty
    if sin2 <= 1e-300:
        return nz
    return nz * math.exp((nx * tx * tx + ny * ty * ty) * math.log(cz) / sin2)  # eq. 2: (h.n)^e


@njit(cache=True)
def previous_peak_tile_average(h, nx, ny, c_y, c_f, gl_x, gl_w, most):
    """The previous peak rule (kept for the ``kang`` bench section's side-by-side timing): dl-space tan map with
    a tan per node, node count 2 + ceil(1.5 r + 4 c), no support clipping.

    A(h) (N,) of the module docstring for unit half vectors h (N, 3) in the yarn frame (1/sr, with the eq. 2
    constant sqrt((nx+1)(ny+1)) / (2 pi)); 0 where h_z <= 0.  ``gl_x``, ``gl_w`` (M + 1, M): row k the
    k-node Gauss-Legendre rule on [-1, 1], weights summing to 1; ``most`` <= M nodes per axis."""
    n = h.shape[0]
    out = np.zeros(n)
    scale = math.sqrt((nx + 1.0) * (ny + 1.0)) / (2.0 * math.pi)  # eq. 2 constant
    xa = np.zeros(most)
    wa = np.zeros(most)
    xl = np.zeros(most)
    wl = np.zeros(most)
    root_nx = math.sqrt(max(nx, 1e-12))
    root_ny = math.sqrt(max(ny, 1e-12))
    for i in range(n):
        hx, hy, hz = h[i, 0], h[i, 1], h[i, 2]
        if hz <= 0.0:
            continue
        hyz = math.sqrt(hy * hy + hz * hz)  # = sqrt(1 - hx^2)
        # across axis: centred on the highest h.n_p reachable (the peak hx if |hy| <= c_f, else the peak
        # along the edge dl = +-c_f), width cos(asin hx) / sqrt(nx) (the lobe cos^nx along the ridge)
        mu_a = hx
        if abs(hy) > c_f:
            dl_edge = math.copysign(c_f, hy)
            mu_a = hx * math.sqrt(1.0 - dl_edge * dl_edge) / math.sqrt(hx * hx + hz * hz)
        sigma_a = hyz / root_nx
        count_a = _axis_count(c_y, sigma_a, most)
        _axis_nodes(mu_a, sigma_a, c_y, count_a, gl_x, gl_w, xa, wa)
        acc = 0.0
        for a in range(count_a):
            da = xa[a]
            s = math.sqrt(1.0 - da * da)
            inv = 1.0 / s
            # along axis, given da: the conditional peak dl* = hy s / hyz (max of h.n_p over dl, h.b = 0
            # there), width h_z s / (hyz^2 sqrt(ny)) (from d(h.b)/d(dl) at dl*)
            sigma_l = max(hz, 1e-6) * s / (hyz * hyz * root_ny)
            count_l = _axis_count(c_f, sigma_l, most)
            _axis_nodes(hy * s / hyz, sigma_l, c_f, count_l, gl_x, gl_w, xl, wl)
            inner = 0.0
            for b in range(count_l):
                inner += wl[b] * _lobe(hx, hy, hz, da, xl[b], inv, nx, ny)
            acc += wa[a] * inner
        out[i] = scale * acc
    return out


@njit(cache=True, inline="always", error_model="numpy")
def _sin_map_range(centre, lam, lo, hi):
    """The sin map's v-range of [lo, hi] (x = centre + lam v / sqrt(1 - v^2)): (mid, half, scale) with
    v = mid + half x_k for the Gauss-Legendre nodes x_k and scale = 2 half lam (gl_w sums to 1 over [-1, 1],
    i.e. dv = 2 half gl_w; dx = lam q^3 dv, q = 1 / sqrt(1 - v^2))."""
    pa = lo - centre
    pb = hi - centre
    va = pa / math.sqrt(lam * lam + pa * pa)
    vb = pb / math.sqrt(lam * lam + pb * pb)
    half = 0.5 * (vb - va)
    return 0.5 * (vb + va), half, 2.0 * half * lam


@njit(cache=True, inline="always", error_model="numpy")
def _mapped_rule(centre, lam, lo, hi, count, plain, tan_map, gl_x, gl_w, out_x, out_w):
    """``count`` nodes / weights (the weights integrate over [lo, hi], they do not average) of Gauss-Legendre
    after a change of variables that puts the nodes on a lobe of scale lam at ``centre`` (inside [lo, hi] or
    not), with Cauchy-like tails so that nothing is truncated:

    - ``tan_map``: x = centre + lam tan u, Gauss-Legendre in u (nodes evenly in the lobe's angle); tan of the
      nodes by angle addition, tan(m +- d) = (tan m +- tan d) / (1 -+ tan m tan d): one tan per symmetric pair
      of nodes instead of one per node;
    - else: x = centre + lam v / sqrt(1 - v^2) (v = sin u), Gauss-Legendre in v: a square root per node, no
      trigonometry (cheaper; fewer nodes in the far tails);
    - ``plain`` and lam >= (hi - lo) / 2 (a lobe wider than the interval): plain Gauss-Legendre on [lo, hi]."""
    half_x = 0.5 * (hi - lo)
    if plain and lam >= half_x:
        mid_x = 0.5 * (hi + lo)
        for k in range(count):
            out_x[k] = mid_x + half_x * gl_x[count, k]
            out_w[k] = 2.0 * half_x * gl_w[count, k]
        return
    if tan_map:
        ua = math.atan((lo - centre) / lam)
        ub = math.atan((hi - centre) / lam)
        half = 0.5 * (ub - ua)
        tan_mid = math.tan(0.5 * (ub + ua))
        for k in range((count + 1) // 2):  # gl_x ascending: nodes k and count - 1 - k are symmetric
            tan_d = math.tan(half * gl_x[count, count - 1 - k])
            for sign, j in ((1.0, count - 1 - k), (-1.0, k)):
                t = (tan_mid + sign * tan_d) / (1.0 - sign * tan_mid * tan_d)
                out_x[j] = min(max(centre + lam * t, lo), hi)
                out_w[j] = gl_w[count, j] * 2.0 * half * lam * (1.0 + t * t)  # dx = lam sec^2 u du
        return
    mid, half, scale = _sin_map_range(centre, lam, lo, hi)
    for k in range(count):
        v = mid + half * gl_x[count, k]
        q = 1.0 / math.sqrt(1.0 - v * v)
        out_x[k] = min(max(centre + lam * v * q, lo), hi)
        out_w[k] = gl_w[count, k] * scale * q * q * q


@njit(cache=True, inline="always", error_model="numpy")
def _lit_across(hx, hy, hz, hyz, c_f):
    """Largest |da| (>= 0) on the side opposite to h_x at which some dl in [-c_f, c_f] still gives h.n_p > 0
    (2.0: no limit).  The lobe of eq. 2 is 0 where h.n_p <= 0; h.n_p is concave in (da, dl), so its positive set
    in da is an interval, and it is unbounded on h_x's side (h.n_p(da, 0) > 0 there).  With the conditional
    peak dl* = h_y s / hyz inside the range the bound is |da| = hyz (h.n_p = |h_x| da + s hyz = 0); otherwise
    h.n_p = 0 on the edge dl = sign(h_y) c_f: a quadratic in da.  Arguments |h_x|, |h_y| >= 0."""
    if hx <= 0.0:
        return 2.0
    if hy * hx / hyz <= c_f:
        return hyz
    k = hy * c_f
    r2 = 1.0 - c_f * c_f
    if k >= hx * math.sqrt(r2):
        return 2.0
    a2 = hx * hx + hz * hz
    return (k * hx + hz * math.sqrt(a2 * r2 - k * k)) / a2


@njit(cache=True, inline="always", error_model="numpy")
def _across_terms(da, hx, hyz, cb, sb, c_f, root_nx):
    """The terms of :func:`peak_tile_average` at across node da that need square roots and divisions, without
    branches: (s, h_x da, h_x / s, da / s, t_hi, t_lo, kappa, tan(acos kappa / 2), cos psi_x, sin psi_x,
    sigma_x); the rule uses each only where it applies (the clamps change nothing there)."""
    s = math.sqrt(1.0 - da * da)
    hxda = hx * da
    # along: n_p = (da, s sin beta, s cos beta), beta = beta0 + psi, t = tan(psi / 2) (rational sin psi, cos psi);
    # dl = s sin beta in [-c_f, c_f] and h.n_p = h_x da + s hyz cos psi > 0
    sin_b = c_f / s
    cos_b = math.sqrt(1.0 - sin_b * sin_b)
    t_hi = (sin_b * cb - cos_b * sb) / (1.0 + cos_b * cb + sin_b * sb)  # tan((B - beta0) / 2)
    t_lo = -(sin_b * cb + cos_b * sb) / (1.0 + cos_b * cb - sin_b * sb)  # tan((-B - beta0) / 2)
    kappa = -hxda / (s * hyz)  # cos psi > kappa is the lit part
    t_lit = math.sqrt(max(1.0 - kappa * kappa, 0.0)) / (1.0 + kappa)  # tan(acos(kappa) / 2), for |kappa| < 1
    # h.t = 0 where h.n_p = h_x / da (da > 0): with nx > ny the lobe peaks there, at psi = +-psi_x,
    # cos psi_x = h_x s / (da hyz) - two peaks, width 1 / (sqrt(nx) da hyz sin psi_x) (for 0 <= cos psi_x < 1)
    cos_x = hx * s / (da * hyz)
    sin_x = math.sqrt(max(1.0 - cos_x * cos_x, 0.0))
    sigma_x = 0.5 / (root_nx * da * hyz * sin_x)  # in psi / 2
    return s, hxda, hx / s, da / s, t_hi, t_lo, kappa, t_lit, cos_x, sin_x, sigma_x


@njit(cache=True, inline="always", error_model="numpy")
def _sin_map_nodes(centre, lam, lo, hi, count, gl_x, gl_w, node, f):
    """:func:`_mapped_rule`'s sin map (``tan_map`` False, not ``plain``: the along axis) in two halves: here the
    parts that do not need a square root per node - v = mid + half x_k and gl_w_k 2 half lam, with the piece's
    centre, lam, lo, hi - written to columns f, ..., f + count - 1 of ``node`` (rows 0-5); the loop of
    :func:`peak_tile_average` then forms x = clip(centre + lam v q, lo, hi) and the weight (gl_w 2 half lam) q^3,
    q = 1 / sqrt(1 - v^2), for all along nodes of a direction at once.  Returns f + count."""
    mid, half, scale = _sin_map_range(centre, lam, lo, hi)
    for k in range(count):
        node[0, f + k] = mid + half * gl_x[count, k]
        node[1, f + k] = gl_w[count, k] * scale
        node[2, f + k] = centre
        node[3, f + k] = lam
        node[4, f + k] = lo
        node[5, f + k] = hi
    return f + count


@njit(cache=True, error_model="numpy")
def peak_tile_average(h, nx, ny, c_y, c_f, gl_x, gl_w, most):
    """A(h) (N,) of the module docstring (1/sr, with the eq. 2 constant sqrt((nx+1)(ny+1)) / (2 pi)) for unit
    half vectors h (N, 3) in the yarn frame; 0 where h_z <= 0.  ``gl_x``, ``gl_w`` (M + 1, M): row k the k-node
    Gauss-Legendre rule on [-1, 1], weights summing to 1; at most ``most`` <= M nodes per axis.

    The peak-centred rule on the lit part of the rectangle (module docstring, "The rule"): A depends on
    (|h_x|, |h_y|, h_z) only (the rectangle is symmetric), so the signs are dropped."""
    n = h.shape[0]
    out = np.zeros(n)
    scale = math.sqrt((nx + 1.0) * (ny + 1.0)) / (2.0 * math.pi)  # eq. 2 constant
    xa = np.zeros(4 * most)
    wa = np.zeros(4 * most)
    xp = np.zeros(most)
    wp = np.zeros(most)
    mode = np.empty(4 * most, dtype=np.int64)  # per across node: 0 nothing lit, 1 one node (single), 2 along nodes
    start = np.empty(4 * most, dtype=np.int64)  # its along nodes in the flat block: [start, stop)
    stop = np.empty(4 * most, dtype=np.int64)
    single = np.empty(4 * most)
    across = np.empty((11, 4 * most))  # per across node: s, h_x da, h_x / s, da / s, the along range's ends, ...
    a_s, a_hxda, a_hxs, a_das, a_thi, a_tlo = across[0], across[1], across[2], across[3], across[4], across[5]
    a_kappa, a_tlit, a_cosx, a_sinx, a_sigx = across[6], across[7], across[8], across[9], across[10]
    node = np.empty((11, 8 * most * most))  # per along node: v, weight scale, centre, lam, lo, hi, s, h_x da, ...
    res = np.empty((3, 8 * most * most))  # per along node: the weight times ao d(dl) / dt (0: not lit), e, h.n_p
    root_nx = math.sqrt(max(nx, 1e-12))
    root_ny = math.sqrt(max(ny, 1e-12))
    delta = 0.0
    for i in range(n):
        hx, hy, hz = abs(h[i, 0]), abs(h[i, 1]), h[i, 2]
        if hz <= 0.0:
            continue
        hyz = math.sqrt(hy * hy + hz * hz)  # = sqrt(1 - hx^2)
        sb = hy / hyz  # sin, cos of beta0 = atan2(h_y, h_z): the along angle of the lobe's peak
        cb = hz / hyz
        # --- across (da): centred on the highest reachable h.n_p, width hyz / sqrt(nx), on the lit interval
        sigma_a = hyz / root_nx
        if c_y < R_SINGLE and c_y < R_SINGLE * sigma_a:
            count_a = 1
            xa[0] = 0.0
            wa[0] = 1.0
        else:
            mu_a = hx
            if hy > c_f:  # the peak dl* = h_y lies beyond the edge: the highest point along dl = c_f
                mu_a = hx * math.sqrt(1.0 - c_f * c_f) / math.sqrt(hx * hx + hz * hz)
            lo_a = -min(c_y, _lit_across(hx, hy, hz, hyz, c_f))
            # the along peak (beta = beta0) enters [-B, B], B = asin(c_f / s), where s = c_f / sin(beta0): a step
            # of width delta in the across integrand at da = +-da_c; split there when it is sharper than the piece
            da_c = 2.0
            if sb > c_f:
                s_c = c_f / sb
                da_c = math.sqrt(1.0 - s_c * s_c)
                delta = s_c * s_c * math.sqrt(max(s_c * s_c - c_f * c_f, 0.0)) / (c_f * da_c * hyz * root_ny)
            if da_c < c_y and LAM_WIDTHS * delta < 0.5 * (c_y - lo_a):
                # pieces [lo_a, -da_c], [-da_c, 0], [0, da_c], [da_c, c_y] (those inside), mapped on their step end
                count_a = 0
                for piece in range(4):
                    p0 = (lo_a, -da_c, 0.0, da_c)[piece]
                    p1 = (-da_c, 0.0, da_c, c_y)[piece]
                    p0 = max(p0, lo_a)
                    if p1 <= p0:
                        continue
                    centre, width = (p1 if piece % 2 == 0 else p0), delta  # on the step
                    if sigma_a < delta and p0 <= mu_a <= p1:
                        centre, width = mu_a, sigma_a  # on the across peak, where it is the sharper feature
                    count = min(most, NODES_BASE + int(math.ceil(NODES_PER_WIDTH_ACROSS * 0.5 * (p1 - p0)
                                                                 / min(sigma_a, delta))))
                    _mapped_rule(centre, LAM_WIDTHS * width, p0, p1, count, True, TAN_ACROSS, gl_x, gl_w, xp, wp)
                    for k in range(count):
                        xa[count_a + k] = xp[k]
                        wa[count_a + k] = wp[k] / (2.0 * c_y)
                    count_a += count
            else:
                half_a = 0.5 * (c_y - lo_a)
                # the along range B(da) = asin(c_f / s) widens over the across range; in along lobe widths:
                shift = (math.asin(min(c_f / math.sqrt(1.0 - c_y * c_y), 1.0)) - math.asin(c_f)) * hyz * root_ny
                count_a = min(most, NODES_BASE + int(math.ceil(NODES_PER_WIDTH_ACROSS * half_a / sigma_a
                                                               + NODES_PER_ALONG_SHIFT * shift)))
                _mapped_rule(mu_a, LAM_WIDTHS * sigma_a, lo_a, c_y, count_a, True, TAN_ACROSS, gl_x, gl_w, xa, wa)
                for a in range(count_a):
                    wa[a] /= 2.0 * c_y  # mean over [-c_y, c_y]
        # --- per across node: the along range and its nodes (the parts without a square root per node), into
        # the flat block `node`; then one branch-free loop over all of the direction's along nodes (it
        # vectorises: the square root and three divisions per node), then exp / log in the order of the nodes
        # every across node has along nodes where c_f >= R_SINGLE: their terms in one loop, which vectorises
        # (for a few across nodes, made one by one below)
        ahead = c_f >= R_SINGLE and count_a >= 4
        if ahead:
            for a in range(count_a):
                s, hxda, hxs, das, t_hi, t_lo, kappa, t_lit, cos_x, sin_x, sigma_x = _across_terms(
                    xa[a], hx, hyz, cb, sb, c_f, root_nx)
                a_s[a] = s
                a_hxda[a] = hxda
                a_hxs[a] = hxs
                a_das[a] = das
                a_thi[a] = t_hi
                a_tlo[a] = t_lo
                a_kappa[a] = kappa
                a_tlit[a] = t_lit
                a_cosx[a] = cos_x
                a_sinx[a] = sin_x
                a_sigx[a] = sigma_x
        n_flat = 0
        for a in range(count_a):
            mode[a] = 0
            da = xa[a]
            if ahead:
                s, hxda, hxs, das, t_hi, t_lo, kappa, t_lit, cos_x, sin_x, sigma_x = (
                    a_s[a], a_hxda[a], a_hxs[a], a_das[a], a_thi[a], a_tlo[a], a_kappa[a], a_tlit[a], a_cosx[a],
                    a_sinx[a], a_sigx[a])
            else:
                s = math.sqrt(1.0 - da * da)
                hxda = hx * da
                hxs = hx / s
                das = da / s
            if c_f < R_SINGLE and c_f * hyz * hyz * root_ny < R_SINGLE * hz * s:
                # one node dl = 0 (eqs. 3-4 with delta_along = 0): n_p = (da, 0, s), ao = s
                cz = hxda + hz * s
                if cz > 0.0:
                    tx = hxs - das * cz  # h.t
                    sin2 = tx * tx + hy * hy  # h.b = h_y
                    e = (nx * tx * tx + ny * hy * hy) / sin2 if sin2 > 1e-300 else 0.0
                    mode[a] = 1
                    single[a] = wa[a] * s * math.exp(e * math.log(cz))  # eq. 2: (h.n)^e, times ao (sec. 4.2.2)
                continue
            if not ahead:  # (the same values as made ahead)
                s, hxda, hxs, das, t_hi, t_lo, kappa, t_lit, cos_x, sin_x, sigma_x = _across_terms(
                    da, hx, hyz, cb, sb, c_f, root_nx)
            if kappa >= 1.0:
                continue
            if kappa > -1.0:
                t_lo = max(t_lo, -t_lit)
                t_hi = min(t_hi, t_lit)
                if t_hi <= t_lo:
                    continue
            sigma_t = 0.5 / (hyz * root_ny)  # the lobe exp(-ny hyz^2 psi^2 / 2) in t ~ psi / 2
            t_x = 0.0  # the two peaks at +-psi_x (above): split at t = 0 where they are sharper than the range
            if nx > ny and da > 0.0 and hx > 0.0:
                if kappa < cos_x < 1.0:
                    if sin_x > 0.0 and math.asin(sin_x) > LAM_WIDTHS * sigma_x and sigma_x < sigma_t:
                        t_x = sin_x / (1.0 + cos_x)  # tan(psi_x / 2)
                        sigma_x *= 1.0 + t_x * t_x  # dt = (1 + t^2) / 2 d(psi)
            first = n_flat
            if t_x > 0.0 and t_lo < 0.0 < t_hi:
                for piece in range(2):
                    p0, p1, centre = (t_lo, 0.0, -t_x) if piece == 0 else (0.0, t_hi, t_x)
                    count = min(most, NODES_BASE + int(math.ceil(NODES_PER_WIDTH_ALONG * 0.5 * (p1 - p0) / sigma_x)))
                    n_flat = _sin_map_nodes(centre, LAM_WIDTHS * sigma_x, p0, p1, count, gl_x, gl_w, node, n_flat)
            else:
                # h.t = h_x s - da hyz cos psi varies along too: by da hyz (1 - cos psi) over the range, which
                # the across exponent nx turns into sqrt(nx) x that lobe widths (nx >> ny: the lobe's shape)
                t_m = max(-t_lo, t_hi)
                sweep = root_nx * abs(da) * hyz * 2.0 * t_m * t_m / (1.0 + t_m * t_m)
                count_l = min(most, NODES_BASE + int(math.ceil(NODES_PER_WIDTH_ALONG * (0.5 * (t_hi - t_lo)
                                                                                        / sigma_t + sweep))))
                n_flat = _sin_map_nodes(0.0, min(LAM_WIDTHS * sigma_t, 1.0), t_lo, t_hi, count_l, gl_x, gl_w, node,
                                        n_flat)
            hyz_s = hyz * s
            for f in range(first, n_flat):  # the across node's terms, for the loop over the flat block
                node[6, f] = s
                node[7, f] = hxda
                node[8, f] = hyz_s
                node[9, f] = hxs
                node[10, f] = das
            mode[a] = 2
            start[a] = first
            stop[a] = n_flat
        v_, ws_, cen_, lam_, lo_, hi_ = node[0], node[1], node[2], node[3], node[4], node[5]
        s_, hxda_, hyzs_, hxs_, das_ = node[6], node[7], node[8], node[9], node[10]
        pre_, e_, cz_ = res[0], res[1], res[2]
        for f in range(n_flat):  # branch-free (selects), so it vectorises; each node's arithmetic as before
            v = v_[f]
            q = 1.0 / math.sqrt(1.0 - v * v)
            t = min(max(cen_[f] + lam_[f] * v * q, lo_[f]), hi_[f])  # _mapped_rule's sin map: the node
            w = ws_[f] * q * q * q  # and its weight, dx = lam q^3 dv
            u = 1.0 / (1.0 + t * t)
            cos_p = (1.0 - t * t) * u
            sin_p = 2.0 * t * u
            nz = s_[f] * (cb * cos_p - sb * sin_p)  # n_p.z = s cos beta = ao (sec. 4.2.2)
            cz = hxda_[f] + hyzs_[f] * cos_p  # h.n_p
            tx = hxs_[f] - das_[f] * cz  # h.t
            ty = hyz * sin_p  # |h.b|
            sin2 = tx * tx + ty * ty
            e = (nx * tx * tx + ny * ty * ty) / sin2
            e_[f] = e if sin2 > 1e-300 else 0.0  # eq. 2 exponent
            cz_[f] = cz
            # ao p d(dl) = nz * (h.n_p)^e * nz d(psi), d(psi) = 2 u dt; 0 marks a node that is not lit (a lit
            # node's factor is > 0, and adding 0.0 would not change a sum of positive terms anyway)
            pre = w * nz * nz * 2.0 * u
            pre_[f] = 0.0 if (cz <= 0.0 or nz <= 0.0) else pre
        acc = 0.0
        for a in range(count_a):  # the across nodes' sums in their order, each over its along nodes in order
            if mode[a] == 1:
                acc += single[a]
            elif mode[a] == 2:
                inner = 0.0
                for f in range(start[a], stop[a]):
                    if pre_[f] != 0.0:
                        inner += pre_[f] * math.exp(e_[f] * math.log(cz_[f]))  # eq. 2: (h.n)^e
                acc += wa[a] * inner / (2.0 * c_f)  # mean over [-c_f, c_f]
        out[i] = scale * acc
    return out


def gauss_legendre_table(most: int) -> tuple[np.ndarray, np.ndarray]:
    """(x, w) (most + 1, most): row k the k-node Gauss-Legendre rule on [-1, 1], weights summing to 1."""
    x = np.zeros((most + 1, most))
    w = np.zeros((most + 1, most))
    for k in range(1, most + 1):
        nodes, weights = np.polynomial.legendre.leggauss(k)
        x[k, :k], w[k, :k] = nodes, weights / 2.0
    return x, w


@njit(cache=True)
def legendre_tile_average(h, nx, ny, c_y, c_f, x_a, w_a, x_l, w_l):
    """A(h) (N,) with a fixed tensor Gauss-Legendre rule over the rectangle (nodes ``x_a`` x ``x_l`` on
    [-1, 1], weights summing to 1): the previous rule, compiled (the converged reference with many nodes)."""
    n = h.shape[0]
    out = np.zeros(n)
    scale = math.sqrt((nx + 1.0) * (ny + 1.0)) / (2.0 * math.pi)  # eq. 2 constant
    for i in range(n):
        hx, hy, hz = h[i, 0], h[i, 1], h[i, 2]
        if hz <= 0.0:
            continue
        acc = 0.0
        for a in range(x_a.size):
            da = c_y * x_a[a]
            inv_s = 1.0 / math.sqrt(1.0 - da * da)
            inner = 0.0
            for b in range(x_l.size):
                inner += w_l[b] * _lobe(hx, hy, hz, da, c_f * x_l[b], inv_s, nx, ny)
            acc += w_a[a] * inner
        out[i] = scale * acc
    return out


# ------------------------------------------------------------------ a new direction set (the cold path)


@njit(cache=True, error_model="numpy")
def direction_terms(wi, wo):
    """The parameter-free terms of eq. 1 at fabric-frame directions wi, wo (N, 3) in one pass:
    (h (N, 3), m5 (N,), inv_denom (N,)) with h = |(wi + wo) / |wi + wo|| componentwise (zero where
    wi + wo = 0; A depends on |h_x|, |h_y|, h_z only), m5 = (1 - clip(k.h, 0, 1))^5 of Schlick's Fresnel and
    inv_denom = 1 / (4 (k.h) max(k1.n, k2.n)), 0 where not lit (a direction below the horizon, k.h <= 0).
    Yarn frames: the warp's is the fabric frame; the weft's is it rotated by 90 deg about z (h_weft =
    (|h_y|, |h_x|, h_z)), and k.h, k1.n, k2.n do not change under that rotation, so m5 and inv_denom are the
    same for both yarn types."""
    n = wi.shape[0]
    h = np.empty((n, 3))
    m5 = np.empty(n)
    inv_denom = np.empty(n)
    columns = np.empty((9, n))  # wi, wo and |h| by component: the loop on contiguous columns vectorises
    for i in range(n):
        columns[0, i], columns[1, i], columns[2, i] = wi[i, 0], wi[i, 1], wi[i, 2]
        columns[3, i], columns[4, i], columns[5, i] = wo[i, 0], wo[i, 1], wo[i, 2]
    ix, iy, iz, ox, oy, oz, ax, ay, az = (columns[0], columns[1], columns[2], columns[3], columns[4], columns[5],
                                          columns[6], columns[7], columns[8])
    for i in range(n):  # branch-free (selects)
        sx, sy, sz = ix[i] + ox[i], iy[i] + oy[i], iz[i] + oz[i]
        norm = math.sqrt(sx * sx + sy * sy + sz * sz)
        positive = norm > 0.0
        hx = sx / norm if positive else 0.0
        hy = sy / norm if positive else 0.0
        hz = sz / norm if positive else 0.0
        ax[i], ay[i], az[i] = abs(hx), abs(hy), abs(hz)
        cos_kh = ix[i] * hx + iy[i] * hy + iz[i] * hz
        c = min(max(cos_kh, 0.0), 1.0)
        m = 1.0 - c
        m5[i] = m * m * m * m * m  # Schlick's (1 - k.h)^5
        denom = 4.0 * cos_kh * max(iz[i], oz[i])
        lit = (iz[i] > 0.0) & (oz[i] > 0.0) & (cos_kh > 0.0) & (denom > 0.0)
        inv_denom[i] = 1.0 / denom if lit else 0.0
    for i in range(n):
        h[i, 0], h[i, 1], h[i, 2] = ax[i], ay[i], az[i]
    return h, m5, inv_denom


@njit(cache=True)
def equal_row_groups(keys):
    """Groups of equal rows of int64 ``keys`` (N, 3): (first (M,), inverse (N,)) with first[g] the index of
    group g's first row (groups in order of first appearance) and inverse[n] the group of row n.  One pass
    with an open-addressing hash table (O(N); a sort is O(N log N))."""
    n = keys.shape[0]
    size = 1
    while size < 2 * n:
        size *= 2
    table = np.full(size, -1, dtype=np.int64)  # group of a slot, -1 empty
    first = np.empty(n, dtype=np.int64)
    inverse = np.empty(n, dtype=np.intp)
    groups = 0
    mask = size - 1
    for i in range(n):
        a, b, c = keys[i, 0], keys[i, 1], keys[i, 2]
        slot = ((a * 0x9E3779B1) ^ (b * 0x85EBCA77) ^ (c * 0xC2B2AE3D)) & mask
        while True:
            g = table[slot]
            if g < 0:
                table[slot] = groups
                first[groups] = i
                inverse[i] = groups
                groups += 1
                break
            r = first[g]
            if keys[r, 0] == a and keys[r, 1] == b and keys[r, 2] == c:
                inverse[i] = g
                break
            slot = (slot + 1) & mask
    return first[:groups].copy(), inverse


@njit(cache=True)
def half_vector_groups(h, swaps, scale):
    """Groups of equal half vectors over ``len(swaps)`` blocks of the rows of h (N, 3) - block b is h itself
    (``swaps[b]`` 0: the warp's yarn frame) or h with x and y swapped (1: the weft's, :func:`direction_terms`) -
    as (representatives (M, 3), inverse (B N,)): rows whose components rounded to integers after multiplying
    by ``scale`` agree form a group (numpy's ``rint``, half to even), evaluated at its first row; the groups of
    :func:`equal_row_groups` of those integer keys, without forming the blocks (one pass)."""
    n = h.shape[0]
    blocks = swaps.shape[0]
    keys = np.empty((n * blocks, 3), dtype=np.int64)
    for b in range(blocks):
        ix, iy = (1, 0) if swaps[b] else (0, 1)
        for i in range(n):
            r = b * n + i
            keys[r, 0] = np.int64(np.rint(h[i, ix] * scale))
            keys[r, 1] = np.int64(np.rint(h[i, iy] * scale))
            keys[r, 2] = np.int64(np.rint(h[i, 2] * scale))
    first, inverse = equal_row_groups(keys)
    representatives = np.empty((first.shape[0], 3))
    for g in range(first.shape[0]):
        b, i = first[g] // n, first[g] % n
        ix, iy = (1, 0) if swaps[b] else (0, 1)
        representatives[g, 0], representatives[g, 1], representatives[g, 2] = h[i, ix], h[i, iy], h[i, 2]
    return representatives, inverse
