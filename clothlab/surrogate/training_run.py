"""One training run in a directory: label the data (:mod:`.data`), train (:mod:`.training`), save the
surrogate (:mod:`.serialise`) and write the loss curve and held-out errors (JSON + PNG).

Directory layout: ``data/`` (chunks, ``data.npy`` memory-mapped), ``checkpoint.npz`` (resume),
``surrogate.npz`` + ``surrogate.json``, ``training.json`` (specs, curve, metrics), ``loss.png``,
``heldout.png``.  The CPU budget (seconds, ``time.process_time``) is shared: labelling stops at
``label_share`` of it (a partial data set trains; ``resume`` labels the rest), training takes what is left.
On a runner the labelling is counted as wall time x workers, for the stop and for what is left.
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import ConfigError
from clothlab.progress import get_logger
from clothlab.surrogate.data import DataSpec, assemble, generate
from clothlab.surrogate.serialise import save_surrogate
from clothlab.surrogate.training import TrainResult, TrainSpec, train

LOG = get_logger("surrogate.training_run")


def run_training(directory, label_sources, materials, data_spec: DataSpec, train_spec: TrainSpec, *,
                 budget_s: float, label_share: float = 0.5, heldout_materials=(), encoding: dict | None = None,
                 resume: bool = False, plots: bool = True, runner=None, references=None,
                 heldout_pattern=(), probes=None) -> TrainResult:
    """Label and train within ``budget_s`` CPU seconds; ``label_sources[m]`` and ``materials[m]`` (encoder
    input) describe material m.  Returns the result after writing every file of the directory.  ``runner``
    (:class:`clothlab.parallel.Runner`): the labelling chunks as tasks on its workers, their CPU counted as
    wall time x workers.  ``references``: per material the reflectance model (residual networks);
    ``probes``: per material the texture probe (probing networks).
    ``heldout_materials`` / ``heldout_pattern``: material indices never trained on (:func:`.train`)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    manifest = directory / "data" / "data.json"
    if manifest.exists() and json.loads(manifest.read_text(encoding="utf-8")).get("spec") != data_spec.to_dict():
        raise ConfigError(f"the data in {directory / 'data'} was sampled with other settings "
                          f"({json.loads(manifest.read_text(encoding='utf-8')).get('spec')}); resume with the same "
                          "--pairs and --seed, or start a new directory", path=directory)
    start = time.process_time()
    names = tuple(label_sources[0].component_names)
    wall = time.perf_counter()
    if runner is None:
        def used() -> float:
            return time.process_time() - start
    else:
        def used() -> float:
            return (time.perf_counter() - wall) * runner.workers
    written = generate(directory / "data", data_spec, label_sources, stop=lambda: used() > label_share * budget_s,
                       runner=runner)
    data, sha = assemble(directory / "data", data_spec, len(label_sources), len(names))
    label_s = used()  # on a runner: wall x workers, the workers' CPU as the label share counted it
    LOG.info(f"{written} chunks labelled ({data.shape[0]:,} queries in all) in {label_s:.1f} CPU-s"
             + ("" if runner is None else f" (wall x {runner.workers} workers)"))
    spec = replace(train_spec, budget_s=max(1.0, budget_s - label_s)) if train_spec.steps is None else train_spec
    encoding = {**(encoding or {}), "data_spec": data_spec.to_dict()}  # the held-out cells follow from it
    result = train(data, names, materials, spec, encoding=encoding, heldout_materials=heldout_materials,
                   checkpoint=directory / "checkpoint.npz", resume=resume, references=references,
                   heldout_pattern=heldout_pattern, probes=probes)
    result.metrics["label_cpu_s"] = label_s
    result.metrics["queries"] = int(data.shape[0])
    save_surrogate(result.surrogate, directory / "surrogate.npz", data_hash=sha, metrics=result.metrics)
    summary = {"data_spec": data_spec.to_dict(), "train_spec": spec.to_dict(), "data_sha256": sha,
               "components": list(names), "curve": result.curve, "metrics": result.metrics}
    atomic_write_bytes(directory / "training.json", (json.dumps(summary, indent=2) + "\n").encode())
    if plots:
        write_plots(directory, result)
    return result


