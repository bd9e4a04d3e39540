"""Report figures of a saved fit, drawn the way Irawan & Marschner (2012) plot their BRDF data.

Sec. 4.1 of the paper: "Each incident hemisphere is plotted in projection onto the tangent plane, with the
warp direction vertical" - one disc per exitant direction, x = sin(theta_i) cos(phi_i) (weft, to the right),
y = sin(theta_i) sin(phi_i) (warp, up).  Sec. 8: fit quality as median / 80th-percentile relative error.

Every function builds a :class:`matplotlib.figure.Figure` directly (no pyplot, no global state) and
returns it, so it shows in Jupyter and can be saved with ``fig.savefig(path, dpi=110)``.  Tables are the
dicts of column arrays read by :func:`clothlab.report.data.read_csv_table`.
"""

from __future__ import annotations

import textwrap

import numpy as np

from clothlab.config.schema import DEFAULT_PERCENTILES
from clothlab.report.data import (
    channel_values,
    channels_of,
    error_percentiles,
    exitant_groups,
    percentile_key,
    signed_relative_error,
)

#: Colours of named channels in line plots; other channel names take the default cycle.
CHANNEL_COLOURS = {"R": "tab:red", "G": "tab:green", "B": "tab:blue", "Y": "0.2", "luminance": "0.2"}
STAGE_COLOURS = {"global": "tab:orange", "local": "tab:blue", "polish": "black"}
BRDF_CMAP = "inferno"
ERROR_CMAP = "RdBu_r"
#: Measured points within this angle (deg) of an exitant direction's incidence plane are shown in slices.
PLANE_TOLERANCE_DEG = 7.5


def _figure(width: float, height: float, *, margins: dict | None = None):
    """A figure of ``width`` x ``height`` inches: constrained layout, or, for the many-panel grids, fixed
    ``margins`` (inches from each edge, plus subplots_adjust's hspace / wspace), which draw in about half the
    time (the constrained solver measures every tick label of every panel)."""
    from matplotlib.figure import Figure

    if margins is None:
        return Figure(figsize=(width, height), layout="constrained")
    fig = Figure(figsize=(width, height))
    m = dict(margins)
    fig.subplots_adjust(left=m.pop("left") / width, right=1 - m.pop("right") / width,
                        bottom=m.pop("bottom") / height, top=1 - m.pop("top") / height, **m)
    return fig


def _channel_colour(channel: str, index: int) -> str:
    return CHANNEL_COLOURS.get(channel, f"C{index % 10}")


def _direction_label(theta_o: float, phi_o: float) -> str:
    return f"\u03b8o={theta_o:g}\u00b0  \u03c6o={phi_o:g}\u00b0"


def tangent_plane_xy(theta, phi) -> tuple[np.ndarray, np.ndarray]:
    """Projection of directions (deg) onto the tangent plane: x = sin t cos p (weft), y = sin t sin p (warp)."""
    t, p = np.deg2rad(np.asarray(theta, dtype=np.float64)), np.deg2rad(np.asarray(phi, dtype=np.float64))
    return np.sin(t) * np.cos(p), np.sin(t) * np.sin(p)


def _merge_duplicate_points(x, y, values):
    """Average values at coincident projected points (e.g. every phi at theta_i = 0)."""
    keys = np.round(np.stack([x, y], axis=1), 9)
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    finite = np.isfinite(values)
    sums = np.bincount(inverse, weights=np.where(finite, values, 0.0), minlength=len(unique))
    counts = np.bincount(inverse, weights=finite.astype(float), minlength=len(unique))
    merged = np.full(len(unique), np.nan)
    np.divide(sums, counts, out=merged, where=counts > 0)
    return unique[:, 0], unique[:, 1], merged


