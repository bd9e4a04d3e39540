"""A virtual gonioreflectometer: a model + the paper's sampling + a seeded noise model -> a Measurement.

Sampling (Irawan & Marschner 2012, sec. 4.1): 225 incident directions on a grid covering the hemisphere out
to 75 deg, for each of 7 exitant directions coarsely covering the hemisphere out to 60 deg (with the 180 deg
rotational symmetry the paper assumes, exitant azimuths lie in [0, 180) deg).  The paper does not list
its grid; clothlab uses a 15 x 15 square grid mapped to the projected disc of radius sin(75 deg) by the
equal-area concentric map (Shirley & Chiu 1997), and the exitant set theta_o/phi_o = 0/0, 30/0, 30/90,
45/45, 45/135, 60/0, 60/90 deg.

Noise: value = f exp(s_m e1 - s_m^2 / 2) + s_a e2 with e1, e2 ~ N(0, 1) from numpy's PCG64 seeded by
``seed`` (multiplicative log-normal with mean 1, plus additive Gaussian), then floored at ``floor`` (a
BRDF table may not hold negative values; the count of floored values is kept in the provenance).
sigma = sqrt((s_m f)^2 + s_a^2) is written as the per-value uncertainty.

Nominal angles: an instrument records the angles it was set to, not the round-off of the arithmetic that
chose them.  :func:`nominal_angles` rounds every angle to :data:`ANGLE_DECIMALS` decimals of a degree (1e-6
deg, far below any goniometer's resolution and far above float64 round-off), so the paper grid's rim reads
75 and not 75.00000000000001, and a table regenerated on another CPU (numpy's SIMD paths differ in the last
bits) records the same angles.  The model is evaluated at the recorded angles.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from clothlab.frames import vector_to_spherical
from clothlab.io.measurement import Measurement
from clothlab.models.components import combine

EXITANT_DIRECTIONS = ((0.0, 0.0), (30.0, 0.0), (30.0, 90.0), (45.0, 45.0), (45.0, 135.0), (60.0, 0.0), (60.0, 90.0))


def concentric_disk(a, b):
    """Shirley-Chiu equal-area map of the square [-1, 1]^2 to the unit disc; returns (x, y)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    horizontal = np.abs(a) > np.abs(b)
    r = np.where(horizontal, a, b)
    safe_a = np.where(a == 0.0, 1.0, a)
    safe_b = np.where(b == 0.0, 1.0, b)
    phi = np.where(horizontal, 0.25 * np.pi * b / safe_a, 0.5 * np.pi - 0.25 * np.pi * a / safe_b)
    phi = np.where((a == 0.0) & (b == 0.0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def incident_grid(n: int = 15, max_theta: float = 75.0) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) in degrees of an n x n incident grid covering the hemisphere out to ``max_theta``."""
    g = np.linspace(-1.0, 1.0, n)
    a, b = np.meshgrid(g, g, indexing="xy")
    x, y = concentric_disk(a.ravel(), b.ravel())
    radius = np.sin(np.deg2rad(max_theta))
    x, y = radius * x, radius * y
    z = np.sqrt(np.maximum(1.0 - x * x - y * y, 0.0))
    theta, phi = vector_to_spherical(np.stack([x, y, z], axis=1))
    return theta, phi


def paper_sampling(n: int = 15, max_theta: float = 75.0, exitant=EXITANT_DIRECTIONS):
    """(theta_i, phi_i, theta_o, phi_o) in degrees: every incident grid direction for each exitant one."""
    ti, pi_ = incident_grid(n, max_theta)
    exitant = np.asarray(exitant, dtype=np.float64)
    k = len(exitant)
    return nominal_angles(np.tile(ti, k), np.tile(pi_, k), np.repeat(exitant[:, 0], len(ti)),
                          np.repeat(exitant[:, 1], len(ti)))


ANGLE_DECIMALS = 6
"""Decimals of a degree the virtual gonioreflectometer records (module docstring: nominal angles)."""
MAX_NOMINAL_THETA = 90.0 - 10.0**-ANGLE_DECIMALS
"""Largest recorded elevation: a direction just above the horizon stays above it after rounding."""


def nominal_angles(theta_i, phi_i, theta_o, phi_o):
    """The angles (deg) as the instrument records them: rounded to :data:`ANGLE_DECIMALS` decimals, elevations
    kept in [0, :data:`MAX_NOMINAL_THETA`], azimuths in [0, 360)."""
    def elevation(t):
        return np.clip(np.round(np.asarray(t, dtype=np.float64), ANGLE_DECIMALS), 0.0, MAX_NOMINAL_THETA)

    def azimuth(p):
        return np.mod(np.round(np.asarray(p, dtype=np.float64), ANGLE_DECIMALS), 360.0)

    return elevation(theta_i), azimuth(phi_i), elevation(theta_o), azimuth(phi_o)


MIN_SIGMA = 1e-12
"""Smallest sigma (1/sr) a noisy simulation records: a value that carries noise has a positive uncertainty."""


@dataclass(frozen=True)
class NoiseModel:
    """Multiplicative log-normal (``multiplicative``, relative sigma) plus additive Gaussian (1/sr)."""

    multiplicative: float = 0.0
    additive: float = 0.0
    seed: int = 0
    floor: float = 1e-6

    def apply(self, clean: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Noisy values, their sigma and the number of values raised to the floor."""
        rng = np.random.default_rng(self.seed)
        e1 = rng.standard_normal(clean.shape)
        e2 = rng.standard_normal(clean.shape)
        s_m = self.multiplicative
        noisy = clean * np.exp(s_m * e1 - 0.5 * s_m * s_m) + self.additive * e2
        floored = int(np.count_nonzero(noisy < self.floor))
        noisy = np.maximum(noisy, self.floor)
        sigma = np.sqrt((s_m * clean) ** 2 + self.additive**2)
        # a tiny sigma squares to 0 (underflow): at least MIN_SIGMA, as a valid table's sigma is > 0
        sigma = np.where(sigma < MIN_SIGMA, MIN_SIGMA, sigma)
        return noisy, sigma, floored


def simulate(model, params: dict, coefficients: dict, *, channels=("R", "G", "B"), noise: NoiseModel | None = None,
             sampling=None, provenance: dict | None = None) -> Measurement:
    """Measure ``model`` with ``params`` and per-channel ``coefficients`` on ``sampling`` (default: the paper's).

    Returns a Measurement whose provenance says plainly that it is simulated and records the generator.
    """
    from clothlab.frames import spherical_to_vector

    ti, pi_, to, po = nominal_angles(*(sampling if sampling is not None else paper_sampling()))
    wi, wo = spherical_to_vector(ti, pi_), spherical_to_vector(to, po)
    clean = combine(model.components(wi, wo, params), {k: np.asarray(v, dtype=np.float64)
                                                       for k, v in coefficients.items()})
    noise = noise or NoiseModel()
    if noise.multiplicative > 0.0 or noise.additive > 0.0:
        values, sigma, floored = noise.apply(clean)
    else:
        values, sigma, floored = clean, None, 0
    info = {
        "simulated": True,
        "generator": "clothlab simulate (virtual gonioreflectometer)",
        "model": model.kind,
        "parameters": {k: float(v) for k, v in model.resolve(params).items()},
        "coefficients": {k: [float(x) for x in np.atleast_1d(v)] for k, v in coefficients.items()},
        "noise": asdict(noise),
        "floored_values": floored,
    }
    info.update(provenance or {})
    return Measurement(ti, pi_, to, po, values, tuple(channels), sigma, info)
