"""``clothlab check``: numerical stability of the IM model (Irawan & Marschner 2012, secs. 5.1-5.4) at its
numerical traps.

Three parts, returned as a dict (:func:`run_check`) with their human-readable lines (:func:`check_lines`):

1. extremes - the traps (kappa -> -1, r_hat = 0 and either side, umax -> 0 / 90 deg, psi -> 0 and
   at the filament threshold, psi -> 90 deg, beta from 1e-6 to 1e5, segments violating sec. 5.3, delta 0 /
   -> 1) swept on a grid and at random (seeded), each parameter set evaluated on many direction pairs at once
   (random pairs over the hemisphere plus special ones: normal incidence, wi = wo, mirror pairs, grazing to
   89.99999 deg, wi ~ -wo at grazing (|h| -> 0), back-facing).  Per quadrature rule: counts of
   non-finite values, negative values, non-zero back-facing values and reciprocity violations
   |f(wi, wo) - f(wo, wi)| > 1e-9 max(|f(wi, wo)|, |f(wo, wi)|), with a reproducer for the first few.
2. continuity - kappa, psi and umax swept finely; f at x and at x + eps (eps = 1e-9 of the sweep range) are
   compared per direction; the jump is |f(x + eps) - f(x)| / max_x |f| (per direction).  Jumps above
   JUMP_TOLERANCE are listed with where they happen.  Expected: at the psi filament threshold (measured
   separately) and, with delta = 0, at the filament cutoff |u| = umax (unsmoothed); anything else is a
   finding (e.g. a trapezoid node crossing a support end of the staple integrand).
3. stiff fits (``full`` only) - :func:`clothlab.studies.stiff.run_stiff`.

The full run evaluates more than 10^6 (parameter, direction) configurations per rule.

Chunked (issue 13): the extremes sweep runs as tasks of :data:`CHUNK_SETS` parameter sets (one rule, one part
each) and the continuity study as one task per (sweep, rule), on a :class:`clothlab.parallel.Runner`
(in-process by default, ``clothlab check --workers N`` / ``--scheduler``).  The chunks are fixed by the seed and
the run's sizes alone, never by the number of workers; each chunk's counts are written to a ``.npz`` file as it
finishes (:func:`write_chunk`; a rerun with the same ``chunk_dir`` reuses them) and merged in chunk order
(:func:`merge_sweeps`), so the findings equal the sequential sweep's exactly.

Verdict (``result["verdict"]``, :func:`verdict`; :func:`run_check_command` returns :func:`exit_code`): the sweep
fails when it finds any non-finite or negative value, any reciprocity violation above RECIPROCITY_RTOL relative,
or any evaluation that raised (its value is unknown); exit code 1 then, 0 otherwise.  Continuity jumps, the
psi-threshold switch and the stiff fits are findings to read, not failures.
"""

from __future__ import annotations

import itertools
import math
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from clothlab.errors import GeometryWarning

RECIPROCITY_RTOL = 1e-9
JUMP_TOLERANCE = 1e-4
RULES_CHECKED = (("trapezoid", 11), ("support", 8))
FAILING_COUNTS = ("non_finite", "negative", "reciprocity", "exceptions")
"""Sweep counts that make ``clothlab check`` fail (exit code 1) when non-zero."""


def verdict(totals: dict) -> dict:
    """{"passed": bool, "failures": {count: n} for the non-zero FAILING_COUNTS of the sweep ``totals``}."""
    failures = {key: int(totals.get(key, 0)) for key in FAILING_COUNTS if totals.get(key, 0)}
    return {"passed": not failures, "failures": failures,
            "rule": (f"fails on any non-finite or negative value, any reciprocity violation above "
                     f"{RECIPROCITY_RTOL:g} relative or any evaluation that raised")}


def exit_code(result: dict) -> int:
    """Exit status of ``clothlab check`` for a :func:`run_check` result: 0 when the sweep passed, else 1."""
    v = result.get("verdict") or verdict(result["totals"])
    return 0 if v["passed"] else 1


