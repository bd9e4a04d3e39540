"""The shipped multi-material network of the surface model (Chen, Wang & Wang 2024, kind ``surface``) on
``pattern:twill-3x3``: it loads, and on an unseen material (a held-out midpoint of its --vary grid, never
trained on) it agrees with fresh footprint labels within the error its sidecar records for unseen materials.
It is a residual network (``--residual``): it corrects the surface reflectance model of each material."""

from __future__ import annotations

import pytest
from neural_fresh import assert_agrees_with_fresh_labels

SURFACE_FAMILY = "families/surface-twill-3x3-alpha-beta"


@pytest.fixture(scope="module")
def family():
    from clothlab.models.neural.model import SHIPPED, load_neural

    return load_neural(SHIPPED / f"{SURFACE_FAMILY}.npz")  # residual: R of every material attached


def test_shipped_surface_family_is_small_and_describes_its_grid(family):
    from clothlab.models.neural.model import SHIPPED

    surrogate, sidecar = family
    enc = sidecar["encoding"]
    assert enc["kind"] == "surface" and enc["weave"] == "twill-3x3" and enc["residual"]
    assert len(surrogate.references) == 13
    assert sidecar["components"] == ["diffuse_warp", "diffuse_weft", "specular_warp", "specular_weft"]
    assert len(enc["materials_params"]) == 13 and enc["heldout_materials"] == [9, 10, 11, 12]
    assert surrogate.materials.shape[0] == 13
    assert sorted({q["warp.alpha"] for q in enc["materials_params"][:9]}) == pytest.approx([0.1, 0.1 ** 0.5, 1.0])
    assert sorted({q["warp.beta"] for q in enc["materials_params"][:9]}) == pytest.approx([0.0, 1.0, 2.0])
    assert all(b["rows"] > 0 for b in sidecar["metrics"]["heldout_materials"])
    size = sum((SHIPPED / f"{SURFACE_FAMILY}{ext}").stat().st_size for ext in (".npz", ".json"))
    assert size < 5_000_000


@pytest.mark.parametrize("unseen", [9, 12])
def test_shipped_surface_family_agrees_with_fresh_labels_of_an_unseen_material(family, unseen):
    """Fresh whole-tile-split MC-256 labels (the training labels were MC-64, another seed) of queries on
    held-out direction pairs of an unseen material; relative RMSE of f at 0.12-1 and 1-5 tiles within 1.5x
    the largest error the sidecar records for unseen materials in those bins (the queries differ, and the
    held-out pairs are harder than the sidecar's mix of pairs)."""
    from clothlab.models.registry import build_model
    from clothlab.weave.presets import resolve_weave

    surrogate, sidecar = family
    enc = sidecar["encoding"]
    model = build_model("surface", resolve_weave("pattern:twill-3x3", "."))
    params = {**enc["params"], **enc["materials_params"][unseen]}
    assert_agrees_with_fresh_labels(surrogate, sidecar, unseen, model, params, sidecar["metrics"]["heldout_materials"])
