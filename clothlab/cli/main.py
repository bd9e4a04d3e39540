"""The ``clothlab`` parser, its global options, dispatch to a subcommand, and errors -> exit codes.

Global options: ``-v/--verbose`` (repeatable: debug messages) and ``-q/--quiet`` (warnings and errors only,
no progress; wins over ``-v``).  Both may be given before or after the command name
(``clothlab -q fit ...`` = ``clothlab fit ... -q``).  They call :func:`clothlab.progress.configure` for the
duration of the command.  Messages (log records, warnings) go to stderr, results to stdout.

Exit codes: 0 success; 1 a command's own failure verdict (e.g. ``check`` found a violation); 2 a user
mistake (:class:`clothlab.errors.ClothlabError`: one line ``clothlab: error: ...``, no traceback) or a usage
error, or a file-system fault (``OSError``: the path and the reason, no traceback); 130 interrupted (Ctrl-C;
a Ctrl-C swallowed by a C callback still stops the command before any result is committed, and a second
Ctrl-C while stopping is ignored).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import sys

from clothlab import __version__
from clothlab.atomic import interrupts_recorded, was_interrupted
from clothlab.cli import (
    bench,
    calibrate,
    check,
    fit,
    fit_btf,
    import_table,
    render,
    report,
    select,
    simulate,
    train_surrogate,
)
from clothlab.cli import eval as eval_
from clothlab.cli.options import DEPRECATED
from clothlab.errors import ClothlabError

SUBCOMMANDS = (fit, select, report, eval_, simulate, import_table, fit_btf, render, calibrate, check, bench,
               train_surrogate)
"""The subcommand modules, in the order ``clothlab --help`` lists them; each has ``add_parser(sub)``
(returning its parser) and ``run(args) -> int``."""

_VERBOSE_HELP = "more messages (-v: debug); before or after the command name"
_QUIET_HELP = "warnings and errors only, no progress; before or after the command name; wins over -v"


def _add_verbosity(parser, dest_suffix: str = "") -> None:
    parser.add_argument("-v", "--verbose", action="count", default=0, dest="verbose" + dest_suffix,
                        help=_VERBOSE_HELP)
    parser.add_argument("-q", "--quiet", action="store_true", dest="quiet" + dest_suffix, help=_QUIET_HELP)


class ClothlabParser(argparse.ArgumentParser):
    """argparse with clothlab's error format: a usage mistake is ONE line ``clothlab: error: ...`` naming the
    option (``field '--nodes': ...``) and exit 2, for the top parser and every subcommand's (argparse makes
    the subparsers of this class); no usage block.  ``clothlab COMMAND --help`` shows the usage.

    Options listed in :attr:`dash_values` (e.g. ``import --columns``) take the next word as their value even
    when it begins with '-' (``--columns -,theta_o,...``: '-' skips a column)."""

    dash_values: frozenset = frozenset()

    def error(self, message: str):
        self.exit(2, f"clothlab: error: {usage_message(message)}\n")

    def parse_known_args(self, args=None, namespace=None):
        if args is not None and self.dash_values:
            args = _join_dash_values(list(args), self.dash_values, self._option_string_actions)
        return super().parse_known_args(args, namespace)


def usage_message(message: str) -> str:
    """argparse's ``argument --nodes: expected ...`` as clothlab's ``field '--nodes': expected ...``, on one
    line (control characters of the user's words shown escaped)."""
    head, sep, rest = message.partition(": ")
    if head.startswith("argument ") and sep:
        message = f"field '{head[len('argument '):]}': {rest}"
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)


def _join_dash_values(args: list, options, known) -> list:
    """``[..., '--columns', '-,x']`` -> ``[..., '--columns=-,x']`` for ``options`` whose value begins with '-'
    (argparse would read it as an option), unless the next word is itself an option of the parser."""
    out, i = [], 0
    while i < len(args):
        word = args[i]
        if word == "--":
            out += args[i:]
            break
        if word in options and i + 1 < len(args) and args[i + 1].startswith("-") and args[i + 1] != "--" and \
                args[i + 1].split("=", 1)[0] not in known:
            out.append(f"{word}={args[i + 1]}")
            i += 2
            continue
        out.append(word)
        i += 1
    return out