# ---------------------------------------------------------------------------------------------- ticks
def log_ticks(vmin: float, vmax: float, most: int = 6) -> list[float]:
    """Tick values for a log axis from ``vmin`` to ``vmax`` (> 0): decades, else 1-3, 1-2-5 or 1..9 steps
    within decades, whichever first gives at least three ticks; a range too short for any gives three
    log-spaced values rounded to two significant digits.  Never more than ``most``; used with
    :func:`tick_labels` instead of matplotlib's log locators (minor ticks and mathtext: most of a figure's
    drawing time) - and a range under a decade still gets labels."""
    vmin, vmax = float(min(vmin, vmax)), float(max(vmin, vmax))
    lo, hi = int(np.floor(np.log10(vmin))), int(np.ceil(np.log10(vmax)))
    ticks: list[float] = []
    for mantissas in ((1,), (1, 3), (1, 2, 5), tuple(range(1, 10))):
        ticks = [m * 10.0 ** e for e in range(lo, hi + 1) for m in mantissas
                 if vmin * (1 - 1e-9) <= m * 10.0 ** e <= vmax * (1 + 1e-9)]
        if len(ticks) >= 3:
            break
    if len(ticks) > most:
        ticks = ticks[::-(-len(ticks) // most)]
    if len(ticks) < 2:
        ticks = [float(f"{t:.2g}") for t in np.geomspace(vmin, vmax, 3)]
    return ticks


def tick_labels(ticks) -> list[str]:
    """Plain-text labels ('0.01', '2e-05'): no mathtext."""
    return [f"{t:g}" for t in ticks]


def set_log_axis(axis, vmin: float, vmax: float) -> None:
    """A log-scaled x or y ``axis`` (``ax.xaxis`` / ``ax.yaxis``) with :func:`log_ticks`, labelled, no minor
    ticks."""
    from matplotlib.ticker import FixedFormatter, FixedLocator, NullLocator

    ticks = log_ticks(vmin, vmax)
    axis.set_major_locator(FixedLocator(ticks))
    axis.set_major_formatter(FixedFormatter(tick_labels(ticks)))
    axis.set_minor_locator(NullLocator())


def log_colourbar(fig, cax, norm, cmap, label: str, *, orientation: str = "horizontal"):
    """A colour bar of a LogNorm with labelled ticks at any range (:func:`log_ticks`)."""
    from matplotlib.cm import ScalarMappable

    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax, orientation=orientation, label=label)
    set_log_axis(bar.ax.xaxis if orientation == "horizontal" else bar.ax.yaxis, norm.vmin, norm.vmax)
    return bar


def linear_colourbar(fig, cax, norm, cmap, label: str, *, percent: bool = False, orientation: str = "horizontal",
                     ticks: int = 5):
    """A colour bar of a linear norm with ``ticks`` labelled ticks (percent labels when ``percent``)."""
    from matplotlib.cm import ScalarMappable

    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax, orientation=orientation, label=label)
    ticks = np.linspace(norm.vmin, norm.vmax, ticks)
    labels = [f"{100 * t:+.3g} %" if percent and t else ("0" if not t else f"{t:.3g}") for t in ticks]
    (bar.ax.xaxis if orientation == "horizontal" else bar.ax.yaxis).set_ticks(ticks, labels=labels)
    return bar


# ---------------------------------------------------------------------------------------------- discs
DISC_RINGS_DEG = (30.0, 60.0, 90.0)
"""Polar-angle rings drawn (and labelled) on every hemisphere disc."""
DISC_PIXELS = 121
"""Pixels across a disc image (matplotlib resamples it to the output resolution)."""


class DiscCanvas:
    """Many hemisphere discs drawn into ONE axes spanning the figure (data units: inches from the lower left).

    A grid of small axes costs tens of milliseconds per axes (ticks, spines, layout) before anything is drawn;
    here every disc is an image (``imshow``) at its place, the rings of all discs one line collection, the
    markers one line per kind.  Discs are the tangent-plane projection x = sin(theta) cos(phi) (weft, right),
    y = sin(theta) sin(phi) (warp, up) of Irawan & Marschner 2012, sec. 4.1.
    """

    def __init__(self, fig):
        self.fig = fig
        width, height = fig.get_size_inches()
        self.ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
        self.ax.set_xlim(0.0, width)
        self.ax.set_ylim(0.0, height)
        self.ax.set_axis_off()
        self._rings: list[np.ndarray] = []
        self._points: dict[tuple, list] = {}

    def place(self, cx: float, cy: float, r: float, x, y):
        """Figure positions (inches) of tangent-plane points (x, y) on the disc centred at (cx, cy), radius r."""
        return cx + r * np.asarray(x), cy + r * np.asarray(y)

    def image(self, cx, cy, r, values, *, cmap, norm, gid: str | None = None):
        """Draw a (P, P) image of values over the square [-1, 1]^2 of the disc (NaN shows as blank)."""
        im = self.ax.imshow(np.ma.masked_invalid(values), origin="lower", extent=(cx - r, cx + r, cy - r, cy + r),
                            cmap=cmap, norm=norm, interpolation="bilinear", aspect="auto")
        if gid:
            im.set_gid(gid)
        return im

    def frame(self, cx, cy, r, *, labels: bool = True) -> None:
        """The polar-angle rings of :data:`DISC_RINGS_DEG` (solid at 90 deg), labelled in degrees."""
        circle = np.linspace(0.0, 2.0 * np.pi, 121)
        for ring in DISC_RINGS_DEG:
            s = np.sin(np.deg2rad(ring))
            self._rings.append(np.column_stack([cx + r * s * np.cos(circle), cy + r * s * np.sin(circle)]))
            if labels:
                angle = np.deg2rad(-62.0)  # lower right, clear of the warp and weft axes
                self.ax.text(cx + r * s * np.cos(angle), cy + r * s * np.sin(angle), f"{ring:g}\u00b0",
                             fontsize=5.5, color="0.35", ha="left", va="top")

    def mark(self, kind: tuple, x, y) -> None:
        """Queue markers of a style ``kind`` = (marker, size, edge width, colour, face colour)."""
        self._points.setdefault(kind, []).append((np.atleast_1d(x), np.atleast_1d(y)))

    def finish(self) -> None:
        """Draw the queued rings and markers (one artist per style)."""
        from matplotlib.collections import LineCollection

        if self._rings:
            self.ax.add_collection(LineCollection(self._rings, colors="0.55", linewidths=0.6, linestyles=":"))
        for (marker, size, width, colour, face), parts in self._points.items():
            x = np.concatenate([p[0] for p in parts])
            y = np.concatenate([p[1] for p in parts])
            self.ax.plot(x, y, ls="none", marker=marker, ms=size, mew=width, color=colour,
                         mfc=face if face is not None else colour)


