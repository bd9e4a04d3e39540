"""The input families of models and surrogates (issue 24): weights ``.npz``, their ``.json`` sidecars, model
options, ``clothlab eval`` direction CSVs, ``train-surrogate --vary`` specs and weave-free kinds.

Each family has a hypothesis strategy that draws bad inputs from a valid one (corrupt zips, mutated sidecars,
fields from ``BAD_TOKENS``, option values), and every outcome must be a
:class:`~clothlab.errors.ClothlabError` naming the place (file, and a line or a field, one line) or a result
that passes an independent validity check.  ``CLOTHLAB_FUZZ_EXAMPLES=N`` draws N cases per family (as
tests/test_fuzz_inputs.py); each test prints its outcome counts (``pytest -s``).  Then one test per finding
of the issue, each of which failed on the code before it (noted in its docstring).
"""

from __future__ import annotations

import collections
import copy
import io
import json
import math
import os
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_fuzz_inputs import BAD_TOKENS, TOKENS, check_named, clothlab_lines, mutate_lines, replace_field, report

from clothlab.errors import ClothlabError, ConfigError, InputError

EXAMPLES = int(os.environ.get("CLOTHLAB_FUZZ_EXAMPLES", "25"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
REPO = Path(__file__).parent.parent
SHIPPED = REPO / "clothlab/models/neural/data/cotton-denim.npz"
DIRECTIONS = ([30.0, 10.0, 60.0, 75.0], [0.0, 90.0, 200.0, 330.0], [30.0, 50.0, 20.0, 5.0], [180.0, 10.0, 0.0, 45.0])


def directions():
    from clothlab.frames import spherical_to_vector

    ti, pi, to, po = (np.array(a) for a in DIRECTIONS)
    return spherical_to_vector(ti, pi), spherical_to_vector(to, po)


def named_or_whole_file(exc: ClothlabError, *paths) -> None:
    """:func:`check_named`, except that a refusal of the whole file (empty, not a zip, no such file) may name
    only the file."""
    if exc.field is None and exc.line is None:
        assert exc.path is not None and any(str(p) in exc.path for p in paths), (exc.path, paths)
        assert any(w in exc.detail for w in ("empty", "not a .npz", "not found", "bytes; at most")), str(exc)
        assert "\n" not in str(exc).strip()
        return
    check_named(exc, *paths)


def copy_weights(tmp_path: Path, name: str = "w") -> Path:
    npz = tmp_path / f"{name}.npz"
    shutil.copy(SHIPPED, npz)
    shutil.copy(SHIPPED.with_suffix(".json"), npz.with_suffix(".json"))
    return npz


def npz_bytes(arrays: dict, *, compress: bool = False) -> bytes:
    buffer = io.BytesIO()
    (np.savez_compressed if compress else np.savez)(buffer, allow_pickle=False, **arrays)
    return buffer.getvalue()


def shipped_arrays() -> dict:
    with np.load(SHIPPED, allow_pickle=False) as data:
        return {k: data[k].copy() for k in data.files}


def valid_neural(model) -> None:
    """An accepted network answers finite, non-negative components at a few directions."""
    wi, wo = directions()
    comps = model.components(wi, wo)
    assert set(comps) == set(model.component_names)
    for name, value in comps.items():
        assert np.isfinite(value).all() and (value >= 0).all() and (value < 1e6).all(), (name, value)


# ---------------------------------------------------------------------------------------------------------
# Weights .npz: a strategy of corrupt archives

def _zip_with(members: dict[str, bytes], method=zipfile.ZIP_STORED) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=method) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return buffer.getvalue()


def _npy(array) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=True)
    return buffer.getvalue()


def corrupt_weights(data: bytes, arrays: dict, draw) -> bytes:
    """One corruption of the weights archive ``data`` (its ``arrays``), chosen by ``draw``."""
    names = sorted(arrays)
    kind = draw(st.sampled_from(["truncate", "empty", "garbage", "flip", "value", "shape", "dtype", "pickle",
                                 "extra", "missing", "bomb", "npy-header", "deflated-value"]))
    if kind == "truncate":
        return data[:draw(st.integers(0, len(data) - 1))]
    if kind == "empty":
        return b""
    if kind == "garbage":
        return draw(st.binary(max_size=200)) + data[draw(st.integers(0, len(data))):]
    if kind == "flip":
        k = draw(st.integers(0, len(data) - 1))
        return data[:k] + bytes([data[k] ^ draw(st.integers(1, 255))]) + data[k + 1:]
    out = dict(arrays)
    name = draw(st.sampled_from(names))
    if kind in ("value", "deflated-value"):
        value = draw(st.sampled_from([np.inf, -np.inf, np.nan, 1e38, -3e38, 1e5, 1e300, 0.0, 0.5]))
        changed = out[name].astype(np.float64 if abs(value) > 3.4e38 else out[name].dtype)
        changed.flat[draw(st.integers(0, changed.size - 1))] = value
        out[name] = changed
        return npz_bytes(out, compress=kind == "deflated-value")
    if kind == "shape":
        out[name] = np.zeros(draw(st.sampled_from([(1,), (0,), (3, 3), (100000,), (2, 2, 2)])))
        return npz_bytes(out)
    if kind == "dtype":
        out[name] = out[name].astype(draw(st.sampled_from([np.int64, np.complex128, np.float16, np.bool_, "U3"])))
        return npz_bytes(out)
    members = {f"{k}.npy": _npy(v) for k, v in out.items()}
    if kind == "pickle":
        members[f"{name}.npy"] = _npy(np.array([{"a": 1}, None], dtype=object))
    elif kind == "extra":
        members["__extra__.npy"] = _npy(np.zeros(3))
    elif kind == "missing":
        del members[f"{name}.npy"]
    elif kind == "bomb":
        members[f"{name}.npy"] = members[f"{name}.npy"] + b"\0" * (1 << 22)
        return _zip_with(members, zipfile.ZIP_DEFLATED)
    elif kind == "npy-header":
        raw = members[f"{name}.npy"]
        cut = draw(st.integers(0, 140))
        members[f"{name}.npy"] = raw[:cut] + draw(st.binary(max_size=20)) + raw[cut + 20:]
    return _zip_with(members)


