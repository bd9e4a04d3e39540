"""Faults below the file formats: the strict number and YAML rules, damaged posterior checkpoints, results
that must never be saved (non-finite numbers), bounded slice tables and image decoding."""

from __future__ import annotations

import math
import re
import zipfile
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clothlab.errors import ClothlabError, InputError, ResultError
from clothlab.untrusted import MAX_NODES, load_json_text, load_yaml_text, parse_number

DECIMAL = r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?"  # the documented notation, written here again


@settings(max_examples=300, deadline=None)
@given(text=st.one_of(st.text(alphabet="0123456789+-.eE_ nainfx\u0661", max_size=10),
                      st.floats(allow_nan=True, allow_infinity=True).map(repr), st.text(max_size=6)))
def test_parse_number_reads_exactly_plain_decimal_notation(text):
    stripped = text.strip()
    expected = None
    if re.fullmatch(DECIMAL, stripped) and len(stripped) <= 64 and math.isfinite(float(stripped)):
        expected = float(stripped)
    try:
        value = parse_number(text, path="f.csv", line=3, field="R")
    except InputError as exc:
        assert expected is None, (text, str(exc))
        assert exc.path == "f.csv" and exc.line == 3 and exc.field == "R"
    else:
        assert value == expected


@settings(max_examples=200, deadline=None)
@given(x=st.floats(allow_nan=False, allow_infinity=False))
def test_every_finite_float_round_trips_through_its_repr(x):
    assert parse_number(repr(x), path="f", line=1, field="x") == x


@pytest.mark.parametrize("text, expected", [
    ("a: 0_1", {"a": "0_1"}), ("a: 2020-02-30", {"a": "2020-02-30"}), ("a: 2020-02-03", {"a": "2020-02-03"}),
    ("a: 1:30", {"a": "1:30"}), ("a: 017", {"a": 17}), ("a: 0x10", {"a": "0x10"}), ("a: 1e3", {"a": 1000.0}),
    ("a: .5", {"a": 0.5}), ("a: -3", {"a": -3}), ("a: .inf", {"a": math.inf}), ("a: yes", {"a": True}),
])
def test_yaml_scalars_follow_the_strict_rules(text, expected):
    assert load_yaml_text(text, path="x.yaml") == expected


@pytest.mark.parametrize("text, fragment", [
    ("a: " + "9" * 31, "31 digits"), ("a: " + "[" * 65 + "]" * 65, "nested"),
    ("a: &a [1, 2]\n" + "".join(f"b{i}: &b{i} [" + ", ".join([f"*{'a' if i == 0 else f'b{i - 1}'}"] * 10) + "]\n"
                                 for i in range(6)), "expands to more than"),
    ("a: \x07", "does not allow"), ("a: [1, 2", "not valid YAML"),
])
def test_yaml_bounds_refuse_with_the_file_named(text, fragment):
    with pytest.raises(InputError, match=fragment) as info:
        load_yaml_text(text, path="x.yaml")
    assert info.value.path == "x.yaml"


def test_alias_expansion_bound_counts_expanded_nodes():
    # 10 ** 6 leaves through six levels of ten aliases: just above the bound once the lists are counted
    levels = ["l0: &l0 [" + ", ".join(["0"] * 10) + "]"]
    levels += [f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 10) + "]" for i in range(1, 6)]
    with pytest.raises(InputError, match="expands"):
        load_yaml_text("\n".join(levels), path="x.yaml")
    assert len(load_yaml_text("\n".join(levels[:4]), path="x.yaml")["l3"]) == 10  # 10**4 leaves: fine
    assert 10**6 > MAX_NODES / 2


@pytest.mark.parametrize("text, fragment", [("[" * 70 + "]" * 70, "nested"), ('{"a": NaN}', "finite"),
                                            ('{"a": 1', "invalid JSON")])
def test_json_bounds(text, fragment):
    with pytest.raises(InputError, match=fragment):
        load_json_text(text, path="fit.json")


# ---------------------------------------------------------------------------------------------------------
# Posterior checkpoints

