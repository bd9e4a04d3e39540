"""Pinhole camera: world-space rays through continuous pixel positions (row 0 = top of the image)."""

from __future__ import annotations

import numpy as np

from clothlab.render.scene import Camera


class PinholeCamera:
    """Rays of a :class:`~clothlab.render.scene.Camera`: origin at the eye, unit directions (mm, world)."""

    def __init__(self, camera: Camera):
        self.camera = camera
        self.width, self.height = camera.resolution
        eye = np.asarray(camera.position, dtype=np.float64)
        forward = np.asarray(camera.look_at, dtype=np.float64) - eye
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, np.asarray(camera.up, dtype=np.float64))
        right /= np.linalg.norm(right)
        self.eye, self.forward, self.right = eye, forward, right
        self.down = np.cross(forward, right)  # image rows grow downwards
        self.half_height = np.tan(0.5 * np.deg2rad(camera.fov_deg))  # image plane at distance 1

    def directions(self, px, py) -> np.ndarray:
        """Unit ray directions (..., 3) through pixel positions px (column), py (row), continuous pixels:
        (0, 0) is the top-left corner of the image, (i + 0.5, j + 0.5) the centre of pixel (row j, col i)."""
        px, py = np.broadcast_arrays(np.asarray(px, dtype=np.float64), np.asarray(py, dtype=np.float64))
        scale = 2.0 * self.half_height / self.height  # image-plane units per pixel
        x = (px - 0.5 * self.width) * scale
        y = (py - 0.5 * self.height) * scale
        d = self.forward + x[..., None] * self.right + y[..., None] * self.down
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def pixel_samples(self, spp: int, rng: np.random.Generator | None):
        """Sample positions (H, W, spp) px, py: the pixel centre for spp = 1; otherwise
        :func:`pixel_jitter` in each pixel (``rng``)."""
        h, w = self.height, self.width
        cols, rows = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        if spp == 1:
            return (cols + 0.5)[..., None], (rows + 0.5)[..., None]
        jitter = pixel_jitter((h, w), spp, rng)
        return cols[..., None] + jitter[0], rows[..., None] + jitter[1]


def pixel_jitter(shape, spp: int, rng: np.random.Generator) -> np.ndarray:
    """(2, *shape, spp) positions in the unit pixel [0, 1)^2 (x, y): stratified jitter (one uniform point in
    each cell of an n x n grid, cell k at column k mod n, row k div n) when spp = n^2, otherwise uniform."""
    jitter = rng.random((2, *shape, spp))
    n = int(round(np.sqrt(spp)))
    if n * n == spp:
        k = np.arange(spp)
        jitter = (np.stack([k % n, k // n]).reshape(2, *(1,) * len(shape), spp) + jitter) / n
    return jitter
