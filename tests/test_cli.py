"""The command line as a user meets it: exit codes, one-line errors, files left behind."""

from __future__ import annotations

import csv
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from clothlab.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "measurements" / "polyester-lining"


def _project(tmp_path, max_evals=200):
    """A copy of one example with a small budget, writing under tmp_path."""
    shutil.copy(EXAMPLE / "noisy.csv", tmp_path / "noisy.csv")
    text = (EXAMPLE / "fabric.yaml").read_text()
    text, n = re.subn(r"max_evals: \d+, starts: \d+", f"max_evals: {max_evals}, starts: 1, polish: 0", text)
    assert n == 1
    text = "\n".join(line for line in text.splitlines() if not line.startswith(("  cv_folds:", "  posterior:")))
    assert "posterior" not in text and "cv_folds" not in text
    text = text.replace("output: {fits: ../../fits, reports: ../../reports}", "output: {fits: fits, reports: reports}")
    (tmp_path / "fabric.yaml").write_text(text)
    return tmp_path / "fabric.yaml"


def test_import_is_light_and_help_is_fast():
    code = ("import sys, clothlab, clothlab.cli; heavy = [m for m in ('matplotlib', 'colour', 'OpenImageIO', "
            "'emcee', 'nlopt', 'numba', 'scipy') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    help_out = subprocess.run([sys.executable, "-m", "clothlab.cli", "--help"], capture_output=True, text=True)
    assert help_out.returncode == 0 and "fit" in help_out.stdout and "report" in help_out.stdout


def test_fit_report_eval_end_to_end(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = _project(tmp_path)
    assert main(["fit", str(config), "--quiet", "--report"]) == 0
    out = capsys.readouterr().out
    fit_dir = tmp_path / "fits" / "polyester-lining"
    assert (fit_dir / "fit.json").is_file()
    saved = json.loads((fit_dir / "fit.json").read_text())
    assert str(Path("fits") / "polyester-lining") in out  # the summary names the fit directory
    line = next(line for line in out.splitlines() if "warp.umax" in line)  # and shows the saved value
    printed = float(re.search(r"warp\.umax\D*?(\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)", line).group(1))
    assert printed == pytest.approx(saved["parameters"]["warp.umax"]["value"], rel=1e-3)
    assert (tmp_path / "reports" / "polyester-lining" / "index.html").is_file()
    # the same command again refuses to overwrite, with exit code 2 and one line naming --force
    before = (fit_dir / "fit.json").read_bytes()
    assert main(["fit", str(config), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--force" in err[0]
    assert (fit_dir / "fit.json").read_bytes() == before
    # eval of the saved fit at a few directions, with components; values match predictions.csv
    directions = tmp_path / "dirs.csv"
    with (fit_dir / "predictions.csv").open() as fh:
        rows = list(csv.DictReader(fh))[:5]
    with directions.open("w") as fh:
        fh.write("theta_i,phi_i,theta_o,phi_o\n")
        for r in rows:
            fh.write(f"{r['theta_i']},{r['phi_i']},{r['theta_o']},{r['phi_o']}\n")
    out_csv = tmp_path / "values.csv"
    assert main(["eval", str(fit_dir), str(directions), "-o", str(out_csv), "--components"]) == 0
    with out_csv.open() as fh:
        values = list(csv.DictReader(fh))
    for r, v in zip(rows, values, strict=True):
        assert float(v["R"]) == pytest.approx(float(r["model_R"]), rel=1e-8)
        parts = float(v["diffuse_R"]) + float(v["specular_warp_R"]) + float(v["specular_weft_R"])
        assert parts == pytest.approx(float(v["R"]), rel=1e-12)
    # report of several fits -> comparison page
    shutil.copytree(fit_dir, tmp_path / "fits" / "polyester-copy")
    fit_json = json.loads((tmp_path / "fits" / "polyester-copy" / "fit.json").read_text())
    fit_json["name"] = "polyester-copy"
    (tmp_path / "fits" / "polyester-copy" / "fit.json").write_text(json.dumps(fit_json))
    assert main(["report", "--force"]) == 0
    assert (tmp_path / "reports" / "comparison" / "index.html").is_file()


@pytest.mark.parametrize("edit, words", [
    (lambda t: t.replace("metric: relative", "metric: relative\n  colour: red"), ["colour"]),
    (lambda t: t.replace("weft.umax: 20", "weft.umax: 120"), ["weft.umax", "120"]),
    (lambda t: t.replace("preset:polyester-lining", "preset:velvet"), ["velvet"]),
    (lambda t: t.replace("path: noisy.csv", "path: missing.csv"), ["missing.csv"]),
])
def test_bad_fabric_yaml_exits_2_with_one_line(tmp_path, capsys, monkeypatch, edit, words):
    monkeypatch.chdir(tmp_path)
    config = _project(tmp_path)
    config.write_text(edit(config.read_text()))
    assert main(["fit", str(config), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("clothlab: error:")
    for word in words:
        assert word in err[0]
    assert "fabric.yaml" in err[0]
    assert not (tmp_path / "fits").exists() or not any((tmp_path / "fits").iterdir())


def _set_cell(rows, data_row, column, value):
    """Replace one cell of the data_row-th data row (after the header comments and the column header)."""
    first = next(i for i, r in enumerate(rows) if not r.startswith("#")) + 1
    cells = rows[first + data_row].split(",")
    cells[column] = value
    return rows[:first + data_row] + [",".join(cells)] + rows[first + data_row + 1:]


@pytest.mark.parametrize("edit, words", [
    (lambda rows: _set_cell(rows, 10, 5, "nan"), ["nan", "field 'G'"]),
    (lambda rows: _set_cell(rows, 10, 4, "-0.5"), ["negative", "'R'"]),
    (lambda rows: _set_cell(rows, 3, 0, "95"), ["theta_i", "95"]),
    (lambda rows: [r.replace("angle_unit: deg", "angle_unit: gradians") for r in rows], ["gradians"]),
    (lambda rows: [r.replace(",sigma_B", "") for r in rows], ["sigma"]),
])
def test_bad_table_exits_2_naming_the_line(tmp_path, capsys, monkeypatch, edit, words):
    monkeypatch.chdir(tmp_path)
    config = _project(tmp_path)
    table = tmp_path / "noisy.csv"
    rows = table.read_text().splitlines()
    table.write_text("\n".join(edit(rows)) + "\n")
    assert main(["fit", str(config), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "noisy.csv" in err[0]
    for word in words:
        assert word.lower() in err[0].lower(), err[0]
    assert not (tmp_path / "fits").exists() or not any((tmp_path / "fits").iterdir())


def test_simulate_writes_a_loadable_table(tmp_path):
    out = tmp_path / "sim.csv"
    assert main(["simulate", "preset:silk-charmeuse", "-o", str(out), "--kd", "0.2,0.02,0.03",
                 "--noise-mult", "0.05", "--seed", "3"]) == 0
    from clothlab.io.loader import load_measurement

    m = load_measurement(out)
    assert m.n == 1575 and m.provenance["simulated"] is True and m.sigma is not None
    assert main(["simulate", "preset:silk-charmeuse", "-o", str(out)]) == 2  # exists, no --force


def test_python_api_lazy_exports_resolve():
    import clothlab as cl

    for name in cl.__all__:
        assert getattr(cl, name) is not None, name
    with pytest.raises(AttributeError):
        cl.no_such_thing  # noqa: B018


def _posterior_project(tmp_path, steps, max_steps, cv=""):
    config = _project(tmp_path, max_evals=150)
    posterior = f"  posterior: {{walkers: 16, steps: {steps}, max_steps: {max_steps}}}"
    text = config.read_text().replace(
        "  metric: relative", f"  metric: relative\n{posterior}" + (f"\n  cv_folds: {cv}" if cv else ""))
    config.write_text(text)
    return config


def test_fit_with_posterior_and_cross_validation(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = _posterior_project(tmp_path, 100, 200, cv=2)
    assert main(["fit", str(config), "--quiet", "--report"]) == 0
    fit_dir = tmp_path / "fits" / "polyester-lining"
    fit = json.loads((fit_dir / "fit.json").read_text())
    assert fit["cross_validation"]["k"] == 2 and fit["cross_validation"]["held_out"]["p50"] > 0
    posterior = json.loads((fit_dir / "posterior.json").read_text())
    assert set(posterior["parameters"]) >= set(fit["config"]["fit"]["free"])
    assert (fit_dir / "posterior_samples.csv").is_file()
    html = (tmp_path / "reports" / "polyester-lining" / "index.html").read_text()
    assert "Posterior" in html and "cross-validation" in html
    assert (tmp_path / "reports" / "polyester-lining" / "corner.png").is_file()
    assert not list(tmp_path.glob("fits/.*checkpoint*"))  # the checkpoint is gone once the fit is saved


def test_sigint_during_posterior_then_rerun_continues(tmp_path):
    import os
    import signal
    import time

    config = _posterior_project(tmp_path, 1200, 1200)  # checkpoints every 100 steps: interrupted after the first
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "clothlab.cli", "fit", str(config), "--quiet"]
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    checkpoint = tmp_path / "fits" / ".polyester-lining.posterior-checkpoint.npz"
    deadline = time.time() + 240
    while not checkpoint.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert checkpoint.exists(), proc.communicate()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert not (tmp_path / "fits" / "polyester-lining").exists()  # nothing half-written
    done = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    posterior = json.loads((tmp_path / "fits" / "polyester-lining" / "posterior.json").read_text())
    assert posterior["convergence"]["resumed_from_step"] > 0


def test_check_report_page(tmp_path):

    assert main(["check", "-o", str(tmp_path / "check")]) == 0
    page = (tmp_path / "check" / "index.html").read_text()
    assert "non_finite" in page and "reciprocity" in page
    result = json.loads((tmp_path / "check" / "result.json").read_text())
    assert result["totals"]["non_finite"] == 0 and result["totals"]["negative"] == 0


def test_calibrate_corrects_a_synthetic_camera(tmp_path, capsys):
    import numpy as np

    from clothlab.colour.chart import chart_reference

    reference = chart_reference()
    camera = np.array([[0.8, 0.15, 0.05], [0.1, 0.85, 0.05], [0.05, 0.2, 0.75]])
    measured = reference @ camera.T  # a camera mixing the channels; the correction must undo it
    chart = tmp_path / "chart.csv"
    chart.write_text("patch,R,G,B\n" + "".join(f"p{i},{r!r},{g!r},{b!r}\n" for i, (r, g, b) in enumerate(measured)))
    out = tmp_path / "corrected.csv"
    args = ["calibrate", str(chart), "--apply", str(EXAMPLE / "noisy.csv"), "-o", str(out),
            "--report", str(tmp_path / "cal")]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert float(text.split("after mean ")[1].split()[0]) < 0.5
    assert out.is_file() and (tmp_path / "cal" / "index.html").is_file()
    bad = tmp_path / "bad.csv"
    bad.write_text("R,G,B\n0.1,0.2,oops\n")
    assert main(["calibrate", str(bad)]) == 2
    assert "bad.csv:2" in capsys.readouterr().err


def test_simulate_btf_then_fit_btf_from_the_cli(tmp_path, capsys):
    stack = tmp_path / "stack"
    assert main(["simulate", "preset:polyester-lining", "--btf", str(stack), "--btf-directions", "6",
                 "--btf-size", "32", "--btf-tiles", "3", "--btf-offset", "0.2,0.3"]) == 0
    assert (stack / "manifest.yaml").is_file() and len(list(stack.rglob("*.exr"))) == 6
    assert main(["simulate", "preset:polyester-lining", "--btf", str(stack)]) == 2  # exists, no --force
    capsys.readouterr()
    assert main(["fit-btf", str(stack), str(EXAMPLE / "fabric.yaml"), "-o", str(tmp_path / "texfit")]) == 0
    result = json.loads((tmp_path / "texfit" / "texfit.json").read_text())
    from clothlab.texfit.fit import offset_error_cells
    from clothlab.weave.presets import get_preset

    truth = result["truth"]  # the simulator's manifest, read back by fit-btf
    assert truth["offset"] == [0.2, 0.3]
    assert offset_error_cells(result["offset_tiles"], truth["offset"], get_preset("polyester-lining")) < 0.1
    assert abs(result["hwidth"] - truth["hwidth"]) < 0.03 and abs(result["ratio_scale"] - 1) < 0.05


def test_render_command_writes_exr_and_png(tmp_path, capsys):
    scene = ROOT / "measurements" / "scenes" / "receding_plane.yaml"
    stem = tmp_path / "plane"
    assert main(["render", str(scene), "-o", str(stem), "--spp", "1"]) == 0
    assert (tmp_path / "plane.exr").stat().st_size > 0 and (tmp_path / "plane.png").read_bytes()[:4] == b"\x89PNG"
    out = capsys.readouterr().out
    assert "im-lod, 1 spp" in out and "texture model in" in out and str(tmp_path / "plane.exr") in out
    assert main(["render", str(scene), "-o", str(stem)]) == 2  # no silent overwrite
