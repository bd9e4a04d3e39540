"""The fit report: what a scientist needs from one fit, as text (``fit_report()``) and HTML (Jupyter).

Modelled on lmfit's ``fit_report()``: the fit's statistics, every parameter with its value and uncertainty,
warnings for parameters stuck at a bound, the correlations above a threshold, then what lmfit has no room for:
the linear coefficients per colour channel, the relative-error percentiles in-sample and cross-validated
(Irawan & Marschner 2012, sec. 8 report the median and 80th percentile), and the time of each stage.

The uncertainty is the emcee posterior's (median and 95 % interval) when a posterior ran, else the standard
error of the Gauss-Newton approximation at the optimum (:mod:`clothlab.fit.uncertainty`); the report says
which.  Both a fresh :class:`clothlab.fit.runner.FitResult` and a :class:`clothlab.fit.store.SavedFit` read
from a fit directory report from the same two documents - the content of ``fit.json`` and of
``posterior.json`` - so a fit reports the same before and after saving.
"""

from __future__ import annotations

import abc
import html
import math
from dataclasses import dataclass, field

from clothlab.fit.metrics import fit_statistics

CORREL_THRESHOLD = 0.5
"""Correlations with a larger magnitude are listed (lmfit's default ``min_correl`` is 0.1)."""


@dataclass
class Section:
    """One block of the report: a title, a caption, an optional table (header + rows) and free lines."""

    title: str
    caption: str = ""
    header: list[str] | None = None
    rows: list[list[str]] = field(default_factory=list)
    lines: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------------------------- formatting
def _num(value, digits: int = 6) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{float(value):.{digits}g}"


def unit_text(unit: str | None) -> str:
    """A declared unit as shown: nothing for dimensionless values ("1", "1 (...)")."""
    if not unit or unit == "1" or unit.startswith("1 "):
        return ""
    return unit


def _percentile_keys(summary: dict) -> list[str]:
    keys = [k for k in summary if k.startswith("p") and _is_number(k[1:])]
    return sorted(keys, key=lambda k: float(k[1:]))


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _percentile_label(key: str) -> str:
    q = float(key[1:])
    return "median" if q == 50 else f"{q:g}th"


def _percent(value) -> str:
    return "n/a" if value is None else f"{100.0 * float(value):.2f} %"


def _seconds(value) -> str:
    return "n/a" if value is None else f"{float(value):.1f} s"


# ---------------------------------------------------------------------------------------------- sections
def _counts(fit: dict) -> tuple[int, int, int]:
    """(n, free parameters, linear coefficients): n the fitted values (rows x channels), as the selection table."""
    m = fit.get("measurement") or {}
    n = (m.get("n") or 0) * len(m.get("channels") or [])
    free = sum(1 for e in (fit.get("parameters") or {}).values() if e.get("free"))
    return n, free, sum(len(v) for v in (fit.get("coefficients") or {}).values())


def _values(fit: dict, k: int) -> str:
    n, _, coefficients = _counts(fit)
    return f"{k}, and {coefficients} linear coefficients (NNLS), for {n} values"


def statistics(fit: dict) -> dict | None:
    """lmfit's fit statistics of a fit summary (fit.json content): :func:`clothlab.fit.metrics.fit_statistics` of
    the final objective F with n the fitted values and k the free parameters plus the linear coefficients, as the
    selection table (:mod:`clothlab.fit.select`) counts them; None when no final objective is recorded."""
    final = (fit.get("objective") or {}).get("final")
    if final is None:
        return None
    n, free, coefficients = _counts(fit)
    return fit_statistics(float(final), n, free + coefficients)


def _statistics_section(fit: dict) -> Section:
    stats = statistics(fit)
    if stats is None:
        return Section("Statistics", "none recorded (no final objective in this fit)")
    _, free, coefficients = _counts(fit)
    rows = [["data points (n)", str(stats["n"])],
            ["variables (k)", f"{stats['k']} ({free} free parameters + {coefficients} linear coefficients)"],
            ["chi-square", _num(stats["chi_square"])], ["reduced chi-square", _num(stats["reduced_chi_square"])],
            ["Akaike info crit (AIC)", _num(stats["aic"], 8)], ["Bayesian info crit (BIC)", _num(stats["bic"], 8)]]
    return Section("Statistics", "chi-square = n F, F the final objective (mean loss of the metric residuals); "
                   "AIC = n ln F + 2k, BIC = n ln F + k ln n, comparable between fits of the same data only", None,
                   rows)