def write_plots(directory: Path, result: TrainResult) -> None:
    """``loss.png`` (training loss vs CPU seconds) and ``heldout.png`` (relative RMSE by footprint size)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5, 3.2))
    ax = fig.add_subplot()
    ax.semilogy([c["cpu_s"] for c in result.curve], [c["loss"] for c in result.curve])
    ax.set(xlabel="CPU seconds", ylabel="training loss (eq. 11)", title="surrogate training")
    fig.tight_layout()
    fig.savefig(directory / "loss.png", dpi=110)
    fig = Figure(figsize=(5, 3.2))
    ax = fig.add_subplot()
    for key in ("heldout_pairs", "heldout_materials", "heldout_pattern", "train_sample"):
        bins = result.metrics.get(key)
        if bins:
            centre = [(b["size_lo"] * b["size_hi"]) ** 0.5 for b in bins]
            value = np.array([b["relative_rmse"] for b in bins])
            interval = np.array([b.get("relative_rmse_interval") or [v, v] for b, v in zip(bins, value, strict=True)])
            ax.errorbar(centre, value, yerr=np.abs(interval.T - value), marker="o", capsize=2,
                        label=key.replace("_", " "))
    ax.set(xscale="log", yscale="log")
    ax.axhline(0.25, color="grey", lw=0.8, ls="--")
    ax.set(xlabel="footprint size (tiles)", ylabel="relative RMSE of f (90 % bootstrap)",
           title="error by footprint size")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(directory / "heldout.png", dpi=110)


def _interval(row: dict) -> str:
    """A bin's bootstrap interval of the relative RMSE as text ('-' for metrics recorded without it)."""
    interval = row.get("relative_rmse_interval")
    return f"{interval[0]:.3f}-{interval[1]:.3f}" if interval else "-"


def write_report_page(directory: Path, metrics: dict, *, latent: dict | None = None) -> Path:
    """``report.html`` beside the PNGs: loss vs CPU time, held-out error by footprint size (tables of the
    held-out pairs and, for a multi-material network, the unseen materials) and, when given, the latent
    interpolation of Fig. 8 (``latent.png``)."""
    import html

    directory = Path(directory)
    parts = ["<!doctype html><meta charset='utf-8'><title>surrogate training</title>",
             "<h1>Neural surrogate training</h1>",
             f"<p>{metrics.get('steps', 0)} Adam steps, {metrics.get('queries', 0):,} labelled queries, "
             f"{metrics.get('label_cpu_s', 0.0) + metrics.get('cpu_s', 0.0):.0f} CPU-s in all.</p>",
             "<h2>Loss vs time</h2><img src='loss.png'>", "<h2>Held-out error by footprint size</h2>",
             "<img src='heldout.png'>"]
    for key, title in (("heldout_pairs", "held-out direction pairs"), ("heldout_materials", "unseen materials"),
                       ("heldout_pattern", "unseen pattern")):
        bins = metrics.get(key)
        if bins:
            rows = "".join(f"<tr><td>{b['size_lo']:g}-{b['size_hi']:g}</td><td>{b['relative_rmse']:.3f}</td>"
                           f"<td>{_interval(b)}</td><td>{b['mse']:.3g}</td><td>{b['rows']}</td></tr>" for b in bins)
            parts.append(f"<h3>{html.escape(title)}</h3><table border=1 cellpadding=3><tr><th>footprint (tiles)"
                         "</th><th>relative RMSE of f</th><th>90 % bootstrap interval</th><th>MSE</th><th>queries"
                         f"</th></tr>{rows}</table>")
    if latent is not None:
        parts.append("<h2>Latent interpolation (Fig. 8)</h2><img src='latent.png'><p>Decoder at z(t) = (1 - t) "
                     "z_a + t z_b, the surrogate at the interpolated material vector, and the model at the "
                     "interpolated parameters (far view).</p>")
    path = directory / "report.html"
    atomic_write_bytes(path, "\n".join(parts).encode())
    return path
