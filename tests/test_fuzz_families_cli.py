"""The command-line input families of issue 24: Dask options (scheduler address, --workers, the environment
variable), argparse argument vectors, ``report``'s fit directories, ``fit-btf``'s name-based stacks, the size-like
fields of fabric.yaml and ``train-surrogate``'s weave list.

Each family draws bad inputs from a valid one (fields of ``BAD_TOKENS``, arbitrary text, deleted or duplicated
lines, deleted or corrupted images) and every outcome must be a :class:`~clothlab.errors.ClothlabError` naming
its place in one line (the file and a line or a field; for an option or an environment variable, its name) -
for argparse, exit 2 with one ``clothlab: error: field '...'`` line - or a result that passes an independent
validity check.  ``CLOTHLAB_FUZZ_EXAMPLES=N`` draws N cases per family (as tests/test_fuzz_inputs.py); each test
prints its outcome counts (``pytest -s``).  The findings themselves are tests/test_cli_inputs.py.
"""

from __future__ import annotations

import collections
import ipaddress
import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_fuzz_inputs import BAD_TOKENS, TOKENS, check_named, mutate_lines, replace_field, report

from clothlab.errors import ClothlabError

EXAMPLES = int(os.environ.get("CLOTHLAB_FUZZ_EXAMPLES", "25"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
REPO = Path(__file__).parent.parent


def one_line(exc: ClothlabError) -> str:
    text = str(exc)
    assert text.strip() and "\n" not in text and "\r" not in text, text
    return text


# ---------------------------------------------------------------------------------------------------------
# Dask options

ADDRESS_PARTS = st.one_of(
    st.sampled_from(["tcp://", "tls://", "inproc://", "ucx://", "http://", "TCP://", "", "tcp:/", "://"]),
    st.text(max_size=4))
HOSTS = st.one_of(st.sampled_from(["127.0.0.1", "localhost", "[::1]", "::1", "10.0.0.5", "256.1.1.1", "a..b",
                                   "-a.b", "a_b", "node-1.example.org", "", "1.2.3", "[fe80::1%eth0]",
                                   "x" * 64, "\u0661.1.1.1", "h\x00st"]), st.text(max_size=10))
PORTS = st.one_of(st.sampled_from(["8786", "0", "1", "65535", "65536", "-1", "8_786", "\u0668\u0667", "+80",
                                   "99999999999999999999", "", " 80", "80/x", "80?a"]),
                  st.integers(-5, 70000).map(str), st.text(max_size=5))


def _valid_address(address, text: str) -> None:
    """Independent check of an accepted address: tcp/tls, a port in 1-65535 written in ASCII digits in the text,
    a host that is an IP address or RFC 1123 labels, and the normalised text parses to itself."""
    from clothlab.parallel.address import parse_scheduler_address

    assert address.scheme in ("tcp", "tls") and 1 <= address.port <= 65535
    assert text.isascii() and not any(c.isspace() for c in text)
    port = text.rsplit(":", 1)[1]
    assert port.isascii() and port.isdigit() and int(port) == address.port
    try:
        ipaddress.ip_address(address.host)
    except ValueError:
        labels = address.host.split(".")
        assert all(0 < len(label) <= 63 and label[0] != "-" and label[-1] != "-" and
                   all(c.isalnum() or c == "-" for c in label) for label in labels), address.host
    assert parse_scheduler_address(address.text, "--scheduler") == address


def test_fuzz_dask_options():
    """--scheduler / $DASK_SCHEDULER_ADDRESS / --workers as a command checks them (no connection is made)."""
    from clothlab.parallel.runner import resolve_options

    counts = collections.Counter()

    @SETTINGS
    @given(scheme=ADDRESS_PARTS, host=HOSTS, sep=st.sampled_from([":", "", "::", ": "]), port=PORTS,
           where=st.sampled_from(["--scheduler", "DASK_SCHEDULER_ADDRESS"]),
           workers=st.one_of(st.none(), st.integers(-3, 3)), raw=st.one_of(st.none(), TOKENS))
    def run(scheme, host, sep, port, where, workers, raw):
        text = raw if raw is not None else f"{scheme}{host}{sep}{port}"
        scheduler = text if where == "--scheduler" else None
        environ = {"DASK_SCHEDULER_ADDRESS": text} if where != "--scheduler" else {}
        try:
            got_workers, address = resolve_options(workers, scheduler, environ=environ)
        except ClothlabError as exc:
            one_line(exc)
            if workers is not None and (scheduler is not None or workers < 1):
                assert exc.field == "--workers", str(exc)
            else:
                assert exc.field == where, (str(exc), where)
            counts["refused (named)"] += 1
            return
        if workers is not None:  # --workers wins over the environment; with --scheduler it was refused
            assert scheduler is None and workers >= 1 and got_workers == workers and address is None
            counts["local cluster"] += 1
        elif not text:
            assert address is None  # an empty variable is unset
            counts["in-process"] += 1
        else:
            assert address.source == where
            _valid_address(address, text)
            counts["accepted (valid)"] += 1

    run()
    report("dask options", counts)


# ---------------------------------------------------------------------------------------------------------
# argparse argument vectors

COMMANDS = ["fit", "select", "report", "eval", "simulate", "import", "fit-btf", "render", "calibrate", "check",
            "bench", "train-surrogate", "bogus", ""]
OPTIONS = ["--nodes", "--rule", "--max-evals", "--seed", "--cv", "-o", "--workers", "--scheduler", "--force",
           "--columns", "--delimiter", "--header", "--comment", "--budget", "--pairs", "--width", "--target",
           "--labels", "--samples", "--comparison-name", "--format", "--option", "--free", "--crop", "-v", "-q",
           "--nope", "-x", "--", "-", "--kinds", "--weaves", "--candidate-cv", "--footprint", "--channels"]
WORDS = st.one_of(st.sampled_from(OPTIONS), TOKENS, st.sampled_from(["a.yaml", "fits/x", "d.csv", "-,theta_o",
                                                                   "3", "-3", "1e3", "x=y", "a\nb"]))


def test_fuzz_argparse_vectors(capsys):
    """Any argument vector: parsed, or exit 2 with ONE line ``clothlab: error: ...`` (an option named as
    ``field '...'``), never a usage block, a ``clothlab <cmd>: error:`` prefix or another exception."""
    from clothlab.cli.main import build_parser

    parser = build_parser()
    counts = collections.Counter()

    @SETTINGS
    @given(command=st.sampled_from(COMMANDS), words=st.lists(WORDS, max_size=6))
    def run(command, words):
        argv = ([command] if command else []) + [w for w in words if w not in ("-h", "--help", "--version")]
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            err = capsys.readouterr().err
            assert exc.code == 2, (argv, err)
            lines = err.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("clothlab: error: "), (argv, err)
            assert "usage:" not in err and not lines[0].startswith("clothlab " + command + ":"), err
            if "argument " in err:
                assert "field '" in lines[0], err
            counts["refused (one line)"] += 1
            return
        counts["parsed"] += 1

    run()
    report("argparse vectors", counts)


# ---------------------------------------------------------------------------------------------------------
# report: fit directories

FIT_VALUES = ["NaN", "Infinity", "-Infinity", "null", "true", "0", "-1", "1e308", '"x"', "[]", "{}", '"bogus"',
              '"irawan"', '"lambert"', "1575", "2", "0.5", '""', "[1, NaN]", "{\"a\": Infinity}"]


@pytest.fixture(scope="module")
def small_fit(tmp_path_factory):
    """fits/polyester-lining-lambert/ cut to 40 prediction rows (measurement.n matching)."""
    d = tmp_path_factory.mktemp("fit") / "f"
    shutil.copytree(REPO / "fits" / "polyester-lining-lambert", d)
    lines = (d / "predictions.csv").read_text().splitlines()
    (d / "predictions.csv").write_text("\n".join(lines[:41]) + "\n")
    fit = json.loads((d / "fit.json").read_text())
    fit["measurement"]["n"] = 40
    (d / "fit.json").write_text(json.dumps(fit, indent=1))
    return d


def _leaves(value, prefix=()):
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _leaves(v, prefix + (k,))
    elif isinstance(value, list) and value and len(value) <= 8:
        for i, v in enumerate(value):
            yield from _leaves(v, prefix + (i,))
    else:
        yield prefix


def _valid_record(record) -> None:
    """Independent check of a fit directory the report accepted."""
    from clothlab.models.registry import MODEL_KINDS

    fit = record.fit
    assert fit["model"]["kind"] in MODEL_KINDS
    objective = fit.get("objective")
    if objective is not None:
        assert isinstance(objective["final"], int | float) and math.isfinite(objective["final"])
    n = len(record.predictions["theta_i"])
    assert n >= 2 and fit["measurement"].get("n") in (None, n)
    t = record.predictions
    assert all(((0 <= t[k]) & (t[k] <= 90)).all() for k in ("theta_i", "theta_o"))
    assert all((np.abs(t[k]) <= 360).all() for k in ("phi_i", "phi_o"))
    for c in record.channels:
        measured, model = record.predictions[f"measured_{c}"], record.predictions[f"model_{c}"]
        assert (measured >= 0).all() and (model >= 0).all() and max(measured.max(), model.max()) <= 1e30
        assert np.isfinite(measured).all() and np.isfinite(model).all()
        assert (measured > 0).any() and model.any()
    text = json.dumps(fit, allow_nan=False)  # no NaN / Infinity anywhere
    assert text
    if record.slices is not None:
        sl = record.slices
        assert ((0 <= sl["theta_o"]) & (sl["theta_o"] <= 90)).all() and (np.abs(sl["signed_theta_i"]) <= 90).all()
        assert all(((sl[k] >= 0) & (sl[k] <= 1e30)).all() for k in sl if k.startswith("model_"))
    if record.trace is not None:
        for k in ("value", "best"):
            finite = record.trace[k][np.isfinite(record.trace[k])]
            assert (np.abs(finite) <= 1e30).all() and not ((finite != 0) & (np.abs(finite) < 2.2e-308)).any()


def test_fuzz_report_fit_directories(tmp_path, small_fit):
    """fit.json with one value replaced (NaN, Infinity, a wrong type, a bogus kind) or a key deleted, or
    predictions.csv with one line mutated: the record loads valid, or one line names the file and a field/line."""
    from clothlab.report.data import load_fit_dir

    fit_text = (small_fit / "fit.json").read_text()
    fit = json.loads(fit_text)
    leaves = list(_leaves(fit))
    tables = {name: (small_fit / name).read_text().splitlines()
              for name in ("predictions.csv", "slices.csv", "trace.csv")}
    counts = collections.Counter()

    @SETTINGS
    @given(target=st.sampled_from(["fit.json", "fit.json", "predictions.csv", "slices.csv", "trace.csv"]),
           leaf=st.sampled_from(leaves), value=st.one_of(st.sampled_from(FIT_VALUES), TOKENS.map(json.dumps)),
           delete=st.booleans(), op=st.integers(0, 4), index=st.integers(0, 10**6), col=st.integers(0, 40),
           token=st.one_of(TOKENS, st.sampled_from(["1e308", "-1e308", "1e-320", "-5", "200", "inf", "nan"])))
    def run(target, leaf, value, delete, op, index, col, token):
        d = tmp_path / "case"
        shutil.rmtree(d, ignore_errors=True)
        shutil.copytree(small_fit, d)
        if target == "fit.json":
            data = json.loads(fit_text)
            parent = data
            for key in leaf[:-1]:
                parent = parent[key]
            if delete and isinstance(parent, dict):
                del parent[leaf[-1]]
                text = json.dumps(data)
            else:
                parent[leaf[-1]] = "@@VALUE@@"
                text = json.dumps(data).replace('"@@VALUE@@"', value)
            (d / "fit.json").write_text(text)
        else:
            lines = tables[target]
            if op == 4:  # one cell of a data row
                lines = replace_field(lines, 1 + index % (len(lines) - 1), col, token)
            else:
                lines = mutate_lines(lines, op, index, token)
            (d / target).write_text("\n".join(lines) + "\n")
        try:
            record = load_fit_dir(d)
        except ClothlabError as exc:
            check_named(exc, *(d / name for name in ("fit.json", "predictions.csv", "slices.csv", "trace.csv")))
            counts["refused (named)"] += 1
            return
        _valid_record(record)
        counts["accepted (valid)"] += 1

    run()
    report("report fit directories", counts)


# ---------------------------------------------------------------------------------------------------------
# fit-btf: name-based stacks


@pytest.fixture(scope="module")
def names_stack(tmp_path_factory):
    from clothlab.simulate.btf import TextureLayout, simulate_btf

    path = simulate_btf("preset:cotton-denim", tmp_path_factory.mktemp("btf") / "stack", n_directions=8, size=8,
                        tile_repeats=2, layout=TextureLayout(offset=(0.1, 0.2), hwidth=0.35, noise=False, seed=1))
    (path / "manifest.yaml").unlink()
    return path


def _product_filled(directions) -> bool:
    """Independent: off-pole directions that fill >= 3/4 of their polar x azimuth product fill all of it."""
    off = {d for d in directions if d[0] != 0}
    thetas, phis = {t for t, _ in off}, {p for _, p in off}
    grid = len(thetas) * len(phis)
    return len(thetas) < 2 or len(phis) < 2 or len(off) == grid or len(off) < 0.75 * grid


def test_fuzz_btf_name_stacks(tmp_path, names_stack):
    """Images of a name-based stack deleted, renamed (bad angles), emptied or replaced by text: the stack
    opens complete and readable, or one line names the file."""
    from clothlab.btf import BtfStack

    images = sorted(p.name for p in (names_stack / "tv000_pv000").iterdir())
    counts = collections.Counter()

    @SETTINGS
    @given(deleted=st.sets(st.sampled_from(images), max_size=6),
           renamed=st.one_of(st.none(), st.tuples(st.sampled_from(images), TOKENS)),
           broken=st.one_of(st.none(), st.tuples(st.sampled_from(images), st.sampled_from([b"", b"xyz", b"\0" * 9]))))
    def run(deleted, renamed, broken):
        d = tmp_path / "case"
        shutil.rmtree(d, ignore_errors=True)
        shutil.copytree(names_stack, d)
        view = d / "tv000_pv000"
        for name in deleted:
            (view / name).unlink()
        if renamed is not None and renamed[0] not in deleted:
            new = renamed[1].replace("/", "_").replace("\0", "_") + ".exr"
            if new not in images and not new.startswith("."):
                try:
                    (view / renamed[0]).rename(view / new)
                except OSError:
                    pass
        if broken is not None and (view / broken[0]).exists():
            (view / broken[0]).write_bytes(broken[1])
        try:
            stack = BtfStack.open(d)
        except ClothlabError as exc:
            assert exc.path is not None and str(d) in exc.path, str(exc)
            one_line(exc)
            counts["refused (named)"] += 1
            return
        assert len(stack) == len(stack.entries) > 0 and all(e.path.is_file() for e in stack.entries)
        lights = {(round(e.angles[0], 4), round(e.angles[1] % 360, 4)) for e in stack.entries}
        assert _product_filled(lights), sorted(lights)
        counts["accepted (valid)"] += 1

    run()
    report("fit-btf name stacks", counts)


# ---------------------------------------------------------------------------------------------------------
# fabric.yaml: size-like fields

SIZE_FIELDS = {
    "fit.posterior.walkers": "  posterior: {{walkers: {}}}\n", "fit.posterior.steps": "  posterior: {{steps: {}}}\n",
    "fit.posterior.max_steps": "  posterior: {{max_steps: {}}}\n", "fit.cv_folds": "  cv_folds: {}\n",
    "fit.optimizer.max_evals": "  optimizer: {{max_evals: {}}}\n", "select.max_evals": None, "select.cv_folds": None,
    "select.weaves": None,
}
SIZES = st.one_of(st.sampled_from(["0", "1", "2", "4096", "4097", "1000000", "1000001", "1e15", "1000000000000000",
                                   "2147483647", "2147483648", "-1", "[]", "null", "1_000", "\u0665", "3.0", "[a, ]",
                                   "[preset:cotton-denim, '']", "['']", "[preset:cotton-denim]"]),
                  st.integers(-10, 10**16).map(str), st.sampled_from(BAD_TOKENS))


def test_fuzz_config_size_fields(tmp_path):
    """One size-like field of fabric.yaml set to a drawn value: a config within the documented limits, or a
    ConfigError at the file, line and field."""
    from clothlab.config import load_config
    from clothlab.config.validate import MAX_CHAIN_BYTES, MAX_CV_FOLDS, MAX_EVALS, MAX_POSTERIOR_STEPS, MAX_WALKERS

    shutil.copy(REPO / "measurements" / "cotton-denim" / "noisy.csv", tmp_path / "m.csv")
    base = "name: x\nmeasurement: {path: m.csv}\nmodel: {kind: irawan, weave: preset:cotton-denim}\n"
    path = tmp_path / "fabric.yaml"
    counts = collections.Counter()

    @SETTINGS
    @given(field=st.sampled_from(sorted(SIZE_FIELDS)), value=SIZES)
    def run(field, value):
        if field.startswith("select."):
            text = base + f"select:\n  {field.split('.')[1]}: {value}\n"
        else:
            text = base + "fit:\n  free: [alpha, beta]\n" + SIZE_FIELDS[field].format(value)
        path.write_text(text, encoding="utf-8")
        try:
            cfg = load_config(path)
        except ClothlabError as exc:
            check_named(exc, path)
            assert exc.line is not None, str(exc)
            counts["refused (named)"] += 1
            return
        post = cfg.fit.posterior
        if post is not None:
            assert 4 <= post.walkers <= MAX_WALKERS and 1 <= post.steps <= post.max_steps <= MAX_POSTERIOR_STEPS
            assert post.max_steps * post.walkers * 3 * 8 <= MAX_CHAIN_BYTES
        assert 0 <= cfg.fit.cv_folds <= MAX_CV_FOLDS and cfg.fit.cv_folds != 1
        assert 1 <= cfg.fit.optimizer.max_evals <= MAX_EVALS and 1 <= cfg.select.max_evals <= MAX_EVALS
        assert 0 <= cfg.select.cv_folds <= MAX_CV_FOLDS
        if field == "select.weaves":
            assert len(cfg.select.weaves) >= 1 and all(cfg.select.weaves)
        counts["accepted (valid)"] += 1

    run()
    report("config size fields", counts)


# ---------------------------------------------------------------------------------------------------------
# train-surrogate: the SOURCE weave list


def test_fuzz_train_surrogate_weave_list():
    """SOURCE as a comma list of weaves, empty items and text: every item kept (none dropped), or one line
    naming ``source`` / ``--heldout-pattern``."""
    from types import SimpleNamespace

    from clothlab.cli.train_surrogate import _weave_specs

    items = st.one_of(st.sampled_from(["pattern:plain", "preset:cotton-denim", "", " ", "pattern:twill-3x3",
                                       "a.wv"]), TOKENS)
    counts = collections.Counter()

    @SETTINGS
    @given(parts=st.lists(items, max_size=5), held=st.one_of(st.none(), items))
    def run(parts, held):
        source = ",".join(parts)
        try:
            specs, held_spec = _weave_specs(SimpleNamespace(source=source, heldout_pattern=held))
        except ClothlabError as exc:
            one_line(exc)
            assert exc.field in ("source", "--heldout-pattern"), str(exc)
            counts["refused (named)"] += 1
            return
        assert specs == [p.strip() for p in source.split(",")] and all(specs)
        assert held_spec is None or held_spec == held.strip() != ""
        counts["accepted (valid)"] += 1

    run()
    report("train-surrogate weave list", counts)


def test_fuzz_fit_btf_options():
    """--crop and --free / --refine of fit-btf: four non-negative pixel integers in ASCII digits / names of the
    lists, or one line naming the option."""
    from clothlab.texfit.fit import REFINABLE, TEXTURE_FREE, parse_crop, parse_names

    numbers = st.one_of(st.integers(-3, 10**10).map(str), st.sampled_from(BAD_TOKENS))
    counts = collections.Counter()

    @SETTINGS
    @given(cells=st.lists(numbers, min_size=1, max_size=5), names=st.lists(
        st.one_of(st.sampled_from(list(TEXTURE_FREE) + list(REFINABLE) + ["", " "]), TOKENS), min_size=1,
        max_size=4), flag=st.sampled_from(["--free", "--refine"]))
    def run(cells, names, flag):
        text = ",".join(cells)
        try:
            crop = parse_crop(text)
        except ClothlabError as exc:
            assert exc.field == "--crop", str(exc)
            one_line(exc)
            counts["crop refused (named)"] += 1
        else:
            assert len(crop) == 4 and crop[0] >= 0 and crop[1] >= 0 and crop[2] >= 1 and crop[3] >= 1
            assert all(c.strip().isascii() and c.strip().isdigit() for c in cells), cells
            counts["crop accepted (valid)"] += 1
        allowed = TEXTURE_FREE if flag == "--free" else REFINABLE
        try:
            got = parse_names(",".join(names), allowed, flag)
        except ClothlabError as exc:
            assert exc.field == flag, str(exc)
            one_line(exc)
            counts["names refused (named)"] += 1
        else:
            assert all(n in allowed for n in got) and len(set(got)) == len(got) == len(names)
            counts["names accepted (valid)"] += 1

    run()
    report("fit-btf options", counts)
