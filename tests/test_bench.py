"""Smoke test of the benchmark sections (small sizes), with properties that must hold."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from clothlab.studies import bench

FITS = Path(__file__).resolve().parents[1] / "fits"


def _checkpoints(root: Path) -> dict:
    """Posterior checkpoints (hidden .npz files) under ``root`` with their modification times.  (Only these: other
    engineers may regenerate the example fits while the tests run.)"""
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in root.rglob("*checkpoint*")}


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


def test_pareto_front_of_known_points():
    times = np.array([1.0, 2.0, 3.0, 1.5, 4.0])
    errors = np.array([1e-1, 1e-3, 1e-2, 1e-1, 1e-5])
    assert bench.pareto_front(times, errors) == [0, 1, 4]


def test_tradeoff_section_small(tmp_path):
    out = bench.tradeoff_section(True, figures_dir=tmp_path, fabrics=("polyester-lining",), n_reference=25,
                                 repeats=1)
    f = out["fabrics"]["polyester-lining"]
    rows = {f"{r['rule']}-{r['nodes']}": r for r in f["rows"]}
    assert set(rows) == set(out["rules"])
    # converged rules agree with the quad reference; coarse ones do not; errors fall with the node count
    assert rows["adaptive-4"]["p80"] < 1e-8
    assert rows["support-16"]["p80"] < 1e-6
    assert rows["trapezoid-81"]["p80"] < rows["trapezoid-3"]["p80"]
    assert all(r["seconds_1575"] > 0 for r in rows.values())
    assert any(r["pareto"] for r in rows.values())
    assert rows["trapezoid-11"]["time_ratio"] == 1.0
    assert f["claim_rules"] == [name for name, r in rows.items() if r["p80"] <= 0.1 * rows["trapezoid-11"]["p80"]
                                and r["time_ratio"] <= 1.0]
    assert (tmp_path / "tradeoff.png").stat().st_size > 10_000
    if f["claim_rules"]:
        assert out["explanation"] is None
    else:  # the report explains, with numbers, why no rule qualifies
        assert "polyester-lining" in out["explanation"] and "filament" in out["explanation"]
        assert f"{1e3 * f['trapezoid11']['seconds_1575']:.2f} ms" in out["explanation"]


def _row(rule, nodes, ms, p80, base_ms=1.0, base_p80=1e-2):
    return {"rule": rule, "nodes": nodes, "seconds_1575": ms / 1e3, "p80": p80, "time_ratio": ms / base_ms,
            "p80_ratio": p80 / base_p80}


def test_tradeoff_explanation_from_the_numbers(capsys):
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
    text = bench.explain_tradeoff(result)
    assert text.startswith("No rule reaches 10x") and "2 of 2 fabrics" in text
    assert "filament-yarn fabrics (polyester-lining)" in text and "staple-yarn fabrics (cotton-denim)" in text
    assert "support-4 at 1.10x its time" in text  # the cheapest 10x rule of the filament group
    assert "up to 5 pieces" in text and "support-4 evaluates 20 integrand nodes" in text and "6.0x its time" in text
    assert "3.00 ms of it is computing and sorting" in text  # support-4 minus split-4
    assert "support-16 at 20.0x" in text and "gauss-81 (7.4x the nodes)" in text
    assert "80 % of trapezoid-11's time" in text and "50 % of trapezoid-11's time" in text  # outside the integrals
    result["explanation"] = text
    bench.print_tradeoff({**result, "fabrics": {}})
    assert "why no rule qualifies" in capsys.readouterr().out
    filament["claim_rules"], staple["claim_rules"] = ["support-4"], ["gauss-81"]
    assert bench.explain_tradeoff(result) is None


def test_paired_timings_alternate_with_the_base():
    calls = []
    base = lambda: calls.append("b")  # noqa: E731
    other = lambda: calls.append("o")  # noqa: E731
    base_best, timed = bench._paired_timings(base, [other, base], rounds=4, min_sample_s=0.0)
    assert timed[1] == (base_best, 1.0)  # the base against itself
    assert timed[0][1] > 0 and base_best > 0
    assert calls[:2] == ["b", "o"]  # warm-up calls
    assert calls[2:] == ["b", "o"] * 4  # strict alternation, at least ``rounds`` pairs


def test_fit_section_times_the_optimisation_alone(no_cv_no_checkpoint):
    """The "one full fit" figure is the optimisation only: no cross-validation, no posterior, no checkpoint, nothing
    written under fits/ (the example fabric.yaml asks for 5-fold CV and a posterior)."""
    f = bench.fit_section(True, max_evals=120)
    assert no_cv_no_checkpoint == []  # no posterior ran
    assert f["cross_validation"] is False and f["posterior"] is False
    assert len(f["free"]) == 6 and f["values"] == 1575 * 3
    assert f["budget"] == 120 and 0 < f["evaluations"] < 1000  # the bench budget, not fabric.yaml's 6,000 x 8
    assert 0 < f["wall_time_s"] <= f["total_wall_time_s"]
    assert f["target_s"] == 20.0 and f["meets_target"] == (f["wall_time_s"] < 20.0)


def test_coverage_section_small(no_cv_no_checkpoint, capsys):
    out = bench.coverage_section(True, fabrics=("polyester-lining",), walkers=12, steps=40, max_steps=40,
                                 check_every=20, optimizer={"max_evals": 150, "starts": 1})
    assert len(no_cv_no_checkpoint) == 1 and no_cv_no_checkpoint[0] is not None  # one posterior, temp checkpoint
    r = out["fabrics"]["polyester-lining"]
    assert r["n_free"] == 6 and out["total"] == 6 and 0 <= out["covered"] <= 6  # truth known for all six
    assert out["fraction"] == out["covered"] / 6 and out["passed"] == (out["fraction"] >= 0.9)
    assert r["steps"] == 40 and r["wall_time_s"] > 0
    bench.print_coverage(out)
    text = capsys.readouterr().out
    assert "polyester-lining" in text and "criterion >= 90 %" in text


def test_posterior_benchmark_samples_once(no_cv_no_checkpoint, monkeypatch):
    """One posterior, under the time cap, checkpointed in a temporary directory (the fit itself samples none)."""
    import clothlab.studies.posterior as posterior

    real = posterior._fabric_config

    def cheap(fabric, variant="noisy"):  # the example's fabric.yaml (CV and posterior on), a small optimiser budget
        from dataclasses import replace

        cfg = real(fabric, variant)
        assert cfg.fit.cv_folds >= 2 and cfg.fit.posterior is not None
        return replace(cfg, fit=replace(cfg.fit, optimizer=replace(cfg.fit.optimizer, max_evals=150, starts=1)))

    monkeypatch.setattr(posterior, "_fabric_config", cheap)
    out = posterior.posterior_benchmark("polyester-lining", max_minutes=0.02, walkers=12, progress=False)
    assert len(no_cv_no_checkpoint) == 1 and no_cv_no_checkpoint[0] is not None
    assert out["stop_reason"] == "max_seconds" and not out["within_limit"]
    assert out["posterior_wall_time_s"] < 10.0


def test_fit_algorithms_section_small(tmp_path):
    from clothlab.fit.optimize import SUPPORTED_GLOBAL, SUPPORTED_LOCAL

    out = bench.fit_algorithms_section(True, figures_dir=tmp_path, fabrics=("polyester-lining",), max_evals=30)
    f = out["fabrics"]["polyester-lining"]
    assert len(f["rows"]) == len(SUPPORTED_GLOBAL) + len(SUPPORTED_LOCAL)
    for r in f["rows"]:
        assert r["evaluations"] <= 30
        assert r["objective"] <= f["start_objective"] * (1 + 1e-12) or "+" in r["algorithm"]
    assert min(r["excess"] for r in f["rows"]) == 0.0
    assert (tmp_path / "fit_algorithms.png").is_file()


def test_run_benchmarks_writes_machine_json(tmp_path):
    path = tmp_path / "bench.json"
    assert bench.run_benchmarks(quick=True, json_path=path, figures_dir=tmp_path, sections=("cli",)) == 0
    data = json.loads(path.read_text())
    assert data["machine"]["cpus"] >= 1 and data["machine"]["versions"]["numpy"]
    assert "help_seconds_best" in data["cli"]
