"""Bench section ``tradeoff``: error against run time of the whole IM model (Irawan & Marschner 2012,
eq. 10 for both yarn types, phase function eq. 7, diffuse term) per preset and quadrature rule.

Per preset: the time of the 1,575-direction set against the median / 80th-percentile relative error of the
model value against the converged reference (:func:`clothlab.studies.quad_reference.converged_reference`), for
every rule of :data:`TRADEOFF_RULES`; a log-log plot with the Pareto front; and the answer to "does a rule
reach 10x lower p80 than trapezoid-11 at no more than its run time?", with a paragraph generated from the
numbers explaining why not where none does.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from clothlab.errors import GeometryWarning
from clothlab.studies.data import paper_directions
from clothlab.studies.quad_reference import converged_reference
from clothlab.studies.quadrature_accuracy import RULES
from clothlab.studies.timing import paired_timings

TRADEOFF_RULES = RULES
"""Rules of the error-against-time study (the former experimental ``split`` rule, breakpoints inside the
compiled loop, became the ``support`` rule)."""


def model_value(model, wi, wo, params, coefficients, scale, *, cold=False):
    """The whole IM model (eq. 10 for both yarn types, phase function eq. 7, diffuse term), (N, C):
    kd / pi + sum_j ks_j f_c I_j / scale_j, with f_c I_j the raw components of ``model`` (an IrawanModel with the
    rule under study).  Its memo of integrals is cleared (every call integrates); ``cold`` also forgets the
    direction set's parameter-free terms (filament moments, staple lit pieces), which a fit keeps."""
    from clothlab.studies.timing import clear_memo

    if cold:
        model._directions = None
    clear_memo(model)
    comps = model.components(wi, wo, params, normalised=False, warn=False)
    total = comps["diffuse"][:, None] * np.asarray(coefficients["kd"])[None, :]
    for kind in ("warp", "weft"):
        total = total + (comps[f"specular_{kind}"] / scale[kind])[:, None] * \
            np.asarray(coefficients[f"ks_{kind}"])[None, :]
    return total


def pareto_front(times, errors) -> list[int]:
    """Indices of the points no other point beats in both time and error, sorted by time."""
    order = np.lexsort((errors, times))
    front, best = [], math.inf
    for i in order:
        if errors[i] < best:
            front.append(int(i))
            best = errors[i]
    return front