def test_fuzz_weights_npz(tmp_path):
    """Corrupt weights are refused naming the .npz (and the member), or load to a finite network."""
    from clothlab.models.neural.model import NeuralModel
    from clothlab.surrogate.serialise import MAX_WEIGHT, load_surrogate
    from clothlab.weave.presets import get_preset

    npz = copy_weights(tmp_path)
    data, arrays = npz.read_bytes(), shipped_arrays()
    weave = get_preset("cotton-denim")
    valid_neural(NeuralModel(weave, weights=str(npz)))  # the uncorrupted copy is valid
    counts = collections.Counter()

    @SETTINGS
    @given(draw=st.data())
    def run(draw):
        npz.write_bytes(corrupt_weights(data, arrays, draw.draw))
        try:
            surrogate, _ = load_surrogate(npz)
        except ClothlabError as exc:
            named_or_whole_file(exc, npz)
            counts["refused (named)"] += 1
            with pytest.raises(ConfigError) as err:  # the model names the file and the option
                NeuralModel(weave, weights=str(npz))
            check_named(err.value, npz)
            assert err.value.field == "model.options.weights"
            return
        counts["accepted (valid)"] += 1
        for value in surrogate.network.params().values():
            assert np.isfinite(value).all() and np.abs(value).max() <= MAX_WEIGHT
        valid_neural(NeuralModel(weave, weights=str(npz)))

    run()
    report("weights .npz", counts)
    assert counts["refused (named)"] > 0


# ---------------------------------------------------------------------------------------------------------
# Sidecar JSON: a strategy of mutated sidecars

SIDECAR_VALUES = [None, True, False, "x", "", "complex128", "float16", -1, 0, 1, 2, 3, 8, 1e9, 10**30, 1e-320,
                  5e-324, 1e308, -1e308, 0.5, -0.0, [], {}, [1, 2], {"a": 1}, [None], "nan", 64, 1025, 1e38]


def _leaves(value, prefix=()):
    """Every (path, value) of a JSON document, containers included."""
    out = [(prefix, value)]
    if isinstance(value, dict):
        for k, v in value.items():
            out += _leaves(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value[:4]):
            out += _leaves(v, prefix + (i,))
    return out


def _mutate(doc, path, op, value):
    doc = copy.deepcopy(doc)
    if not path:
        return value
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    if op == "delete":
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return doc


SIDECAR_PATHS = [p for p, _ in _leaves(json.loads(SHIPPED.with_suffix(".json").read_text()))
                 if not (p and p[0] == "metrics")] + [("metrics",)]


def test_fuzz_sidecar(tmp_path):
    """Mutated sidecars are refused naming the sidecar and the dotted field (read_sidecar) and, through the
    model, the file and the option; or the model built from them answers finite components."""
    from clothlab.models.neural.model import NeuralModel
    from clothlab.surrogate.serialise import read_sidecar
    from clothlab.weave.presets import get_preset

    npz = copy_weights(tmp_path)
    sidecar = npz.with_suffix(".json")
    doc = json.loads(sidecar.read_text())
    weave = get_preset("cotton-denim")
    counts = collections.Counter()

    @SETTINGS
    @given(path=st.sampled_from(SIDECAR_PATHS), op=st.sampled_from(["delete", "set", "set"]),
           value=st.one_of(st.sampled_from(SIDECAR_VALUES), st.integers(-2, 2**70), st.text(max_size=8),
                           st.floats(allow_nan=False)))
    def run(path, op, value):
        if op == "delete" and not path:
            op = "set"
        sidecar.write_text(json.dumps(_mutate(doc, path, op, value)))
        try:
            read_sidecar(npz)
            model = NeuralModel(weave, weights=str(npz))
        except ClothlabError as exc:
            check_named(exc, sidecar, npz)
            counts["refused (named)"] += 1
            return
        counts["accepted (valid)"] += 1
        valid_neural(model)

    run()
    report("sidecar .json", counts)
    assert counts["refused (named)"] > 0


FAMILY = REPO / "clothlab/models/neural/data/families/surface-table2.npz"
FAMILY_PATHS = [p for p, _ in _leaves(json.loads(FAMILY.with_suffix(".json").read_text()))
                if not (p and p[0] == "metrics")]