@pytest.mark.parametrize("damage", ["empty", "truncated", "not-a-zip", "foreign-npz"])
def test_damaged_checkpoint_is_refused_with_a_clear_message(tmp_path, damage):
    from clothlab.fit.posterior.checkpoint import _ChainState, _load_checkpoint, _save_checkpoint

    path = tmp_path / ".x.posterior-checkpoint.npz"
    rng = np.random.default_rng(0)
    state = _ChainState(np.zeros((4, 2)), np.zeros((3, 4, 2)), np.zeros((3, 4)), np.zeros((4, 2)), np.zeros(4),
                        rng.bit_generator.state and np.random.RandomState(1).get_state(legacy=True))
    _save_checkpoint(path, '{"version": 2}', state)
    assert _load_checkpoint(path, '{"version": 2}').steps == 3  # intact: resumes
    data = path.read_bytes()
    if damage == "empty":
        path.write_bytes(b"")
    elif damage == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif damage == "not-a-zip":
        path.write_bytes(b"hello world" * 10)
    else:
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("other.npy", b"")
    with pytest.raises(InputError, match="delete it to start the posterior over") as info:
        _load_checkpoint(path, '{"version": 2}')
    assert info.value.path == str(path)


# ---------------------------------------------------------------------------------------------------------
# Results that must not be saved, bounded slice tables

def _result(params=None, coefficients=None, errors=None):
    return SimpleNamespace(config=SimpleNamespace(path="fabric.yaml"),
                           params=params or {"alpha": 0.1},
                           coefficients=coefficients or {"kd": np.array([0.1, 0.2])},
                           errors=errors or {"overall": {"p50": 0.1, "n": 4}})


@pytest.mark.parametrize("bad", ["param", "coefficient", "prediction", "percentile"])
def test_non_finite_results_are_never_saved(bad):
    from clothlab.fit.store import check_finite_result

    predictions = {"theta_i": np.array([10.0, 20.0]), "model_R": np.array([0.1, 0.2])}
    check_finite_result(_result(), predictions)  # a finite result passes
    if bad == "param":
        result = _result(params={"alpha": math.nan})
    elif bad == "coefficient":
        result = _result(coefficients={"kd": np.array([0.1, math.nan])})
    elif bad == "percentile":
        result = _result(errors={"overall": {"p50": math.nan, "n": 0}})
    else:
        result, predictions = _result(), {**predictions, "model_R": np.array([0.1, math.inf])}
    with pytest.raises(ResultError, match="nothing was saved"):
        check_finite_result(result, predictions)
    assert issubclass(ResultError, ClothlabError) and ResultError.exit_code == 2


@settings(max_examples=50, deadline=None)
@given(counts=st.lists(st.integers(1, 9), min_size=1, max_size=60))
def test_slice_directions_keep_the_most_measured_ones(counts):
    from clothlab.fit.store import MAX_SLICE_DIRECTIONS, slice_directions

    theta_o = np.repeat(np.arange(len(counts), dtype=float), counts)
    phi_o = 2.0 * theta_o
    kept = slice_directions(theta_o, phi_o)
    assert len(kept) == min(len(counts), MAX_SLICE_DIRECTIONS)
    assert len({tuple(r) for r in kept.tolist()}) == len(kept)
    kept_counts = sorted((counts[int(t)] for t in kept[:, 0]), reverse=True)
    assert kept_counts == sorted(counts, reverse=True)[: len(kept)]  # no dropped direction had more rows


def test_image_decoding_is_bounded_before_allocation():
    from clothlab.btf.images import MAX_IMAGE_BYTES, check_image_memory

    check_image_memory(4096, 4096, 3)
    with pytest.raises(InputError, match="give a crop") as info:
        check_image_memory(20000, 20000, 3, path="big.png")
    assert info.value.path == "big.png" and 20000 * 20000 * 3 * 4 > MAX_IMAGE_BYTES
    with pytest.raises(InputError, match="smaller crop"):
        check_image_memory(20000, 20000, 3, cropped=True)


def test_render_memory_is_estimated_before_rendering():
    from clothlab.errors import ConfigError
    from clothlab.render.scene import check_render_memory

    check_render_memory((1280, 720), 4)
    with pytest.raises(ConfigError, match="camera.resolution or render.spp") as info:
        check_render_memory((16384, 16384), 1, source="scene.yaml")
    assert info.value.field == "camera.resolution" and info.value.path == "scene.yaml"
