"""``clothlab bench``: speed and accuracy figures, measured side by side in one run (never timed tests).

This module is the list of sections (:data:`SECTIONS`, one module each under :mod:`clothlab.studies`) and the
run loop (:func:`run_bench`).  A section module defines ``run(context) -> dict`` and ``lines(result) ->
list[str]`` (:mod:`clothlab.studies.section`); the loop hands each section's lines to ``emit`` as it finishes,
collects the figures with the machine description, writes them as JSON and, with an output directory, as an
HTML page with the plots (:func:`clothlab.report.study_pages.write_study_report`).  Nothing here prints.

Data (``data_dir``, ``clothlab bench --data DIR``): a directory holding ``measurements/<fabric>/`` and
``fits/<fabric>/`` - the repository root for the full run.  Without one (an installed wheel run in an empty
directory) the six example measurements are regenerated deterministically into a temporary directory (the
generator of ``clothlab simulate --paper-examples DIR``, a few seconds, only when a section needs them), and
the sections that read saved fits fall back and say so in their lines and figures: ``models`` evaluates the
models at their default parameters, ``coverage`` runs the live reduced study instead of reading the example
fits' posteriors.  Every section runs either way; a data directory that lacks a file a section needs is an
error naming ``--data``.

No section writes under the data directory: fits run with cross-validation and the configured posterior off,
and the posteriors the studies run checkpoint into a temporary directory.

Provenance (issue 27: a result that cannot go stale unnoticed).  Every run records under ``provenance`` the git
commit it measured (with the files modified under ``clothlab/`` at the time, if any), the date, and per section
a hash of the code it measures (:func:`source_hash`: the section's module and the packages in
:attr:`Section.measures`, docstrings and comments ignored).  :func:`stale_sections` compares a result with the
current code; the test suite runs it on the committed ``reports/bench/result.json``, which ``clothlab bench``
writes by default (:data:`DEFAULT_RESULT`; a run of some sections replaces those sections and keeps the rest,
each with its own provenance).
"""

from __future__ import annotations

import ast
import hashlib
import importlib
import importlib.util
import json
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from clothlab.errors import ConfigError
from clothlab.progress import get_logger

LOG = get_logger("studies.bench")


class Section(NamedTuple):
    name: str
    module: str
    summary: str
    #: the packages or modules whose code the section's figures measure (hashed into the result's provenance)
    measures: tuple[str, ...] = ()


_IM = "clothlab.models.irawan"
_FIT = ("clothlab.fit", _IM)  # (not io / config: reading the table and the yaml is a negligible part of a fit)
SECTIONS = (
    Section("cli", "clothlab.studies.cli_startup", "clothlab --help time, heavy modules pulled in by import",
            ("clothlab.cli", "clothlab.progress", "clothlab.__main__")),
    Section("report", "clothlab.studies.report_speed",
            "clothlab report of one fit vs 3 s; figures drawn in one vs two processes", ("clothlab.report",)),
    Section("speed", "clothlab.studies.model_speed",
            "IM model pairs/s vs a quad loop; IM kernels before/after when present; issue 27's objective and IM "
            "cold/warm", (_IM, "clothlab.fit")),
    Section("texture", "clothlab.studies.texture_speed", "512 x 512 texture-model evaluation time vs 1 s", (_IM,)),
    Section("accuracy", "clothlab.studies.quadrature_accuracy", "quadrature rules vs scipy quad, per yarn", (_IM,)),
    Section("fit", "clothlab.studies.full_fit", "one full fit vs 3 s; objective and fit before/after", _FIT),
    Section("tradeoff", "clothlab.studies.quadrature_tradeoff", "model error vs run time per rule, Pareto front",
            (_IM,)),
    Section("fit_algorithms", "clothlab.studies.nlopt_algorithms", "objective vs time for every nlopt algorithm",
            _FIT),
    Section("models", "clothlab.studies.im_vs_kang", "IM vs Kang speed and the saved fits' errors",
            (_IM, "clothlab.models.kang")),
    Section("kang", "clothlab.studies.kang_speed",
            "Kang tile average and LoD weave level: previous vs peak rule, pairs/s and error vs reference",
            ("clothlab.models.kang",)),
    Section("posterior", "clothlab.studies.posterior", "one six-parameter posterior to the stopping rule", _FIT),
    Section("coverage", "clothlab.studies.coverage", "95 % posterior interval coverage over six sets", _FIT),
    Section("btf", "clothlab.studies.btf_memory", "BTF stack streaming: images/s and peak memory", ("clothlab.btf",)),
    Section("render", "clothlab.studies.render_lod", "receding plane: LoD render cost and error by distance",
            ("clothlab.render", _IM, "clothlab.models.kang")),
    Section("footprint", "clothlab.studies.footprint", "footprint averages: SAT vs MC queries/s and error by size",
            ("clothlab.footprint", _IM)),
    Section("neural", "clothlab.studies.neural", "neural surrogate decoder queries/s at three widths",
            ("clothlab.surrogate", "clothlab.models.neural")),
    Section("mitsuba", "clothlab.studies.mitsuba_render", "Mitsuba 3 plugin vs clothlab render: time, parity, chi2",
            ("clothlab.mitsuba",)),
    Section("scaleout", "clothlab.studies.scaleout",
            "sequential / 2 Dask workers: example fit batch, CV folds of one fit, per-task overhead, check sweep, "
            "posterior pool", ("clothlab.parallel",) + _FIT),
)
DEFAULT_RESULT = Path("reports") / "bench" / "result.json"
"""Where ``clothlab bench`` writes its figures without ``-o`` / ``--json`` (relative to the working directory:
the repository root in the README's command)."""
SECTION_NAMES: tuple[str, ...] = tuple(s.name for s in SECTIONS)


