"""The benchmark sections at small sizes, the section registry and the run loop, with properties that must hold."""

from __future__ import annotations

import ast
import importlib
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from clothlab.errors import ConfigError
from clothlab.studies import bench, coverage, full_fit, nlopt_algorithms, quadrature_tradeoff, timing
from clothlab.studies.data import StudyData

REPO = Path(__file__).resolve().parents[1]
FITS = REPO / "fits"
STUDIES = REPO / "clothlab" / "studies"


def _checkpoints(root: Path) -> dict:
    """Posterior checkpoints (hidden .npz files) under ``root`` with their modification times.  (Only these: other
    engineers may regenerate the example fits while the tests run.)"""
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in root.rglob("*checkpoint*")}


@pytest.fixture
def repo_data():
    with StudyData(REPO) as data:
        yield data


@pytest.fixture
def no_cv_no_checkpoint(monkeypatch):
    """Cross-validation must not run; every posterior must checkpoint outside the repository's fits/."""
    import clothlab.fit.crossval
    import clothlab.fit.posterior
    import clothlab.studies.posterior

    def no_cv(*args, **kwargs):
        raise AssertionError("cross-validation ran inside a benchmark fit")

    real = clothlab.fit.posterior.run_posterior
    calls = []

    def spy(*args, checkpoint_path=None, **kwargs):
        calls.append(checkpoint_path)
        assert checkpoint_path is None or FITS.resolve() not in Path(checkpoint_path).resolve().parents
        return real(*args, checkpoint_path=checkpoint_path, **kwargs)

    monkeypatch.setattr(clothlab.fit.crossval, "cross_validate", no_cv)
    monkeypatch.setattr(clothlab.fit.posterior, "run_posterior", spy)
    monkeypatch.setattr(clothlab.studies.posterior, "run_posterior", spy)
    before = _checkpoints(FITS)
    yield calls
    assert _checkpoints(FITS) == before, "a benchmark wrote a posterior checkpoint under fits/"
    for path in calls:
        assert path is None or not Path(path).exists(), "a temporary checkpoint was left behind"


# ------------------------------------------------------------------------------------- registry and run loop

def test_every_section_is_a_module_with_run_and_lines():
    assert len(set(bench.SECTION_NAMES)) == len(bench.SECTION_NAMES) == len(bench.SECTIONS)
    for section in bench.SECTIONS:
        module = importlib.import_module(section.module)
        assert callable(module.run) and callable(module.lines), section.name
        assert section.summary


