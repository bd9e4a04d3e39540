"""Synthetic RGL-EPFL .bsdf files for the tests (written with clothlab's own tensor-file writer; no downloads).

Random positive tables of the layout a measured file holds (docs/formats.md, "RGL-EPFL .bsdf"):
theta_i (P1,), phi_i (P0,), ndf and sigma (2-D), vndf and luminance (P0, P1, ny, nx), rgb (P0, P1, 3, n, n)
or spectra with wavelengths, jacobian [1], description.
"""

from __future__ import annotations

import math

import numpy as np

from clothlab.io.rglbsdf import write_tensor_file

PHI_FULL = tuple(np.linspace(-math.pi, math.pi, 5))
PHI_HALF = tuple(np.linspace(-math.pi, 0.0, 4))
PHI_QUARTER = tuple(np.linspace(-math.pi, -math.pi / 2, 3))


def _mirror_symmetric(a):
    """Symmetric under u_y -> 1 - u_y (relative azimuth -> its negative), as an isotropic material is."""
    return 0.5 * (a + a[..., ::-1, :])


def synthetic_fields(*, phi=PHI_FULL, seed=3, jacobian=1, n=8, spectral=False, isotropic=False):
    """The fields of a random measured file, periodic in azimuth and uniform in it at the pole (u_x = 0) as a
    measured one is; ``isotropic``: one phi_i node, ndf / sigma independent of phi, tables mirror-symmetric in
    the relative azimuth and independent of it at normal incidence (a physically isotropic material)."""
    rng = np.random.default_rng(seed)
    if isotropic:
        phi = (0.0,)
    theta = np.linspace(0.0, 1.45, 6)
    p0, p1 = len(phi), len(theta)
    ndf, sigma = rng.uniform(0.2, 3.0, (9, 7)), rng.uniform(0.5, 1.5, (5, 6))
    vndf = rng.uniform(0.1, 2.0, (p0, p1, 10, 9))
    n_c = 4 if spectral else 3
    values = rng.uniform(0.0, 1.0, (p0, p1, n_c, n, n))
    luminance = rng.uniform(0.1, 2.0, (p0, p1, n, n))
    if isotropic:
        ndf, sigma = np.repeat(ndf[:1], 9, 0), np.repeat(sigma[:1], 5, 0)
        vndf, values = _mirror_symmetric(vndf), _mirror_symmetric(values)
        for a in (vndf, values):  # at normal incidence nothing depends on the azimuth
            a[:, 0] = a[:, 0].mean(axis=-2, keepdims=True)
    for a in (ndf, sigma, vndf, luminance, values):  # periodic in azimuth: u_y = 0 and 1 are one direction
        a[..., -1, :] = a[..., 0, :]
        a[..., 0] = a[..., 0].mean(axis=-1, keepdims=True)  # at the pole u_x = 0 the azimuth means nothing
    if np.isclose(phi[-1] - phi[0], 2 * math.pi):  # and phi_i = -pi, pi one incident azimuth
        for a in (vndf, luminance, values):
            a[-1] = a[0]
    f32 = np.float32
    fields = {"description": np.frombuffer(b"synthetic woven sample", dtype=np.uint8).copy(),
              "jacobian": np.array([jacobian], dtype=np.uint8), "theta_i": theta.astype(f32),
              "phi_i": np.asarray(phi, dtype=f32), "ndf": ndf.astype(f32), "sigma": sigma.astype(f32),
              "vndf": vndf.astype(f32), "luminance": luminance.astype(f32)}
    if spectral:
        fields["wavelengths"] = np.array([450.0, 550.0, 600.0, 650.0], dtype=f32)
        fields["spectra"] = values.astype(f32)
    else:
        fields["rgb"] = values.astype(f32)
    return fields


def write_synthetic(path, **options):
    return write_tensor_file(synthetic_fields(**options), path, overwrite=True)