def test_fuzz_sidecar_multi_material(tmp_path):
    """The same over a network of several weaves and materials (materials_params, held-out rows, weaves_wv,
    materials_weave, probe points): a named refusal, or a surrogate whose materials and latents are finite
    and shaped as its sidecar says (the model's query is checked by test_fuzz_sidecar)."""
    from clothlab.models.neural.model import read_sidecar
    from clothlab.surrogate.serialise import load_surrogate, materials_count
    from clothlab.surrogate.threads import one_blas_thread

    npz = tmp_path / "f.npz"
    shutil.copy(FAMILY, npz)
    sidecar = npz.with_suffix(".json")
    doc = json.loads(FAMILY.with_suffix(".json").read_text())
    counts = collections.Counter()

    @SETTINGS
    @given(path=st.sampled_from(FAMILY_PATHS), op=st.sampled_from(["delete", "set", "set"]),
           value=st.one_of(st.sampled_from(SIDECAR_VALUES), st.integers(-2, 300), st.text(max_size=8)))
    def run(path, op, value):
        if op == "delete" and not path:
            op = "set"
        sidecar.write_text(json.dumps(_mutate(doc, path, op, value), indent=1))  # as written (no 64 K lines)
        try:
            checked = read_sidecar(npz, as_config=False)
            surrogate, _ = load_surrogate(npz)
        except ClothlabError as exc:
            check_named(exc, sidecar, npz)
            counts["refused (named)"] += 1
            return
        counts["accepted (valid)"] += 1
        rows = materials_count(checked["encoding"])
        assert surrogate.materials.shape == (rows, checked["architecture"]["n_material"])
        with one_blas_thread():  # fusion_biases encodes outside the inference's thread limit
            assert np.isfinite(surrogate.fusion_biases()).all()
        assert all(0 <= i < rows for i in surrogate.trained_rows())

    run()
    report("sidecar .json (several weaves)", counts)
    assert counts["refused (named)"] > 0


# ---------------------------------------------------------------------------------------------------------
# Model options in fabric.yaml

OPTION_CASES = {
    "surface": ("tile_nodes", "[32, 16]"),
    "kang": ("tile_nodes", "6"),
}
KANG_OPTIONS = ["tile_nodes", "prefilter_min_samples", "prefilter_max_samples", "seed", "tile_rule",
                "weave_level", "alternating"]


def _option_yaml(kind: str, name: str, value: str) -> str:
    return ("name: opts\nmeasurement: {path: m.csv}\nmodel:\n"
            f"  kind: {kind}\n  weave: preset:cotton-denim\n  options:\n    {name}: {value}\n")


def test_fuzz_model_options(tmp_path):
    """A drawn value for a size-like or named model option of surface / kang is refused at the yaml line and
    field model.options.<name>, or builds a model whose sizes stay within the documented limits."""
    from clothlab.config import load_config
    from clothlab.models.kang.model import MAX_PREFILTER_SAMPLES
    from clothlab.models.kang.model import MAX_TILE_NODES as KANG_MAX
    from clothlab.models.registry import build_model
    from clothlab.models.surface.model import MAX_TILE_NODES, MAX_TILE_POINTS
    from clothlab.weave.presets import resolve_weave

    (tmp_path / "m.csv").write_text("\n".join(clothlab_lines()) + "\n")
    path = tmp_path / "fabric.yaml"
    counts = collections.Counter()
    values = st.one_of(TOKENS, st.integers(-5, 10**7).map(str), st.integers(1, 300).map(str),
                       st.sampled_from(["4", "[8, 4]", "[1024, 256]", "[1025, 1]", "peak", "legendre", "flat",
                                        "true", "false", "null", "64", "4096", "4097", "256", "257"]),
                       st.lists(st.integers(-2, 5000), max_size=3).map(lambda v: json.dumps(v)))

    @SETTINGS
    @given(kind=st.sampled_from(["surface", "kang", "kang"]), option=st.sampled_from(KANG_OPTIONS), value=values)
    def run(kind, option, value):
        option = "tile_nodes" if kind == "surface" else option
        path.write_bytes(_option_yaml(kind, option, value).encode("utf-8", "surrogatepass"))
        try:
            cfg = load_config(path)
            model = build_model(kind, resolve_weave(cfg.model.weave, cfg.base_dir), None, **cfg.model.options)
        except ClothlabError as exc:
            check_named(exc, path)
            counts["refused (named)"] += 1
            return
        counts["accepted (valid)"] += 1
        if kind == "surface":
            across, along = model.tile_nodes
            assert 1 <= across <= MAX_TILE_NODES and 1 <= along <= MAX_TILE_NODES
            assert across * along <= MAX_TILE_POINTS
        else:
            assert model.tile_nodes is None or 1 <= model.tile_nodes <= KANG_MAX
            assert 1 <= model.prefilter_min_samples < model.prefilter_max_samples <= MAX_PREFILTER_SAMPLES
            assert 0 <= model.seed < 2**63

    run()
    report("model options", counts)


# ---------------------------------------------------------------------------------------------------------
# clothlab eval direction CSVs

EVAL_HEADER = "theta_i,phi_i,theta_o,phi_o,u,v,footprint"
EVAL_ROWS = ["30,0,30,180,0.25,0.5,0.1", "45,90,20,270,1.5,-2,2", "10,10,80,350,0,0,0.5", "60,-45,5,135,3,3,4"]


def valid_directions(d) -> None:
    from clothlab.fit.eval_csv import MAX_AZIMUTH, MAX_FOOTPRINT, MAX_TEXTURE_COORDINATE

    for name, values in d.items():
        assert np.isfinite(values).all(), name
    for name in ("theta_i", "theta_o"):
        assert ((d[name] >= 0) & (d[name] <= 90)).all()
    for name in ("phi_i", "phi_o"):
        assert (np.abs(d[name]) <= MAX_AZIMUTH).all()
    for name in ("u", "v"):
        if name in d:
            assert (np.abs(d[name]) <= MAX_TEXTURE_COORDINATE).all()
    if "footprint" in d:
        assert ((d["footprint"] > 0) & (d["footprint"] <= MAX_FOOTPRINT)).all()


