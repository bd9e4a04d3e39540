"""Tests of clothlab.report: HTML/PNG/JSON report of a saved fit directory, and the comparison page.

The fit directories are synthetic (numpy only, no model code): a cross-shaped anisotropic lobe plus a
diffuse term, 'measured' with multiplicative log-normal noise.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

EXITANT = ((0.0, 0.0), (30.0, 0.0), (30.0, 45.0), (30.0, 90.0), (30.0, 135.0), (60.0, 0.0), (60.0, 90.0))
CHANNELS = ("R", "G", "B")


def _unit(theta, phi):
    t, p = np.deg2rad(theta), np.deg2rad(phi)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def _synthetic_brdf(theta_i, phi_i, theta_o, phi_o):
    """(N, 3) components diffuse, warp bar, weft bar of a cross-shaped synthetic BRDF (1/sr)."""
    h = _unit(theta_i, phi_i) + _unit(theta_o, phi_o)
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    warp = np.exp(-((h[:, 1] / 0.07) ** 2)) * np.exp(-((h[:, 0] / 0.45) ** 2))  # warp yarns run along +y
    weft = np.exp(-((h[:, 0] / 0.10) ** 2)) * np.exp(-((h[:, 1] / 0.30) ** 2))
    return np.stack([np.ones_like(warp), warp, weft], axis=-1)


KD = {"R": 0.12, "G": 0.03, "B": 0.025}
KS_WARP = {"R": 1.5, "G": 0.6, "B": 0.5}
KS_WEFT = {"R": 0.4, "G": 0.2, "B": 0.2}


def _write_csv(path: Path, columns: dict) -> None:
    names = list(columns)
    n = len(next(iter(columns.values())))
    lines = [",".join(names)]
    for k in range(n):
        cells = [columns[c][k] for c in names]
        lines.append(",".join(c if isinstance(c, str) else repr(float(c)) for c in cells))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_synthetic_fit_dir(root, name="synthetic-denim", *, seed=0, n_theta=15, n_phi=15, noise=0.2,
                            fabric="cotton-denim", with_optional=True) -> Path:
    """Write fits/<name>/ (fit.json, predictions.csv, slices.csv, trace.csv) from numpy values only."""
    rng = np.random.default_rng(seed)
    fit_dir = Path(root) / name
    fit_dir.mkdir(parents=True)
    ti, pi = np.meshgrid(np.linspace(5.0, 75.0, n_theta), np.arange(n_phi) * 360.0 / n_phi, indexing="ij")
    ti, pi = ti.ravel(), pi.ravel()
    rows = {k: [] for k in ("theta_i", "phi_i", "theta_o", "phi_o")}
    for to, po in EXITANT:
        rows["theta_i"].append(ti)
        rows["phi_i"].append(pi)
        rows["theta_o"].append(np.full_like(ti, to))
        rows["phi_o"].append(np.full_like(ti, po))
    table = {k: np.concatenate(v) for k, v in rows.items()}
    comps = _synthetic_brdf(table["theta_i"], table["phi_i"], table["theta_o"], table["phi_o"])
    for c in CHANNELS:
        parts = comps * np.array([KD[c], KS_WARP[c], KS_WEFT[c]])
        model = parts.sum(axis=1)
        table[f"measured_{c}"] = model * np.exp(noise * rng.standard_normal(model.size))
        table[f"model_{c}"] = model
        if with_optional:
            table[f"sigma_{c}"] = noise * model
            table[f"diffuse_{c}"], table[f"specular_warp_{c}"], table[f"specular_weft_{c}"] = parts.T
    _write_csv(fit_dir / "predictions.csv", table)

    if with_optional:
        signed = np.arange(-89.0, 89.5, 1.0)
        sl = {k: [] for k in ("theta_o", "phi_o", "signed_theta_i")}
        for to, po in EXITANT:
            sl["theta_o"].append(np.full_like(signed, to))
            sl["phi_o"].append(np.full_like(signed, po))
            sl["signed_theta_i"].append(signed)
        sl = {k: np.concatenate(v) for k, v in sl.items()}
        phi_in = np.where(sl["signed_theta_i"] >= 0, sl["phi_o"] + 180.0, sl["phi_o"])
        comps = _synthetic_brdf(np.abs(sl["signed_theta_i"]), phi_in, sl["theta_o"], sl["phi_o"])
        for c in CHANNELS:
            sl[f"model_{c}"] = comps @ np.array([KD[c], KS_WARP[c], KS_WEFT[c]])
        _write_csv(fit_dir / "slices.csv", sl)

        n_eval = 300
        value = 10.0 * np.exp(-np.arange(n_eval) / 60.0) * (1.0 + rng.random(n_eval)) + 0.5
        _write_csv(fit_dir / "trace.csv", {
            "evaluation": np.arange(1, n_eval + 1), "time_s": 0.01 * np.arange(1, n_eval + 1), "value": value,
            "best": np.minimum.accumulate(value), "stage": ["global"] * 200 + ["local"] * 100})

    fit = {
        "name": name, "created": "2025-01-01T12:00:00+00:00", "clothlab_version": "0.1.0",
        "versions": {"numpy": np.__version__, "nlopt": "2.9.1"}, "config_hash": "abc123<&>",
        "config": {"name": fabric, "model": {"kind": "irawan"}},
        "model": {"kind": "irawan", "weave": f"preset:{fabric}", "quadrature": {"rule": "trapezoid", "nodes": 11}},
        "measurement": {"path": "measurements/sim.csv", "n": int(table["theta_i"].size), "channels": list(CHANNELS),
                        "provenance": {"simulated": True, "instrument": "virtual gonioreflectometer"}},
        "parameters": {
            "warp.umax": {"value": 12.3, "unit": "deg", "free": True, "lower": 1, "upper": 85, "start": 30.0,
                          "at_bound": None, "truth": 12.0},
            "warp.kappa": {"value": -0.5, "unit": "", "free": True, "lower": -0.5, "upper": 5.0, "start": 0.0,
                           "at_bound": "lower", "truth": -0.3},
            "alpha": {"value": 0.05, "unit": "", "free": False, "lower": 0.0, "upper": 1.0, "start": 0.05,
                      "at_bound": None},
        },
        "coefficients": {"kd": KD, "ks_warp": KS_WARP, "ks_weft": KS_WEFT},
        "metric": "relative",
        "errors": {"overall": {"p50": 0.1, "p80": 0.2, "p95": 0.3, "mean": 0.12, "n": 10}, "per_channel": {}},
        "objective": {"start": 20.0, "final": 0.51}, "evaluations": 300, "wall_time_s": 3.0, "seed": seed,
        "optimizer": {"global": "GN_CRS2_LM", "local": "LN_BOBYQA", "max_evals": 4000},
        "warnings": ["warp.kappa ended at its lower bound <check>"],
    }
    (fit_dir / "fit.json").write_text(json.dumps(fit, indent=1), encoding="utf-8")
    return fit_dir
