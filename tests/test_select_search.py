"""The selection's search space (issue 28 items 1 and 6): losses as candidates, fit.free mapped per kind (an
unmappable name an error), AIC/BIC on the squared residual whatever the loss, not-determined flags."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from clothlab.config import apply_overrides, load_config
from clothlab.errors import ConfigError
from clothlab.fit.determined import bound_band, not_determined
from clothlab.fit.select import Candidate, SelectSettings, candidate_config, candidates, map_free

EXAMPLE = Path(__file__).parent.parent / "measurements" / "scattered-twill" / "fabric.yaml"
IM_FREE = ("orientation", "warp.umax", "weft.umax", "warp.psi", "weft.psi", "alpha", "beta")


def test_losses_and_scales_multiply_the_candidates_and_name_them():
    s = SelectSettings(weaves=("preset:cotton-twill",), kinds=("irawan",), orientation_starts=1,
                       losses=("squared", "huber", "cauchy"), loss_scales=(0.05, 0.1))
    names = [c.name for c in candidates(s)]
    assert names == ["cotton-twill irawan squared #1", "cotton-twill irawan huber 0.05 #1",
                     "cotton-twill irawan huber 0.1 #1", "cotton-twill irawan cauchy 0.05 #1",
                     "cotton-twill irawan cauchy 0.1 #1"]
    assert len(candidates(replace(s, losses=()))) == 1  # default: fabric.yaml's loss only
    cfg = load_config(EXAMPLE)
    c = candidate_config(cfg, Candidate("preset:cotton-twill", "irawan", 1, "cauchy", 0.05), max_evals=10,
                         cv_folds=0)
    assert (c.fit.loss, c.fit.loss_scale) == ("cauchy", 0.05)


def test_surface_gets_its_own_parameters_from_the_im_free_list():
    free, mapping = map_free("surface", IM_FREE)
    assert free == ["warp.umax", "weft.umax", "warp.psi", "weft.psi", "warp.alpha", "weft.alpha", "warp.beta",
                    "weft.beta"]
    assert mapping == {"alpha": ["warp.alpha", "weft.alpha"], "beta": ["warp.beta", "weft.beta"]}
    kang, _ = map_free("kang", IM_FREE)
    assert kang == ["yarn_curvature", "fibre_slope", "warp.nx", "weft.nx", "warp.ny", "weft.ny"]
    diffuse, mapping = map_free("oren-nayar", IM_FREE)
    assert diffuse == [] and all(v == [] for v in mapping.values())  # no specular part: recorded, not hidden


def test_a_name_with_no_counterpart_is_an_error_not_a_drop():
    with pytest.raises(ConfigError) as exc:
        map_free("irawan", ("warp.umax", "blurb"))
    assert "blurb" in str(exc.value) and exc.value.field == "fit.free"


def test_selection_refuses_an_unmappable_name_before_fitting(monkeypatch):
    from clothlab.fit import select as sel

    cfg = load_config(EXAMPLE)
    cfg = replace(cfg, fit=replace(cfg.fit, free=(*cfg.fit.free, "blurb")))  # a name of no model
    calls = []
    monkeypatch.setattr(sel, "fit_candidate", lambda task: calls.append(task))
    with pytest.raises(ConfigError, match="blurb"):
        sel.select(cfg, SelectSettings(weaves=("preset:cotton-twill",), kinds=("kang",), orientation_starts=1),
                   run_task=lambda task: calls.append(task))
    assert calls == []


def test_robust_candidates_rank_on_held_out_error_with_comparable_information_criteria():
    """A huber candidate's AIC uses the mean squared relative residual (as its squared twin's does), so the
    two AICs differ only as their residuals do, not by the loss's scale."""
    import numpy as np

    from clothlab.fit.select import CandidateTask, fit_candidate

    cfg = apply_overrides(load_config(EXAMPLE), max_evals=60)
    cfg = replace(cfg, fit=replace(cfg.fit, posterior=None, cv_folds=0))
    rows = [fit_candidate(CandidateTask(cfg, Candidate("preset:wool-gabardine", "irawan", 1, loss, scale), 60,
                                        0, None if False else __import__("clothlab.io.loader", fromlist=["x"])
                                        .load_measurement(cfg.measurement.path))).row
            for loss, scale in (("squared", None), ("huber", 0.02))]
    sq, hu = rows
    assert hu["loss"] == "huber" and hu["loss_scale"] == 0.02 and "huber 0.02" in hu["candidate"]
    # both F are mean squared residuals of fits of the same data: same order of magnitude
    f_sq = np.exp((sq["aic"] - 2 * sq["k"]) / sq["n"])
    f_hu = np.exp((hu["aic"] - 2 * hu["k"]) / hu["n"])
    assert 0.5 < f_hu / f_sq < 2.0
    assert hu["objective"] < f_hu  # the huber objective itself is smaller than the squared residual


