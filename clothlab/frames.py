"""The one internal frame of clothlab and the conversions into it (docs/design.md principle 1).

Fabric frame: z is the surface normal, y the warp direction, x = y x z completes a right-handed frame
(so x points along the weft).  Directions are unit vectors pointing *away* from the surface (towards the
light for ``wi``, towards the sensor for ``wo``).

Spherical angles in clothlab's convention: theta is measured from +z, phi counter-clockwise (seen from
above, +z towards the viewer) from +x, i.e. phi = 0 points along the weft and phi = 90 deg along the warp.
Loaders convert a file's own azimuth convention with :func:`azimuth_to_clothlab` once, at loading.

Yarn frames (Irawan & Marschner 2012, sec. 5.2): a warp yarn is described in the fabric frame itself
(y along the yarn); a weft yarn in the same frame rotated by +90 deg about z, so that its local y is the
fabric x.  :func:`to_yarn_frame` applies that rotation.

>>> import numpy as np
>>> from clothlab.frames import spherical_to_vector, vector_to_spherical
>>> w = spherical_to_vector(45.0, 90.0)  # 45 deg from the normal, towards the warp (+y)
>>> (np.round(w, 6) + 0.0).tolist()
[0.0, 0.707107, 0.707107]
>>> [round(float(a), 6) for a in vector_to_spherical(w)]
[45.0, 90.0]
"""

from __future__ import annotations

import numpy as np

#: Azimuth zero directions a file may declare and their clothlab azimuth (degrees).
AZIMUTH_ZERO = {"weft": 0.0, "x": 0.0, "warp": 90.0, "y": 90.0}
AZIMUTH_SENSE = ("ccw", "cw")


def spherical_to_vector(theta, phi, *, degrees: bool = True) -> np.ndarray:
    """Unit vectors (..., 3) from polar angle ``theta`` and azimuth ``phi`` (clothlab convention).

    >>> (np.round(spherical_to_vector([0.0, 90.0], [0.0, 0.0]), 6) + 0.0).tolist()  # the normal; the weft
    [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]
    """
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    if degrees:
        theta = np.deg2rad(theta)
        phi = np.deg2rad(phi)
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def vector_to_spherical(w, *, degrees: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) of direction vectors (..., 3); phi in [0, 360) deg (or [0, 2 pi)).

    >>> theta, phi = vector_to_spherical([0.0, -1.0, 1.0])  # need not be unit length
    >>> round(float(theta), 6), round(float(phi), 6)
    (45.0, 270.0)
    """
    w = np.asarray(w, dtype=np.float64)
    norm = np.linalg.norm(w, axis=-1)
    theta = np.arccos(np.clip(w[..., 2] / norm, -1.0, 1.0))
    phi = np.mod(np.arctan2(w[..., 1], w[..., 0]), 2.0 * np.pi)
    if degrees:
        return np.rad2deg(theta), np.rad2deg(phi)
    return theta, phi


def _convention(zero: str, sense: str, degrees: bool) -> tuple[float, float]:
    """(full turn, offset of ``zero``) in degrees or radians; ValueError for an unknown convention."""
    if zero not in AZIMUTH_ZERO:
        raise ValueError(f"azimuth zero must be one of {sorted(AZIMUTH_ZERO)}, got {zero!r}")
    if sense not in AZIMUTH_SENSE:
        raise ValueError(f"azimuth sense must be one of {AZIMUTH_SENSE}, got {sense!r}")
    if degrees:
        return 360.0, AZIMUTH_ZERO[zero]
    return 2.0 * np.pi, float(np.deg2rad(AZIMUTH_ZERO[zero]))


def azimuth_to_clothlab(phi, *, zero: str = "weft", sense: str = "ccw", degrees: bool = True):
    """Convert azimuths measured from ``zero`` ('weft'|'x'|'warp'|'y') in ``sense`` ('ccw'|'cw').

    A file's 30 deg clockwise from the warp is clothlab's 60 deg (counter-clockwise from the weft):

    >>> float(azimuth_to_clothlab(30.0, zero="warp", sense="cw"))
    60.0
    """
    full, offset = _convention(zero, sense, degrees)
    phi = np.asarray(phi, dtype=np.float64)
    signed = phi if sense == "ccw" else -phi
    return wrap_azimuth(signed + offset, full)


def azimuth_from_clothlab(phi, *, zero: str = "weft", sense: str = "ccw", degrees: bool = True):
    """Inverse of :func:`azimuth_to_clothlab`.

    >>> float(azimuth_from_clothlab(60.0, zero="warp", sense="cw"))
    30.0
    """
    full, offset = _convention(zero, sense, degrees)
    phi = np.asarray(phi, dtype=np.float64)
    shifted = phi - offset
    return wrap_azimuth(shifted if sense == "ccw" else -shifted, full)


def wrap_azimuth(phi, full: float = 360.0):
    """``phi`` wrapped into [0, full): ``np.mod`` of a tiny negative angle rounds to ``full`` itself (e.g.
    mod(-1e-14, 360) == 360.0), which is mapped to 0.

    >>> wrap_azimuth(np.array([-90.0, 370.0, -1e-14])).tolist()
    [270.0, 10.0, 0.0]
    """
    out = np.mod(phi, full)
    return np.where(out >= full, 0.0, out)


def to_yarn_frame(w: np.ndarray, kind: str) -> np.ndarray:
    """Express fabric-frame directions (..., 3) in the local frame of a ``'warp'`` or ``'weft'`` yarn.

    Weft: local (x', y', z') = (-y, x, z), the fabric frame rotated by +90 deg about z.

    >>> weft = np.array([1.0, 0.0, 0.0])  # the fabric's x axis runs along the weft yarns
    >>> (to_yarn_frame(weft, "weft") + 0.0).tolist()  # ... which is the weft yarn's own y (along the yarn)
    [0.0, 1.0, 0.0]
    """
    if kind == "warp":
        return w
    if kind == "weft":
        return np.stack([-w[..., 1], w[..., 0], w[..., 2]], axis=-1)
    raise ValueError(f"yarn kind must be 'warp' or 'weft', got {kind!r}")


def rotate_about_normal(w, angle, *, degrees: bool = True) -> np.ndarray:
    """Directions (..., 3) rotated counter-clockwise (seen from above, +z towards the viewer) by ``angle``
    about the normal z: (x, y, z) -> (x cos a - y sin a, x sin a + y cos a, z).  An angle of exactly 0
    returns the input values unchanged (a float64 copy).

    >>> (np.round(rotate_about_normal([1.0, 0.0, 0.5], 90.0), 12) + 0.0).tolist()
    [0.0, 1.0, 0.5]
    """
    w = np.array(w, dtype=np.float64)
    a = np.deg2rad(angle) if degrees else float(angle)
    if a == 0.0:
        return w
    c, s = np.cos(a), np.sin(a)
    x, y = w[..., 0].copy(), w[..., 1].copy()
    w[..., 0] = c * x - s * y
    w[..., 1] = s * x + c * y
    return w


def to_weave_frame(w, orientation: float) -> np.ndarray:
    """Fabric-frame directions (..., 3) of a table expressed in the frame of a weave rotated by
    ``orientation`` degrees counter-clockwise about the normal (its warp at azimuth 90 + orientation deg of
    the table): the directions rotated by -orientation (:func:`rotate_about_normal`).

    >>> (np.round(to_weave_frame([0.0, 1.0, 0.0], 90.0), 12) + 0.0).tolist()  # the table's +y, weave turned 90
    [1.0, 0.0, 0.0]
    """
    return rotate_about_normal(w, -float(orientation))