def _evaluations(fit: dict, any_free: bool) -> str:
    if not any_free:
        return f"{fit.get('evaluations')} (one NNLS solve, no optimiser)"
    opt = fit.get("optimizer") or {}
    budget = ((fit.get("config") or {}).get("fit") or {}).get("optimizer") or {}
    starts = budget.get("starts", 1)
    polish = budget.get("polish")
    return (f"{fit.get('evaluations')} (global {opt.get('global')}, local {opt.get('local')}; budget "
            f"{opt.get('max_evals')} over {starts} start{'s' if starts != 1 else ''}"
            + (f" + polish {polish}" if polish else "") + ")")


def _loss(cfg: dict) -> str:
    """fit.loss as the objective uses it (fit.json records it in config.fit when not the default squared)."""
    loss = cfg.get("loss", "squared")
    return loss if loss in ("squared", "l1") else f"{loss} (scale {cfg.get('loss_scale')})"


def _fit_section(fit: dict) -> Section:
    model, m = fit.get("model") or {}, fit.get("measurement") or {}
    q = model.get("quadrature")
    setting = f"quadrature {q['rule']} {q['nodes']}" if q else ", ".join(
        f"{k} {v}" for k, v in (model.get("options") or {}).items())
    channels = list(m.get("channels") or [])
    simulated = " (simulated)" if (m.get("provenance") or {}).get("simulated") else ""
    opt = fit.get("optimizer") or {}
    objective = fit.get("objective") or {}
    free = [n for n, e in fit["parameters"].items() if e.get("free")]
    rows = [
        ["model", f"{model.get('kind')} (weave {model.get('weave')}{', ' + setting if setting else ''})"],
        ["measurement", f"{m.get('path')}{simulated}: {m.get('n')} directions x {len(channels)} channels "
                        f"({', '.join(channels)})"],
        ["free parameters", _values(fit, len(free))],
        ["metric", str(fit.get("metric"))],
        ["loss", _loss(((fit.get("config") or {}).get("fit")) or {})],
        ["evaluations", _evaluations(fit, bool(free))],
        ["objective", f"{_num(objective.get('start'))} at the start -> {_num(objective.get('final'))}"],
        ["optimiser status", str(opt.get("status", ""))],
    ]
    return Section("Fit", fit.get("name", ""), None, rows)


def _parameter_section(fit: dict, posterior: dict | None) -> Section:
    post = (posterior or {}).get("parameters") or {}
    unc = fit.get("uncertainty") or {}
    stderr = unc.get("stderr") or {}
    if not any(e.get("free") for e in fit["parameters"].values()):
        caption = "no free parameter: every value fixed, the linear coefficients solved by NNLS"
        header = ["name", "value", "unit", "", "", "start", "bounds", "note"]
    elif posterior:
        conv = posterior.get("convergence") or {}
        state = "converged" if conv.get("converged") else f"NOT converged ({conv.get('stop_reason')})"
        caption = (f"uncertainty: posterior median and 95 % interval (emcee, {conv.get('walkers')} walkers x "
                   f"{conv.get('steps')} steps, {state})")
        header = ["name", "value", "unit", "median", "95 % interval", "start", "bounds", "note"]
    elif stderr:
        caption = "uncertainty: standard error from the Gauss-Newton approximation at the optimum (no posterior)"
        header = ["name", "value", "unit", "std. error", "relative", "start", "bounds", "note"]
    else:
        caption = "uncertainty: none recorded (no posterior; no Gauss-Newton estimate in this fit)"
        header = ["name", "value", "unit", "", "", "start", "bounds", "note"]
    rows = []
    from clothlab.fit.determined import not_determined

    undetermined = not_determined(fit)  # coefficient 0, no effect, within 2 % of a bound (issue 28 item 6)
    for name, e in fit["parameters"].items():
        value = e.get("value")
        notes = []
        if not e.get("free"):
            rows.append([name, _num(value), unit_text(e.get("unit")), "", "", "", "", "fixed"])
            continue
        if e.get("at_bound"):
            notes.append(f"AT {e['at_bound'].upper()} BOUND")
        if name in undetermined:
            notes.append(f"NOT DETERMINED: {undetermined[name]}")
        if "truth" in e:
            notes.append(f"truth {_num(e['truth'])}")
        if name in post:
            p = post[name]
            cells = [_num(p.get("median")), f"[{_num(p.get('p2.5'))}, {_num(p.get('p97.5'))}]"]
            if not p.get("determined", True):
                notes.append("not determined by these data")
        elif stderr:
            se = stderr.get(name)
            rel = None if se is None or not value else abs(se / value)
            cells = [_num(se, 3), "n/a" if rel is None else f"{100 * rel:.2g} %"]
        else:
            cells = ["", ""]
        bounds = f"[{_num(e.get('lower'))}, {_num(e.get('upper'))}]"
        rows.append([name, _num(value), unit_text(e.get("unit")), *cells, _num(e.get("start")), bounds,
                     "; ".join(notes)])
    for name, p in post.items():  # sampled quantities that are not model parameters (the noise scale)
        if name not in fit["parameters"]:
            rows.append([name, _num(p.get("optimum")), unit_text(p.get("unit")), _num(p.get("median")),
                         f"[{_num(p.get('p2.5'))}, {_num(p.get('p97.5'))}]", "", "", "sampled noise scale"])
    return Section("Parameters", caption, header, rows)


