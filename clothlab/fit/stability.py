"""Selection stability: how often each weave, weave family, kind, loss and orientation range wins when the rows
change (issue 28 build item 3; docs/select.md).

The selection is repeated on ``B`` seeded subsamples of the rows (each without replacement, a fraction
:data:`SUBSAMPLE` of them - subsampling rather than the bootstrap, whose duplicated rows would sit in the
training and the held-out part of the same inner CV fold; Politis, Romano & Wolf 1999, "Subsampling", ch. 2),
every candidate fitted and ranked by its inner CV on the subsample alone.  The winners are tallied by weave,
by weave family (plain / twill / satin: :func:`weave_family`), by kind (the diffuse option), by loss and by
orientation range (:data:`ORIENTATION_BINS` equal ranges of the period).  The outer-fold winners of a nested
CV (:mod:`clothlab.fit.nested`) are tallied the same way.

Verdict: an aspect is **not determined** by these data when no value of it wins a clear majority, more than
:data:`MAJORITY` of the repetitions - the selection's counterpart of the parameter flags.

Each (subsample, candidate) pair is an independent task, so a runner distributes the list and the tallies are
the in-process loop's bit for bit.
"""

from __future__ import annotations

import time

import numpy as np

SUBSAMPLE = 0.8
MAJORITY = 0.5
ORIENTATION_BINS = 6
ASPECTS = ("weave", "weave family", "kind", "loss", "orientation range")
#: The weave family (Irawan & Marschner 2012, sec. 4: "plain weave, twill, and satin") of each shipped preset, as
#: the paper describes the fabric it measured (sec. 8, fabrics (1)-(6)); a ``pattern:<name>`` weave's family is
#: its name's first word (clothlab.weave.patterns); any other weave (a .wv file) is "other".
PRESET_FAMILIES = {"cotton-twill": "twill", "cotton-denim": "twill", "wool-gabardine": "twill",
                   "polyester-lining": "plain", "silk-charmeuse": "satin", "silk-shantung": "plain"}


def weave_family(weave: str | None) -> str | None:
    """plain / twill / satin of a candidate's weave (``preset:<name>`` or ``pattern:<name>``), else "other"."""
    if weave is None:
        return None
    text = str(weave)
    if text.startswith("preset:"):
        return PRESET_FAMILIES.get(text[len("preset:"):], "other")
    if text.startswith("pattern:"):
        return text[len("pattern:"):].split("-")[0]
    return "other"