def test_fuzz_eval_directions(tmp_path):
    """A BAD_TOKENS field (or a dropped / doubled / extra line) in an eval CSV is refused naming the file,
    line and column, or reads to finite values inside the documented bounds."""
    from clothlab.fit.eval_csv import read_directions

    path = tmp_path / "dirs.csv"
    path.write_text("\n".join([EVAL_HEADER, *EVAL_ROWS]) + "\n")
    valid_directions(read_directions(path))
    counts = collections.Counter()

    @SETTINGS
    @given(row=st.integers(0, len(EVAL_ROWS)), col=st.integers(0, 6), token=TOKENS, field_edit=st.booleans(),
           op=st.integers(0, 3))
    def run(row, col, token, field_edit, op):
        lines = [EVAL_HEADER, *EVAL_ROWS]
        lines = replace_field(lines, row, col, token) if field_edit else mutate_lines(lines, op, row, token)
        path.write_bytes(("\n".join(lines) + "\n").encode("utf-8", "surrogatepass"))
        try:
            result = read_directions(path)
        except ClothlabError as exc:
            if exc.line is None and exc.field is None:  # a whole-file refusal: the file is named
                assert str(path) in str(exc) and "\n" not in str(exc)
            else:
                check_named(exc, path)
            counts["refused (named)"] += 1
            return
        counts["accepted (valid)"] += 1
        valid_directions(result)

    run()
    report("eval directions", counts)
    assert counts["refused (named)"] > 0


# ---------------------------------------------------------------------------------------------------------
# train-surrogate --vary

def test_fuzz_vary_specs():
    """A drawn ``--vary NAME=LO:HI:N`` is refused at field --vary, or gives a bounded grid of finite sets
    inside the parameter's fit bounds."""
    from clothlab.models.registry import build_model
    from clothlab.surrogate.materials import MAX_VARY_MATERIALS, material_grid
    from clothlab.weave.presets import get_preset

    model = build_model("irawan", get_preset("cotton-denim"))
    base = model.resolve(None)
    names = [n for n in model.params.names() if n != "orientation"]
    counts = collections.Counter()

    @st.composite
    def spec(draw):
        """NAME=LO:HI:N inside NAME's bounds, then (often) one part replaced by a token."""
        name = draw(st.sampled_from(names))
        lo_b, hi_b = model.params[name].bounds
        a, b = sorted(draw(st.lists(st.floats(0, 1), min_size=2, max_size=2)))
        parts = [name, repr(lo_b + a * (hi_b - lo_b)), repr(lo_b + b * (hi_b - lo_b)),
                 str(draw(st.sampled_from([2, 3, 4, 64, 65, 0, 1])))]
        if draw(st.booleans()):
            parts[draw(st.integers(0, 3))] = draw(TOKENS)
        return f"{parts[0]}{draw(st.sampled_from(['=', '=', '=', ':', '']))}{parts[1]}:{parts[2]}:{parts[3]}"

    @SETTINGS
    @given(vary=st.lists(spec(), min_size=1, max_size=3))
    def run(vary):
        specs = [v.split("=")[0] for v in vary]
        try:
            sets, held = material_grid(model.params, base, vary)
        except ClothlabError as exc:
            assert isinstance(exc, ConfigError) and exc.field == "--vary", str(exc)
            assert "\n" not in str(exc)
            counts["refused (named)"] += 1
            return
        counts["accepted (valid)"] += 1
        assert 1 <= len(sets) <= MAX_VARY_MATERIALS and all(0 <= i < len(sets) for i in held)
        for q in sets:
            for name, value in q.items():
                assert math.isfinite(value)
                lo, hi = model.params[name].bounds
                assert name not in specs or lo <= value <= hi

    run()
    report("--vary", counts)


# ---------------------------------------------------------------------------------------------------------
# Findings: weights

