"""Bench section ``footprint``: footprint-aggregated components (Chen, Wang & Wang 2024, eqs. 3-5) - the
estimators' speed and error side by side, the error-against-time table a neural surrogate has to beat.

For each texture kind (the registry's kinds with a texture model, on the cotton-denim weave, default
parameters, no noise) ``pairs`` random direction pairs (cos theta uniform in [cos 80 deg, 1]) each get
``footprints`` random box footprints (centres uniform in a tile; sizes log-uniform over the bins of
:data:`SIZE_BINS`, 0.01 to 5 tiles, the paper's Table 2 range).  The reference is the summed-area table at
:data:`REFERENCE_RESOLUTION` texels per tile side (exact for box footprints on its own texels; its
discretisation error is measured by the default R = 128 row against it).  Measured in one run:

- queries per second: SAT (one R = 128 table per direction pair, its build amortised over the pair's
  footprints, and the query alone) and stratified MC at 1 / 4 / 16 / 256 samples (one vectorised call);
- MSE against the reference per size bin, as a relative RMSE: sqrt(sum of squared errors / sum of squared
  reference values) over the queries of the bin and the components that vary (a constant one, IM's
  diffuse = 1/pi, is exact for every estimator and would only dilute the figure);
- the tables' discretisation error itself: SAT at R = 128 and at the reference resolution against stratified
  MC with :data:`CHECK_SAMPLES` samples on the first ``check`` queries of each size bin (MC's own error at
  that count is the floor of this figure).
"""

from __future__ import annotations

import math
import time

import numpy as np

WEAVE = "cotton-denim"
MC_SAMPLES = (1, 4, 16, 256)
RESOLUTION = 128
REFERENCE_RESOLUTION = 512
SIZE_BINS = (0.01, 0.03, 0.1, 0.3, 1.0, 5.0)  # tiles: bin edges
CHECK_SAMPLES = 4096


def _queries(rng, pairs: int, footprints: int):
    from clothlab.frames import spherical_to_vector

    lo = math.cos(math.radians(80.0))
    th = np.degrees(np.arccos(rng.uniform(lo, 1.0, (2, pairs))))
    wi = spherical_to_vector(th[0], rng.uniform(0, 360, pairs))
    wo = spherical_to_vector(th[1], rng.uniform(0, 360, pairs))
    n = pairs * footprints
    centre = rng.uniform(0.0, 1.0, (n, 2))
    size = np.exp(rng.uniform(math.log(SIZE_BINS[0]), math.log(SIZE_BINS[-1]), n))
    return wi, wo, np.repeat(np.arange(pairs), footprints), centre, size


def _relative_rmse(estimate: dict, reference: dict, rows: np.ndarray) -> float:
    """sqrt(sum of squared errors / sum of squared reference values) over the non-constant components."""
    names = [k for k in reference if np.ptp(reference[k]) > 0.0]  # IM's diffuse is 1/pi everywhere
    err = sum(float(np.sum((estimate[k][rows] - reference[k][rows]) ** 2)) for k in names)
    ref = sum(float(np.sum(reference[k][rows] ** 2)) for k in names)
    return math.sqrt(err / ref) if ref > 0 else 0.0


