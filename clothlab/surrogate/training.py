"""Training the surrogate on labelled footprint queries (:mod:`.data`) and its held-out errors.

Adam (:mod:`.optimizer`) on the loss of eqs. 9-11 (:mod:`.losses`) with mini-batches drawn from the
training rows; the step schedule of sec. 5.2 (x 0.2 at 60 % and 90 % of the run) counts in steps or,
with a budget, in CPU seconds (``time.process_time``).  Rows are split three ways: training, held-out
direction pairs (the ``heldout_pair`` column), held-out materials (every row of the materials named) and,
for a network over several patterns, the materials of a held-out pattern (scored apart: "unseen pattern").
Held-out error by footprint size bin (:data:`SIZE_BINS`, tiles): relative RMSE of f = the sum of the
components (unit coefficients), sqrt(sum (f_pred - f)^2 / sum f^2), and the MSE.
A checkpoint (network, Adam moments, step, CPU time, loss curve) makes a run resumable.

``residual`` (:mod:`.surrogate`): the loss of eqs. 9-11 compares T(R) + net with T(label); R is a constant
of each row (computed once from ``references`` before the first step, its CPU time counted in the run), so
the network's backward pass is unchanged (d loss / d net = d loss / d g).

``reciprocal`` (not in the paper): Helmholtz reciprocity f(wi, wo) = f(wo, wi) holds for the IM texture and
its tile average (checked on the run's references and probes before the first step), so a training row
with wi and wo exchanged is another training row with the same label, T(R) and probe.  Each batch swaps a
random half of the rows whose swapped pair is a trained (wi cell, wo cell) pair: the direction pairs seen
double at no label cost, and the held-out pairs stay unseen.
"""

from __future__ import annotations

import io
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import InputError
from clothlab.progress import Progress, get_logger
from clothlab.surrogate.data import COLUMNS, DataSpec, swap_trained
from clothlab.surrogate.encodings import BLOB_BINS, n_direction_features, n_yarn_features
from clothlab.surrogate.losses import column_weights, encode_targets, highlight_weights, is_specular, loss_and_gradient
from clothlab.surrogate.network import Architecture, SurrogateNetwork
from clothlab.surrogate.optimizer import Adam, step_schedule
from clothlab.surrogate.surrogate import Surrogate
from clothlab.surrogate.threads import one_blas_thread

LOG = get_logger("surrogate.training")
SIZE_BINS = (0.01, 0.03, 0.06, 0.12, 0.25, 0.5, 1.0, 2.0, 4.0, 5.0)
N_QUERY = len(COLUMNS)


@dataclass(frozen=True)
class TrainSpec:
    """Network widths, optimiser settings and the run length (``steps`` and / or ``budget_s`` CPU seconds)."""

    width: int = 64
    spatial: int = 32
    enc_width: int = 128
    latent: int = 64
    half_vector: bool = True
    position_bins: int = BLOB_BINS
    size_bins: int = BLOB_BINS
    yarn_bins: int = 0
    residual: bool = False
    residual_input: bool = False
    highlight_scale: float | None = None  # 1/sr: losses.highlight_weights (None: eqs. 9-11 as the paper)
    probe_points: int = 0  # texture probe points per side (surrogate module docstring; 0: none, as the paper)
    reciprocal: bool = False  # swap wi and wo of half the eligible batch rows (reciprocal_rows; off: as the paper)
    batch: int = 4096
    lr: float = 3e-3
    weight_decay: float = 1e-6
    milestones: tuple[float, ...] = (0.6, 0.9)
    gamma: float = 0.2
    steps: int | None = None
    budget_s: float | None = None
    seed: int = 0
    log_every: int = 50
    checkpoint_every: int = 500

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class TrainResult:
    surrogate: Surrogate
    curve: list[dict] = field(default_factory=list)  # step, cpu_s, lr, loss (training batch, eq. 11)
    metrics: dict = field(default_factory=dict)


def split_rows(data: np.ndarray, heldout_materials=(), heldout_pattern=()) -> dict[str, np.ndarray]:
    """Row indices: ``train``, ``heldout_pairs`` (trained materials), ``heldout_materials`` and
    ``heldout_pattern`` (every row of the materials of the held-out pattern; none are trained on)."""
    material = np.asarray(data[:, 0]).astype(np.int64)
    pair = np.asarray(data[:, 10]) > 0.5
    unseen = np.isin(material, np.asarray(list(heldout_materials), dtype=np.int64))
    pattern = np.isin(material, np.asarray(list(heldout_pattern), dtype=np.int64)) & ~unseen
    return {"train": np.flatnonzero(~pair & ~unseen & ~pattern),
            "heldout_pairs": np.flatnonzero(pair & ~unseen & ~pattern),
            "heldout_materials": np.flatnonzero(unseen), "heldout_pattern": np.flatnonzero(pattern)}


