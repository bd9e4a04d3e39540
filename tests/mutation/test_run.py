"""The mutation sweep's own checks (opt-in, ``--runslow``: the default suite never runs the sweep).

Every mutation site of tests/mutation/run.py exists once in the working tree, and one mutant is really applied to
a copy, killed by its tests, and the checkout left untouched."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def _sweep_module():
    spec = importlib.util.spec_from_file_location("clothlab_mutation_run", HERE / "run.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the class is made
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_every_mutation_site_is_found_once():
    run = _sweep_module()
    assert run.check_sites(run.MUTANTS) == []
    assert len({m.name for m in run.MUTANTS}) == len(run.MUTANTS)
    assert {m.module for m in run.MUTANTS} == set(run.TESTS)


@pytest.mark.slow
def test_one_mutant_is_killed_in_a_copy(capsys):
    run = _sweep_module()
    strict = (ROOT / "clothlab" / "untrusted.py").read_bytes()
    assert run.main(["--only", "strict-limit-65"]) == 0
    out = capsys.readouterr().out
    assert "strict-limit-65" in out and "killed" in out and "mutation score: 1 / 1 = 100 %" in out
    assert (ROOT / "clothlab" / "untrusted.py").read_bytes() == strict  # the checkout is never touched
