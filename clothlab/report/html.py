"""HTML pages of the report: one page per fit, one comparison page for several fits.

Pages are self-contained (inline CSS, no scripts, no external assets); figures are PNG files next to the
page, referenced by file name.  Every piece of text from a fit file goes through :func:`html.escape`.
Relative errors are stored as fractions and shown in percent, like the paper's sec. 8 figures.
"""

from __future__ import annotations

import html
import json
import math

from clothlab.report.data import (
    PAPER_RELATIVE_ERRORS,
    PAPER_SOURCE,
    fabric_name,
    is_simulated,
    model_setting,
    paper_fabric,
    percentile_key,
    selection_rows,
)

CSS = """
body { font-family: system-ui, -apple-system, 'Segoe UI', sans-serif; margin: 1.5em auto; max-width: 1100px;
       color: #222; line-height: 1.4; padding: 0 1em; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { font-size: 1.15em; margin-top: 1.6em;
     border-bottom: 1px solid #ccc; padding-bottom: 0.15em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; } td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
tr.atbound td { background: #fdecea; } .warn { color: #b00020; font-weight: bold; }
.banner { background: #b00020; color: white; padding: 0.5em 1em; font-weight: bold; font-size: 1.1em;
          border-radius: 4px; margin: 0.6em 0; }
.note { color: #555; font-size: 0.9em; } figure { margin: 1em 0; } figure img { max-width: 100%; }
figcaption { font-size: 0.9em; color: #444; } pre { background: #f7f7f7; padding: 0.6em; overflow-x: auto;
font-size: 0.85em; } ul.warnings li { color: #8a4b00; }
table.kv { margin: 0; font-size: 1em; } table.kv th { font-weight: normal; }
"""

#: Captions of the figures a fit report may hold (file names come from the caller).
FIGURE_CAPTIONS = {
    "hemispheres": "Measured and model BRDF and their relative error. Each incident hemisphere is projected "
                   "onto the tangent plane with the warp direction vertical (Irawan & Marschner 2012, "
                   "sec. 4.1); one row per exitant direction (\u00d7), \u25cb marks the mirror direction; "
                   "dotted rings at \u03b8i = 30 and 60\u00b0. Several channels are shown as their mean.",
    "slices": "Model BRDF in the incidence plane of each exitant direction, with the measured points that "
              "lie within a few degrees of that plane.",
    "error_histogram": "Distribution of the relative error |model \u2212 measured| / measured, all channels "
                       "pooled, with the percentile lines.",
    "parameters": "Fitted parameters within their fit bounds, with the start value (and the true value "
                  "for simulated data).",
    "trace": "Optimiser trace: objective of each evaluation and best so far, by stage.",
    "comparison": "Median and 80th-percentile relative error per fit; hatched bars: the paper's published "
                  "figures on its real measurements.",
    "corner": "Posterior samples: marginal histograms with the 16 / 50 / 84 % quantiles (dashed) on the "
              "diagonal, joint histograms with the contours holding 39 % and 87 % of the samples below it; "
              "axes in the parameters' declared units; blue lines mark the generating values of simulated data.",
}

#: Captions of the figures of a scattered sampling (:mod:`clothlab.report.sampling`), where they differ.
SCATTERED_CAPTIONS = {
    "hemispheres": "The fitted model over the exitant hemisphere (tangent-plane projection, warp vertical) for a "
                   "few representative incident directions (+; \u25cb its mirror direction), chosen to cover the "
                   "most samples; the measured samples whose incident direction lies within the window are "
                   "overlaid, coloured by their relative error. Several channels are shown as their mean.",
    "slices": "The fitted model in the incidence plane of the incident directions shown above, with the "
              "samples of their window that lie near that plane (only planes with such samples are drawn).",
    "residuals": "Relative error (model \u2212 measured) / measured against \u03b8i, \u03b8o, the phase "
                 "angle between the incident and exitant directions (the distance to retro-reflection), the "
                 "half-vector polar angle and the distance to the mirror direction, with binned medians; the "
                 "p80 tail (the rows whose |error| exceeds its 80th percentile) ringed in black.",
    "parity": "Measured against model BRDF on log-log axes: points on the diagonal are fitted exactly; dashed "
              "lines at \u00b120 %.",
}


def esc(value) -> str:
    """Escaped text of any value (None shows as an em dash)."""
    return "\u2014" if value is None else html.escape(str(value), quote=True)