def footprint_benchmark(quick: bool, *, pairs: int | None = None, footprints: int | None = None,
                        kinds=None, reference_resolution: int = REFERENCE_RESOLUTION, check: int | None = None) -> dict:
    """Figures per kind: settings, one row per estimator (queries_per_second, relative_rmse by size bin),
    the SAT build time per pair and the query time, and the tables' discretisation check (``check``
    queries per bin).  ``quick``: 4 pairs x 250 footprints, 20 checked per bin, the registry's default kind
    (IM) only."""
    from clothlab.config.build import model_from_weave
    from clothlab.footprint import FootprintTable, mc_estimate
    from clothlab.models.registry import DEFAULT_KIND, MODEL_KINDS, model_class
    from clothlab.weave.presets import get_preset

    pairs = pairs or (4 if quick else 16)
    footprints = footprints or (250 if quick else 500)
    check = check or (20 if quick else 200)
    if kinds is None:
        kinds = (DEFAULT_KIND,) if quick else tuple(k for k in MODEL_KINDS if model_class(k).has_texture)
    bins = [(SIZE_BINS[i], SIZE_BINS[i + 1]) for i in range(len(SIZE_BINS) - 1)]
    out = {"settings": {"weave": WEAVE, "pairs": pairs, "footprints_per_pair": footprints,
                        "resolution": RESOLUTION, "reference_resolution": reference_resolution,
                        "size_bins_tiles": bins, "mc_samples": list(MC_SAMPLES)}, "kinds": {}}
    for kind in kinds:
        model = model_from_weave(get_preset(WEAVE), kind=kind)
        texture, params = model.texture(), model.default_parameters()
        rng = np.random.default_rng(1)
        wi, wo, pair, centre, size = _queries(rng, pairs, footprints)
        n = len(size)
        in_bin = [(size >= lo) & (size < hi) for lo, hi in bins]
        FootprintTable.build(texture, params, wi[:1], wo[:1], 8)  # warm-up (compilation, albedo tables)
        reference = FootprintTable.build(texture, params, wi, wo, reference_resolution).query(centre, size, pair=pair)

        started = time.perf_counter()
        table = FootprintTable.build(texture, params, wi, wo, RESOLUTION)
        build_s = time.perf_counter() - started
        started = time.perf_counter()
        sat = table.query(centre, size, pair=pair)
        query_s = time.perf_counter() - started
        rows = [{"estimator": f"SAT R={RESOLUTION}", "samples": None,
                 "queries_per_second": n / (build_s + query_s), "query_only_per_second": n / query_s,
                 "relative_rmse": [_relative_rmse(sat, reference, m) for m in in_bin]}]
        for samples in MC_SAMPLES:
            started = time.perf_counter()
            mean, _ = mc_estimate(texture, params, wi[pair], wo[pair], centre, size, samples=samples, seed=2)
            seconds = time.perf_counter() - started
            rows.append({"estimator": f"MC {samples}", "samples": samples, "queries_per_second": n / seconds,
                         "relative_rmse": [_relative_rmse(mean, reference, m) for m in in_bin]})
        picked = np.concatenate([np.flatnonzero(m)[:check] for m in in_bin])
        truth, _ = mc_estimate(texture, params, wi[pair[picked]], wo[pair[picked]], centre[picked], size[picked],
                               samples=CHECK_SAMPLES, seed=3)
        sub_bins = [m[picked] for m in in_bin]
        discretisation = {
            f"SAT R={RESOLUTION}": [_relative_rmse({k: v[picked] for k, v in sat.items()}, truth, m) for m in sub_bins],
            f"SAT R={reference_resolution}": [_relative_rmse({k: v[picked] for k, v in reference.items()}, truth, m)
                                             for m in sub_bins]}
        out["kinds"][kind] = {"rows": rows, "sat_build_seconds_per_pair": build_s / pairs,
                              "sat_query_seconds": query_s, "queries": n,
                              "queries_per_bin": [int(m.sum()) for m in in_bin],
                              "discretisation_vs_mc": discretisation,
                              "checked_per_bin": [int(m.sum()) for m in sub_bins]}
    return out


def run(context) -> dict:
    return footprint_benchmark(context.quick)


def lines(result: dict) -> list[str]:
    s = result["settings"]
    head = " ".join(f"{lo:g}-{hi:g}".rjust(9) for lo, hi in s["size_bins_tiles"])
    out = [f"== footprint: box-footprint averages on {s['weave']}, {s['pairs']} direction pairs x "
           f"{s['footprints_per_pair']} footprints; relative RMSE vs SAT R={s['reference_resolution']} by "
           "footprint size (tiles) =="]
    for kind, f in result["kinds"].items():
        out.append(f"  {kind}: SAT build {1e3 * f['sat_build_seconds_per_pair']:.1f} ms per direction pair, "
                   f"queries per bin {f['queries_per_bin']}")
        out.append(f"    {'estimator':<11} {'queries/s':>11} {head}")
        for row in f["rows"]:
            errors = " ".join(f"{e:9.2e}" for e in row["relative_rmse"])
            out.append(f"    {row['estimator']:<11} {row['queries_per_second']:11,.0f} {errors}")
        sat = f["rows"][0]
        out.append(f"    SAT query alone (table built): {sat['query_only_per_second']:,.0f} queries/s")
        out.append(f"    tables vs MC {CHECK_SAMPLES} ({f['checked_per_bin']} queries per bin; MC's own error is "
                   "the floor):")
        for name, errors in f["discretisation_vs_mc"].items():
            out.append(f"    {name:<11} {'':>11} " + " ".join(f"{e:9.2e}" for e in errors))
    return out
