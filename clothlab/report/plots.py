"""Report figures of a saved fit, drawn the way Irawan & Marschner (2012) plot their BRDF data.

Sec. 4.1 of the paper: "Each incident hemisphere is plotted in projection onto the tangent plane, with the
warp direction vertical" - one disc per exitant direction, x = sin(theta_i) cos(phi_i) (weft, to the right),
y = sin(theta_i) sin(phi_i) (warp, up).  Sec. 8: fit quality as median / 80th-percentile relative error.

Every function builds a :class:`matplotlib.figure.Figure` directly (no pyplot, no global state) and
returns it, so it shows in Jupyter and can be saved with ``fig.savefig(path, dpi=110)``.  Tables are the
dicts of column arrays read by :func:`clothlab.report.data.read_csv_table`.
"""

from __future__ import annotations

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
STAGE_COLOURS = {"global": "tab:orange", "local": "tab:blue", "polish": "tab:green"}
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


def _disc_axes(ax, theta_o: float, phi_o: float) -> None:
    """Unit circle (theta_i = 90 deg), rings at 30 and 60 deg, exitant (x) and mirror (o) markers."""
    circle = np.linspace(0.0, 2.0 * np.pi, 181)
    for ring, style in ((1.0, "-"), (np.sin(np.deg2rad(60.0)), ":"), (0.5, ":")):
        ax.plot(ring * np.cos(circle), ring * np.sin(circle), style, color="0.55", lw=0.6)
    xo, yo = tangent_plane_xy(theta_o, phi_o)
    ax.plot([xo], [yo], marker="x", ms=7, mew=2.2, color="white")
    ax.plot([xo], [yo], marker="x", ms=6, mew=1.2, color="black")
    ax.plot([-xo], [-yo], marker="o", ms=6, mfc="none", mew=1.0, color="0.6")
    ax.set_xlim(-1.05, 1.05)
    ax.set_ylim(-1.05, 1.05)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_visible(False)


def _draw_disc(ax, x, y, values, *, cmap, norm) -> None:
    """Interpolate ``values`` over the disc (Delaunay + Gouraud); scatter if the triangulation fails."""
    import matplotlib.tri as mtri

    x, y, values = _merge_duplicate_points(x, y, values)
    finite = np.isfinite(values)
    try:
        if finite.sum() < 3:
            raise ValueError("fewer than three finite points")
        triangulation = mtri.Triangulation(x, y)
        bad = ~finite[triangulation.triangles].all(axis=1)
        if bad.all():
            raise ValueError("no triangle with finite values")
        triangulation.set_mask(bad)
        ax.tripcolor(triangulation, np.where(finite, values, np.nanmin(values[finite])),
                     shading="gouraud", cmap=cmap, norm=norm, rasterized=True)
    except (ValueError, RuntimeError):  # collinear / too few points: show the samples themselves
        ax.scatter(x[finite], y[finite], c=values[finite], s=18, cmap=cmap, norm=norm, edgecolors="none")
    ax.plot(x, y, ",", color="0.5", alpha=0.5)  # sample positions, faint


def _below(fig, axes) -> list[float]:
    """[left, bottom, width, height] (figure fractions) of a colour bar strip under a row of axes."""
    boxes = [ax.get_position() for ax in np.ravel(axes)]
    left, right = min(b.x0 for b in boxes), max(b.x1 for b in boxes)
    inch = 1.0 / fig.get_figheight()
    return [left + 0.05 * (right - left), boxes[0].y0 - 0.6 * inch, 0.9 * (right - left), 0.12 * inch]


