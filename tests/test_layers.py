"""The layering of the package: the import-linter contracts of pyproject.toml, and no upward import hidden
behind the lazy attributes of ``clothlab/__init__.py``."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

import clothlab

PACKAGE = Path(clothlab.__file__).parent
ROOT = PACKAGE.parent


def _lint_imports() -> Path:
    script = Path(sysconfig.get_path("scripts")) / ("lint-imports.exe" if os.name == "nt" else "lint-imports")
    if not script.exists():
        pytest.fail(f"import-linter is not installed for {sys.executable} (pip install 'clothlab[test]')")
    return script


def _run_contracts(root: Path) -> subprocess.CompletedProcess:
    """lint-imports with ``root``'s pyproject.toml on the package under ``root`` (not an installed copy)."""
    path = [str(root), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(path))
    out = subprocess.run([str(_lint_imports()), "--no-cache", "--no-logo", str(root / "pyproject.toml")],
                         cwd=root, env=env, capture_output=True, text=True, timeout=600)
    assert "Analyzed" in out.stdout, out.stdout + out.stderr  # the contracts were read and the graph built
    return out


def test_import_contracts_are_kept():
    out = _run_contracts(ROOT)
    assert out.returncode == 0, out.stdout + out.stderr


def test_contracts_catch_an_upward_import_and_a_cycle(tmp_path):
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    shutil.copytree(PACKAGE, tmp_path / "clothlab", ignore=shutil.ignore_patterns("__pycache__"))
    with open(tmp_path / "clothlab" / "frames.py", "a", encoding="utf-8") as f:
        f.write("\n\ndef _probe():\n    import clothlab.cli  # noqa: F401\n")
    with open(tmp_path / "clothlab" / "io" / "astm.py", "a", encoding="utf-8") as f:
        f.write("\n\ndef _probe():\n    import clothlab.io.loader  # noqa: F401\n")
    out = _run_contracts(tmp_path)
    assert out.returncode != 0
    assert "clothlab.frames is not allowed to import clothlab.cli" in out.stdout, out.stdout
    assert "No cycles are allowed in clothlab.io" in out.stdout, out.stdout


def _eager_root_names() -> set[str]:
    """Names ``clothlab/__init__.py`` binds at import time (the rest are served lazily by ``__getattr__``)."""
    names = set()
    for node in ast.parse((PACKAGE / "__init__.py").read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign):
            names |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.FunctionDef | ast.ClassDef):
            names.add(node.name)
    return names


def _root_imports(path: Path, root: Path) -> list[tuple[int, str]]:
    """(line, text) of each import of the root package in ``path`` (a file under ``root``):
    ``import clothlab`` or ``from clothlab import name``, absolute or relative."""
    package = path.relative_to(root).with_suffix("").parts[:-1]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, f"import {a.name}") for a in node.names if a.name == "clothlab"]
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else ()
            target = ".".join([*base, *([node.module] if node.module else [])])
            if target == "clothlab":
                found += [(node.lineno, f"from clothlab import {a.name}") for a in node.names]
    return found


def test_root_imports_take_only_eager_names():
    eager = _eager_root_names()
    assert "__version__" in eager and "run_fit" not in eager and "run_fit" in clothlab.__all__
    upward = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == PACKAGE / "__init__.py":
            continue
        for line, text in _root_imports(path, ROOT):
            if text.startswith("import ") or text.rsplit(" ", 1)[-1] not in eager:
                upward.append(f"{path.relative_to(ROOT)}:{line}: {text}")
    assert not upward, ("modules reach other layers through the lazy attributes of clothlab/__init__.py; "
                        "import from the module that defines the name instead:\n" + "\n".join(upward))


def test_root_import_scan_sees_absolute_relative_and_bare_imports(tmp_path):
    probe = tmp_path / "clothlab" / "models" / "probe.py"
    probe.parent.mkdir(parents=True)
    probe.write_text("from clothlab import run_fit\nfrom .. import load_config\nfrom . import base\n"
                     "import clothlab\nimport clothlab.fit\nfrom clothlab.fit import runner\n")
    assert _root_imports(probe, tmp_path) == [
        (1, "from clothlab import run_fit"), (2, "from clothlab import load_config"), (4, "import clothlab")]
