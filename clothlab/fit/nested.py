"""Nested cross-validation of model selection (issue 28 build item 2; docs/select.md).

The cross-validated error of the selection's winner (its row's ``cv_*``) is the minimum over every candidate
scored on the same folds: the selection chose it *because* it was low there, so it is an optimistic estimate
of the error of the selected model on new directions (Varma & Simon 2006, "Bias in error estimation when using
cross-validation for model selection"; Cawley & Talbot 2010, JMLR 11, sec. 5).  Nested CV removes that bias:
the rows are split into K outer folds (:func:`clothlab.fit.crossval.fold_labels`, the fit's scheme and seed);
for each outer fold the **whole selection** - every candidate fitted with its reduced budget and ranked by its
own inner cross-validation, all on the outer-training rows only - picks a winner, and that winner's fit (the
candidate's optimum on the outer-training rows) predicts the outer held-out rows.  Every row is held out once;
the pooled outer held-out relative errors are the figure reported for the selected model.

Reported next to it (the fit.json ``selection.nested`` mapping, :func:`nested_summary`):

* ``held_out``: pooled outer held-out percentiles and mean (the selected model's error on unseen directions);
* ``selection_score``: the inner CV figure of the selection on all rows (the winner's row: what the ranking
  minimised, *not* an estimate of new-data error), and per outer fold the winner's inner CV figure;
* ``folds``: each outer fold's winner, its inner score and its held-out figures; ``winners_agree`` and a
  sentence saying whether the outer folds chose the same candidate (or weave and kind) as the full selection.

What is estimated is the error of the *procedure* "select with these settings, then use the winner's
candidate fit": the saved winner is refitted on all rows with the full budget, which can only fit the rows
better, so the nested figure is, if anything, conservative for it.

Each (outer fold, candidate) pair is an independent :class:`clothlab.fit.select.CandidateTask` (its
outer-training rows in ``measurement``, its outer held-out rows in ``held_out``), so a runner distributes the
K x candidates list and the result is the in-process loop's bit for bit.
"""

from __future__ import annotations

import time

import numpy as np

from clothlab.fit.metrics import error_percentiles
from clothlab.progress import Progress, get_logger

log = get_logger(__name__)

RULE = ("nested cross-validation: the whole selection (every candidate fitted and ranked by its inner "
        "cross-validation) repeated on the training rows of each outer fold; the outer fold's winner predicts "
        "its held-out rows; pooled over the outer folds")


def outer_labels(config, measurement, k: int):
    """(labels, scheme, reason): the outer folds, by the fit's own CV scheme and seed
    (``fit.cv_scheme``, ``fit.optimizer.seed``; :mod:`clothlab.fit.crossval`)."""
    from clothlab.fit.crossval import choose_scheme, fold_labels

    scheme, reason = choose_scheme(measurement, k, config.fit.cv_scheme)
    labels = fold_labels(measurement, k, config.fit.optimizer.seed, scheme)
    return labels, scheme, reason


def nested_tasks(measurement, labels, candidate_list, make_task) -> list:
    """The (outer fold, candidate) tasks, fold-major: ``make_task(fold, candidate, train, held_out)`` for every
    candidate (:func:`clothlab.fit.select.candidates`), fitted on the outer-training rows and predicting the
    outer held-out rows."""
    tasks = []
    for fold in range(int(labels.max()) + 1):
        test = labels == fold
        train, held = measurement.subset(~test), measurement.subset(test)
        tasks += [make_task(fold, c, train, held) for c in candidate_list]
    return tasks


def run_tasks(tasks, run_task, runner=None, desc="select: nested folds", *, names=None,
              what: str = "nested candidate fits") -> list:
    """Every task's result in task order (the in-process loop, or one runner task each, named by ``names``:
    by default each task's outer fold and candidate; ``what`` names the tasks in a failure's message)."""
    if runner is not None:
        from clothlab.parallel.runner import raise_failures

        if names is None:
            names = [f"outer fold {t.outer_fold + 1} {t.candidate.name}" for t in tasks]
        return raise_failures(runner.map(run_task, tasks, names=names, desc=desc), what)
    out = []
    with Progress(len(tasks), desc, unit="fit") as bar:
        for task in tasks:
            out.append(run_task(task))
            bar.update(1)
    return out


def _figures(summary: dict) -> dict:
    return {k: (None if v is None or not np.isfinite(v) else float(v)) for k, v in summary.items()
            if k != "n"} | {"n": int(summary.get("n", 0))}


def _score(row: dict) -> dict:
    return {"mean": row.get("cv_mean"), "p50": row.get("cv_p50"), "p80": row.get("cv_p80")}


