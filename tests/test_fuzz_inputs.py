"""Fuzzing every input family: a bad input is refused with a message naming its place, a good one is valid.

Each family starts from a valid file and replaces one field (or one line) with a value drawn from a pool
of known-bad spellings (Python-only numbers, non-finite, denormal, huge, YAML timestamps, 5,000-digit
integers, NUL bytes, ...) or from arbitrary text.  Every outcome must be one of

- a :class:`~clothlab.errors.ClothlabError` naming the file and a line or a dotted field (the CLI prints it
  as one line and exits 2), or
- a result that passes an independent validity check (finite numbers in their declared ranges).

Anything else (another exception type = a traceback at the CLI) fails.  The default run draws a few dozen
cases per family; ``CLOTHLAB_FUZZ_EXAMPLES=N`` draws N per family (the ``--runslow`` variant draws 1,000),
and each test prints its outcome counts (``pytest -s``).
"""

from __future__ import annotations

import collections
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clothlab.errors import ClothlabError

EXAMPLES = int(os.environ.get("CLOTHLAB_FUZZ_EXAMPLES", "25"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

BAD_TOKENS = [
    "0_1", "1_000.5", "nan", "NaN", ".nan", "inf", "-inf", ".inf", "infinity", "1e-320", "4.9e-324", "-1e-310",
    "1e308", "1e31", "1e300", "1e400", "2020-02-30", "2020-02-03", "12:30:00", "", " ", "\u0661", "0x10", "0o7",
    "1e", "--1", "9" * 5000, "1" + "0" * 400, "a\x00b", "1,2", "'1'", "[1]", "{a: 1}", "*a", "&a 1",
    "!!python/object/apply:os.system ['true']", "-0", "0", "1", "91", "-1", ".5", "1.", "+1", "720", "-400",
    "0.0000001", "1e-30", "true", "null", "~", "\ufeff1",
]
TOKENS = st.one_of(st.sampled_from(BAD_TOKENS), st.text(max_size=12),
                   st.floats(allow_nan=True, allow_infinity=True).map(repr))


def check_named(exc: ClothlabError, *paths) -> None:
    """The refusal names one of ``paths`` and a line or a field (the place to fix)."""
    assert type(exc).__name__ != "ClothlabError" or exc.path is not None
    assert exc.path is not None, str(exc)
    assert any(str(p) in exc.path for p in paths), (exc.path, paths)
    assert exc.line is not None or exc.field is not None, str(exc)
    assert "\n" not in str(exc).strip(), str(exc)


def outcome(counts, fn, *args, paths=()):
    """Run ``fn``; count and return ('refused', exc) or ('accepted', result); other exceptions propagate."""
    try:
        result = fn(*args)
    except ClothlabError as exc:
        check_named(exc, *paths)
        counts["refused (named)"] += 1
        return "refused", exc
    counts["accepted (valid)"] += 1
    return "accepted", result


def report(family: str, counts) -> None:
    print(f"\nfuzz {family}: {sum(counts.values())} cases: {dict(counts)}")


def replace_field(lines: list[str], row: int, col: int, token: str, sep: str = ",") -> list[str]:
    out = list(lines)
    fields = out[row].split(sep) if sep != " " else out[row].split()
    fields[col % len(fields)] = token
    out[row] = (sep if sep != " " else " ").join(fields)
    return out


def replace_nth(text: str, old: str, nth: int, token: str) -> bytes:
    """``text`` with one occurrence of ``old`` (the nth, cyclically) replaced by ``token``, as bytes."""
    pieces = text.split(old)
    k = 1 + nth % (len(pieces) - 1)
    return (old.join(pieces[:k]) + token + old.join(pieces[k:])).encode("utf-8", "surrogatepass")


def fuzz_yaml_values(family: str, path: Path, text: str, values, load, check) -> None:
    """Replace one occurrence of one of ``values`` in the YAML ``text`` by a drawn token, write it to
    ``path`` and read it with ``load``: a named refusal, or ``check(result)`` holds."""
    counts = collections.Counter()

    @SETTINGS
    @given(old=st.sampled_from(values), token=TOKENS, nth=st.integers(0, 3))
    def run(old, token, nth):
        path.write_bytes(replace_nth(text, old, nth, token))
        kind, result = outcome(counts, load, path, paths=(path,))
        if kind == "accepted":
            check(result)

    run()
    report(family, counts)


def mutate_lines(lines: list[str], op: int, index: int, token: str) -> list[str]:
    out = list(lines)
    index %= len(out)
    if op == 0:
        del out[index]
    elif op == 1:
        out.insert(index, out[index])
    elif op == 2:
        out.insert(index, token)
    else:
        out[index] = out[index] + token
    return out


# ---------------------------------------------------------------------------------------------------------
# Tables (clothlab, ASTM, pab-opto)

ROWS = [(10.0 * k % 85, 30.0 * k % 360, (17.0 * k + 5) % 85, (45.0 * k + 10) % 360, 0.1 + 0.01 * k, 0.2, 0.3)
        for k in range(8)]
CLOTHLAB_HEADER = ["# clothlab-table: 1", "# angle_unit: deg", "# quantity: brdf", "# azimuth_zero: weft",
                   "# azimuth_sense: ccw", "# channels: [R, G, B]", "theta_i,phi_i,theta_o,phi_o,R,G,B"]


def clothlab_lines() -> list[str]:
    return CLOTHLAB_HEADER + [",".join(repr(v) for v in r) for r in ROWS]


def astm_lines() -> list[str]:
    return (["NUM_POINTS 8", "VARS theta_i,phi_i,theta_s,phi_s,R,G,B"]
            + [",".join(repr(math.radians(v) if i < 4 else v) for i, v in enumerate(r)) for r in ROWS])


def pabopto_lines() -> list[str]:
    return (["#format: theta phi BRDF", "#intheta 30", "#inphi 0", "#colorimetry: CIE-XYZ"]
            + [" ".join(repr(v) for v in r[2:]) for r in ROWS])


def valid_measurement(m) -> None:
    assert m.n >= 2
    for a in (m.theta_i, m.theta_o):
        assert np.isfinite(a).all() and (a >= 0).all() and (a <= 90).all()
    for a in (m.phi_i, m.phi_o):
        assert np.isfinite(a).all()
    v = m.values
    assert np.isfinite(v).all() and (v >= 0).all() and (v <= 1e30 * 2).all()
    tiny = np.finfo(np.float64).tiny
    assert not ((np.abs(v) > 0) & (np.abs(v) < tiny / 4)).any()  # no denormal (cos division can shrink a bit)


TABLES = {"clothlab": (clothlab_lines, ",", 7), "astm": (astm_lines, ",", 2), "pabopto": (pabopto_lines, " ", 4)}


def _table_case(tmp_path, fmt, data, counts):
    make, sep, first = TABLES[fmt]
    lines = make()
    token = data.draw(TOKENS)
    if data.draw(st.booleans()):
        lines = replace_field(lines, data.draw(st.integers(first, len(lines) - 1)), data.draw(st.integers(0, 6)),
                              token, sep)
    else:
        lines = mutate_lines(lines, data.draw(st.integers(0, 3)), data.draw(st.integers(0, len(lines) - 1)),
                             token)
    path = tmp_path / f"m.{fmt}.txt"
    path.write_bytes(("\n".join(lines) + "\n").encode("utf-8", errors="surrogatepass"))
    from clothlab.io.loader import load_measurement

    kind, result = outcome(counts, load_measurement, path, fmt, paths=(path,))
    if kind == "accepted":
        valid_measurement(result)


@pytest.mark.parametrize("fmt", list(TABLES))
def test_fuzz_tables(tmp_path, fmt):
    from clothlab.io.loader import load_measurement

    counts = collections.Counter()
    make, _, _ = TABLES[fmt]
    (tmp_path / "base.txt").write_text("\n".join(make()) + "\n")
    valid_measurement(load_measurement(tmp_path / "base.txt", fmt))  # the unmutated file is valid

    @SETTINGS
    @given(data=st.data())
    def run(data):
        _table_case(tmp_path, fmt, data, counts)

    run()
    report(f"table/{fmt}", counts)


# ---------------------------------------------------------------------------------------------------------
# fabric.yaml

FABRIC = """\
name: fuzz
measurement:
  path: m.csv
  format: clothlab
model:
  kind: irawan
  weave: preset:cotton-denim
  quadrature: {rule: trapezoid, nodes: 11}
  params: {alpha: 0.05, beta: 2, warp.umax: 20}
fit:
  free: [alpha, beta]
  metric: relative
  cv_folds: 3
  optimizer: {global: GN_CRS2_LM, local: LN_BOBYQA, max_evals: 100, seed: 1, max_time: 30, starts: 2}
  posterior: {walkers: 8, steps: 100}
report: {percentiles: [50, 80, 95]}
output: {fits: fits, reports: reports}
"""
FABRIC_VALUES = ["m.csv", "clothlab", "irawan", "preset:cotton-denim", "trapezoid", "11", "0.05", "2", "20",
                 "relative", "3", "GN_CRS2_LM", "LN_BOBYQA", "100", "1", "30", "8", "fuzz", "[50, 80, 95]",
                 "fits", "[alpha, beta]"]


def _finite_everywhere(value, where="config") -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _finite_everywhere(v, f"{where}.{k}")
    elif isinstance(value, list | tuple):
        for i, v in enumerate(value):
            _finite_everywhere(v, f"{where}[{i}]")
    elif isinstance(value, float):
        assert math.isfinite(value), where
    elif isinstance(value, int) and not isinstance(value, bool):
        assert abs(value) < 2**63, where


def test_fuzz_fabric_yaml(tmp_path):
    from clothlab.config import load_config

    (tmp_path / "m.csv").write_text("\n".join(clothlab_lines()) + "\n")
    (tmp_path / "fabric.yaml").write_text(FABRIC)
    assert load_config(tmp_path / "fabric.yaml").name == "fuzz"  # the unmutated file is valid

    def check(cfg):
        _finite_everywhere(cfg.canonical())
        assert 1 <= cfg.fit.optimizer.max_evals <= 2**31 - 1
        assert len(cfg.name) <= 200

    fuzz_yaml_values("fabric.yaml", tmp_path / "fabric.yaml", FABRIC, FABRIC_VALUES, load_config, check)


# ---------------------------------------------------------------------------------------------------------
# .wv weave files

def _wv_text() -> str:
    return (Path(__file__).parent.parent / "clothlab/weave/data/cotton-denim.wv").read_text()


def test_fuzz_wv(tmp_path):
    import re

    from clothlab.weave.parameters import IRAWAN_PARAMS
    from clothlab.weave.wvformat import FIELD_RANGES, parse_wv

    text = _wv_text()
    numbers = [m.span() for m in re.finditer(r"(?<==)\s*[-+0-9.eE]+", text)]
    (tmp_path / "base.wv").write_text(text)
    assert parse_wv(tmp_path / "base.wv").name == "cotton-denim"  # the unmutated file is valid
    counts = collections.Counter()

    @SETTINGS
    @given(index=st.integers(0, len(numbers) - 1), token=TOKENS)
    def run(index, token):
        start, end = numbers[index]
        path = tmp_path / "w.wv"
        path.write_bytes((text[:start] + " " + token + text[end:]).encode("utf-8", errors="surrogatepass"))
        kind, weave = outcome(counts, parse_wv, path, paths=(path,))
        if kind == "accepted":
            for attr in ("alpha", "beta", "delta", "hwidth", "warp_area", "weft_area", "fineness", "period"):
                assert math.isfinite(getattr(weave, attr)), attr
            assert all(-90 <= d <= 90 for d in weave.dumax)
            assert FIELD_RANGES["fineness"][0] <= weave.fineness <= FIELD_RANGES["fineness"][1]
            for kind_ in ("warp", "weft"):
                geometry = getattr(weave, kind_)
                for attr in ("psi", "umax", "kappa", "w", "l"):
                    lo, hi = IRAWAN_PARAMS[f"{kind_}.{attr}"].valid  # the declared physical range
                    assert math.isfinite(getattr(geometry, attr)) and lo <= getattr(geometry, attr) <= hi

    run()
    report(".wv", counts)


# ---------------------------------------------------------------------------------------------------------
# Scene files

SCENE = """\
patch: {shape: flat, size_mm: [40, 40], tile_mm: [1.0, 2.0], warp_angle_deg: 0}
camera: {position: [0, -40, 40], look_at: [0, 0, 0], up: [0, 0, 1], fov_deg: 30, resolution: [32, 24]}
light: {type: directional, direction: [0.3, -0.2, 1.0], intensity: 1.0}
fabric:
  weave: preset:cotton-denim
  params: {alpha: 0.05}
  coefficients: {kd: [0.2, 0.26, 0.42], ks_warp: [0.12, 0.12, 0.12], ks_weft: [0.02, 0.03, 0.07]}
render: {spp: 1, seed: 0, exposure: 0.0}
"""
SCENE_VALUES = ["40", "1.0", "2.0", "0", "-40", "30", "32", "24", "0.3", "-0.2", "0.05", "0.2", "0.12", "0.07", "1",
                "flat", "directional", "preset:cotton-denim", "[32, 24]"]


def test_fuzz_scene(tmp_path):
    from clothlab.render.scene import MAX_RENDER_BYTES, load_scene, render_bytes

    (tmp_path / "base.yaml").write_text(SCENE)
    assert load_scene(tmp_path / "base.yaml").camera.resolution == (32, 24)  # the unmutated file is valid

    def check(scene):
        for coef in scene.fabric.coefficients.values():
            assert np.isfinite(coef).all() and (coef >= 0).all()
        assert render_bytes(scene.camera.resolution, scene.spp) <= MAX_RENDER_BYTES
        assert all(math.isfinite(float(v)) for v in scene.fabric.params.values())

    fuzz_yaml_values("scene", tmp_path / "scene.yaml", SCENE, SCENE_VALUES, load_scene, check)


# ---------------------------------------------------------------------------------------------------------
# Colour charts

def chart_lines() -> list[str]:
    rng = np.random.default_rng(5)
    patches = rng.uniform(0.02, 0.9, (24, 3)).tolist()
    return ["patch,R,G,B"] + [f"p{k},{r!r},{g!r},{b!r}" for k, (r, g, b) in enumerate(patches)]


def test_fuzz_chart(tmp_path):
    from clothlab.colour.calibrate import read_chart

    counts = collections.Counter()
    (tmp_path / "base.csv").write_text("\n".join(chart_lines()) + "\n")
    assert read_chart(tmp_path / "base.csv")[0].shape == (24, 3)  # the unmutated chart is valid

    @SETTINGS
    @given(row=st.integers(1, 24), col=st.integers(1, 3), token=TOKENS,
           encoding=st.sampled_from(["utf-8", "utf-8", "utf-8-sig", "latin-1", "utf-16"]))
    def run(row, col, token, encoding):
        lines = replace_field(chart_lines(), row, col, token)
        path = tmp_path / "chart.csv"
        text = "\n".join(lines) + "\n"
        try:
            data = text.encode(encoding)
        except UnicodeEncodeError:
            data = text.encode("utf-8", "surrogatepass")
        path.write_bytes(data)
        kind, result = outcome(counts, read_chart, path, paths=(path,))
        if kind == "accepted":
            values, _ = result
            assert np.isfinite(values).all() and (values >= 0).all() and (values <= 1e30).all()
            assert values.any() and not np.all(values == values[0])

    run()
    report("chart", counts)


# ---------------------------------------------------------------------------------------------------------
# BTF manifests (CSV)

def manifest_lines() -> list[str]:
    return (["# warp_axis: vertical", "file,theta_i,phi_i,theta_o,phi_o"]
            + [f"img{k}.exr,{10 * k % 80},{30 * k % 360},{(13 * k + 5) % 80},{(40 * k) % 360}" for k in range(6)])


def test_fuzz_btf_manifest(tmp_path):
    from clothlab.btf.names import read_manifest

    (tmp_path / "base.csv").write_text("\n".join(manifest_lines()) + "\n")
    assert len(read_manifest(tmp_path / "base.csv")[0]) == 6  # the unmutated file is valid
    counts = collections.Counter()

    @SETTINGS
    @given(row=st.integers(2, 7), col=st.integers(0, 4), token=TOKENS)
    def run(row, col, token):
        path = tmp_path / "manifest.csv"
        path.write_bytes(("\n".join(replace_field(manifest_lines(), row, col, token)) + "\n").encode(
            "utf-8", "surrogatepass"))
        kind, result = outcome(counts, read_manifest, path, paths=(path,))
        if kind == "accepted":
            entries, _ = result
            files = [e.path for e in entries]
            assert len(set(files)) == len(files)
            for e in entries:
                assert all(math.isfinite(a) for a in e.angles)
                assert 0 <= e.angles[0] <= 90 and 0 <= e.angles[2] <= 90

    run()
    report("btf manifest", counts)


@pytest.mark.slow
def test_fuzz_thousands(tmp_path, monkeypatch):
    """The whole fuzz suite with 1,000 cases per family, in a child pytest (``--runslow``)."""
    import subprocess
    import sys

    env = dict(os.environ, CLOTHLAB_FUZZ_EXAMPLES="1000")
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-s", __file__, "-k", "not thousands",
                           "-p", "no:cacheprovider"], env=env, capture_output=True, text=True, cwd=tmp_path)
    print(done.stdout[-4000:])
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
