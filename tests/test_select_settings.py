"""One set of selection defaults (issue 25): the selection's settings are the config's ``select`` section."""

from dataclasses import fields

import pytest

from clothlab.config.schema import SelectConfig
from clothlab.fit import select as sel
from clothlab.weave.presets import PRESET_NAMES


def test_settings_are_the_config_section():
    assert sel.SelectSettings is SelectConfig
    names = {f.name for f in fields(SelectConfig)}
    assert {"weaves", "kinds", "orientation_starts", "max_evals", "cv_folds", "nested", "losses", "loss_scales",
            "stability"} <= names
    # no second copy of a default in clothlab.fit.select
    assert not [n for n in vars(sel) if n.startswith("DEFAULT_")]


def test_empty_weaves_mean_every_preset():
    s = SelectConfig(kinds=("irawan",), orientation_starts=1)
    assert sel.weaves_of(s) == tuple("preset:" + n for n in PRESET_NAMES)
    assert len(sel.candidates(s)) == len(PRESET_NAMES)
    assert sel.weaves_of(SelectConfig(weaves=("preset:cotton-twill",))) == ("preset:cotton-twill",)


def _project(tmp_path, select: str):
    (tmp_path / "t.csv").write_text("theta_i,phi_i,theta_o,phi_o,value\n")
    path = tmp_path / "fabric.yaml"
    path.write_text(f"name: t\nmeasurement: {{path: t.csv}}\nmodel: {{weave: preset:cotton-twill}}\n"
                    f"select: {select}\n")
    return path


def test_the_yaml_select_section_takes_the_checks_on_top(tmp_path):
    """select.nested / losses / loss_scales / stability (issue 28): read from fabric.yaml, with the CLI's bounds,
    and a command-line value still replaces the yaml's."""
    from clothlab.config import load_config

    cfg = load_config(_project(tmp_path, "{nested: 5, losses: [huber, squared], loss_scales: [0.05, 0.1], "
                                          "stability: 8}"))
    s = sel.settings_from_config(cfg)
    assert (s.nested, s.losses, s.loss_scales, s.stability) == (5, ("huber", "squared"), (0.05, 0.1), 8)
    assert sel.settings_from_config(cfg, nested=0, losses=["cauchy"]).nested == 0
    assert sel.settings_from_config(cfg, nested=0, losses=["cauchy"]).losses == ("cauchy",)


@pytest.mark.parametrize("select, field", [("{nested: 1}", "select.nested"), ("{nested: 101}", "select.nested"),
                                           ("{losses: [huberr]}", "select.losses[0]"),
                                           ("{losses: [huber, huber]}", "select.losses[1]"),
                                           ("{loss_scales: [0]}", "select.loss_scales[0]"),
                                           ("{loss_scales: [.nan]}", "select.loss_scales[0]"),
                                           ("{stability: -1}", "select.stability"),
                                           ("{stabilty: 3}", "select.stabilty")])
def test_bad_select_checks_are_refused_at_their_field(tmp_path, select, field):
    from clothlab.config import load_config
    from clothlab.errors import ConfigError

    with pytest.raises(ConfigError) as info:
        load_config(_project(tmp_path, select))
    assert field in str(info.value) and "fabric.yaml:4" in str(info.value)


def test_the_default_search_is_the_measured_one():
    """The defaults docs/select.md measured under nested CV on the shared CUReT fabrics: IM + Oren-Nayar with
    the fibre sheen and the Fresnel factor (index free), without and with the opposition surge, huber at 0.1;
    ``losses: []`` falls back to fabric.yaml's fit.loss."""
    from clothlab.models.registry import DEFAULT_SELECT_KINDS, MODEL_KINDS

    d = SelectConfig()
    assert d.kinds == DEFAULT_SELECT_KINDS and set(d.kinds) <= set(MODEL_KINDS)
    assert (d.losses, d.loss_scales) == (("huber",), (0.1,))
    names = [c.name for c in sel.candidates(SelectConfig(weaves=("preset:cotton-twill",), orientation_starts=1))]
    assert names == ["cotton-twill irawan+oren-nayar+sheen+fresnel-eta huber 0.1 #1",
                     "cotton-twill irawan+oren-nayar+sheen+retro+fresnel-eta huber 0.1 #1"]
    plain = [c.name for c in sel.candidates(SelectConfig(weaves=("preset:cotton-twill",), kinds=("irawan",),
                                                         orientation_starts=1, losses=()))]
    assert plain == ["cotton-twill irawan #1"]
