"""Bench section ``render``: the receding plane, and the IM and Kang shaders timed in one scene.

:func:`render_benchmark` renders a flat cotton-denim patch seen at 45 deg elevation from a sequence of
distances.  Per distance and shader (im-lod, im-texture = always texture, kang-lod, kang-texture, 4 samples
per pixel): the relative L1 error against the supersampled texture-level shader of the same family (64
stratified samples), and the cost of the image twice over:

- **model evaluations** per image (texture-model points + reflectance-model points for IM, Kang points for
  Kang).  They are deterministic - the same scene gives the same counts on every run and machine - so they
  carry the trend.  A reflectance point costs about twice a texture point (its quadrature over the yarn;
  the measured microseconds per point of each model are in the settings);
- **time**: the shading CPU time of this process (``time.process_time``: other load on a shared machine
  disturbs it far less than the wall clock), least of up to ``repeats`` renders, on an image large enough
  to time (128 x 96 in the full run); the wall-clock shading and total times of that render are listed
  too.  Times still wander by ~10 %; no trend is claimed from them beyond "LoD is faster far away than
  near, and than always-texture there".

Stated results, checked by the benchmark (and by tests/test_render.py at a tiny resolution):

- **error bound**: the im-lod image's error is at most :data:`ERROR_BOUND` at *every* distance;
- **cost trend**: from the first distance at which no pixel is left in the pure texture range (the smallest
  footprint exceeds f0) on, the im-lod model evaluations per image never increase with distance
  (``lod_cost_falls``); where every footprint exceeds f1 they are one reflectance evaluation per pixel and
  no texture evaluation (1/spp of always-texture's count).  Nearer than that, LoD does the texture work of
  always-texture plus one reflectance evaluation per blend pixel where blend pixels appear, so it costs
  more than always-texture there (blend pixels run the texture at about (1 - b) of their samples,
  :func:`clothlab.render.shade.blend_texture_samples`, so this extra cost is gone by mid-blend);
- **time** (``lod_time_falls``): the LoD shading CPU time at the farthest distance is below that at the
  nearest and below always-texture's at the farthest.

Result rows are flat dicts of scalars (``<shader>_<figure>``, e.g. ``im_lod_relative_error``) so that the
HTML page of ``clothlab bench --report`` shows every figure.  With ``figures_dir`` a PNG plot of error,
evaluations and time against distance is written there (``render_lod.png``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from clothlab.render.render import compare_lod
from clothlab.render.scene import scene_from_dict
from clothlab.render.shade import SAMPLE_COUNTERS, FabricModels

#: bound on the relative L1 error of im-lod against the supersampled reference, at every distance
ERROR_BOUND = 0.15
SHADERS = ("im-lod", "im-texture", "kang-lod", "kang-texture")
FULL_DISTANCES = (5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0)
QUICK_DISTANCES = (2.5, 10.0, 40.0, 160.0, 640.0)
#: figures copied into each flat row per shader
SHADER_FIGURES = ("relative_error", "model_evaluations", "texture_evaluations", "reflectance_evaluations",
                  "kang_evaluations", "neural_evaluations", "shading_cpu_seconds", "shading_seconds", "seconds", "runs",
                  "texture_pixel_fraction",
                  "blend_pixel_fraction")

RECEDING_PLANE = {
    "patch": {"shape": "flat", "size_mm": [4000, 4000], "tile_mm": [1.0, 2.0], "warp_angle_deg": 0},
    "camera": {"position": [0, -40, 40], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 30,
               "resolution": [96, 72]},
    "light": {"type": "directional", "direction": [0.3, -0.2, 1.0], "intensity": 1.0},
    "fabric": {"weave": "preset:cotton-denim", "seed": 0},
    "render": {"spp": 4, "seed": 1},
}


def receding_plane_scene(resolution=(96, 72)):
    """The benchmark scene (the same as measurements/scenes/receding_plane.yaml) at ``resolution``."""
    data = {**RECEDING_PLANE, "camera": {**RECEDING_PLANE["camera"], "resolution": list(resolution)}}
    return scene_from_dict(data, source=None)


def _key(shader: str) -> str:
    return shader.replace("-", "_")


def flat_rows(rows: list[dict], shaders=SHADERS) -> list[dict]:
    """:func:`compare_lod` rows as flat dicts of scalars: the view's figures and ``<shader>_<figure>``."""
    out = []
    for row in rows:
        flat = {k: v for k, v in row.items() if not isinstance(v, dict)}
        for shader in shaders:
            for name in SHADER_FIGURES:
                flat[f"{_key(shader)}_{name}"] = row[shader][name]
        out.append(flat)
    return out


