"""The ``>>>`` examples of the public API run as tests (issue 25 item 6): each listed module's docstrings are
collected by doctest and every example must give the output shown.  Examples print rounded or formatted numbers
only, so they pass on any CPU; each runs in well under a second.  A module listed here that loses all its
examples fails too (add new example-bearing modules to the list)."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = (
    "clothlab",
    "clothlab.weave.presets",
    "clothlab.frames",
    "clothlab.io.measurement",
    "clothlab.io.table",
    "clothlab.models.registry",
    "clothlab.fit.metrics",
    "clothlab.fit.nnls",
)
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


@pytest.mark.parametrize("name", MODULES)
def test_examples_in_docstrings(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # examples that touch files make their own temporary directories; none leaks
    module = importlib.import_module(name)
    tests = [t for t in doctest.DocTestFinder(exclude_empty=True).find(module, name) if t.examples]
    assert tests, f"{name} has no >>> example"
    failures = []
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    for test in tests:
        runner.run(test, out=failures.append)
    assert runner.failures == 0, "".join(failures)
    assert list(tmp_path.iterdir()) == []