def interpolate_disc(x, y, values, pixels: int = DISC_PIXELS) -> np.ndarray:
    """Values at scattered tangent-plane points linearly interpolated (Delaunay triangles) onto a
    ``pixels`` x ``pixels`` image of [-1, 1]^2; NaN outside the points' hull and outside the unit disc.
    Collinear or too few points: each pixel takes the nearest point's value within 0.08 of it."""
    import matplotlib.tri as mtri

    x, y, values = _merge_duplicate_points(np.asarray(x, float), np.asarray(y, float), np.asarray(values, float))
    g = np.linspace(-1.0, 1.0, pixels)
    gx, gy = np.meshgrid(g, g)
    inside = gx ** 2 + gy ** 2 <= 1.0
    finite = np.isfinite(values)
    out = np.full(gx.shape, np.nan)
    try:
        if finite.sum() < 3:
            raise ValueError("fewer than three finite points")
        triangulation = mtri.Triangulation(x[finite], y[finite])
        grid = mtri.LinearTriInterpolator(triangulation, values[finite])(gx, gy)
        out = np.where(np.ma.getmaskarray(grid), np.nan, np.ma.getdata(grid))
    except (ValueError, RuntimeError):  # collinear / too few points: nearest sample, small radius
        if finite.any():
            d = np.hypot(gx[..., None] - x[finite], gy[..., None] - y[finite])
            nearest = np.argmin(d, axis=-1)
            out = np.where(d.min(axis=-1) <= 0.08, values[finite][nearest], np.nan)
    out[~inside] = np.nan
    return out


def _brdf_norm(*arrays):
    """A LogNorm over the positive finite values (at most four decades below the maximum)."""
    from matplotlib.colors import LogNorm

    both = np.concatenate([np.ravel(a) for a in arrays])
    positive = both[np.isfinite(both) & (both > 0)]
    vmax = float(positive.max()) if positive.size else 1.0
    vmin = float(max(positive.min(), vmax * 1e-4)) if positive.size else 1e-3
    vmin = min(vmin, vmax / 1.01)
    return LogNorm(vmin=vmin, vmax=vmax, clip=True)


def _error_norm(error):
    """Symmetric linear limits at the 98th percentile of |error| (at least 1 %)."""
    from matplotlib.colors import Normalize

    finite_error = np.abs(error[np.isfinite(error)])
    limit = float(np.percentile(finite_error, 98)) if finite_error.size else 1.0
    limit = max(limit, 0.01)
    return Normalize(vmin=-limit, vmax=limit, clip=True)


#: Largest PNG height (px at :data:`clothlab.report.build.PNG_DPI` = 110) the disc figures are laid out for.
MAX_FIGURE_INCHES = 26.5


def plot_hemisphere_comparison(predictions: dict, channel: str | None = None):
    """Measured, model and relative-error discs for every exitant direction (paper Figs. 16-21, sec. 4.1).

    predictions : table with theta_i, phi_i, theta_o, phi_o (deg) and measured_<c>, model_<c> (1/sr).
    channel : a channel name or 'luminance' (the channel mean); default the only channel, or the mean of
    several (:func:`clothlab.report.data.shown_channel`).
    One row per exitant direction (sorted by theta_o, phi_o): measured | model on one shared logarithmic
    colour scale, then (model - measured) / measured on a diverging scale with symmetric limits.  Each
    disc is the incident hemisphere projected onto the tangent plane, weft to the right and warp up, with
    rings at theta_i = 30, 60, 90 deg.  Rows shrink so that the figure stays under
    :data:`MAX_FIGURE_INCHES` whatever the number of exitant directions.
    """
    from clothlab.report.data import shown_channel

    channels = channels_of(predictions)
    default_key, default_label = shown_channel(channels)
    channel = channel or default_key
    label = default_label if channel == default_key else ("mean of " + ", ".join(channels)
                                                          if channel == "luminance" else channel)
    measured = channel_values(predictions, "measured", channel, channels)
    model = channel_values(predictions, "model", channel, channels)
    error = signed_relative_error(measured, model)
    groups = exitant_groups(predictions)
    brdf_norm, error_norm = _brdf_norm(measured, model), _error_norm(error)

    top, bottom, row_gap = 0.55, 1.0, 0.2
    row = min(2.0, (MAX_FIGURE_INCHES - top - bottom) / len(groups) - row_gap)  # disc diameter (in)
    width = 8.2
    height = top + bottom + len(groups) * (row + row_gap)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    canvas = DiscCanvas(fig)
    r = row / 2.0
    columns = [0.75 + r + k * (width - 0.9 - 2 * r) / 2.0 for k in range(3)]
    tx_i, ty_i = tangent_plane_xy(predictions["theta_i"], predictions["phi_i"])
    font = 8.5 if row >= 1.5 else 6.5
    # text is the costliest artist to draw (~5 ms each): column headers once, one label per row, the ring
    # angles on the first disc only (the title names them)
    for cx, title in zip(columns, ("measured", "model", "relative error"), strict=True):
        canvas.ax.text(cx, height - top - 0.05, title, ha="center", va="bottom", fontsize=9)
    for index, (theta_o, phi_o, rows) in enumerate(groups):
        cy = height - top - row_gap - index * (row + row_gap) - r
        xo, yo = tangent_plane_xy(theta_o, phi_o)
        panels = (("measured", measured, BRDF_CMAP, brdf_norm), ("model", model, BRDF_CMAP, brdf_norm),
                  ("relative error", error, ERROR_CMAP, error_norm))
        for cx, (title, values, cmap, norm) in zip(columns, panels, strict=True):
            image = interpolate_disc(tx_i[rows], ty_i[rows], values[rows])
            canvas.image(cx, cy, r, image, cmap=cmap, norm=norm, gid=f"disc:{title}:{theta_o:g}:{phi_o:g}")
            canvas.frame(cx, cy, r, labels=index == 0 and cx == columns[0])
            canvas.mark(("o", 1.0, 0, "0.5", None), *canvas.place(cx, cy, r, tx_i[rows], ty_i[rows]))
            canvas.mark(("x", 7, 2.2, "white", None), *canvas.place(cx, cy, r, xo, yo))
            canvas.mark(("x", 6, 1.2, "black", None), *canvas.place(cx, cy, r, xo, yo))
            canvas.mark(("o", 6, 1.0, "0.6", "none"), *canvas.place(cx, cy, r, -xo, -yo))
        canvas.ax.text(columns[0] - r - 0.1, cy, f"{_direction_label(theta_o, phi_o)}\ny = warp \u2191",
                       rotation=90, ha="right", va="center", fontsize=font, multialignment="center")
    canvas.ax.text(columns[0], bottom - 0.05, "x = weft \u2192", ha="center", va="top", fontsize=7.5)
    canvas.finish()
    log_colourbar(fig, fig.add_axes((0.08, 0.42 / height, 0.55, 0.12 / height)), brdf_norm, BRDF_CMAP,
                  f"BRDF (1/sr), {label}, log scale")
    linear_colourbar(fig, fig.add_axes((0.70, 0.42 / height, 0.25, 0.12 / height)), error_norm, ERROR_CMAP,
                     "(model \u2212 measured) / measured", percent=True, ticks=3)
    fig.suptitle("Incident hemispheres projected onto the tangent plane (warp vertical); "
                 "\u00d7 exitant, \u25cb mirror direction; rings: \u03b8i = 30, 60, 90\u00b0", fontsize=9,
                 y=1.0 - 0.12 / height)
    return fig


