"""Report figures for scattered samplings (:mod:`clothlab.report.sampling`): a fixed number of panels whatever
the number of directions.

- :func:`plot_scattered_hemispheres` - for each representative incident direction, the exitant hemisphere
  of the fitted model (tangent-plane projection, warp up, Irawan & Marschner 2012 sec. 4.1) with the measured
  samples of that window overlaid, coloured by their relative error (model - measured) / measured (sec. 8).
- :func:`plot_residuals` - the relative error against theta_i, theta_o, the phase angle g = arccos(wi . wo),
  the half-vector polar angle and the distance to the mirror direction, with binned medians and the p80 tail.
- :func:`plot_parity` - measured against model on log-log axes with the 1:1 line.
- :func:`plot_scattered_slices` - the model in the incidence plane of the panels' incident directions, only
  where measured samples lie near that plane.

Every function returns a :class:`matplotlib.figure.Figure` (no pyplot).
"""

from __future__ import annotations

import textwrap

import numpy as np

from clothlab.report.data import channel_values, channels_of, shown_channel, signed_relative_error
from clothlab.report.plots import (
    BRDF_CMAP,
    ERROR_CMAP,
    PLANE_TOLERANCE_DEG,
    DiscCanvas,
    _brdf_norm,
    _channel_colour,
    _error_norm,
    _figure,
    incidence_plane_coordinates,
    linear_colourbar,
    log_colourbar,
    set_log_axis,
    tangent_plane_xy,
)
from clothlab.report.sampling import WINDOW_DEG, Panel, unit_vectors

MAP_PIXELS = 61
"""Exitant directions across a model map (about 2,900 inside the disc; matplotlib smooths the image)."""
MIN_SLICE_POINTS = 2
"""Fewest measured samples near an incidence plane for its slice to be drawn."""


def _incident_label(theta_i: float, phi_i: float) -> str:
    return f"\u03b8i={theta_i:.3g}\u00b0  \u03c6i={phi_i:.3g}\u00b0"


def exitant_disc_grid(pixels: int = MAP_PIXELS) -> tuple[np.ndarray, np.ndarray]:
    """(mask (P, P) of pixels inside the unit disc, (M, 3) exitant unit vectors of those pixels): pixel
    (row, col) at tangent-plane y = -1 + 2 row / (P - 1), x = -1 + 2 col / (P - 1), z = sqrt(1 - x^2 - y^2)
    (kept above 0.5 deg elevation)."""
    g = np.linspace(-1.0, 1.0, pixels)
    gx, gy = np.meshgrid(g, g)
    inside = gx ** 2 + gy ** 2 <= np.cos(np.deg2rad(0.5)) ** 2
    x, y = gx[inside], gy[inside]
    return inside, np.column_stack([x, y, np.sqrt(np.clip(1.0 - x ** 2 - y ** 2, 0.0, None))])


def model_maps(model, panels: list[Panel], channel: str, pixels: int = MAP_PIXELS) -> list[np.ndarray]:
    """(P, P) images of the fitted model's ``channel`` (or channel mean) over the exitant hemisphere of each
    panel's incident direction (NaN outside the disc); one model call for all panels."""
    inside, wo = exitant_disc_grid(pixels)
    wi = unit_vectors([p.theta_i for p in panels], [p.phi_i for p in panels])
    values = model(np.repeat(wi, len(wo), axis=0), np.tile(wo, (len(panels), 1)))
    column = model.channel(values, channel).reshape(len(panels), len(wo))
    maps = []
    for k in range(len(panels)):
        image = np.full(inside.shape, np.nan)
        image[inside] = column[k]
        maps.append(image)
    return maps