def make_surrogate(spec: TrainSpec, materials: np.ndarray, names, encoding: dict, references=None,
                   probes=None) -> Surrogate:
    """A new (untrained) surrogate of ``spec``; ``references``: per material the reflectance model's label
    source (needed when ``spec.residual`` or ``spec.residual_input``); ``probes``: per material the texture
    probe (:class:`clothlab.surrogate.labels.TextureProbe`, needed when ``spec.probe_points``)."""
    if (spec.residual or spec.residual_input) and not references:
        raise ValueError("a residual network needs the reflectance model of each material (references)")
    if spec.probe_points and not probes:
        raise ValueError("a probing network needs the texture probe of each material (probes)")
    n_spatial = 2 * spec.position_bins + spec.size_bins + n_yarn_features(spec.yarn_bins)
    n_angular = (n_direction_features(spec.half_vector) + (len(names) if spec.residual_input else 0)
                 + len(names) * spec.probe_points ** 2)
    arch = Architecture(n_material=materials.shape[1], n_spatial=n_spatial, n_angular=n_angular, n_out=len(names),
                        enc_width=spec.enc_width, latent=spec.latent, width=spec.width, spatial=spec.spatial)
    return Surrogate(SurrogateNetwork(arch, seed=spec.seed), tuple(names), np.asarray(materials, dtype=np.float64),
                     {**encoding, "half_vector": spec.half_vector, "position_bins": spec.position_bins,
                      "size_bins": spec.size_bins, "yarn_bins": spec.yarn_bins, "residual": spec.residual,
                      "residual_input": spec.residual_input, "highlight_scale": spec.highlight_scale,
                      "probe_points": spec.probe_points, "reciprocal": spec.reciprocal},
                     references=list(references) if references else None, probes=list(probes) if probes else None)


def _per_row(transform, data: np.ndarray, width: int) -> np.ndarray:
    """``transform(centre, size, wi, wo, material)`` (n, width) of every row of ``data``, material by
    material, as float32 (a constant of each row, computed once before the first step)."""
    q = np.asarray(data[:, :N_QUERY])
    out = np.empty((q.shape[0], width), dtype=np.float32)
    for m in np.unique(q[:, 0]).astype(np.int64):
        sel = q[:, 0] == m
        out[sel] = transform(q[sel, 1:3], q[sel, 3], q[sel, 4:7], q[sel, 7:10], int(m))
    return out


def transformed_references(surrogate: Surrogate, data: np.ndarray) -> np.ndarray | None:
    """T(R) (rows, C) float32 of every row of ``data`` (each by its material's reference), or None."""
    if not (surrogate.residual or surrogate.residual_input):
        return None
    return _per_row(surrogate.transformed_reference, data, len(surrogate.component_names))


def transformed_probes(surrogate: Surrogate, data: np.ndarray) -> np.ndarray | None:
    """T of the texture probe (rows, n^2 C) float32 of every row of ``data``, or None without a probe."""
    if not surrogate.probe_points:
        return None
    return _per_row(surrogate.transformed_probe, data, len(surrogate.component_names) * surrogate.probe_points ** 2)


def check_reciprocal(sources, what: str, pairs: int = 64, tolerance: float = 1e-9) -> None:
    """ValueError unless every source (``source(wi, wo, centre, size)``: the references or probes of a run)
    gives the same values for (wi, wo) and (wo, wi) on ``pairs`` seeded direction pairs, within ``tolerance``
    relative to its largest value (Helmholtz reciprocity, which ``TrainSpec.reciprocal`` relies on)."""
    rng = np.random.default_rng(7411)
    xy = rng.uniform(-0.7, 0.7, (2, pairs, 2))
    wi, wo = (np.column_stack([d, np.sqrt(1.0 - np.sum(d * d, axis=1))]) for d in xy)
    centre, size = rng.random((pairs, 2)), rng.uniform(0.05, 2.0, pairs)
    for m, source in enumerate(sources or ()):
        a, b = np.asarray(source(wi, wo, centre, size)), np.asarray(source(wo, wi, centre, size))
        gap = float(np.max(np.abs(a - b)))
        if gap > tolerance * max(float(np.max(np.abs(a))), 1e-300):
            raise ValueError(f"reciprocal training needs a reciprocal model, but the {what} of material {m} "
                             f"changes by {gap:.3g} when wi and wo are swapped")


