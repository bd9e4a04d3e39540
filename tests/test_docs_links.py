"""The docs cite only things that exist: module paths, dotted names, files and relative links.

A reference that no longer resolves (a module renamed, a guide split, a note moved) fails here with the doc,
its line and the reference.  Checked in README.md and every docs/*.md:

- a path under ``clothlab/``, ``docs/``, ``tests/``, ``measurements/``, ``fits/`` or ``reports/`` (templates
  such as ``fits/<name>/`` or globs such as ``measurements/*/kang.yaml`` are skipped);
- a backticked path ending in ``.py`` that has a folder (``fit/problem.py``: under clothlab/ or the root);
- a dotted name ``clothlab.a.b.c``: its longest prefix must be a module or package file of the new layout
  (an old name that only imports through ``clothlab.renamed`` does not count) and the next part, if any, a
  name defined or imported at the top level of that module;
- a markdown link ``[text](relative/path#anchor)``: the file must exist.

docs/notes/ pages are logs of past sessions: only their links and doc references are checked (their module
references may name the code as it was when they were measured).
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "clothlab"
GUIDES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
NOTES = sorted((ROOT / "docs" / "notes").glob("*.md"))

PATH_RE = re.compile(r"(?<![\w/.\-])((?:clothlab|docs|tests|measurements|fits|reports)/[A-Za-z0-9_./\-]*)")
BACKTICK_PY_RE = re.compile(r"`([A-Za-z0-9_\-]+(?:/[A-Za-z0-9_\-]+)+\.py)`")
DOTTED_RE = re.compile(r"(?<![\w.\-/])clothlab((?:\.[A-Za-z_]\w*)+)")
LINK_RE = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
TEMPLATE_NEXT = set("<*{$")
DOC_PREFIXES = ("docs/",)
OUTPUT_PREFIXES = ("fits/", "reports/")
PLACEHOLDER_RE = re.compile(r"[A-Z][A-Z_]+")


def _lines(path: Path):
    yield from enumerate(path.read_text(encoding="utf-8").splitlines(), 1)


def _path_problem(token: str, following: str, in_code: bool) -> str | None:
    """Why a repository path cited in a doc does not resolve, or None."""
    if following in TEMPLATE_NEXT:
        return None                       # a template (fits/<name>/) or a glob (measurements/*/x.yaml)
    token = token.rstrip(".,;:")
    if not token or token.endswith("..") or "//" in token:
        return None
    if any(PLACEHOLDER_RE.fullmatch(part) for part in re.split(r"[/.]", token)):
        return None                       # clothlab/models/neural/data/NAME.npz
    if in_code and token.startswith(OUTPUT_PREFIXES):
        return None                       # a command's output (clothlab fit ... -> fits/x) in a code block
    if (ROOT / token).exists():
        return None
    return f"no such file or folder: {token}"


@cache
def _module_file(dotted: str) -> Path | None:
    """The file of a module of the current layout (clothlab.a.b), or None."""
    parts = dotted.split(".")[1:]
    base = PACKAGE.joinpath(*parts)
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    if base.with_suffix(".py").is_file():
        return base.with_suffix(".py")
    return None


@cache
def _top_level_names(path: Path) -> frozenset[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                for sub in ast.walk(target):
                    if isinstance(sub, ast.Name):
                        names.add(sub.id)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            for alias in node.names:
                names.add((alias.asname or alias.name).split(".")[0])
        elif isinstance(node, (ast.If, ast.Try)):
            for sub in ast.walk(node):
                if isinstance(sub, (ast.FunctionDef, ast.ClassDef)):
                    names.add(sub.name)
                elif isinstance(sub, (ast.Import, ast.ImportFrom)):
                    for alias in sub.names:
                        names.add((alias.asname or alias.name).split(".")[0])
                elif isinstance(sub, ast.Name) and isinstance(sub.ctx, ast.Store):
                    names.add(sub.id)
    if "__getattr__" in names:            # a lazy package: its names are listed in __all__ or a table
        names.update(re.findall(r"[\"'](\w+)[\"']", path.read_text(encoding="utf-8")))
    return frozenset(names)


def _dotted_problem(dotted: str) -> str | None:
    """Why ``clothlab.a.b.c`` does not resolve in the current layout, or None."""
    parts = dotted.split(".")
    for end in range(len(parts), 0, -1):
        module = ".".join(parts[:end])
        path = _module_file(module) if end > 1 else PACKAGE / "__init__.py"
        if path is None:
            continue
        if end == len(parts):
            return None
        attribute = parts[end]
        if attribute in _top_level_names(path) or _module_file(f"{module}.{attribute}"):
            return None
        return f"{module} defines no {attribute!r} (cited as {dotted})"
    return f"no module {dotted}"


def _problems(path: Path, *, modules: bool) -> list[str]:
    found = []
    where = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path.name
    in_code = False
    for number, line in _lines(path):
        if line.lstrip().startswith("```"):
            in_code = not in_code
            continue
        for match in PATH_RE.finditer(line):
            token = match.group(1)
            if not modules and not token.startswith(DOC_PREFIXES):
                continue
            following = line[match.end():match.end() + 1]
            problem = _path_problem(token, following, in_code)
            if problem:
                found.append(f"{where}:{number}: {problem}")
        if modules:
            for match in BACKTICK_PY_RE.finditer(line):
                token = match.group(1)
                if token.startswith(("clothlab/", "tests/")):
                    continue              # checked above
                if not ((PACKAGE / token).is_file() or (ROOT / token).is_file()):
                    found.append(f"{where}:{number}: no such module file: {token} (under clothlab/ or the root)")
            for match in DOTTED_RE.finditer(line):
                dotted = "clothlab" + match.group(1)
                problem = _dotted_problem(dotted)
                if problem:
                    found.append(f"{where}:{number}: {problem}")
        for match in LINK_RE.finditer(line):
            target = match.group(1)
            if re.match(r"^[a-z]+:", target) or target.startswith("#"):
                continue                  # a URL or an anchor on the same page
            target = target.split("#", 1)[0]
            if target and not (path.parent / target).exists():
                found.append(f"{where}:{number}: dangling link: {match.group(1)}")
    return found


@pytest.mark.parametrize("path", GUIDES, ids=lambda p: str(p.relative_to(ROOT)))
def test_guides_cite_only_what_exists(path):
    problems = _problems(path, modules=True)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("path", NOTES, ids=lambda p: str(p.relative_to(ROOT)))
def test_notes_link_only_to_existing_docs(path):
    problems = _problems(path, modules=False)
    assert not problems, "\n".join(problems)


def test_the_checker_catches_what_it_is_for(tmp_path):
    """Each kind of dangling reference is reported, and a sound one of each kind is not."""
    doc = tmp_path / "doc.md"
    doc.write_text(
        "`clothlab/fit/eval_csv.py` `clothlab/fit/evaluate.py` `fit/problem.py` `fit/nothing.py`\n"
        "clothlab.fit.optimize.multistart_minimize clothlab.strict clothlab.fit.optimize.no_such_name\n"
        "`fits/<name>/` `measurements/*/kang.yaml` docs/fitting.md docs/nowhere.md\n"
        "[ok](design.md#data-flow) [bad](nowhere.md) [web](https://example.org/x)\n", encoding="utf-8")
    (tmp_path / "design.md").write_text("# design\n", encoding="utf-8")
    problems = _problems(doc, modules=True)
    text = "\n".join(problems)
    for bad in ("clothlab/fit/evaluate.py", "fit/nothing.py", "(cited as clothlab.strict)", "no_such_name",
                "docs/nowhere.md", "dangling link: nowhere.md"):
        assert bad in text, (bad, text)
    for good in ("eval_csv", "fit/problem.py", "multistart_minimize (", "fits/", "kang.yaml",
                 "docs/fitting.md", "design.md", "example.org"):
        assert good not in text, (good, text)
    assert len(problems) == 6, text


def test_design_names_every_package_and_core_module():
    """docs/design.md's package table names every package of clothlab/ and every top-level module."""
    text = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")
    packages = sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file())
    modules = sorted(p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__")
    missing = [f"{name}/" for name in packages if f"`{name}/`" not in text]
    missing += [name for name in modules if f"`{name}`" not in text]
    assert not missing, f"docs/design.md does not name: {', '.join(missing)}"
