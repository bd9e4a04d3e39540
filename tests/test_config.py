"""fabric.yaml loading and validation: values, defaults, paths, hash, and errors naming line and field."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clothlab.config import apply_overrides, config_from_dict, load_config
from clothlab.errors import ConfigError

FULL = """\
name: polyester-lining
measurement:
  path: ../measurements/polyester-lining/brdf.csv
  format: astm
  options: {angle_unit: rad}
model:
  kind: irawan
  weave: weaves/lining.wv
  quadrature: {rule: gauss, nodes: 15}
  params: {warp.umax: 22, beta: 4.0}
fit:
  free: [warp.umax, weft.umax, warp.kappa, weft.kappa, alpha, beta]
  bounds: {warp.umax: [5, 60]}
  metric: log
  optimizer: {global: G_MLSL_LDS, local: LN_SBPLX, max_evals: 1234, seed: 7, max_time: 30}
  posterior: {walkers: 40, steps: 500, max_steps: 9000}
  cv_folds: 4
report: {percentiles: [95, 50, 80]}
output: {fits: ../out/fits, reports: ../out/reports}
"""

MINIMAL = """\
name: lining
measurement: {path: ../measurements/polyester-lining/brdf.csv}
model:
  weave: weaves/lining.wv
"""


def project(root: Path, text: str) -> Path:
    """A project tree: configs/fabric.yaml, the measurement and weave files it refers to."""
    (root / "measurements/polyester-lining").mkdir(parents=True, exist_ok=True)
    (root / "measurements/polyester-lining/brdf.csv").write_text("theta_i,phi_i,theta_o,phi_o,value\n")
    (root / "configs/weaves").mkdir(parents=True, exist_ok=True)
    (root / "configs/weaves/lining.wv").write_text("# weave\n")
    path = root / "configs/fabric.yaml"
    path.write_text(text)
    return path


def line_of(text: str, snippet: str) -> int:
    """1-based line of the (unique) line containing ``snippet``, counted independently of the loader."""
    hits = [i + 1 for i, line in enumerate(text.splitlines()) if snippet in line]
    assert len(hits) == 1, (snippet, hits)
    return hits[0]


def edit(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


def fails(tmp_path: Path, text: str) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        load_config(project(tmp_path, text))
    return info.value


# ---------------------------------------------------------------------------------------------------------
# valid configurations


def test_full_config_values_and_resolved_paths(tmp_path):
    config = load_config(project(tmp_path, FULL))
    assert config.name == "polyester-lining"
    assert config.base_dir == tmp_path / "configs"
    assert config.measurement.path == tmp_path / "measurements/polyester-lining/brdf.csv"
    assert (config.measurement.format, config.measurement.options) == ("astm", {"angle_unit": "rad"})
    assert config.model.kind == "irawan"
    assert config.model.weave_path == tmp_path / "configs/weaves/lining.wv"
    assert config.model.weave_preset is None
    assert (config.model.quadrature.rule, config.model.quadrature.nodes) == ("gauss", 15)
    assert config.model.params == {"warp.umax": 22.0, "beta": 4.0}
    fit = config.fit
    assert fit.free == ("warp.umax", "weft.umax", "warp.kappa", "weft.kappa", "alpha", "beta")
    assert fit.bounds == {"warp.umax": (5.0, 60.0)}
    assert fit.metric == "log"
    opt = fit.optimizer
    assert (opt.global_algorithm, opt.local_algorithm, opt.max_evals, opt.seed, opt.max_time) == (
        "G_MLSL_LDS", "LN_SBPLX", 1234, 7, 30.0)
    assert (fit.posterior.walkers, fit.posterior.steps, fit.posterior.max_steps) == (40, 500, 9000)
    assert fit.cv_folds == 4
    assert opt.polish is None and opt.polish_evals == 1234 // 3  # the default final polish
    assert load_config(project(tmp_path, edit(FULL, "max_time: 30}", "max_time: 30, polish: 0}"))
                       ).fit.optimizer.polish_evals == 0
    assert config.report.percentiles == (50.0, 80.0, 95.0)
    assert config.output.fits == tmp_path / "out/fits"
    assert config.output.reports == tmp_path / "out/reports"
    assert config.raw["fit"]["optimizer"]["max_evals"] == 1234


def test_minimal_config_defaults(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = load_config(project(tmp_path, MINIMAL))
    assert config.measurement.format == "auto" and config.measurement.options == {}
    assert config.model.kind == "irawan" and config.model.params == {}
    assert (config.model.quadrature.rule, config.model.quadrature.nodes) == ("trapezoid", 11)
    assert config.fit.free == ("warp.umax", "weft.umax", "warp.kappa", "weft.kappa", "alpha", "beta")
    assert config.fit.metric == "relative" and config.fit.posterior is None and config.fit.cv_folds == 0
    opt = config.fit.optimizer
    assert (opt.global_algorithm, opt.local_algorithm, opt.max_evals, opt.seed, opt.max_time) == (
        "GN_CRS2_LM", "LN_BOBYQA", 4000, 1, None)
    assert config.report.percentiles == (50.0, 80.0, 95.0)
    assert config.output.fits == tmp_path / "fits" and config.output.reports == tmp_path / "reports"


def test_posterior_true_false_and_defaults(tmp_path):
    text = MINIMAL + "fit:\n  free: [warp.umax, alpha]\n"
    on = load_config(project(tmp_path, text + "  posterior: true\n")).fit.posterior
    assert (on.walkers, on.steps, on.max_steps) == (32, 4000, 20000)
    long = load_config(project(tmp_path, text + "  posterior: {steps: 30000}\n")).fit.posterior
    assert long.max_steps == 30000  # the default cap never lies below the steps asked for
    assert load_config(project(tmp_path, text + "  posterior: false\n")).fit.posterior is None
    err = fails(tmp_path, text.replace("[warp.umax, alpha]", "[]") + "  posterior: true\n")
    assert err.field == "fit.posterior" and "at least one parameter" in str(err)


def test_kang_params_are_validated_against_its_declarations(tmp_path):
    text = edit(MINIMAL, "  weave: weaves/lining.wv\n",
                "  kind: kang\n  weave: weaves/lining.wv\n  params: {warp.ny: 40}\n  options: {tile_nodes: 6}\n")
    config = load_config(project(tmp_path, text + "fit: {free: [warp.ny, weft.nx]}\n"))
    assert config.model.kind == "kang" and config.model.params == {"warp.ny": 40.0}
    assert config.model.options == {"tile_nodes": 6} and config.fit.free == ("warp.ny", "weft.nx")
    bad = edit(MINIMAL, "  weave: weaves/lining.wv\n",
               "  kind: kang\n  weave: weaves/lining.wv\n  params: {roughness: 0.3}\n")
    with pytest.raises(ConfigError, match="roughness"):
        load_config(project(tmp_path, bad))


def test_config_from_dict_resolves_against_base_dir(tmp_path):
    project(tmp_path, MINIMAL)
    d = {"name": "x", "measurement": {"path": "measurements/polyester-lining/brdf.csv"},
         "model": {"weave": "configs/weaves/lining.wv", "params": {"alpha": 0.1}}}
    config = config_from_dict(d, base_dir=tmp_path)
    assert config.measurement.path == tmp_path / "measurements/polyester-lining/brdf.csv"
    assert config.model.params == {"alpha": 0.1} and config.path is None
    d["model"]["params"]["alpha"] = -1
    with pytest.raises(ConfigError) as info:
        config_from_dict(d, source="api", base_dir=tmp_path)
    err = info.value
    assert err.field == "model.params.alpha" and err.line is None and err.path == "api"
    assert "-1" in str(err)


# ---------------------------------------------------------------------------------------------------------
# the hash


def test_hash_ignores_location_and_spelling_but_not_settings(tmp_path):
    a = load_config(project(tmp_path / "a", FULL))
    # the same project elsewhere, with the same values spelled differently (block style, 22.0, reordered)
    respelled = edit(FULL, "  params: {warp.umax: 22, beta: 4.0}\n", "  params:\n    beta: 4\n    warp.umax: 22.0\n")
    respelled = edit(respelled, "output: {fits: ../out/fits, reports: ../out/reports}\n", "")
    b = load_config(project(tmp_path / "elsewhere" / "b", respelled))
    assert a.hash == b.hash
    assert len(a.hash) == 64 and int(a.hash, 16) >= 0
    assert str(tmp_path) not in str(a.canonical())
    # a copied tree gives the same hash too
    shutil.copytree(tmp_path / "a", tmp_path / "copy")
    assert load_config(tmp_path / "copy/configs/fabric.yaml").hash == a.hash
    changed = load_config(project(tmp_path / "c", edit(FULL, "seed: 7", "seed: 8")))
    assert changed.hash != a.hash
    assert apply_overrides(a, seed=8).hash == changed.hash


# ---------------------------------------------------------------------------------------------------------
# errors: each names the file, the line and the field, and shows the value found


def test_yaml_syntax_error_line(tmp_path):
    text = edit(FULL, "  metric: log\n", "  metric: log: x\n")
    err = fails(tmp_path, text)
    assert err.line == line_of(text, "metric: log: x")
    assert "YAML" in str(err) and err.path.endswith("fabric.yaml")


def test_unclosed_flow_sequence_reports_a_line(tmp_path):
    text = edit(FULL, "[warp.umax, weft.umax, warp.kappa, weft.kappa, alpha, beta]", "[warp.umax, beta")
    err = fails(tmp_path, text)
    assert err.line is not None and err.line >= line_of(text, "free: [warp.umax, beta")


@pytest.mark.parametrize("text, line", [("- a\n- b\n", 1), ("\n\njust text\n", 3), ("", None)])
def test_not_a_mapping(tmp_path, text, line):
    err = fails(tmp_path, text)
    assert err.line == line and "mapping" in str(err)


def test_unknown_key_suggests_the_closest(tmp_path):
    text = edit(FULL, "  metric: log\n", "  metrik: log\n")
    err = fails(tmp_path, text)
    assert err.line == line_of(text, "metrik")
    assert err.field == "fit.metrik" and "'metrik'" in str(err) and "did you mean 'metric'" in str(err)


def test_unknown_top_level_key(tmp_path):
    text = FULL + "reprot: {}\n"
    err = fails(tmp_path, text)
    assert err.line == line_of(text, "reprot") and "did you mean 'report'" in str(err)


def test_duplicate_key(tmp_path):
    text = edit(FULL, "  metric: log\n", "  metric: log\n  metric: relative\n")
    err = fails(tmp_path, text)
    assert err.line == line_of(text, "metric: relative") and err.field == "fit.metric"
    assert "duplicate" in str(err)


def test_missing_required_keys(tmp_path):
    text = edit(FULL, "  path: ../measurements/polyester-lining/brdf.csv\n", "")
    err = fails(tmp_path, text)
    assert err.field == "measurement.path" and err.line == line_of(text, "measurement:")
    assert "missing required key 'path'" in str(err)
    err = fails(tmp_path, edit(FULL, "name: polyester-lining\n", ""))
    assert err.field == "name" and err.line is None
    text = edit(FULL, "  weave: weaves/lining.wv\n", "")
    err = fails(tmp_path, text)
    assert err.field == "model.weave" and err.line == line_of(text, "model:")


@pytest.mark.parametrize("old, new, field, shown", [
    ("nodes: 15", "nodes: eleven", "model.quadrature.nodes", "'eleven'"),
    ("nodes: 15", "nodes: 15.0", "model.quadrature.nodes", "15.0"),
    ("max_evals: 1234", "max_evals: true", "fit.optimizer.max_evals", "True"),
    ("beta: 4.0}", "beta: four}", "model.params.beta", "'four'"),
    ("cv_folds: 4", "cv_folds: [4]", "fit.cv_folds", "[4]"),
    ("name: polyester-lining", "name: 2024", "name", "2024"),
    ("  free: [warp.umax", "  free: {warp.umax: 1}\n  #", "fit.free", "{'warp.umax': 1}"),
    ("report: {percentiles: [95, 50, 80]}", "report: {percentiles: [95, fifty]}", "report.percentiles[1]",
     "'fifty'"),
])
def test_wrong_type(tmp_path, old, new, field, shown):
    text = edit(FULL, old, new)
    err = fails(tmp_path, text)
    assert err.field == field
    assert err.line == line_of(text, new.splitlines()[0])
    assert shown in str(err) and field in str(err)


def test_invalid_name(tmp_path):
    text = edit(FULL, "name: polyester-lining", "name: my fabric/1")
    err = fails(tmp_path, text)
    assert err.field == "name" and err.line == 1 and "'my fabric/1'" in str(err)


def test_out_of_range_start_value(tmp_path):
    text = edit(FULL, "  params: {warp.umax: 22, beta: 4.0}\n", "  params:\n    beta: 4.0\n    warp.umax: 95\n")
    err = fails(tmp_path, text)
    assert err.line == line_of(text, "warp.umax: 95")
    assert err.field == "model.params.warp.umax" and "95" in str(err) and "physical range" in str(err)


@pytest.mark.parametrize("old, new, field", [
    ("params: {warp.umax: 22,", "params: {warp.umaks: 22,", "model.params.warp.umaks"),
    ("free: [warp.umax, weft.umax,", "free: [warp.umax, weft.umx,", "fit.free[1]"),
    ("bounds: {warp.umax: [5, 60]}", "bounds: {wrap.umax: [5, 60]}", "fit.bounds.wrap.umax"),
])
def test_unknown_parameter_name(tmp_path, old, new, field):
    text = edit(FULL, old, new)
    err = fails(tmp_path, text)
    assert err.field == field and err.line == line_of(text, new)
    bad = field.rsplit(".", 1)[-1] if "[" not in field else "weft.umx"
    assert bad in str(err) and "unknown parameter" in str(err) and "did you mean" in str(err)


@pytest.mark.parametrize("bounds, field, expect", [
    ("[0, 60]", "fit.bounds.warp.umax[0]", "physical range"),      # umax lives in the open (0, 90)
    ("[5, 120]", "fit.bounds.warp.umax[1]", "120"),
    ("[60, 5]", "fit.bounds.warp.umax", "[60, 5]"),
    ("[30, 30]", "fit.bounds.warp.umax", "[30, 30]"),
    ("[5]", "fit.bounds.warp.umax", "[5]"),
    ("[25, 60]", "fit.bounds.warp.umax", "22"),                   # the start value lies outside
])
def test_bad_bounds(tmp_path, bounds, field, expect):
    text = edit(FULL, "bounds: {warp.umax: [5, 60]}", f"bounds:\n    warp.umax: {bounds}")
    err = fails(tmp_path, text)
    assert err.field == field and err.line == line_of(text, f"warp.umax: {bounds}")
    assert expect in str(err)


def test_bounds_for_a_fixed_parameter(tmp_path):
    text = edit(FULL, "bounds: {warp.umax: [5, 60]}", "bounds: {warp.psi: [-10, 10]}")
    err = fails(tmp_path, text)
    assert err.field == "fit.bounds.warp.psi" and "not in fit.free" in str(err)


def test_unknown_preset(tmp_path):
    good = load_config(project(tmp_path, edit(FULL, "weaves/lining.wv", "preset:polyester-lining")))
    assert good.model.weave_preset == "polyester-lining" and good.model.weave_path is None
    # spellings clothlab.weave.presets accepts name the same preset (and give the same hash)
    other = load_config(project(tmp_path, edit(FULL, "weaves/lining.wv", "preset:Polyester_Lining")))
    assert other.model.weave == "preset:polyester-lining" and other.hash == good.hash
    text = edit(FULL, "weaves/lining.wv", "preset:polyester-linin")
    err = fails(tmp_path, text)
    assert err.field == "model.weave" and err.line == line_of(text, "preset:")
    assert "'polyester-linin'" in str(err) and "did you mean 'polyester-lining'" in str(err)


def test_missing_measurement_and_weave_files_name_the_resolved_path(tmp_path):
    text = edit(FULL, "polyester-lining/brdf.csv", "polyester-lining/brdf2.csv")
    err = fails(tmp_path, text)
    assert err.field == "measurement.path" and err.line == line_of(text, "brdf2.csv")
    assert str(tmp_path / "measurements/polyester-lining/brdf2.csv") in str(err)
    text = edit(FULL, "weaves/lining.wv", "weaves/linen.wv")
    err = fails(tmp_path, text)
    assert err.field == "model.weave" and err.line == line_of(text, "linen.wv")
    assert str(tmp_path / "configs/weaves/linen.wv") in str(err)


@pytest.mark.parametrize("old, new, field, bad", [
    ("metric: log", "metric: cuberoot", "fit.metric", "cuberoot"),
    ("rule: gauss", "rule: simpson", "model.quadrature.rule", "simpson"),
    ("global: G_MLSL_LDS", "global: GN_CRS2", "fit.optimizer.global", "GN_CRS2"),
    ("local: LN_SBPLX", "local: LN_BOBYQ", "fit.optimizer.local", "LN_BOBYQ"),
    ("local: LN_SBPLX", "local: GN_CRS2_LM", "fit.optimizer.local", "GN_CRS2_LM"),
    ("format: astm", "format: csv", "measurement.format", "csv"),
    ("kind: irawan", "kind: marschner", "model.kind", "marschner"),
])
def test_unknown_choice(tmp_path, old, new, field, bad):
    text = edit(FULL, old, new)
    err = fails(tmp_path, text)
    assert err.field == field and err.line == line_of(text, new) and f"'{bad}'" in str(err)
    assert "expected one of" in str(err)


def test_optimizer_needs_an_algorithm(tmp_path):
    text = edit(FULL, "global: G_MLSL_LDS, local: LN_SBPLX", "global: null, local: null")
    err = fails(tmp_path, text)
    assert err.line == line_of(text, "optimizer:") and "both null" in str(err)
    text = edit(FULL, "local: LN_SBPLX", "local: null")
    err = fails(tmp_path, text)
    assert err.field == "fit.optimizer.local" and "G_MLSL_LDS" in str(err)
    only_local = load_config(project(tmp_path, edit(FULL, "global: G_MLSL_LDS", "global: null")))
    assert only_local.fit.optimizer.global_algorithm is None


@pytest.mark.parametrize("value", ["0", "-5", str(2**31), "1" + "0" * 23])
def test_max_evals_must_be_a_positive_c_int(tmp_path, value):
    text = edit(FULL, "max_evals: 1234", f"max_evals: {value}")
    err = fails(tmp_path, text)
    assert err.field == "fit.optimizer.max_evals" and err.line == line_of(text, "optimizer:")
    assert value in str(err) and f"[1, {2**31 - 1}]" in str(err)


def test_walkers_at_least_twice_the_free_parameters(tmp_path):
    text = edit(FULL, "walkers: 40", "walkers: 11")
    err = fails(tmp_path, text)
    assert err.field == "fit.posterior.walkers" and err.line == line_of(text, "walkers: 11")
    assert "11" in str(err) and "12" in str(err)  # 6 free parameters need 12 walkers
    assert load_config(project(tmp_path, edit(FULL, "walkers: 40", "walkers: 12"))).fit.posterior.walkers == 12


@pytest.mark.parametrize("old, new, field", [
    ("max_steps: 9000", "max_steps: 400", "fit.posterior.max_steps"),
    ("cv_folds: 4", "cv_folds: 1", "fit.cv_folds"),
    ("max_time: 30", "max_time: 0", "fit.optimizer.max_time"),
    ("seed: 7", "seed: -1", "fit.optimizer.seed"),
    ("[95, 50, 80]", "[95, 50, 101]", "report.percentiles[2]"),
    ("[95, 50, 80]", "[95, 50, 95]", "report.percentiles[2]"),
    ("nodes: 15", "nodes: 1", "model.quadrature.nodes"),
    ("nodes: 15", "nodes: 1001", "model.quadrature.nodes"),
])
def test_out_of_range_settings(tmp_path, old, new, field):
    text = edit(FULL, old, new)
    err = fails(tmp_path, text)
    assert err.field == field and err.line == line_of(text, new)
    assert new.split()[-1].strip("[]") in str(err)


def test_block_style_lines_point_at_the_value(tmp_path):
    text = edit(FULL, "  optimizer: {global: G_MLSL_LDS, local: LN_SBPLX, max_evals: 1234, seed: 7, max_time: 30}\n",
                "  optimizer:\n    global: G_MLSL_LDS\n    local: LN_SBPLX\n    max_evals:\n      -3\n")
    err = fails(tmp_path, text)
    assert err.field == "fit.optimizer.max_evals" and err.line == line_of(text, "-3")


@pytest.mark.parametrize("written", ['"a\\0b.csv"', "x" * 5000 + ".csv", "~no_such_user_4711/brdf.csv", '""'])
def test_unusable_measurement_paths(tmp_path, written):
    text = edit(FULL, "../measurements/polyester-lining/brdf.csv", written)
    err = fails(tmp_path, text)
    assert err.field == "measurement.path" and err.line == 3


def test_anchors_merges_and_cycles(tmp_path):
    text = edit(FULL, "  posterior: {walkers: 40, steps: 500, max_steps: 9000}\n",
                "  posterior:\n    <<: &chain {steps: 500, max_steps: 9000}\n    walkers: 40\n")
    assert load_config(project(tmp_path, text)).fit.posterior.max_steps == 9000
    err = fails(tmp_path, edit(text, "max_steps: 9000", "max_steps: 300"))
    assert err.field == "fit.posterior.max_steps" and err.line == line_of(text, "<<: &chain")
    err = fails(tmp_path, edit(FULL, "  options: {angle_unit: rad}", "  options: &loop {a: *loop}"))
    assert err.line == line_of(FULL, "options:") and "cycle" in str(err)


def test_missing_config_file(tmp_path):
    with pytest.raises(ConfigError) as info:
        load_config(tmp_path / "nope.yaml")
    assert "nope.yaml" in str(info.value)


# ---------------------------------------------------------------------------------------------------------
# command-line overrides


def test_overrides_apply_and_validate(tmp_path):
    config = load_config(project(tmp_path, FULL))
    new = apply_overrides(config, rule="adaptive", nodes="21", max_evals=50, seed=3)
    assert (new.model.quadrature.rule, new.model.quadrature.nodes) == ("adaptive", 21)
    assert (new.fit.optimizer.max_evals, new.fit.optimizer.seed) == (50, 3)
    assert new.fit.optimizer.global_algorithm == "G_MLSL_LDS" and new.model.params == config.model.params
    assert config.model.quadrature.nodes == 15  # the original is unchanged
    assert new.hash != config.hash and apply_overrides(config).hash == config.hash
    for kwargs, field, shown in [({"nodes": 5000}, "--nodes", "5000"), ({"nodes": "many"}, "--nodes", "many"),
                                 ({"rule": "simpson"}, "--rule", "simpson"),
                                 ({"max_evals": 0}, "--max-evals", "0"), ({"seed": -2}, "--seed", "-2")]:
        with pytest.raises(ConfigError) as info:
            apply_overrides(config, **kwargs)
        assert info.value.field == field and info.value.line is None and shown in str(info.value)


# ---------------------------------------------------------------------------------------------------------
# robustness and documentation


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(start=st.integers(0, len(FULL)), length=st.integers(0, 12),
       junk=st.text(alphabet=st.sampled_from(list(" \t\n:-[]{},#&*!|>'\"0123456789.eanulx")), max_size=12))
def test_mangled_yaml_gives_a_config_or_a_config_error(tmp_path, start, length, junk):
    text = FULL[:start] + junk + FULL[start + length:]
    try:
        config = load_config(project(tmp_path, text))
    except ConfigError as err:
        assert err.path.endswith("fabric.yaml")
        assert err.line is None or 1 <= err.line <= text.count("\n") + 1
    else:
        assert config.hash == load_config(tmp_path / "configs/fabric.yaml").hash


def test_reference_lists_every_key_choice_and_parameter():
    from clothlab.config.choices import CV_SCHEMES, GLOBAL_ALGORITHMS, LOCAL_ALGORITHMS, METRICS
    from clothlab.io.loader import FORMAT_CHOICES
    from clothlab.models.irawan.parameters import IRAWAN_PARAMS
    from clothlab.models.irawan.quadrature import RULES
    from clothlab.models.registry import MODEL_KINDS

    doc = (Path(__file__).parent.parent / "docs" / "fabric-yaml.md").read_text()
    keys = ["name", "measurement.path", "measurement.format", "measurement.options", "model.kind",
            "model.weave", "model.quadrature.rule", "model.quadrature.nodes", "model.params", "fit.free",
            "fit.bounds", "fit.metric", "fit.optimizer.global", "fit.optimizer.local",
            "fit.optimizer.max_evals", "fit.optimizer.seed", "fit.optimizer.max_time", "fit.posterior.walkers",
            "fit.posterior.steps", "fit.posterior.max_steps", "fit.cv_folds", "fit.cv_scheme", "report.percentiles",
            "output.fits", "output.reports"]
    words = keys + [f"`{name}`" for name in IRAWAN_PARAMS.names()]
    for group in (FORMAT_CHOICES, MODEL_KINDS, RULES, METRICS, CV_SCHEMES, GLOBAL_ALGORITHMS, LOCAL_ALGORITHMS):
        words += [f"`{c}`" for c in group]
    missing = [w for w in words if w not in doc]
    assert not missing


def test_start_outside_the_declared_fit_bounds_is_refused_not_clipped(tmp_path):
    from clothlab.models.irawan.parameters import IRAWAN_PARAMS

    lo, hi = IRAWAN_PARAMS["beta"].bounds
    start = hi * 1.5  # inside beta's physical range, outside the declared fit bounds
    assert IRAWAN_PARAMS["beta"].check(start) == start
    text = edit(FULL, "beta: 4.0}", f"beta: {start:g}}}")
    err = fails(tmp_path, text)
    assert err.field == "model.params.beta" and err.line == line_of(text, "params: {")
    assert f"[{lo:g}, {hi:g}]" in str(err) and "fit.bounds.beta" in str(err)


def test_polish_must_be_a_non_negative_count(tmp_path):
    text = edit(FULL, "max_time: 30}", "max_time: 30, polish: -3}")
    err = fails(tmp_path, text)
    assert err.field == "fit.optimizer.polish" and "-3" in str(err)


# ---------------------------------------------------------------------------------------------------------
# the YAML line map (public API)


def _flatten(value, prefix=()):
    """Every key path of plain data in insertion order, computed without the line map."""
    out = []
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, list):
        items = enumerate(value)
    else:
        return out
    for k, v in items:
        out.append(prefix + (k,))
        out += _flatten(v, prefix + (k,))
    return out


def position_of(text: str, line_snippet: str, token: str) -> tuple[int, int]:
    """1-based (line, column) of ``token`` on the unique line containing ``line_snippet``."""
    line = line_of(text, line_snippet)
    return line, text.splitlines()[line - 1].index(token) + 1


def test_line_map_positions_of_values_keys_and_defaults(tmp_path):
    import yaml

    from clothlab.config import LineMap, load_yaml_with_lines
    from clothlab.config.linemap import dotted

    path = project(tmp_path, FULL)
    data, lines = load_yaml_with_lines(path)
    assert data == yaml.safe_load(FULL) and isinstance(lines, LineMap) and lines.source == str(path)
    assert lines.at("fit.optimizer.max_evals") == position_of(FULL, "optimizer:", "1234")
    assert lines.at("fit.optimizer.max_evals", key=True) == position_of(FULL, "optimizer:", "max_evals")
    assert lines.at("model.params.warp.umax") == position_of(FULL, "params:", "22")  # a key holding a dot
    assert lines.at(("model", "params", "warp.umax")) == lines.at("model.params.warp.umax")
    assert lines.at("report.percentiles[1]") == position_of(FULL, "percentiles", "50")
    assert lines.at("name") == (1, len("name: ") + 1) and lines.at("name", key=True) == (1, 1)
    # a default (not written) sits at the key of its nearest written parent; nothing written: no position
    assert lines.at("fit.optimizer.polish") == position_of(FULL, "optimizer:", "optimizer")
    assert lines.at("model.params.alpha") == position_of(FULL, "params:", "params")
    assert lines.at("nothing.here") == (None, None) and lines.line("fit.metric") == line_of(FULL, "metric: log")
    assert lines.fields() == [dotted(p) for p in _flatten(data)]
    assert LineMap().at("fit.metric") == (None, None)


def test_line_map_of_text_with_merge_keys_and_errors():
    from clothlab.config import parse_yaml_with_lines

    text = "base: &b {x: 1, y: 2}\nuse:\n  <<: *b\n  y: 3\n"
    data, lines = parse_yaml_with_lines(text, source="t.yaml")
    assert data["use"] == {"x": 1, "y": 3}
    assert lines.at("use.y") == position_of(text, "  y: 3", "3")  # the explicit key wins over the merged one
    assert lines.at("use.x") == position_of(text, "base:", "1")  # a merged key sits where the anchor wrote it
    with pytest.raises(ConfigError) as info:
        parse_yaml_with_lines("a: 1\nb:\n  c: 2\n  c: 3\n", source="t.yaml")
    assert (info.value.path, info.value.line, info.value.field) == ("t.yaml", 4, "b.c")
    assert parse_yaml_with_lines("", source="t.yaml")[0] is None


# ---------------------------------------------------------------------------------------------------------
# each closed list is declared once, by the module that implements it


def test_closed_lists_come_from_their_owners(tmp_path):
    import numpy as np

    from clothlab.config import choices
    from clothlab.fit import metrics, optimize
    from clothlab.io.loader import FORMAT_CHOICES, FORMATS, READERS
    from clothlab.models.irawan.model import Quadrature
    from clothlab.models.irawan.quadrature import RULES

    assert optimize.SUPPORTED_GLOBAL is choices.GLOBAL_ALGORITHMS
    assert optimize.SUPPORTED_LOCAL is choices.LOCAL_ALGORITHMS and metrics.METRICS is choices.METRICS
    assert set(FORMAT_CHOICES) == {"auto", *READERS} and set(FORMATS) == set(READERS)
    measured = np.array([0.5, 1.0, 2.0])
    for metric in choices.METRICS:  # every metric the validator accepts is one the fitter computes
        assert np.allclose(metrics.metric_residuals(measured, measured, metric), 0.0)
        assert np.all(metrics.metric_residuals(measured, 2 * measured, metric) > 0)
    for rule in RULES:  # every rule the validator accepts builds a quadrature
        config = load_config(project(tmp_path, edit(FULL, "rule: gauss", f"rule: {rule}")))
        assert config.model.quadrature.rule == rule == apply_overrides(config, rule=rule).model.quadrature.rule
        assert Quadrature(rule, 8).rule == rule
    for fmt in FORMAT_CHOICES:
        text = edit(edit(FULL, "format: astm", f"format: {fmt}"), "  options: {angle_unit: rad}\n", "")
        assert load_config(project(tmp_path, text)).measurement.format == fmt


@pytest.mark.parametrize("options, field, fragment", [
    ("{angle_units: rad}", "measurement.options.angle_units", "not accepted by the astm reader"),
    ("{angle_unit: radians}", "measurement.options.angle_unit", "expected one of deg | rad"),
    ("{up: north}", "measurement.options.up", "not accepted"),
])
def test_measurement_options_are_checked_at_their_line(tmp_path, options, field, fragment):
    text = edit(FULL, "options: {angle_unit: rad}", f"options: {options}")
    err = fails(tmp_path, text)
    assert err.field == field and err.line == line_of(text, f"options: {options}") and fragment in str(err)
    assert err.path is not None and err.path.endswith("fabric.yaml")


def test_model_options_are_checked_at_their_line(tmp_path):
    text = edit(FULL, "kind: irawan\n", "kind: irawan\n  options: {no_such_option: 1}\n")
    err = fails(tmp_path, text)
    assert err.field == "model.options.no_such_option" and err.line == line_of(text, "options: {no_such")


def test_auto_format_detects_like_no_format():
    from clothlab.io.loader import AUTO, load_measurement

    path = Path(__file__).parent.parent / "measurements" / "silk-charmeuse" / "clean.csv"
    auto, detected = load_measurement(path, AUTO), load_measurement(path)
    assert auto.values.shape == detected.values.shape and (auto.values == detected.values).all()


def test_version_is_declared_once():
    import tomllib

    import clothlab

    pyproject = tomllib.loads((Path(__file__).parent.parent / "pyproject.toml").read_text())
    assert "version" not in pyproject["project"] and "version" in pyproject["project"]["dynamic"]
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "clothlab.__version__"}
    package = Path(clothlab.__file__).parent
    declared = [str(f.relative_to(package)) for f in package.rglob("*.py")
                if any(line.startswith("__version__") for line in f.read_text(encoding="utf-8").splitlines())]
    assert declared == ["__init__.py"]


def test_cv_scheme_defaults_to_auto_and_keeps_the_config_hash(tmp_path):
    """fit.cv_scheme: auto unless given; the default leaves the canonical form (and so older hashes) unchanged."""
    from clothlab.fit import crossval

    default = load_config(project(tmp_path, FULL))
    assert default.fit.cv_scheme == "auto" and "cv_scheme" not in default.canonical()["fit"]
    chosen = load_config(project(tmp_path, edit(FULL, "cv_folds: 4", "cv_folds: 4\n  cv_scheme: random")))
    assert chosen.fit.cv_scheme == "random" and chosen.canonical()["fit"]["cv_scheme"] == "random"
    assert chosen.hash != default.hash
    assert crossval.SCHEMES == ("auto", "grouped", "grouped-incident", "leave-one-direction-out", "random")
    text = edit(FULL, "cv_folds: 4", "cv_folds: 4\n  cv_scheme: leave-one-out")
    err = fails(tmp_path, text)
    assert err.field == "fit.cv_scheme" and err.line == line_of(text, "cv_scheme:")
    assert "leave-one-out" in str(err) and "random" in str(err)


@pytest.mark.parametrize("value", ["1", "0", "2000", "12.5", "true", "many"])
def test_orientation_average_out_of_range_is_named_at_its_line(tmp_path, value):
    text = edit(FULL, "  cv_folds: 4\n", f"  cv_folds: 4\n  orientation_average: {value}\n")
    err = fails(tmp_path, text)
    assert err.field == "fit.orientation_average" and err.line == line_of(text, "orientation_average")


def test_orientation_average_is_read_and_hashed_only_when_not_the_default(tmp_path):
    default = load_config(project(tmp_path, FULL))
    given = load_config(project(tmp_path, edit(FULL, "  cv_folds: 4\n", "  cv_folds: 4\n  orientation_average: 32\n")))
    assert default.fit.orientation_average == 128 and given.fit.orientation_average == 32
    assert given.hash != default.hash
