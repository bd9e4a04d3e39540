"""The corpus of bad inputs (tests/fuzz_corpus/): each is refused through the CLI with exit 2 and one line
naming the file, never a traceback, an accepted bad value, or unbounded time and memory.

File names are ``<family>--<case>.<ext>``; the family decides the command that reads the file:
``table`` (a fabric.yaml fitting it), ``fabric`` (``clothlab fit``), ``weave`` (a fabric.yaml using it),
``scene`` (``clothlab render``), ``chart`` (``clothlab calibrate``), ``btf`` (a BTF manifest); ``valid--``
files must be accepted.  Fit directories given to ``report`` / ``eval`` are derived from a shipped fit.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from clothlab.cli.main import main

CORPUS = Path(__file__).parent / "fuzz_corpus"
REPO = Path(__file__).parent.parent
OK_TABLE = """\
# clothlab-table: 1
# angle_unit: deg
# quantity: brdf
# azimuth_zero: weft
# azimuth_sense: ccw
# channels: [R, G, B]
theta_i,phi_i,theta_o,phi_o,R,G,B
10,30,22,55,0.1,0.2,0.3
20,60,39,100,0.11,0.2,0.3
30,90,56,145,0.12,0.2,0.3
"""
FIT_YAML = """\
name: corpus
measurement: {{path: {table}}}
model: {{kind: irawan, weave: {weave}}}
fit: {{free: [alpha], optimizer: {{global: null, local: LN_BOBYQA, max_evals: 2}}}}
output: {{fits: fits, reports: reports}}
"""


def cases(prefix):
    return sorted(p.name for p in CORPUS.glob(f"{prefix}--*"))


def run_cli(argv, capsys):
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    return rc, err


def assert_refused(rc, err, named):
    assert rc == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("clothlab: error: "), err
    assert "Traceback" not in err
    assert str(named) in lines[0], (named, lines[0])


@pytest.fixture
def work(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "ok.csv").write_text(OK_TABLE)
    return tmp_path


@pytest.mark.parametrize("name", cases("table"))
def test_bad_tables_are_refused_naming_file_and_line(work, capsys, name):
    table = work / name
    shutil.copy(CORPUS / name, table)
    (work / "fabric.yaml").write_text(FIT_YAML.format(table=name, weave="preset:cotton-denim"))
    rc, err = run_cli(["fit", work / "fabric.yaml"], capsys)
    assert_refused(rc, err, table)
    assert not (work / "fits" / "corpus").exists()


def test_the_nan_reproducer_names_file_line_and_column(work, capsys):
    shutil.copy(CORPUS / "table--denormal.csv", work / "t.csv")
    (work / "fabric.yaml").write_text(FIT_YAML.format(table="t.csv", weave="preset:cotton-denim"))
    rc, err = run_cli(["fit", work / "fabric.yaml"], capsys)
    line = next(i for i, text in enumerate((work / "t.csv").read_text().splitlines(), 1) if "1e-320" in text)
    assert_refused(rc, err, f"{work / 't.csv'}:{line}, field 'R'")


def test_a_utf8_bom_table_is_read_with_format_auto(tmp_path):
    from clothlab.io.loader import load_measurement

    shutil.copy(CORPUS / "valid--bom-auto.csv", tmp_path / "t.csv")
    m = load_measurement(tmp_path / "t.csv", "auto")
    assert m.n == 8 and m.channels == ("R", "G", "B")


@pytest.mark.parametrize("name", cases("fabric"))
def test_bad_fabric_yaml_is_refused_before_any_fit(work, capsys, monkeypatch, name):
    import clothlab.fit.runner as runner

    if "dev-zero" not in name:  # that configuration is fine: its measurement is refused when the fit loads it
        monkeypatch.setattr(runner, "run_fit", lambda *a, **k: pytest.fail("a bad fabric.yaml was accepted"))
    shutil.copy(CORPUS / name, work / name)
    rc, err = run_cli(["fit", work / name], capsys)
    assert_refused(rc, err, "/dev/zero" if "dev-zero" in name else work / name)


@pytest.mark.parametrize("name", cases("weave"))
def test_bad_weave_files_are_refused_naming_file_and_line(work, capsys, name):
    shutil.copy(CORPUS / name, work / name)
    (work / "fabric.yaml").write_text(FIT_YAML.format(table="ok.csv", weave=name))
    rc, err = run_cli(["fit", work / "fabric.yaml"], capsys)
    assert_refused(rc, err, work / name)
    assert ":" in err.split(name, 1)[1][:3]  # a line number follows the file name


@pytest.mark.parametrize("name", cases("scene"))
def test_bad_scenes_are_refused_naming_file_and_field(work, capsys, name):
    shutil.copy(CORPUS / name, work / name)
    rc, err = run_cli(["render", work / name, "-o", work / "out"], capsys)
    assert_refused(rc, err, work / name)
    assert "field '" in err
    assert not list(work.glob("out*"))


@pytest.mark.parametrize("name", cases("chart"))
def test_bad_charts_are_refused_naming_the_file(work, capsys, name):
    shutil.copy(CORPUS / name, work / name)
    rc, err = run_cli(["calibrate", work / name, "-o", work / "corrected.csv"], capsys)
    assert_refused(rc, err, work / name)


def test_a_manifest_mapping_one_image_to_two_angle_sets_is_refused(tmp_path):
    from clothlab.btf.names import read_manifest
    from clothlab.errors import InputError

    name = "btf--one-image-two-angle-sets.csv"
    shutil.copy(CORPUS / name, tmp_path / name)
    with pytest.raises(InputError, match="listed twice") as info:
        read_manifest(tmp_path / name)
    assert info.value.line == 4 and info.value.field == "file"


# ---------------------------------------------------------------------------------------------------------
# Fit directories given to report / eval

def _mutations():
    def fit_json(edit):
        def apply(d):
            data = json.loads((d / "fit.json").read_text())
            edit(data)
            (d / "fit.json").write_text(json.dumps(data))
        return apply

    def set_coefficient(data):
        name = next(iter(data["coefficients"]))
        channel = next(iter(data["coefficients"][name]))
        data["coefficients"][name][channel] = None

    def predictions(edit):
        def apply(d):
            lines = (d / "predictions.csv").read_text().splitlines()
            lines = edit(lines)
            (d / "predictions.csv").write_text("\n".join(lines) + "\n")
        return apply

    def cell(value):
        def edit(lines):
            fields = lines[3].split(",")
            fields[4] = value
            lines[3] = ",".join(fields)
            return lines
        return edit

    return {
        "empty fit.json": ("fit.json", lambda d: (d / "fit.json").write_text("")),
        "zero-byte predictions": ("predictions.csv", lambda d: (d / "predictions.csv").write_text("")),
        "non-numeric prediction": ("predictions.csv", predictions(cell("abc"))),
        "empty prediction cell": ("predictions.csv", predictions(cell(""))),
        "nan prediction": ("predictions.csv", predictions(cell("nan"))),
        "null coefficient": ("fit.json", fit_json(set_coefficient)),
        "missing coefficients": ("fit.json", fit_json(lambda data: data.pop("coefficients"))),
        "string parameter": ("fit.json", fit_json(
            lambda data: data["parameters"][next(iter(data["parameters"]))].update(value="0.5"))),
        "missing fit.json": ("fit.json", lambda d: (d / "fit.json").unlink()),
        "deep fit.json": ("fit.json", lambda d: (d / "fit.json").write_text("[" * 100000 + "]" * 100000)),
    }


@pytest.mark.parametrize("command", ["report", "eval"])
@pytest.mark.parametrize("case", list(_mutations()))
def test_broken_fit_directories_are_refused_naming_the_file(work, capsys, command, case):
    culprit, mutate = _mutations()[case]
    fit_dir = work / "fits" / "lining"
    shutil.copytree(REPO / "fits" / "polyester-lining", fit_dir)
    mutate(fit_dir)
    if command == "eval" and culprit == "predictions.csv":
        pytest.skip("eval does not read predictions.csv")
    (work / "dirs.csv").write_text("theta_i,phi_i,theta_o,phi_o\n30,0,30,180\n")
    argv = (["report", fit_dir, "-o", work / "reports"] if command == "report"
            else ["eval", fit_dir, work / "dirs.csv", "-o", work / "out.csv"])
    rc, err = run_cli(argv, capsys)
    assert_refused(rc, err, fit_dir / culprit)
    assert not (work / "out.csv").exists() and not (work / "reports" / "lining").exists()


# ---------------------------------------------------------------------------------------------------------
# Bounded time and memory (a child process under resource limits)

BOUNDED = r"""
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))
resource.setrlimit(resource.RLIMIT_CPU, (60, 60))
from clothlab.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("name", ["fabric--billion-laughs.yaml", "fabric--dev-zero.yaml", "fabric--deep-nesting.yaml",
                                  "fabric--5000-digits.yaml"])
def test_hostile_files_are_refused_within_memory_and_cpu_limits(tmp_path, name):
    shutil.copy(CORPUS / name, tmp_path / name)
    (tmp_path / "ok.csv").write_text(OK_TABLE)
    done = subprocess.run([sys.executable, "-c", BOUNDED, "fit", name], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300, env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr and done.stderr.startswith("clothlab: error: ")
