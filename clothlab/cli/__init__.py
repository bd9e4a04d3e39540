"""The ``clothlab`` command line: one module per subcommand (``add_parser(sub)``, ``run(args) -> int``),
assembled and dispatched by :mod:`clothlab.cli.main`.

The CLI parses, calls the domain functions and prints their results; nothing else prints.  Heavy imports
live inside the commands so that ``clothlab --help`` stays fast.  A user mistake
(:class:`clothlab.errors.ClothlabError`) prints one line ``clothlab: error: ...`` and exits with code 2.
"""

from __future__ import annotations

from clothlab.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
