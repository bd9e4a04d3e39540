"""The command line's surface without running the heavy work: help on every option, global -v/-q before or
after the command, one spelling for output options (old spellings hidden but working), warnings once,
logging state restored, bench/check handing their options to the studies API, and the fit summary."""

from __future__ import annotations

import argparse
import ast
import logging
import re
import warnings
from pathlib import Path

import pytest

import clothlab
from clothlab import progress
from clothlab.cli import build_parser, main
from clothlab.cli.options import DEPRECATED, DeprecatedAlias

SECTION_NAMES = ("cli", "speed", "fit", "coverage")
"""Stand-in section names (the studies package defines the real ones)."""


@pytest.fixture
def bench_api(monkeypatch):
    """Stand-ins for clothlab.studies.bench.SECTION_NAMES / run_bench recording their calls."""
    import clothlab.studies.bench as bench

    calls = []

    def run_bench(**kwargs):
        calls.append(kwargs)
        kwargs["emit"]("bench line")
        return 3

    monkeypatch.setattr(bench, "SECTION_NAMES", SECTION_NAMES, raising=False)
    monkeypatch.setattr(bench, "run_bench", run_bench, raising=False)
    return calls


@pytest.fixture
def check_api(monkeypatch):
    import clothlab.studies.stability as stability

    calls = []

    def run_check_command(**kwargs):
        calls.append(kwargs)
        kwargs["emit"]("check line")
        return 1

    monkeypatch.setattr(stability, "run_check_command", run_check_command, raising=False)
    return calls