def build_parser() -> argparse.ArgumentParser:
    """The whole ``clothlab`` parser (subcommand modules add their own options)."""
    parser = ClothlabParser(
        prog="clothlab",
        description="Measure, fit and report the appearance of woven cloth (Irawan-Marschner, Kang).",
        epilog="Run `clothlab COMMAND --help` for the options of a command.")
    parser.add_argument("--version", action="version", version=f"clothlab {__version__}",
                        help="print the version and exit")
    _add_verbosity(parser)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands",
                                help="the command to run")
    for module in SUBCOMMANDS:
        p = module.add_parser(sub)
        _add_verbosity(p, "_after")  # the same options after the command name (a separate dest, then summed)
        p.set_defaults(run=module.run)
    return parser


def verbosity(args) -> int:
    """-1 quiet, 0 normal, n >= 1 with n times -v (before and after the command name together)."""
    if args.quiet or getattr(args, "quiet_after", False):
        return -1
    return args.verbose + getattr(args, "verbose_after", 0)


def main(argv=None) -> int:
    """The console entry point: parse ``argv`` (default ``sys.argv[1:]``), run the command, return its exit code."""
    with interrupts_recorded():  # from here on a second Ctrl-C while stopping is ignored
        try:
            code = _run(argv)
            if argv is None:  # done: a Ctrl-C from now on (interpreter shutdown) cannot undo or break anything
                signal.signal(signal.SIGINT, signal.SIG_IGN)
            return code
        except Exception:
            if not was_interrupted():
                raise
            # a failure caused by the interrupt itself (a library whose C callback swallowed the
            # KeyboardInterrupt and then failed, e.g. numba's compiler): report the interrupt
            return _interrupted(argv)
        except KeyboardInterrupt:
            return _interrupted(argv)


def _interrupted(argv) -> int:
    print("\nclothlab: interrupted", file=sys.stderr)
    if argv is None:  # the process itself: end it here
        _exit_interrupted()
    return 130


def _exit_interrupted() -> None:
    """End an interrupted process with status 130 at once, after flushing its output.

    Every result was already committed or rolled back by the ``with`` blocks that unwound; skipping the
    interpreter's finalisation avoids its known faults after a Ctrl-C: a SIGINT there kills the process
    (Python resets handlers to SIG_DFL, and re-raises SIGINT at exit when a KeyboardInterrupt went through
    embedded code), and native threads (numba, OpenMP) can crash while they are torn down."""
    import os

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(130)


def _run(argv) -> int:
    """Parse and run; a user mistake or an unforeseen file-system fault -> one line and exit 2."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    log = logging.getLogger("clothlab.cli")
    try:
        with _configured(verbosity(args)), _geometry_warnings_logged():
            for old, new in getattr(args, DEPRECATED, []):
                log.warning(f"{old} is deprecated; use {new}")
            return args.run(args)
    except ClothlabError as exc:
        print(f"clothlab: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:  # a file-system fault the command did not foresee: name the path, no traceback
        where = exc.filename if exc.filename is not None else "a file"
        print(f"clothlab: error: {where}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except RecursionError:
        print("clothlab: error: input nested too deeply to be read", file=sys.stderr)
        return 2


class _Formatter(logging.Formatter):
    """Log records as the user reads them: ``clothlab: warning: ...`` / ``clothlab: error: ...``, plain text
    for information."""

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        if record.levelno >= logging.ERROR:
            return f"clothlab: error: {text}"
        if record.levelno >= logging.WARNING:
            return f"clothlab: warning: {text}"
        return text


def _configured(level: int):
    """:func:`clothlab.progress.configured` with the CLI's ``clothlab: warning:`` formatter."""
    from clothlab.progress import configured

    return configured(level, formatter=_Formatter("%(message)s"))


@contextlib.contextmanager
def _geometry_warnings_logged():
    """A GeometryWarning (e.g. a segment violating w sin(umax) < l, Irawan & Marschner sec. 5.3) reaches the
    user as one ``clothlab: warning: ...`` line per distinct message, however often the model raises it."""
    import warnings

    from clothlab.errors import GeometryWarning

    log = logging.getLogger("clothlab.cli")
    seen = set()
    previous = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, GeometryWarning):
            return previous(message, category, filename, lineno, file, line)
        if str(message) not in seen:
            seen.add(str(message))
            log.warning(str(message))

    with warnings.catch_warnings():
        warnings.simplefilter("always", GeometryWarning)
        warnings.showwarning = show
        yield