def check_directions(n_random: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) fabric-frame direction pairs: ``n_random`` random ones (theta up to 89.99999 deg, some
    back-facing) followed by special pairs."""
    from clothlab.frames import spherical_to_vector

    theta_i = rng.uniform(0.0, 90.0 - 1e-5, n_random)
    theta_o = rng.uniform(0.0, 90.0 - 1e-5, n_random)
    theta_i[: n_random // 20] += 90.0  # a few back-facing incident directions
    wi = spherical_to_vector(theta_i, rng.uniform(0.0, 360.0, n_random))
    wo = spherical_to_vector(theta_o, rng.uniform(0.0, 360.0, n_random))
    g = 90.0 - 1e-5
    si = [(0, 0), (30, 40), (g, 0), (g, 90), (45, 10), (60, 200), (g, 180), (g, 37), (89.9, 123), (1e-7, 0),
          (75, 90), (75, 0), (120, 0)]
    so = [(0, 0), (30, 40), (g, 180), (g, 270), (45, 190), (60, 20), (g, 0), (g, 217), (89.9, 303), (1e-7, 180),
          (75, 270), (75, 180), (10, 0)]
    wi_s = spherical_to_vector(*np.array(si, dtype=float).T)
    wo_s = spherical_to_vector(*np.array(so, dtype=float).T)
    return np.vstack([wi, wi_s]), np.vstack([wo, wo_s])


def kappa_parabola(umax_deg: float) -> float:
    """kappa with r_hat = 1 + kappa (1 + cot umax) = 0 (sec. 5.4): the ellipse / hyperbola boundary."""
    return -1.0 / (1.0 + 1.0 / math.tan(math.radians(umax_deg)))


def grid_parameter_sets(fast: bool) -> list[dict]:
    """Parameter sets (warp yarn) on a grid over the extremes of the module docstring."""
    from clothlab.models.irawan.model import PSI_FILAMENT_THRESHOLD

    edge = math.degrees(PSI_FILAMENT_THRESHOLD)
    umaxes = (1e-6, 0.5, 30.0, 90.0 - 1e-6) if not fast else (1e-6, 30.0, 90.0 - 1e-6)
    psis = (0.0, 1e-9, -edge * (1 - 1e-9), edge * (1 + 1e-9), 30.0, -(90.0 - 1e-6)) if not fast else (
        0.0, -edge * (1 - 1e-9), edge * (1 + 1e-9), 30.0)
    betas = (1e-6, 4.0, 1e4, 1e5) if not fast else (1e-6, 1e5)
    shapes = ((1.0, 1.0), (1.0, 9.0), (4.0, 1.0))  # (w, l); the last violates sec. 5.3 for umax > 14.5 deg
    deltas = (0.0, 0.5, 1.0 - 1e-9) if not fast else (0.0, 1.0 - 1e-9)
    out = []
    for umax in umaxes:
        kp = kappa_parabola(umax)
        kappas = (-1.0 + 1e-12, -1.0 + 1e-9, -0.99, kp - 1e-12, kp, kp + 1e-12, 0.0, 2.0, 1e3)
        if fast:
            kappas = (-1.0 + 1e-12, kp, 0.0, 1e3)
        for kappa, psi, beta, (w, l), delta in itertools.product(kappas, psis, betas, shapes, deltas):
            if kappa <= -1.0:
                continue
            out.append({"alpha": 0.01, "beta": beta, "delta": delta, "warp.psi": psi, "warp.umax": umax,
                        "warp.kappa": kappa, "warp.w": w, "warp.l": l})
    return out


def random_parameter_sets(n: int, rng) -> list[dict]:
    """``n`` random parameter sets over the valid ranges, log-uniform where the scale spans decades and
    with the extremes over-represented (kappa near -1, umax near 0 / 90, psi near 0)."""
    out = []
    for _ in range(n):
        kappa = -1.0 + 10.0 ** rng.uniform(-12, 0) if rng.random() < 0.4 else rng.uniform(-0.999, 50.0)
        umax = 10.0 ** rng.uniform(-6, math.log10(90.0 - 1e-6))
        psi = float(rng.choice([-1.0, 1.0])) * (10.0 ** rng.uniform(-9, 0) if rng.random() < 0.4
                                                 else rng.uniform(0.0, 90.0 - 1e-6))
        if rng.random() < 0.2:
            psi = 0.0
        out.append({"alpha": rng.uniform(0.0, 0.5), "beta": 10.0 ** rng.uniform(-6, 5),
                    "delta": rng.uniform(0.0, 1.0 - 1e-9) if rng.random() < 0.7 else 0.0, "warp.psi": psi,
                    "warp.umax": umax, "warp.kappa": kappa, "warp.w": 10.0 ** rng.uniform(-1.5, 1.5),
                    "warp.l": 10.0 ** rng.uniform(-1.5, 1.5)})
    return out


def _evaluate(wi, wo, params, rule):
    from clothlab.models.irawan.model import Quadrature, yarn_specular

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        return yarn_specular(wi, wo, params, "warp", Quadrature(*rule))


def sweep_extremes(parameter_sets, wi, wo, rule, max_examples: int = 5) -> dict:
    """Counts of non-finite, negative, non-zero back-facing values and reciprocity violations over all
    (parameter set, direction pair) configurations; the first ``max_examples`` problems as reproducers."""
    back = (wi[:, 2] <= 0.0) | (wo[:, 2] <= 0.0)
    counts = {"configurations": 0, "non_finite": 0, "negative": 0, "back_facing_nonzero": 0, "reciprocity": 0}
    worst_reciprocity = 0.0
    examples = []
    for params in parameter_sets:
        try:
            forward = _evaluate(wi, wo, params, rule)
            backward = _evaluate(wo, wi, params, rule)
        except Exception as error:  # noqa: BLE001 - an exception is a finding, reported with its reproducer
            counts.setdefault("exceptions", 0)
            counts["exceptions"] += 1
            if len(examples) < max_examples:
                examples.append({"kind": "exception", "params": params, "error": repr(error)})
            continue
        counts["configurations"] += len(wi)
        bad = {"non_finite": ~np.isfinite(forward), "negative": forward < 0.0,
               "back_facing_nonzero": back & (forward != 0.0)}
        scale = np.maximum(np.abs(forward), np.abs(backward))
        with np.errstate(invalid="ignore"):
            rel = np.where(scale > 0.0, np.abs(forward - backward) / np.where(scale > 0.0, scale, 1.0), 0.0)
        rel = np.where(np.isfinite(forward) & np.isfinite(backward) & np.isfinite(rel), rel, np.inf)
        bad["reciprocity"] = rel > RECIPROCITY_RTOL
        finite_rel = rel[np.isfinite(rel)]
        worst_reciprocity = max(worst_reciprocity, float(finite_rel.max(initial=0.0)))
        for key, mask in bad.items():
            hits = np.flatnonzero(mask)
            counts[key] += hits.size
            if hits.size and len(examples) < max_examples:
                i = int(hits[0])
                examples.append({"kind": key, "params": params, "wi": wi[i].tolist(), "wo": wo[i].tolist(),
                                 "value": float(forward[i]), "swapped": float(backward[i])})
    return {**counts, "worst_reciprocity_rel": worst_reciprocity, "examples": examples}


CHUNK_SETS = 1024
"""Parameter sets per extremes task (the fast check is one task per rule and part)."""
_COUNT_KEYS = ("configurations", "non_finite", "negative", "back_facing_nonzero", "reciprocity", "exceptions")


def merge_sweeps(parts, max_examples: int = 5) -> dict:
    """One :func:`sweep_extremes` result from those of consecutive chunks of its parameter sets, in order:
    counts summed, the worst reciprocity the largest, the first ``max_examples`` reproducers (exactly the
    sequential sweep's result)."""
    merged = {key: sum(int(p.get(key, 0)) for p in parts) for key in _COUNT_KEYS}
    if not any("exceptions" in p for p in parts):
        del merged["exceptions"]  # as sweep_extremes: the key only when an evaluation raised
    examples = [ex for p in parts for ex in p["examples"]][:max_examples]
    return {**merged, "worst_reciprocity_rel": max(float(p["worst_reciprocity_rel"]) for p in parts),
            "examples": examples}


def _sweep_task(directions, job):
    """One extremes chunk (a Runner task): ``job`` = (rule, parameter sets)."""
    rule, sets = job
    return sweep_extremes(sets, *directions, rule)


def chunk_key(rule, part: str, index: int, sets, wi, wo) -> str:
    """File stem of one extremes chunk: rule, part, index and a digest of its inputs (a changed sweep never
    reuses an old chunk file)."""
    import hashlib
    import json

    from clothlab import __version__

    digest = hashlib.sha256(json.dumps([__version__, list(rule), sets], sort_keys=True).encode()
                            + np.ascontiguousarray(wi).tobytes() + np.ascontiguousarray(wo).tobytes())
    return f"extremes-{rule[0]}-{rule[1]}-{part}-{index:04d}-{digest.hexdigest()[:16]}"


def write_chunk(path: Path, counts: dict) -> None:
    """One chunk's :func:`sweep_extremes` result as ``.npz`` (counts as integers, the reproducers as JSON),
    written atomically."""
    import io
    import json

    from clothlab.atomic import atomic_write_bytes

    buffer = io.BytesIO()
    np.savez(buffer, **{k: np.int64(counts[k]) for k in _COUNT_KEYS if k in counts},
             worst_reciprocity_rel=np.float64(counts["worst_reciprocity_rel"]),
             examples=np.array(json.dumps(counts["examples"], default=float)))
    atomic_write_bytes(path, buffer.getvalue())


def read_chunk(path: Path) -> dict:
    """A chunk written by :func:`write_chunk`, as the :func:`sweep_extremes` result it holds."""
    import json

    with np.load(path) as data:
        out = {k: int(data[k]) for k in _COUNT_KEYS if k in data.files}
        out["worst_reciprocity_rel"] = float(data["worst_reciprocity_rel"])
        out["examples"] = json.loads(str(data["examples"]))
    return out


def sweep_chunked(jobs, wi, wo, runner, chunk_dir: Path) -> dict:
    """:func:`sweep_extremes` of every (label, rule, part, parameter sets) in ``jobs`` as chunks of
    :data:`CHUNK_SETS` sets on ``runner``; each chunk lands in ``chunk_dir`` as it finishes and chunks found
    there already are reused.  Returns {label: {part: merged result}}."""
    from clothlab.parallel import raise_failures

    chunk_dir = Path(chunk_dir)
    chunk_dir.mkdir(parents=True, exist_ok=True)
    chunks = []  # (label, part, path, rule, sets)
    for label, rule, part, sets in jobs:
        for index, start in enumerate(range(0, max(len(sets), 1), CHUNK_SETS)):
            piece = sets[start:start + CHUNK_SETS]
            chunks.append((label, part, chunk_dir / f"{chunk_key(rule, part, index, piece, wi, wo)}.npz", rule,
                           piece))
    todo = [c for c in chunks if not c[2].exists()]

    def landed(i, counts):
        if isinstance(counts, dict):
            write_chunk(todo[i][2], counts)

    raise_failures(runner.map(_sweep_task, [(c[3], c[4]) for c in todo], shared=(wi, wo),
                              names=[c[2].stem for c in todo], desc="check: extremes", on_result=landed),
                   "check chunks")
    out: dict = {}
    for label, part, path, _, _ in chunks:
        out.setdefault(label, {}).setdefault(part, []).append(read_chunk(path))
    return {label: {part: merge_sweeps(p) for part, p in parts.items()} for label, parts in out.items()}


def _refine_jump(base, name, lo, hi, f_lo, f_hi, wi, wo, rule, width):
    """Bisect [lo, hi] on one direction pair, keeping the half with the larger change, until it is
    narrower than ``width``; returns (x, |f(x + width) - f(x)|)."""
    while hi - lo > width:
        mid = 0.5 * (lo + hi)
        f_mid = _evaluate(wi, wo, {**base, name: mid}, rule)[0]
        if abs(f_mid - f_lo) >= abs(f_hi - f_mid):
            hi, f_hi = mid, f_mid
        else:
            lo, f_lo = mid, f_mid
    return lo, abs(f_hi - f_lo)


def continuity_sweeps(fast: bool) -> list[tuple]:
    """(label, base parameters, swept name, lo, hi, expected-jump description) of the continuity study."""
    staple = {"alpha": 0.01, "beta": 4.0, "delta": 0.3, "warp.psi": -30.0, "warp.umax": 30.0, "warp.kappa": 0.0,
              "warp.w": 1.0, "warp.l": 3.0}
    filament = {**staple, "warp.psi": 0.0}
    tight = {"warp.w": 2.0, "warp.l": 1.0}  # w sin(umax) = l at umax = 30 deg (sec. 5.3)
    return [
        ("kappa, staple", staple, "warp.kappa", -0.999, 4.0, None),
        ("kappa, filament", filament, "warp.kappa", -0.999, 4.0, None),
        ("psi across the filament threshold", staple, "warp.psi", -2.0, 2.0, "psi threshold"),
        ("psi, staple range", staple, "warp.psi", -60.0, -5.0, None),
        ("umax, staple, segment limit at 30 deg", {**staple, **tight}, "warp.umax", 0.5, 89.5, "sec. 5.3"),
        ("umax, filament delta 0.3, limit at 30 deg", {**filament, **tight}, "warp.umax", 0.5, 89.5, "sec. 5.3"),
        ("umax, filament delta 0 (unsmoothed cutoff)", {**filament, "delta": 0.0}, "warp.umax", 0.5, 89.5,
         "filament cutoff |u| = umax"),
    ]


def continuity_study(fast: bool, wi, wo, rules=RULES_CHECKED, refine: int = 12, runner=None) -> list[dict]:
    """Discontinuities in the swept parameter, per sweep and rule (one :func:`continuity_row` each, as tasks
    on ``runner`` when given).

    The parameter is swept on a grid of K points; per direction the grid steps whose change is at least
    JUMP_TOLERANCE of max_x |f| and 3x the larger neighbouring step are candidates; the ``refine`` largest are
    bisected down to eps = 1e-9 of the range, and the jump |f(x + eps) - f(x)| / max_x |f| is measured there.
    A continuous function gives ~eps |f'| / max |f| (tiny); a discontinuity keeps its size."""
    jobs = [(sweep, rule, 120 if fast else 1000, refine) for sweep in continuity_sweeps(fast) for rule in rules]
    if runner is None:
        return [continuity_row((wi, wo), job) for job in jobs]
    from clothlab.parallel import raise_failures

    return raise_failures(runner.map(continuity_row, jobs, shared=(wi, wo), desc="check: continuity",
                                     names=[f"{job[0][0]}, {job[1][0]}-{job[1][1]}" for job in jobs]),
                          "continuity sweeps")


def continuity_row(directions, job) -> dict:
    """One row of :func:`continuity_study`: ``job`` = (sweep of :func:`continuity_sweeps`, rule, grid points K,
    refine), ``directions`` = (wi, wo)."""
    from clothlab.frames import vector_to_spherical

    wi, wo = directions
    (label, base, name, lo, hi, expected), rule, k, refine = job
    xs = np.linspace(lo, hi, k)
    eps = 1e-9 * (hi - lo)
    f = np.array([_evaluate(wi, wo, {**base, name: x}, rule) for x in xs])  # (K, M)
    scale = np.maximum(np.abs(f).max(axis=0), 1e-300)
    step = np.abs(np.diff(f, axis=0)) / scale  # (K-1, M)
    padded = np.pad(step, ((1, 1), (0, 0)))
    neighbours = np.maximum(padded[:-2], padded[2:])
    candidate = (step > JUMP_TOLERANCE) & (step > 3.0 * neighbours)
    idx = np.argwhere(candidate)
    order = np.argsort(-step[candidate])[:refine]
    jumps = []
    for kk, mm in idx[order]:
        x, size = _refine_jump(base, name, xs[kk], xs[kk + 1], f[kk, mm], f[kk + 1, mm],
                               wi[mm:mm + 1], wo[mm:mm + 1], rule, eps)
        jumps.append((size / scale[mm], x, mm))
    real = [j for j in jumps if j[0] > JUMP_TOLERANCE]
    row = {"sweep": label, "parameter": name, "rule": f"{rule[0]}-{rule[1]}", "expected": expected,
           "points": k, "eps": eps, "candidates": int(candidate.sum()), "refined": len(jumps),
           "jumps": len(real), "largest_jump": 0.0, "at": None, "direction_deg": None}
    if jumps:
        size, x, mm = max(jumps)
        ti, pi_ = vector_to_spherical(wi[mm:mm + 1])
        to, po = vector_to_spherical(wo[mm:mm + 1])
        row.update({"largest_jump": float(size), "at": float(x),
                    "direction_deg": [round(float(v), 4) for v in (ti[0], pi_[0], to[0], po[0])],
                    "jump_locations": sorted({round(float(j[1]), 6) for j in real})[:10]})
    return row


def psi_threshold_jump(wi, wo, rules=RULES_CHECKED + (("support", 32),)) -> list[dict]:
    """The staple/filament switch at each rule's own threshold (:func:`clothlab.models.irawan.yarn.staple_path`:
    PSI_FILAMENT_THRESHOLD for support-aware rules, half the node spacing for fixed-node rules): relative change
    of f across it (psi = threshold (1 -/+ 1e-9)), per direction over the front-facing pairs with a significant
    value."""
    from clothlab.models.irawan.model import PSI_FILAMENT_THRESHOLD

    base = {"alpha": 0.01, "beta": 4.0, "delta": 0.0, "warp.psi": 0.0, "warp.umax": 30.0, "warp.kappa": 0.0,
            "warp.w": 1.0, "warp.l": 3.0}
    out = []
    for rule in rules:
        edge = math.degrees(PSI_FILAMENT_THRESHOLD)
        if rule[0] in ("trapezoid", "gauss"):
            edge = max(edge, base["warp.umax"] / max(rule[1] - 1, 1))
        below = _evaluate(wi, wo, {**base, "warp.psi": edge * (1 - 1e-9)}, rule)
        above = _evaluate(wi, wo, {**base, "warp.psi": edge * (1 + 1e-9)}, rule)
        sig = np.maximum(below, above) > 1e-3 * max(below.max(), above.max(), 1e-300)
        rel = np.abs(above - below)[sig] / np.maximum(below, above)[sig]
        out.append({"rule": f"{rule[0]}-{rule[1]}", "threshold_deg": edge, "directions": int(sig.sum()),
                    "median_rel": float(np.median(rel)) if rel.size else 0.0,
                    "p80_rel": float(np.percentile(rel, 80)) if rel.size else 0.0,
                    "max_rel": float(rel.max()) if rel.size else 0.0,
                    "sum_below": float(below.sum()), "sum_above": float(above.sum())})
    return out


PARTS = ("extremes", "continuity", "psi_threshold", "stiff", "verdict")
"""The parts of :func:`run_check`, in order (``stiff`` in the full run only)."""


def run_check(full: bool = False, seed: int = 0, figures_dir=None, on_part=None, runner=None,
              chunk_dir=None) -> dict:
    """Run the stability study (fast subset by default, ``full`` for >= 10^6 configurations per rule and
    the stiff fits) and return its findings.  ``on_part(name, result)`` is called as each part of
    :data:`PARTS` finishes (``"start"`` first, with the run's sizes).  ``runner``: where the extremes chunks and
    continuity sweeps run (default in-process); ``chunk_dir``: where the chunk files go (default a temporary
    directory, removed after the merge; a kept one is reused by a rerun)."""
    import contextlib
    import tempfile

    from clothlab.parallel import InProcessRunner

    with contextlib.ExitStack() as stack:
        if chunk_dir is None:
            chunk_dir = stack.enter_context(tempfile.TemporaryDirectory(prefix="clothlab-check-"))
        return _run_check(full, seed, figures_dir, on_part, runner or InProcessRunner(), Path(chunk_dir),
                          parallel=runner is not None)


def _run_check(full, seed, figures_dir, on_part, runner, chunk_dir, parallel) -> dict:
    def done(name):
        if on_part is not None:
            on_part(name, result)

    started = time.perf_counter()
    rng = np.random.default_rng(seed)
    wi, wo = check_directions(200 if full else 40, rng)
    grid = grid_parameter_sets(fast=not full)
    random_sets = random_parameter_sets(4000 if full else 150, rng)
    result = {"full": full, "seed": seed, "directions": len(wi), "grid_sets": len(grid),
              "random_sets": len(random_sets), "extremes": {}}
    done("start")
    jobs = [(f"{rule[0]}-{rule[1]}", rule, part, sets) for rule in RULES_CHECKED
            for part, sets in (("grid", grid), ("random", random_sets))]
    result["extremes"] = sweep_chunked(jobs, wi, wo, runner, chunk_dir)
    totals = {"configurations": 0, "non_finite": 0, "negative": 0, "back_facing_nonzero": 0, "reciprocity": 0,
              "exceptions": 0}
    for parts in result["extremes"].values():
        for part in parts.values():
            for key in totals:
                totals[key] += part.get(key, 0)
    result["totals"] = totals
    done("extremes")
    cwi, cwo = check_directions(60 if full else 24, np.random.default_rng(seed + 1))
    front = (cwi[:, 2] > 0) & (cwo[:, 2] > 0)
    cwi, cwo = cwi[front], cwo[front]
    result["continuity"] = continuity_study(not full, cwi, cwo, runner=runner if parallel else None)
    done("continuity")
    result["psi_threshold"] = psi_threshold_jump(*check_directions(400, np.random.default_rng(seed + 2)))
    done("psi_threshold")
    if full:
        from clothlab.studies.stiff import run_stiff

        result["stiff"] = run_stiff(seed=seed, figures_dir=figures_dir)
        done("stiff")
    result["verdict"] = verdict(totals)
    result["wall_time_s"] = time.perf_counter() - started
    done("verdict")
    return result


def part_lines(name: str, result: dict) -> list[str]:
    """The human-readable lines of one part of a (possibly partial) :func:`run_check` result."""
    if name == "start":
        return [f"clothlab check ({'full' if result['full'] else 'fast subset'}, seed {result['seed']}): "
                f"{result['grid_sets']} grid + {result['random_sets']} random parameter sets x "
                f"{result['directions']} direction pairs per rule"]
    if name == "extremes":
        out = ["", "== extreme inputs ==",
               f"  {'rule':13s} {'part':6s} {'configs':>9s} {'non-fin':>7s} {'neg':>5s} {'back':>5s} {'recip':>6s} "
               f"{'exc':>4s} {'worst recip rel':>15s}"]
        for label, parts in result["extremes"].items():
            for part, c in parts.items():
                out.append(f"  {label:13s} {part:6s} {c['configurations']:9,d} {c['non_finite']:7d} "
                           f"{c['negative']:5d} {c['back_facing_nonzero']:5d} {c['reciprocity']:6d} "
                           f"{c.get('exceptions', 0):4d} {c['worst_reciprocity_rel']:15.2e}")
                out += [f"      reproducer ({ex['kind']}): {ex}" for ex in c["examples"]]
        t = result["totals"]
        out.append(f"  total: {t['configurations']:,d} configurations; non-finite {t['non_finite']}, negative "
                   f"{t['negative']}, back-facing non-zero {t['back_facing_nonzero']}, reciprocity > "
                   f"{RECIPROCITY_RTOL:g} relative {t['reciprocity']}, exceptions {t['exceptions']}")
        return out
    if name == "continuity":
        out = ["", f"== continuity (jump = |f(x + eps) - f(x)| / max_x |f| per direction; tolerance "
               f"{JUMP_TOLERANCE:g}) ==",
               f"  {'sweep':44s} {'rule':13s} {'cand.':>6s} {'jumps':>6s} {'largest':>9s} {'at':>10s}  expected; "
               "direction (theta_i, phi_i, theta_o, phi_o)"]
        for r in result["continuity"]:
            at = "-" if r["at"] is None else f"{r['at']:.6g}"
            out.append(f"  {r['sweep']:44s} {r['rule']:13s} {r['candidates']:6d} {r['jumps']:6d} "
                       f"{r['largest_jump']:9.2e} {at:>10s}  {r['expected'] or '-'}; {r['direction_deg']}")
        return out
    if name == "psi_threshold":
        out = ["", "== staple/filament switch at |psi| = threshold (relative change across it, significant values) =="]
        for r in result["psi_threshold"]:
            out.append(f"  {r['rule']:13s} at {r['threshold_deg']:.4g} deg {r['directions']:4d} directions: "
                       f"median {r['median_rel']:.2e}, 80th {r['p80_rel']:.2e}, max {r['max_rel']:.2e}; sum below "
                       f"{r['sum_below']:.5g}, above {r['sum_above']:.5g}")
        return out
    if name == "stiff":
        from clothlab.studies.stiff import stiff_lines

        return stiff_lines(result["stiff"])
    if name == "verdict":
        v = result.get("verdict") or verdict(result["totals"])
        reason = (", ".join(f"{k.replace('_', '-')} {n}" for k, n in v["failures"].items()) if v["failures"] else
                  f"no non-finite or negative value, no reciprocity violation above {RECIPROCITY_RTOL:g} relative, "
                  "no exception")
        return ["", f"verdict: {'PASS' if v['passed'] else 'FAIL'} ({reason})",
                f"(check took {result['wall_time_s']:.1f} s)"]
    raise ValueError(f"unknown check part {name!r}; choose from start, {', '.join(PARTS)}")


def check_lines(result: dict) -> list[str]:
    """All lines of a finished :func:`run_check` result."""
    return [line for name in ("start", *PARTS) if name != "stiff" or "stiff" in result
            for line in part_lines(name, result)]


def run_check_command(*, full: bool, seed: int, data_dir: Path | None, output: Path | None,
                      json_path: Path | None, emit: Callable[[str], None], runner=None) -> int:
    """``clothlab check``: run :func:`run_check`, hand its lines to ``emit`` as each part finishes, write the
    findings as JSON to ``json_path`` and, with ``output``, an HTML page (and the JSON) into that directory.
    Returns :func:`exit_code` (1 when the sweep found a problem).  ``data_dir`` is accepted for symmetry with
    ``clothlab bench`` and not needed: every data set of the check is simulated in the run.  ``runner``: as in
    :func:`run_check`."""
    del data_dir

    def on_part(name, partial):
        for line in part_lines(name, partial):
            emit(line)

    result = run_check(full=full, seed=seed, figures_dir=output, on_part=on_part, runner=runner)
    if json_path is not None:
        import json

        from clothlab.atomic import atomic_write_text

        atomic_write_text(json_path, json.dumps(result, indent=1, default=float) + "\n")
        emit(f"results written to {json_path}")
    if output is not None:
        from clothlab.report.study_pages import write_study_report

        output = Path(output)
        page = write_study_report(result, output, title="clothlab check: numerical stability and stiff fits",
                                  figures=sorted(output.glob("*.png")) if output.is_dir() else ())
        emit(f"report: {page}")
    return exit_code(result)