def fmt_number(value, digits: int = 4) -> str:
    """A number with ``digits`` significant digits, escaped; non-numbers as escaped text."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return esc(value)
    if isinstance(value, int):
        return str(value)
    return "\u2014" if not math.isfinite(value) else f"{value:.{digits}g}"


def fmt_percent(fraction) -> str:
    """A relative error stored as a fraction, shown in percent with one decimal ('21.0 %')."""
    if not isinstance(fraction, int | float) or isinstance(fraction, bool) or not math.isfinite(fraction):
        return "\u2014"
    return f"{100.0 * fraction:.1f} %"


def _table(header, rows, *, row_classes=None) -> str:
    """rows hold already-escaped cell HTML; a cell given as ('num', html) is right-aligned; ``header`` None
    writes no header row (key / value tables)."""
    out = ["<table>"] + (["<tr>" + "".join(f"<th>{h}</th>" for h in header) + "</tr>"] if header else [])
    for index, row in enumerate(rows):
        css = f' class="{row_classes[index]}"' if row_classes and row_classes[index] else ""
        cells = []
        for cell in row:
            if isinstance(cell, tuple):
                cells.append(f'<td class="{cell[0]}">{cell[1]}</td>')
            else:
                cells.append(f"<td>{cell}</td>")
        out.append(f"<tr{css}>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def fmt_seconds(value) -> str:
    """A duration in seconds: three significant digits below 100 s, whole seconds above ('14.6 s')."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return "\u2014"
    return f"{value:.3g} s" if abs(value) < 100 else f"{value:.0f} s"


def stage_times(timings) -> str:
    """fit.json ``timings`` ({'optimisation_s': 14.63, ...}) as 'optimisation 14.6 s; posterior 204 s'."""
    if not isinstance(timings, dict) or not timings:
        return "\u2014"
    parts = [f"{esc(k.removesuffix('_s').replace('_', ' '))} {fmt_seconds(v)}" for k, v in timings.items()
             if str(k).endswith("_s") and k != "total_s"]
    return "; ".join(parts) or "\u2014"


def _key_values(mapping) -> str:
    if not isinstance(mapping, dict) or not mapping:
        return "\u2014"
    return "; ".join(f"{esc(k)} = {esc(v)}" for k, v in mapping.items())


def fmt_unit(unit) -> str:
    """A parameter's unit for a table cell: '-' for a dimensionless one (declared '1'), '' for none."""
    if unit is None or unit == "":
        return ""
    return "-" if str(unit) == "1" else esc(unit)


def _value_html(value) -> str:
    """A provenance value: a nested key / value table for a mapping, a comma list for a list of scalars."""
    if isinstance(value, dict):
        return _key_value_table(value) if value else "\u2014"
    if isinstance(value, list | tuple) and not any(isinstance(v, dict | list | tuple) for v in value):
        return ", ".join(fmt_number(v) for v in value) or "\u2014"
    if isinstance(value, list | tuple):
        return "<br>".join(_value_html(v) for v in value) or "\u2014"
    return fmt_number(value) if isinstance(value, int | float) and not isinstance(value, bool) else esc(value)


def _key_value_table(mapping) -> str:
    """A mapping (e.g. a measurement's provenance) as a two-column table, nested mappings as nested tables."""
    if not isinstance(mapping, dict) or not mapping:
        return "\u2014"
    rows = "".join(f"<tr><th>{esc(k)}</th><td>{_value_html(v)}</td></tr>" for k, v in mapping.items())
    return f'<table class="kv">{rows}</table>'


def _page(title: str, body: list[str]) -> str:
    return "\n".join([
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{esc(title)}</title>", f"<style>{CSS}</style>", "</head>", "<body>", *body, "</body>",
        "</html>", "",
    ])


def _header_fabric(fit: dict) -> str:
    """The fabric the header names: a selection's fit is about the fabric of fabric.yaml (its ``name``), not
    the preset that won (:func:`clothlab.report.data.fabric_name` otherwise)."""
    if isinstance(fit.get("selection"), dict):
        name = (fit.get("config") or {}).get("name") or fit.get("name")
        winner = (fit.get("model") or {}).get("weave")
        return f"{name} (selected weave {winner})" if winner else str(name)
    return fabric_name(fit)


def _header_section(fit: dict, sampling=None) -> list[str]:
    model = fit.get("model") or {}
    measurement = fit.get("measurement") or {}
    provenance = measurement.get("provenance") or {}
    out = [f"<h1>clothlab fit report: {esc(fit.get('name'))}</h1>"]
    if is_simulated(provenance):
        out.append('<div class="banner">SIMULATED data: this fit is to a simulated measurement, '
                   "not to a real one.</div>")
    channels = measurement.get("channels")
    rows = [
        ("fabric", esc(_header_fabric(fit))),
        ("model", esc(model.get("kind"))),
        ("weave", esc(model.get("weave"))),
        ("setting", esc(model_setting(fit))),
        ("measurement", esc(measurement.get("path"))),
        ("samples", fmt_number(measurement.get("n"))),
        ("channels", esc(", ".join(map(str, channels)) if channels else None)),
        ("provenance", _key_value_table(provenance)),
        ("metric", esc(fit.get("metric"))),
        ("fit created", esc(fit.get("created"))),
    ]
    if sampling is not None:
        rows.insert(7, ("sampling", esc(sampling.reason)))
    out.append(_table(None, [(f"<b>{k}</b>", v) for k, v in rows]))
    return out


