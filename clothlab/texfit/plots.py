"""Measured vs model unit tiles in the paper's Fig. 4 arrangement (Irawan & Marschner 2012, sec. 4.2).

Fig. 4 shows the averaged tiles "arranged in four half-circles, each represents the elevation angle of the
illumination direction (30, 45, 60 and 75 deg)".  Here the measured tiles (left panel) and the model tiles
(right panel) are each laid out that way: one half circle per illumination elevation, the lowest elevation
outermost, each tile at the polar angle of the light's azimuth (0 deg right, 90 deg up, 180 deg left).
Only the images of one view direction are shown (``view``; default the most frequent view).  Tiles are
linear values divided by the 99th percentile of the measured tiles shown, clipped to [0, 1] and
sRGB-encoded (the same scale for both panels).  Returns a matplotlib Figure (no pyplot).
"""

from __future__ import annotations

import numpy as np


def _views(angles: np.ndarray) -> tuple[np.ndarray, list]:
    keys = [tuple(np.round(row[2:4], 3)) for row in angles]
    unique = sorted(set(keys), key=lambda k: -keys.count(k))
    return np.array([unique.index(k) for k in keys]), unique


def fig4_positions(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) in [-1, 1] x [0, 1] of each tile: radius by elevation ring (lowest elevation outermost),
    direction = light azimuth.  Rings are the distinct theta_i values (0.1 deg)."""
    theta = np.round(angles[:, 0], 1)
    rings = np.unique(theta)  # ascending theta = descending elevation: innermost first
    radius = (np.searchsorted(rings, theta) + 1) / len(rings) * 0.82
    phi = np.deg2rad(angles[:, 1])
    return radius * np.cos(phi), 0.08 + radius * np.sin(phi)


def _display(tile: np.ndarray, scale: float) -> np.ndarray:
    from clothlab.btf.images import linear_to_srgb

    tile = np.asarray(tile, dtype=np.float64)
    if tile.shape[-1] != 3:
        tile = np.repeat(tile.mean(axis=-1, keepdims=True), 3, axis=-1)
    return linear_to_srgb(np.clip(tile / scale, 0.0, 1.0))


def tile_comparison_figure(result, *, view: int = 0, repeat: int = 2, title: str | None = None):
    """Figure of measured (left) and model (right) unit tiles of a :class:`~clothlab.texfit.fit.TextureFit`
    in the Fig. 4 half-circle arrangement; each tile shown ``repeat`` x ``repeat`` times."""
    from matplotlib.figure import Figure

    angles = np.asarray(result.angles)
    view_of, views = _views(angles)
    if not 0 <= view < len(views):
        raise ValueError(f"view {view} out of range: the stack has {len(views)} view direction(s)")
    pick = np.flatnonzero(view_of == view)
    measured, model = result.measured_tiles[pick], result.model_tiles[pick]
    scale = float(np.percentile(measured, 99)) or 1.0
    x, y = fig4_positions(angles[pick])
    figure = Figure(figsize=(12.0, 4.2))
    tile_size = 0.32 / max(2, int(np.ceil(np.sqrt(len(pick)))))
    panels = (("measured (tile averages)", measured, 0.0), ("model (fitted, noise-free)", model, 0.5))
    for label, tiles, x0 in panels:
        figure.text(x0 + 0.25, 0.95, label, ha="center", va="top", fontsize=11)
        for k in range(len(pick)):
            cx, cy = x0 + 0.25 + 0.22 * x[k], 0.05 + 0.8 * y[k]
            height = tile_size * 12.0 / 4.2  # square axes on the 12 x 4.2 in figure
            ax = figure.add_axes([cx - tile_size / 2, cy - height / 2, tile_size, height])
            ax.imshow(np.tile(_display(tiles[k], scale), (repeat, repeat, 1)), interpolation="nearest")
            ax.set_axis_off()
        rings = np.unique(np.round(angles[pick, 0], 1))
        for k, theta in enumerate(rings):  # elevation labels under the right end of each half circle
            figure.text(x0 + 0.25 + 0.22 * (k + 1) / len(rings) * 0.82, 0.005, f"{90 - theta:g}\N{DEGREE SIGN}",
                        ha="center", fontsize=8)
    view_text = f"view theta_o = {views[view][0]:g}, phi_o = {views[view][1]:g} deg"
    figure.suptitle(title or f"Unit tiles by illumination elevation (half circles, Fig. 4); {view_text}",
                    fontsize=10, y=0.995)
    return figure


def error_table(result) -> dict:
    """The per-image error percentiles of a fit (JSON-ready): relative errors of tile averages and pixels."""
    return result.errors