def plot_scattered_hemispheres(predictions: dict, panels: list[Panel], maps: list[np.ndarray] | None = None, *,
                               window: float = WINDOW_DEG):
    """Model maps of the exitant hemisphere for each panel's incident direction with the measured samples
    of its window overlaid (tangent-plane projection of theta_o, phi_o; weft right, warp up), the samples
    coloured by their relative error.  ``maps``: from :func:`model_maps`, or None (points only)."""
    from matplotlib.figure import Figure

    channels = channels_of(predictions)
    key, label = shown_channel(channels)
    measured = channel_values(predictions, "measured", key, channels)
    model = channel_values(predictions, "model", key, channels)
    error = signed_relative_error(measured, model)
    brdf_norm = _brdf_norm(measured, model, *(maps or []))
    error_norm = _error_norm(error)

    ncols = min(3, max(len(panels), 1))
    nrows = -(-len(panels) // ncols) if panels else 1
    disc, gap, top, bottom, left = 2.4, 0.65, 0.6, 1.05, 0.35
    width = left + ncols * (disc + 0.35)
    height = top + nrows * (disc + gap) + bottom
    fig = Figure(figsize=(width, height))
    canvas = DiscCanvas(fig)
    r = disc / 2.0
    tx, ty = tangent_plane_xy(predictions["theta_o"], predictions["phi_o"])
    px, py, pc = [], [], []
    for k, panel in enumerate(panels):
        cx = left + (k % ncols) * (disc + 0.35) + r
        cy = height - top - (k // ncols) * (disc + gap) - r - 0.3
        if maps is not None:
            canvas.image(cx, cy, r, maps[k], cmap=BRDF_CMAP, norm=brdf_norm,
                         gid=f"map:{panel.theta_i:g}:{panel.phi_i:g}")
        canvas.frame(cx, cy, r, labels=k == 0)
        xi, yi = tangent_plane_xy(panel.theta_i, panel.phi_i)
        canvas.mark(("+", 8, 1.5, "tab:cyan", None), *canvas.place(cx, cy, r, xi, yi))
        canvas.mark(("o", 8, 1.2, "tab:cyan", "none"), *canvas.place(cx, cy, r, -xi, -yi))
        x, y = canvas.place(cx, cy, r, tx[panel.rows], ty[panel.rows])
        px.append(x)
        py.append(y)
        pc.append(error[panel.rows])
        canvas.ax.text(cx, cy + r + 0.06, f"{_incident_label(panel.theta_i, panel.phi_i)}\n"
                                          f"{len(panel.rows)} sample(s) within {window:g}\u00b0", ha="center",
                       va="bottom", fontsize=8)
    if px:
        canvas.ax.scatter(np.concatenate(px), np.concatenate(py), c=np.concatenate(pc), cmap=ERROR_CMAP,
                          norm=error_norm, s=26, edgecolors="black", linewidths=0.6, zorder=3)
    canvas.finish()
    log_colourbar(fig, fig.add_axes((0.06, 0.45 / height, 0.5, 0.12 / height)), brdf_norm, BRDF_CMAP,
                  f"model BRDF (1/sr), {label}, log scale" if maps is not None else f"BRDF (1/sr), {label}")
    linear_colourbar(fig, fig.add_axes((0.64, 0.45 / height, 0.3, 0.12 / height)), error_norm, ERROR_CMAP,
                     "samples: (model \u2212 measured) / measured", percent=True, ticks=3)
    what = "fitted model over the exitant hemisphere" if maps is not None else "measured samples (no model map)"
    fig.suptitle(f"{what} for {len(panels)} incident directions (+ incident, \u25cb mirror direction)\n"
                 f"dots: samples within {window:g}\u00b0 of it, by relative error; rings \u03b8o = 30, 60, 90\u00b0",
                 fontsize=8.5, y=1.0 - 0.08 / height)
    return fig


def _binned_median(x, y, bins: int = 12):
    edges = np.linspace(np.nanmin(x), np.nanmax(x), bins + 1)
    index = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
    centres, medians = [], []
    for b in range(bins):
        values = y[(index == b) & np.isfinite(y)]
        if values.size >= 3:
            centres.append(0.5 * (edges[b] + edges[b + 1]))
            medians.append(np.median(values))
    return np.asarray(centres), np.asarray(medians)


def plot_residuals(predictions: dict):
    """Relative error (model - measured) / measured in percent against the geometry a missing term would follow
    (:data:`clothlab.fit.residuals.BINS`: theta_i, theta_o, the phase angle = distance to retro-reflection, the
    half-vector polar angle and the distance to the mirror direction), per channel, with binned medians (black),
    the zero line and the p80 tail (rows whose |error| exceeds its 80th percentile) ringed in black."""
    from clothlab.fit.residuals import LABELS, TAIL, features

    channels = channels_of(predictions)
    geometry = features(*(np.asarray(predictions[k], float) for k in ("theta_i", "phi_i", "theta_o", "phi_o")))
    fig = _figure(16.0, 3.6, margins={"left": 0.8, "right": 0.15, "top": 0.45, "bottom": 0.75, "wspace": 0.05})
    axes = fig.subplots(1, len(geometry), sharey=True)
    errors = {c: 100.0 * signed_relative_error(predictions[f"measured_{c}"], predictions[f"model_{c}"])
              for c in channels}
    pooled = np.concatenate(list(errors.values()))
    finite = np.abs(pooled[np.isfinite(pooled)])
    limit = max(float(np.percentile(finite, 99)) * 1.15, 1.0) if finite.size else 1.0
    cut = float(np.percentile(finite, TAIL)) if finite.size else np.inf
    for ax, (name, x) in zip(axes, geometry.items(), strict=True):
        for index, c in enumerate(channels):
            shown = np.clip(errors[c], -limit, limit)
            ax.plot(x, shown, ".", ms=3, alpha=0.5, color=_channel_colour(c, index), label=c)
            tail = np.abs(errors[c]) > cut
            ax.plot(x[tail], shown[tail], "o", ms=5, mfc="none", mec="black", mew=0.6,
                    label=f"p{TAIL:g} tail" if index == 0 else None)
        centres, medians = _binned_median(np.tile(x, len(channels)), pooled)
        if centres.size:
            ax.plot(centres, medians, "-", color="black", lw=1.4, label="binned median")
        ax.axhline(0.0, color="0.4", lw=0.8)
        ax.set_xlabel("\n".join(textwrap.wrap(f"{LABELS[name]} (deg)", 28)), fontsize=8)
        ax.grid(alpha=0.3, lw=0.5)
    axes[0].set_ylim(-limit, limit)
    axes[0].set_ylabel("(model \u2212 measured) / measured (%)")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Relative error against the geometry (values beyond \u00b1{limit:.3g} % drawn at the edge; "
                 f"ringed: the p{TAIL:g} tail, |error| > {cut:.3g} %)", fontsize=9)
    return fig


def plot_parity(predictions: dict):
    """Measured against model BRDF (1/sr) on log-log axes per channel, the 1:1 line and +-20 % lines."""
    channels = channels_of(predictions)
    fig = _figure(5.2, 5.0, margins={"left": 0.85, "right": 0.2, "top": 0.4, "bottom": 0.65})
    ax = fig.subplots()
    values = []
    for index, c in enumerate(channels):
        m, f = np.asarray(predictions[f"measured_{c}"], float), np.asarray(predictions[f"model_{c}"], float)
        ok = np.isfinite(m) & np.isfinite(f) & (m > 0) & (f > 0)
        ax.plot(m[ok], f[ok], ".", ms=4, alpha=0.6, color=_channel_colour(c, index), label=c)
        values += [m[ok], f[ok]]
    both = np.concatenate(values) if values else np.array([1e-3, 1.0])
    lo, hi = float(both.min()) / 1.2, float(both.max()) * 1.2
    line = np.array([lo, hi])
    ax.plot(line, line, "-", color="black", lw=1.0, label="model = measured")
    for factor, style in ((1.2, "--"), (1 / 1.2, "--")):
        ax.plot(line, factor * line, style, color="0.5", lw=0.8, label="\u00b120 %" if factor > 1 else None)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    set_log_axis(ax.xaxis, lo, hi)
    set_log_axis(ax.yaxis, lo, hi)
    ax.set_xlabel("measured BRDF (1/sr)")
    ax.set_ylabel("model BRDF (1/sr)")
    ax.grid(alpha=0.3, lw=0.5)
    ax.legend(fontsize=8)
    ax.set_title("Measured vs model (log-log)", fontsize=9)
    return fig


def slice_panels(predictions: dict, panels: list[Panel], tolerance: float = PLANE_TOLERANCE_DEG):
    """[(panel, signed theta_o (deg, + = mirror side), rows near the plane)] for the panels whose incidence
    plane has at least :data:`MIN_SLICE_POINTS` of their samples within ``tolerance`` deg."""
    out = []
    for panel in panels:
        signed, distance = incidence_plane_coordinates(predictions["theta_o"][panel.rows],
                                                       predictions["phi_o"][panel.rows], panel.theta_i, panel.phi_i)
        near = distance <= tolerance
        if near.sum() >= MIN_SLICE_POINTS:
            out.append((panel, signed[near], panel.rows[near]))
    return out


def plane_directions(theta_i: float, phi_i: float, step: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(signed theta_o (deg), wi (M, 3), wo (M, 3)) along the incidence plane of (theta_i, phi_i): positive
    angles on the mirror side (azimuth phi_i + 180), as :func:`incidence_plane_coordinates` signs them."""
    signed = np.arange(-89.0, 89.0 + 0.5 * step, step)
    wo = unit_vectors(np.abs(signed), np.where(signed >= 0, phi_i + 180.0, phi_i))
    wi = np.repeat(unit_vectors([theta_i], [phi_i]), len(signed), axis=0)
    return signed, wi, wo


def plot_scattered_slices(predictions: dict, chosen, model=None, *, tolerance: float = PLANE_TOLERANCE_DEG):
    """Model curves in the incidence plane of each chosen panel's incident direction (from
    :func:`slice_panels`) with its samples near the plane, per channel, log y."""
    from clothlab.report.plots import _use_log_y

    channels = channels_of(predictions)
    ncols = min(3, len(chosen))
    nrows = -(-len(chosen) // ncols)
    title = (f"Incidence-plane slices of the shown incident directions: samples of the {WINDOW_DEG:g}\u00b0 "
             f"window within {tolerance:g}\u00b0 of the plane; dotted: mirror angle")
    title = textwrap.fill(title, width=int(14 * 3.6 * ncols))  # ~14 characters per inch at 9 pt: never clipped
    fig = _figure(3.6 * ncols, 2.7 * nrows + 0.9 + 0.15 * title.count("\n"),
                  margins={"left": 0.8, "right": 0.15, "top": 0.7 + 0.15 * title.count("\n"), "bottom": 0.9,
                           "hspace": 0.55, "wspace": 0.08})
    axes = fig.subplots(nrows, ncols, squeeze=False, sharey=True)
    values = []
    for ax, (panel, signed, rows) in zip(axes.flat, chosen, strict=False):
        if model is not None:
            x, wi, wo = plane_directions(panel.theta_i, panel.phi_i)
            curve = model(wi, wo)
        for index, c in enumerate(channels):
            colour = _channel_colour(c, index)
            if model is not None:
                y = curve[:, model.channels.index(c)] if c in model.channels else curve.mean(axis=1)
                ax.plot(x, y, "-", color=colour, lw=1.2, label=f"model {c}")
                values.append(y[y > 0])
            m = np.asarray(predictions[f"measured_{c}"], float)[rows]
            ax.plot(signed, m, "o", ms=4, color=colour, mec="black", mew=0.4, label=f"measured {c}")
            values.append(m)
        ax.axvline(panel.theta_i, color="0.6", ls=":", lw=0.8)
        ax.set_title(f"{_incident_label(panel.theta_i, panel.phi_i)} ({len(rows)} near the plane)", fontsize=8.5)
        ax.set_xlim(-90, 90)
        ax.set_xlabel("signed \u03b8o (deg), + = mirror side", fontsize=8)
        ax.grid(alpha=0.3, lw=0.5)
    for ax in axes.flat[len(chosen):]:
        ax.set_visible(False)
    if values:
        _use_log_y(axes.flat[0], np.concatenate(values))
    for ax in axes[:, 0]:
        ax.set_ylabel("BRDF (1/sr)")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="lower center", ncols=min(6, len(handles)), fontsize=8)
    fig.suptitle(title, fontsize=9)
    return fig