def _error_section(fit: dict, errors: dict, percentiles) -> list[str]:
    header = [f"{q:g}th percentile" if q != 50 else "median (50th)" for q in percentiles] + ["mean", "n"]
    rows = []
    entries = [("overall", errors.get("overall") or {})]
    entries += [(f"channel {c}", e) for c, e in (errors.get("per_channel") or {}).items()]
    for label, entry in entries:
        rows.append([esc(label)] + [("num", fmt_percent(entry.get(percentile_key(q)))) for q in percentiles]
                    + [("num", fmt_percent(entry.get("mean"))), ("num", fmt_number(entry.get("n")))])
    out = ["<h2>Relative error</h2>",
           '<p class="note">|model \u2212 measured| / measured over all measured directions, computed from '
           "predictions.csv (the metric of Irawan &amp; Marschner 2012, sec. 8).</p>",
           _table(["", *header], rows)]
    cv = fit.get("cross_validation")
    if isinstance(cv, dict) and isinstance(cv.get("held_out"), dict):
        qs = [q for q in (50, 80) if percentile_key(q) in cv["held_out"]]
        cv_rows = [[esc(label)] + [("num", fmt_percent((entry or {}).get(percentile_key(q)))) for q in qs]
                   for label, entry in (("in-sample (full fit)", cv.get("in_sample")),
                                        (f"held out ({cv.get('k')}-fold cross-validation)", cv.get("held_out")))]
        reason = f"{cv['scheme_reason']}. " if cv.get("scheme_reason") else ""
        out += [f"<h3>In-sample vs cross-validated</h3><p class=\"note\">{esc(reason)}"
                f"{esc(cv.get('split', ''))} "
                f"{esc(cv.get('refit', ''))}</p>",
                _table(["", *[f"{q}th percentile" if q != 50 else "median" for q in qs]], cv_rows)]
    key = paper_fabric(fit)
    if key:
        median, p80 = PAPER_RELATIVE_ERRORS[key]
        out.append(f'<p class="note">These data are the paper\'s {esc(key)} (measurement provenance). For '
                   f"comparison, the paper's Irawan-Marschner fit of its real {esc(key)} measurement: median "
                   f"{median:g} %, 80th percentile {p80:g} % ({esc(PAPER_SOURCE)}).</p>")
    return out


def _parameter_section(fit: dict) -> list[str]:
    """The parameter table: values, bounds, the Gauss-Newton standard error when recorded (with or without a
    posterior), and the status column with the at-bound and not-determined flags
    (:func:`clothlab.fit.determined.not_determined`); the Gauss-Newton correlations above 0.5 below it."""
    from clothlab.fit.determined import not_determined
    from clothlab.fit.fitreport import correlations

    parameters = fit.get("parameters") or {}
    try:
        undetermined = not_determined(fit)
    except (AttributeError, TypeError):  # a malformed document: the table without the flags
        undetermined = {}
    unc = fit.get("uncertainty") if isinstance(fit.get("uncertainty"), dict) else {}
    stderr = unc.get("stderr") if isinstance(unc.get("stderr"), dict) else {}
    with_truth = any(isinstance(e, dict) and e.get("truth") is not None for e in parameters.values())
    with_status = bool(undetermined) or any(isinstance(e, dict) and e.get("at_bound") for e in parameters.values())
    header = ["parameter", "value", "unit", "free", "lower", "upper", "start"] + (["truth"] if with_truth else [])
    header += ["std. error (Gauss-Newton)"] if stderr else []
    header += ["status"] if with_status else []
    rows, classes = [], []
    for name, entry in parameters.items():
        at_bound = entry.get("at_bound")
        status = [f'<span class="warn">\u26a0 at {esc(at_bound)} bound</span>'] if at_bound else []
        if name in undetermined:
            status.append(f'<span class="warn">\u26a0 not determined: {esc(undetermined[name])}</span>')
        row = [f"<code>{esc(name)}</code>", ("num", fmt_number(entry.get("value"))), fmt_unit(entry.get("unit")),
               "free" if entry.get("free", True) else "fixed", ("num", fmt_number(entry.get("lower"))),
               ("num", fmt_number(entry.get("upper"))), ("num", fmt_number(entry.get("start")))]
        if with_truth:
            row.append(("num", fmt_number(entry.get("truth"))))
        if stderr:
            row.append(("num", fmt_number(stderr.get(name))) if entry.get("free", True) else "")
        if with_status:
            row.append("; ".join(status))
        rows.append(row)
        classes.append("atbound" if status else "")
    out = ["<h2>Parameters</h2>", _table(header, rows, row_classes=classes)]
    if any(classes):
        out.append('<p class="note warn">Parameters at a bound, within 2 % of one, or without effect (their '
                   "component's coefficient is 0) are not determined by these data: widen the bound or fix the "
                   "parameter, and do not read the value as measured.</p>")
    try:
        source, pairs = correlations(fit, None)
    except (AttributeError, TypeError, KeyError, IndexError):
        source, pairs = None, []
    if source is not None:
        listed = ", ".join(f"{esc(a)} / {esc(b)} {r:+.2f}" for a, b, r in pairs) or "none"
        out.append(f'<p class="note">Correlations with |r| &gt; 0.5 ({esc(source)} approximation at the optimum): '
                   f"{listed}.</p>")
    return out