def test_no_studies_module_prints_or_finds_files_through_its_own_path():
    """Studies return lines and take their data as an argument: no print() call, no __file__."""
    for path in sorted(STUDIES.glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                assert node.func.id != "print", f"{path.name}:{node.lineno} prints"
            if isinstance(node, ast.Name):
                assert node.id != "__file__", f"{path.name}:{node.lineno} uses __file__"


def test_unknown_sections_are_an_error_naming_the_choices():
    with pytest.raises(ConfigError, match="--sections") as info:
        bench.run_bench(sections=("cli", "nope"), quick=True, data_dir=None, output=None, json_path=None,
                        emit=lambda line: None)
    assert "nope" in str(info.value) and all(name in str(info.value) for name in bench.SECTION_NAMES)


def test_a_data_directory_without_measurements_is_an_error_naming_data(tmp_path):
    lines = []
    with pytest.raises(ConfigError, match="--data") as info:
        bench.run_bench(sections=("fit",), quick=True, data_dir=tmp_path, output=None, json_path=None,
                        emit=lines.append)
    assert "has no measurements/" in str(info.value) and lines == []  # before any section ran
    with pytest.raises(ConfigError, match="--data"):
        StudyData(tmp_path / "missing")
    (tmp_path / "measurements").mkdir()
    with StudyData(tmp_path) as data, pytest.raises(ConfigError, match="--data") as info:
        data.config_path("polyester-lining")
    assert "polyester-lining/fabric.yaml not found" in str(info.value)


def test_run_bench_writes_json_report_and_emits_each_section(tmp_path):
    path, report, lines = tmp_path / "bench.json", tmp_path / "report", []
    code = bench.run_bench(sections=("cli",), quick=True, data_dir=None, output=report, json_path=path,
                           emit=lines.append)
    assert code == 0
    data = json.loads(path.read_text())
    assert data["machine"]["cpus"] >= 1 and data["machine"]["versions"]["numpy"]
    assert data["sections"] == ["cli"] and data["section_seconds"]["cli"] > 0
    cli = data["cli"]
    assert 0 < cli["help_seconds_best"] <= cli["help_seconds_median"] < data["section_seconds"]["cli"]
    assert cli["import_pulls"] == []  # import clothlab stays light
    assert any(line.startswith("== cli ==") for line in lines) and lines[-1].startswith("report: ")
    assert (report / "index.html").is_file() and json.loads((report / "result.json").read_text())["cli"] == cli


def test_bench_from_an_empty_directory_regenerates_the_examples(tmp_path, monkeypatch, no_cv_no_checkpoint):
    """No data directory: the examples are regenerated into a temporary directory (removed afterwards), the fit
    section fits them and the saved-fit section says it fell back; nothing is written where it runs."""
    monkeypatch.chdir(tmp_path)
    before = set(Path(tempfile.gettempdir()).glob("clothlab-examples-*"))
    lines = []
    json_path = tmp_path.parent / f"{tmp_path.name}-bench.json"
    assert bench.run_bench(sections=("fit", "models"), quick=True, data_dir=None, output=None, json_path=json_path,
                           emit=lines.append) == 0
    data = json.loads(json_path.read_text())
    assert "no --data" in data["data"]
    fit = data["fit"]
    assert fit["fabric"].startswith("polyester-lining") and 0 < fit["evaluations"] and fit["wall_time_s"] > 0
    assert math.isfinite(fit["p50"]) and 0 < fit["p50"] < fit["p80"] < 1  # the noisy example fits
    rows = data["models"]["rows"]
    assert rows and all(r["parameters"] == "defaults" and "p50" not in r for r in rows)
    assert all(r["pairs_per_second"] > 0 for r in rows)
    assert "--data" in data["models"]["note"] and any("note:" in line for line in lines)
    assert list(tmp_path.iterdir()) == []
    assert set(Path(tempfile.gettempdir()).glob("clothlab-examples-*")) == before


CROSS_CPU_ULPS = 4096
"""Largest last-bit difference, in ulps, allowed between a value computed here and one computed on another CPU
(a regenerated table against the shipped one): round-off of a few hundred operations, far below any noise."""
CROSS_CPU_RTOL = CROSS_CPU_ULPS * np.finfo(np.float64).eps


def test_regenerated_examples_reproduce_the_shipped_measurements():
    """The regenerated tables agree with the repository's measurements to rounding (the same seeded generator)."""
    from clothlab.io.table import read_table

    with StudyData(None) as data:
        fabrics = sorted(p.parent.name for p in data.measurements.glob("*/fabric.yaml"))
        shipped = {p.parent.name for p in (REPO / "measurements").glob("*/fabric.yaml")}
        # the scattered example is made by its own `clothlab simulate --sampling` command (its README), not by
        # the paper-examples generator the studies regenerate
        assert set(fabrics) == shipped - {"scattered-twill"}
        for fabric in fabrics:
            for table in ("clean.csv", "noisy.csv"):
                got = read_table(data.measurements / fabric / table)
                want = read_table(REPO / "measurements" / fabric / table)
                # values within CROSS_CPU_ULPS ulps: the generator is seeded, but numpy's SIMD dispatch and
                # numba's host-CPU code differ in the last bits from one CPU to another
                np.testing.assert_allclose(got.values, want.values, rtol=CROSS_CPU_RTOL, atol=0)
                for angle in ("theta_i", "phi_i", "theta_o", "phi_o"):
                    # nominal angles (simulate.gonio.nominal_angles): the same recorded value on any CPU
                    np.testing.assert_allclose(getattr(got, angle), getattr(want, angle), rtol=0, atol=1e-9)
        root = data.measurements
    assert not root.exists()


# ------------------------------------------------------------------------------------------- timing harness

def test_best_time_is_the_fastest_call():
    seconds = timing.best_time(lambda: time.sleep(0.003), repeats=3, min_sample_s=0.0)
    assert 0.003 <= seconds < 0.03


def test_paired_timings_alternate_with_the_base_and_measure_the_ratio():
    calls = []
    base_best, timed = timing.paired_timings(lambda: calls.append("b"), [lambda: calls.append("o")], rounds=4,
                                             min_sample_s=0.0)
    assert calls[:2] == ["b", "o"]  # warm-up calls
    assert calls[2:] == ["b", "o"] * 4  # strict alternation, at least ``rounds`` pairs

    def base():
        time.sleep(0.002)

    def triple():
        time.sleep(0.006)

    base_best, timed = timing.paired_timings(base, [triple, base], rounds=4, min_sample_s=0.0)
    (t_triple, ratio), (t_base, _) = timed
    assert 0.002 <= base_best <= t_base and 2.0 < ratio < 4.0
    assert t_triple >= ratio * base_best * (1 - 1e-12)  # the ratio is to the base's time in its own pairing


# ------------------------------------------------------------------------------------------------ sections

def test_pareto_front_of_known_points():
    times = np.array([1.0, 2.0, 3.0, 1.5, 4.0])
    errors = np.array([1e-1, 1e-3, 1e-2, 1e-1, 1e-5])
    assert quadrature_tradeoff.pareto_front(times, errors) == [0, 1, 4]


def test_pareto_front_is_the_non_dominated_set():
    rng = np.random.default_rng(3)
    times, errors = rng.uniform(size=40), rng.uniform(size=40)
    times[5], errors[7] = times[4], errors[6]  # ties in time and in error
    front = set(quadrature_tradeoff.pareto_front(times, errors))
    points = list(zip(times, errors, strict=True))
    for i, (t, e) in enumerate(points):
        dominated = any(tj <= t and ej <= e and (tj, ej) != (t, e) for tj, ej in points)
        assert (i in front) == (not dominated)


def test_accuracy_section_small():
    from clothlab.studies import quadrature_accuracy

    rows = quadrature_accuracy.accuracy_study(True, fabrics=("polyester-lining",))
    assert len(rows) == 2 * len(quadrature_accuracy.RULES) and {r["yarn"] for r in rows} == {"warp", "weft"}
    by_rule = {(r["yarn"], f"{r['rule']}-{r['nodes']}"): r for r in rows}
    for yarn in ("warp", "weft"):
        assert by_rule[yarn, "adaptive-4"]["p80"] < 1e-6 and by_rule[yarn, "support-16"]["p80"] < 1e-6
        assert by_rule[yarn, "trapezoid-81"]["p80"] < by_rule[yarn, "trapezoid-3"]["p80"]
    for r in rows:
        assert 0 <= r["p50"] <= r["p80"] and r["seconds_1575"] > 0 and r["quad_warnings"] >= 0
        assert r["quad_seconds_1575"] > r["seconds_1575"]  # the compiled rule beats the quad loop
    text = "\n".join(quadrature_accuracy.lines({"rows": rows}))
    assert "polyester-lining" in text and "trapezoid-11 p80" in text


def test_tradeoff_section_small(tmp_path):
    out = quadrature_tradeoff.tradeoff_study(True, figures_dir=tmp_path, fabrics=("polyester-lining",),
                                             n_reference=25, repeats=1)
    f = out["fabrics"]["polyester-lining"]
    rows = {f"{r['rule']}-{r['nodes']}": r for r in f["rows"]}
    assert set(rows) == set(out["rules"])
    # converged rules agree with the quad reference; coarse ones do not; errors fall with the node count
    assert rows["adaptive-4"]["p80"] < 1e-8
    assert rows["support-16"]["p80"] < 1e-6
    assert rows["trapezoid-81"]["p80"] < rows["trapezoid-3"]["p80"]
    base = rows["trapezoid-11"]
    assert base["seconds_1575"] == f["trapezoid11"]["seconds_1575"]
    for name, r in rows.items():
        assert 0 < r["seconds_1575"] and 0 < r["time_ratio"] < math.inf, name
        # each rule's time is its ratio times the base's time in its own pairing, which is >= the base's fastest
        assert r["seconds_1575"] >= r["time_ratio"] * base["seconds_1575"] * (1 - 1e-12), name
        assert 0 <= r["p50"] <= r["p80"] <= r["max"], name
    # the Pareto flags: exactly the rows no other row dominates (no slower and no less accurate, better in one)
    for name, r in rows.items():
        t, e = r["seconds_1575"], r["p80"]
        beaten = any(o["seconds_1575"] <= t and o["p80"] <= e and (o["seconds_1575"] < t or o["p80"] < e)
                     for o in rows.values())
        assert r["pareto"] == (not beaten), name
    assert f["claim_rules"] == [name for name, r in rows.items() if r["p80"] <= 0.1 * base["p80"]
                                and r["time_ratio"] <= 1.0]
    assert (tmp_path / "tradeoff.png").stat().st_size > 10_000
    if f["claim_rules"]:
        assert out["explanation"] is None
    else:  # the report explains, with numbers, why no rule qualifies
        assert "polyester-lining" in out["explanation"] and "filament" in out["explanation"]
        assert f"{1e3 * f['trapezoid11']['seconds_1575']:.2f} ms" in out["explanation"]
    text = "\n".join(quadrature_tradeoff.lines(out))
    assert "polyester-lining" in text and "trapezoid-11 p80" in text


def _row(rule, nodes, ms, p80, base_ms=1.0, base_p80=1e-2):
    return {"rule": rule, "nodes": nodes, "seconds_1575": ms / 1e3, "p80": p80, "time_ratio": ms / base_ms,
            "p80_ratio": p80 / base_p80}


def test_tradeoff_explanation_from_the_numbers():
    """The paragraph quotes the measured ratios of each yarn group; none when every fabric has a qualifying rule."""
    filament = {"staple": [False, False], "claim_rules": [], "fastest_time_ratio": 0.8, "staple_pieces": {},
                "trapezoid11": {"p80": 1e-2, "seconds_1575": 1e-3},
                "rows": [_row("trapezoid", 3, 0.8, 1e-1), _row("trapezoid", 11, 1.0, 1e-2),
                         _row("support", 4, 1.1, 5e-4), _row("gauss", 41, 1.3, 9e-4)]}
    filament["cheapest_10x"] = {"rule": "support-4", "time_ratio": 1.1}
    staple = {"staple": [True, True], "claim_rules": [], "fastest_time_ratio": 0.5,
              "staple_pieces": {"warp": {"max": 5, "mean": 2.0}, "weft": {"max": 4, "mean": 2.0}},
              "trapezoid11": {"p80": 1e-2, "seconds_1575": 1e-3},
              "rows": [_row("trapezoid", 11, 1.0, 1e-2), _row("support", 4, 6.0, 6e-3), _row("split", 4, 3.0, 6e-3),
                       _row("support", 16, 20.0, 2e-4), _row("gauss", 81, 4.0, 5e-4)]}
    staple["cheapest_10x"] = {"rule": "gauss-81", "time_ratio": 4.0}
    result = {"n_reference": 10, "fabrics": {"polyester-lining": filament, "cotton-denim": staple}}
    text = quadrature_tradeoff.explain_tradeoff(result)
    assert text.startswith("No rule reaches 10x") and "2 of 2 fabrics" in text
    assert "filament-yarn fabrics (polyester-lining)" in text and "staple-yarn fabrics (cotton-denim)" in text
    assert "support-4 at 1.10x its time" in text  # the cheapest 10x rule of the filament group
    assert "up to 5 pieces" in text and "support-4 evaluates 20 integrand nodes" in text and "6.0x its time" in text
    assert "3.00 ms of it is computing and sorting" in text  # support-4 minus split-4
    assert "support-16 at 20.0x" in text and "gauss-81 (7.4x the nodes)" in text
    assert "80 % of trapezoid-11's time" in text and "50 % of trapezoid-11's time" in text  # outside the integrals
    result["explanation"] = text
    assert "  why no rule qualifies (from the numbers above):" in quadrature_tradeoff.lines({**result, "fabrics": {}})
    filament["claim_rules"], staple["claim_rules"] = ["support-4"], ["gauss-81"]
    assert quadrature_tradeoff.explain_tradeoff(result) is None


def test_fit_section_times_the_optimisation_alone(no_cv_no_checkpoint, repo_data):
    """The "one full fit" figure is the optimisation only: no cross-validation, no posterior, no checkpoint, nothing
    written under fits/ (the example fabric.yaml asks for 5-fold CV and a posterior)."""
    f = full_fit.full_fit(True, data=repo_data, max_evals=120)
    assert no_cv_no_checkpoint == []  # no posterior ran
    assert f["cross_validation"] is False and f["posterior"] is False
    assert len(f["free"]) == 6 and f["values"] == 1575 * 3
    assert f["budget"] == 120 and 0 < f["evaluations"] < 1000  # the bench budget, not fabric.yaml's 6,000 x 8
    assert 0 < f["wall_time_s"] <= f["total_wall_time_s"]
    assert f["seconds_per_evaluation"] * f["evaluations"] == pytest.approx(f["wall_time_s"])
    assert "met" in full_fit.lines(f)[1]


def test_coverage_section_small(no_cv_no_checkpoint, repo_data):
    out = coverage.coverage(True, data=repo_data, fabrics=("polyester-lining",), walkers=12, steps=40, max_steps=40,
                            check_every=20, optimizer={"max_evals": 150, "starts": 1})
    assert len(no_cv_no_checkpoint) == 1 and no_cv_no_checkpoint[0] is not None  # one posterior, temp checkpoint
    r = out["fabrics"]["polyester-lining"]
    assert r["n_free"] == 6 and out["total"] == 6  # truth known for all six
    assert out["covered"] == r["n_covered"] == sum(r["covered"].values())
    for name, (lo, hi, truth) in r["intervals"].items():  # covered = the truth inside the 95 % interval
        assert r["covered"][name] == (lo <= truth <= hi)
    assert r["steps"] == 40 and r["wall_time_s"] > 0 and out["reduced"]
    text = "\n".join(coverage.lines(out))
    assert "polyester-lining" in text and "criterion >= 90 %" in text


@pytest.mark.skipif(not all((FITS / f / "posterior.json").is_file() for f in coverage.COVERAGE_FABRICS),
                    reason="the example fits' posteriors are not in this checkout")
def test_saved_coverage_reads_the_example_posteriors():
    out = coverage.saved_coverage(FITS, coverage.COVERAGE_FABRICS)
    assert set(out["fabrics"]) == set(coverage.COVERAGE_FABRICS)
    for name, r in out["fabrics"].items():
        post = json.loads((FITS / name / "posterior.json").read_text())
        for parameter, hit in r["covered"].items():
            e = post["parameters"][parameter]
            assert hit == (e["p2.5"] <= e["truth"] <= e["p97.5"]), (name, parameter)
    assert out["total"] == sum(r["n_free"] for r in out["fabrics"].values())
    assert 0 <= out["covered"] <= out["total"]


def test_full_coverage_without_saved_posteriors_runs_the_reduced_study_and_says_so(monkeypatch, tmp_path):
    calls = []

    def fake_study(fabrics, *, data, **settings):
        calls.append(settings)
        return {"fabrics": {}, "covered": 0, "total": 0, "fraction": math.nan, "settings": settings}

    monkeypatch.setattr(coverage, "coverage_study", fake_study)
    (tmp_path / "measurements").mkdir()
    with StudyData(tmp_path) as data:  # a data directory without fits/
        out = coverage.coverage(False, data=data)
    assert calls == [coverage.REDUCED] and out["reduced"] and "--data" in out["note"]
    out = coverage.coverage(False, data=StudyData(tmp_path), rerun=True)
    assert calls[-1] == coverage.FULL and not out["reduced"]


def test_posterior_benchmark_samples_once(no_cv_no_checkpoint, repo_data):
    """One posterior, under the time cap, checkpointed in a temporary directory (the fit itself samples none)."""
    from clothlab.studies import posterior

    assert repo_data.load_config("polyester-lining").fit.posterior is not None  # the yaml asks for one
    out = posterior.posterior_benchmark("polyester-lining", max_minutes=0.02, data=repo_data, walkers=12,
                                        progress=False, optimizer={"max_evals": 150, "starts": 1})
    assert len(no_cv_no_checkpoint) == 1 and no_cv_no_checkpoint[0] is not None
    assert out["stop_reason"] == "max_seconds" and not out["within_limit"]
    assert out["posterior_wall_time_s"] < 10.0
    assert "polyester-lining" in posterior.lines(out)[0]


def test_fit_algorithms_section_small(tmp_path, repo_data):
    from clothlab.fit.optimize import SUPPORTED_GLOBAL, SUPPORTED_LOCAL

    out = nlopt_algorithms.nlopt_algorithms(True, data=repo_data, figures_dir=tmp_path, fabrics=("polyester-lining",),
                                            max_evals=30)
    f = out["fabrics"]["polyester-lining"]
    assert len(f["rows"]) == len(SUPPORTED_GLOBAL) + len(SUPPORTED_LOCAL)
    for r in f["rows"]:
        assert r["evaluations"] <= 30 and r["excess"] >= 0.0 and r["wall_time_s"] > 0
        assert r["objective"] <= f["start_objective"] * (1 + 1e-12) or "+" in r["algorithm"]
        assert np.all(np.diff(r["trace_best"]) <= 0)  # best so far never rises
    assert (tmp_path / "fit_algorithms.png").is_file()


def test_texture_speed_section():
    from clothlab.studies import texture_speed

    f = texture_speed.texture_speed(quick=True, size=64)
    assert f["size"] == 64 and 0 < f["seconds"] < 60 and f["pixels_per_second"] > 0
    assert f["target_s"] < texture_speed.TARGET_S  # scaled with the pixel count
    assert texture_speed.lines(f)[1].startswith(f"  {f['seconds']:.3f} s")


def test_clothlab_bench_command_runs_the_chosen_sections(tmp_path, capsys):
    from clothlab.cli import main

    path = tmp_path / "bench.json"
    assert main(["bench", "--quick", "--sections", "cli", "--json", str(path), "--report", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert "== cli ==" in out and f"figures written to {path}" in out and (tmp_path / "r" / "index.html").is_file()
    assert json.loads(path.read_text())["sections"] == ["cli"]
    assert main(["bench", "--sections", "cli,bogus"]) == 2
    assert "--sections" in capsys.readouterr().err


def test_report_section_times_both_ways_on_the_same_figures(tmp_path):
    """The section's figures: the same report in one process and in two; the ratio is the two timings'."""
    from test_report import write_synthetic_fit_dir

    from clothlab.studies import report_speed

    fit_dir = write_synthetic_fit_dir(tmp_path / "fits")
    result = report_speed.report_speed(True, fit_dir=fit_dir, runs=1)  # no data: the examples are not needed
    assert set(result["figures"]) >= {"hemispheres.png", "error_histogram.png", "parameters.png"}
    assert result["ratio"] == pytest.approx(result["build_one_process_s"] / result["build_two_processes_s"])
    assert 0 < result["cli_seconds_best"] <= result["cli_seconds_median"]
    assert result["meets_target"] == (result["cli_seconds_median"] <= report_speed.REPORT_TARGET_S)
    text = "\n".join(report_speed.lines(result))
    assert "one process" in text and "two processes" in text and str(fit_dir) in text


def test_posterior_benchmark_runs_each_proposal_on_the_same_target(no_cv_no_checkpoint, repo_data):
    from clothlab.studies import posterior

    out = posterior.posterior_benchmark("polyester-lining", max_minutes=0.02, data=repo_data, walkers=12,
                                        progress=False, optimizer={"max_evals": 150, "starts": 1},
                                        moves=("de-snooker", "stretch"))
    assert len(no_cv_no_checkpoint) == 2 and all(no_cv_no_checkpoint)  # two posteriors, temporary checkpoints
    runs = out["by_moves"]
    assert list(runs) == ["de-snooker", "stretch"] and out["steps"] == runs["de-snooker"]["steps"]
    assert all(r["steps"] >= 1 and r["max_tau"] > 0 and r["cpu_s"] > 0 for r in runs.values())
    text = "\n".join(posterior.lines(out))
    assert "moves de-snooker vs stretch" in text


# ------------------------------------------------------------------ provenance: a result that cannot go stale


def test_committed_bench_result_is_current():
    """reports/bench/result.json was measured on the code it reports: every section's recorded hash of the code it
    measures equals the current one (regenerate with ``clothlab bench --quick`` from the repository root)."""
    result = json.loads((REPO / "reports" / "bench" / "result.json").read_text())
    stale = bench.stale_sections(result)
    assert not stale, f"reports/bench/result.json is stale (run clothlab bench --quick): {stale}"
    assert result["sections"], "the committed result holds no section"
    prov = (result.get("provenance_by_section") or {}).get(result["sections"][0]) or result["provenance"]
    assert prov["commit"] and prov["date"][:4].isdigit()


@pytest.fixture
def toy_section(tmp_path, monkeypatch):
    """A section ``toy`` measuring a module of a temporary package (so its code can be edited here)."""
    pkg = tmp_path / "toy_measured"
    pkg.mkdir()
    (pkg / "__init__.py").write_text('"""A package."""\n')
    (pkg / "core.py").write_text('"""Docstring."""\n\nSCALE = 2.0  # a comment\n\n\ndef f(x):\n    return SCALE * x\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.invalidate_caches()
    section = bench.Section("toy", "clothlab.studies.cli_startup", "toy", ("toy_measured",))
    monkeypatch.setattr(bench, "SECTIONS", bench.SECTIONS + (section,))
    monkeypatch.setattr(bench, "SECTION_NAMES", bench.SECTION_NAMES + ("toy",))
    return pkg / "core.py", section


def test_a_result_goes_stale_when_the_measured_code_changes(toy_section):
    core, section = toy_section
    result = {"sections": ["toy"], "provenance": bench.provenance([section])}
    assert bench.stale_sections(result) == {}  # a fresh result passes
    text = core.read_text()
    core.write_text(text.replace("Docstring.", "Another docstring.").replace("a comment", "another comment"))
    assert bench.stale_sections(result) == {}  # docstrings and comments are not the measured code
    core.write_text(text.replace("SCALE = 2.0", "SCALE = 3.0"))
    stale = bench.stale_sections(result)
    assert set(stale) == {"toy"} and result["provenance"]["sources"]["toy"] in stale["toy"]
    assert bench.stale_sections({"sections": ["toy"]}) == {"toy": "no source hash recorded"}  # an old result


def test_committed_style_result_fails_when_stale_and_passes_when_fresh(toy_section, tmp_path):
    """The CLI's default result, written by a run, passes the staleness check; edited code makes it fail."""
    core, section = toy_section
    path = tmp_path / "result.json"
    bench.run_bench(sections=("cli",), quick=True, data_dir=None, output=None, json_path=path, emit=lambda _: None,
                    merge=True)
    result = json.loads(path.read_text())
    assert bench.stale_sections(result) == {} and result["provenance"]["commit"]
    result["provenance_by_section"]["cli"]["sources"]["cli"] = "0" * 16  # as if measured on other code
    assert set(bench.stale_sections(result)) == {"cli"}


def test_a_run_of_some_sections_keeps_the_others():
    old = {"quick": True, "sections": ["cli", "fit"], "cli": {"a": 1}, "fit": {"b": 2}, "section_seconds": {"cli": 1,
           "fit": 2}, "provenance": {"commit": "old", "date": "d0", "sources": {"cli": "x", "fit": "y"}}}
    new = {"quick": True, "sections": ["fit"], "fit": {"b": 3}, "section_seconds": {"fit": 4},
           "provenance": {"commit": "new", "date": "d1", "sources": {"fit": "z"}}}
    merged = bench.merge_result(old, new)
    assert merged["sections"] == ["cli", "fit"] and merged["cli"] == {"a": 1} and merged["fit"] == {"b": 3}
    assert merged["provenance_by_section"]["cli"]["commit"] == "old"
    assert merged["provenance_by_section"]["fit"]["commit"] == "new"
    assert merged["section_seconds"] == {"cli": 1, "fit": 4}
    full = bench.merge_result({**old, "quick": False}, new)  # a quick run replaces a full one entirely
    assert full["sections"] == ["fit"] and "cli" not in full


def test_clothlab_bench_writes_the_default_result_in_the_working_directory(tmp_path, monkeypatch, capsys):
    from clothlab.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--quick", "--sections", "cli"]) == 0
    result = json.loads((tmp_path / "reports" / "bench" / "result.json").read_text())
    assert result["sections"] == ["cli"] and bench.stale_sections(result) == {}
    assert "figures written to reports/bench/result.json" in capsys.readouterr().out
