"""Fresh-label errors of a network over several weaves (``train-surrogate SRC1,SRC2,... --draw N
--heldout-pattern WEAVE``, docs/neural.md "The Table-2 network"): relative RMSE of f (the sum of the
components, unit coefficients) by footprint bin for three groups of materials, each against fresh
whole-tile-split MC labels (:class:`clothlab.surrogate.labels.TextureMonteCarloLabels`, another seed than the
training labels, on held-out direction pairs of the data spec), beside the reflectance model alone on the
same labels, and the far view (>= 4 tiles: relative RMS difference of the network from the reflectance model).

Groups: ``heldout_pairs`` (trained materials, held-out pairs), ``heldout_materials`` (unseen parameter sets
of the trained weaves), ``heldout_pattern`` (every material of the weave never trained on).  The queries of a
bin are spread evenly over the group's materials.

Run: ``python -c "from clothlab.studies.neural_table2 import evaluate; print(chr(10).join(evaluate('PATH.npz')[1]))"``.

:func:`texture_bins` scores the same groups against the per-fabric bench's reference instead (issue 23 item 7):
the texture's own box average by 16,384 stratified points, no R (:func:`clothlab.studies.neural_bins.
texture_reference`), on the bench's bins (:data:`clothlab.studies.neural_bins.BINS`), every material of the
group, with 90 % bootstrap intervals: ``python -c "from clothlab.studies.neural_table2 import texture_bins,
texture_lines; print(chr(10).join(texture_lines(texture_bins('PATH.npz'))))"``.
"""

from __future__ import annotations

import json
import time

import numpy as np

BINS = (0.01, 0.03, 0.06, 0.12, 0.25, 0.5, 1.0, 2.0, 4.0, 5.0)  # tiles (as clothlab.surrogate.training.SIZE_BINS)
GROUPS = ("heldout_pairs", "heldout_materials", "heldout_pattern")
RANGES = ((0.03, 0.12), (0.12, 1.0), (1.0, 5.0))  # tiles: the coarse ranges of the per-weave breakdown


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.sum(np.square(a - b)) / np.sum(np.square(b))))


def group_materials(encoding: dict) -> dict[str, list[int]]:
    """Material indices of each group (module docstring) from a sidecar's encoding."""
    unseen, pattern = list(encoding.get("heldout_materials", [])), list(encoding.get("heldout_pattern", []))
    n = len(encoding.get("materials_params", [encoding.get("params")]))
    trained = [m for m in range(n) if m not in set(unseen) | set(pattern)]
    return {"heldout_pairs": trained, "heldout_materials": unseen, "heldout_pattern": pattern}


