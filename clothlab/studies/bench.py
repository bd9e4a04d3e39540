"""``clothlab bench``: speed and accuracy figures, measured side by side in one run (never timed tests).

This module is the list of sections (:data:`SECTIONS`, one module each under :mod:`clothlab.studies`) and the
run loop (:func:`run_bench`).  A section module defines ``run(context) -> dict`` and ``lines(result) ->
list[str]`` (:mod:`clothlab.studies.section`); the loop hands each section's lines to ``emit`` as it finishes,
collects the figures with the machine description, writes them as JSON and, with an output directory, as an
HTML page with the plots (:func:`clothlab.report.studies.write_study_report`).  Nothing here prints.

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
"""

from __future__ import annotations

import importlib
import json
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


SECTIONS = (
    Section("cli", "clothlab.studies.cli_startup", "clothlab --help time, heavy modules pulled in by import"),
    Section("report", "clothlab.studies.report_speed",
            "clothlab report of one fit vs 3 s; figures drawn in one vs two processes"),
    Section("speed", "clothlab.studies.model_speed",
            "IM model pairs/s vs a quad loop; IM kernels before/after when present"),
    Section("texture", "clothlab.studies.texture_speed", "512 x 512 texture-model evaluation time vs 1 s"),
    Section("accuracy", "clothlab.studies.quadrature_accuracy", "quadrature rules vs scipy quad, per yarn"),
    Section("fit", "clothlab.studies.full_fit", "one full fit vs 3 s; objective and fit before/after"),
    Section("tradeoff", "clothlab.studies.quadrature_tradeoff", "model error vs run time per rule, Pareto front"),
    Section("fit_algorithms", "clothlab.studies.nlopt_algorithms", "objective vs time for every nlopt algorithm"),
    Section("models", "clothlab.studies.im_vs_kang", "IM vs Kang speed and the saved fits' errors"),
    Section("kang", "clothlab.studies.kang_speed",
            "Kang tile average and LoD weave level: previous vs peak rule, pairs/s and error vs reference"),
    Section("posterior", "clothlab.studies.posterior", "one six-parameter posterior to the tau rule"),
    Section("coverage", "clothlab.studies.coverage", "95 % posterior interval coverage over six sets"),
    Section("btf", "clothlab.studies.btf_memory", "BTF stack streaming: images/s and peak memory"),
    Section("render", "clothlab.studies.render_lod", "receding plane: LoD render cost and error by distance"),
    Section("footprint", "clothlab.studies.footprint", "footprint averages: SAT vs MC queries/s and error by size"),
    Section("neural", "clothlab.studies.neural", "neural surrogate decoder queries/s at three widths"),
    Section("scaleout", "clothlab.studies.scaleout",
            "sequential / 2 Dask workers: example fit batch, CV folds of one fit, per-task overhead, check sweep, "
            "posterior pool"),
)
SECTION_NAMES: tuple[str, ...] = tuple(s.name for s in SECTIONS)


def _selected(sections) -> tuple[Section, ...]:
    if sections is None:
        return SECTIONS
    unknown = [s for s in sections if s not in SECTION_NAMES]
    if unknown:
        raise ConfigError(f"unknown bench section(s) {', '.join(unknown)}; choose from {', '.join(SECTION_NAMES)}",
                          field="--sections")
    return tuple(s for s in SECTIONS if s.name in sections)


def run_bench(*, sections: tuple[str, ...] | None, quick: bool, data_dir: Path | None, output: Path | None,
              json_path: Path | None, emit: Callable[[str], None]) -> int:
    """Run the benchmark ``sections`` (all when None, in :data:`SECTION_NAMES` order) and return the exit code.

    ``quick``: the reduced run; ``data_dir``: see the module docstring; ``output``: report directory (plots as
    PNG, index.html and result.json); ``json_path``: also write all figures there; ``emit``: receives the
    human-readable lines, each section's as it finishes."""
    from clothlab.studies.data import StudyData
    from clothlab.studies.section import Context
    from clothlab.studies.timing import machine

    chosen = _selected(sections)
    data = StudyData(data_dir)  # a bad --data stops the run here, before any section
    output = None if output is None else Path(output)
    figures: dict = {"machine": machine(), "quick": quick, "sections": [s.name for s in chosen],
                     "section_seconds": {}}
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
    if json_path is not None:
        from clothlab.atomic import atomic_write_text

        atomic_write_text(json_path, json.dumps(figures, indent=1, default=float) + "\n")
        emit(f"figures written to {json_path}")
    if output is not None:
        from clothlab.report.studies import write_study_report

        page = write_study_report(figures, output, title="clothlab bench: speed and accuracy",
                                  figures=sorted(output.glob("*.png")))
        emit(f"report: {page}")
    return 0