def _parsers(parser):
    """(name, parser) of the top-level parser and every subcommand parser."""
    out = [("clothlab", parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out += [(f"clothlab {name}", p) for name, p in action.choices.items()]
    return out


def test_every_option_and_positional_has_help(bench_api):
    parser = build_parser()
    parsers = _parsers(parser)
    assert {name.split()[-1] for name, _ in parsers[1:]} == {
        "fit", "select", "report", "eval", "simulate", "import", "fit-btf", "render", "calibrate", "check", "bench",
        "train-surrogate"}
    hidden = []
    for name, p in parsers:
        for action in p._actions:
            label = f"{name} {'/'.join(action.option_strings) or action.dest}"
            assert action.help is not None and str(action.help).strip(), f"{label} has no help"
            if action.help is argparse.SUPPRESS:
                assert isinstance(action, DeprecatedAlias), f"{label} is hidden but not a deprecated alias"
                hidden.append(label)
            if isinstance(action, argparse._SubParsersAction):
                for choice in action._choices_actions:
                    assert choice.help and choice.help.strip(), f"{name} {choice.dest} has no help"
        text = p.format_help()  # help computed when shown (lists of names) formats without error
        shown = set(re.findall(r"--[\w-]+", text))
        for alias in (a for a in p._actions if isinstance(a, DeprecatedAlias)):
            assert not shown & set(alias.option_strings), (name, alias.option_strings)
    assert sorted(hidden) == sorted(["clothlab fit --fits-dir", "clothlab report --out", "clothlab bench --report",
                                     "clothlab bench --figures", "clothlab check --report", "clothlab check --figures"])


def test_lists_of_names_in_help_come_from_their_modules(bench_api):
    from clothlab.colour.chart import METHODS
    from clothlab.models.irawan.quadrature import RULES as QUADRATURE_RULES
    from clothlab.texfit.fit import REFINABLE, TEXTURE_FREE

    helps = {name: p.format_help() for name, p in _parsers(build_parser())}
    flat = {name: " ".join(text.split()) for name, text in helps.items()}
    for command in ("fit", "eval", "simulate"):
        assert all(rule in flat[f"clothlab {command}"] for rule in QUADRATURE_RULES)
    assert all(m in flat["clothlab calibrate"] for m in METHODS)
    assert all(n in flat["clothlab fit-btf"] for n in TEXTURE_FREE + REFINABLE)
    assert ", ".join(SECTION_NAMES) in flat["clothlab bench"]


def test_unknown_choice_is_a_usage_error_listing_the_names(capsys):
    from clothlab.models.irawan.quadrature import RULES as QUADRATURE_RULES

    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args(["eval", "fits/x", "dirs.csv", "--rule", "simpson"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "simpson" in err and all(rule in err for rule in QUADRATURE_RULES)


@pytest.mark.parametrize("argv, expected", [
    (["fit", "a.yaml"], 0),
    (["-q", "fit", "a.yaml"], -1),
    (["fit", "a.yaml", "-q"], -1),
    (["fit", "a.yaml", "--quiet"], -1),  # the old fit --quiet is the global -q
    (["-v", "fit", "a.yaml"], 1),
    (["-v", "fit", "a.yaml", "-vv"], 3),
    (["-v", "fit", "a.yaml", "-q"], -1),  # -q wins
    (["report", "--verbose"], 1),
])
def test_verbosity_before_or_after_the_command(argv, expected):
    from clothlab.cli.main import verbosity

    assert verbosity(build_parser().parse_args(argv)) == expected


def _fake_command(monkeypatch, body):
    """Replace ``clothlab report`` by ``body(args)`` (the parser picks ``run`` up when it is built)."""
    import clothlab.cli.report as report

    monkeypatch.setattr(report, "run", body)


def test_verbosity_sets_log_level_and_progress_then_restores_them(monkeypatch, capsys):
    seen = {}

    def body(args):
        log = progress.get_logger("fit")
        log.debug("a debug record")
        log.info("an info record")
        log.warning("a warning record")
        seen[args.verbose + args.verbose_after, args.quiet or args.quiet_after] = progress.progress_enabled()
        return 0

    _fake_command(monkeypatch, body)
    logger = logging.getLogger("clothlab")
    before = (list(logger.handlers), logger.level, logger.propagate, dict(progress._settings))
    expected = {(): ["an info record", "clothlab: warning: a warning record"],
                ("-q",): ["clothlab: warning: a warning record"],
                ("-v",): ["a debug record", "an info record", "clothlab: warning: a warning record"]}
    for flags, lines in expected.items():
        assert main([*flags, "report"]) == 0
        captured = capsys.readouterr()
        assert captured.err.splitlines() == lines and captured.out == ""
        assert (list(logger.handlers), logger.level, logger.propagate, dict(progress._settings)) == before
    assert seen == {(0, False): True, (0, True): False, (1, False): True}


def test_geometry_warning_reaches_stderr_once_per_message_even_with_quiet(monkeypatch, capsys):
    from clothlab.errors import GeometryWarning

    def body(args):
        for _ in range(3):
            warnings.warn("warp: w sin(umax) >= l", GeometryWarning, stacklevel=1)
        warnings.warn("weft: w sin(umax) >= l", GeometryWarning, stacklevel=1)
        return 0

    _fake_command(monkeypatch, body)
    assert main(["report", "-q"]) == 0
    assert capsys.readouterr().err.splitlines() == ["clothlab: warning: warp: w sin(umax) >= l",
                                                    "clothlab: warning: weft: w sin(umax) >= l"]


@pytest.mark.parametrize("argv, dest", [
    (["fit", "a.yaml", "--fits-dir", "D"], "fits-dir"),
    (["report", "--out", "D"], "out"),
    (["bench", "--report", "D"], "report"),
    (["bench", "--figures", "D"], "figures"),
    (["check", "--report", "D"], "report"),
    (["check", "--figures", "D"], "figures"),
])
def test_old_output_spellings_still_work_and_say_so(argv, dest):
    args = build_parser().parse_args(argv)
    assert args.output == Path("D")
    assert getattr(args, DEPRECATED) == [(f"--{dest}", "-o/--output")]
    assert build_parser().parse_args([*argv[:-2], "-o", "D"]).output == Path("D")
    assert not hasattr(build_parser().parse_args([*argv[:-2], "-o", "D"]), DEPRECATED)


def test_deprecated_spelling_warns_once_on_stderr(monkeypatch, capsys):
    outputs = []
    _fake_command(monkeypatch, lambda args: outputs.append(args.output) or 0)
    assert main(["report", "--out", "old"]) == 0
    assert outputs == [Path("old")]
    assert capsys.readouterr().err.splitlines() == ["clothlab: warning: --out is deprecated; use -o/--output"]
    assert main(["report"]) == 0 and outputs[-1] == Path("reports")  # the default of -o
    assert capsys.readouterr().err == ""


def test_bench_hands_its_options_to_run_bench(bench_api, capsys, tmp_path):
    code = main(["bench", "--quick", "--sections", "fit, cli", "--data", str(tmp_path / "data"),
                 "-o", str(tmp_path / "out"), "--json", str(tmp_path / "b.json")])
    assert code == 3  # run_bench's exit code is the command's
    assert bench_api == [{"sections": ("fit", "cli"), "quick": True, "data_dir": tmp_path / "data",
                          "output": tmp_path / "out", "json_path": tmp_path / "b.json", "emit": print,
                          "merge": False}]
    assert capsys.readouterr().out == "bench line\n"
    assert main(["bench"]) == 3  # without -o / --json: the committed result, updated section by section
    assert bench_api[-1] == {"sections": None, "quick": False, "data_dir": None, "output": None,
                             "json_path": Path("reports") / "bench" / "result.json", "emit": print, "merge": True}


def test_bench_unknown_section_names_the_sections(bench_api, capsys):
    assert main(["bench", "--sections", "fit,nope"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("clothlab: error:") and "nope" in err[0]
    assert all(name in err[0] for name in SECTION_NAMES)
    assert bench_api == []  # nothing ran


def test_check_hands_its_options_to_run_check_command(check_api, capsys, tmp_path):
    assert main(["check", "--full", "--seed", "7", "--data", str(tmp_path), "-o", str(tmp_path / "o")]) == 1
    assert check_api == [{"full": True, "seed": 7, "data_dir": tmp_path, "output": tmp_path / "o",
                          "json_path": None, "emit": print}]
    assert capsys.readouterr().out == "check line\n"
    assert main(["check", "--json", str(tmp_path / "c.json")]) == 1
    assert check_api[-1] == {"full": False, "seed": 0, "data_dir": None, "output": None,
                             "json_path": tmp_path / "c.json", "emit": print}


def test_present_fit_uses_the_results_own_report():
    from clothlab.cli.fit import present_fit

    class Result:
        def fit_report(self):
            return "the report of the result"

    assert present_fit(Result()) == "the report of the result"
    assert present_fit(Result(), saved_to=Path("fits/x")).splitlines() == ["the report of the result",
                                                                           "  saved to fits/x"]


def test_clothlab_error_is_one_line_with_its_exit_code(monkeypatch, capsys):
    from clothlab.errors import ConfigError

    def body(args):
        raise ConfigError("bad value 3; expected >= 4", field="fit.cv_folds")

    _fake_command(monkeypatch, body)
    assert main(["report"]) == ConfigError("x").exit_code == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("clothlab: error:") and "fit.cv_folds" in err[0]


def test_only_the_cli_prints():
    root = Path(clothlab.__file__).parent
    printing = set()
    for path in root.rglob("*.py"):
        rel = path.relative_to(root).as_posix()
        if rel.startswith("cli/"):
            continue
        tree = ast.parse(path.read_text())
        calls = (n for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name))
        if any(n.func.id == "print" for n in calls):
            printing.add(rel)
    assert not printing, sorted(printing)


@pytest.mark.parametrize("argv", [["fit", "x.yaml", "--max-evals", "1_0"], ["fit", "x.yaml", "--seed", "+3"],
                                  ["fit", "x.yaml", "--cv", "\u0665"], ["fit", "x.yaml", "--nodes", "1"],
                                  ["fit", "x.yaml", "--workers", "0"], ["check", "--seed", "-1"],
                                  ["render", "s.yaml", "--spp", "1e3"],
                                  ["train-surrogate", "preset:silk-shantung", "--width", "1_28"],
                                  ["train-surrogate", "preset:silk-shantung", "--budget", "nan"],
                                  ["eval", "f", "d.csv", "--footprint-seed", "x"]])
def test_integer_options_take_plain_decimal_digits_in_range(argv, capsys):
    """Every integer option goes through one strict type (clothlab.cli.options.count_type): no Python-only
    spellings (1_0, +3, non-ASCII digits), no values outside the range; argparse's exit 2 naming the option."""
    from clothlab.cli.main import main

    with pytest.raises(SystemExit) as info:
        main(argv)
    option = next(a for a in argv if a.startswith("--"))
    assert info.value.code == 2 and option in capsys.readouterr().err