def fresh_errors(weights, per_bin: int = 150, samples: int = 1024, seed: int = 21) -> dict:
    """{group: [{size_lo, size_hi, queries, surrogate, reflectance_model}], group + "_far_view": float,
    group + "_by_weave": {weave: [{size_lo, size_hi, surrogate, reflectance_model}] over :data:`RANGES`},
    "cpu_s": float} for the network at ``weights`` (.npz, residual or not; R from
    :func:`clothlab.models.neural.model.load_neural`)."""
    from clothlab.models.neural.model import load_neural, reference_model
    from clothlab.surrogate.data import DataSpec, heldout_queries
    from clothlab.surrogate.labels import ModelLabels, TextureMonteCarloLabels
    from clothlab.surrogate.training import relative_rmse_interval

    start = time.process_time()
    surrogate, sidecar = load_neural(weights)
    enc = sidecar["encoding"]
    spec = DataSpec(**enc["data_spec"])
    sets = enc.get("materials_params", [enc.get("params", {})])
    owners = enc.get("materials_weave") or [None] * len(sets)
    models = {name: reference_model(sidecar, None, name) for name in set(owners)}
    out = {}
    for group, members in group_materials(enc).items():
        if not members:
            continue
        each = -(-per_bin // len(members))
        rows, far, kept = [], [], []
        for i, (lo, hi) in enumerate(zip(BINS[:-1], BINS[1:], strict=True)):
            f_true, f_pred, f_model = [], [], []
            for m in members:
                model, params = models[owners[m]], {k: float(v) for k, v in sets[m].items()}
                r = ModelLabels(model, params)
                mc = TextureMonteCarloLabels(model.texture(seed=0), params, samples=samples, seed=seed + 1,
                                             tile_average=r)
                q = heldout_queries(spec, each, seed=seed + 100 * i + 7 * m, sizes=(lo, hi), material=m)
                args = (q[:, 4:7], q[:, 7:10], q[:, 1:3], q[:, 3])
                f_true.append(mc(*args).sum(axis=1))
                f_model.append(r(*args).sum(axis=1))
                f_pred.append(surrogate.query(q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10], material=m).sum(axis=1))
                kept.append((owners[m], q[:, 3], f_true[-1], f_pred[-1], f_model[-1]))
            f_true, f_pred, f_model = (np.concatenate(x) for x in (f_true, f_pred, f_model))
            rows.append({"size_lo": lo, "size_hi": hi, "queries": int(f_true.size),
                         "surrogate": _relative(f_pred, f_true),
                         "surrogate_interval": relative_rmse_interval(f_pred, f_true),
                         "reflectance_model": _relative(f_model, f_true)})
            if lo >= 4.0:
                far.append(_relative(f_pred, f_model))
        out[group] = rows
        out[f"{group}_far_view"] = far[0] if far else None
        by_weave = {}
        for name in sorted({k[0] for k in kept}, key=str):
            parts = [np.concatenate(x) for x in zip(*[k[1:] for k in kept if k[0] == name], strict=True)]
            size, f_t, f_p, f_m = parts
            sel = [(lo, hi, (size >= lo) & (size < hi)) for lo, hi in RANGES]
            by_weave[str(name)] = [{"size_lo": lo, "size_hi": hi, "surrogate": _relative(f_p[k], f_t[k]),
                                    "reflectance_model": _relative(f_m[k], f_t[k])} for lo, hi, k in sel]
        out[f"{group}_by_weave"] = by_weave
    out["cpu_s"] = time.process_time() - start
    return out


def table_lines(result: dict, recorded: dict | None = None) -> list[str]:
    """A markdown table: per bin the three groups (fresh labels; the sidecar's training-label figures in
    brackets when ``recorded`` = its ``metrics``) and the reflectance model alone on each group's labels."""
    head = ["footprint"] + [g.replace("heldout_", "") for g in GROUPS if g in result]
    head += [f"R alone: {g.replace('heldout_', '')}" for g in GROUPS if g in result]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i, lo_hi in enumerate(zip(BINS[:-1], BINS[1:], strict=True)):
        cells = [f"{lo_hi[0]:g}-{lo_hi[1]:g}"]
        for g in GROUPS:
            if g in result:
                text = f"{result[g][i]['surrogate']:.3f}"
                rec = (recorded or {}).get(g)
                match = [b for b in rec or [] if abs(b["size_lo"] - lo_hi[0]) < 1e-9]
                cells.append(f"{text} ({match[0]['relative_rmse']:.3f})" if match else text)
        cells += [f"{result[g][i]['reflectance_model']:.3f}" for g in GROUPS if g in result]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def evaluate(weights, per_bin: int = 150, samples: int = 1024) -> tuple[dict, list[str]]:
    """:func:`fresh_errors` of ``weights`` and its lines: :func:`table_lines`, the far views, the per-weave
    breakdown and the CPU time (the caller prints them)."""
    from pathlib import Path

    result = fresh_errors(weights, per_bin=per_bin, samples=samples)
    sidecar = json.loads(Path(weights).with_suffix(".json").read_text(encoding="utf-8"))
    lines = table_lines(result, sidecar.get("metrics"))
    lines += [f"far view {g}: {result[f'{g}_far_view']:.4f}" for g in GROUPS
              if result.get(f"{g}_far_view") is not None]
    for g in GROUPS:
        for name, ranges in result.get(f"{g}_by_weave", {}).items():
            lines.append(f"{g} {name}: " + ", ".join(f"{r['size_lo']:g}-{r['size_hi']:g}: {r['surrogate']:.3f} "
                                                     f"(R {r['reflectance_model']:.3f})" for r in ranges))
    lines.append(f"CPU {result['cpu_s']:.0f} s")
    return result, lines