def test_truncated_empty_and_non_zip_weights_are_named_input_errors(tmp_path):
    """Before: BadZipFile / EOFError tracebacks from np.load."""
    from clothlab.surrogate.serialise import load_surrogate

    npz = copy_weights(tmp_path)
    data = npz.read_bytes()
    for corrupt in (data[: len(data) // 2], data[:100], b"", b"PK\x03\x04" + b"\0" * 50, b"not a zip at all"):
        npz.write_bytes(corrupt)
        with pytest.raises(InputError) as err:
            load_surrogate(npz)
        assert err.value.path == str(npz) and "\n" not in str(err.value)


def test_a_zip_bomb_member_is_refused_before_it_is_inflated(tmp_path):
    """A member declaring 64 MiB where the architecture allows a few KiB is refused from its ZipInfo, with
    less than 8 MiB allocated (before: np.load inflated it, ArrayMemoryError for larger bombs)."""
    import tracemalloc

    from clothlab.surrogate.serialise import load_surrogate

    npz = copy_weights(tmp_path)
    members = {f"{k}.npy": _npy(v) for k, v in shipped_arrays().items()}
    members["param/ang5.b.npy"] = members["param/ang5.b.npy"] + b"\0" * (64 << 20)
    npz.write_bytes(_zip_with(members, zipfile.ZIP_DEFLATED))
    assert npz.stat().st_size < 1 << 20
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as err:
            load_surrogate(npz)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert err.value.field == "param/ang5.b" and "declares" in err.value.detail
    assert peak < 8 << 20, peak


@pytest.mark.parametrize("value", [np.inf, -np.inf, np.nan, 1e38])
def test_non_finite_or_huge_weights_name_the_weights_file_and_member(tmp_path, value):
    """Before: infinite biases were accepted (35 % error) and NaN / 1e38 weights were blamed on the
    measurement; now the .npz and the member are named."""
    from clothlab.surrogate.serialise import load_surrogate

    npz = copy_weights(tmp_path)
    arrays = shipped_arrays()
    arrays["param/ang5.b"] = arrays["param/ang5.b"].copy()
    arrays["param/ang5.b"][1] = value
    npz.write_bytes(npz_bytes(arrays))
    with pytest.raises(InputError) as err:
        load_surrogate(npz)
    check_named(err.value, npz)
    assert err.value.field == "param/ang5.b"


def test_weights_that_overflow_float32_in_the_network_are_refused(tmp_path):
    """Every value within the magnitude bound, yet the layers overflow float32: refused at load, naming the
    weights (the outputs are checked at the network's own materials)."""
    from clothlab.surrogate.serialise import MAX_WEIGHT, load_surrogate

    npz = copy_weights(tmp_path)
    arrays = shipped_arrays()
    for name in arrays:
        if name.startswith("param/") and name.endswith(".W"):
            arrays[name] = np.full_like(arrays[name], MAX_WEIGHT)
    npz.write_bytes(npz_bytes(arrays))
    with pytest.raises(InputError) as err:
        load_surrogate(npz)
    assert err.value.path == str(npz) and "overflow" in err.value.detail


def test_weights_larger_than_the_architecture_allows_are_not_read(tmp_path):
    """The archive's size is bounded by the members the sidecar implies: a padded file is refused from its
    size, before it is read."""
    from clothlab.surrogate.serialise import load_surrogate

    npz = copy_weights(tmp_path)
    with npz.open("ab") as handle:
        handle.truncate(8 << 20)
    with pytest.raises(InputError) as err:
        load_surrogate(npz)
    assert err.value.path == str(npz) and "bytes; at most" in err.value.detail


def test_pickled_or_complex_members_are_refused(tmp_path):
    from clothlab.surrogate.serialise import load_surrogate

    npz = copy_weights(tmp_path)
    for bad in (np.array([{"a": 1}], dtype=object), np.zeros(3, dtype=np.complex128)):
        members = {f"{k}.npy": _npy(v) for k, v in shipped_arrays().items()}
        members["materials.npy"] = _npy(bad)
        npz.write_bytes(_zip_with(members))
        with pytest.raises(InputError) as err:
            load_surrogate(npz)
        assert err.value.field == "materials" and "dtype" in err.value.detail


def test_the_shipped_weights_still_load_and_the_parameter_count_matches_the_network():
    from clothlab.surrogate.network import Architecture, SurrogateNetwork
    from clothlab.surrogate.serialise import load_surrogate, parameter_count, parameter_shapes

    for npz in sorted((REPO / "clothlab/models/neural/data").rglob("*.npz")):
        surrogate, sidecar = load_surrogate(npz)
        assert surrogate.network.n_parameters() == parameter_count(sidecar["architecture"]) == sidecar["parameters"]
    for dims in ((5, 24, 8, 3, 16, 8, 12, 6), (39, 41, 44, 4, 128, 64, 64, 32)):  # the shapes the loader expects
        arch = Architecture(*dims)
        network = SurrogateNetwork(arch)
        assert {k: v.shape for k, v in network.params().items()} == parameter_shapes(arch.to_dict())


def test_the_largest_documented_architecture_is_within_the_parameter_bound():
    """train-surrogate takes --width / --spatial up to 4,096 and --yarn-bins up to 256: such a network's
    sidecar passes the schema's bounds (its weights are not built here)."""
    from clothlab.surrogate.serialise import MAX_BINS, MAX_PARAMETERS, MAX_WIDTH, parameter_count

    arch = {"n_material": 39, "n_spatial": 2 * 8 + 8 + 1 + 2 * 256, "n_angular": 8, "n_out": 4, "enc_width": 128,
            "latent": 64, "width": 4096, "spatial": 4096}
    assert max(arch.values()) <= MAX_WIDTH and MAX_BINS >= 256 and parameter_count(arch) <= MAX_PARAMETERS


# ---------------------------------------------------------------------------------------------------------
# Findings: sidecar

def _write_sidecar(npz: Path, edit) -> Path:
    sidecar = npz.with_suffix(".json")
    doc = json.loads(SHIPPED.with_suffix(".json").read_text())
    edit(doc)
    sidecar.write_text(json.dumps(doc))
    return sidecar


@pytest.mark.parametrize(("edit", "field"), [
    (lambda d: d["architecture"].pop("width") and d["architecture"].pop("n_out"), "architecture.n_out"),
    (lambda d: d["architecture"].update(width=10**9), "architecture.width"),
    (lambda d: d["architecture"].update(width="64"), "architecture.width"),
    (lambda d: d.update(architecture=[1, 2]), "architecture"),
    (lambda d: d.update(dtype="complex128"), "dtype"),
    (lambda d: d.update(k_specular=1e-320), "k_specular"),
    (lambda d: d.update(components="diffuse"), "components"),
    (lambda d: d["encoding"].update(position_bins=1e9), "encoding.position_bins"),
    (lambda d: d["encoding"].update(half_vector="yes"), "encoding.half_vector"),
    (lambda d: d["encoding"]["params"].update(alpha="0.1"), "encoding.params.alpha"),
    (lambda d: d["encoding"].update(output_max=[1.0]), "encoding.output_max"),
    (lambda d: d["encoding"].update(weave_wv="weave {"), "encoding.weave_wv"),
    (lambda d: d.update(encoding="none"), "encoding"),
])
def test_bad_sidecars_name_the_dotted_field(tmp_path, edit, field):
    """Before: KeyError / ValueError / AttributeError tracebacks, an allocation error for width 1e9,
    complex128 accepted; now an InputError naming the sidecar and the dotted field."""
    from clothlab.surrogate.serialise import load_surrogate

    npz = copy_weights(tmp_path)
    sidecar = _write_sidecar(npz, edit)
    with pytest.raises(InputError) as err:
        load_surrogate(npz)
    assert err.value.path == str(sidecar) and err.value.field == field, str(err.value)


def test_a_width_of_1e9_is_refused_before_allocating(tmp_path):
    import tracemalloc

    from clothlab.surrogate.serialise import load_surrogate

    npz = copy_weights(tmp_path)
    _write_sidecar(npz, lambda d: d["architecture"].update(width=4096, enc_width=4096, latent=4096, spatial=4096))
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as err:
            load_surrogate(npz)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert err.value.field == "architecture" and "parameters" in err.value.detail
    assert peak < 4 << 20


def test_bad_sidecar_through_fabric_yaml_names_line_option_and_sidecar_field(tmp_path):
    from clothlab.config import load_config

    npz = copy_weights(tmp_path)
    sidecar = _write_sidecar(npz, lambda d: d["architecture"].update(width=10**9))
    (tmp_path / "m.csv").write_text("\n".join(clothlab_lines()) + "\n")
    (tmp_path / "fabric.yaml").write_text("name: n\nmeasurement: {path: m.csv}\nmodel:\n  kind: neural\n"
                                          "  weave: preset:cotton-denim\n  options:\n    weights: w.npz\n")
    with pytest.raises(ConfigError) as err:
        load_config(tmp_path / "fabric.yaml")
    assert err.value.line == 7 and err.value.field == "model.options.weights"
    assert str(sidecar) in err.value.detail and "architecture.width" in err.value.detail


# ---------------------------------------------------------------------------------------------------------
# Findings: the CLI on corrupt weights (fit and eval exit 2, one line naming the file)

def _neural_project(tmp_path) -> Path:
    copy_weights(tmp_path)
    (tmp_path / "m.csv").write_text("\n".join(clothlab_lines()) + "\n")
    (tmp_path / "fabric.yaml").write_text("name: n\nmeasurement: {path: m.csv}\nmodel:\n  kind: neural\n"
                                          "  weave: preset:cotton-denim\n  options: {weights: w.npz}\n"
                                          "fit: {free: [alpha], optimizer: {global: null, max_evals: 5}}\n"
                                          "output: {fits: fits, reports: reports}\n")
    (tmp_path / "dirs.csv").write_text("theta_i,phi_i,theta_o,phi_o\n30,0,30,180\n")
    return tmp_path / "fabric.yaml"


@pytest.mark.parametrize("corruption", ["truncated", "empty", "not a zip", "infinite bias", "1e38 weight"])
@pytest.mark.parametrize("command", ["fit", "eval"])
def test_fit_and_eval_on_corrupt_weights_exit_2_with_one_line_naming_the_file(tmp_path, capsys, monkeypatch,
                                                                                corruption, command):
    """Before: tracebacks (BadZipFile, EOFError) or the measurement blamed; now exit 2 and one line naming
    the .npz."""
    from clothlab.cli.main import main

    monkeypatch.chdir(tmp_path)
    config = _neural_project(tmp_path)
    npz = tmp_path / "w.npz"
    data = npz.read_bytes()
    if corruption in ("infinite bias", "1e38 weight"):
        arrays = shipped_arrays()
        arrays["param/ang4.b"] = arrays["param/ang4.b"].copy()
        arrays["param/ang4.b"][0] = np.inf if corruption == "infinite bias" else 1e38
        npz.write_bytes(npz_bytes(arrays))
    else:
        npz.write_bytes({"truncated": data[:1000], "empty": b"", "not a zip": b"\x93NUMPY hello"}[corruption])
    argv = ["fit", str(config), "--quiet"] if command == "fit" else \
        ["eval", str(config), str(tmp_path / "dirs.csv"), "-o", str(tmp_path / "out.csv")]
    rc = main(argv)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert rc == 2, err
    assert len(lines) == 1 and lines[0].startswith("clothlab: error: "), err
    assert str(npz) in lines[0] and "Traceback" not in err
    assert not (tmp_path / "out.csv").exists() and not (tmp_path / "fits" / "n").exists()


# ---------------------------------------------------------------------------------------------------------
# Findings: model options

@pytest.mark.parametrize("kind", ["surface", "kang"])
def test_tile_nodes_of_a_million_is_refused_at_its_yaml_line(tmp_path, kind):
    """Before: accepted, then a 7.3 TiB allocation; the model's own error lacked file:line."""
    from clothlab.config import load_config

    (tmp_path / "m.csv").write_text("\n".join(clothlab_lines()) + "\n")
    path = tmp_path / "fabric.yaml"
    path.write_text(_option_yaml(kind, "tile_nodes", "1000000"))
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert err.value.path == str(path) and err.value.line == 7 and err.value.field == "model.options.tile_nodes"
    assert "at most" in err.value.detail or "to 256" in err.value.detail


@pytest.mark.parametrize(("kind", "options"), [("surface", {"tile_nodes": 1_000_000}),
                                               ("surface", {"tile_nodes": [1024, 1024]}),
                                               ("kang", {"tile_nodes": 257}),
                                               ("kang", {"prefilter_max_samples": 10**9}),
                                               ("kang", {"seed": -1})])
def test_build_model_checks_option_sizes_and_names_the_option(kind, options):
    """The registry applies the model's option checks too (fit directories rebuild models from fit.json)."""
    from clothlab.models.registry import build_model
    from clothlab.weave.presets import get_preset

    with pytest.raises(ConfigError) as err:
        build_model(kind, get_preset("cotton-denim"), None, **options)
    assert err.value.field == f"model.options.{next(iter(options))}"


@pytest.mark.parametrize(("value", "refused"), [("4", False), ("1000000", True), ("true", True)])
def test_composite_kinds_take_their_specular_parts_options(tmp_path, value, refused):
    """docs/fabric-yaml.md: a composite's model.options go to its specular part (before: every option was
    refused as unknown, and the registry accepted unchecked sizes)."""
    from clothlab.config import load_config
    from clothlab.fit.problem import build_problem

    (tmp_path / "m.csv").write_text("\n".join(clothlab_lines()) + "\n")
    path = tmp_path / "fabric.yaml"
    path.write_text(_option_yaml("kang+oren-nayar", "tile_nodes", value))
    if refused:
        with pytest.raises(ConfigError) as err:
            load_config(path)
        assert err.value.line == 7 and err.value.field == "model.options.tile_nodes"
    else:
        assert build_problem(load_config(path)).model.specular.tile_nodes == int(value)


@pytest.mark.parametrize(("options", "field"), [({"weights": 5}, "model.options.weights"),
                                                ({"refine": "yes"}, "model.options.refine")])
def test_neural_options_are_checked_by_the_registry(options, field):
    """A fit directory's recorded options rebuild the model through the registry (before: Path(5) raised a
    TypeError)."""
    from clothlab.models.registry import build_model
    from clothlab.weave.presets import get_preset

    with pytest.raises(ConfigError) as err:
        build_model("neural", get_preset("cotton-denim"), None, **options)
    assert err.value.field == field


def test_the_largest_documented_tile_nodes_are_accepted():
    from clothlab.models.kang.model import MAX_TILE_NODES as KANG_MAX
    from clothlab.models.registry import build_model
    from clothlab.models.surface.model import MAX_TILE_NODES, MAX_TILE_POINTS
    from clothlab.weave.presets import get_preset

    weave = get_preset("cotton-denim")
    assert build_model("kang", weave, None, tile_nodes=KANG_MAX).tile_nodes == KANG_MAX
    assert build_model("surface", weave, None, tile_nodes=[MAX_TILE_NODES, MAX_TILE_POINTS // MAX_TILE_NODES]
                       ).tile_nodes == (MAX_TILE_NODES, MAX_TILE_POINTS // MAX_TILE_NODES)


def test_loss_scale_1e_320_is_refused_at_its_line(tmp_path):
    """Before: a denormal loss scale was accepted."""
    from clothlab.config import load_config

    (tmp_path / "m.csv").write_text("\n".join(clothlab_lines()) + "\n")
    path = tmp_path / "fabric.yaml"
    path.write_text("name: n\nmeasurement: {path: m.csv}\nmodel: {kind: irawan, weave: preset:cotton-denim}\n"
                    "fit:\n  loss: huber\n  loss_scale: 1e-320\n")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert err.value.line == 6 and err.value.field == "fit.loss_scale"


# ---------------------------------------------------------------------------------------------------------
# Findings: eval CSVs

@pytest.mark.parametrize(("column", "token"), [("theta_i", "3_0"), ("phi_o", "\u0663\u0660"), ("u", "1e300"),
                                               ("v", "-1e300"), ("footprint", "1e30"), ("footprint", "1e300"),
                                               ("phi_i", "1e300"), ("footprint", "inf"), ("u", "0x10")])
def test_eval_csv_numbers_are_strict_and_bounded(tmp_path, column, token):
    """Before: float() read 3_0 and Arabic-Indic digits as 30, u = 1e300 was accepted and a footprint of 1e30
    wrote 0.0; now an InputError naming file, line and column."""
    from clothlab.fit.eval_csv import read_directions

    rows = ["theta_i,phi_i,theta_o,phi_o,u,v,footprint", "30,0,30,180,0.2,0.3,0.5", "20,0,30,180,0.2,0.3,0.5"]
    header = rows[0].split(",")
    fields = rows[2].split(",")
    fields[header.index(column)] = token
    rows[2] = ",".join(fields)
    path = tmp_path / "dirs.csv"
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    with pytest.raises(InputError) as err:
        read_directions(path)
    assert err.value.path == str(path) and err.value.line == 3 and err.value.field == column


@pytest.mark.parametrize("header", ["theta_i,phi_i,theta_o,phi_o", "theta_i,phi_i,theta_o,phi_o,u,v,footprint"])
def test_eval_csv_with_only_a_header_is_refused(tmp_path, capsys, header):
    """Before: a header alone wrote a header alone (exit 0) or, with a footprint column, a TypeError."""
    from clothlab.cli.main import main

    path = tmp_path / "dirs.csv"
    path.write_text(f"# directions\n{header}\n")
    rc = main(["eval", str(REPO / "fits" / "polyester-lining"), str(path), "-o", str(tmp_path / "out.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and f"{path}:2" in err, err
    assert not (tmp_path / "out.csv").exists()


def test_eval_csv_errors_give_the_physical_line(tmp_path):
    """A quoted field spanning two lines shifts the record count; the error names the file's own line (before:
    the record number)."""
    from clothlab.fit.eval_csv import read_directions

    path = tmp_path / "dirs.csv"
    path.write_text('theta_i,phi_i,theta_o,phi_o,note\n30,0,30,180,"two\nlines"\n30,0,95,180,x\n')
    with pytest.raises(InputError) as err:
        read_directions(path)
    assert err.value.line == 4 and err.value.field == "theta_o"
    path.write_text("theta_i,phi_i,theta_o,phi_o,note\n30,0,30,180,x\n30,0,30,180," + "y" * 200_000 + "\n")
    with pytest.raises(InputError) as err:  # csv's field size limit
        read_directions(path)
    assert err.value.line == 3 and str(path) in str(err.value)


def test_the_largest_footprint_and_coordinates_give_the_tile_average(tmp_path):
    """At the documented limits (footprint MAX_FOOTPRINT tiles centred at u = MAX_TEXTURE_COORDINATE) a box
    footprint of a whole number of tiles is the tile average: the summed-area tables still resolve it
    (equal to a one-tile footprint at the origin to 1e-9)."""
    from clothlab.fit.eval_csv import MAX_FOOTPRINT, MAX_TEXTURE_COORDINATE, evaluate_directions_file

    (tmp_path / "fabric.yaml").write_text("name: n\nmeasurement: {path: m.csv}\n"
                                          "model: {kind: irawan, weave: preset:cotton-denim}\n")
    (tmp_path / "m.csv").write_text("\n".join(clothlab_lines()) + "\n")
    path = tmp_path / "dirs.csv"
    path.write_text(f"theta_i,phi_i,theta_o,phi_o,u,v,footprint\n30,0,30,180,0,0,1\n"
                    f"30,0,30,180,{MAX_TEXTURE_COORDINATE!r},{-MAX_TEXTURE_COORDINATE!r},{MAX_FOOTPRINT!r}\n")
    text = evaluate_directions_file(tmp_path / "fabric.yaml", path, resolution=8)
    rows = [line.split(",") for line in text.strip().splitlines()]
    one, big = (np.array([float(x) for x in r[7:]]) for r in rows[1:])
    assert (one > 0).all() and np.allclose(big, one, rtol=1e-9, atol=0)


# ---------------------------------------------------------------------------------------------------------
# Findings: --vary

@pytest.mark.parametrize("spec", ["alpha=0_01:0.1:3", "alpha=0.01:0.1:\u0663", "alpha=0.1:0.01:3",
                                  "alpha=0.01:0.1:1000000", "alpha=nan:0.1:3", "bogus=0.01:0.1:3",
                                  "alpha=0.01:0.1", "orientation=0:10:3"])
def test_vary_specs_are_strict(spec):
    """Before: float() / int() read 0_01 and Arabic-Indic digits and N was unbounded."""
    from clothlab.models.registry import build_model
    from clothlab.surrogate.materials import material_grid
    from clothlab.weave.presets import get_preset

    model = build_model("irawan", get_preset("cotton-denim"))
    with pytest.raises(ConfigError) as err:
        material_grid(model.params, model.resolve(None), [spec])
    assert err.value.field == "--vary"


def test_a_grid_too_large_is_refused_and_a_valid_one_is_read():
    from clothlab.models.registry import build_model
    from clothlab.surrogate.materials import material_grid
    from clothlab.weave.presets import get_preset

    model = build_model("irawan", get_preset("cotton-denim"))
    base = model.resolve(None)
    with pytest.raises(ConfigError, match="at most"):
        material_grid(model.params, base, ["alpha=0.01:0.1:64", "beta=1:4:64"])
    sets, held = material_grid(model.params, base, ["alpha=0.01:0.1:3", "beta=1:4:2"])
    assert len(sets) == 3 * 2 + 2 * 1 and held == [6, 7]
    mid = math.sqrt(0.01 * 0.1) if model.params["alpha"].transform == "log" else 0.055
    assert sorted({q["alpha"] for q in sets[:6]}) == pytest.approx([0.01, mid, 0.1])


# ---------------------------------------------------------------------------------------------------------
# Findings: weave-free kinds

@pytest.mark.parametrize("kind", ["lambert", "oren-nayar"])
def test_weave_free_kinds_need_no_weave(tmp_path, kind):
    """Before: 'missing required key weave' for kind lambert / oren-nayar, which the docs allow."""
    from clothlab.config import load_config
    from clothlab.fit.problem import build_problem

    (tmp_path / "m.csv").write_text("\n".join(clothlab_lines()) + "\n")
    path = tmp_path / "fabric.yaml"
    path.write_text(f"name: n\nmeasurement: {{path: m.csv}}\nmodel: {{kind: {kind}}}\n")
    cfg = load_config(path)
    problem = build_problem(cfg)
    wi, wo = directions()
    comps = problem.model.components(wi, wo)
    assert np.isfinite(comps["diffuse"]).all() and (comps["diffuse"] > 0).all()
    path.write_text("name: n\nmeasurement: {path: m.csv}\nmodel: {kind: irawan}\n")
    with pytest.raises(ConfigError) as err:  # a kind that needs one still names the missing key
        load_config(path)
    assert err.value.field == "model.weave"


def test_bad_tokens_cover_the_strict_reader_cases():
    """The pool this file draws from holds the issue's spellings (so the strategies reach them)."""
    for token in ("0_1", "\u0661", "1e300", "1e-320", "inf", "nan"):
        assert token in BAD_TOKENS
