"""The shipped example data: one simulated measurement per paper fabric (Irawan & Marschner 2012, sec. 4).

The published presets carry no yarn colours; the albedos below are plausible choices for the paper's
fabrics (black cotton twill, blue-weft / white-warp denim, red gabardine, red polyester, red charmeuse,
red-weft / dark-grey-warp shantung).  kd is the diffuse albedo, ks_warp / ks_weft the mean specular albedo of
each segment type (:mod:`clothlab.models.irawan.model`).  These data are SIMULATED: `clothlab simulate
--paper-examples measurements/` regenerates them bit for bit (seeded noise).

Free parameters and starting values of the example fits: the yarn geometry the BRDF shows best (umax and,
for staple yarns, psi; for filament yarns the spine curvature kappa) and the phase function (alpha, beta);
starts are the parameter declarations' generic defaults, not the generating values.
"""

from __future__ import annotations

YARN_COLOURS = {
    "cotton-twill": {"kd": (0.030, 0.030, 0.032), "ks_warp": (0.050, 0.050, 0.050), "ks_weft": (0.020, 0.020, 0.020)},
    "cotton-denim": {"kd": (0.200, 0.260, 0.420), "ks_warp": (0.120, 0.120, 0.115), "ks_weft": (0.020, 0.035, 0.080)},
    "wool-gabardine": {"kd": (0.300, 0.040, 0.045), "ks_warp": (0.060, 0.022, 0.022), "ks_weft": (0.045, 0.015, 0.015)},
    "polyester-lining": {"kd": (0.25, 0.03, 0.035), "ks_warp": (0.15, 0.05, 0.05), "ks_weft": (0.15, 0.05, 0.05)},
    "silk-charmeuse": {"kd": (0.200, 0.020, 0.030), "ks_warp": (0.300, 0.100, 0.100), "ks_weft": (0.080, 0.030, 0.030)},
    "silk-shantung": {"kd": (0.250, 0.030, 0.040), "ks_warp": (0.040, 0.040, 0.045), "ks_weft": (0.250, 0.060, 0.060)},
}

#: Noise of the "noisy" variant: 5 % multiplicative log-normal plus 2e-4 1/sr additive Gaussian.
NOISE = {"multiplicative": 0.05, "additive": 2e-4}
SEEDS = {name: 1000 + i for i, name in enumerate(YARN_COLOURS)}

STAPLE_FREE = ("warp.psi", "weft.psi", "warp.umax", "weft.umax", "alpha", "beta")
FILAMENT_FREE = ("warp.umax", "weft.umax", "warp.kappa", "weft.kappa", "alpha", "beta")
START = {"warp.umax": 30.0, "weft.umax": 30.0, "warp.psi": 0.0, "weft.psi": 0.0, "warp.kappa": 0.0,
         "weft.kappa": 0.0, "alpha": 0.05, "beta": 4.0}


def free_parameters(name: str) -> tuple[str, ...]:
    from clothlab.presets import get_preset

    weave = get_preset(name)
    return STAPLE_FREE if weave.warp.psi != 0.0 or weave.weft.psi != 0.0 else FILAMENT_FREE


def fabric_yaml(name: str, variant: str) -> str:
    """The fabric.yaml text of an example fit (variant 'noisy' or 'clean')."""
    free = free_parameters(name)
    start = {k: START[k] for k in free}
    suffix = "" if variant == "noisy" else "-clean"
    lines = [
        f"# Example fit of SIMULATED data for the paper's {name} (see measurements/{name}/README.md).",
        f"name: {name}{suffix}",
        f"measurement: {{path: {variant}.csv}}",
        "model:",
        "  kind: irawan",
        f"  weave: preset:{name}",
        "  quadrature: {rule: trapezoid, nodes: 11}",
        "  params: {" + ", ".join(f"{k}: {v:g}" for k, v in start.items()) + "}",
        "fit:",
        "  free: [" + ", ".join(free) + "]",
        "  metric: relative",
        "  optimizer: {global: GN_CRS2_LM, local: LN_BOBYQA, max_evals: 6000, starts: 8, seed: 1}",
        "report: {percentiles: [50, 80, 95]}",
        "output: {fits: ../../fits, reports: ../../reports}",
    ]
    return "\n".join(lines) + "\n"


def write_paper_examples(root, *, force: bool = False) -> list:
    """Simulate the six paper fabrics into root/<fabric>/ (clean.csv, noisy.csv, fabric yaml files, README)."""
    import warnings
    from pathlib import Path

    import numpy as np

    from clothlab.atomic import atomic_write_text
    from clothlab.errors import GeometryWarning
    from clothlab.io.table import write_table
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.presets import get_preset
    from clothlab.simulate import NoiseModel, simulate

    written = []
    for name, colours in YARN_COLOURS.items():
        folder = Path(root) / name
        folder.mkdir(parents=True, exist_ok=True)
        model = IrawanModel(get_preset(name))
        coefficients = {k: np.asarray(v) for k, v in colours.items()}
        for variant in ("clean", "noisy"):
            noise = NoiseModel(**NOISE, seed=SEEDS[name]) if variant == "noisy" else None
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", GeometryWarning)
                m = simulate(model, {}, coefficients, noise=noise,
                             provenance={"sample_name": f"{name} ({variant}, SIMULATED)", "fabric": name,
                                         "variant": variant, "reference_standard": "none (simulated BRDF)"})
            written.append(write_table(m, folder / f"{variant}.csv", overwrite=force))
            yaml_name = "fabric.yaml" if variant == "noisy" else "fabric-clean.yaml"
            atomic_write_text(folder / yaml_name, fabric_yaml(name, variant))
        atomic_write_text(folder / "README.md", _readme(name, colours))
    return written


def _readme(name: str, colours: dict) -> str:
    rows = "\n".join(f"| {k} | {', '.join(f'{x:g}' for x in v)} |" for k, v in colours.items())
    return f"""# {name} - SIMULATED example data

Not a measurement. Generated by `clothlab simulate --paper-examples measurements/` from the published
{name} preset (`preset:{name}`, Irawan & Marschner 2012) with the Irawan-Marschner model (trapezoid 11),
the paper's sampling (225 incident x 7 exitant directions, sec. 4.1) and these yarn colours (albedos, R G B):

| coefficient | R, G, B |
|---|---|
{rows}

- `clean.csv`: noise-free; `noisy.csv`: 5 % multiplicative log-normal + 2e-4 1/sr additive Gaussian noise,
  seed {SEEDS[name]} (per-value sigma columns included).
- The generating parameters are recorded in each table's header (`provenance.parameters`).
- `fabric.yaml` fits the noisy set, `fabric-clean.yaml` the clean one.
"""