def lod_trend(rows: list[dict], f0: float, f1: float, shader: str = "im-lod", texture: str = "im-texture") -> dict:
    """The cost and error statements of the module docstring, checked on flat rows."""
    k, t = _key(shader), _key(texture)
    cost = [r[f"{k}_model_evaluations"] for r in rows]
    start = next((i for i, r in enumerate(rows) if r["footprint_min_tiles"] > f0), None)
    tail = [] if start is None else list(range(start, len(rows)))
    far = [i for i in range(len(rows)) if rows[i]["footprint_min_tiles"] >= f1]
    errors = [r[f"{k}_relative_error"] for r in rows]
    times = [r[f"{k}_shading_cpu_seconds"] for r in rows]
    return {
        "error_max": max(errors),
        "within_bound": all(e <= ERROR_BOUND for e in errors),
        "trend_from_mm": None if start is None else rows[start]["distance_mm"],
        "cost_non_increasing": bool(tail) and all(cost[i + 1] <= cost[i] for i in tail[:-1]),
        "evaluations_below_texture_from_mm": next(
            (rows[i]["distance_mm"] for i in range(len(rows))
             if all(cost[j] < rows[j][f"{t}_model_evaluations"] for j in range(i, len(rows)))), None),
        "far_one_reflectance_per_pixel": all(
            rows[i][f"{k}_texture_evaluations"] == 0 and rows[i][f"{k}_reflectance_evaluations"] > 0 for i in far),
        "cost_ratio_far_vs_near": cost[-1] / cost[0] if cost[0] else float("nan"),
        "time_ratio_far_vs_near": times[-1] / times[0] if times[0] else float("nan"),
        "time_far_below_texture": times[-1] < rows[-1][f"{t}_shading_cpu_seconds"],
    }


def render_benchmark(quick: bool = False, *, figures_dir=None, resolution=None, distances=None, spp: int = 4,
                     reference_spp: int | None = None, repeats: int | None = None, shaders=SHADERS) -> dict:
    """Receding-plane figures: {'settings', 'rows' (flat), 'error_bound', 'within_bound',
    'lod_cost_falls', 'lod_time_falls', 'trend', 'figure'}; ``quick``: a smaller image and fewer distances (a
    few seconds).  ``figures_dir``: also write ``render_lod.png`` there.  The other arguments override the
    mode's settings (tests use a tiny image)."""
    resolution = tuple(resolution or ((32, 24) if quick else (128, 96)))
    distances = tuple(distances or (QUICK_DISTANCES if quick else FULL_DISTANCES))
    reference_spp = reference_spp or (16 if quick else 64)
    repeats = repeats or (3 if quick else 5)
    scene = receding_plane_scene(resolution)
    nested = compare_lod(scene, distances, shaders=shaders, spp=spp, reference_spp=reference_spp,
                         repeats=repeats, repeat_budget_s=1.5)
    rows = flat_rows(nested, shaders)
    trend = lod_trend(rows, scene.lod.f0, scene.lod.f1) if {"im-lod", "im-texture"} <= set(shaders) else {}
    per_point = {}
    for model in SAMPLE_COUNTERS:  # texture, reflectance and the self-filtering shader's kind
        points = sum(r[s][f"{model}_evaluations"] for r in nested for s in shaders)
        seconds = sum(r[s][f"{model}_cpu_seconds"] for r in nested for s in shaders)
        per_point[f"{model}_us_per_point"] = 1e6 * seconds / points if points else float("nan")
    result = {
        "settings": {"scene": "receding plane, cotton denim, tile 1 x 2 mm, 45 deg elevation",
                     "width_px": resolution[0], "height_px": resolution[1], "spp": spp,
                     "reference_spp": reference_spp, "repeats": repeats, "lod_f0_tiles": scene.lod.f0,
                     "lod_f1_tiles": scene.lod.f1, "error": "relative L1 vs the same family's texture-level "
                     f"shader at {reference_spp} spp, fully covered pixels",
                     "cost": "model evaluations per image (texture + reflectance points; Kang points)",
                     "time": f"least shading CPU seconds of up to {repeats} renders", **per_point},
        "rows": rows,
        "error_bound": ERROR_BOUND,
        "within_bound": trend.get("within_bound"),
        "lod_cost_falls": bool(trend.get("cost_non_increasing") and trend.get("far_one_reflectance_per_pixel")),
        "lod_time_falls": bool(trend.get("time_ratio_far_vs_near", 1.0) < 1.0 and trend.get("time_far_below_texture")),
        "trend": trend,
    }
    if figures_dir is not None and trend:
        result["figure"] = str(plot_render_benchmark(result, Path(figures_dir) / "render_lod.png"))
    return result


