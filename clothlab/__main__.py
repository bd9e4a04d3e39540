"""``python -m clothlab`` and the ``clothlab`` console script: the command line (:mod:`clothlab.cli`).

:func:`run` installs a provisional Ctrl-C handler before the command line is imported, so an interrupt in
the first moments (while modules load, before :func:`clothlab.cli.main.main` installs its own handler)
ends with one line and exit 130, never a traceback.  Nothing can have been written at that point.  Only a
Ctrl-C inside the interpreter's own start-up, before this module runs (a few tens of ms), is beyond reach.
"""

import os
import signal
import sys


def _interrupted_while_starting(signum, frame) -> None:
    os.write(2, b"clothlab: interrupted\n")
    os._exit(130)


def run() -> int:
    """The console entry point: the provisional handler, then :func:`clothlab.cli.main` (which replaces it)."""
    signal.signal(signal.SIGINT, _interrupted_while_starting)
    from clothlab.cli import main

    return main()


if __name__ == "__main__":
    sys.exit(run())
