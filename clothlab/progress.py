"""The one progress and logging layer of clothlab.

Domain code never prints: it logs through :func:`get_logger` (the ``clothlab`` logger hierarchy) and shows
long work through :class:`Progress`.  The CLI calls :func:`configure` once (``-q`` / ``-v``); a library user
(Jupyter) may call it too, otherwise log records go to Python's default handling and progress is silent.

* On a terminal, :class:`Progress` is a tqdm bar; elsewhere (a captured log, CI) it writes one plain line
  every ``PLAIN_INTERVAL`` seconds and one at the end, never carriage returns.
* ``-q`` (verbosity < 0): warnings and errors only, no progress.  ``-v``: debug records too.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import time

ROOT_LOGGER = "clothlab"
PLAIN_INTERVAL = 10.0
"""Seconds between two plain progress lines when the output is not a terminal."""

_settings = {"verbosity": None, "stream": None}


def get_logger(name: str = "") -> logging.Logger:
    """The logger ``clothlab.<name>`` (the package's root logger for an empty name)."""
    name = name.removeprefix("clothlab.").removeprefix("clothlab")
    return logging.getLogger(f"{ROOT_LOGGER}.{name}" if name else ROOT_LOGGER)


def configure(verbosity: int = 0, stream=None, formatter: logging.Formatter | None = None) -> None:
    """Send clothlab's log records to ``stream`` (stderr) as plain lines and enable progress output.

    ``verbosity``: -1 quiet (warnings and errors, no progress), 0 normal (info), >= 1 debug; ``formatter``
    (default: the bare message) formats the records."""
    stream = sys.stderr if stream is None else stream
    logger = logging.getLogger(ROOT_LOGGER)
    for handler in list(logger.handlers):
        if getattr(handler, "_clothlab", False):
            logger.removeHandler(handler)
    handler = logging.StreamHandler(stream)
    handler._clothlab = True
    handler.setFormatter(formatter or logging.Formatter("%(message)s"))
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING if verbosity < 0 else logging.DEBUG if verbosity > 0 else logging.INFO)
    logger.propagate = False
    _settings.update(verbosity=verbosity, stream=stream)


@contextlib.contextmanager
def configured(verbosity: int = 0, stream=None, formatter: logging.Formatter | None = None):
    """:func:`configure` for the duration of a ``with`` block, then the logging and progress state as before
    (a command run in-process, from a test or a notebook, leaves nothing behind)."""
    logger = logging.getLogger(ROOT_LOGGER)
    saved = (list(logger.handlers), logger.level, logger.propagate, dict(_settings))
    configure(verbosity, stream, formatter)
    try:
        yield
    finally:
        for handler in list(logger.handlers):
            logger.removeHandler(handler)
        for handler in saved[0]:
            logger.addHandler(handler)
        logger.setLevel(saved[1])
        logger.propagate = saved[2]
        _settings.update(saved[3])


def progress_enabled() -> bool:
    """True when :func:`configure` was called without ``-q``."""
    return _settings["verbosity"] is not None and _settings["verbosity"] >= 0


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


class Progress:
    """Progress of one stage: ``Progress(total, "start 2/4, global", unit="eval")``, ``update(n)``, ``close()``.

    Silent unless :func:`progress_enabled` (or ``enabled=True``); a tqdm bar on a terminal, plain lines
    elsewhere.  Usable as a context manager."""

    def __init__(self, total: int | None, desc: str, unit: str = "it", *, enabled: bool | None = None):
        self.total, self.desc, self.unit, self.n = total, desc, unit, 0
        self.enabled = progress_enabled() if enabled is None else enabled
        self._bar = None
        self._started = self._last = time.perf_counter()
        stream = _settings["stream"] or sys.stderr
        self._stream = stream
        if self.enabled and _is_terminal(stream):
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=desc, unit=unit, file=stream, leave=False, dynamic_ncols=True)

    def _line(self, final: bool = False) -> str:
        elapsed = time.perf_counter() - self._started
        count = f"{self.n}/{self.total}" if self.total else f"{self.n}"
        share = f" ({100.0 * self.n / self.total:.0f} %)" if self.total else ""
        return f"{self.desc}: {count} {self.unit}{share}, {elapsed:.1f} s{' - done' if final else ''}"

    def update(self, n: int = 1) -> None:
        """Advance by ``n``."""
        self.n += n
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(n)
            return
        now = time.perf_counter()
        if now - self._last >= PLAIN_INTERVAL:
            self._last = now
            self._stream.write(self._line() + "\n")
            self._stream.flush()

    def set_description(self, desc: str) -> None:
        """Rename the stage (e.g. from "start 1/4, global" to "start 1/4, local")."""
        self.desc = desc
        if self._bar is not None:
            self._bar.set_description(desc)

    def close(self) -> None:
        """End the stage (a final plain line when not on a terminal)."""
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        else:
            self._stream.write(self._line(final=True) + "\n")
            self._stream.flush()
        self.enabled = False

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