def _coefficient_section(fit: dict) -> list[str]:
    coefficients = fit.get("coefficients") or {}
    if not coefficients:
        return []
    channels = list(dict.fromkeys(c for v in coefficients.values() if isinstance(v, dict) for c in v))
    rows = []
    for name, values in coefficients.items():
        if isinstance(values, dict):
            rows.append([f"<code>{esc(name)}</code>"] + [("num", fmt_number(values.get(c))) for c in channels])
        else:
            rows.append([f"<code>{esc(name)}</code>", ("num", fmt_number(values))] + [""] * (len(channels) - 1))
    return ["<h2>Linear coefficients</h2>",
            '<p class="note">Diffuse and specular weights per channel, solved by linear least squares.</p>',
            _table(["coefficient", *map(esc, channels or ["value"])], rows)]


def _statistics_section(fit: dict) -> list[str]:
    """lmfit's fit statistics (:func:`clothlab.fit.fitreport.statistics`), as the text report shows them."""
    from clothlab.fit.fitreport import statistics

    stats = statistics(fit)
    if stats is None:
        return []
    rows = [("data points (n)", stats["n"]), ("variables (k: free parameters + linear coefficients)", stats["k"]),
            ("chi-square", fmt_number(stats["chi_square"], 6)),
            ("reduced chi-square", fmt_number(stats["reduced_chi_square"], 6)),
            ("Akaike info crit (AIC)", fmt_number(stats["aic"], 8)),
            ("Bayesian info crit (BIC)", fmt_number(stats["bic"], 8))]
    return ["<h2>Fit statistics</h2>",
            '<p class="note">chi-square = n F, F the final objective (mean loss of the metric residuals); '
            "AIC = n ln F + 2k, BIC = n ln F + k ln n (as the selection table), comparable between fits of the "
            "same data only.</p>",
            _table(None, [(f"<b>{esc(k)}</b>", ("num", str(v))) for k, v in rows])]


INFORMATIONAL = ("fitted with filament_arc:", "parameters refined with the exact surface model")
"""Phrases of fit.json ``warnings`` entries that state a convention or what was done, not a problem: the page
lists them under "Notes" (e.g. the filament-arc convention of a ``.wv`` export)."""


def is_informational(text: str) -> bool:
    """True for a fit message that informs (:data:`INFORMATIONAL`) rather than warns."""
    return any(phrase in text for phrase in INFORMATIONAL)


def _warning_section(fit: dict, notes) -> list[str]:
    messages = [str(w) for w in fit.get("warnings") or []]
    warnings = [w for w in messages if not is_informational(w)]
    notes = [w for w in messages if is_informational(w)] + list(notes)
    out = []
    if warnings:
        out += ["<h2>Warnings from the fit</h2>", '<ul class="warnings">']
        out += [f"<li>{esc(w)}</li>" for w in warnings]
        out.append("</ul>")
    if notes:
        out += ["<h2>Notes</h2>", '<ul class="notes">'] + [f"<li>{esc(n)}</li>" for n in notes] + ["</ul>"]
    return out


def _figure_section(figures: dict, captions: dict | None = None) -> list[str]:
    if not figures:
        return []
    out = ["<h2>Figures</h2>"]
    for name, filename in figures.items():
        caption = (captions or {}).get(name) or FIGURE_CAPTIONS.get(name, name.replace("_", " "))
        out.append(f'<figure id="fig-{esc(name)}"><img src="{esc(filename)}" alt="{esc(name)}">'
                   f"<figcaption>{esc(caption)}</figcaption></figure>")
    return out


