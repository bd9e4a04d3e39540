"""Model selection pieces: composite models equal their parts, information criteria, ranking, the CLI refusal."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from clothlab.errors import GeometryWarning
from clothlab.fit.select import Candidate, CandidateResult, information_criteria, rank
from clothlab.frames import spherical_to_vector
from clothlab.models.registry import build_model
from clothlab.weave.presets import get_preset

RNG = np.random.default_rng(3)
WI = spherical_to_vector(RNG.uniform(0, 85, 40), RNG.uniform(0, 360, 40))
WO = spherical_to_vector(RNG.uniform(0, 85, 40), RNG.uniform(0, 360, 40))


def test_composites_are_their_parts():
    weave = get_preset("wool-gabardine")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        im = build_model("irawan", weave).components(WI, WO, {"orientation": 30.0})
        same = build_model("irawan+lambert", weave).components(WI, WO, {"orientation": 30.0})
        on = build_model("irawan+oren-nayar", weave).components(WI, WO, {"sigma": 35.0, "orientation": 30.0})
    ref = build_model("oren-nayar", weave).components(WI, WO, {"sigma": 35.0})
    assert set(same) == set(im)
    for name in im:
        assert np.array_equal(same[name], im[name])
    assert np.array_equal(on["specular_warp"], im["specular_warp"])
    np.testing.assert_allclose(on["diffuse"], ref["diffuse"], rtol=1e-15)


def test_information_criteria_by_hand():
    aic, bic = information_criteria(0.01, 200, 10)
    assert aic == pytest.approx(200 * math.log(0.01) + 20)
    assert bic == pytest.approx(200 * math.log(0.01) + 10 * math.log(200))


def test_rank_puts_cross_validated_first_then_bic_then_unfitted():
    def r(name, cv, bic, fitted=True):
        row = {"cv_mean": cv, "bic": bic, "objective": 1.0 if fitted else None}
        return CandidateResult(Candidate("preset:" + name, "irawan"), row)

    ordered = rank([r("a", None, -5.0), r("b", 0.2, 0.0), r("c", 0.1, 9.0), r("d", None, None, False)])
    assert [x.candidate.weave for x in ordered] == ["preset:c", "preset:b", "preset:a", "preset:d"]
    assert [x.row["rank"] for x in ordered] == [1, 2, 3, 4]


def test_cli_refuses_an_unknown_kind(capsys):
    from clothlab.cli.main import main

    code = main(["select", "measurements/scattered-twill/fabric.yaml", "--kinds", "irawan,nope", "-o", "/tmp/x"])
    assert code == 2 and "nope" in capsys.readouterr().err