def run(context) -> dict:
    return render_benchmark(quick=context.quick, figures_dir=context.figures_dir)


def lines(result: dict) -> list[str]:
    """The receding-plane table and the checked statements."""
    s, t = result["settings"], result["trend"]
    out = [f"== render LoD: {s['scene']}; {s['width_px']} x {s['height_px']} px, {s['spp']} spp; reference: "
           f"texture level at {s['reference_spp']} spp; f0 = {s['lod_f0_tiles']:g}, f1 = {s['lod_f1_tiles']:g} "
           "tiles ==",
           f"  err: relative L1 vs the reference; evals: model evaluations per image (thousands); ms: {s['time']} "
           f"(ms); us/point: texture {s['texture_us_per_point']:.2f}, reflectance "
           f"{s['reflectance_us_per_point']:.2f}, Kang {s['kang_us_per_point']:.2f}",
           f"  {'dist mm':>7} {'footprint':>13} | {'err LoD':>7} {'err tex':>7} {'evals LoD':>9} {'(tex+refl)':>13} "
           f"{'evals tex':>9} {'ms LoD':>6} {'ms tex':>6} {'tex px':>6} | {'err KLoD':>8} {'err KTex':>8} "
           f"{'ms KLoD':>7} {'ms KTex':>7}"]
    for r in result["rows"]:
        tex_refl = f"{r['im_lod_texture_evaluations'] / 1e3:.1f}+{r['im_lod_reflectance_evaluations'] / 1e3:.1f}"
        out.append(f"  {r['distance_mm']:7g} {r['footprint_min_tiles']:6.3f}-{r['footprint_max_tiles']:<6.3g} | "
                   f"{r['im_lod_relative_error']:7.3f} {r['im_texture_relative_error']:7.3f} "
                   f"{r['im_lod_model_evaluations'] / 1e3:9.1f} {'(' + tex_refl + ')':>13} "
                   f"{r['im_texture_model_evaluations'] / 1e3:9.1f} {1e3 * r['im_lod_shading_cpu_seconds']:6.1f} "
                   f"{1e3 * r['im_texture_shading_cpu_seconds']:6.1f} "
                   f"{100 * r['im_lod_texture_pixel_fraction']:5.1f}% | "
                   f"{r['kang_lod_relative_error']:8.3f} {r['kang_texture_relative_error']:8.3f} "
                   f"{1e3 * r['kang_lod_shading_cpu_seconds']:7.1f} {1e3 * r['kang_texture_shading_cpu_seconds']:7.1f}")
    out.append(f"  LoD error <= {result['error_bound']:g} at every distance: {result['within_bound']} "
               f"(max {t['error_max']:.3f}); from {t['trend_from_mm']} mm on (no pixel left in the texture range) "
               f"LoD evaluations never increase: {t['cost_non_increasing']}; fewer evaluations than always-texture "
               f"from {t['evaluations_below_texture_from_mm']} mm on; far/near evaluations "
               f"{t['cost_ratio_far_vs_near']:.2f}, shading time {t['time_ratio_far_vs_near']:.2f}; far LoD faster "
               f"than always-texture: {t['time_far_below_texture']}")
    if "figure" in result:
        out.append(f"  plot: {result['figure']}")
    return out