def _files(name: str) -> list[Path]:
    """The source files of module or package ``name`` (found without importing it)."""
    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        raise ValueError(f"bench: no module {name!r}")
    origin = Path(spec.origin)
    if spec.submodule_search_locations:  # a package: every module under it
        return sorted(origin.parent.rglob("*.py"))
    return [origin]


def _code(path: Path) -> str:
    """The code of a source file without its docstrings and comments (the AST, no positions): an edit of the
    text only does not make a measured result stale."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) and \
                isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
            body[0] = ast.Pass()
    return ast.dump(tree, include_attributes=False)


def source_hash(section: Section | str) -> str:
    """sha256 (16 hex digits) of the code the section measures: its module and :attr:`Section.measures`
    (:func:`_code` of each file, in path order)."""
    if isinstance(section, str):
        section = {s.name: s for s in SECTIONS}[section]
    files = sorted({f.resolve() for name in (section.module, *section.measures) for f in _files(name)})
    digest = hashlib.sha256()
    root = Path(importlib.util.find_spec("clothlab").origin).parent.parent
    for f in files:
        digest.update(str(f.relative_to(root) if f.is_relative_to(root) else f.name).encode())
        digest.update(_code(f).encode())
    return digest.hexdigest()[:16]


def _git(*args: str) -> str | None:
    root = Path(importlib.util.find_spec("clothlab").origin).parent.parent
    try:
        out = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def provenance(sections) -> dict:
    """What a run measured: git commit (None outside a checkout), files modified under clothlab/ then, the
    date (UTC) and per section :func:`source_hash`."""
    dirty = _git("status", "--porcelain", "--", "clothlab")
    return {"commit": _git("rev-parse", "HEAD"), "modified": [line[3:] for line in (dirty or "").splitlines()],
            "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "sources": {s.name: source_hash(s) for s in sections}}


def stale_sections(result: dict) -> dict[str, str]:
    """{section: why} for the sections of a bench result whose code changed since it was measured (or that
    carry no provenance); {} for a current result."""
    out = {}
    for name in result.get("sections") or [n for n in SECTION_NAMES if n in result]:
        if name not in SECTION_NAMES:
            continue
        prov = (result.get("provenance_by_section") or {}).get(name) or result.get("provenance") or {}
        recorded = (prov.get("sources") or {}).get(name)
        if recorded is None:
            out[name] = "no source hash recorded"
        elif recorded != source_hash(name):
            out[name] = f"measured code {recorded} at {prov.get('commit') or '?'} ({prov.get('date')}), now " \
                        f"{source_hash(name)}"
    return out


def merge_result(old: dict | None, new: dict) -> dict:
    """``new`` with the sections of ``old`` it did not run kept (each section's provenance under
    ``provenance_by_section``), so a run of some sections updates a full result in place."""
    prov = dict((old or {}).get("provenance_by_section") or {})
    for name in (old or {}).get("sections") or []:
        prov.setdefault(name, (old or {}).get("provenance"))
    for name in new["sections"]:
        prov[name] = new["provenance"]
    if old is None or old.get("quick") != new.get("quick"):
        return {**new, "provenance_by_section": {n: prov[n] for n in new["sections"]}}
    kept = [n for n in SECTION_NAMES if n in (old.get("sections") or []) and n not in new["sections"]]
    merged = {**{n: old[n] for n in kept if n in old}, **new}
    merged["sections"] = [n for n in SECTION_NAMES if n in kept or n in new["sections"]]
    merged["section_seconds"] = {**(old.get("section_seconds") or {}), **new["section_seconds"]}
    merged["provenance_by_section"] = {n: prov[n] for n in merged["sections"]}
    return merged


def _selected(sections) -> tuple[Section, ...]:
    if sections is None:
        return SECTIONS
    unknown = [s for s in sections if s not in SECTION_NAMES]
    if unknown:
        raise ConfigError(f"unknown bench section(s) {', '.join(unknown)}; choose from {', '.join(SECTION_NAMES)}",
                          field="--sections")
    return tuple(s for s in SECTIONS if s.name in sections)


def _load_average() -> float | None:
    import os

    return os.getloadavg()[0] if hasattr(os, "getloadavg") else None


def run_bench(*, sections: tuple[str, ...] | None, quick: bool, data_dir: Path | None, output: Path | None,
              json_path: Path | None, emit: Callable[[str], None], merge: bool = False) -> int:
    """Run the benchmark ``sections`` (all when None, in :data:`SECTION_NAMES` order) and return the exit code.

    ``quick``: the reduced run; ``data_dir``: see the module docstring; ``output``: report directory (plots as
    PNG, index.html and result.json); ``json_path``: also write all figures there; ``emit``: receives the
    human-readable lines, each section's as it finishes; ``merge``: keep the sections of an existing
    ``json_path`` that this run does not measure (:func:`merge_result`)."""
    from clothlab.studies.data import StudyData
    from clothlab.studies.section import Context
    from clothlab.studies.timing import machine

    chosen = _selected(sections)
    data = StudyData(data_dir)  # a bad --data stops the run here, before any section
    output = None if output is None else Path(output)
    figures: dict = {"machine": machine(), "quick": quick, "sections": [s.name for s in chosen],
                     "section_seconds": {}, "provenance": provenance(chosen), "load_average_start": _load_average()}
    emit(f"clothlab bench ({'quick' if quick else 'full'}) on {figures['machine']['cpus']} CPUs; sections: "
         f"{', '.join(figures['sections'])}")
    with data:
        figures["data"] = data.describe()
        emit(figures["data"])
        context = Context(quick=quick, data=data, figures_dir=output)
        for section in chosen:
            LOG.info("bench: section %s (%s)", section.name, section.summary)
            module = importlib.import_module(section.module)
            started = time.perf_counter()
            result = module.run(context)
            figures["section_seconds"][section.name] = time.perf_counter() - started
            figures[section.name] = result
            emit("")
            for line in module.lines(result):
                emit(line)
    figures["load_average_end"] = _load_average()
    if json_path is not None:
        from clothlab.atomic import atomic_write_text

        old = None
        if merge and Path(json_path).is_file():
            try:
                old = json.loads(Path(json_path).read_text(encoding="utf-8"))
            except (OSError, ValueError):
                old = None
        written = merge_result(old, figures) if merge else figures
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(json_path, json.dumps(written, indent=1, default=float) + "\n")
        emit(f"figures written to {json_path} (commit {(figures['provenance']['commit'] or '?')[:10]}, "
             f"{figures['provenance']['date']})")
    if output is not None:
        from clothlab.report.study_pages import write_study_report

        page = write_study_report(figures, output, title="clothlab bench: speed and accuracy",
                                  figures=sorted(output.glob("*.png")))
        emit(f"report: {page}")
    return 0
