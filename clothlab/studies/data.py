"""Where the studies find their data: a data directory, or the example measurements regenerated.

A data directory (``clothlab bench --data DIR``; the repository root for the full run) holds
``measurements/<fabric>/`` (``fabric.yaml``, ``fabric-clean.yaml``, ``kang.yaml`` and their tables) and,
optionally, ``fits/<fabric>/`` (the example fits, with their posteriors).  Nothing is looked up relative to
the installed package.

Without a data directory (an installed wheel run in an empty directory) the six example measurements are
regenerated on first use, deterministically, by :func:`clothlab.simulate.examples.write_paper_examples` into
a temporary directory removed when the run ends (a few seconds; the same generator as ``clothlab simulate
--paper-examples DIR``; its tables agree with the repository's measurements to rounding, within 1e-15
relative).  There are no saved fits then: the sections that read them say so and use their
fallback (model defaults, or the live reduced study).
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from clothlab.errors import ConfigError
from clothlab.progress import get_logger

LOG = get_logger("studies")
LAYOUT = "measurements/<fabric>/ and fits/<fabric>/ (e.g. the repository root)"


class StudyData:
    """The data of one run.  ``StudyData(DIR)`` reads DIR; ``StudyData(None)`` regenerates the examples into a
    temporary directory on first use.  Use as a context manager (or call :meth:`close`) to remove it."""

    def __init__(self, data_dir: Path | None = None):
        self.data_dir = None if data_dir is None else Path(data_dir)
        if self.data_dir is not None and not (self.data_dir / "measurements").is_dir():
            found = "has no measurements/" if self.data_dir.is_dir() else "not found"
            raise ConfigError(f"data directory {self.data_dir} {found}; it should hold {LAYOUT}; without --data the "
                              "example measurements are regenerated", field="--data")
        self._tmp: Path | None = None

    @property
    def regenerated(self) -> bool:
        """True when the measurements are the regenerated examples (no data directory given)."""
        return self.data_dir is None

    @property
    def measurements(self) -> Path:
        """The directory holding ``<fabric>/fabric.yaml`` (regenerating the examples on first use)."""
        if self.data_dir is not None:
            return self.data_dir / "measurements"
        if self._tmp is None:
            from clothlab.simulate.examples import write_paper_examples

            tmp = Path(tempfile.mkdtemp(prefix="clothlab-examples-"))
            LOG.info("no --data directory: regenerating the six example measurements into %s", tmp)
            write_paper_examples(tmp / "measurements")
            self._tmp = tmp
        return self._tmp / "measurements"

    @property
    def fits(self) -> Path | None:
        """The saved fits' directory, or None (regenerated examples, or a data directory without ``fits/``)."""
        if self.data_dir is None or not (self.data_dir / "fits").is_dir():
            return None
        return self.data_dir / "fits"

    def fit_dir(self, name: str) -> Path | None:
        """``fits/<name>`` when it holds a ``fit.json``, else None."""
        fits = self.fits
        return fits / name if fits is not None and (fits / name / "fit.json").is_file() else None

    def config_path(self, fabric: str, variant: str = "noisy") -> Path:
        """``measurements/<fabric>/fabric.yaml`` (``variant`` "noisy"), ``fabric-clean.yaml`` ("clean") or
        ``kang.yaml`` ("kang"); a missing file is an error naming ``--data``."""
        name = {"noisy": "fabric.yaml", "clean": "fabric-clean.yaml", "kang": "kang.yaml"}[variant]
        path = self.measurements / fabric / name
        if not path.is_file():
            raise ConfigError(f"{path} not found: the data directory should hold {LAYOUT}; without --data the "
                              "example measurements are regenerated", field="--data")
        return path

    def load_config(self, fabric: str, variant: str = "noisy"):
        """The :class:`clothlab.config.Config` of :meth:`config_path`."""
        from clothlab.config import load_config

        return load_config(self.config_path(fabric, variant))

    def describe(self) -> str:
        """One line: where this run's data come from."""
        if self.data_dir is None:
            return ("data: no --data directory; the six example measurements are regenerated into a temporary "
                    "directory when a section needs them, no saved fits")
        fits = "with saved fits" if self.fits is not None else "no fits/ (saved-fit figures fall back)"
        return f"data: {self.data_dir} ({fits})"

    def close(self) -> None:
        """Remove the regenerated examples, if any."""
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def __enter__(self) -> StudyData:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def paper_directions():
    """The paper's 1,575 (wi, wo) pairs (sec. 4.1: 225 incident x 7 exitant), (N, 3) each, fabric frame."""
    from clothlab.frames import spherical_to_vector
    from clothlab.simulate.gonio import paper_sampling

    ti, pi_, to, po = paper_sampling()
    return spherical_to_vector(ti, pi_), spherical_to_vector(to, po)


@contextmanager
def study_data(data: StudyData | Path | None) -> Iterator[StudyData]:
    """``data`` as a :class:`StudyData`: the given one (left open), or one made from a path or None (closed on
    exit, removing regenerated examples)."""
    if isinstance(data, StudyData):
        yield data
        return
    with StudyData(data) as made:
        yield made