def plot_render_benchmark(result: dict, path) -> Path:
    """PNG: error, model evaluations and shading time against distance, LoD vs always-texture, IM and Kang."""
    from matplotlib.figure import Figure

    from clothlab.atomic import atomic_write_bytes

    rows = result["rows"]
    d = [r["distance_mm"] for r in rows]
    styles = {"kang-lod": ("C3", "-", "o", "Kang LoD"), "kang-texture": ("C3", "--", "s", "Kang full detail"),
              "im-lod": ("C0", "-", "o", "IM LoD"), "im-texture": ("C0", "--", "s", "IM always texture")}
    figure = Figure(figsize=(13.5, 4.0), layout="constrained")
    axes = figure.subplots(1, 3)
    panels = (("relative_error", 1.0, "relative L1 error vs reference"),
              ("model_evaluations", 1e-3, "model evaluations per image (thousands)"),
              ("shading_cpu_seconds", 1e3, "shading CPU time (ms, least of runs)"))
    for ax, (name, scale, label) in zip(axes, panels, strict=True):
        for shader, (colour, line, marker, text) in styles.items():
            key = f"{_key(shader)}_{name}"
            if key in rows[0]:
                ax.plot(d, [scale * r[key] for r in rows], line, color=colour, marker=marker, ms=3.5,
                        mfc="none" if line == "--" else colour, label=text)
        ax.set_xscale("log")
        ax.set_xlabel("camera distance (mm)")
        ax.set_title(label, fontsize=10)
        ax.grid(True, alpha=0.3)
    axes[0].axhline(result["error_bound"], color="k", lw=0.8, ls=":", label=f"bound {result['error_bound']:g}")
    axes[0].set_ylim(bottom=0.0)
    axes[2].set_yscale("log")
    if "im_lod_texture_evaluations" in rows[0]:
        axes[1].plot(d, [1e-3 * r["im_lod_texture_evaluations"] for r in rows], ":", color="C0", lw=1,
                     label="IM LoD: texture part")
    start = result["trend"].get("trend_from_mm")
    if start is not None:
        for ax in axes:
            ax.axvline(start, color="0.6", lw=0.8)
        axes[1].annotate(" from here no pixel\n in the texture range", (start, 0.02),
                         xycoords=("data", "axes fraction"), fontsize=7, va="bottom", ha="left", color="0.4")
    axes[0].legend(fontsize=7, loc="upper left")
    axes[1].legend(fontsize=7, loc="center right")
    s = result["settings"]
    figure.suptitle(f"Receding plane (cotton denim): {s['width_px']} x {s['height_px']} px, {s['spp']} spp; "
                    f"reference {s['reference_spp']} spp; LoD f0 = {s['lod_f0_tiles']:g}, "
                    f"f1 = {s['lod_f1_tiles']:g} tiles", fontsize=10)
    import io

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=100)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buffer.getvalue())
    return path


NEURAL_SHADERS = ("im-lod", "neural-lod")
#: distances of the neural-lod comparison: 0.05-0.09 tile (5 mm) to 6-12 tiles (640 mm), denser over
#: 0.1-1 tile, where the estimators differ
NEURAL_DISTANCES = (5.0, 10.0, 14.0, 20.0, 28.0, 40.0, 56.0, 80.0, 160.0, 640.0)
QUICK_NEURAL_DISTANCES = (5.0, 20.0, 40.0, 160.0)
#: relative difference of two errors below which the neural-lod table calls a view a tie: on its small images
#: a second 256-spp reference differs from the first by 0.3-2 % relative L1 near and 1-2 % far, so the
#: order of two errors within 5 % of each other is not resolved
TIE = 0.05
#: im-lod's samples per pixel in the equal-CPU comparisons with neural-lod: square counts only (stratified
#: jitter; other counts are uniform random points in the pixel, a worse estimator that would flatter
#: neural-lod), tried in order until im-lod's shading CPU reaches neural-lod's
EQUAL_CPU_SPP = (1, 4, 9, 16, 25, 36, 64, 100, 144)


def equal_cpu_sweep(run, seconds: float, spps=EQUAL_CPU_SPP, include=()) -> list[dict]:
    """Rows ``run(spp)`` (dicts with ``shading_cpu_s``) over ``spps`` in order until one costs at least
    ``seconds`` (all of them if none does); the spp counts of ``include`` are run whatever their cost."""
    rows = []
    for k in sorted({*spps, *include}):
        if rows and rows[-1]["shading_cpu_s"] >= seconds and all(k > i for i in include):
            break
        rows.append(run(k))
    return rows


