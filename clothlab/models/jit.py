"""numba's ``njit`` with an on-disk cache that never stops an import (issue 27, first run).

Compiled kernels are cached on disk (``cache=True``): the first process compiles each kernel when it is first
called with a new signature, later processes load it (milliseconds).  numba looks for a writable cache
directory next to the source (``__pycache__``), then in the user's cache directory (``~/.cache/numba``, or
``NUMBA_CACHE_DIR`` when set); where there is none - a read-only install run by a user without a writable home -
``numba.njit(cache=True)`` raises RuntimeError ("no locator available") when the module is imported, so no
model could be evaluated at all.  :func:`njit` then compiles the kernel without the cache (in every process)
and logs that once per source file, naming ``NUMBA_CACHE_DIR`` as the remedy; values are the same either way.

Imported lazily with the kernels (numba costs ~0.5 s to import).
"""

from __future__ import annotations

import numba

from clothlab.progress import get_logger

log = get_logger(__name__)

_UNCACHED: set[str] = set()
"""Source files whose kernels run uncached in this process (no writable cache directory)."""


def _compile(fn, options: dict):
    if not options.get("cache"):
        return numba.njit(**options)(fn)
    try:
        return numba.njit(**options)(fn)
    except RuntimeError as exc:
        if "no locator available" not in str(exc):
            raise
    source = fn.__code__.co_filename
    if source not in _UNCACHED:
        _UNCACHED.add(source)
        log.info("numba: no writable cache directory for %s (its __pycache__ and the user cache are read-only): "
                 "its kernels are compiled in every process; set NUMBA_CACHE_DIR to a writable directory to cache "
                 "them", source)
    return numba.njit(**{**options, "cache": False})(fn)


def njit(*args, **options):
    """``numba.njit`` (same arguments), falling back to an uncached kernel when no cache directory is writable
    (module docstring).  Use as ``@njit`` or ``@njit(cache=True, ...)``."""
    if args and callable(args[0]) and len(args) == 1 and not options:
        return _compile(args[0], {})
    if args:
        raise TypeError("njit takes keyword options only (or a function)")
    return lambda fn: _compile(fn, options)


def uncached_sources() -> frozenset[str]:
    """The source files whose kernels could not be cached in this process."""
    return frozenset(_UNCACHED)
