"""Test options: long studies are opt-in (``--runslow``); the default run stays fast.

The fuzz families (``tests/test_fuzz_*.py``) carry the ``fuzz`` marker, so ``python -m pytest -m fuzz`` runs
them alone; ``CLOTHLAB_FUZZ_EXAMPLES=N`` draws N cases per family (default 25).  With ``-m fuzz`` (or
``HYPOTHESIS_PROFILE=ci``) the hypothesis profile ``ci`` is loaded: a fixed seed (``derandomize``), no example
database, no deadline, so a run is the same on every machine.  Every run ends with the count of generated
hypothesis cases (docs/robustness.md).
"""

from __future__ import annotations

import collections
import os

import pytest

FUZZ_MODULE_PREFIX = "test_fuzz_"
_COUNTED_PHASES = ("explicit", "reuse", "generate", "target")  # shrinking re-runs cases, it draws none
_CASES: collections.Counter = collections.Counter()  # module -> generated cases that ran the test

try:
    from hypothesis import HealthCheck, settings

    settings.register_profile("ci", derandomize=True, database=None, deadline=None, print_blob=True,
                              suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
except ImportError:  # hypothesis is a test dependency; without it the fuzz modules do not import either
    settings = None


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False,
                     help="also run tests marked slow (full benchmarks, MCMC to convergence, all-fabric studies)")


def pytest_configure(config):
    """Load the ``ci`` hypothesis profile for ``-m fuzz`` or ``HYPOTHESIS_PROFILE=ci`` (before the test modules
    are imported, so the settings they build inherit it)."""
    if settings is None:
        return
    profile = os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if "fuzz" in (config.option.markexpr or "") else None)
    if profile:
        settings.load_profile(profile)


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.module is not None and item.module.__name__.startswith(FUZZ_MODULE_PREFIX):
            item.add_marker(pytest.mark.fuzz)
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow study: run with --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


def _count(module: str, stats: dict) -> None:
    for phase in _COUNTED_PHASES:
        cases = stats.get(f"{phase}-phase", {}).get("test-cases", [])
        _CASES[module] += sum(1 for case in cases if case.get("status") in ("valid", "interesting"))


@pytest.hookimpl(hookwrapper=True, trylast=True)
def pytest_runtest_call(item):
    """Count the hypothesis cases of the test (also of a ``@given`` function defined and run inside it), then
    hand the statistics on to whoever collected them before (hypothesis's own ``--hypothesis-show-statistics``)."""
    try:
        from hypothesis.statistics import collector
    except ImportError:
        yield
        return
    previous = collector.value
    module = item.module.__name__ if item.module is not None else "?"

    def note(stats):
        _count(module, stats)
        if previous is not None:
            previous(stats)

    with collector.with_value(note):
        yield


def pytest_sessionfinish(session):
    """On a pytest-xdist worker: hand this worker's counts to the controller, which prints the summary."""
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:
        workeroutput["hypothesis_cases"] = dict(_CASES)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    """On the pytest-xdist controller: add a finished worker's counts (``-n auto``, pyproject addopts)."""
    _CASES.update(getattr(node, "workeroutput", {}).get("hypothesis_cases", {}))


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not _CASES:
        return
    fuzz = sum(n for m, n in _CASES.items() if m.startswith(FUZZ_MODULE_PREFIX))
    per_module = ", ".join(f"{m} {n}" for m, n in sorted(_CASES.items()) if m.startswith(FUZZ_MODULE_PREFIX))
    terminalreporter.write_line(f"hypothesis: {sum(_CASES.values())} generated cases in all, {fuzz} in the fuzz "
                                f"families ({per_module or 'none run'}); CLOTHLAB_FUZZ_EXAMPLES="
                                f"{os.environ.get('CLOTHLAB_FUZZ_EXAMPLES', '25 (default)')}")