def nested_cross_validation(config, measurement, k: int, *, candidate_list, make_task, run_task, rank,
                            runner=None, full_winner: dict | None = None, percentiles=None) -> dict:
    """The nested CV of a selection on ``measurement`` with ``k`` outer folds (module docstring): the
    ``candidate_list`` as tasks (``make_task``, :func:`nested_tasks`) run by ``run_task`` (a candidate fit:
    its result's ``row`` and ``held_out`` prediction) and ranked per fold by ``rank`` (the selection's own
    functions, :mod:`clothlab.fit.select`); ``full_winner``: the table row of the selection's winner on all
    rows (its inner CV figure is the selection score).  Returns the fit.json ``selection.nested`` mapping."""
    from clothlab.errors import ConfigError

    if k < 2:
        raise ConfigError(f"nested cross-validation needs at least 2 outer folds, got {k}", field="--nested")
    started = time.perf_counter()
    percentiles = tuple(percentiles or config.report.percentiles)
    labels, scheme, reason = outer_labels(config, measurement, k)
    tasks = nested_tasks(measurement, labels, candidate_list, make_task)
    results = run_tasks(tasks, run_task, runner)
    n_folds = int(labels.max()) + 1
    per_fold = len(tasks) // n_folds
    pooled = np.full(measurement.values.shape, np.nan)
    folds = []
    for fold in range(n_folds):
        ranked = rank(results[fold * per_fold:(fold + 1) * per_fold])
        best = ranked[0]
        test = labels == fold
        entry = {"fold": fold, "n_train": int((~test).sum()), "n_test": int(test.sum()),
                 "winner": best.row["candidate"], "weave": best.row["weave"], "kind": best.row["kind"],
                 "loss": best.row.get("loss"), "loss_scale": best.row.get("loss_scale"),
                 "orientation": best.row.get("orientation"),
                 "selection_score": _score(best.row), "runner_up": ranked[1].row["candidate"] if len(ranked) > 1
                 else None}
        if best.held_out is None:
            entry["held_out"] = None
            entry["note"] = f"no candidate could be fitted on this fold's training rows: {best.row['note']}"
        else:
            pooled[test] = best.held_out
            entry["held_out"] = _figures(error_percentiles(measurement.values[test], best.held_out,
                                                           percentiles)["overall"])
        folds.append(entry)
    covered = np.all(np.isfinite(pooled), axis=1)
    held = _figures(error_percentiles(measurement.values[covered], pooled[covered], percentiles)["overall"])
    winners = [f["winner"] for f in folds]
    out = {"k": n_folds, "seed": int(config.fit.optimizer.seed), "scheme": scheme, "scheme_reason": reason,
           "rule": RULE, "held_out": held, "rows_held_out": int(covered.sum()), "rows": int(measurement.n),
           "selection_score": _score(full_winner) if full_winner else None,
           "selection_score_rule": ("the inner cross-validated error of the selection's winner on all rows: the "
                                    "minimum the ranking chose, optimistic as an estimate of new-data error"),
           "folds": folds, "candidates_per_fold": per_fold, "fits": len(tasks),
           "wall_time_s": time.perf_counter() - started}
    out.update(agreement(winners, [(f["weave"], f["kind"]) for f in folds],
                         full_winner.get("candidate") if full_winner else None))
    return out


def agreement(winners, families, full=None) -> dict:
    """``winners_agree`` (every outer fold chose the same candidate) and a sentence saying so, naming how many
    folds chose which candidate and whether they agree on weave and kind at least."""
    counts: dict = {}
    for w in winners:
        counts[w] = counts.get(w, 0) + 1
    same = len(counts) == 1
    listed = ", ".join(f"{w} ({c} of {len(winners)})" for w, c in sorted(counts.items(), key=lambda t: -t[1]))
    if same:
        text = f"every outer fold chose the same candidate, {winners[0]}"
        if full is not None and winners[0] != full:
            text += f" (the selection on all rows chose {full})"
    else:
        weaves, kinds = {f[0] for f in families}, {f[1] for f in families}
        if len(weaves) == 1 and len(kinds) == 1:
            tail = "; all the same weave and kind (they differ in loss or orientation start)"
        else:
            undetermined = [w for w, n in (("weave", len(weaves)), ("kind", len(kinds))) if n > 1]
            tail = f"; the {' and the '.join(undetermined)} {'is' if len(undetermined) == 1 else 'are'} not " \
                   "determined by these data"
        text = f"the outer folds chose DIFFERENT candidates: {listed}{tail}"
    return {"winners": list(winners), "winners_agree": same, "winner_counts": counts, "agreement": text}


def nested_lines(nested: dict) -> list[str]:
    """The nested-CV result as text lines (printed summary, selection.md)."""
    if not nested:
        return []
    held, score = nested.get("held_out") or {}, nested.get("selection_score") or {}

    def pct(v):
        return "n/a" if v is None else f"{100.0 * v:.2f} %"

    lines = [f"Nested cross-validation ({nested['k']} outer folds, {nested['scheme']}; {nested['fits']} candidate "
             f"fits, {nested['wall_time_s']:.0f} s):",
             f"  selected model, outer held-out: median {pct(held.get('p50'))}, p80 {pct(held.get('p80'))}, "
             f"mean {pct(held.get('mean'))} ({nested['rows_held_out']} of {nested['rows']} rows)",
             f"  selection score (inner CV of the winner on all rows, optimistic): median {pct(score.get('p50'))}, "
             f"p80 {pct(score.get('p80'))}, mean {pct(score.get('mean'))}"]
    for f in nested["folds"]:
        h = f.get("held_out") or {}
        s = f.get("selection_score") or {}
        lines.append(f"  outer fold {f['fold'] + 1}: winner {f['winner']}, selection score p50 {pct(s.get('p50'))}"
                     f" / p80 {pct(s.get('p80'))}, outer held-out p50 {pct(h.get('p50'))} / p80 {pct(h.get('p80'))}")
    lines.append(f"  {nested['agreement']}")
    return lines


__all__ = ["RULE", "agreement", "nested_cross_validation", "nested_lines", "nested_tasks", "outer_labels"]
