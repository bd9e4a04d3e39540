"""Which estimator of a pixel's footprint average is cheapest at a given error (issue 23 item 4): the
per-weave crossovers that ``clothlab render --shader neural-lod`` reads from a network's sidecar.

For a box footprint of side f tiles (Chen, Wang & Wang 2024, eq. 3) four estimators compete:

* ``mc`` k: k stratified texture points over the box (k = 1 is a single texture point: the texture model
  as im-texture evaluates it; the texture is nearly constant over very small footprints, so a few points
  suffice there);
* ``surrogate``: one network query (features, R, probe, decoder);
* ``reflectance``: the reflectance model R alone (the tile average: right for footprints of many tiles).

Per footprint bin the measured relative RMSE of each (against a texture reference that does not use R) and
its CPU time per query give the choice (:func:`pick`): the cheapest estimator whose relative RMSE is at
most ``error_target``; when none is, the cheapest within 10 % of the most accurate.  The choice is stored in
the sidecar as ``estimator_choice`` (:func:`check_choice` is its schema; written by
:func:`clothlab.studies.neural_bins.measure_estimator_choice`), and :func:`estimator_at` looks a footprint
up: below the first bin the first bin's choice, above the last the last's.  A sidecar without the field
gives None: neural-lod then runs its documented default (:mod:`clothlab.render.neural_lod`).
"""

from __future__ import annotations

import numpy as np

ESTIMATORS = ("mc", "surrogate", "reflectance")
DEFAULT_ERROR_TARGET = 0.08
"""Relative RMSE of f a pixel's estimator must reach (when some candidate does).  Measured on the close-up
render (docs/neural.md, "neural-lod"; session 14, with the pixel-centred footprint): cotton denim's error at
targets 0.05 / 0.08 / 0.12 is 0.0210 / 0.0236 / 0.0332 at 0.25 / 0.15 / 0.08 shading CPU-s, against
im-lod's 0.0314 / 0.0323 / 0.0359 at the same CPU; silk charmeuse's 0.0325 / 0.0330 / 0.0499 against
0.0390 / 0.0391 / 0.0587.  Every target wins there: 0.05 by the most at 1.6x the CPU of 0.08, 0.12 the
cheapest with an 8 % margin on cotton denim; 0.08 lies between and is the shipped choices' target."""
MAX_MC_SAMPLES = 256
NEAR_BEST = 1.1
"""When no candidate meets the target: candidates within this factor of the best relative RMSE count as
equally good (a bin of a few hundred queries does not resolve finer), and the cheapest of them is taken."""


def mc_fit(samples, us, mse) -> tuple[np.ndarray, np.ndarray]:
    """MC-k's CPU time and MSE smoothed over k: time c0 + c1 k (least squares, c0, c1 >= 0), MSE a power law
    c k^-a (log-log least squares, a >= 0).  A bin of a few hundred queries is decided by a few highlights,
    so the raw MSE of neighbouring k can swap order; the fit keeps more samples never worse or cheaper."""
    k = np.asarray(samples, dtype=np.float64)
    design = np.column_stack([np.ones_like(k), k])
    c0, c1 = np.maximum(np.linalg.lstsq(design, np.asarray(us, dtype=np.float64), rcond=None)[0], 0.0)
    slope, level = np.polyfit(np.log(k), np.log(np.maximum(np.asarray(mse, dtype=np.float64), 1e-300)), 1)
    return c0 + c1 * k, np.exp(level + min(slope, 0.0) * np.log(k))


def candidates(row: dict) -> list[dict]:
    """The estimators of one measured bin (a :func:`clothlab.studies.neural_bins.bin_figures` row): MC-k from
    its plain-MC sweep (:func:`mc_fit`; relative RMSE from the MSE ratio to the surrogate's), the surrogate
    and R alone (its cost: the measured R / probe share of the query, an upper bound for a probing network),
    each {estimator, samples, us, relative_rmse}."""
    rel_s, mse_s = float(row["surrogate"]), float(row["surrogate_mse"])
    out = [{"estimator": "surrogate", "samples": 0, "us": float(row["us_per_query"]), "relative_rmse": rel_s}]
    sweep = row["mc_plain"]
    us, mse = mc_fit([m["samples"] for m in sweep], [m["us_per_query"] for m in sweep], [m["mse"] for m in sweep])
    for mc, t, e in zip(sweep, us, mse, strict=True):
        rel = rel_s * float(np.sqrt(e / mse_s)) if mse_s > 0 else float("inf")
        out.append({"estimator": "mc", "samples": int(mc["samples"]), "us": float(t), "relative_rmse": rel})
    out.append({"estimator": "reflectance", "samples": 0, "us": float(row["inputs_us"]),
                "relative_rmse": float(row["reflectance_model"])})
    return out