def correlations(fit: dict, posterior: dict | None, threshold: float = CORREL_THRESHOLD):
    """(source, [(name_i, name_j, r)]) of the free-parameter pairs with |r| > threshold, largest first: the
    posterior's correlations when it ran, else the Gauss-Newton ones (source "posterior" / "gauss-newton" /
    None when neither was recorded)."""
    if posterior and posterior.get("correlation"):
        source, corr = "posterior", posterior["correlation"]
    elif (fit.get("uncertainty") or {}).get("correlation", {}).get("matrix"):
        source, corr = "gauss-newton", fit["uncertainty"]["correlation"]
    else:
        return None, []
    names, matrix = corr["names"], corr["matrix"]
    pairs = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            r = matrix[i][j]
            if r is not None and abs(r) > threshold:
                pairs.append((names[i], names[j], float(r)))
    return source, sorted(pairs, key=lambda p: -abs(p[2]))


def _correlation_section(fit: dict, posterior: dict | None, threshold: float) -> Section:
    source, pairs = correlations(fit, posterior, threshold)
    if source is None:
        return Section("Correlations", "none recorded", None, [])
    caption = (f"|r| > {threshold:g}, " + ("posterior samples" if source == "posterior" else
                                          "Gauss-Newton approximation")
               + " (unit-box coordinates: log for log-scaled parameters)")
    rows = [[f"C({a}, {b})", f"{r:+.3f}"] for a, b, r in pairs]
    return Section("Correlations", caption, None, rows, [] if rows else ["none above the threshold"])


def _coefficient_section(fit: dict) -> Section:
    channels = list((fit.get("measurement") or {}).get("channels") or [])
    coefs = fit.get("coefficients") or {}
    rows = [[name, *(_num(values.get(c), 5) for c in channels)] for name, values in coefs.items()]
    return Section("Coefficients", str(fit.get("coefficient_meaning", "")), ["name", *channels], rows)


def _error_section(fit: dict) -> Section:
    errors = fit.get("errors") or {}
    overall = errors.get("overall") or {}
    keys = _percentile_keys(overall)
    header = ["", *map(_percentile_label, keys), "mean"]

    def row(label, summary):
        return [label, *(_percent(summary.get(k)) for k in keys), _percent(summary.get("mean"))]

    rows = [row("in-sample", overall)]
    for channel, summary in (errors.get("per_channel") or {}).items():
        rows.append(row(f"  channel {channel}", summary))
    lines = []
    cv = fit.get("cross_validation")
    if cv and cv.get("failed"):
        state = "incomplete" if cv.get("folds") else "not run"  # some fold refits landed, or none
        lines.append(f"cross-validation ({cv.get('k')}-fold) {state}: {cv['failed']}")
    elif cv:
        rows.append(row(f"cross-validated ({cv.get('k')}-fold, held out)", cv.get("held_out") or {}))
        rows.append(row("  fold fits on their training rows", cv.get("train_folds") or {}))
        if cv.get("scheme_reason"):
            lines.append(f"cross-validation folds: {cv['scheme_reason']}")
        lines.append(f"cross-validation: {cv.get('refit')}")
    else:
        lines.append("no cross-validation (fit.cv_folds: 0)")
    return Section("Errors", "relative error |model - measured| / measured (Irawan & Marschner 2012, sec. 8)",
                   header, rows, lines)


def _time_section(fit: dict, posterior: dict | None) -> Section:
    t = fit.get("timings") or {}
    rows = [["optimisation", _seconds(t.get("optimisation_s"))]]
    if "standard_errors_s" in t:
        rows.append(["standard errors", _seconds(t["standard_errors_s"])])
    if "cross_validation_s" in t:
        rows.append(["cross-validation", _seconds(t["cross_validation_s"])])
    if "posterior_s" in t:
        resumed = ((posterior or {}).get("convergence") or {}).get("resumed_from_step")
        rows.append(["posterior", _seconds(t["posterior_s"])
                     + (f" (resumed at step {resumed}: the sessions' sum)" if resumed else "")])
    rows.append(["total", _seconds(t.get("total_s", fit.get("wall_time_s")))])
    return Section("Time", "", None, rows)