def incidence_plane_coordinates(theta_i, phi_i, theta_o: float, phi_o: float):
    """Signed in-plane angle and distance from the plane (deg) of incident directions.

    The incidence plane of exitant direction (theta_o, phi_o) holds the normal and the azimuth phi_o; the
    signed angle is positive on the mirror side (azimuth phi_o + 180), as in slices.csv.
    """
    t, p = np.deg2rad(np.asarray(theta_i, dtype=np.float64)), np.deg2rad(np.asarray(phi_i, dtype=np.float64))
    wx, wy, wz = np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)
    po = np.deg2rad(phi_o)
    along = -(wx * np.cos(po) + wy * np.sin(po))  # component towards azimuth phi_o + 180
    across = -wx * np.sin(po) + wy * np.cos(po)
    signed = np.rad2deg(np.arctan2(along, wz))
    distance = np.rad2deg(np.arcsin(np.clip(np.abs(across), 0.0, 1.0)))
    return signed, distance


def _use_log_y(ax, values) -> None:
    """Log y (:func:`set_log_axis`: labelled ticks, no minor ticks) when every finite value is positive."""
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size and (values > 0).all():
        ax.set_yscale("log")
        lo, hi = float(values.min()), float(values.max())
        pad = (hi / lo) ** 0.05 if hi > lo else 1.5
        ax.set_ylim(lo / pad, hi * pad)
        set_log_axis(ax.yaxis, lo / pad, hi * pad)


#: A posterior band narrower than this (median of log10(p95 / p5), decades) is invisible under the line.
VISIBLE_BAND_DECADES = 0.01


def band_width_decades(bands: dict, rows=None) -> float:
    """Median width log10(p95 / p5) (decades) of posterior-predictive bands over their finite positive rows."""
    lo, hi = np.asarray(bands["p5"], dtype=float), np.asarray(bands["p95"], dtype=float)
    if rows is not None:
        lo, hi = lo[rows], hi[rows]
    ok = np.isfinite(lo) & np.isfinite(hi) & (lo > 0) & (hi > 0)
    return float(np.median(np.log10(hi[ok] / lo[ok]))) if ok.any() else 0.0


