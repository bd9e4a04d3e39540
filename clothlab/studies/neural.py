"""Bench section ``neural``: inference speed of the numpy surrogate's decoder (Chen, Wang & Wang 2024,
sec. 4.2-4.3: only the decoder runs per query) at the chosen width and one narrower and one wider, measured
side by side in one run, against the target of :data:`TARGET_QPS` queries per second on this machine; then
the per-bin figures of every shipped network end to end (:mod:`clothlab.studies.neural_bins`) and the
neural-lod render.

Each width is timed in worker processes started with one BLAS thread each (OPENBLAS/OMP/MKL_NUM_THREADS=1:
many small matrix products stall with threaded BLAS under load), float32, queries in chunks of
:data:`CHUNK` rows: one worker alone, then one worker per core concurrently.  Queries/s is the total
queries over the slowest worker's wall time; queries per CPU-second divides by the CPU time the workers
used.  The weights are random: the cost does not depend on their values.

:func:`surrogate_vs_mc` (used by :func:`compare_networks`, not by the section: it pools bins and its
reference uses R) sets a shipped per-fabric network against Monte-Carlo footprint integration at equal
time (the "MSE vs time" table): held-out direction
pairs of its training data spec (one pair per query), footprints >= 0.12 tile; the reference is the
whole-tile-split MC estimate with :data:`REFERENCE_SAMPLES` samples
(:class:`clothlab.surrogate.labels.TextureMonteCarloLabels`); the MC estimates are plain stratified box
averages of k = 1, 2, 4, ..., 256 texture samples (what a renderer does); MSE of f = the sum of the
components, seconds per query measured in this process.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

TARGET_QPS = 1.0e6
CHUNK = 2048
WIDTHS = ((32, 16), (64, 32), (128, 64))  # (decoder width, spatial feature width); 64 / 32 is the default
CHOSEN = (64, 32)


def _worker(args) -> tuple[float, float]:
    """(wall s, CPU s) of ``repeats`` passes over ``n`` queries at one width (best of the passes)."""
    import time

    from clothlab.surrogate.network import Architecture, SurrogateNetwork
    from clothlab.surrogate.surrogate import Surrogate

    width, spatial, n, repeats = args
    arch = Architecture(n_material=39, n_spatial=24, n_angular=8, n_out=3, width=width, spatial=spatial)
    rng = np.random.default_rng(0)
    surrogate = Surrogate(SurrogateNetwork(arch), ("diffuse", "specular_warp", "specular_weft"),
                          rng.random((1, 39)))
    features = rng.random((n, 24)).astype(np.float32), rng.standard_normal((n, 8)).astype(np.float32)
    surrogate.outputs(features[0][:CHUNK], features[1][:CHUNK])  # warm-up
    best = (np.inf, np.inf)
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        surrogate.outputs(*features, chunk=CHUNK)
        best = min(best, (time.perf_counter() - wall, time.process_time() - cpu))
    return best


def _pool(processes: int):
    """A spawn pool whose workers start with one BLAS thread (the variables are read at numpy import)."""
    import multiprocessing

    names = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    saved = {k: os.environ.get(k) for k in names}
    os.environ.update({k: "1" for k in names})
    try:
        return multiprocessing.get_context("spawn").Pool(processes)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def neural_speed(quick: bool, queries: int | None = None, repeats: int | None = None) -> dict:
    """Queries/s and queries per CPU-second per width, one worker and one worker per core (``queries`` per
    worker and timing ``repeats`` override the run size)."""
    from clothlab.surrogate.network import Architecture

    cores = max(1, os.cpu_count() or 1)
    n = queries or (65536 if quick else 262144)
    repeats = repeats or (3 if quick else 5)
    rows = []
    with _pool(cores) as pool:
        pool.map(_worker, [(8, 8, CHUNK, 1)] * cores)  # start the workers (imports) before timing
        for width, spatial in WIDTHS:
            one = pool.apply(_worker, ((width, spatial, n, repeats),))
            many = pool.map(_worker, [(width, spatial, n, repeats)] * cores)
            arch = Architecture(39, 24, 8, 3, width=width, spatial=spatial)
            qps = cores * n / max(w for w, _ in many)
            rows.append({"width": width, "spatial": spatial, "kflop_per_query": arch.decoder_flops() / 1e3,
                         "qps_one_worker": n / one[0], "qps_per_cpu_s_one_worker": n / max(one[1], 1e-9),
                         "workers": cores, "qps": qps, "qps_per_cpu_s": cores * n / max(sum(c for _, c in many), 1e-9),
                         "chosen": (width, spatial) == CHOSEN, "meets_target": qps >= TARGET_QPS})
    return {"queries": n, "chunk": CHUNK, "target_qps": TARGET_QPS, "widths": rows}


REFERENCE_SAMPLES = 4096
MC_SAMPLES = (1, 2, 4, 8, 16, 32, 64, 128, 256)
SHIPPED_FABRIC = "silk-shantung"


def surrogate_vs_mc(quick: bool, fabric: str = SHIPPED_FABRIC, queries: int | None = None, weights=None) -> dict:
    """MSE and seconds per query of the shipped surrogate (or the ``weights`` .npz) and of k-sample MC, by
    footprint group; a residual network's time includes its reflectance-model evaluation."""
    from clothlab.config.build import model_from_weave
    from clothlab.models.neural.model import DEFAULT_TARGET_KIND, SHIPPED, load_neural
    from clothlab.studies.timing import best_time
    from clothlab.surrogate.data import DataSpec, heldout_queries
    from clothlab.surrogate.labels import ModelLabels, TextureMonteCarloLabels
    from clothlab.weave.presets import get_preset

    path = SHIPPED / f"{fabric}.npz" if weights is None else Path(weights)
    if not path.exists():
        return {"skipped": f"no shipped surrogate for {fabric}"}
    surrogate, sidecar = load_neural(path)  # a residual network evaluates the reflectance model per query
    enc = sidecar["encoding"]
    model = model_from_weave(get_preset(enc["weave"]), kind=enc.get("kind", DEFAULT_TARGET_KIND))
    params, texture = enc["params"], model.texture()
    q = heldout_queries(DataSpec(**enc.get("data_spec", {})), queries or (200 if quick else 1000), seed=11,
                        sizes=(0.12, 5.0))
    args = (q[:, 4:7], q[:, 7:10], q[:, 1:3], q[:, 3])
    ref = TextureMonteCarloLabels(texture, params, samples=REFERENCE_SAMPLES // (4 if quick else 1), seed=12345,
                                  tile_average=ModelLabels(model, params))(*args).sum(axis=1)
    groups = {"size >= 0.12": q[:, 3] >= 0.12, "size >= 1": q[:, 3] >= 1.0}

    def row(name, fn, samples=None):
        value = fn().sum(axis=1)
        seconds = best_time(fn, 1 if quick else 3, min_sample_s=0.0) / len(q)
        return {"method": name, "samples": samples, "us_per_query": 1e6 * seconds,
                **{g: float(np.mean(np.square(value[sel] - ref[sel]))) for g, sel in groups.items()}}

    rows = [row("surrogate", lambda: surrogate.query(q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10]))]
    for k in MC_SAMPLES:
        rows.append(row(f"MC {k}", lambda k=k: TextureMonteCarloLabels(texture, params, samples=k, seed=7)(*args), k))
    sur = rows[0]
    equal = next((r for r in rows[1:] if r["us_per_query"] >= sur["us_per_query"]), rows[-1])
    ratios = {g: equal[g] / max(sur[g], 1e-300) for g in groups}
    mc16 = next(r for r in rows if r["samples"] == 16)
    return {"fabric": fabric, "queries": int(len(q)), "reference_samples": REFERENCE_SAMPLES // (4 if quick else 1),
            "rows": rows, "equal_time_mc": equal["method"], "mse_ratio_equal_time": ratios,
            "mse_ratio_mc16_size_ge_1": mc16["size >= 1"] / max(sur["size >= 1"], 1e-300)}