def test_not_determined_by_coefficient_zero_and_by_the_two_percent_band():
    fit = {"parameters": {
        "warp.umax": {"value": 40.0, "lower": 1.0, "upper": 85.0, "free": True},
        "weft.umax": {"value": 42.3, "lower": 1.0, "upper": 85.0, "free": True},
        "weft.psi": {"value": 84.2 - 60.0, "lower": -60.0, "upper": 60.0, "free": True},
        "alpha": {"value": 0.499, "lower": 0.0, "upper": 0.5, "free": True},
        "beta": {"value": 1.0, "lower": 0.5, "upper": 60.0, "free": True, "transform": "log"},
        "orientation": {"value": 89.9, "lower": -90.0, "upper": 90.0, "free": True},
        "delta": {"value": 0.0, "lower": 0.0, "upper": 0.95, "free": False}},
        "coefficients": {"ks_warp": {"grey": 0.2}, "ks_weft": {"grey": 0.0}, "kd": {"grey": 0.3}}}
    flags = not_determined(fit)
    assert set(flags) == {"weft.umax", "weft.psi", "alpha"}
    assert "ks_weft is 0" in flags["weft.umax"] and "upper bound (0.5)" in flags["alpha"]
    assert bound_band("warp.umax", {"value": 84.2, "lower": 1.0, "upper": 85.0}).startswith("within 2 %")
    assert bound_band("warp.umax", {"value": 83.0, "lower": 1.0, "upper": 85.0}) is None  # 2.4 % away
    assert bound_band("beta", {"value": 0.52, "lower": 0.5, "upper": 60.0, "transform": "log"}) is not None
    assert bound_band("orientation", {"value": 90.0, "lower": -90.0, "upper": 90.0}) is None


def test_fit_report_and_report_page_show_the_flags():
    from clothlab.fit.fitreport import format_text, report_sections
    from clothlab.report import html

    fit = {"name": "x", "parameters": {"warp.umax": {"value": 84.5, "lower": 1.0, "upper": 85.0, "free": True,
                                                     "unit": "deg", "start": 30.0}},
           "coefficients": {"ks_warp": {"grey": 0.0}},
           "uncertainty": {"stderr": {"warp.umax": None}, "notes": []}}
    text = format_text(report_sections(fit))
    assert "NOT DETERMINED" in text and "ks_warp is 0" in text and "within 2 %" in text
    page = "".join(html._parameter_section(fit))
    assert "not determined" in page and "std. error (Gauss-Newton)" in page


def test_the_box_check_recognises_a_warp_weft_swapped_twin():
    """A point outside the box whose warp/weft-swapped twin (orientation + half a period) is inside with the
    same objective is another in-box basin, not a bound problem (issue 28: Kang's 'optimum MOVES')."""
    from types import SimpleNamespace

    import numpy as np

    from clothlab.fit.optimize import _swapped_twin

    def objective(p):  # symmetric under warp <-> weft with the orientation turned by 90 deg
        a, b = (p["warp.nx"], p["weft.nx"]) if (p["orientation"] % 180.0) < 90.0 else (p["weft.nx"], p["warp.nx"])
        return SimpleNamespace(objective=(a - 3.0) ** 2 + (b - 40.0) ** 2)

    spec = [SimpleNamespace(name="warp.nx", period=None), SimpleNamespace(name="weft.nx", period=None),
            SimpleNamespace(name="orientation", period=180.0)]
    problem = SimpleNamespace(free=("warp.nx", "weft.nx", "orientation"), specs=spec,
                              lower=np.array([1.0, 1.0, -90.0]), upper=np.array([50.0, 50.0, 90.0]), solve=objective)
    outside = {"warp.nx": 40.0, "weft.nx": 3.0, "orientation": 100.0}  # orientation beyond the box
    twin = _swapped_twin(problem, outside, objective(outside).objective)
    assert twin == {"warp.nx": 3.0, "weft.nx": 40.0, "orientation": 10.0}
    assert _swapped_twin(problem, outside, objective(outside).objective + 1.0) is None  # not the same value


@pytest.mark.parametrize("args, field", [(["--losses", "squared,nope"], "nope"),
                                         (["--loss-scales", "0.1,-2"], "--loss-scales"),
                                         (["--loss-scales", "0.1,abc"], "--loss-scales"),
                                         (["--losses", "huber,huber"], "listed twice")])
def test_cli_refuses_bad_loss_and_stability_options(capsys, args, field):
    from clothlab.cli.main import main

    code = main(["fit", "--select", str(EXAMPLE), *args, "-o", "/tmp/clothlab-select-x"])
    err = capsys.readouterr().err
    assert code == 2 and field in err and "clothlab: error:" in err


def test_cli_refuses_a_negative_stability_count():
    from clothlab.cli.main import main

    with pytest.raises(SystemExit) as exc:
        main(["fit", "--select", str(EXAMPLE), "--stability", "-1", "-o", "/tmp/clothlab-select-x"])
    assert exc.value.code == 2
