"""What a benchmark section receives: the run's settings (:class:`Context`).

A section module defines ``run(context) -> dict`` (its figures, JSON-ready) and ``lines(result) -> list[str]``
(the human-readable table of those figures); :mod:`clothlab.studies.bench` lists the sections and runs them.
Sections never print and never write outside ``context.figures_dir`` (plots) and temporary directories.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from clothlab.studies.data import StudyData


@dataclass(frozen=True)
class Context:
    """``quick``: the reduced run (seconds to minutes instead of hours); ``data``: where the measurements and
    saved fits come from; ``figures_dir``: where plots go (None: no plots)."""

    quick: bool
    data: StudyData
    figures_dir: Path | None = None
