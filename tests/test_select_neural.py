"""``clothlab select`` on a ``kind: neural`` fabric.yaml with an empty ``fit.free``: the candidate frees the
parameters the network was trained over (config validation's rule, ``clothlab.config.validate.default_free``),
not the class's IM defaults ``alpha`` / ``beta``, which a surface-family network does not declare."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

FAMILY = "families/surface-twill-3x3-alpha-beta"
TRUTH = {"warp.alpha": 0.1778279410038923, "warp.beta": 0.5}  # a held-out midpoint of the family's grid
COEFFICIENTS = {"diffuse_warp": 0.3, "diffuse_weft": 0.2, "specular_warp": 0.5, "specular_weft": 0.4}


@pytest.fixture(scope="module")
def fabric(tmp_path_factory):
    """A neural fabric.yaml naming a copy of the surface family network (``fit.free: []``), on a table of an
    unseen material simulated by the exact surface model (60 direction pairs)."""
    from clothlab.frames import spherical_to_vector
    from clothlab.io.measurement import Measurement
    from clothlab.io.table import write_table
    from clothlab.models.neural.model import SHIPPED
    from clothlab.models.registry import build_model
    from clothlab.weave.presets import resolve_weave

    root = tmp_path_factory.mktemp("select-neural")
    for ext in (".npz", ".json"):
        shutil.copy((SHIPPED / FAMILY).with_suffix(ext), root / f"family{ext}")
    rng = np.random.default_rng(5)
    angles = np.column_stack([rng.uniform(5, 70, 60), rng.uniform(0, 360, 60), rng.uniform(5, 70, 60),
                              rng.uniform(0, 360, 60)])
    wi, wo = spherical_to_vector(angles[:, 0], angles[:, 1]), spherical_to_vector(angles[:, 2], angles[:, 3])
    exact = build_model("surface", resolve_weave("pattern:twill-3x3", "."))
    c = exact.components(wi, wo, {**exact.resolve({}), **TRUTH})
    write_table(Measurement(*angles.T, sum(v * c[k] for k, v in COEFFICIENTS.items())[:, None], ("value",)),
                root / "table.csv")
    path = root / "fabric.yaml"
    path.write_text("name: sel\nmeasurement: {path: table.csv}\nmodel:\n  kind: neural\n  weave: pattern:twill-3x3\n"
                    "  options: {weights: family.npz}\nfit:\n  free: []\n"
                    "  optimizer: {global: GN_CRS2_LM, local: LN_BOBYQA, max_evals: 30, starts: 1, seed: 1}\n")
    return path


def _trained_over(sidecar_path) -> tuple:
    """The parameters that differ between the network's grid materials, read from its sidecar directly."""
    materials = json.loads(sidecar_path.read_text())["encoding"]["materials_params"]
    return tuple(k for k in materials[0] if len({q[k] for q in materials}) > 1)


def test_select_candidate_frees_the_network_parameters(fabric):
    from clothlab.config import load_config
    from clothlab.fit.select import Candidate, candidate_config

    cfg = load_config(fabric)
    assert cfg.fit.free == ()  # fit.free: [] given, so select falls back to the default
    expected = _trained_over(fabric.with_name("family.json"))
    assert expected == ("warp.alpha", "warp.beta")
    # the same rule as config validation without fit.free
    without = fabric.with_name("default.yaml")
    without.write_text(fabric.read_text().replace("  free: []\n", ""))
    assert load_config(without).fit.free == expected
    got = candidate_config(cfg, Candidate("pattern:twill-3x3", "neural"), max_evals=30, cv_folds=0)
    assert got.fit.free == expected
    assert got.model.options == cfg.model.options  # the network goes with the candidate


def test_select_fits_a_neural_candidate(fabric):
    """The candidate fit runs (before the fix: alpha / beta, unknown to a surface network, "not fitted") and
    its free parameters are the network's."""
    from clothlab.config import load_config
    from clothlab.fit.select import Candidate, CandidateTask, fit_candidate

    cfg = load_config(fabric)
    res = fit_candidate(CandidateTask(cfg, Candidate("pattern:twill-3x3", "neural"), max_evals=30, cv_folds=0))
    assert res.row["note"] is None and res.row["objective"] is not None
    assert res.free == ("warp.alpha", "warp.beta") and set(res.params) == set(TRUTH)
