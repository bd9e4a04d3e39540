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
    """(x, y) of each tile in ring units: radius = ring number by illumination elevation (the highest
    elevation innermost, at radius 1; a light at the pole, theta_i = 0, at the centre), direction = the
    light's azimuth (0 deg right, 90 deg up).  Rings are the distinct theta_i values (0.1 deg)."""
    theta = np.round(angles[:, 0], 1)
    rings = np.unique(theta)  # ascending theta = descending elevation: innermost first
    index = np.searchsorted(rings, theta)
    radius = index + (0 if rings[0] == 0.0 else 1)
    phi = np.deg2rad(angles[:, 1])
    return radius * np.cos(phi), radius * np.sin(phi)


def tile_width(x: np.ndarray, y: np.ndarray, aspect: float, fill: float = 0.9) -> float:
    """Width (ring units) of axis-aligned tiles of height ``aspect`` x width centred at (x, y) so that no two
    overlap: w = fill x min over pairs of max(|dx|, |dy| / aspect), at most ``fill`` x one ring step (tiles
    at one place, e.g. azimuths 0 and 360 deg, are left to overlap)."""
    w = 1.0
    if len(x) > 1:
        dx = np.abs(x[:, None] - x[None, :])
        dy = np.abs(y[:, None] - y[None, :]) / aspect
        separation = np.maximum(dx, dy)
        separation[separation < 1e-6] = np.inf  # itself, and coincident directions (phi 0 and 360)
        w = min(w, float(separation.min()))
    return fill * min(w, 1.0 / max(aspect, 1.0))


def _display(tile: np.ndarray, scale: float) -> np.ndarray:
    from clothlab.btf.images import linear_to_srgb

    tile = np.asarray(tile, dtype=np.float64)
    if tile.shape[-1] != 3:
        tile = np.repeat(tile.mean(axis=-1, keepdims=True), 3, axis=-1)
    return linear_to_srgb(np.clip(tile / scale, 0.0, 1.0))


def tile_comparison_figure(result, *, view: int = 0, repeat: int = 2, title: str | None = None):
    """Figure of measured (left) and model (right) unit tiles of a :class:`~clothlab.texfit.fit.TextureFit`
    in the Fig. 4 half-circle arrangement; each tile shown ``repeat`` x ``repeat`` times.

    Layout: one axes per panel with equal aspect, the tiles drawn at their ring positions
    (:func:`fig4_positions`) with the largest size at which no two tiles overlap (:func:`tile_width`, the
    tile's own aspect kept), the rings as faint arcs, and each ring's elevation written under the baseline
    below its right end (lights with azimuths beyond 180 deg: full circles, the elevations in the title)."""
    from matplotlib.figure import Figure

    angles = np.asarray(result.angles)
    view_of, views = _views(angles)
    if not 0 <= view < len(views):
        raise ValueError(f"view {view} out of range: the stack has {len(views)} view direction(s)")
    pick = np.flatnonzero(view_of == view)
    measured, model = result.measured_tiles[pick], result.model_tiles[pick]
    scale = float(np.percentile(measured, 99)) or 1.0
    x, y = fig4_positions(angles[pick])
    aspect = measured.shape[1] / measured.shape[2]  # tile rows / columns, shown repeat x repeat
    w = tile_width(x, y, aspect)
    h = aspect * w
    theta = np.round(angles[pick, 0], 1)
    rings = np.unique(theta)
    radii = np.arange(len(rings)) + (0 if rings[0] == 0.0 else 1)
    half = bool(np.all(y >= -1e-9))
    outer = float(radii.max()) if len(radii) else 1.0
    label_gap = 0.28
    bottom = -h / 2 - label_gap if half else -outer - h / 2
    top, side = outer + h / 2, outer + w / 2
    panel_aspect = (top - bottom) / (2 * side)
    figure = Figure(figsize=(12.0, max(2.5, 6.0 * panel_aspect + 0.9)))
    elevations = ", ".join(f"{90 - t:g}" for t in rings)
    panels = (("measured (tile averages)", measured), ("model (fitted, noise-free)", model))
    for k, (label, tiles) in enumerate(panels):
        ax = figure.add_axes([0.015 + 0.5 * k, 0.02, 0.46, 0.84])
        arc = np.linspace(0.0, np.pi if half else 2 * np.pi, 181)
        for radius in radii[radii > 0]:
            ax.plot(radius * np.cos(arc), radius * np.sin(arc), color="0.85", lw=0.8, zorder=0)
        for i in range(len(pick)):
            ax.imshow(np.tile(_display(tiles[i], scale), (repeat, repeat, 1)), interpolation="nearest",
                      extent=(x[i] - w / 2, x[i] + w / 2, y[i] - h / 2, y[i] + h / 2), zorder=1)
        if half:
            for radius, t in zip(radii, rings, strict=True):
                ax.text(radius, -h / 2 - 0.06, f"{90 - t:g}\N{DEGREE SIGN}", ha="center", va="top", fontsize=8)
            ax.text(-side, -h / 2 - 0.06, "elevation", ha="left", va="top", fontsize=7, color="0.4")
        ax.set_xlim(-side, side)
        ax.set_ylim(bottom, top)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(label if half else f"{label}; rings inside out: elevation {elevations} deg", fontsize=11)
    view_text = f"view theta_o = {views[view][0]:g}, phi_o = {views[view][1]:g} deg"
    figure.suptitle(title or f"Unit tiles by illumination elevation ({'half ' if half else ''}circles, Fig. 4); "
                    f"{view_text}",
                    fontsize=10, y=0.995)
    return figure