def tradeoff_study(quick: bool, figures_dir=None, fabrics=None, n_reference=None, repeats=None) -> dict:
    """Error against run time of the whole model per preset (see the module docstring).

    The time is for the full 1,575-direction set as a fit evaluates it (the model's parameter-free terms of the
    direction set kept, the integrals recomputed): each rule's fastest of many calls, timed in strict alternation
    with trapezoid-11 (:func:`clothlab.studies.timing.paired_timings`, ``repeats`` rounds); ``time_ratio`` is
    the ratio to trapezoid-11 from that alternation, which the verdict uses (p80_ratio <= 0.1 and
    time_ratio <= 1).  ``cold_time_ratio``: the same with those terms computed in every call (a one-off
    evaluation at new directions).  Errors are relative errors of the model value (all channels) against the converged
    reference on ``n_reference`` seeded directions (all 1,575 in the full run).  The specular normalisations
    scale_j are fixed (pi x the mean reference f_c I_j over the set) so that only the quadrature differs
    between rules."""
    from clothlab.models.irawan.model import PSI_FILAMENT_THRESHOLD, IrawanModel, Quadrature
    from clothlab.simulate.examples import YARN_COLOURS
    from clothlab.weave.presets import PRESET_NAMES, get_preset

    fabrics = tuple(fabrics or PRESET_NAMES)
    repeats = repeats or (5 if quick else 9)
    wi, wo = paper_directions()
    n_reference = n_reference or (200 if quick else len(wi))
    subset = np.sort(np.random.default_rng(7).choice(len(wi), min(n_reference, len(wi)), replace=False))
    out = {"rules": [f"{r}-{n}" for r, n in TRADEOFF_RULES], "n_reference": len(subset), "fabrics": {}}
    for name in fabrics:
        p = IrawanModel(get_preset(name)).default_parameters()
        coef = {k: np.asarray(v) for k, v in YARN_COLOURS[name].items()}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", GeometryWarning)
            refs, quad_warnings = {}, {}
            for kind in ("warp", "weft"):
                refs[kind], quad_warnings[kind] = converged_reference(wi[subset], wo[subset], p, kind)
            scale = {kind: np.pi * float(refs[kind].mean()) for kind in refs}
            total = np.asarray(coef["kd"])[None, :] / np.pi + sum(
                (refs[k] / scale[k])[:, None] * np.asarray(coef[f"ks_{k}"])[None, :] for k in refs)
            rows, runs, cold_runs = [], [], []
            for rule, nodes in TRADEOFF_RULES:
                model = IrawanModel(get_preset(name), Quadrature(rule, nodes))
                got = model_value(model, wi[subset], wo[subset], p, coef, scale)  # also compiles
                model_value(model, wi, wo, p, coef, scale)
                runs.append(lambda m=model, p=p, c=coef, s=scale: model_value(m, wi, wo, p, c, s))
                cold_runs.append(lambda m=model, p=p, c=coef, s=scale: model_value(m, wi, wo, p, c, s, cold=True))
                rel = (np.abs(got - total) / total).ravel()
                rows.append({"rule": rule, "nodes": nodes, "p50": float(np.median(rel)),
                             "p80": float(np.percentile(rel, 80)), "max": float(rel.max())})
            i_base = TRADEOFF_RULES.index(("trapezoid", 11))
            _, timed = paired_timings(runs[i_base], runs, repeats)
            for r, (seconds, ratio) in zip(rows, timed, strict=True):
                r["seconds_1575"], r["time_ratio"] = seconds, ratio
            _, timed = paired_timings(cold_runs[i_base], cold_runs, max(2, repeats // 3))
            for r, (seconds, ratio) in zip(rows, timed, strict=True):
                r["cold_seconds_1575"], r["cold_time_ratio"] = seconds, ratio
            pieces = _staple_pieces(wi, wo, p)
        times = np.array([r["seconds_1575"] for r in rows])
        front = pareto_front(times, np.array([r["p80"] for r in rows]))
        base = rows[i_base]
        for i, r in enumerate(rows):
            r["pareto"] = i in front
            r["p80_ratio"] = r["p80"] / base["p80"]
        winners = [f"{r['rule']}-{r['nodes']}" for r in rows if r["p80_ratio"] <= 0.1 and r["time_ratio"] <= 1.0]
        best_10x = min((r for r in rows if r["p80_ratio"] <= 0.1), key=lambda r: r["time_ratio"], default=None)
        out["fabrics"][name] = {
            "staple": [abs(math.radians(p[f"{k}.psi"])) >= PSI_FILAMENT_THRESHOLD for k in ("warp", "weft")],
            "rows": rows, "fastest_time_ratio": float(min(r["time_ratio"] for r in rows)), "staple_pieces": pieces,
            "quad_warnings": quad_warnings, "trapezoid11": {"p80": base["p80"], "seconds_1575": base["seconds_1575"]},
            "claim_rules": winners,
            "cheapest_10x": None if best_10x is None else {
                "rule": f"{best_10x['rule']}-{best_10x['nodes']}", "p80": best_10x["p80"],
                "seconds_1575": best_10x["seconds_1575"], "time_ratio": best_10x["time_ratio"]}}
    out["claim_holds"] = {name: bool(f["claim_rules"]) for name, f in out["fabrics"].items()}
    out["explanation"] = explain_tradeoff(out)
    if figures_dir is not None:
        out["figure"] = str(plot_tradeoff(out, Path(figures_dir) / "tradeoff.png"))
    return out


def _staple_pieces(wi, wo, params) -> dict:
    """Per staple yarn type: the lit pieces (those the ``support`` rule integrates; the integrand is 0 on the
    others) into which its breakpoints cut [-umax, umax] on these directions (front-facing pairs; "max" and
    "mean" over the directions), from the same breakpoints (:func:`clothlab.models.irawan.yarn.staple_breaks`:
    support ends, visibility cuts, zeros of eq. 8's cosines)."""
    from clothlab.frames import to_yarn_frame
    from clothlab.models.irawan.model import PSI_FILAMENT_THRESHOLD
    from clothlab.models.irawan.yarn import staple_breaks

    out = {}
    for kind in ("warp", "weft"):
        psi, umax = math.radians(params[f"{kind}.psi"]), math.radians(params[f"{kind}.umax"])
        if abs(psi) < PSI_FILAMENT_THRESHOLD:
            continue
        lw, lo = to_yarn_frame(wi, kind), to_yarn_frame(wo, kind)
        front = (lw[:, 2] > 0) & (lo[:, 2] > 0)
        _, lit = staple_breaks(lw[front], lo[front], psi, umax)
        out[kind] = {"max": int(lit.max(initial=0)), "mean": float(lit.mean()) if lit.size else 0.0}
    return out


def _range(values, fmt: str, suffix: str = "") -> str:
    lo, hi = min(values), max(values)
    return f"{lo:{fmt}}{suffix}" if f"{lo:{fmt}}" == f"{hi:{fmt}}" else f"{lo:{fmt}}-{hi:{fmt}}{suffix}"


def _names(rows) -> str:
    return ", ".join(sorted({f"{r['rule']}-{r['nodes']}" for r in rows}))


def _cheapest_10x(rows: dict, rules=None):
    """The fastest row (by time ratio to trapezoid-11) with p80 <= trapezoid-11's / 10 (among ``rules``
    families), or None."""
    return min((r for r in rows.values() if r["p80_ratio"] <= 0.1 and (rules is None or r["rule"] in rules)),
               key=lambda r: r["time_ratio"], default=None)


def _on(found, n: int) -> str:
    return "" if len(found) == n else f" (on {len(found)} of these {n} fabrics; none on the others)"


def explain_tradeoff(result: dict) -> str | None:
    """One paragraph, generated from the measured numbers, on why no rule reaches 10x lower p80 than
    trapezoid-11 at no more than its run time on the fabrics where none does (None when every fabric has one).

    Fabrics are grouped by yarn type (filament: both yarns on the filament path; staple: both staple).  Per group:
    the cheapest rule reaching 10x and its time ratio; the share of trapezoid-11's time spent outside the yarn
    integrals (estimated by the fastest rule's time: phase function, frames, diffuse term), which leaves the
    integrals a small budget; the support rule's cost; for staple yarns its pieces per direction (nodes =
    pieces x n against 11) and what computing the breakpoints in numpy costs (support-n minus split-n, the same
    pieces with the breakpoints found inside the compiled loop); and the fixed-node rules' first 10x rule."""
    failing = {n: f for n, f in result["fabrics"].items() if not f["claim_rules"]}
    if not failing:
        return None
    groups: dict[str, list] = {}
    for name, f in failing.items():
        label = "staple" if all(f["staple"]) else "filament" if not any(f["staple"]) else "mixed staple/filament"
        groups.setdefault(label, []).append(name)
    parts = [f"No rule reaches 10x lower 80th-percentile error than trapezoid-11 at no more than its run time on "
             f"{len(failing)} of {len(result['fabrics'])} fabrics ({', '.join(failing)})."]
    for label, names in groups.items():
        fabs = [failing[n] for n in names]
        n = len(fabs)
        rows = [{f"{r['rule']}-{r['nodes']}": r for r in f["rows"]} for f in fabs]
        base_ms = [1e3 * f["trapezoid11"]["seconds_1575"] for f in fabs]
        fixed = [min(f["fastest_time_ratio"], 1.0) for f in fabs]
        text = (f"For the {label}-yarn fabrics ({', '.join(names)}) trapezoid-11 takes {_range(base_ms, '.2f')} ms "
                f"per 1,575 directions at p80 {_range([f['trapezoid11']['p80'] for f in fabs], '.1e')}; ")
        found = [c for c in (_cheapest_10x(rs) for rs in rows) if c is not None]
        if not found:
            text += "no rule of the study reaches 10x lower p80 at any cost. "
        else:
            text += (f"the cheapest rules with 10x lower p80 are {_names(found)} at "
                     f"{_range([c['time_ratio'] for c in found], '.2f', 'x')} its time{_on(found, n)}. ")
        text += (f"{_range([100 * x for x in fixed], '.0f', ' %')} of trapezoid-11's time is spent outside the yarn "
                 "integrals (the fastest rule's time: phase function, frame changes, diffuse term), so a rule may "
                 "spend at most the remaining "
                 f"{_range([b * (1 - x) for b, x in zip(base_ms, fixed, strict=True)], '.2f')} ms on the integrals; ")
        pairs = [(s, f) for s, f in zip((_cheapest_10x(rs, ("support",)) for rs in rows), fabs, strict=True)
                 if s is not None]
        if label == "filament":
            if pairs:
                extra = [1e3 * (s["time_ratio"] - 1.0) * f["trapezoid11"]["seconds_1575"] for s, f in pairs]
                sup = [s for s, _ in pairs]
                text += (f"the support rule (Gauss-Legendre on the arc where both clamped cosines of eq. 8 are "
                         f"positive, found in closed form per direction) reaches 10x with "
                         f"{_range([s['nodes'] for s in sup], 'd')} nodes (p80 "
                         f"{_range([s['p80_ratio'] for s in sup], '.2g', 'x')} trapezoid-11's) but takes "
                         f"{_range([s['time_ratio'] for s in sup], '.2f', 'x')} the time{_on(sup, n)} "
                         f"({_range(extra, '.2f')} ms more per 1,575 directions; the arc itself is found once per "
                         "direction set, with the filament moments).")
            else:
                text += "no support rule of the study reaches 10x."
        else:
            pieces = [max((v["max"] for v in f["staple_pieces"].values()), default=0) for f in fabs]
            s4 = [(rs["support-4"], rs.get("split-4"), q, f) for rs, q, f in zip(rows, pieces, fabs, strict=True)
                  if "support-4" in rs and q]
            if s4:
                text += (f"the support split leaves up to {_range([q for _, _, q, _ in s4], 'd')} pieces per "
                         "direction on which the integrand is not 0 (cut at the support ends, the visibility cuts and "
                         "the zeros of eq. 8's cosines; the others are skipped), so support-4 evaluates "
                         f"{_range([4 * q for _, _, q, _ in s4], 'd')} integrand nodes at most against "
                         "trapezoid-11's 11 and "
                         f"takes {_range([a['time_ratio'] for a, *_ in s4], '.1f', 'x')} its time at p80 "
                         f"{_range([a['p80_ratio'] for a, *_ in s4], '.2g', 'x')} trapezoid-11's")
                split = [(a, b, f) for a, b, _, f in s4 if b is not None]
                if split:
                    numpy_ms = [1e3 * (a["time_ratio"] - b["time_ratio"]) * f["trapezoid11"]["seconds_1575"]
                                for a, b, f in split]
                    text += (f" ({_range(numpy_ms, '.2f')} ms of it is computing and sorting 20 candidate "
                             "breakpoints per direction in numpy: split-4, the same pieces found inside the compiled "
                             f"loop, takes {_range([b['time_ratio'] for _, b, _ in split], '.1f', 'x')})")
                text += "; "
            if pairs:
                sup = [s for s, _ in pairs]
                text += (f"the first support rule at 10x is {_names(sup)} at "
                         f"{_range([s['time_ratio'] for s in sup], '.1f', 'x')} the time{_on(sup, n)}; ")
            else:
                text += "no support rule of the study reaches 10x; "
            fixed_node = [c for c in (_cheapest_10x(rs, ("trapezoid", "gauss")) for rs in rows) if c is not None]
            if fixed_node:
                text += (f"the fixed-node rules need {_names(fixed_node)} "
                         f"({_range([r['nodes'] / 11 for r in fixed_node], '.1f', 'x')} the nodes) for 10x, at "
                         f"{_range([r['time_ratio'] for r in fixed_node], '.1f', 'x')} the time{_on(fixed_node, n)}, "
                         "because the staple integrand has kinks and jumps inside [-umax, umax] (support ends, "
                         "visibility cuts) on which fixed nodes converge only slowly.")
            else:
                text += "no fixed-node rule of the study reaches 10x."
        parts.append(text)
    return " ".join(parts)


def plot_tradeoff(result: dict, path: Path) -> Path:
    """Log-log plot per fabric: time of the 1,575-direction set vs p80 (filled) / p50 (open) error;
    the Pareto front (p80) is the black line, trapezoid-11 is circled."""
    from matplotlib.figure import Figure

    names = list(result["fabrics"])
    cols = min(3, len(names))
    rows_ = math.ceil(len(names) / cols)
    fig = Figure(figsize=(5.2 * cols, 4.2 * rows_), layout="constrained")
    colours = {"trapezoid": "tab:blue", "gauss": "tab:orange", "support": "tab:green", "adaptive": "tab:red",
               "split": "tab:purple"}
    for k, name in enumerate(names):
        ax = fig.add_subplot(rows_, cols, k + 1)
        rows = result["fabrics"][name]["rows"]
        for rule, colour in colours.items():
            sel = [r for r in rows if r["rule"] == rule]
            if not sel:
                continue
            t = [1e3 * r["seconds_1575"] for r in sel]
            ax.loglog(t, [r["p80"] for r in sel], "o-", color=colour, label=f"{rule} p80", ms=4, lw=0.8)
            ax.loglog(t, [r["p50"] for r in sel], "o", mfc="none", color=colour, ms=4)
            for r, x in zip(sel, t, strict=True):
                ax.annotate(str(r["nodes"]), (x, r["p80"]), fontsize=6, xytext=(2, 2), textcoords="offset points")
        front = sorted((r for r in rows if r["pareto"]), key=lambda r: r["seconds_1575"])
        ax.loglog([1e3 * r["seconds_1575"] for r in front], [r["p80"] for r in front], "k-", lw=2, alpha=0.4,
                  label="Pareto front (p80)")
        base = result["fabrics"][name]["trapezoid11"]
        ax.loglog([1e3 * base["seconds_1575"]], [base["p80"]], "ko", mfc="none", ms=11, label="trapezoid-11")
        ax.axhline(0.1 * base["p80"], color="k", ls=":", lw=0.8)
        ax.axvline(1e3 * base["seconds_1575"], color="k", ls=":", lw=0.8)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("time of 1,575 directions [ms]")
        ax.set_ylabel("relative error of the model value")
        if k == 0:
            ax.legend(fontsize=7)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def run(context) -> dict:
    return tradeoff_study(context.quick, figures_dir=context.figures_dir)


def lines(result: dict) -> list[str]:
    out = [f"== error against run time: whole IM model, 1,575 directions, error on {result['n_reference']} "
           "directions vs converged reference (* = Pareto front; ms and x t11: a fit's evaluation, the direction "
           "set's parameter-free terms kept; cold x: computed in every call) =="]
    for name, f in result["fabrics"].items():
        kinds = "/".join("staple" if s else "filament" for s in f["staple"])
        out += ["", f"  {name} (warp/weft {kinds}; quad IntegrationWarnings replaced by adaptive: "
                f"warp {f['quad_warnings']['warp']}, weft {f['quad_warnings']['weft']})",
                f"  {'rule':10s} {'n':>3s} {'ms/1575':>9s} {'x t11':>7s} {'cold x':>7s} {'median':>10s} {'p80':>10s} "
                f"{'max':>10s}"]
        for r in f["rows"]:
            cold = f"{r['cold_time_ratio']:7.2f}" if "cold_time_ratio" in r else f"{'-':>7s}"
            out.append(f"  {r['rule']:10s} {r['nodes']:3d} {1e3 * r['seconds_1575']:9.2f} {r['time_ratio']:7.2f} "
                       f"{cold} {r['p50']:10.2e} {r['p80']:10.2e} {r['max']:10.2e} {'*' if r['pareto'] else ''}")
    out += ["", "  claim: a rule with p80 <= trapezoid-11's / 10 at no more than trapezoid-11's run time (x t11: "
            "time ratio from calls alternating with trapezoid-11's)"]
    for name, f in result["fabrics"].items():
        base, c = f["trapezoid11"], f["cheapest_10x"]
        cheapest = ("no rule reaches 10x" if c is None else
                    f"cheapest 10x: {c['rule']} p80 {c['p80']:.2e} at {1e3 * c['seconds_1575']:.2f} ms "
                    f"({c['time_ratio']:.2f}x the time)")
        out.append(f"  {name:18s} {'YES' if f['claim_rules'] else 'NO ':3s} trapezoid-11 p80 {base['p80']:.2e} at "
                   f"{1e3 * base['seconds_1575']:.2f} ms; {cheapest}; qualifying: {', '.join(f['claim_rules']) or '-'}")
    if result.get("explanation"):
        import textwrap

        out += ["", "  why no rule qualifies (from the numbers above):",
                textwrap.fill(result["explanation"], width=116, initial_indent="  ", subsequent_indent="  ")]
    if "figure" in result:
        out.append(f"  plot: {result['figure']}")
    return out
