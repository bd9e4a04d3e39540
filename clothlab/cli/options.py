"""Option builders shared by the subcommands: the output option, hidden deprecated spellings, the
quadrature overrides, and lists of names read from the module that owns them only when they are needed.

Building the parser imports nothing heavy: a list such as the quadrature rules or the bench sections is
imported when an option is given (:func:`one_of`) or when its help is shown (:class:`LazyText`).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from importlib import import_module
from pathlib import Path

DEPRECATED = "_deprecated_options"
"""Namespace attribute listing (old spelling, new spelling) of every deprecated option given."""


def names_of(module: str, attribute: str) -> Callable[[], Sequence[str]]:
    """A function returning ``module.attribute`` (a tuple of names), imported when called."""
    return lambda: tuple(getattr(import_module(module), attribute))


class LazyText:
    """Help text computed when it is shown, e.g. from a list of names in a module that is slow to import.

    argparse formats help as ``help % params``; this object supports that and ``strip()``."""

    def __init__(self, make: Callable[[], str]):
        self._make = make

    def __str__(self) -> str:
        return self._make()

    def strip(self) -> str:
        return str(self).strip()

    def __mod__(self, params) -> str:
        return str(self) % params


def one_of(names: Callable[[], Sequence[str]], what: str) -> Callable[[str], str]:
    """An argparse ``type`` accepting one of ``names()`` (a usage error listing them otherwise)."""

    def check(text: str) -> str:
        allowed = names()
        if text not in allowed:
            raise argparse.ArgumentTypeError(f"unknown {what} {text!r}; choose one of {', '.join(allowed)}")
        return text

    check.__name__ = what.replace(" ", "_")
    return check


class DeprecatedAlias(argparse.Action):
    """A hidden old spelling of an option: stores into the new option's ``dest`` and records itself under
    :data:`DEPRECATED` so that the command can say which spelling to use instead."""

    def __init__(self, option_strings, dest, *, new: str, nargs=None, **kwargs):
        kwargs["help"] = argparse.SUPPRESS
        super().__init__(option_strings, dest, nargs=nargs, default=argparse.SUPPRESS, **kwargs)
        self.new = new

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        given = list(getattr(namespace, DEPRECATED, []))
        setattr(namespace, DEPRECATED, [*given, (option_string, self.new)])


def number_type(low: float | None = None, high: float | None = None):
    """An argparse type: a finite number in plain decimal notation (no ``nan``, ``inf``, ``1_0``) in
    [low, high]."""
    def parse(text: str) -> float:
        import argparse

        from clothlab.errors import ConfigError
        from clothlab.untrusted import parse_number

        try:
            value = parse_number(text, error=ConfigError)
        except ConfigError as exc:
            raise argparse.ArgumentTypeError(exc.detail) from None
        if (low is not None and value < low) or (high is not None and value > high):
            lo = "-inf" if low is None else f"{low:g}"
            hi = "inf" if high is None else f"{high:g}"
            raise argparse.ArgumentTypeError(f"{value:g} is outside [{lo}, {hi}]")
        return value

    return parse


def count_type(low: int, high: int):
    """An argparse type: an integer in plain decimal digits (no ``1_0``, ``+``, non-ASCII digits) in [low, high]."""
    def parse(text: str) -> int:
        import argparse
        import re

        stripped = text.strip()
        if not re.fullmatch(r"-?[0-9]{1,30}", stripped):
            raise argparse.ArgumentTypeError(f"expected an integer in decimal digits, got {text!r}")
        value = int(stripped)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{value} is outside [{low}, {high}]")
        return value

    return parse


def add_output(parser, help: str, *, deprecated: Sequence[str] = (), **kwargs) -> None:
    """``-o/--output`` (a Path) with ``help``; ``deprecated`` old spellings stay as hidden aliases."""
    kwargs.setdefault("type", Path)
    parser.add_argument("-o", "--output", help=help, **kwargs)
    for old in deprecated:
        parser.add_argument(old, dest="output", type=kwargs["type"], metavar=kwargs.get("metavar"),
                            action=DeprecatedAlias, new="-o/--output")


def _quadrature_nodes(text: str) -> int:
    """``--nodes``: an integer in the range :class:`~clothlab.models.irawan.quadrature.Quadrature` accepts (its
    NODES_RANGE, read when the option is given: the one validation of yaml and API)."""
    low, high = import_module("clothlab.models.irawan.quadrature").NODES_RANGE
    return count_type(low, high)(text)


def add_quadrature_overrides(parser) -> None:
    """``--rule`` and ``--nodes``: the quadrature of the model, overriding fabric.yaml."""
    rules = names_of("clothlab.models.irawan.quadrature", "RULES")
    parser.add_argument("--rule", type=one_of(rules, "quadrature rule"),
                        help=LazyText(lambda: f"quadrature rule, one of {', '.join(rules())} "
                                              "(overrides fabric.yaml model.quadrature.rule)"))
    parser.add_argument("--nodes", type=_quadrature_nodes,
                        help="quadrature nodes (per piece for the support and adaptive rules; "
                                                  "overrides fabric.yaml model.quadrature.nodes)")


def add_force(parser, what: str) -> None:
    """``--force``: replace an existing ``what`` (nothing is overwritten without it)."""
    parser.add_argument("--force", action="store_true", help=f"replace existing {what}")



def add_parallel(parser, what: str) -> None:
    """``--workers N`` (a Dask LocalCluster of N worker processes) and ``--scheduler ADDRESS`` (an existing
    Dask cluster; default ``$DASK_SCHEDULER_ADDRESS``) for ``what``; without either, in-process.  Dask is the
    optional extra ``clothlab[dask]`` (docs/parallel.md); :func:`runner_of` builds the runner."""
    group = parser.add_argument_group("parallel execution (docs/parallel.md; needs pip install \"clothlab[dask]\")")
    group.add_argument("--workers", type=count_type(1, 1024), metavar="N",
                       help=f"run {what} on a local Dask cluster of N worker processes (1 thread each)")
    group.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                       help=f"run {what} on the existing Dask cluster at this scheduler address (default: "
                            "$DASK_SCHEDULER_ADDRESS when set, else in-process)")


def runner_of(args):
    """The :class:`clothlab.parallel.Runner` of :func:`add_parallel`'s options (close it when done)."""
    from clothlab.parallel import make_runner

    return make_runner(workers=args.workers, scheduler=args.scheduler)


def parallel_requested(args) -> bool:
    """True when :func:`add_parallel`'s options (or ``$DASK_SCHEDULER_ADDRESS``) ask for a Dask runner; then
    Dask must be installed (else the one-line error naming the extra, before any work).  The options are
    checked here, before any work and whether or not the command then distributes anything: ``--workers``
    with ``--scheduler`` is refused, and a malformed address is refused naming where it came from (the
    option or the environment variable)."""
    from clothlab.parallel import require_dask
    from clothlab.parallel.runner import resolve_options

    workers, address = resolve_options(args.workers, args.scheduler)
    requested = workers is not None or address is not None
    if requested:
        require_dask()
    return requested