def reciprocal_rows(data: np.ndarray, train_rows: np.ndarray, data_spec: DataSpec, block: int = 262_144) -> np.ndarray:
    """(rows of ``data``,) bool: the training rows that may be swapped (wi <-> wo, the same label by Helmholtz
    reciprocity f(wi, wo) = f(wo, wi)): those whose swapped pair is a trained cell pair of ``data_spec``
    (:func:`clothlab.surrogate.data.swap_trained`), so the held-out pairs stay unseen."""
    out = np.zeros(data.shape[0], dtype=bool)
    for start in range(0, train_rows.size, block):
        rows = np.sort(train_rows[start:start + block])
        out[rows] = swap_trained(np.asarray(data[rows, :N_QUERY]), data_spec)
    return out


def swap_directions(rows: np.ndarray, flip: np.ndarray) -> np.ndarray:
    """``rows`` (a copy) with wi and wo exchanged in the rows where ``flip`` is True."""
    out = np.array(rows, copy=True)
    out[flip, 4:7], out[flip, 7:10] = rows[flip, 7:10], rows[flip, 4:7]
    return out


def _batch(surrogate: Surrogate, rows: np.ndarray, specular: np.ndarray, t_reference=None, t_probe=None):
    """Material index, features and loss-space targets of a batch; with a residual network the targets are
    T(label) - T(R), the part the network's outputs must supply (g_pred = T(R) + net, eqs. 9-11)."""
    q = np.asarray(rows[:, :N_QUERY])
    spatial, angular = surrogate.features(q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10], t_reference, t_probe)
    targets = encode_targets(np.asarray(rows[:, N_QUERY:]), specular)
    if surrogate.residual:
        targets = targets - t_reference
    return q[:, 0].astype(np.int64), spatial, angular, targets.astype(spatial.dtype)


def _save_checkpoint(path: Path, surrogate, optimizer, step, cpu_s, curve) -> None:
    arrays = {f"param/{k}": v for k, v in surrogate.network.params().items()}
    arrays |= {f"adam/{k}": v for k, v in optimizer.state().items()}
    arrays["step"], arrays["cpu_s"] = np.array(step), np.array(cpu_s)
    arrays["curve"] = np.frombuffer(json.dumps(curve).encode(), dtype=np.uint8)
    buffer = io.BytesIO()
    np.savez(buffer, allow_pickle=False, **arrays)
    atomic_write_bytes(path, buffer.getvalue())


def _load_checkpoint(path: Path, surrogate, optimizer):
    try:
        with np.load(path, allow_pickle=False) as data:
            surrogate.network.set_params({k[6:]: data[k] for k in data.files if k.startswith("param/")})
            optimizer.load_state({k[5:]: data[k] for k in data.files if k.startswith("adam/")})
            return int(data["step"]), float(data["cpu_s"]), json.loads(bytes(data["curve"]).decode())
    except (KeyError, ValueError) as exc:
        raise InputError(f"checkpoint does not fit this network ({exc}); resume with the same --width and "
                         "--spatial, or start a new directory", path=path) from None


