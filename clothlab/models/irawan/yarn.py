"""The specular integral of one yarn segment type (Irawan & Marschner 2012, eqs. 1, 2, 10, Algorithms 1-2).

:func:`yarn_integral` returns the geometric part  I(wi, wo) = integral G A  of eq. 10; the phase function
f_c (eq. 7) depends on wi.wo only, so it factors out of the integral and is applied by the caller.
Directions are (N, 3) unit vectors in the *yarn* frame (z normal, y along the yarn), both with z > 0.
Angles in radians; w and l in any common length unit (only w / l matters after normalisation).

Staple yarns (psi != 0) integrate G_v A over u in [-umax, umax] (eq. 1), filament yarns G_u A_s over v in
[-pi/2, pi/2] (eq. 2); the integrands, one helper per equation, are in :mod:`clothlab.models.irawan.kernels`.
This module chooses the path (:func:`staple_path`) and the nodes (:mod:`clothlab.models.irawan.quadrature`).
The ``support`` and ``adaptive`` rules split the staple integral where its integrand jumps or kinks (the ends
of eq. 3's support |D| <= 1 and the visibility cut |v| = pi/2 in closed form, the zeros of eq. 8's clamped
cosines c_i, c_r on the specular curve as roots of a quartic), found per direction inside the compiled loop
(:func:`clothlab.models.irawan.kernels.staple_lit_pieces`; parameter-free, so a model keeps them per direction
set) and integrate only the lit pieces (:func:`clothlab.models.irawan.kernels.staple_support_sum`); they
integrate the filament one over the closed-form arc where both clamped cosines of eq. 8 are positive.
"""

from __future__ import annotations

import numpy as np

from clothlab.models.irawan.quadrature import (
    ADAPTIVE_MAX_NODES,
    ADAPTIVE_RTOL,
    compact_breaks,
    cosine_mapped_unit_rule,
    interval_rule,
    unit_rule,
)