def _selection_section(fit: dict) -> list[str]:
    """The model-selection candidates (fit.json ``selection``, :func:`clothlab.report.data.selection_rows`) as
    the table of ``selection.md`` (:func:`clothlab.fit.select.display_rows`), the winner marked, with the
    ranking rule and what the candidates were; nothing when the fit has no selection."""
    from clothlab.fit.select import DISPLAY_HEAD, display_rows

    rows = selection_rows(fit)
    if not rows:
        return []
    selection = fit.get("selection") if isinstance(fit.get("selection"), dict) else {}
    winner = selection.get("winner")
    numeric = set(DISPLAY_HEAD[2:11])
    cells = []
    for row, shown in zip(rows, display_rows(rows), strict=True):
        mark = " (winner, this fit)" if winner is not None and row.get("candidate") == winner else ""
        cells.append([("num", esc(v)) if h in numeric else esc(v + mark if h == "candidate" else v)
                      for h, v in zip(DISPLAY_HEAD, shown, strict=True)])
    out = ["<h2>Model selection: candidates and runners-up</h2>"]
    how = selection.get("ranking") or selection.get("criterion")
    if how:
        out.append(f'<p class="note">Ranked by {esc(how)}.  Errors are relative, in %; CV = held out by '
                   f'cross-validation, p50 / p80 = in-sample.  {esc(selection.get("information_criteria") or "")}'
                   "</p>")
    tried, budget = selection.get("tried") or {}, selection.get("budget") or {}
    if tried or budget:
        parts = [f"{esc(k)}: {esc(', '.join(map(str, v)) if isinstance(v, list) else v)}" for k, v in tried.items()]
        parts += [f"{esc(k)} {esc(v)}" for k, v in budget.items()]
        out.append(f'<p class="note">Candidates tried - {"; ".join(parts)} (per candidate).</p>')
    return (out + [_table([esc(h) for h in DISPLAY_HEAD], cells)] + _nested_section(selection.get("nested"))
            + _stability_section(selection.get("stability")) + _top_residual_section(selection.get("top_residuals")))


def _top_residual_section(top) -> list[str]:
    """Where the p80 tail of each of the top candidates lies (fit.json ``selection.top_residuals``)."""
    if not isinstance(top, list) or not top:
        return []
    items = "".join(f"<li><b>{esc(t.get('candidate', ''))}</b>: {esc(t.get('summary', ''))}</li>" for t in top
                    if isinstance(t, dict))
    return ["<h3>Residual diagnostics of the top candidates</h3>", f"<ul>{items}</ul>"]


def _stability_section(stab) -> list[str]:
    """fit.json ``selection.stability`` (:mod:`clothlab.fit.stability`): how often each weave, kind, loss and
    orientation range won on the subsamples (and the nested CV's outer folds), with the verdict per aspect."""
    if not isinstance(stab, dict) or not isinstance(stab.get("counts"), dict):
        return []
    rows = []
    sources = (("subsamples", stab.get("counts"), stab.get("verdict") or {}),
               ("nested outer folds", stab.get("nested_counts"), stab.get("nested_verdict") or {}))
    for source, counts, verdicts in sources:
        for aspect, c in (counts or {}).items():
            if not isinstance(c, dict) or not c:
                continue
            text = str(verdicts.get(aspect, ""))
            cell = f'<span class="warn">{esc(text)}</span>' if text.startswith("NOT DETERMINED") else esc(text)
            rows.append([esc(source), esc(aspect), esc(", ".join(f"{v} {n}" for v, n in c.items())), cell])
    return ["<h3>Selection stability</h3>", f'<p class="note">{esc(stab.get("rule", ""))}.</p>',
            _table(["repetitions", "aspect", "wins", "verdict"], rows)]


def model_error_for_floor(fit: dict, errors: dict) -> tuple[dict, str]:
    """The model's error compared with the noise floor: the nested outer held-out error of a selection, else
    the cross-validated one, else the in-sample one (``errors``), with its label."""
    nested = (fit.get("selection") or {}).get("nested") if isinstance(fit.get("selection"), dict) else None
    if isinstance(nested, dict) and isinstance(nested.get("held_out"), dict):
        return nested["held_out"], "outer held-out, nested CV"
    cv = fit.get("cross_validation")
    if isinstance(cv, dict) and isinstance(cv.get("held_out"), dict):
        return cv["held_out"], "held out by cross-validation"
    return (errors or {}).get("overall") or {}, "in-sample"


