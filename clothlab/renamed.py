"""Old module names, kept for one release after the rooms were renamed (2026-12-04, issue 25 item 5).

``import clothlab.neural.surrogate`` still works and gives the very module object of the new name
(:mod:`clothlab.surrogate.surrogate`), with a :class:`DeprecationWarning` naming the new one.  The aliases are
resolved by a meta-path finder installed once by ``clothlab/__init__.py``; nothing is loaded twice.

>>> import importlib, warnings
>>> with warnings.catch_warnings(record=True):
...     warnings.simplefilter("always")
...     old = importlib.import_module("clothlab.strict")
>>> old is importlib.import_module("clothlab.untrusted")
True
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

#: old dotted prefix -> new dotted prefix (longest prefix wins)
RENAMED = {
    "clothlab.strict": "clothlab.untrusted",
    "clothlab.fit.evaluate": "clothlab.fit.eval_csv",
    "clothlab.models.footprint": "clothlab.footprint",
    "clothlab.neural.run": "clothlab.surrogate.training_run",
    "clothlab.neural": "clothlab.surrogate",
    "clothlab.report.modelview": "clothlab.report.model_on_grid",
    "clothlab.report.studies": "clothlab.report.study_pages",
}


def new_name(old: str) -> str | None:
    """The current dotted name of a renamed module, or None when ``old`` was not renamed."""
    for prefix in sorted(RENAMED, key=len, reverse=True):
        if old == prefix or old.startswith(prefix + "."):
            return RENAMED[prefix] + old[len(prefix):]
    return None


class _AliasLoader(importlib.abc.Loader):
    def __init__(self, target: str):
        self.target = target

    def create_module(self, spec):
        warnings.warn(f"{spec.name} was renamed {self.target}; the old name goes in the next release",
                      DeprecationWarning, stacklevel=3)
        return importlib.import_module(self.target)

    def exec_module(self, module):
        pass  # the target module is already executed


class _AliasFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        new = new_name(fullname)
        if new is None:
            return None
        return importlib.util.spec_from_loader(fullname, _AliasLoader(new))


def install() -> None:
    """Put the alias finder on ``sys.meta_path`` (idempotent)."""
    if not any(isinstance(f, _AliasFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _AliasFinder())  # before the path finder, which would load a second copy