def error_at_cpu(times, errors, seconds: float) -> tuple[float, str]:
    """im-lod's error at shading CPU ``seconds`` from its rows (CPU s, error): the lower envelope in CPU (a
    larger budget can always buy a cheaper spp: the running minimum of the error in CPU order), interpolated
    log-log between the rows; outside their range the cheapest row's (it costs more: note
    ``"im-lod's cheapest costs more"``) or the dearest's (``"im-lod's dearest costs less"``); note "" inside."""
    order = np.argsort(times)
    t = np.log(np.maximum(np.asarray(times, dtype=np.float64)[order], 1e-12))  # a tiny render may time as 0
    e = np.log(np.maximum(np.minimum.accumulate(np.asarray(errors, dtype=np.float64)[order]), 1e-300))
    if seconds <= np.exp(t[0]):
        return float(np.exp(e[0])), "im-lod's cheapest costs more"
    if seconds > np.exp(t[-1]):
        return float(np.exp(e[-1])), "im-lod's dearest costs less"
    return float(np.exp(np.interp(np.log(seconds), t, e))), ""


def neural_lod_benchmark(quick: bool = False, *, figures_dir=None, resolution=None, distances=None, spp: int = 4,
                         reference_spp: int = 256, repeats: int | None = None, noise: bool = False) -> dict:
    """neural-lod against im-lod at equal shading CPU (issue 23 item 4) on the receding plane (cotton denim),
    per view: the relative L1 error of each against im-texture at ``reference_spp`` stratified samples (the
    reference's own error from a second seed beside it), neural-lod at ``spp`` and im-lod at the square spp
    counts of :data:`EQUAL_CPU_SPP` up to neural-lod's shading CPU (``process_time`` of this process, the
    least of ``repeats`` cold renders each), and im-lod's error at neural-lod's CPU interpolated over those
    rows (:func:`error_at_cpu`).  ``verdict`` per view: ``same`` (the two images agree: both shaders are
    the same model there, e.g. the reflectance model far away), ``tie`` (the two errors within :data:`TIE`
    of each other), else ``better`` or ``worse`` (neural-lod's error below / above im-lod's at equal CPU).
    neural-lod runs the weave's shipped network with the crossovers of its sidecar when it has them, else its
    documented default (:mod:`clothlab.render.shade`).

    ``noise`` (default off): the scene's texture noise (sec. 7.2.1).  The networks learn the noise-free
    texture (their labels have noise off), so with noise the reference has per-segment intensity variation
    (exponential, mean 1) that no footprint query carries; the comparison is made on the model the network
    represents.  Needs the scene weave's shipped network (``{'skipped': ...}`` otherwise).  ``figures_dir``:
    ``neural_lod.png``."""
    from dataclasses import replace

    from clothlab.models.neural.model import SHIPPED
    from clothlab.render.render import relative_error, render, render_figures, timed_render

    scene = receding_plane_scene(tuple(resolution or ((32, 24) if quick else (64, 48))))
    scene = replace(scene, fabric=replace(scene.fabric, noise=noise))
    weave = RECEDING_PLANE["fabric"]["weave"].removeprefix("preset:")
    if not (SHIPPED / f"{weave}.npz").exists():
        return {"skipped": f"no shipped network for {weave}"}
    repeats = repeats or (3 if quick else 5)
    distances = tuple(distances or (QUICK_NEURAL_DISTANCES if quick else NEURAL_DISTANCES))
    fabric = FabricModels.build(scene.fabric)  # one set of models (and one network load) for every render
    small = replace(scene, camera=replace(scene.camera, resolution=(4, 3)))
    for shader in (*NEURAL_SHADERS, "im-texture"):  # compilation out of the timings
        render(small, shader=shader, spp=1, fabric=fabric)
    rows = []
    for distance in distances:
        view = replace(scene, camera=scene.camera.at_distance(distance))
        reference = render(view, shader="im-texture", spp=reference_spp, fabric=fabric)
        mask = reference.coverage >= 1.0
        second = render(view, shader="im-texture", spp=reference_spp, fabric=fabric, seed=view.seed + 1)
        neural, runs = timed_render(view, "neural-lod", spp, fabric, repeats)
        t_n = neural.timings["shading_cpu"]
        images = {}

        def im_lod(k, view=view, reference=reference, mask=mask, images=images):
            result, n = timed_render(view, "im-lod", k, fabric, repeats)
            images[k] = result
            return {"spp": k, "shading_cpu_s": result.timings["shading_cpu"],
                    "relative_error": relative_error(result.image, reference.image, mask), "runs": n}

        sweep = equal_cpu_sweep(im_lod, t_n, include=(spp,))
        st = neural.stats
        row = {"distance_mm": float(distance), "pixels": int(mask.sum()),
               "footprint_min_tiles": st["footprint_min_tiles"], "footprint_median_tiles": st["footprint_median_tiles"],
               "footprint_max_tiles": st["footprint_max_tiles"],
               "im_reference_error": relative_error(second.image, reference.image, mask)}
        for shader, result, n in (("im-lod", images[spp], next(r["runs"] for r in sweep if r["spp"] == spp)),
                                  ("neural-lod", neural, runs)):
            figures = render_figures(result, reference.image, mask, n)
            row.update({f"{_key(shader)}_{name}": figures[name] for name in SHADER_FIGURES})
        err_n = row["neural_lod_relative_error"]
        row["neural_time_ratio"] = t_n / row["im_lod_shading_cpu_seconds"]
        row["im_lod_sweep"] = [{k: r[k] for k in ("spp", "shading_cpu_s", "relative_error")} for r in sweep]
        error, note = error_at_cpu([r["shading_cpu_s"] for r in sweep], [r["relative_error"] for r in sweep], t_n)
        row["equal_time_relative_error"], row["equal_time_note"] = error, note
        row["equal_time_max_spp"] = sweep[-1]["spp"]
        same = np.allclose(neural.image, images[spp].image, rtol=1e-9, atol=0.0)
        row["verdict"] = ("same" if same else "tie" if abs(err_n - error) <= TIE * error
                          else "better" if err_n < error else "worse")
        rows.append(row)
    differs = [r for r in rows if r["verdict"] != "same"]
    result = {"settings": {"scene": "receding plane, cotton denim, tile 1 x 2 mm, 45 deg elevation",
                           "noise": noise, "width_px": scene.camera.resolution[0],
                           "height_px": scene.camera.resolution[1], "spp": spp, "reference_spp": reference_spp,
                           "repeats": repeats, "im_lod_spp": list(EQUAL_CPU_SPP),
                           "estimator_choice": _has_choice(fabric)},
              "rows": rows, "network_used_mm": [r["distance_mm"] for r in rows if r["neural_lod_neural_evaluations"]],
              "differs_mm": [r["distance_mm"] for r in differs],
              "neural_better_where_it_differs": bool(differs) and all(r["verdict"] == "better" for r in differs),
              "never_worse": all(r["verdict"] != "worse" for r in rows)}
    result["settings"]["tie"] = TIE
    if figures_dir is not None:
        result["figure"] = str(plot_neural_lod(result, Path(figures_dir) / "neural_lod.png"))
    return result


