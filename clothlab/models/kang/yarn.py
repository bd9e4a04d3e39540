"""Yarn geometry of the Kang shader: normal perturbation (paper eqs. 3-4), ambient occlusion, per-yarn noise.

Everything is in the *yarn frame* (clothlab.frames.to_yarn_frame): local x across the yarn, local y along
it, z the macro normal.  In that frame eqs. 3 (weft) and 4 (warp) are one formula:

    delta_across = c_y sigma,            sigma = 2 x / w in [-1, 1]  (offset across the yarn, in half widths)
    delta_along  = c_f (2 fract(N_xi (y - s_f x)) - 1)               (fibre ridges, sawtooth in [-c_f, c_f])
    n_p = (delta_across, delta_along, sqrt(1 - delta_across^2 - delta_along^2)),   ao = n_p.z

x, y are the point's offsets across / along the yarn in weave cells (clothlab.weave.lookup), w the yarn
width in cells.  Readings of the printed text: the z component is sqrt(1 - dx^2 - dy^2) (the squares are
lost in the printed "sqrt(1.0 - dx - dy)", which would not give a unit normal); the fibre phase is sheared
by the offset *across* the yarn (s_f the fibre slope), the reading in which s_f slants the fibre ridges.
"""

from __future__ import annotations

import numpy as np


def yarn_offsets(x_across, y_along, width, n_strands, fibre_slope):
    """(sigma, phase): sigma = 2 x / w clipped to [-1, 1]; phase = fract(N_xi (y - s_f x)) in [0, 1)."""
    sigma = np.clip(2.0 * np.asarray(x_across, dtype=np.float64) / width, -1.0, 1.0)
    phase = np.mod(n_strands * (np.asarray(y_along, dtype=np.float64) - fibre_slope * x_across), 1.0)
    return sigma, phase


def perturbation(sigma, phase, fibre_curvature, yarn_curvature):
    """Eqs. 3-4 in the yarn frame: (delta_across, delta_along) = (c_y sigma, c_f (2 phase - 1))."""
    return yarn_curvature * np.asarray(sigma, dtype=np.float64), fibre_curvature * (2.0 * np.asarray(phase) - 1.0)


def perturbed_normal(delta_across, delta_along):
    """Unit normal (..., 3) in the yarn frame with z = sqrt(1 - da^2 - dl^2); its z is the AO term."""
    da, dl = np.broadcast_arrays(np.asarray(delta_across, dtype=np.float64), np.asarray(delta_along))
    z = np.sqrt(np.clip(1.0 - da * da - dl * dl, 0.0, None))
    n = np.stack([da, dl, z], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def ambient_occlusion(normal):
    """Kang's ambient-occlusion term: the z of the perturbed normal (sec. 4.2.2), in [0, 1]."""
    return np.clip(np.asarray(normal)[..., 2], 0.0, 1.0)


def tangent_of(normal):
    """Unit tangent perpendicular to ``normal`` (the yarn-frame x, across the yarn, projected): phi = 0 of eq. 2."""
    n = np.asarray(normal, dtype=np.float64)
    t = np.zeros_like(n)
    t[..., 0] = 1.0
    t = t - n[..., :1] * n
    return t / np.linalg.norm(t, axis=-1, keepdims=True)


_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _splitmix(z):
    z = z + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


def yarn_random(tile_u, tile_v, segment):
    """A uniform number in [0, 1) per (tile column, tile row, segment), from integer hashing only.

    Independent of float width and platform (integer hashing, no floating-point state); negative tile indices are fine.
    """
    shape = np.broadcast(tile_u, tile_v, segment).shape
    key = np.zeros(max(1, int(np.prod(shape))), dtype=np.uint64)  # 1-D: array ops wrap silently
    for part in (tile_u, tile_v, segment):
        bits = np.asarray(part, dtype=np.int64).astype(np.uint64)  # two's complement for negatives
        key = _splitmix(key ^ np.broadcast_to(bits, shape).ravel())
    return ((key >> np.uint64(11)).astype(np.float64) / float(2**53)).reshape(shape)


def yarn_noise(tile_u, tile_v, segment, amplitude):
    """Per-yarn intensity factor 1 + amplitude (2 xi - 1), mean 1 over yarns (Kang's noise, sec. 5.2)."""
    return 1.0 + amplitude * (2.0 * yarn_random(tile_u, tile_v, segment) - 1.0)