def plot_incidence_slices(predictions: dict, slices: dict | None, *, tolerance: float = PLANE_TOLERANCE_DEG,
                          bands: dict | None = None):
    """Model curves in each exitant direction's incidence plane with measured points near it (log y).

    slices : table theta_o, phi_o, signed_theta_i (deg, + = mirror side), model_<c> (1/sr), or None.
    Measured points from ``predictions`` within ``tolerance`` deg of the plane are drawn as dots at their
    in-plane angle.  Dotted vertical lines: mirror (+theta_o) and retro-reflection (-theta_o) angles.
    bands : posterior-predictive bands on the same rows as ``slices`` ({"p5": (M, C), "p95": (M, C)}, from
    posterior.json), drawn as shaded 5-95 % ranges.
    """
    channels = channels_of(predictions)
    pred_groups = {(t, p): rows for t, p, rows in exitant_groups(predictions)}
    slice_groups = {(t, p): rows for t, p, rows in exitant_groups(slices)} if slices else {}
    keys = sorted(set(pred_groups) | set(slice_groups))
    ncols = min(4, len(keys))
    nrows = -(-len(keys) // ncols)
    # fixed margins (the constrained solver measured every tick label of every panel, most of the figure's
    # drawing time): per row 0.75 in for the x tick labels, x label and the next row's title; the legend
    # goes in a strip reserved below the last row's x labels, one 0.19 in line per legend row
    n_handles = len(channels) * (2 + (bands is not None and slices is not None))
    legend_cols = min(6, max(n_handles, 1))
    legend_height = 0.19 * -(-n_handles // legend_cols) + 0.12
    width, height = 3.4 * ncols, 2.55 * nrows + 0.5 + legend_height
    panel_height = (height - 0.5 - 0.55 - legend_height - 0.75 * (nrows - 1)) / nrows
    fig = _figure(width, height, margins={"left": 0.75, "right": 0.12, "top": 0.5,
                                          "bottom": 0.55 + legend_height,
                                          "hspace": 0.75 / panel_height, "wspace": 0.06 * ncols / width * 4})
    axes = fig.subplots(nrows, ncols, squeeze=False, sharey=True)
    all_values = []
    band_note = band_title = ""
    if bands is not None:
        decades = band_width_decades(bands)
        if decades < VISIBLE_BAND_DECADES:  # say so rather than list an invisible band
            band_note = " (too thin to see)"
            band_title = (f"; posterior 5-95 % bands \u00b1{100 * (10 ** (decades / 2) - 1):.2g} % about the "
                          "curve: thinner than the line")
    for ax, (theta_o, phi_o) in zip(axes.flat, keys, strict=False):
        for index, c in enumerate(channels):
            colour = _channel_colour(c, index)
            if (theta_o, phi_o) in slice_groups and f"model_{c}" in slices:
                rows = slice_groups[(theta_o, phi_o)]
                order = np.argsort(slices["signed_theta_i"][rows])
                x, y = slices["signed_theta_i"][rows][order], slices[f"model_{c}"][rows][order]
                ax.plot(x, y, "-", color=colour, lw=1.2, label=f"model {c}")
                all_values.append(y)
                if bands is not None:
                    lo = np.asarray(bands["p5"], dtype=float)[rows, index][order]
                    hi = np.asarray(bands["p95"], dtype=float)[rows, index][order]
                    ax.fill_between(x, lo, hi, color=colour, alpha=0.25, lw=0,
                                    label=f"posterior 5-95 % {c}" + band_note)
            if (theta_o, phi_o) in pred_groups:
                rows = pred_groups[(theta_o, phi_o)]
                signed, distance = incidence_plane_coordinates(
                    predictions["theta_i"][rows], predictions["phi_i"][rows], theta_o, phi_o)
                near = distance <= tolerance
                y = predictions[f"measured_{c}"][rows][near]
                ax.plot(signed[near], y, "o", ms=3.5, color=colour, mfc=colour, alpha=0.75,
                        mec="black", mew=0.3, label=f"measured {c}")
                all_values.append(y)
        for angle in (theta_o, -theta_o):
            ax.axvline(angle, color="0.6", ls=":", lw=0.8)
        ax.set_title(_direction_label(theta_o, phi_o), fontsize=9)
        ax.set_xlim(-90, 90)
        ax.set_xlabel("signed \u03b8i (deg), + = mirror side", fontsize=8)
        ax.grid(alpha=0.3, lw=0.5)
    for ax in axes.flat[len(keys):]:
        ax.set_visible(False)
    if all_values:
        _use_log_y(axes.flat[0], np.concatenate(all_values))
    for ax in axes[:, 0]:
        ax.set_ylabel("BRDF (1/sr)")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="lower center", bbox_to_anchor=(0.5, 0.04 / height),
                   ncols=min(6, len(handles)), fontsize=8)
    fig.suptitle(f"Incidence-plane slices: model curves, measured points within {tolerance:g}\u00b0 "
                 f"of the plane{band_title}", fontsize=9, y=1.0 - 0.08 / height)
    return fig


def stage_family(stage: str) -> str:
    """'global' for 'global#2', 'local' for 'local#1', the stage itself otherwise."""
    return str(stage).split("#", 1)[0]


def plot_fit_trace(trace: dict):
    """Objective per evaluation (dots) and best so far (line) against evaluation and wall time (s).

    trace : table evaluation, time_s, value, best, stage ('global#k' | 'local#k' | 'polish' | ...); log y
    when positive.  One colour per stage family (global, local, polish: :data:`STAGE_COLOURS`, distinct), the
    starts of a multi-start run separated by faint vertical lines.
    """
    fig = _figure(10.0, 3.6, margins={"left": 0.85, "right": 0.15, "top": 0.4, "bottom": 0.55, "wspace": 0.04})
    axes = fig.subplots(1, 2, sharey=True)
    stages = np.asarray(trace["stage"], dtype=str)
    order = np.argsort(trace["evaluation"], kind="stable")
    stages = stages[order]
    families = np.array([stage_family(st) for st in stages])
    others = [f"C{k}" for k in range(10) if f"C{k}" not in ("C0", "C1", "C2")]  # C0-C2 = blue, orange, green
    colours = {}
    for family in dict.fromkeys(families):
        colours[family] = STAGE_COLOURS.get(family) or others[len(colours) % len(others)]
    starts = [st for st in dict.fromkeys(stages) if "#" in st]
    n_starts = len({st.split("#", 1)[1] for st in starts})
    for ax, xname, xlabel in ((axes[0], "evaluation", "evaluation"), (axes[1], "time_s", "wall time (s)")):
        x = np.asarray(trace[xname], dtype=np.float64)[order]
        seen = set()
        for stage in dict.fromkeys(stages):
            family = stage_family(stage)
            mask = stages == stage
            colour = colours[family]
            ax.plot(x[mask], trace["value"][order][mask], ".", ms=2.5, color=colour, alpha=0.35)
            label = None if family in seen else f"best so far ({family})"
            seen.add(family)
            ax.plot(x[mask], trace["best"][order][mask], "-", lw=1.6, color=colour, label=label)
            if stage.startswith("global#") and stage != "global#1" and mask.any():
                ax.axvline(x[mask][0], color="0.8", lw=0.6, zorder=0)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3, lw=0.5)
    _use_log_y(axes[0], np.concatenate([trace["value"], trace["best"]]))
    axes[0].set_ylabel("objective")
    axes[0].legend(fontsize=8)
    starts_text = f"; {n_starts} starts, separated by grey lines" if n_starts > 1 else ""
    fig.suptitle(f"Optimiser trace (dots: each evaluation; line: best so far within the stage{starts_text})",
                 fontsize=9)
    return fig