def orientation_range(orientation, period: float) -> str | None:
    """The range of width period / :data:`ORIENTATION_BINS` (deg) holding ``orientation`` wrapped into
    [-period/2, period/2), e.g. "-30..0"; None when the candidate freed none."""
    if orientation is None or not period:
        return None
    half = 0.5 * period
    wrapped = (float(orientation) + half) % period - half
    width = period / ORIENTATION_BINS
    lo = -half + width * int((wrapped + half) // width)
    return f"{lo:g}..{lo + width:g}"


def tally(rows: list[dict], periods: dict | None = None) -> dict:
    """{aspect: {value: count}} of winner table rows (``weave``, ``kind``, ``loss``, ``orientation``);
    ``periods``: kind -> orientation period (deg)."""
    out = {a: {} for a in ASPECTS}
    for row in rows:
        values = {"weave": row.get("weave"), "weave family": weave_family(row.get("weave")), "kind": row.get("kind"),
                  "loss": _loss(row),
                  "orientation range": orientation_range(row.get("orientation"),
                                                         (periods or {}).get(row.get("kind"), 0.0))}
        for aspect, value in values.items():
            if value is not None:
                out[aspect][str(value)] = out[aspect].get(str(value), 0) + 1
    return out


def _loss(row: dict) -> str | None:
    loss = row.get("loss")
    if loss in (None, "squared", "l1"):
        return loss
    return f"{loss} {row.get('loss_scale'):g}" if row.get("loss_scale") is not None else loss


def verdict(counts: dict, n: int) -> dict:
    """{aspect: sentence} - "<value> wins k of n" or "NOT DETERMINED: ..." when no value wins more than
    :data:`MAJORITY` of ``n``."""
    out = {}
    for aspect, c in counts.items():
        if not c:
            continue
        best, k = max(c.items(), key=lambda t: t[1])
        listed = ", ".join(f"{v} {m}/{n}" for v, m in sorted(c.items(), key=lambda t: -t[1]))
        out[aspect] = (f"{best} wins {k} of {n}" if k > MAJORITY * n else
                       f"NOT DETERMINED: no {aspect} wins a clear majority ({listed})")
    return out


def subsample_masks(n_rows: int, repeats: int, seed: int, fraction: float = SUBSAMPLE) -> list[np.ndarray]:
    """``repeats`` boolean masks, each choosing round(fraction n_rows) rows without replacement (seeded)."""
    rng = np.random.default_rng(seed)
    size = max(2, int(round(fraction * n_rows)))
    out = []
    for _ in range(repeats):
        mask = np.zeros(n_rows, dtype=bool)
        mask[rng.choice(n_rows, size, replace=False)] = True
        out.append(mask)
    return out


def stability(measurement, repeats: int, *, seed: int, candidate_list, make_task, run_task, rank, runner=None,
              periods=None, nested: dict | None = None) -> dict:
    """The stability of a selection (module docstring): ``make_task(b, candidate, rows)`` fits a candidate on
    subsample ``b``'s rows; ``rank`` orders a subsample's results; ``nested``: a nested-CV result whose
    outer-fold winners are tallied too.  Returns the fit.json ``selection.stability`` mapping."""
    from clothlab.fit.nested import run_tasks

    started = time.perf_counter()
    masks = subsample_masks(measurement.n, repeats, seed)
    tasks = [make_task(b, c, measurement.subset(mask)) for b, mask in enumerate(masks) for c in candidate_list]
    names = [f"subsample {b + 1} {c.name}" for b in range(repeats) for c in candidate_list]
    results = run_tasks(tasks, run_task, runner, desc="select: stability subsamples", names=names,
                        what="stability candidate fits")
    per = len(candidate_list)
    winners = [rank(results[b * per:(b + 1) * per])[0].row for b in range(repeats)]
    counts = tally(winners, periods)
    out = {"repeats": repeats, "fraction": SUBSAMPLE, "seed": int(seed),
           "rule": (f"the selection repeated on {repeats} subsamples of {100 * SUBSAMPLE:g} % of the rows (seeded, "
                    f"without replacement); an aspect is not determined when no value wins more than "
                    f"{100 * MAJORITY:g} % of them"),
           "winners": [w.get("candidate") for w in winners], "counts": counts, "verdict": verdict(counts, repeats),
           "fits": len(tasks), "wall_time_s": time.perf_counter() - started}
    if nested and nested.get("folds"):
        rows = [{"weave": f.get("weave"), "kind": f.get("kind"), "loss": f.get("loss"),
                 "loss_scale": f.get("loss_scale"), "orientation": f.get("orientation")} for f in nested["folds"]]
        out["nested_counts"] = tally(rows, periods)
        out["nested_verdict"] = verdict(out["nested_counts"], len(rows))
    return out


def stability_lines(stab: dict) -> list[str]:
    """The stability result as text lines (printed summary, selection.md)."""
    if not stab:
        return []
    lines = [f"Selection stability ({stab['repeats']} subsamples of {100 * stab['fraction']:g} % of the rows, "
             f"{stab['fits']} candidate fits, {stab['wall_time_s']:.0f} s):"]
    lines += [f"  {aspect}: {text}" for aspect, text in stab["verdict"].items()]
    for aspect, text in (stab.get("nested_verdict") or {}).items():
        lines.append(f"  {aspect} (outer folds of the nested CV): {text}")
    return lines


__all__ = ["ASPECTS", "PRESET_FAMILIES", "weave_family",
           "orientation_range", "stability", "stability_lines", "subsample_masks", "tally", "verdict"]
