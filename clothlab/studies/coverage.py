"""Bench section ``coverage``: coverage of the 95 % posterior intervals over the six noisy simulated example
sets (six free parameters each; truth = the generating values), criterion >= 90 % (:data:`clothlab.studies.
posterior.COVERAGE_TARGET`).

Full run: the example fits' own posteriors (``fits/<fabric>/posterior.json`` of the data directory, written by
``clothlab fit measurements/*/fabric.yaml``: the fabric.yaml optimum, then emcee to the tau rule), read by
:func:`saved_coverage` - sampling them again would take ~45 min.  Quick run, and a full run without those
saved posteriors (no data directory, or none under it; the figures say so): the live reduced study
(:func:`clothlab.studies.posterior.coverage_study`; two starts, 3,000 evaluations in all, and a fixed 400-step
chain of 16 walkers per set: unconverged, indicative only).
"""

from __future__ import annotations

import json
from pathlib import Path

from clothlab.studies.data import StudyData, study_data
from clothlab.studies.posterior import COVERAGE_FABRICS, COVERAGE_TARGET, coverage_study

REDUCED = {"walkers": 16, "steps": 400, "max_steps": 400, "optimizer": {"max_evals": 3000, "starts": 2}}
"""Settings of the live reduced study."""
FULL = {"walkers": 32, "steps": 1000, "max_steps": 20_000}
"""Settings of the live full study (``rerun``): 32 walkers, at least 1,000 steps, the default stopping rule, at
most 20,000."""


def saved_coverage(fits_dir: Path, fabrics) -> dict | None:
    """The coverage study as the example fits ran it, from ``fits_dir/<fabric>/posterior.json`` and ``fit.json``
    of each noisy set, or None when one is missing.  Same shape as :func:`coverage_study`."""
    out, settings = {}, []
    for name in fabrics:
        path, fit_path = fits_dir / name / "posterior.json", fits_dir / name / "fit.json"
        if not (path.is_file() and fit_path.is_file()):
            return None
        post, fit = json.loads(path.read_text()), json.loads(fit_path.read_text())
        conv = post["convergence"]
        covered = {n: bool(e.get("truth_in_95")) for n, e in post["parameters"].items()}
        settings.append(fit["config"]["fit"]["posterior"])  # walkers, steps, max_steps as the fit ran them
        out[name] = {"covered": covered, "n_covered": sum(covered.values()), "n_free": len(covered),
                     "converged": conv["converged"], "steps": conv["steps"], "max_tau": max(conv["tau"].values()),
                     "fit_wall_time_s": (fit.get("timings") or {}).get("optimisation_s", float("nan")),
                     "wall_time_s": post["wall_time_s"]}
    total = sum(r["n_free"] for r in out.values())
    hit = sum(r["n_covered"] for r in out.values())
    return {"fabrics": out, "covered": hit, "total": total, "fraction": hit / total, "target": COVERAGE_TARGET,
            "passed": hit / total >= COVERAGE_TARGET, "source": "saved posteriors fits/<fabric>/posterior.json",
            "settings": {"walkers": min(c["walkers"] for c in settings), "steps": min(c["steps"] for c in settings),
                         "max_steps": max(c["max_steps"] for c in settings)}}


def coverage(quick: bool, *, data: StudyData | None = None, fabrics=None, rerun: bool = False,
             **overrides) -> dict:
    """The coverage figures (see the module docstring): saved posteriors in a full run when all are there and
    neither ``rerun`` nor ``overrides`` (coverage_study settings) is given; else the live study - reduced when
    quick or when the saved posteriors are missing, full (:data:`FULL`) with ``rerun``."""
    fabrics = tuple(fabrics or COVERAGE_FABRICS)
    with study_data(data) as d:
        note = None
        if not quick and not rerun and not overrides:
            saved = saved_coverage(d.fits, fabrics) if d.fits is not None else None
            if saved is not None:
                return {**saved, "quick": False, "reduced": False, "note": None}
            note = ("no saved example posteriors (fits/<fabric>/posterior.json under --data DIR): the live reduced "
                    "study ran instead (indicative only)")
        full = rerun and not quick
        settings = {**(FULL if full else REDUCED), **overrides}
        return {**coverage_study(fabrics, data=d, **settings), "quick": quick, "reduced": not full, "note": note}


def run(context) -> dict:
    return coverage(context.quick, data=context.data)


def lines(c: dict) -> list[str]:
    s = c["settings"]
    steps = (f"{s['steps']} steps" if s["steps"] == s["max_steps"] else
             f"{s['steps']:,d} to {s['max_steps']:,d} steps by the stopping rule")
    extra = "; reduced: indicative only" if c.get("reduced") else ""
    if c.get("source"):
        extra += f"; from the {c['source']}"
    out = [f"== coverage of the 95 % posterior intervals (noisy simulated sets, six free parameters each, truth = "
           f"generating values; {s['walkers']} walkers, {steps}{extra}) ==",
           f"  {'fabric':18s} {'covered':>8s} {'conv.':>5s} {'steps':>6s} {'max tau':>8s} {'fit s':>6s} "
           f"{'posterior s':>11s}  outside the 95 % interval"]
    for name, r in c["fabrics"].items():
        missed = [n for n, hit in r["covered"].items() if not hit]
        out.append(f"  {name:18s} {r['n_covered']:4d}/{r['n_free']:<3d} {'yes' if r['converged'] else 'no':>5s} "
                   f"{r['steps']:6d} {r['max_tau']:8.1f} {r['fit_wall_time_s']:6.1f} {r['wall_time_s']:11.1f}  "
                   f"{', '.join(missed) or '-'}")
    out.append(f"  overall: {c['covered']}/{c['total']} free parameters covered ({100 * c['fraction']:.1f} %); "
               f"criterion >= {100 * c['target']:.0f} %: {'PASS' if c['passed'] else 'FAIL'}")
    if c.get("note"):
        out.append(f"  note: {c['note']}")
    return out
