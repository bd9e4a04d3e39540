"""Reproducible noise for the texture model (Irawan & Marschner 2012, sec. 7.2.1).

Everything here starts from *integers*: callers quantise their float64 coordinates with ``floor`` (or take
integer segment / tile indices) and :func:`hash_uniform` mixes them with 64-bit integer arithmetic
(splitmix64 finaliser, numpy ``uint64``, wrapping).  The integers, and so the uniform numbers, are
bit-identical in float32 and float64 builds and on every platform; a float32 input is converted to
float64 before it is floored, so float32 coordinates and the same values in float64 give the same cells.
(The logarithm of :func:`exponential_noise` and the fade polynomial of :func:`perlin_1d` are float64
arithmetic: identical on IEEE platforms up to the last-bit accuracy of the platform's ``log``.)

- :func:`exponential_noise` - the paper's intensity noise: -ln(xi), exponential with mean 1, capped at
  ``INTENSITY_CAP`` = 10 and rescaled so that the mean stays exactly 1 (see its docstring).
- :func:`perlin_1d` - 1-D gradient (Perlin) noise in [-1, 1], continuous, 0 at integer positions.
"""

from __future__ import annotations

import math

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = (np.uint64(s) for s in (30, 27, 31, 11))

#: Cap of the intensity noise (sec. 7.2.1 leaves it unbounded).  P(E > 10) = e^-10.
INTENSITY_CAP = 10.0
#: Mean of min(E, cap) for E ~ Exp(1): integral_0^cap e^-t dt = 1 - e^-cap; the noise is divided by it.
CAPPED_MEAN = 1.0 - math.exp(-INTENSITY_CAP)
#: Standard deviation of the rescaled capped noise min(E, cap) / CAPPED_MEAN (for statistical tests):
#: E[min(E, c)^2] = 2 - 2 e^-c (1 + c), so the variance is that / CAPPED_MEAN^2 - 1.
CAPPED_STD = math.sqrt((2.0 - math.exp(-INTENSITY_CAP) * (2.0 * INTENSITY_CAP + 2.0)) / CAPPED_MEAN**2 - 1.0)


def _mix(z: np.ndarray) -> np.ndarray:
    """splitmix64 step on a 1-D uint64 array (array arithmetic wraps modulo 2^64 without warnings)."""
    z = z + _GOLDEN
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


def hash_bits(*keys, seed: int = 0) -> np.ndarray:
    """64-bit hashes of integer keys (broadcast together); negative keys are fine (two's complement).

    Keys must be integers (Python ints or integer arrays); floats are refused, so a float coordinate can
    only enter through an explicit ``floor``.
    """
    arrays = [np.asarray(k) for k in keys]
    for a in arrays:
        if a.dtype.kind not in "iub":
            raise TypeError(f"hash keys must be integers (floor coordinates first), got dtype {a.dtype}")
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    size = max(1, math.prod(shape))
    z = _mix(np.full(size, int(seed) & 0xFFFFFFFFFFFFFFFF, dtype=np.uint64))
    for a in arrays:
        bits = np.broadcast_to(a.astype(np.int64).astype(np.uint64), shape).reshape(size)
        z = _mix(z ^ bits)
    return z.reshape(shape)


def hash_uniform(*keys, seed: int = 0) -> np.ndarray:
    """Uniform numbers in the open interval (0, 1) from integer keys: (top 53 bits + 1/2) / 2^53.

    Never 0 and never 1, exactly representable in float64.
    """
    bits = hash_bits(*keys, seed=seed) >> _S11
    return (bits.astype(np.float64) + 0.5) * 2.0**-53


def exponential_noise(*keys, seed: int = 0) -> np.ndarray:
    """The intensity noise of sec. 7.2.1: min(-ln xi, INTENSITY_CAP) / CAPPED_MEAN per integer key.

    xi from :func:`hash_uniform` is never 0, so -ln xi <= ln 2^54 = 37.4 before the cap.  The cap at 10 is
    reached with probability e^-10 = 4.5e-5 and lowers the mean from 1 to 1 - e^-10; dividing by
    CAPPED_MEAN = 1 - e^-10 restores mean exactly 1 (so the noise leaves the average BRDF unchanged, as
    the paper requires).  Values lie in (0, 10 / (1 - e^-10)].  Standard deviation: CAPPED_STD (~1).
    """
    xi = hash_uniform(*keys, seed=seed)
    return np.minimum(-np.log(xi), INTENSITY_CAP) / CAPPED_MEAN


def perlin_1d(t, *keys, seed: int = 0) -> np.ndarray:
    """1-D gradient (Perlin) noise at positions ``t`` (float, lattice units) on the line named by ``keys``.

    Each integer lattice point k gets a gradient g_k uniform in (-1, 1) from hash(keys, k); between
    lattice points n(t) = 2 [g_k f (1 - s(f)) + g_{k+1} (f - 1) s(f)] with f = t - k and the quintic fade
    s(f) = 6f^5 - 15f^4 + 10f^3.  n is continuous (C^2), 0 at every lattice point, |n| <= 1, mean 0.
    ``t`` is converted to float64 before ``floor`` (same result for float32 and float64 inputs).
    """
    t = np.asarray(t, dtype=np.float64)
    k = np.floor(t)
    f = t - k
    k = k.astype(np.int64)
    g0 = 2.0 * hash_uniform(*keys, k, seed=seed) - 1.0
    g1 = 2.0 * hash_uniform(*keys, k + 1, seed=seed) - 1.0
    s = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
    return 2.0 * (g0 * f * (1.0 - s) + g1 * (f - 1.0) * s)