def plot_hemisphere_comparison(predictions: dict, channel: str = "luminance"):
    """Measured, model and relative-error discs for every exitant direction (paper Figs. 16-21, sec. 4.1).

    predictions : table with theta_i, phi_i, theta_o, phi_o (deg) and measured_<c>, model_<c> (1/sr).
    channel : a channel name or 'luminance' (the channel mean, the default for RGB data).
    One row per exitant direction (sorted by theta_o, phi_o): measured | model on one shared logarithmic
    colour scale, then (model - measured) / measured on a diverging scale with symmetric limits.  Each
    disc is the incident hemisphere projected onto the tangent plane, weft to the right and warp up.
    """
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.ticker import NullFormatter

    channels = channels_of(predictions)
    measured = channel_values(predictions, "measured", channel, channels)
    model = channel_values(predictions, "model", channel, channels)
    error = signed_relative_error(measured, model)
    groups = exitant_groups(predictions)

    both = np.concatenate([measured, model])
    positive = both[np.isfinite(both) & (both > 0)]
    vmax = float(positive.max()) if positive.size else 1.0
    vmin = float(max(positive.min(), vmax * 1e-4)) if positive.size else 1e-3
    vmin = min(vmin, vmax / 1.01)
    brdf_norm = LogNorm(vmin=vmin, vmax=vmax, clip=True)
    finite_error = np.abs(error[np.isfinite(error)])
    limit = float(np.percentile(finite_error, 98)) if finite_error.size else 1.0
    limit = max(limit, 0.01)
    error_norm = Normalize(vmin=-limit, vmax=limit, clip=True)

    fig = _figure(8.2, 2.45 * len(groups) + 1.1, margins={"left": 0.35, "right": 0.15, "top": 0.95, "bottom": 1.25,
                                                          "hspace": 0.45, "wspace": 0.08})
    axes = fig.subplots(len(groups), 3, squeeze=False)
    tx_i, ty_i = tangent_plane_xy(predictions["theta_i"], predictions["phi_i"])
    for row, (theta_o, phi_o, rows) in enumerate(groups):
        panels = (("measured", measured, BRDF_CMAP, brdf_norm), ("model", model, BRDF_CMAP, brdf_norm),
                  ("relative error", error, ERROR_CMAP, error_norm))
        for col, (title, values, cmap, norm) in enumerate(panels):
            ax = axes[row, col]
            _draw_disc(ax, tx_i[rows], ty_i[rows], values[rows], cmap=cmap, norm=norm)
            _disc_axes(ax, theta_o, phi_o)
            ax.set_title(f"{title}\n{_direction_label(theta_o, phi_o)}", fontsize=8.5)
        axes[row, 0].set_ylabel("y = warp \u2191", fontsize=8)
    axes[-1, 0].set_xlabel("x = weft \u2192", fontsize=8)
    bar = fig.colorbar(ScalarMappable(norm=brdf_norm, cmap=BRDF_CMAP), cax=fig.add_axes(_below(fig, axes[-1, :2])),
                       orientation="horizontal", label=f"BRDF (1/sr), {channel}, log scale")
    # a short log range would label every minor tick and the labels overlap: label decades only
    bar.ax.xaxis.set_minor_formatter(NullFormatter())
    fig.colorbar(ScalarMappable(norm=error_norm, cmap=ERROR_CMAP), cax=fig.add_axes(_below(fig, axes[-1, 2:])),
                 orientation="horizontal", label="(model \u2212 measured) / measured")
    fig.suptitle("Incident hemispheres projected onto the tangent plane (warp vertical); "
                 "\u00d7 exitant, \u25cb mirror direction", fontsize=9, y=1.0 - 0.2 / fig.get_figheight())
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
    """Log y when every finite value is positive; beyond three decades without minor ticks (a wide log range
    has dozens of unlabelled minor ticks per axis, most of a figure's drawing time)."""
    from matplotlib.ticker import NullLocator

    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size and (values > 0).all():
        ax.set_yscale("log")
        if values.max() > 1e3 * values.min():
            for shared in ax.get_shared_y_axes().get_siblings(ax):
                shared.yaxis.set_minor_locator(NullLocator())


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
                                    label=f"posterior 5-95 % {c}")
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
                 "of the plane", fontsize=9, y=1.0 - 0.08 / height)
    return fig