def _has_choice(fabric) -> bool:
    from clothlab.render.neural_lod import estimator_choice

    return estimator_choice(fabric.weave) is not None


def neural_lod_lines(result: dict) -> list[str]:
    """The im-lod vs neural-lod table."""
    if "skipped" in result:
        return [f"  neural-lod render: skipped ({result['skipped']})"]
    s = result["settings"]
    policy = ("the crossovers of its sidecar" if s["estimator_choice"]
              else "its documented default (the sidecar has no crossovers)")
    out = [f"  neural-lod ({policy}) vs im-lod at equal shading CPU, receding plane {s['width_px']} x "
           f"{s['height_px']} px, texture noise {'on' if s['noise'] else 'off'}; error: relative L1 vs im-texture "
           f"at {s['reference_spp']} spp (ref: a second reference's difference); ms: least shading CPU "
           f"(process_time) of {s['repeats']} cold renders; im-lod at equal CPU: interpolated log-log over its "
           f"renders at {', '.join(map(str, s['im_lod_spp']))} spp (stratified) up to neural-lod's CPU",
           f"  {'dist mm':>7} {'footprint':>13} | {'ref':>6} {'err im-lod':>10} {'err neural':>10} | "
           f"{'ms im-lod':>9} {'ms neural':>9} {'ratio':>6} {'queries':>7} | {'im-lod at equal CPU':>24} | verdict",
           f"  {'':>7} {'':>13} | {'':>6} {str(s['spp']) + ' spp':>10} {'':>10} | "
           f"{'':>9} {'':>9} {'':>6} {'':>7} | {'err':>7} {'up to spp':>9} {'':>6} |"]
    for r in result["rows"]:
        note = f" ({r['equal_time_note']})" if r["equal_time_note"] else ""
        out.append(f"  {r['distance_mm']:7g} {r['footprint_min_tiles']:6.3f}-{r['footprint_max_tiles']:<6.3g} | "
                   f"{r['im_reference_error']:6.3f} {r['im_lod_relative_error']:10.3f} "
                   f"{r['neural_lod_relative_error']:10.3f} | {1e3 * r['im_lod_shading_cpu_seconds']:9.1f} "
                   f"{1e3 * r['neural_lod_shading_cpu_seconds']:9.1f} {r['neural_time_ratio']:6.2f} "
                   f"{r['neural_lod_neural_evaluations']:7d} | {r['equal_time_relative_error']:7.3f} "
                   f"{r['equal_time_max_spp']:9d} {'':>6} | {r['verdict']}{note}")
    where = ", ".join(f"{d:g}" for d in result["differs_mm"]) or "nowhere"
    out.append(f"  where neural-lod differs from im-lod ({where} mm) it has the lower error at equal shading CPU: "
               f"{result['neural_better_where_it_differs']}; never worse (tie: within {100 * s['tie']:.0f} %): "
               f"{result['never_worse']}")
    if "figure" in result:
        out.append(f"  plot: {result['figure']}")
    return out


