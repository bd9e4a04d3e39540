"""Smoke test of the benchmark sections (small sizes), with properties that must hold."""

from __future__ import annotations

import json

import numpy as np

from clothlab import bench


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
    assert f["claim_rules"] == [name for name, r in rows.items() if r["p80"] <= 0.1 * rows["trapezoid-11"]["p80"]
                                and r["seconds_1575"] <= rows["trapezoid-11"]["seconds_1575"]]
    assert (tmp_path / "tradeoff.png").stat().st_size > 10_000


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