def _residual_section(diag) -> list[str]:
    """The residuals binned against the geometry a missing term would follow (:mod:`clothlab.fit.residuals`):
    per feature and bin the median signed relative residual and the p80-tail enrichment; the worst rows."""
    from clothlab.fit.residuals import summary_sentence

    if not isinstance(diag, dict) or not isinstance(diag.get("features"), dict):
        return []
    rows = []
    for name, entry in diag["features"].items():
        cells = []
        for b in entry.get("bins") or []:
            if not b.get("n"):
                cells.append("—")
                continue
            text = f"{100 * b['median_r']:+.1f} % ({b['n']}; tail {b['enrichment']:.1f} x)"
            cells.append(f'<span class="warn">{esc(text)}</span>' if (b.get("enrichment") or 0) > 1.5 and
                         b["n"] >= 5 else esc(text))
        edges = ", ".join(f"{b['lo']:g}-{b['hi']:g}" for b in entry.get("bins") or [])
        rows.append([f"{esc(entry.get('label', name))}<br><small>bins {esc(edges)} deg</small>", *cells])
    width = max((len(r) for r in rows), default=1)
    rows = [r + [""] * (width - len(r)) for r in rows]
    worst = ", ".join(f"({w['theta_i']:.0f}, {w['phi_i']:.0f}) -> ({w['theta_o']:.0f}, {w['phi_o']:.0f}) "
                      f"{100 * w['r']:+.0f} %" for w in diag.get("worst") or [])
    return ["<h3>Residual diagnostics</h3>", f'<p class="note">{esc(summary_sentence(diag))}.  {esc(diag["rule"])}; '
            "each cell: median (model − measured) / measured in the bin (rows; tail enrichment).</p>",
            _table(["feature", *[f"bin {i + 1}" for i in range(width - 1)]], rows),
            f'<p class="note">Worst rows (theta_i, phi_i) -&gt; (theta_o, phi_o) deg, signed error: {esc(worst)}.</p>']


def _noise_floor_section(fit: dict, floor, errors: dict) -> list[str]:
    """The measurement's own scatter next to the model's error (:mod:`clothlab.fit.noise_floor`), or the
    statement that this table has no repeated or reciprocal pairs to estimate it from."""
    from clothlab.fit.noise_floor import floor_sentence

    if not isinstance(floor, dict):
        return []
    model, label = model_error_for_floor(fit, errors)
    cls = "note" if "sigma" in floor else "warn"
    return ["<h3>Noise floor</h3>", f'<p class="{cls}">{esc(floor_sentence(floor, model, label))}.</p>',
            f'<p class="note">{esc(floor.get("rule", ""))}.</p>']


def _nested_section(nested) -> list[str]:
    """fit.json ``selection.nested`` (:mod:`clothlab.fit.nested`): the selected model's outer held-out error
    (the figure to quote) beside the selection score (the winner's inner CV, optimistic), each outer fold's
    winner, and whether they agree; nothing when no nested CV ran."""
    if not isinstance(nested, dict) or not isinstance(nested.get("folds"), list):
        return []
    held, score = nested.get("held_out") or {}, nested.get("selection_score") or {}
    out = ["<h3>Nested cross-validation of the selection</h3>",
           f'<p class="note">{esc(nested.get("rule", ""))}; {esc(nested.get("k"))} outer folds '
           f'({esc(nested.get("scheme", ""))}), {esc(nested.get("fits"))} candidate fits, '
           f'{fmt_number(nested.get("wall_time_s"))} s.</p>',
           _table(["figure", "median", "80th", "mean", "what it is"],
                  [["<b>selected model: outer held-out error (nested CV)</b>", ("num", fmt_percent(held.get("p50"))),
                    ("num", fmt_percent(held.get("p80"))), ("num", fmt_percent(held.get("mean"))),
                    "the error of the selection procedure on directions it never saw: the figure to quote"],
                   ["selection score (inner CV of the winner on all rows)", ("num", fmt_percent(score.get("p50"))),
                    ("num", fmt_percent(score.get("p80"))), ("num", fmt_percent(score.get("mean"))),
                    esc(nested.get("selection_score_rule", ""))]])]
    rows = []
    for f in nested["folds"]:
        if not isinstance(f, dict):
            continue
        h, s = f.get("held_out") or {}, f.get("selection_score") or {}
        rows.append([("num", esc(int(f.get("fold", 0)) + 1)), esc(f.get("winner", "")),
                     ("num", fmt_percent(s.get("p50"))), ("num", fmt_percent(s.get("p80"))),
                     ("num", fmt_percent(h.get("p50"))), ("num", fmt_percent(h.get("p80"))),
                     esc(f.get("runner_up") or "")])
    out.append(_table(["outer fold", "winner", "selection score p50", "selection score p80", "outer held-out p50",
                       "outer held-out p80", "runner-up"], rows))
    cls = "note" if nested.get("winners_agree") else "warn"
    out.append(f'<p class="{cls}"><b>Outer-fold winners:</b> {esc(nested.get("agreement", ""))}.</p>')
    return out


