"""Issue 24, the command-line families: Dask options (the address parsed and probed, conflicts refused, the
client closed on error, the source of the address named), one error format for argparse's own mistakes,
``report`` of a corrupt fit directory, ``fit-btf`` with a missing grid image, the size limits of fabric.yaml,
``train-surrogate``'s run directory and ``--resume``, and Ctrl-C in the posterior.

Network tests aim at loopback only: a listener of the test's own on 127.0.0.1."""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from clothlab.cli.main import build_parser, main
from clothlab.errors import ClothlabError

REPO = Path(__file__).resolve().parents[1]


def one_error_line(err: str) -> str:
    """The single ``clothlab: error:`` line of ``err`` (fails on a traceback, a usage block, several lines)."""
    lines = err.strip().splitlines()
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert len(lines) == 1 and lines[0].startswith("clothlab: error: "), err
    return lines[0]


# ---------------------------------------------------------------------------------------------------------
# A. Dask options


class Listener:
    """A TCP server on 127.0.0.1 (a free port) that sends ``greeting`` to each connection, then ``reply`` to
    whatever the client sends; closed on exit."""

    def __init__(self, greeting: bytes, reply: bytes = b""):
        self.greeting, self.reply = greeting, reply
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.port = self.sock.getsockname()[1]
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.thread = threading.Thread(target=self._serve, daemon=True)

    def _serve(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            with conn:
                try:
                    conn.sendall(self.greeting)
                    conn.settimeout(3)
                    if self.reply and conn.recv(65536):
                        conn.sendall(self.reply)
                    time.sleep(0.5)
                except OSError:
                    pass

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.sock.close()


def fake_dask_handshake() -> bytes:
    """What a Dask scheduler sends first: total length, frame count, frame length, a msgpack map."""
    msgpack = pytest.importorskip("msgpack")
    frame = msgpack.packb({"compression": None, "python": [3, 11, 7], "pickle-protocol": 5})
    body = struct.pack("<QQ", 1, len(frame)) + frame
    return struct.pack("<Q", len(body)) + body


HTTP = b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"


@pytest.mark.parametrize("address, words", [
    ("", "empty"), ("127.0.0.1", "port is missing"), ("tcp://127.0.0.1", "port is missing"),
    ("tcp://127.0.0.1:0", "outside 1-65535"), ("tcp://127.0.0.1:65536", "outside 1-65535"),
    ("tcp://127.0.0.1:99999999999", "not a number"), ("tcp://127.0.0.1:8_786", "not a number"),
    ("tcp://127.0.0.1:\u0668\u0667", "non-ASCII"), ("http://127.0.0.1:8786", "unknown scheme"),
    ("inproc://127.0.0.1/1/2", "inproc"), ("tcp://:8786", "host is missing"), ("tcp://300.1.1.1:8786", "IPv4"),
    ("tcp://bad_host:8786", "host name"), ("tcp://::1:8786", "brackets"), ("tcp://[::zz]:8786", "IPv6"),
    ("tcp://h:8786/path", "path"), ("tcp://127.0.0.1:8786 ", "space"), ("tcp://a\nb:1", "control"),
    ("x" * 400, "characters"),
])
def test_a_malformed_scheduler_address_is_refused_before_any_connection(address, words):
    from clothlab.parallel.runner import resolve_options

    with pytest.raises(ClothlabError) as info:
        resolve_options(None, address)
    assert info.value.field == "--scheduler" and words in str(info.value), str(info.value)
    assert "\n" not in str(info.value)
    if not address:  # an empty variable means "not set": in-process
        assert resolve_options(None, None, environ={"DASK_SCHEDULER_ADDRESS": ""}) == (None, None)
        return
    with pytest.raises(ClothlabError) as info:  # the same address from the environment is blamed as itself
        resolve_options(None, None, environ={"DASK_SCHEDULER_ADDRESS": address})
    assert info.value.field == "DASK_SCHEDULER_ADDRESS", str(info.value)


def test_good_addresses_are_normalised():
    from clothlab.parallel.address import parse_scheduler_address

    assert parse_scheduler_address("127.0.0.1:8786", "--scheduler").text == "tcp://127.0.0.1:8786"
    assert parse_scheduler_address("TCP://Node-1.example.org:1", "--scheduler").text == "tcp://Node-1.example.org:1"
    assert parse_scheduler_address("tls://[::1]:8786", "--scheduler").text == "tls://[::1]:8786"


def test_a_non_dask_service_is_named_without_a_huge_allocation(monkeypatch):
    """An HTTP server answering on the port: before, Dask's client read its first 8 bytes as a length and
    tried to allocate 3 EiB (a traceback); now a bounded probe names it in one line, at once."""
    pytest.importorskip("distributed")
    import clothlab.parallel.runner as runner

    monkeypatch.setattr(runner, "CONNECT_TIMEOUT_S", 2.0)
    for greeting in (HTTP, b"\xff" * 64, b"\x00" * 8, b""):
        with Listener(greeting) as server:
            tic = time.monotonic()
            with pytest.raises(ClothlabError) as info:
                runner.make_runner(scheduler=server.address)
            assert time.monotonic() - tic < 10
        text = str(info.value)
        assert info.value.field == "--scheduler" and server.address in text and "\n" not in text, text
        assert "Dask" in text, text


def test_a_service_that_breaks_after_the_handshake_is_one_line_and_the_client_is_closed(tmp_path):
    """The probe passes (a Dask-shaped handshake), then garbage: one line, exit 2, and no ``Client.__del__``
    traceback at exit (the client is closed on error)."""
    pytest.importorskip("distributed")
    handshake = fake_dask_handshake()
    with Listener(handshake, reply=HTTP * 4) as server:
        code = ("import sys\nimport clothlab.parallel.runner as r\nr.CONNECT_TIMEOUT_S = 3.0\n"
                "from clothlab.cli.main import main\nsys.exit(main(sys.argv[1:]))")
        done = subprocess.run([sys.executable, "-c", code, "check", "--scheduler", server.address],
                              capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    line = one_error_line(done.stderr)
    assert "field '--scheduler'" in line and server.address in line


def test_the_environment_variable_is_blamed_as_itself(tmp_path):
    pytest.importorskip("distributed")
    with Listener(HTTP) as server:
        env = dict(os.environ, DASK_SCHEDULER_ADDRESS=server.address)
        done = subprocess.run([sys.executable, "-m", "clothlab", "check"], capture_output=True, text=True,
                              timeout=120, cwd=tmp_path, env=env)
    assert done.returncode == 2, done.stderr
    line = one_error_line(done.stderr)
    assert "field 'DASK_SCHEDULER_ADDRESS'" in line and "--scheduler" not in line, line
    env = dict(os.environ, DASK_SCHEDULER_ADDRESS="tcp://127.0.0.1:http")
    done = subprocess.run([sys.executable, "-m", "clothlab", "check"], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path, env=env)
    assert done.returncode == 2 and "field 'DASK_SCHEDULER_ADDRESS'" in one_error_line(done.stderr)


def test_bad_scheduler_and_conflicting_options_refused_when_nothing_is_distributed(tmp_path, capsys):
    """One fit without CV or posterior distributes nothing: before, a malformed --scheduler (and --workers with
    --scheduler) was ignored and the fit ran; now both are refused before any work."""
    from test_parallel import make_project

    [config] = make_project(tmp_path, fabrics=("polyester-lining",), max_evals=10)
    for extra, field in ((["--scheduler", "tcp://127.0.0.1:99999"], "--scheduler"),
                         (["--scheduler", "nonsense"], "--scheduler"),
                         (["--workers", "2", "--scheduler", "tcp://127.0.0.1:8786"], "--workers")):
        assert main(["fit", str(config), *extra]) == 2
        assert f"field '{field}'" in one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "fits").exists()


# ---------------------------------------------------------------------------------------------------------
# B. One error format, argparse included


@pytest.mark.parametrize("argv, option", [
    (["fit", "x.yaml", "--nodes", "abc"], "--nodes"),
    (["fit", "x.yaml", "--max-evals", "1_0"], "--max-evals"),
    (["bogus"], "COMMAND"),
    (["report", "--comparison-name"], "--comparison-name"),
    (["train-surrogate", "preset:cotton-denim", "--target", "nope"], "--target"),
    (["import", "a.csv", "-o", "b.csv", "--delimiter", "pipe"], "--delimiter"),
    (["-v=3"], "-v/--verbose"),
    (["eval", "fits/x", "d.csv", "--rule", "sim\npson"], "--rule"),
])
def test_argparse_mistakes_are_one_line_naming_the_option(argv, option, capsys):
    with pytest.raises(SystemExit) as info:
        build_parser().parse_args(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    line = one_error_line(err)
    assert f"field '{option}'" in line and "usage:" not in err and "clothlab fit:" not in err, err


@pytest.mark.parametrize("argv, words", [
    (["fit"], "required"), (["report", "--nope"], "unrecognized arguments: --nope"),
    (["fit", "a.yaml", "--nope\nx"], "unrecognized"),
])
def test_other_usage_errors_are_one_line_too(argv, words, capsys):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2 and words in one_error_line(capsys.readouterr().err)


def test_import_columns_may_begin_with_a_dash(tmp_path, capsys):
    """``--columns -,theta_i,...`` ('-' skips the first column) is a value, not an unknown option (issue 28)."""
    from clothlab.io.table import read_table

    rows = ["7,10,0,30,180,0.5", "8,20,90,40,270,0.25"]
    (tmp_path / "lab.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "t.csv"
    assert main(["import", str(tmp_path / "lab.csv"), "-o", str(out), "--header", "no", "--columns",
                 "-,theta_i,phi_i,theta_o,phi_o,grey", "-q"]) == 0, capsys.readouterr().err
    table = read_table(out)
    assert list(table.theta_i) == [10.0, 20.0] and list(table.theta_o) == [30.0, 40.0]
    # an option word after --columns is still the next option: its value is missing
    with pytest.raises(SystemExit):
        main(["import", str(tmp_path / "lab.csv"), "-o", str(out), "--columns", "--force"])
    assert "field '--columns'" in one_error_line(capsys.readouterr().err)


# ---------------------------------------------------------------------------------------------------------
# C. report of a corrupt fit directory


def _fit_copy(tmp_path: Path, edit=None, text_edit=None, predictions=None) -> Path:
    """A copy of the shipped fits/polyester-lining-lambert/ with fit.json (or predictions.csv) edited."""
    d = tmp_path / "fits" / "f"
    shutil.copytree(REPO / "fits" / "polyester-lining-lambert", d)
    fit = json.loads((d / "fit.json").read_text())
    if edit is not None:
        edit(fit)
    text = json.dumps(fit)
    if text_edit is not None:
        text = text_edit(text)
    (d / "fit.json").write_text(text)
    if predictions is not None:
        lines = (d / "predictions.csv").read_text().splitlines()
        (d / "predictions.csv").write_text("\n".join(predictions(lines)) + "\n")
    return d


def _zero_measured(lines):
    header = lines[0].split(",")
    cols = [i for i, h in enumerate(header) if h.startswith("measured_")]
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        for i in cols:
            cells[i] = "0"
        out.append(",".join(cells))
    return out


@pytest.mark.parametrize("case, kwargs, file, field", [
    ("bogus kind", {"edit": lambda f: f["model"].update(kind="bogus")}, "fit.json", "model.kind"),
    ("missing kind", {"edit": lambda f: f["model"].pop("kind")}, "fit.json", "model.kind"),
    ("no model", {"edit": lambda f: f.pop("model")}, "fit.json", "model.kind"),
    ("zero n", {"edit": lambda f: f["measurement"].update(n=0)}, "fit.json", "measurement.n"),
    ("wrong n", {"edit": lambda f: f["measurement"].update(n=7)}, "fit.json", "measurement.n"),
    ("zero measured", {"predictions": _zero_measured}, "predictions.csv", "measured_R"),
    ("theta_i 200", {"predictions": lambda lines: [lines[0], "200" + lines[1][lines[1].index(","):], *lines[2:]]},
     "predictions.csv", "theta_i"),  # before: rendered, exit 0
    ("model 1e308", {"predictions": lambda lines: [lines[0], ",".join(lines[1].split(",")[:5] + ["1e308"] +
                                                                    lines[1].split(",")[6:]), *lines[2:]]},
     "predictions.csv", "model_R"),
    ("NaN objective", {"text_edit": lambda t: re.sub(r'"final": [-+0-9.eE]+', '"final": NaN', t, count=1)},
     "fit.json", "objective.final"),
    ("null objective", {"edit": lambda f: f["objective"].update(final=None)}, "fit.json", "objective.final"),
    ("string objective", {"edit": lambda f: f["objective"].update(start="0.3")}, "fit.json", "objective.start"),
    ("Infinity deep", {"text_edit": lambda t: t.replace('"wall_time_s": ', '"wall_time_s": Infinity, "x": ', 1)},
     "fit.json", "wall_time_s"),
    ("string CV entry", {"edit": lambda f: f["cross_validation"].update(in_sample="x")}, "fit.json",
     "cross_validation.in_sample"),  # before: an AttributeError traceback while rendering
    ("list CV", {"edit": lambda f: f.update(cross_validation=[1])}, "fit.json", "cross_validation"),
    ("-Infinity in a list", {"edit": lambda f: f.update(extra=[1, {"a": [0, "MARK"]}]),
                             "text_edit": lambda t: t.replace('"MARK"', "-Infinity")}, "fit.json", "extra.1.a.1"),
])
def test_report_refuses_a_corrupt_fit_naming_the_file_and_field(tmp_path, capsys, case, kwargs, file, field):
    """Before: rendered and exit 0 (or, for Infinity, a message without the field)."""
    d = _fit_copy(tmp_path, **kwargs)
    assert main(["report", str(d), "-o", str(tmp_path / "reports")]) == 2, case
    line = one_error_line(capsys.readouterr().err)
    assert f"{file}, field '{field}'" in line, line
    assert not (tmp_path / "reports" / "f").exists()


def test_report_still_renders_the_shipped_fit(tmp_path):
    d = _fit_copy(tmp_path)
    assert main(["report", str(d), "-o", str(tmp_path / "reports"), "-q"]) == 0
    assert (tmp_path / "reports" / "polyester-lining-lambert" / "index.html").is_file()


# ---------------------------------------------------------------------------------------------------------
# D. fit-btf with a missing grid image


@pytest.fixture(scope="module")
def names_only_stack(tmp_path_factory):
    """A simulated 8-image stack (Fig. 4's elevations 15-60 deg x azimuths 0, 180) without its manifest: the
    angles come from the UTIA file names."""
    from clothlab.simulate.btf import TextureLayout, simulate_btf

    path = simulate_btf("preset:cotton-denim", tmp_path_factory.mktemp("btf") / "stack", n_directions=8, size=12,
                        tile_repeats=2, layout=TextureLayout(offset=(0.1, 0.2), hwidth=0.35, noise=False, seed=1))
    (path / "manifest.yaml").unlink()
    return path


def test_fit_btf_with_a_missing_grid_image_exits_2_naming_it(tmp_path, capsys, names_only_stack):
    """Before: the 7 remaining images were fitted and the command exited 0."""
    from clothlab.btf import BtfStack

    assert len(BtfStack.open(names_only_stack)) == 8  # the complete grid opens
    stack = tmp_path / "stack"
    shutil.copytree(names_only_stack, stack)
    victim = sorted((stack / "tv000_pv000").iterdir())[3]
    victim.unlink()
    assert main(["fit-btf", str(stack), str(REPO / "fits" / "cotton-denim"), "-o", str(tmp_path / "out")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"missing image: expected 'tv000_pv000/{victim.name}'" in line and str(victim) in line, line
    assert not (tmp_path / "out").exists()


def test_a_scattered_names_only_stack_is_not_taken_for_a_grid(tmp_path, names_only_stack):
    """Directions that do not fill three quarters of their polar x azimuth product claim no grid."""
    from clothlab.btf import BtfStack

    stack = tmp_path / "stack"
    shutil.copytree(names_only_stack, stack)
    view = stack / "tv000_pv000"
    for image in sorted(view.iterdir()):
        if not image.name.startswith(("tl015_pl000", "tl030_pl180", "tl060_pl000")):
            image.unlink()
    assert len(BtfStack.open(stack)) == 3  # 3 of 3 x 2: a scattered sampling


# ---------------------------------------------------------------------------------------------------------
# F. Ctrl-C in the posterior, train-surrogate's run directory


@pytest.mark.parametrize("at_call", [3, 4, 9, 20])
def test_ctrl_c_inside_the_log_probability_prints_nothing_and_keeps_whole_steps(tmp_path, capfd, monkeypatch,
                                                                               at_call):
    """A KeyboardInterrupt raised inside the likelihood (where a Ctrl-C lands most of the time): before,
    emcee's wrapper printed "emcee: Exception while calling your likelihood function" and a traceback; now
    nothing is printed, the checkpoint holds whole steps of the uninterrupted chain, and a resume gives it."""
    import numpy as np
    from test_posterior import FAST, _problem

    from clothlab.fit.posterior import _Likelihood, run_posterior

    problem, truth = _problem()
    reference = run_posterior(problem, truth, seed=7, **FAST)
    calls = {"n": 0}
    original = _Likelihood.__call__

    def counting(self, X):
        calls["n"] += 1
        if calls["n"] == at_call:
            raise KeyboardInterrupt
        return original(self, X)

    checkpoint = tmp_path / "posterior.npz"
    monkeypatch.setattr(_Likelihood, "__call__", counting)
    capfd.readouterr()
    with pytest.raises(KeyboardInterrupt):
        run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    out, err = capfd.readouterr()
    assert "emcee" not in out + err and "Traceback" not in out + err, out + err
    monkeypatch.setattr(_Likelihood, "__call__", original)
    if checkpoint.exists():
        with np.load(checkpoint) as z:
            done = len(z["chain"])
            np.testing.assert_array_equal(z["chain"], reference.chain[:done])
    resumed = run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    np.testing.assert_array_equal(resumed.chain, reference.chain)
    np.testing.assert_array_equal(resumed.log_prob, reference.log_prob)


POSTERIOR_FABRIC = """\
name: sig
measurement: {path: m.csv}
model: {kind: irawan, weave: preset:cotton-denim}
fit:
  free: [alpha, beta]
  optimizer: {global: null, local: LN_BOBYQA, max_evals: 30, seed: 1}
  posterior: {walkers: 8, steps: 200000, max_steps: 200000}
output: {fits: fits, reports: reports}
"""


def test_ctrl_c_during_the_posterior_exits_130_with_one_line(tmp_path):
    """SIGINT a few times while the posterior samples (its checkpoint exists): exit 130, one line, nothing on
    stdout from emcee, the hidden checkpoint kept for the next run and no fit directory committed."""
    import signal

    rows = (REPO / "measurements" / "cotton-denim" / "noisy.csv").read_text().splitlines()
    header = [r for r in rows if r.startswith("#") or not r[:1].isdigit()]
    data = [r for r in rows if r[:1].isdigit()]
    (tmp_path / "m.csv").write_text("\n".join(header + data[::8]) + "\n")
    (tmp_path / "fabric.yaml").write_text(POSTERIOR_FABRIC)
    checkpoint = tmp_path / "fits" / ".sig.posterior-checkpoint.npz"
    for delay in (0.0, 0.13, 0.31):
        child = subprocess.Popen([sys.executable, "-m", "clothlab", "fit", "fabric.yaml", "--force"], cwd=tmp_path,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 env=dict(os.environ, PYTHONPATH=str(REPO)))
        def stamp():
            return checkpoint.stat().st_mtime_ns if checkpoint.exists() else None

        before, deadline = stamp(), time.monotonic() + 240
        while stamp() == before and child.poll() is None and time.monotonic() < deadline:  # sampling in this run
            time.sleep(0.05)
        assert child.poll() is None, child.communicate()
        time.sleep(delay)
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=120)
        assert child.returncode == 130, (out, err)
        assert "emcee" not in out + err and "Traceback" not in out + err, (out, err)
        assert err.strip().splitlines()[-1] == "clothlab: interrupted", err
        assert [line for line in err.strip().splitlines() if line.startswith("clothlab:")] == \
            ["clothlab: interrupted"], err
        assert checkpoint.exists() and not (tmp_path / "fits" / "sig").exists()


TINY_SURROGATE = ["--budget", "0.02", "--labels", "model", "--pairs", "4", "--width", "8", "--spatial", "8", "-q"]


def test_train_surrogate_replaces_its_directory_atomically(tmp_path, capsys, monkeypatch):
    """--force builds the new run next to the old one and swaps it in when complete: a run that fails half way
    leaves the previous directory as it was (before: shutil.rmtree first, then a half-written directory)."""
    import clothlab.surrogate.training_run

    out = tmp_path / "run"
    args = ["train-surrogate", "preset:cotton-denim", "-o", str(out), *TINY_SURROGATE]
    assert main(args) == 0
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert (out / "surrogate.npz").is_file() and (out / "materials.json").is_file()

    def broken(*a, **k):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(clothlab.surrogate.training_run, "write_plots", broken)
    with pytest.raises(RuntimeError, match="disk on fire"):
        main([*args, "--force", "--seed", "3"])
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before  # the previous run, byte for byte
    assert [p.name for p in tmp_path.iterdir()] == ["run"]  # no temporary or lock left
    monkeypatch.undo()
    capsys.readouterr()
    assert main([*args, "--force", "--seed", "3"]) == 0
    assert capsys.readouterr().out.startswith(f"{out / 'surrogate.npz'}: ")  # the final path, not the temporary
    assert json.loads((out / "training.json").read_text())["train_spec"]["seed"] == 3


@pytest.mark.parametrize("prepare", ["missing", "empty", "other files"])
def test_resume_without_a_run_directory_is_refused(tmp_path, capsys, prepare):
    """Before: --resume with nothing to resume silently started a new run."""
    out = tmp_path / "run"
    if prepare != "missing":
        out.mkdir()
    if prepare == "other files":
        (out / "notes.txt").write_text("x")
    assert main(["train-surrogate", "preset:cotton-denim", "-o", str(out), "--resume", *TINY_SURROGATE]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "field '--resume'" in line and "nothing to resume" in line and str(out) in line
    assert not (out / "surrogate.npz").exists()


@pytest.mark.parametrize("source", ["pattern:plain,,pattern:twill-3x3", "pattern:plain,", ",pattern:plain",
                                    "pattern:plain, ,pattern:satin-5x5"])
def test_an_empty_item_of_the_weave_list_is_refused_not_dropped(tmp_path, capsys, source):
    assert main(["train-surrogate", source, "-o", str(tmp_path / "run"), *TINY_SURROGATE]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "field 'source'" in line and "is empty" in line
    assert not (tmp_path / "run").exists()


# ---------------------------------------------------------------------------------------------------------
# E. fabric.yaml: size-like fields have documented limits, select.weaves: [] says nothing to try

BASE_YAML = "name: x\nmeasurement: {path: m.csv}\nmodel: {kind: irawan, weave: preset:cotton-denim}\n"


@pytest.mark.parametrize("extra, field, line", [
    ("fit:\n  free: [alpha]\n  posterior: {steps: 1000000000000000}\n", "fit.posterior.steps", 6),
    ("fit:\n  free: [alpha]\n  posterior:\n    max_steps: 1000001\n", "fit.posterior.max_steps", 7),
    ("fit:\n  free: [alpha]\n  posterior: {walkers: 100000}\n", "fit.posterior.walkers", 6),
    ("fit:\n  free: [alpha]\n  posterior: {walkers: 4096, max_steps: 1000000}\n", "fit.posterior.max_steps", 6),
    ("fit:\n  cv_folds: 1000000000\n", "fit.cv_folds", 5),
    ("fit:\n  optimizer: {max_evals: 2147483648}\n", "fit.optimizer.max_evals", 5),
    ("select:\n  max_evals: 2147483648\n", "select.max_evals", 5),
    ("select:\n  cv_folds: 123456789\n", "select.cv_folds", 5),
    ("select:\n  weaves: []\n", "select.weaves", 5),
])
def test_size_like_fields_have_a_limit_named_at_file_line_field(tmp_path, extra, field, line):
    """Before: accepted (posterior.steps 1e15 then hung, select.weaves [] silently meant every preset)."""
    from clothlab.config import load_config
    from clothlab.errors import ConfigError

    shutil.copy(REPO / "measurements" / "cotton-denim" / "noisy.csv", tmp_path / "m.csv")
    path = tmp_path / "fabric.yaml"
    path.write_text(BASE_YAML + extra)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value).startswith(f"{path}:{line}, field '{field}': "), str(info.value)


def test_the_limits_still_accept_the_shipped_settings(tmp_path):
    from clothlab.config import load_config

    shutil.copy(REPO / "measurements" / "cotton-denim" / "noisy.csv", tmp_path / "m.csv")
    path = tmp_path / "fabric.yaml"
    path.write_text(BASE_YAML + "fit:\n  free: [alpha]\n  cv_folds: 100000\n  optimizer: {max_evals: 2147483647}\n"
                    "  posterior: {walkers: 4096, steps: 4000, max_steps: 20000}\n")
    cfg = load_config(path)
    assert cfg.fit.posterior.walkers == 4096 and cfg.fit.cv_folds == 100000
    for shipped in sorted((REPO / "measurements").glob("*/fabric.yaml")):
        load_config(shipped)


def test_cv_override_is_limited_naming_the_option(tmp_path, capsys):
    from test_parallel import make_project

    [config] = make_project(tmp_path, fabrics=("polyester-lining",), max_evals=10)
    with pytest.raises(SystemExit) as info:  # beyond --cv's documented limit (fit.cv_folds's)
        main(["fit", str(config), "--cv", "100001"])
    assert info.value.code == 2
    assert "field '--cv'" in one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("crop", ["1_0,0,4,4", "\u0661,0,4,4", "+1,0,4,4", "1,0,4,4e0", "0x1,0,4,4"])
def test_fit_btf_crop_is_read_strictly(crop):
    """Before: int() read '1_0' as 10 and Arabic-Indic digits as numbers."""
    from clothlab.errors import ConfigError
    from clothlab.texfit.fit import parse_crop

    with pytest.raises(ConfigError) as info:
        parse_crop(crop)
    assert info.value.field == "--crop"


def test_infinity_in_fit_json_is_named_by_every_reader(tmp_path, capsys, names_only_stack):
    """fit-btf (and eval, through clothlab.fit.store) read fit.json with the strict JSON reader, which now
    names the dotted field of a NaN / Infinity (before: 'invalid JSON: Infinity is not a finite number')."""
    src = tmp_path / "fits" / "cotton-denim"
    shutil.copytree(REPO / "fits" / "cotton-denim", src)
    text = (src / "fit.json").read_text()
    (src / "fit.json").write_text(text.replace('"wall_time_s": ', '"wall_time_s": -Infinity, "was": ', 1))
    assert main(["fit-btf", str(names_only_stack), str(src), "-o", str(tmp_path / "out")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"{src / 'fit.json'}, field 'wall_time_s'" in line and "-Infinity" in line, line


def _edit_csv(path: Path, column: str, value: str, row: int = 3) -> None:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[row].split(",")
    cells[header.index(column)] = value
    lines[row] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("file, column, value", [
    ("slices.csv", "signed_theta_i", "1e308"), ("slices.csv", "model_R", "1e-320"), ("slices.csv", "phi_o", "-1e308"),
    ("trace.csv", "value", "1e308"), ("trace.csv", "best", "1e-320"), ("trace.csv", "time_s", "-1"),
    ("posterior_samples.csv", "alpha", "nan"),
])
def test_report_refuses_bad_optional_tables_naming_the_column(tmp_path, capsys, file, column, value):
    """Before: a ValueError traceback from matplotlib ('Axis limits cannot be NaN or Inf', 'x and y must have
    the same length') or overflow warnings and exit 0."""
    d = tmp_path / "fits" / "polyester-lining"
    shutil.copytree(REPO / "fits" / "polyester-lining", d)
    _edit_csv(d / file, column, value)
    assert main(["report", str(d), "-o", str(tmp_path / "reports")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert str(d / file) in line and (f"field '{column}'" in line or f"{file}:" in line), line


@pytest.mark.parametrize("key, value, field", [
    ("predictive_slices", '"x"', "predictive_slices"), ("parameters", "[]", "parameters"),
    ("correlation", '{"names": ["a"], "matrix": 5}', "correlation.matrix"),
    ("predictive_slices", '{"bands": {"p5": [[1, NaN]]}}', "predictive_slices.bands.p5.0.1"),
    ("predictive_slices", '{"bands": {"p5": [["a"]]}}', "predictive_slices.bands.p5"),
])
def test_report_refuses_a_malformed_posterior_json_naming_the_field(tmp_path, capsys, key, value, field):
    d = tmp_path / "fits" / "polyester-lining"
    shutil.copytree(REPO / "fits" / "polyester-lining", d)
    post = json.loads((d / "posterior.json").read_text())
    post[key] = "@@"
    (d / "posterior.json").write_text(json.dumps(post, indent=1).replace('"@@"', value))
    assert main(["report", str(d), "-o", str(tmp_path / "reports")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"posterior.json, field '{field}'" in line, line


@pytest.mark.parametrize("force", [[], ["--force"]])
def test_train_surrogate_never_replaces_a_file_with_its_run(tmp_path, capsys, force):
    target = tmp_path / "notes.txt"
    target.write_text("keep me")
    assert main(["train-surrogate", "preset:cotton-denim", "-o", str(target), *force, *TINY_SURROGATE]) == 2
    assert "not a directory" in one_error_line(capsys.readouterr().err)
    assert target.read_text() == "keep me"