def pick(options: list[dict], error_target: float) -> dict:
    """The cheapest of ``options`` ({estimator, samples, us, relative_rmse}) whose relative RMSE is at most
    ``error_target``; when none is, the cheapest within :data:`NEAR_BEST` of the most accurate."""
    good = [c for c in options if c["relative_rmse"] <= error_target]
    if not good:
        best = min(c["relative_rmse"] for c in options)
        good = [c for c in options if c["relative_rmse"] <= NEAR_BEST * best]
    return min(good, key=lambda c: (c["us"], c["relative_rmse"]))


def choice_from_rows(rows, error_target: float = DEFAULT_ERROR_TARGET, measured: str = "") -> dict:
    """The sidecar field ``estimator_choice`` from measured bin rows (ascending, adjacent bins): per bin the
    pick and every candidate (so :func:`rechoose` can apply another target without measuring again)."""
    bins = []
    for row in rows:
        options = candidates(row)
        bins.append({"lo": float(row["size_lo"]), "hi": float(row["size_hi"]), **pick(options, error_target),
                     "candidates": options})
    return {"error_target": float(error_target), "measured": measured, "bins": bins}


def rechoose(choice: dict, error_target: float) -> dict:
    """``choice`` with every bin's pick made again from its stored candidates at ``error_target``."""
    bins = [{"lo": b["lo"], "hi": b["hi"], **pick(b["candidates"], error_target), "candidates": b["candidates"]}
            for b in choice["bins"]]
    return {**choice, "error_target": float(error_target), "bins": bins}


def check_choice(check, value, field: str = "estimator_choice") -> dict:
    """Schema of the sidecar field (``check``: the sidecar reader's schema object, whose ``fail`` raises an
    InputError naming the file and ``field``): an error target in (0, 10], bins in ascending order, each an
    estimator of :data:`ESTIMATORS` with samples 1..:data:`MAX_MC_SAMPLES` for ``mc``."""
    choice = check.mapping(value, field)
    check.number(choice.get("error_target"), f"{field}.error_target", 0.0, 10.0, open_lo=True)
    bins = choice.get("bins")
    if not isinstance(bins, list) or not bins or len(bins) > 64:
        check.fail(f"{field}.bins", "expected a list of 1 to 64 footprint bins")
    last = 0.0
    for i, b in enumerate(bins):
        at = f"{field}.bins[{i}]"
        check.mapping(b, at)
        lo = check.number(b.get("lo"), f"{at}.lo", 0.0, 1e6)
        hi = check.number(b.get("hi"), f"{at}.hi", 0.0, 1e6)
        if not (last <= lo < hi):
            check.fail(at, f"bins must ascend without overlap: [{lo:g}, {hi:g}) after {last:g}")
        last = hi
        if b.get("estimator") not in ESTIMATORS:
            check.fail(f"{at}.estimator", f"expected one of {', '.join(ESTIMATORS)}, got {b.get('estimator')!r:.40}")
        if b["estimator"] == "mc":
            check.integer(b.get("samples"), f"{at}.samples", 1, MAX_MC_SAMPLES)
    return choice


def estimator_at(choice: dict, footprint) -> tuple[np.ndarray, np.ndarray]:
    """(bin index, MC samples) per footprint (tiles) of a checked ``estimator_choice``: the bin holding it,
    the first below the first bin, the last above the last (and in a gap, the bin below)."""
    bins = choice["bins"]
    lo = np.array([b["lo"] for b in bins])
    f = np.asarray(footprint, dtype=np.float64)
    index = np.clip(np.searchsorted(lo, f, side="right") - 1, 0, len(bins) - 1)
    samples = np.array([int(b.get("samples") or 0) for b in bins])[index]
    return index, samples