def _notes_section(fit: dict, posterior: dict | None) -> Section:
    notes = list(fit.get("warnings") or [])
    for note in (fit.get("uncertainty") or {}).get("notes") or []:
        notes.append(f"Gauss-Newton: {note}")
    for note in (posterior or {}).get("warnings") or []:
        if note not in notes:
            notes.append(note)
    return Section("Notes", "", None, [], notes or ["none"])


def report_sections(fit: dict, posterior: dict | None = None, *,
                    correl_threshold: float = CORREL_THRESHOLD) -> list[Section]:
    """The report of a fit summary (fit.json content) and its posterior summary (posterior.json, or None)."""
    return [_fit_section(fit), _statistics_section(fit), _parameter_section(fit, posterior),
            _correlation_section(fit, posterior, correl_threshold), _coefficient_section(fit),
            _error_section(fit), _time_section(fit, posterior), _notes_section(fit, posterior)]


# ---------------------------------------------------------------------------------------------- rendering
def _text_table(rows: list[list[str]], indent: str = "    ") -> list[str]:
    widths = [max(len(r[i]) for r in rows if i < len(r)) for i in range(max(map(len, rows)))]
    return [(indent + "  ".join(cell.ljust(w) for cell, w in zip(r, widths, strict=False))).rstrip()
            for r in rows]


def format_text(sections: list[Section]) -> str:
    """The sections as plain text: ``[[Title]] caption``, then the table and lines, indented."""
    out = []
    for s in sections:
        out.append(f"[[{s.title}]]" + (f" {s.caption}" if s.caption else ""))
        table = ([s.header] if s.header else []) + s.rows
        if table:
            out += _text_table(table)
        out += [f"    {line}" for line in s.lines]
    return "\n".join(out)


def format_html(sections: list[Section]) -> str:
    """The sections as HTML tables (for Jupyter's ``_repr_html_``)."""
    e = html.escape
    out = ["<div class='clothlab-fit-report'>"]
    for s in sections:
        out.append(f"<h4>{e(s.title)}{': ' + e(s.caption) if s.caption else ''}</h4>")
        if s.header or s.rows:
            out.append("<table>")
            if s.header:
                out.append("<tr>" + "".join(f"<th>{e(c)}</th>" for c in s.header) + "</tr>")
            for r in s.rows:
                out.append("<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>")
            out.append("</table>")
        if s.lines:
            out.append("<ul>" + "".join(f"<li>{e(line)}</li>" for line in s.lines) + "</ul>")
    out.append("</div>")
    return "\n".join(out)


def short_text(kind_of_object: str, fit: dict) -> str:
    """One line: object, fit name, model kind, free parameters, median in-sample relative error."""
    free = [n for n, e in fit["parameters"].items() if e.get("free")]
    shown = ", ".join(free[:4]) + (", ..." if len(free) > 4 else "")
    median = ((fit.get("errors") or {}).get("overall") or {}).get("p50")
    return (f"<{kind_of_object} {fit.get('name')}: {(fit.get('model') or {}).get('kind')}, {len(free)} free"
            f"{' (' + shown + ')' if free else ''}, median relative error {_percent(median)}>")


class Reportable(abc.ABC):
    """Report methods of a fit (fresh or loaded): implementers provide :meth:`_report_sources`."""

    @abc.abstractmethod
    def _report_sources(self) -> tuple[dict, dict | None]:
        """(fit summary as in fit.json, posterior summary as in posterior.json or None)."""

    def fit_report(self, correl_threshold: float = CORREL_THRESHOLD) -> str:
        """The fit report as text: statistics, parameters with uncertainty (posterior or Gauss-Newton),
        at-bound flags, correlations with |r| > ``correl_threshold``, coefficients per channel, in-sample and
        cross-validated error percentiles, time by stage, notes."""
        fit, posterior = self._report_sources()
        return format_text(report_sections(fit, posterior, correl_threshold=correl_threshold))

    def _repr_html_(self) -> str:
        fit, posterior = self._report_sources()
        return format_html(report_sections(fit, posterior))

    def __repr__(self) -> str:
        return short_text(type(self).__name__, self._report_sources()[0])