def train(data: np.ndarray, names, materials: np.ndarray, spec: TrainSpec, *, encoding: dict | None = None,
          heldout_materials=(), checkpoint: Path | None = None, resume: bool = False,
          references=None, heldout_pattern=(), probes=None) -> TrainResult:
    """Train a surrogate on ``data`` (rows of :data:`clothlab.surrogate.data.COLUMNS` + components ``names``)
    for the materials whose encoder inputs are ``materials`` (M, n_material); ``references``: per material
    the reflectance model's label source (residual networks), ``probes`` its texture probe (probing
    networks).  ``heldout_materials`` / ``heldout_pattern``:
    material indices never trained on, scored as ``metrics["heldout_materials"]`` / ``["heldout_pattern"]``."""
    if spec.steps is None and spec.budget_s is None:
        raise ValueError("give steps or budget_s")
    surrogate = make_surrogate(spec, materials, names, encoding or {}, references, probes)
    specular = is_specular(names)
    weights = column_weights(specular).astype(np.float32)
    optimizer = Adam(surrogate.network.params(), lr=spec.lr, weight_decay=spec.weight_decay)
    split = split_rows(data, heldout_materials, heldout_pattern)
    train_rows = split["train"]
    if train_rows.size == 0:
        raise ValueError("no training rows (every row is held out)")
    step, cpu_used, curve = 0, 0.0, []
    if resume and checkpoint is not None and Path(checkpoint).exists():
        step, cpu_used, curve = _load_checkpoint(Path(checkpoint), surrogate, optimizer)
        LOG.info(f"resumed at step {step} ({cpu_used:.0f} CPU-s)")
    rng = np.random.default_rng([spec.seed, step])
    net = surrogate.network
    start = time.process_time() - cpu_used
    t_reference = transformed_references(surrogate, data)  # constants per row (inside the CPU budget)
    t_probe = transformed_probes(surrogate, data)
    surrogate.encoding["output_max"] = output_max(data, train_rows, specular)
    swappable = None
    if spec.reciprocal:
        if "data_spec" not in surrogate.encoding:
            raise ValueError("reciprocal training needs the data spec (encoding['data_spec']) for its held-out pairs")
        check_reciprocal(references, "reflectance model")
        check_reciprocal(probes, "texture probe")
        swappable = reciprocal_rows(data, train_rows, DataSpec(**surrogate.encoding["data_spec"]))

    def fraction() -> float:
        parts = []
        if spec.steps is not None:
            parts.append(step / spec.steps)
        if spec.budget_s is not None:
            parts.append((time.process_time() - start) / spec.budget_s)
        return max(parts)

    total = spec.steps if spec.steps is not None else None
    with Progress(total, "training the surrogate", unit="step") as bar, one_blas_thread():
        bar.update(step)
        while fraction() < 1.0:
            pick = np.sort(rng.choice(train_rows, size=min(spec.batch, train_rows.size), replace=False))
            rows = data[pick]
            if swappable is not None:  # T(R) and the probe are reciprocal too: their rows stay as they are
                rows = swap_directions(rows, swappable[pick] & (rng.random(pick.size) < 0.5))
            index, spatial, angular, targets = _batch(surrogate, rows, specular,
                                                      None if t_reference is None else t_reference[pick],
                                                      None if t_probe is None else t_probe[pick])
            lr = step_schedule(spec.lr, fraction(), spec.milestones, spec.gamma)
            out = net.forward(surrogate.materials, index, spatial, angular, train=True)
            loss, d_out = loss_and_gradient(out, targets, weights,
                                            highlight_weights(rows[:, N_QUERY:], specular, spec.highlight_scale))
            net.backward(d_out)
            optimizer.step(net.grads(), lr)
            step += 1
            bar.update(1)
            if step % spec.log_every == 0 or step == 1:
                curve.append({"step": step, "cpu_s": time.process_time() - start, "lr": lr, "loss": loss})
            if checkpoint is not None and step % spec.checkpoint_every == 0:
                _save_checkpoint(Path(checkpoint), surrogate, optimizer, step, time.process_time() - start, curve)
    cpu = time.process_time() - start
    if checkpoint is not None:
        _save_checkpoint(Path(checkpoint), surrogate, optimizer, step, cpu, curve)
    surrogate.reset()
    metrics = {"steps": step, "cpu_s": cpu, "rows": {k: int(v.size) for k, v in split.items()},
               "train_sample": errors_by_size(surrogate, data, train_rows[:: max(1, train_rows.size // 50000)]),
               **heldout_metrics(surrogate, data, split)}
    return TrainResult(surrogate, curve, metrics)


def heldout_metrics(surrogate: Surrogate, data: np.ndarray, split: dict[str, np.ndarray]) -> dict:
    """The sidecar's held-out figures of ``surrogate`` on the rows of ``split`` (:func:`split_rows`): relative
    RMSE by footprint size of the held-out pairs, unseen materials and unseen pattern (those present), and the
    far view (residual networks)."""
    metrics = {}
    for key in ("heldout_pairs", "heldout_materials", "heldout_pattern"):
        if split[key].size:
            metrics[key] = errors_by_size(surrogate, data, split[key])
    if surrogate.references:
        metrics["far_view"] = far_view_error(surrogate, data, split["heldout_pairs"])
        if split["heldout_pattern"].size:
            metrics["far_view_heldout_pattern"] = far_view_error(surrogate, data, split["heldout_pattern"])
    return metrics


def output_max(data: np.ndarray, rows: np.ndarray, specular: np.ndarray, block: int = 262_144) -> list[float]:
    """Per component the largest loss-space target T(label) (eqs. 9-11) over ``rows`` of ``data``: the
    surrogate's output cap (:attr:`clothlab.surrogate.surrogate.Surrogate.output_cap`)."""
    top = np.full(specular.shape, -np.inf)
    for start in range(0, rows.size, block):
        labels = np.asarray(data[np.sort(rows[start:start + block]), N_QUERY:])
        top = np.maximum(top, encode_targets(labels, specular).max(axis=0))
    return [float(t) for t in top]


def far_view_error(surrogate: Surrogate, data: np.ndarray, rows: np.ndarray, min_size: float = 4.0) -> dict:
    """Far view (footprints >= ``min_size`` tiles, issue 23 item 5): relative RMS difference of f between the
    surrogate and the rows' labels (the texture model's box average: texture MC with the whole tiles from the
    converged tile average, :mod:`clothlab.surrogate.materials`), and of the reflectance model R
    (``surrogate.references``) from the same labels and from the surrogate, on the ``rows`` with size >=
    ``min_size`` tiles."""
    block = np.asarray(data[np.sort(rows)])
    keep = block[:, 3] >= min_size
    q, truth = block[keep, :N_QUERY], block[keep, N_QUERY:]
    if not len(q):
        return {"rows": 0}
    f_pred, f_ref = np.zeros(len(q)), np.zeros(len(q))
    for m in np.unique(q[:, 0]).astype(np.int64):
        sel = q[:, 0] == m
        args = (q[sel, 1:3], q[sel, 3], q[sel, 4:7], q[sel, 7:10])
        f_pred[sel] = surrogate.query(*args, material=int(m)).sum(axis=1)
        f_ref[sel] = surrogate.references[m](args[2], args[3], args[0], args[1]).sum(axis=1)
    f_true = truth.sum(axis=1)

    def rel(a, b) -> float:
        return float(np.sqrt(np.sum((a - b) ** 2) / max(np.sum(b ** 2), 1e-300)))
    return {"rows": int(len(q)), "min_size": min_size, "relative_rms_vs_texture": rel(f_pred, f_true),
            "reflectance_vs_texture": rel(f_ref, f_true), "relative_rms_vs_reflectance": rel(f_pred, f_ref)}


def errors_by_size(surrogate: Surrogate, data: np.ndarray, rows: np.ndarray, bins=SIZE_BINS) -> list[dict]:
    """Per footprint-size bin: rows, relative RMSE and MSE of f = sum of components (module docstring)."""
    block = np.asarray(data[np.sort(rows)])
    q, truth = block[:, :N_QUERY], block[:, N_QUERY:]
    pred = np.empty_like(truth)
    for m in np.unique(q[:, 0]).astype(np.int64):
        sel = q[:, 0] == m
        pred[sel] = surrogate.query(q[sel, 1:3], q[sel, 3], q[sel, 4:7], q[sel, 7:10], material=int(m))
    f_pred, f_true = pred.sum(axis=1), truth.sum(axis=1)
    out = []
    for lo, hi in zip(bins[:-1], bins[1:], strict=True):
        sel = (q[:, 3] >= lo) & (q[:, 3] < hi)
        if not np.any(sel):
            continue
        err = np.sum(np.square(f_pred[sel] - f_true[sel]))
        out.append({"size_lo": lo, "size_hi": hi, "rows": int(sel.sum()), "mse": float(err / sel.sum()),
                    "relative_rmse": float(np.sqrt(err / max(np.sum(np.square(f_true[sel])), 1e-300))),
                    "relative_rmse_interval": relative_rmse_interval(f_pred[sel], f_true[sel])})
    return out


def relative_rmse_interval(pred: np.ndarray, truth: np.ndarray, resamples: int = 400, level: float = 0.9,
                           seed: int = 0) -> list[float]:
    """Bootstrap percentile interval (``level``, queries resampled with replacement, seeded) of the relative
    RMSE sqrt(sum (pred - truth)^2 / sum truth^2).  A few strong highlights carry most of a small-footprint
    bin's error (docs/neural.md), so the bin's figure is uncertain by far more than 1 / sqrt(rows)."""
    e2, f2 = np.square(np.asarray(pred) - np.asarray(truth)), np.square(np.asarray(truth))
    rng = np.random.default_rng(seed)
    stats = np.empty(resamples)
    for i in range(resamples):
        pick = rng.integers(0, e2.size, e2.size)
        stats[i] = np.sqrt(e2[pick].sum() / max(f2[pick].sum(), 1e-300))
    tail = 50.0 * (1.0 - level)
    return [float(x) for x in np.percentile(stats, [tail, 100.0 - tail])]
