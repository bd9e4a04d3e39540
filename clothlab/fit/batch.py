"""Batch fits: many fabric.yaml files (or every ``fabric.yaml`` below a directory), one task per fit on a
:class:`clothlab.parallel.Runner` (in-process, a Dask LocalCluster or an existing cluster; docs/parallel.md).

Each task runs :func:`clothlab.fit.runner.run_fit` and writes its own fit directory atomically under the
directory's lock (:func:`clothlab.atomic.prepare_result`, then :func:`clothlab.fit.store.save_fit`): a worker
killed mid-task leaves no half-written directory (its temporary is removed by the next writer), and the
retried task writes it whole.  Planning happens before any work: every configuration is loaded, every output
path checked, and a fit whose directory already holds the same configuration (``config_hash`` in fit.json,
:attr:`clothlab.config.schema.Config.hash`) is skipped as done unless ``force``; a directory holding another
configuration is refused without ``force`` (nothing overwritten).  A failed task is retried once and then
reported with its error in the summary; the other fits are kept.

Results do not depend on the runner: a task gets the same configuration (and seed) wherever it runs.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from clothlab.errors import ConfigError, InputError, ResultExistsError
from clothlab.parallel import InProcessRunner, TaskFailure
from clothlab.progress import get_logger

log = get_logger(__name__)

CONFIG_NAME = "fabric.yaml"
"""The file name collected below a directory argument (``clothlab fit measurements/``)."""


@dataclass(frozen=True)
class BatchItem:
    """One fit of a batch: its validated configuration, its fit directory, the ``fits_dir`` override and
    whether an existing directory may be replaced."""

    config: object
    dest: Path
    fits_dir: Path | None
    force: bool

    @property
    def name(self) -> str:
        return self.config.name


def expand_config_paths(paths) -> list[Path]:
    """The fabric.yaml files named by ``paths``: a file as given, a directory as every ``fabric.yaml`` below
    it (sorted); InputError for a directory holding none.  Duplicates are kept once, in order."""
    out: list[Path] = []
    for path in map(Path, paths):
        found = sorted(path.rglob(CONFIG_NAME)) if path.is_dir() else [path]
        if not found:
            raise InputError(f"no {CONFIG_NAME} below this directory", path=path)
        out += [p for p in found if p not in out]
    return out


def done_hash(dest: Path) -> str | None:
    """The ``config_hash`` recorded in ``dest``/fit.json, or None (no fit there, or unreadable)."""
    try:
        return json.loads((Path(dest) / "fit.json").read_text(encoding="utf-8")).get("config_hash")
    except (OSError, ValueError, AttributeError):
        return None


def plan_batch(configs, *, fits_dir=None, force: bool = False) -> tuple[list[BatchItem], list[dict]]:
    """(items to fit, rows of fits skipped as done) for validated ``configs``; checks every output path first.

    A directory holding the same configuration is done (skipped unless ``force``); one holding another
    configuration needs ``force`` (ResultExistsError naming it, before any work).  Two configurations with the
    same fit directory are refused (ConfigError)."""
    from clothlab.atomic import check_output_dir

    items, skipped, seen = [], [], {}
    for cfg in configs:
        dest = (Path(fits_dir) if fits_dir is not None else cfg.output.fits) / cfg.name
        key = dest.absolute()
        if key in seen:
            raise ConfigError(f"{seen[key]} and {cfg.path} both write {dest}; give them different names",
                              path=cfg.path, field="name")
        seen[key] = cfg.path
        check_output_dir(dest)
        if dest.exists() and not force:
            if done_hash(dest) == cfg.hash:
                skipped.append({"name": cfg.name, "status": "done", "path": str(dest)})
                continue
            raise ResultExistsError(f"{dest} already exists with another configuration; use --force "
                                    "(force=True) to replace it", path=dest)
        items.append(BatchItem(cfg, dest, None if fits_dir is None else Path(fits_dir), force))
    return items, skipped


def fit_task(item: BatchItem) -> dict:
    """One batch task (runs on a worker): fit, save the directory atomically, return the summary row."""
    from clothlab.atomic import prepare_result
    from clothlab.fit.runner import run_fit, save_fit

    with prepare_result(item.dest, force=item.force):  # held for the fit: a concurrent writer is refused
        result = run_fit(item.config, fits_dir=item.fits_dir, posterior_progress=False)
        out = save_fit(result, force=item.force, fits_dir=item.fits_dir)
    overall = result.errors["overall"]
    return {"name": item.name, "status": "fitted", "path": str(out), "params": dict(result.params),
            "objective": float(result.optimum.fun), "evaluations": int(result.optimum.nevals),
            "p50": overall.get("p50"), "wall_time_s": result.wall_time, "report": result.fit_report()}


def run_batch(items, runner=None, *, on_row=None) -> list[dict]:
    """Fit every :class:`BatchItem` on ``runner`` (default in-process): one row per item in order, a failed
    fit as ``{"status": "failed", "error": ...}`` (after one retry).  ``on_row(row)`` sees each row as its
    fit finishes."""
    runner = runner or InProcessRunner()
    items = list(items)

    def row_of(i, outcome):
        if isinstance(outcome, TaskFailure):
            return {"name": items[i].name, "status": "failed", "path": str(items[i].dest), "error": outcome.error,
                    "attempts": outcome.attempts}
        return outcome

    def finished(i, outcome):
        if on_row is not None:
            on_row(row_of(i, outcome))

    outcomes = runner.map(fit_task, items, names=[it.name for it in items], desc="batch fits", on_result=finished)
    return [row_of(i, o) for i, o in enumerate(outcomes)]


def batch_lines(rows) -> list[str]:
    """The summary table of a batch (one line per fit: status, median relative error, evaluations, time)."""
    out = [f"{'fit':28s} {'status':7s} {'p50 err':>8s} {'evals':>6s} {'time s':>7s}  fit directory / error"]
    for r in rows:
        if r["status"] == "fitted":
            p50 = "-" if r.get("p50") is None else f"{r['p50']:.4f}"
            out.append(f"{r['name']:28s} {'fitted':7s} {p50:>8s} {r['evaluations']:6d} {r['wall_time_s']:7.1f}  "
                       f"{r['path']}")
        elif r["status"] == "done":
            out.append(f"{r['name']:28s} {'done':7s} {'-':>8s} {'-':>6s} {'-':>7s}  {r['path']} (same "
                       "configuration; --force refits)")
        else:
            out.append(f"{r['name']:28s} {'FAILED':7s} {'-':>8s} {'-':>6s} {'-':>7s}  {r['error']}")
    counts = {s: sum(r["status"] == s for r in rows) for s in ("fitted", "done", "failed")}
    out.append(f"{len(rows)} fits: {counts['fitted']} fitted, {counts['done']} already done, "
               f"{counts['failed']} failed")
    return out
