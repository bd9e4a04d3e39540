"""One quadrature form: fabric.yaml, the command line (--rule/--nodes), fit.json and the API
(``Quadrature(rule, nodes)``) accept and refuse the same (rule, nodes), and give the same Quadrature.

The rule set is independent of the code under test: the documented range (docs/fabric-yaml.md: every rule,
nodes an integer from 2 to 1000) and the rule names of the module docstring."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clothlab.config import apply_overrides, config_from_dict, override_quadrature
from clothlab.config.build import model_from_fit
from clothlab.errors import ClothlabError, ConfigError, InputError, ParameterError
from clothlab.models.irawan.quadrature import Quadrature

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTED_RULES = ("trapezoid", "gauss", "support", "adaptive")

rules = st.one_of(st.sampled_from(DOCUMENTED_RULES), st.sampled_from(("simpson", "Gauss", "", "trapezoid ")),
                  st.none(), st.integers(-2, 3))
nodes = st.one_of(st.integers(-3, 1003), st.sampled_from((2, 1000, 1, 1001, 0)), st.floats(-2, 20),
                  st.booleans(), st.none(), st.sampled_from(("11", "eleven")))


def documented(rule, n) -> bool:
    """What docs/fabric-yaml.md allows."""
    return rule in DOCUMENTED_RULES and type(n) is int and 2 <= n <= 1000


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    root = tmp_path_factory.mktemp("quadrature")
    shutil.copy(ROOT / "measurements" / "cotton-twill" / "noisy.csv", root / "noisy.csv")
    shutil.copy(ROOT / "fits" / "cotton-twill" / "weave.wv", root / "weave.wv")
    return root


def outcome(call):
    try:
        return call()
    except ClothlabError as exc:
        return exc


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rule=rules, n=nodes)
def test_yaml_api_and_fit_json_accept_the_same_quadratures(base, rule, n):
    api = outcome(lambda: Quadrature(rule, n))
    yaml = outcome(lambda: config_from_dict({"name": "q", "measurement": {"path": "noisy.csv"},
                                             "model": {"weave": "preset:cotton-twill",
                                                       "quadrature": {"rule": rule, "nodes": n}}},
                                            base_dir=base).model.quadrature)
    fit = json.loads((ROOT / "fits" / "cotton-twill" / "fit.json").read_text())
    fit["model"]["quadrature"] = {"rule": rule, "nodes": n}
    saved = outcome(lambda: model_from_fit(fit, base).quadrature)
    ok = documented(rule, n)
    assert isinstance(api, Quadrature) == ok, (rule, n, api)
    assert isinstance(yaml, Quadrature) == ok, (rule, n, yaml)
    assert isinstance(saved, Quadrature) == ok, (rule, n, saved)
    if ok:
        assert api == yaml == saved == Quadrature(rule, n) and (api.rule, api.nodes) == (rule, n)
    else:  # each refusal names the field at fault, in the error class of its source
        assert isinstance(api, ParameterError) and isinstance(yaml, ConfigError) and isinstance(saved, InputError)
        assert api.field == yaml.field == saved.field, (api.field, yaml.field, saved.field)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rule=st.one_of(st.sampled_from(DOCUMENTED_RULES), st.sampled_from(("simpson", "Gauss"))),
       n=st.one_of(st.integers(-3, 1003), st.sampled_from((1, 2, 1000, 1001))))
def test_command_line_overrides_accept_what_the_api_accepts(base, rule, n):
    config = config_from_dict({"name": "q", "measurement": {"path": "noisy.csv"},
                               "model": {"weave": "preset:cotton-twill"}}, base_dir=base)
    api = outcome(lambda: Quadrature(rule, n))
    overridden = outcome(lambda: apply_overrides(config, rule=rule, nodes=str(n)).model.quadrature)
    alone = outcome(lambda: override_quadrature(rule=rule, nodes=n))
    ok = documented(rule, n)
    assert isinstance(api, Quadrature) == isinstance(overridden, Quadrature) == isinstance(alone, Quadrature) == ok
    if ok:
        assert api == overridden == alone
    else:  # the option at fault is named
        assert overridden.field == alone.field == ("--rule" if rule not in DOCUMENTED_RULES else "--nodes")


def test_defaults_are_the_papers_and_defined_once(base):
    """trapezoid 11 (Irawan & Marschner 2012, sec. 7.3) wherever nothing is given."""
    config = config_from_dict({"name": "q", "measurement": {"path": "noisy.csv"},
                               "model": {"weave": "preset:cotton-twill"}}, base_dir=base)
    fit = json.loads((ROOT / "fits" / "cotton-twill" / "fit.json").read_text())
    del fit["model"]["quadrature"], fit["config"]
    assert config.model.quadrature == override_quadrature() == Quadrature.from_record({}) == \
        model_from_fit(fit, base).quadrature == Quadrature("trapezoid", 11)