def plot_error_histogram(predictions: dict, percentiles=DEFAULT_PERCENTILES):
    """Distribution of |relative error| (percent) pooled over channels, with the percentile lines (sec. 8)."""
    channels = channels_of(predictions)
    errors = {c: 100.0 * np.abs(signed_relative_error(predictions[f"measured_{c}"], predictions[f"model_{c}"]))
              for c in channels}
    pooled = np.concatenate(list(errors.values()))
    pooled = pooled[np.isfinite(pooled)]
    summary = error_percentiles(predictions, channels, percentiles)["overall"]
    fig = _figure(7.0, 3.8, margins={"left": 0.75, "right": 0.15, "top": 0.35, "bottom": 0.55})
    ax = fig.subplots()
    if pooled.size == 0:
        ax.text(0.5, 0.5, "no finite relative errors", ha="center", va="center", transform=ax.transAxes)
        return fig
    upper = max(float(np.percentile(pooled, 99)) * 1.1, 1e-6)
    bins = np.linspace(0.0, upper, 41)
    ax.hist(np.clip(pooled, 0.0, upper), bins=bins, color="0.8", label=f"all channels (n={pooled.size})")
    for index, (c, err) in enumerate(errors.items()):
        err = err[np.isfinite(err)]
        ax.hist(np.clip(err, 0.0, upper), bins=bins, histtype="step", lw=1.2, color=_channel_colour(c, index),
                label=c)
    styles = ("-", "--", "-.", ":")
    for index, q in enumerate(percentiles):
        value = 100.0 * summary[percentile_key(q)]
        ax.axvline(value, color="black", ls=styles[index % len(styles)], lw=1.0,
                   label=f"{q:g}th percentile = {value:.1f} %")
    over = int((pooled > upper).sum())
    ax.set_xlabel("|model \u2212 measured| / measured (%)" + (f"   ({over} values beyond the last bin)"
                                                                    if over else ""))
    ax.set_ylabel("samples")
    ax.legend(fontsize=8)
    ax.set_title("Relative error distribution", fontsize=9)
    return fig


def _fraction(value, lower, upper):
    if lower is None or upper is None or value is None or not upper > lower:
        return None
    return (float(value) - float(lower)) / (float(upper) - float(lower))