HELDOUT_BINS = (0.01, 0.03, 0.06, 0.12, 0.25, 0.5, 1.0, 2.0, 4.0, 5.0)  # tiles (as training.SIZE_BINS)


def fresh_heldout_labels(sidecar: dict, per_bin: int = 150, samples: int = REFERENCE_SAMPLES, seed: int = 21):
    """Per footprint bin of :data:`HELDOUT_BINS`: ``per_bin`` queries on held-out direction pairs of the
    sidecar's data spec, their fresh whole-tile-split MC labels (``samples`` per query) and the reflectance
    model R (N, C) at them; a list of (lo, hi, queries, labels, R).  Independent of the network, so one call
    serves every variant trained on the same data."""
    from clothlab.models.neural.model import reference_model
    from clothlab.surrogate.data import DataSpec, heldout_queries
    from clothlab.surrogate.labels import ModelLabels, TextureMonteCarloLabels

    enc = sidecar["encoding"]
    model = reference_model(sidecar)
    far = ModelLabels(model, enc["params"])
    mc = TextureMonteCarloLabels(model.texture(), enc["params"], samples=samples, seed=seed + 1, tile_average=far)
    out = []
    for i, (lo, hi) in enumerate(zip(HELDOUT_BINS[:-1], HELDOUT_BINS[1:], strict=True)):
        q = heldout_queries(DataSpec(**enc["data_spec"]), per_bin, seed=seed + 100 * i, sizes=(lo, hi))
        args = (q[:, 4:7], q[:, 7:10], q[:, 1:3], q[:, 3])
        out.append((lo, hi, q, mc(*args), far(*args)))
    return out