def texture_bins(weights, per_bin: int = 3000, samples: int = 16384, seed: int = 4111) -> dict:
    """{group: [{size_lo, size_hi, queries, materials, surrogate, surrogate_interval, reflectance_model,
    reference_noise}], "cpu_s"} of the network at ``weights`` per bin of the bench
    (:data:`clothlab.studies.neural_bins.BINS`) against :func:`clothlab.studies.neural_bins.texture_reference`
    (``samples`` points per query, no R): ``per_bin`` fresh held-out queries per group and bin spread evenly
    over every material of the group (:func:`group_materials`; seeds ``seed`` + ..., not the bench's)."""
    from clothlab.models.neural.model import load_neural
    from clothlab.studies.neural_bins import BINS, Material, texture_reference
    from clothlab.surrogate.data import DataSpec, heldout_queries
    from clothlab.surrogate.training import relative_rmse_interval

    start = time.process_time()
    surrogate, sidecar = load_neural(weights)
    enc = sidecar["encoding"]
    spec = DataSpec(**enc["data_spec"])
    out = {}
    for group, members in group_materials(enc).items():
        if not members:
            continue
        materials = [Material(surrogate, sidecar, m) for m in members]
        each = -(-per_bin // len(materials))
        rows = []
        for i, (lo, hi) in enumerate(BINS):
            ref, diff, pred, base = [], [], [], []
            for m in materials:
                q = heldout_queries(spec, each, seed=seed + 1000 * i + 7 * m.row, sizes=(lo, hi), material=m.row)
                f, d = texture_reference(m, q, samples, seed + 3 + 11 * m.row + 1000 * i)
                ref.append(f)
                diff.append(d)
                pred.append(surrogate.query(q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10], material=m.row).sum(axis=1))
                base.append(m.r(q[:, 4:7], q[:, 7:10], q[:, 1:3], q[:, 3]).sum(axis=1))
            ref, diff, pred, base = (np.concatenate(x) for x in (ref, diff, pred, base))
            rows.append({"size_lo": lo, "size_hi": hi, "queries": int(ref.size), "materials": len(materials),
                         "surrogate": _relative(pred, ref), "surrogate_interval": relative_rmse_interval(pred, ref),
                         "reflectance_model": _relative(base, ref),
                         "reference_noise": 0.5 * float(np.sqrt(np.sum(diff ** 2) / np.sum(ref ** 2)))})
        out[group] = rows
    out["cpu_s"] = time.process_time() - start
    return out


def texture_lines(result: dict) -> list[str]:
    """Markdown rows of :func:`texture_bins`: per group and bin the relative RMSE [90 %], R alone, the
    reference's own noise."""
    lines = ["| group | bin (tiles) | queries (materials) | rel. RMSE [90 %] | R alone | ref. noise |",
             "|---|---|---|---|---|---|"]
    names = {"heldout_pairs": "trained materials", "heldout_materials": "unseen materials",
             "heldout_pattern": "held-out pattern"}
    for g in GROUPS:
        for r in result.get(g, []):
            lo, hi = r["surrogate_interval"]
            lines.append(f"| {names[g]} | {r['size_lo']:g}-{r['size_hi']:g} | {r['queries']:,} "
                         f"({r['materials']}) | {r['surrogate']:.3f} [{lo:.3f}, {hi:.3f}] | "
                         f"{r['reflectance_model']:.3f} | {r['reference_noise']:.4f} |")
    return lines + [f"CPU {result['cpu_s']:.0f} s"]