def plot_parameters(fit: dict):
    """Each parameter's position within its fit bounds (0 = lower, 1 = upper): fitted, start and truth.

    Red marks a parameter at a bound or not determined (:func:`clothlab.fit.determined.not_determined`); grey
    rows are fixed parameters.  Labels give the values and units.
    """
    parameters = fit.get("parameters") or {}
    names = list(parameters)
    # fixed margins: the left one fits the longest parameter name (8 pt, about 0.065 in a character)
    height = 0.42 * max(len(names), 1) + 1.3
    fig = _figure(9.0, height, margins={"left": 0.25 + 0.065 * max((len(n) for n in names), default=4),
                                        "right": 0.1, "top": 0.35, "bottom": 0.4})
    ax = fig.subplots()
    if not names:
        ax.text(0.5, 0.5, "no parameters", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return fig
    seen = set()
    from clothlab.fit.determined import not_determined

    try:
        undetermined = not_determined(fit)  # coefficient 0 / no effect / within 2 % of a bound (issue 28 item 6)
    except (AttributeError, TypeError):
        undetermined = {}

    def mark(x, y, label, **style):
        ax.plot([x], [y], label=None if label in seen else label, **style)
        seen.add(label)

    for row, name in enumerate(names):
        y = len(names) - 1 - row
        entry = parameters[name]
        lower, upper = entry.get("lower"), entry.get("upper")
        free = entry.get("free", True)
        at_bound = entry.get("at_bound")
        flagged = bool(at_bound) or name in undetermined
        colour = "tab:red" if flagged else ("tab:blue" if free else "0.55")
        ax.plot([0, 1], [y, y], "-", color="0.85", lw=5, solid_capstyle="butt")
        for key, label, style in (("start", "start", dict(marker="o", mfc="none", color="0.4", ms=6)),
                                  ("truth", "truth", dict(marker="D", mfc="none", color="tab:green", ms=8,
                                                          mew=1.6))):
            x = _fraction(entry.get(key), lower, upper)
            if x is not None:
                mark(x, y, label, ls="none", **style)
        x = _fraction(entry.get("value"), lower, upper)
        if x is not None:
            mark(x, y, "fitted" if free else "fixed", ls="none", marker="o", color=colour, ms=7)
        unit = "" if entry.get("unit") in (None, "1") else entry["unit"]  # "1": dimensionless, no unit to show
        text = f"{entry['value']:.4g} {unit}".strip() if isinstance(entry.get("value"), int | float) \
            else str(entry.get("value"))
        if lower is not None and upper is not None:
            text += f"  [{lower:.4g}, {upper:.4g}]"
        if "truth" in entry and entry["truth"] is not None:
            text += f"  truth {entry['truth']:.4g}"
        if at_bound:
            text += f"  AT {str(at_bound).upper()} BOUND"
        elif name in undetermined:
            text += "  NOT DETERMINED" + ("" if "bound" in undetermined[name] else " (no effect)")
        if not free:
            text += "  (fixed)"
        ax.text(1.04, y, text, va="center", fontsize=8, color=colour if flagged else "black")
    ax.set_yticks(range(len(names)), labels=names[::-1], fontsize=8)
    ax.set_xlim(-0.05, 1.9)
    ax.set_ylim(-0.7, len(names) - 0.3)
    ax.set_xticks([0, 0.5, 1], labels=["lower", "mid", "upper"], fontsize=8)
    for spine in ("top", "right"):
        ax.spines[spine].set_visible(False)
    ax.legend(fontsize=8, loc="upper right", ncols=2)
    ax.set_title("Parameters within their fit bounds", fontsize=9)
    return fig


def plot_error_comparison(rows: list[dict]):
    """Bar chart of median and 80th-percentile relative error (%) per fit, with the paper's published
    figures (Irawan & Marschner 2012, sec. 8; real measurements) where the fabric matches.

    rows : dicts with 'label', 'p50', 'p80' (fractions) and optional 'paper' = (median %, 80th %).
    """
    fig = _figure(max(6.0, 1.1 * len(rows) + 2.0), 4.0)
    ax = fig.subplots()
    x = np.arange(len(rows))
    width = 0.2
    ours50 = [100.0 * r["p50"] if r.get("p50") is not None else np.nan for r in rows]
    ours80 = [100.0 * r["p80"] if r.get("p80") is not None else np.nan for r in rows]
    paper50 = [r["paper"][0] if r.get("paper") else np.nan for r in rows]
    paper80 = [r["paper"][1] if r.get("paper") else np.nan for r in rows]
    ax.bar(x - 1.5 * width, ours50, width, color="tab:blue", label="median (this fit)")
    ax.bar(x - 0.5 * width, ours80, width, color="tab:cyan", label="80th pct. (this fit)")
    if not np.isnan(paper50).all():
        ax.bar(x + 0.5 * width, paper50, width, color="0.55", hatch="//", edgecolor="white",
               label="median (paper, real data)")
        ax.bar(x + 1.5 * width, paper80, width, color="0.75", hatch="//", edgecolor="white",
               label="80th pct. (paper, real data)")
    ax.set_xticks(x, labels=[r["label"] for r in rows], rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("relative error (%)")
    ax.grid(axis="y", alpha=0.3, lw=0.5)
    ax.legend(fontsize=8)
    ax.set_title("Relative error per fit (paper: Irawan & Marschner 2012, sec. 8)", fontsize=9)
    return fig


CORNER_BINS = 24
"""Bins per parameter of the corner plot's histograms."""


def nice_ticks(lo: float, hi: float, count: int = 3) -> np.ndarray:
    """About ``count`` round tick values (steps 1, 2 or 5 x 10^k) strictly inside (lo, hi)."""
    span = hi - lo
    raw = span / (count + 0.5)
    exponent = np.floor(np.log10(raw))
    step = min((m * 10.0 ** exponent for m in (1, 2, 5, 10)), key=lambda s: abs(s - raw))
    values = np.arange(np.ceil(lo / step), np.floor(hi / step) + 1) * step
    values = values[(values > lo) & (values < hi)]
    return values if values.size else np.array([0.5 * (lo + hi)])


def distinct_labels(values) -> list[str]:
    """Labels with the fewest significant digits (2 to 8) that tell every value apart."""
    for digits in range(2, 9):
        labels = [f"{v:.{digits}g}" for v in values]
        if len(set(labels)) == len(labels):
            return labels
    return labels


def _smooth(counts: np.ndarray) -> np.ndarray:
    """A 2-D histogram smoothed by the [1, 2, 1] / 4 kernel along each axis (edges repeated)."""
    padded = np.pad(counts, 1, mode="edge")
    rows = 0.25 * padded[:-2] + 0.5 * padded[1:-1] + 0.25 * padded[2:]
    return 0.25 * rows[:, :-2] + 0.5 * rows[:, 1:-1] + 0.25 * rows[:, 2:]


def _sigma_levels(density: np.ndarray, masses=(0.393, 0.865)) -> list[float]:
    """Density thresholds enclosing ``masses`` of a 2-D histogram (the 1- and 2-sigma regions of a 2-D
    Gaussian hold 39.3 % and 86.5 %), in increasing order."""
    flat = np.sort(density.ravel())[::-1]
    cumulative = np.cumsum(flat) / max(flat.sum(), 1e-300)
    levels = [flat[min(np.searchsorted(cumulative, m), flat.size - 1)] for m in masses]
    return sorted(set(float(v) for v in levels if v > 0))


def plot_corner(samples: dict, truths: dict | None = None, units: dict | None = None):
    """Corner plot of posterior samples: 1-D histograms on the diagonal (titles: median +(84th - median)
    / -(median - 16th), dashed lines at the 16 / 50 / 84 % quantiles), 2-D histograms below it with the
    contours holding 39 % and 87 % of the samples (1 and 2 sigma of a 2-D Gaussian).

    samples : parameter -> (S,) draws in the declared units; units : parameter -> unit (axis labels);
    truths : parameter -> generating value of simulated data (blue lines, explained in the figure), or None.
    Drawn with plain axes and fixed ticks (three per axis, no mathtext).  The panel size shrinks with many
    parameters so the figure stays under :data:`MAX_FIGURE_INCHES`.
    """
    from matplotlib.figure import Figure

    from clothlab.fit.fitreport import unit_text

    names = list(samples)
    n = len(names)
    data = [np.asarray(samples[name], dtype=float) for name in names]
    data = [d[np.isfinite(d)] for d in data]
    truths = truths or {}
    units = units or {}
    panel = min(1.9, (MAX_FIGURE_INCHES - 1.6) / max(n, 1))
    left, bottom, top = 0.85, 0.85, 0.75
    size = left + n * panel + 0.25, bottom + n * panel + top
    fig = Figure(figsize=size)
    ranges = []
    for d in data:
        lo, hi = (np.quantile(d, [0.005, 0.995]) if d.size else (0.0, 1.0))
        if not hi > lo:
            lo, hi = lo - 0.5 * max(abs(lo), 1e-12), hi + 0.5 * max(abs(hi), 1e-12)
        ranges.append((float(lo), float(hi)))

    def labelled(name):
        unit = unit_text(units.get(name))
        return f"{name} ({unit})" if unit else name

    def ticks(k):
        values = nice_ticks(*ranges[k])
        return values, distinct_labels(values)

    any_truth = False
    for i in range(n):
        for j in range(i + 1):
            ax = fig.add_axes(((left + j * panel) / size[0], (bottom + (n - 1 - i) * panel) / size[1],
                               0.94 * panel / size[0], 0.94 * panel / size[1]))
            xs, xl = ticks(j)
            if i == j:
                counts, edges = np.histogram(data[i], bins=CORNER_BINS, range=ranges[i])
                ax.stairs(counts, edges, color="black", lw=1.0)
                lo, mid, hi = np.quantile(data[i], [0.16, 0.5, 0.84]) if data[i].size else (np.nan,) * 3
                for q in (lo, mid, hi):
                    ax.axvline(q, color="black", ls="--", lw=0.8)
                ax.set_title(f"{names[i]} = {mid:.3g}\n+{hi - mid:.3g} / \u2212{mid - lo:.3g}".replace("-", "\u2212"),
                             fontsize=8)
                ax.set_yticks([])
                ax.set_ylim(0, 1.1 * max(counts.max(), 1))
            else:
                ys, yl = ticks(i)
                counts, xe, ye = np.histogram2d(data[j], data[i], bins=CORNER_BINS, range=(ranges[j], ranges[i]))
                ax.imshow(counts.T, origin="lower", extent=(*ranges[j], *ranges[i]), cmap="Greys", aspect="auto",
                          interpolation="nearest")
                counts = _smooth(counts)
                levels = _sigma_levels(counts)
                if len(levels) >= 1 and counts.max() > 0:
                    centres = (0.5 * (xe[1:] + xe[:-1]), 0.5 * (ye[1:] + ye[:-1]))
                    ax.contour(*centres, counts.T, levels=levels, colors="tab:red", linewidths=0.8)
                ax.set_ylim(*ranges[i])
                truth = truths.get(names[i])
                if isinstance(truth, int | float):
                    ax.axhline(truth, color="tab:blue", lw=1.0)
                    any_truth = True
                if j == 0:
                    ax.set_yticks(ys, labels=yl, fontsize=7)
                    ax.set_ylabel(labelled(names[i]), fontsize=8)
                else:
                    ax.set_yticks(ys, labels=[])
            truth = truths.get(names[j])
            if isinstance(truth, int | float):
                ax.axvline(truth, color="tab:blue", lw=1.0)
                any_truth = True
            ax.set_xlim(*ranges[j])
            if i == n - 1:
                ax.set_xticks(xs, labels=xl, fontsize=7, rotation=30)
                ax.set_xlabel(labelled(names[j]), fontsize=8)
            else:
                ax.set_xticks(xs, labels=[])
    explain = ("Posterior samples (emcee). Diagonal: marginal histograms, dashed 16 / 50 / 84 % quantiles. "
               "Below: joint histograms, red contours enclosing 39 % and 87 % of the samples (1 and 2 sigma)")
    if any_truth:
        explain += ". Blue lines: the values that generated the simulated data"
    text = textwrap.fill(explain + ".", width=int(15 * size[0]))  # ~15 characters per inch at 8 pt
    fig.text(0.5, 1.0 - 0.12 / size[1], text, ha="center", va="top", fontsize=8)
    return fig
