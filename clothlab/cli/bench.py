"""``clothlab bench``: speed and accuracy figures measured side by side in one run
(:func:`clothlab.studies.bench.run_bench`)."""

from __future__ import annotations

from pathlib import Path

from clothlab.cli.options import LazyText, add_output, names_of

SECTION_NAMES = names_of("clothlab.studies.bench", "SECTION_NAMES")


def add_parser(sub):
    p = sub.add_parser("bench", help="speed and accuracy figures, measured side by side in one run",
                       description="Run the benchmark sections and print their tables; with -o also an HTML page "
                                   "and the plots (PNG).")
    p.add_argument("--quick", action="store_true", help="a reduced run (seconds instead of minutes)")
    p.add_argument("--sections", metavar="NAME[,NAME...]", help=LazyText(
        lambda: f"comma-separated subset of the sections {', '.join(SECTION_NAMES())} (default: all)"))
    p.add_argument("--data", type=Path, metavar="DIR",
                   help="directory with the example measurements and fits (default: the shipped examples)")
    add_output(p, "report directory: an HTML page of the figures and the benchmark plots (PNG)", metavar="DIR",
               deprecated=("--report", "--figures"))
    p.add_argument("--json", type=Path, metavar="PATH",
                   help="also write the figures as JSON (default without -o: reports/bench/result.json, the sections "
                        "run replacing theirs there, with the commit, date and code hash measured)")
    return p


def selected_sections(text: str | None) -> tuple[str, ...] | None:
    """The sections named in ``--sections`` (None: all); ConfigError listing the section names for an unknown one."""
    if text is None:
        return None
    from clothlab.errors import ConfigError

    names = SECTION_NAMES()
    sections = tuple(s.strip() for s in text.split(",") if s.strip())
    unknown = [s for s in sections if s not in names]
    if unknown or not sections:
        raise ConfigError(f"unknown bench section(s) {', '.join(unknown) or repr(text)}; choose from "
                          f"{', '.join(names)}", field="--sections")
    return sections


def run(args) -> int:
    from clothlab.studies.bench import DEFAULT_RESULT, run_bench

    default = args.json is None and args.output is None  # the committed result (tests check it is current)
    return run_bench(sections=selected_sections(args.sections), quick=args.quick, data_dir=args.data,
                     output=args.output, json_path=DEFAULT_RESULT if default else args.json, emit=print,
                     merge=default)