def _posterior_section(posterior) -> list[str]:
    """Posterior (emcee) summary: intervals, identifiability, convergence, correlations (posterior.json)."""
    if not posterior:
        return []
    params = posterior.get("parameters") or {}
    conv = posterior.get("convergence") or {}
    out = ["<h2>Posterior</h2>",
           f'<p class="note">{esc(posterior.get("method", ""))}; prior: {esc(posterior.get("prior", ""))}; '
           f'likelihood: {esc(posterior.get("likelihood", ""))}; coefficients: '
           f'{esc(posterior.get("coefficients", ""))}.</p>']
    undetermined = posterior.get("not_determined") or []
    if undetermined:
        out.append('<p class="warn"><b>Not determined by these data:</b> '
                   + ", ".join(f"<code>{esc(n)}</code>" for n in undetermined)
                   + f' ({esc(posterior.get("identifiability_rule", ""))}).</p>')
    keys = ("p2.5", "p16", "median", "p84", "p97.5")  # posterior.json names (clothlab.fit.posterior)
    rows = []
    for name, e in params.items():
        rows.append([f"<code>{esc(name)}</code>", fmt_unit(e.get("unit"))]
                    + [("num", fmt_number(e.get(k))) for k in keys]
                    + [("num", fmt_number(e.get("optimum"))), ("num", fmt_number(e.get("truth"))),
                       ("num", fmt_number(e.get("tau"))), ("num", fmt_number(e.get("ess"))),
                       "yes" if e.get("determined") else '<span class="warn">no</span>'])
    out.append(_table(["parameter", "unit", "2.5 %", "16 %", "median", "84 %", "97.5 %", "optimum", "truth",
                       "tau", "ESS", "determined"], rows))
    acc = conv.get("acceptance_fraction") or {}
    state = "converged" if conv.get("converged") else "NOT converged"
    reason = str(conv.get("stop_reason") or "")
    state += f" ({esc(reason)})" if reason and reason.lower() != state.lower() else ""
    out.append(f'<p class="note">Convergence: {state}; {esc(conv.get("rule", ""))}; steps {conv.get("steps")}, '
               f'walkers {conv.get("walkers")}, burn-in {conv.get("burn_in")}, thin {conv.get("thin")}, '
               f'mean acceptance {fmt_number(acc.get("mean"))}.</p>')
    corr = posterior.get("correlation") or {}
    names, matrix = corr.get("names") or [], corr.get("matrix") or []
    if names and matrix:
        out.append("<h3>Posterior correlations</h3>")
        out.append(_table(["", *[f"<code>{esc(n)}</code>" for n in names]],
                          [[f"<code>{esc(n)}</code>"] + [("num", fmt_number(v, 2)) for v in row]
                           for n, row in zip(names, matrix, strict=False)]))
    return out


def _facts_section(fit: dict) -> list[str]:
    objective = fit.get("objective") or {}
    wall = fit.get("wall_time_s")
    rows = [
        ("evaluations", fmt_number(fit.get("evaluations"))),
        ("wall time", fmt_seconds(wall)),
        ("of which", stage_times(fit.get("timings"))),
        ("objective start \u2192 final",
         f"{fmt_number(objective.get('start'))} \u2192 {fmt_number(objective.get('final'))}"),
        ("seed", fmt_number(fit.get("seed"))),
        ("optimizer", _key_values(fit.get("optimizer"))),
        ("clothlab version", esc(fit.get("clothlab_version"))),
        ("package versions", _key_values(fit.get("versions"))),
        ("config hash", f"<code>{esc(fit.get('config_hash'))}</code>"),
    ]
    out = ["<h2>Fit facts</h2>", _table(None, [(f"<b>{k}</b>", v) for k, v in rows])]
    if fit.get("config"):
        config = json.dumps(fit["config"], indent=2, sort_keys=True, default=str)
        out.append(f"<details><summary>configuration (fabric.yaml as validated)</summary><pre>{esc(config)}"
                   "</pre></details>")
    return out