def plot_fit_trace(trace: dict):
    """Objective per evaluation (dots) and best so far (line) against evaluation and wall time (s).

    trace : table evaluation, time_s, value, best, stage ('global' | 'local' | ...); log y when positive.
    """
    fig = _figure(10.0, 3.6, margins={"left": 0.85, "right": 0.15, "top": 0.4, "bottom": 0.55, "wspace": 0.04})
    axes = fig.subplots(1, 2, sharey=True)
    stages = np.asarray(trace["stage"], dtype=str)
    order = np.argsort(trace["evaluation"], kind="stable")
    for ax, xname, xlabel in ((axes[0], "evaluation", "evaluation"), (axes[1], "time_s", "wall time (s)")):
        x = np.asarray(trace[xname], dtype=np.float64)[order]
        for index, stage in enumerate(dict.fromkeys(stages[order])):
            colour = STAGE_COLOURS.get(stage, f"C{(index + 2) % 10}")
            mask = stages[order] == stage
            ax.plot(x[mask], trace["value"][order][mask], ".", ms=2.5, color=colour, alpha=0.35)
            ax.plot(x[mask], trace["best"][order][mask], "-", lw=1.6, color=colour, label=f"best so far ({stage})")
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3, lw=0.5)
    _use_log_y(axes[0], np.concatenate([trace["value"], trace["best"]]))
    axes[0].set_ylabel("objective")
    axes[0].legend(fontsize=8)
    fig.suptitle("Optimiser trace (dots: each evaluation; line: best so far)", fontsize=9)
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

    Red marks a parameter at a bound; grey rows are fixed parameters.  Labels give the values and units.
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

    def mark(x, y, label, **style):
        ax.plot([x], [y], label=None if label in seen else label, **style)
        seen.add(label)

    for row, name in enumerate(names):
        y = len(names) - 1 - row
        entry = parameters[name]
        lower, upper = entry.get("lower"), entry.get("upper")
        free = entry.get("free", True)
        at_bound = entry.get("at_bound")
        colour = "tab:red" if at_bound else ("tab:blue" if free else "0.55")
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
        unit = entry.get("unit") or ""
        text = f"{entry['value']:.4g} {unit}".strip() if isinstance(entry.get("value"), int | float) \
            else str(entry.get("value"))
        if lower is not None and upper is not None:
            text += f"  [{lower:g}, {upper:g}]"
        if "truth" in entry and entry["truth"] is not None:
            text += f"  truth {entry['truth']:.4g}"
        if at_bound:
            text += f"  AT {str(at_bound).upper()} BOUND"
        if not free:
            text += "  (fixed)"
        ax.text(1.04, y, text, va="center", fontsize=8, color=colour if at_bound else "black")
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


def plot_corner(samples: dict, truths: dict | None = None):
    """Corner plot (corner.corner) of posterior samples: columns parameter -> (S,) in declared units; the
    generating values of simulated data as truths when given; 16/50/84 % quantiles marked."""
    import corner
    from matplotlib.figure import Figure

    names = list(samples)
    data = np.column_stack([np.asarray(samples[n], dtype=float) for n in names])
    fig = Figure(figsize=(1.9 * len(names) + 1, 1.9 * len(names) + 1))
    t = [truths.get(n) for n in names] if truths and any(truths.get(n) is not None for n in names) else None
    corner.corner(data, labels=names, truths=t, quantiles=[0.16, 0.5, 0.84], fig=fig,
                  max_n_ticks=4)  # corner's default 5 crowds the rotated x tick labels of neighbouring panels
    # titles median +(84th - median) / -(median - 16th) in plain text on two lines: corner's own
    # show_titles typesets them with mathtext (about 0.4 s per report) and on one line they overlap
    diagonal = np.asarray(fig.axes).reshape(len(names), len(names)).diagonal()
    for ax, column, name in zip(diagonal, data.T, names, strict=True):
        lo, mid, hi = corner.quantile(column[np.isfinite(column)], [0.16, 0.5, 0.84])
        ax.set_title(f"{name} = " + f"{mid:.3g}\n+{hi - mid:.3g} / \u2212{mid - lo:.3g}".replace("-", "\u2212"),
                     fontsize=9)
    # the upper triangle is blank (frame off, no ticks, nothing drawn) but its axes still cost drawing time
    for ax in list(fig.axes):
        if not ax.get_frame_on() and not (ax.lines or ax.collections or ax.patches or ax.images or ax.texts):
            fig.delaxes(ax)
    return fig