def heldout_errors(weights, fresh) -> dict:
    """The surrogate at ``weights`` (.npz) on :func:`fresh_heldout_labels` ``fresh``: relative RMSE of f (the
    sum of the components) by bin, that of the reflectance model, and the far view (>= 4 tiles): relative RMS
    difference between surrogate and reflectance model."""
    from clothlab.models.neural.model import load_neural
    from clothlab.surrogate.training import relative_rmse_interval

    surrogate, _ = load_neural(weights)
    rows, far = [], None

    def rel(a, b) -> float:
        return float(np.sqrt(np.sum(np.square(a - b)) / np.sum(np.square(b))))

    for lo, hi, q, labels, reflectance in fresh:
        f = labels.sum(axis=1)
        pred = surrogate.query(q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10]).sum(axis=1)
        rows.append({"size_lo": lo, "size_hi": hi, "queries": int(len(q)), "surrogate": rel(pred, f),
                     "surrogate_interval": relative_rmse_interval(pred, f),
                     "reflectance_model": rel(reflectance.sum(axis=1), f)})
        if lo >= 4.0:
            far = rel(pred, reflectance.sum(axis=1))
    return {"bins": rows, "far_view": far}


def compare_networks(weights: dict, per_bin: int = 150, mc_queries: int = 300) -> dict:
    """Networks of one fabric trained on the same data (``weights``: {variant: .npz}) on the same held-out
    queries: :func:`heldout_errors` against one set of :func:`fresh_heldout_labels`, and MC 16 / surrogate MSE
    at >= 1 tile (:func:`surrogate_vs_mc`, ``mc_queries`` queries).  The docs' ablation table."""
    import json

    first = Path(next(iter(weights.values())))
    sidecar = json.loads(first.with_suffix(".json").read_text(encoding="utf-8"))
    fresh = fresh_heldout_labels(sidecar, per_bin)
    out = {}
    for name, path in weights.items():
        versus = surrogate_vs_mc(False, sidecar["encoding"]["weave"], mc_queries, weights=path)
        metrics = json.loads(Path(path).with_suffix(".json").read_text(encoding="utf-8"))["metrics"]
        out[name] = {**heldout_errors(path, fresh), "mc16_over_surrogate_size_ge_1": versus["mse_ratio_mc16_size_ge_1"],
                     "us_per_query": versus["rows"][0]["us_per_query"], "steps": metrics["steps"],
                     "train_cpu_s": metrics["cpu_s"]}
    return out


