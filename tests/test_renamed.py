"""The renamed rooms (issue 25 item 5): every old module name still imports, for one release, as the very
module object of its new name, and says so with a DeprecationWarning."""

import importlib
import sys

import pytest

from clothlab.renamed import RENAMED, new_name

SUBMODULES = {"clothlab.neural.surrogate": "clothlab.surrogate.surrogate",
              "clothlab.models.footprint.sat": "clothlab.footprint.sat"}


@pytest.mark.parametrize("old, new", [*RENAMED.items(), *SUBMODULES.items()])
def test_an_old_name_is_the_new_module_and_warns(old, new):
    assert new_name(old) == new
    for name in [m for m in sys.modules if m == old or m.startswith(old + ".")]:
        del sys.modules[name]  # an alias made by an earlier import (the new module stays under its own name)
    with pytest.warns(DeprecationWarning, match="was renamed") as record:
        module = importlib.import_module(old)
    assert any(f"{old} was renamed {new};" in str(w.message) for w in record)
    assert module is importlib.import_module(new)


def test_names_that_were_not_renamed_are_left_alone():
    assert new_name("clothlab.models.neural") is None
    assert new_name("clothlab.neuralx") is None
    assert new_name("clothlab.fit.evaluated") is None