def half_vectors(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit half vectors (N, 3) and |wi + wo| (N,); a degenerate pair (wo = -wi) gets length 0."""
    from clothlab.models.irawan import kernels

    return kernels.half_vectors(np.ascontiguousarray(wi, dtype=np.float64), np.ascontiguousarray(wo, dtype=np.float64))


def staple_breaks(wi, wo, psi, umax) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints (N, P+1) of the staple integrand over [-umax, umax] for yarn-frame pairs (N, 3), padded
    with umax, and the number of lit pieces (N,) (:func:`clothlab.models.irawan.kernels.staple_breakpoints`:
    support ends, |v| = pi/2, zeros of c_i and c_r); the ``support`` rule finds the same inside its loop."""
    from clothlab.models.irawan import kernels

    table, lit = kernels.staple_break_table(np.ascontiguousarray(wi, dtype=np.float64),
                                            np.ascontiguousarray(wo, dtype=np.float64), float(psi), float(umax))
    used = int(np.max(np.sum(table < umax, axis=1), initial=1)) + 1
    return table[:, :used], lit


def _filament_breaks(wi, wo, h):
    """Breakpoints (N, <= 4) over [-pi/2, pi/2]: where c_i or c_r of eq. 8 cross zero."""
    from clothlab.models.irawan import kernels

    return compact_breaks(-0.5 * np.pi, 0.5 * np.pi, kernels.filament_break_candidates(
        np.ascontiguousarray(wi), np.ascontiguousarray(wo), np.ascontiguousarray(h)))


def staple_pieces(wi, wo, psi, domain) -> tuple[np.ndarray, np.ndarray]:
    """The lit pieces (lo, hi), each (P, N), of the staple integrand on [-domain, domain] (radians) for
    yarn-frame pairs (N, 3) (:func:`clothlab.models.irawan.kernels.staple_lit_pieces`)."""
    from clothlab.models.irawan import kernels

    return kernels.staple_lit_pieces(np.ascontiguousarray(wi, dtype=np.float64),
                                     np.ascontiguousarray(wo, dtype=np.float64), float(psi), float(domain))


def _integrate(wi, wo, rule, n, staple, psi, umax, kappa, w, l, delta, shortened, pieces=None):
    from clothlab.models.irawan import kernels

    def staple_sum(rows, nodes, weights):
        return kernels.staple_quadrature(wi[rows], wo[rows], nodes, weights, psi, umax, kappa, w, l)

    def filament_sum(rows, nodes, weights, on_arc=False):
        return kernels.filament_quadrature(wi[rows], wo[rows], nodes, weights, umax, kappa, w, l, delta, on_arc,
                                           shortened)

    every = slice(None)
    if rule in ("trapezoid", "gauss"):
        lo, hi = (-umax, umax) if staple else (-0.5 * np.pi, 0.5 * np.pi)
        nodes, weights = interval_rule(rule, n, lo, hi)
        return (staple_sum if staple else filament_sum)(every, nodes[None, :], weights[None, :])
    if rule not in ("support", "adaptive"):
        raise ValueError(f"unknown quadrature rule {rule!r}")
    if staple:
        lo, hi = pieces if pieces is not None else staple_pieces(wi, wo, psi, umax)

        def evaluate(rows, m):  # the lit pieces, clipped to [-umax, umax]
            s, ws = cosine_mapped_unit_rule(m)
            return kernels.staple_support_sum(wi[rows], wo[rows], np.ascontiguousarray(lo[:, rows]),
                                              np.ascontiguousarray(hi[:, rows]), s, ws, psi, umax, kappa, w, l)
    else:
        def evaluate(rows, m):  # Gauss-Legendre on the arc where both cosines of eq. 8 are positive
            t, wt = unit_rule("gauss", m)
            return filament_sum(rows, t[None, :], wt[None, :], on_arc=True)

    value = evaluate(every, n)
    if rule == "support":
        return value
    todo = np.arange(len(wi))
    while n < ADAPTIVE_MAX_NODES and todo.size:
        n *= 2
        new = evaluate(todo, n)
        changed = np.abs(new - value[todo]) > ADAPTIVE_RTOL * np.abs(new)
        value[todo] = new
        todo = todo[changed]
    return value


def staple_path(psi, umax, rule, n, psi_threshold) -> bool:
    """Whether |psi| is large enough for the staple integral (eq. 1) with this rule.

    The staple support in u is |cos(u + gamma)| <= |sin psi| / rho, about 2 |sin psi| / rho wide near
    psi = 0.  The support-aware rules resolve any width, so they switch to the filament integral (eq. 2, its
    psi -> 0 limit) only below ``psi_threshold``.  Fixed-node rules (trapezoid, gauss) cannot: with node spacing
    d = 2 umax / (n - 1) a narrower support falls between nodes or onto one with full weight (measured: the
    trapezoid-11 staple sum just above 0.057 deg was 20x the filament value).  They switch below
    max(psi_threshold, d / 2) instead, trading that artefact for the O(psi) staple-filament difference.
    """
    threshold = psi_threshold
    if rule in ("trapezoid", "gauss"):
        threshold = max(threshold, umax / max(n - 1, 1))
    return abs(psi) >= threshold


def yarn_integral(wi, wo, *, psi, umax, kappa, w, l, delta=0.0, rule="trapezoid", n=11, psi_threshold=1e-3,
                  shortened=False, pieces=None):
    """I(wi, wo) = integral of G A (eq. 10) for one segment type; (N,) for (N, 3) yarn-frame directions.

    Staple path when |psi| >= psi_threshold (radians), filament path otherwise (sec. 6.2); see
    :func:`staple_path`.  ``shortened``: the filament spine's R(u) on the arc (1 - delta) umax (the renderer's
    form, :func:`clothlab.models.irawan.kernels.spine_arc`); staple yarns are not smoothed (eq. 9) and ignore it.
    ``pieces``: :func:`staple_pieces` of these directions and psi, if already known (support / adaptive rules).
    """
    wi = np.ascontiguousarray(wi, dtype=np.float64)
    wo = np.ascontiguousarray(wo, dtype=np.float64)
    out = np.zeros(len(wi))
    front = np.flatnonzero((wi[:, 2] > 0.0) & (wo[:, 2] > 0.0))
    if front.size:
        staple = staple_path(psi, umax, rule, n, psi_threshold)
        if pieces is not None:
            pieces = (pieces[0][:, front], pieces[1][:, front])
        out[front] = _integrate(wi[front], wo[front], rule, n, staple, float(psi), float(umax), float(kappa),
                                float(w), float(l), float(delta), bool(shortened), pieces)
    return out