def comparison_lines(table: dict) -> list[str]:
    """Markdown rows of :func:`compare_networks`: relative RMSE by bin, far view, MC 16 / surrogate."""
    out = []
    for name, r in table.items():
        bins = " | ".join(f"{b['surrogate']:.3g}" for b in r["bins"])
        out.append(f"| {name} | {r['steps']:,} | {r['train_cpu_s']:.0f} | {bins} | {100 * r['far_view']:.1f} % | "
                   f"{r['mc16_over_surrogate_size_ge_1']:.1f} | {r['us_per_query']:.2f} |")
    return out


def shipped_fabrics() -> list[str]:
    """The presets with shipped per-fabric weights (:data:`clothlab.models.neural.model.SHIPPED`)."""
    from clothlab.models.neural.model import SHIPPED
    from clothlab.weave.presets import PRESET_NAMES

    return [name for name in PRESET_NAMES if (SHIPPED / f"{name}.npz").exists()]


def run(context) -> dict:
    """Decoder speed, the per-bin figures of every shipped network (:mod:`clothlab.studies.neural_bins`:
    accuracy against the texture model, cold end-to-end cost, equal-time MSE ratios; no pooled figure) and
    the neural-lod render."""
    from clothlab.studies.neural_bins import run_all
    from clothlab.studies.render_lod import neural_lod_benchmark

    return {**neural_speed(context.quick), "per_bin": run_all(context.quick),
            "render": neural_lod_benchmark(context.quick, figures_dir=context.figures_dir)}


def lines(f: dict) -> list[str]:
    out = [f"== neural surrogate: decoder inference, float32, {f['chunk']}-row chunks, 1 BLAS thread per worker "
           f"({f['queries']:,} queries per worker) ==",
           "  width/spatial  kFLOP/query   1 worker q/s   q/CPU-s   workers   all q/s   q/CPU-s   target 1 M/s"]
    for r in f["widths"]:
        out.append(f"  {r['width']:>5}/{r['spatial']:<6}{'*' if r['chosen'] else ' '} {r['kflop_per_query']:>10.1f} "
                   f"{r['qps_one_worker']:>14,.0f} {r['qps_per_cpu_s_one_worker']:>9,.0f} {r['workers']:>9} "
                   f"{r['qps']:>9,.0f} {r['qps_per_cpu_s']:>9,.0f}   {'met' if r['meets_target'] else 'NOT met'}")
    out.append("  * the default width")
    if f.get("per_bin"):
        from clothlab.studies.neural_bins import lines as bin_lines

        out += bin_lines(f["per_bin"])
    for v in f.get("versus_mc_all") or ([f["versus_mc"]] if f.get("versus_mc") else []):
        out += _versus_lines(v)
    if "render" in f:
        from clothlab.studies.render_lod import neural_lod_lines

        out += neural_lod_lines(f["render"])
    return out


def _versus_lines(v: dict) -> list[str]:
    out = []
    if "rows" in v:
        out.append(f"  {v['fabric']}: shipped surrogate vs MC footprint integration, {v['queries']} held-out queries, "
                   f"reference MC {v['reference_samples']} (whole-tile split); MSE of f")
        out.append("    method        us/query   MSE size>=0.12   MSE size>=1")
        for r in v["rows"]:
            out.append(f"    {r['method']:<12}{r['us_per_query']:>9.2f}   {r['size >= 0.12']:>14.4g}"
                       f"   {r['size >= 1']:>11.4g}")
        ratio = v["mse_ratio_equal_time"]
        out.append(f"    equal time ({v['equal_time_mc']}): MC MSE / surrogate MSE = {ratio['size >= 0.12']:.1f} "
                   f"(>= 0.12 tile), {ratio['size >= 1']:.1f} (>= 1 tile); MC 16 / surrogate at >= 1 tile = "
                   f"{v['mse_ratio_mc16_size_ge_1']:.1f}")
    elif v:
        out.append(f"  surrogate vs MC: {v['skipped']}")
    return out
