"""One set of selection defaults (issue 25): the selection's settings are the config's ``select`` section."""

from dataclasses import fields

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