def render_report_html(fit: dict, figures: dict, tables: dict) -> str:
    """The report page of one fit.

    fit : the parsed fit.json.   figures : {figure name: PNG file name next to the page}, in page order
    (known names get captions from :data:`FIGURE_CAPTIONS`).
    tables : ``errors`` (fit.json 'errors' format, fractions; required), ``percentiles`` (default
    (50, 80, 95)), ``notes`` (list of report notes), ``posterior`` (parsed posterior.json or None),
    ``sampling`` (:class:`clothlab.report.sampling.SamplingLayout` or None).
    """
    percentiles = tuple(tables.get("percentiles", (50, 80, 95)))
    sampling = tables.get("sampling")
    body = _header_section(fit, sampling)
    body += _error_section(fit, tables["errors"], percentiles)
    body += _noise_floor_section(fit, tables.get("noise_floor"), tables["errors"])
    body += _residual_section(tables.get("residual_diagnostics"))
    body += _selection_section(fit)
    body += _parameter_section(fit)
    body += _coefficient_section(fit)
    body += _statistics_section(fit)
    body += _warning_section(fit, tables.get("notes") or [])
    body += _figure_section(figures, SCATTERED_CAPTIONS if sampling is not None and sampling.scattered else None)
    body += _posterior_section(tables.get("posterior"))
    body += _facts_section(fit)
    return _page(f"clothlab report: {fit.get('name')}", body)


def _fitted_parameters(parameters) -> str:
    """``name = value unit`` per fitted free parameter (one per line; a dash for none)."""
    if not parameters:
        return "\u2014"
    lines = []
    for name, entry in parameters.items():
        unit = entry.get("unit")
        unit = "" if unit in (None, "1") else f" {unit}"
        lines.append(f"{esc(name)} = {fmt_number(entry.get('value'))}{esc(unit)}")
    return "<br>".join(lines)


def render_comparison_html(rows: list[dict], figures: dict, *, title: str = "comparison") -> str:
    """A table with one row per fit (like the paper's sec. 8 list) and the comparison figure(s).

    rows : dicts with name, fabric, model, setting, parameters ({name: {value, unit}} of the free ones),
    p50, p80, p95 (fractions), free (count),
    evaluations, wall_time_s, simulated (bool), link (relative URL of the fit's report or None) and
    paper = (median %, 80th %) or None.
    """
    header = ["fit", "fabric", "model", "model setting\u2020", "fitted parameters", "median", "80th pct.", "95th pct.",
              "free params", "evaluations", "optimisation time (s)", "model speed (pairs/s)", "paper median*",
              "paper 80th*"]
    table_rows = []
    for row in rows:
        name = esc(row["name"])
        if row.get("link"):
            name = f'<a href="{esc(row["link"])}">{name}</a>'
        if row.get("simulated"):
            name += ' <span class="warn">(SIMULATED)</span>'
        paper = row.get("paper")
        table_rows.append([
            name, esc(row.get("fabric")), esc(row.get("model")), esc(row.get("setting")),
            _fitted_parameters(row.get("parameters")),
            ("num", fmt_percent(row.get("p50"))), ("num", fmt_percent(row.get("p80"))),
            ("num", fmt_percent(row.get("p95"))), ("num", fmt_number(row.get("free"))),
            ("num", fmt_number(row.get("evaluations"))), ("num", fmt_number(row.get("wall_time_s"))),
            ("num", "\u2014" if row.get("pairs_per_second") is None else f"{row['pairs_per_second']:,.0f}"),
            ("num", f"{paper[0]:g} %" if paper else "\u2014"), ("num", f"{paper[1]:g} %" if paper else "\u2014"),
        ])
    heading = f"clothlab comparison of {len(rows)} fits" + ("" if title == "comparison" else f": {title}")
    body = [f"<h1>{esc(heading)}</h1>",
            '<p class="note">Relative error |model \u2212 measured| / measured, recomputed from each fit\'s '
            "predictions.csv.</p>",
            _table(header, table_rows),
            f'<p class="note">* The paper\'s published figures of its Irawan-Marschner fits to its real '
            f"measurements ({esc(PAPER_SOURCE)}), shown in the rows of that model whose data are the paper's "
            "fabric (the measurement's provenance); the paper chose parameters partly by hand and did not "
            "minimise these metrics.<br>\u2020 The quadrature (rule and nodes) of an integrating model, the "
            "constructor options of the others.</p>"]
    generators = sorted({row["generated_by"] for row in rows if row.get("simulated") and row.get("generated_by")})
    if generators:
        body.append(f'<p class="warn">The simulated measurements were generated by the {esc(", ".join(generators))} '
                    "model: a fit of that model can reach the noise level, another model cannot, so these rows "
                    "compare the models with each other, not with real cloth.</p>")
    body += _figure_section(figures)
    return _page(heading, body)