def plot_neural_lod(result: dict, path) -> Path:
    """PNG: relative L1 error and shading CPU time against distance, im-lod vs neural-lod."""
    import io

    from matplotlib.figure import Figure

    from clothlab.atomic import atomic_write_bytes

    rows = result["rows"]
    d = [r["distance_mm"] for r in rows]
    figure = Figure(figsize=(9.5, 3.8), layout="constrained")
    axes = figure.subplots(1, 2)
    for ax, (name, scale, label) in zip(axes, (("relative_error", 1.0, "relative L1 error vs reference"),
                                               ("shading_cpu_seconds", 1e3, "shading CPU time (ms)")), strict=True):
        for shader, colour in (("im-lod", "C0"), ("neural-lod", "C2")):
            ax.plot(d, [scale * r[f"{_key(shader)}_{name}"] for r in rows], "-o", color=colour, ms=3.5,
                    label=f"{shader}, {result['settings']['spp']} spp")
        ax.set_xscale("log")
        ax.set_xlabel("camera distance (mm)")
        ax.set_title(label, fontsize=10)
        ax.grid(True, alpha=0.3)
    axes[0].plot(d, [r["equal_time_relative_error"] for r in rows], "--s", color="C0", ms=3, alpha=0.7,
                 label="im-lod at neural-lod's shading CPU")
    for r in rows:
        axes[0].annotate(f"{r['equal_time_max_spp']}", (r["distance_mm"], r["equal_time_relative_error"]),
                         fontsize=6, color="C0", xytext=(2, 3), textcoords="offset points")
    axes[0].plot(d, [r["im_reference_error"] for r in rows], ":", color="grey", label="two references differ by")
    axes[0].set_ylim(bottom=0.0)
    axes[1].set_yscale("log")
    axes[0].legend(fontsize=7)
    s = result["settings"]
    figure.suptitle(f"Receding plane (cotton denim, texture noise {'on' if s['noise'] else 'off'}): neural-lod vs "
                    f"im-lod, {s['width_px']} x {s['height_px']} px\nreference im-texture {s['reference_spp']} spp; "
                    "numbers: im-lod's largest spp tried (up to neural-lod's CPU)", fontsize=9)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=100)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buffer.getvalue())
    return path
