"""The validated fabric.yaml: frozen dataclasses, one per section, with the defaults of every setting.

:func:`clothlab.config.load_config` builds a :class:`Config` after checking every value
(:mod:`clothlab.config.validate`); code that runs a fit reads these objects, never the raw mapping.
Paths are resolved (absolute); parameter values are in the units the model declares (angles in degrees).
``model.quadrature`` is a :class:`~clothlab.models.irawan.quadrature.Quadrature`, the one form of the choice
with its defaults (Irawan & Marschner 2012, sec. 7.3: the trapezoidal rule with 11 samples for eq. 10).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from clothlab.config.choices import DEFAULT_GLOBAL, DEFAULT_LOCAL, DEFAULT_LOSS_SCALE
from clothlab.models.irawan.quadrature import Quadrature
from clothlab.models.registry import DEFAULT_KIND, DEFAULT_SELECT_KINDS

PRESET_PREFIX = "preset:"
"""``model.weave: preset:<name>`` names a shipped weave preset instead of a .wv file."""

DEFAULT_PERCENTILES = (50.0, 80.0, 95.0)
DEFAULT_WALKERS = 32
DEFAULT_STEPS = 4000
DEFAULT_MAX_STEPS = 20000


@dataclass(frozen=True)
class MeasurementConfig:
    """``measurement``: the data file or directory (resolved), its format and the loader's options."""

    path: Path
    format: str = "auto"
    options: dict = field(default_factory=dict)


QuadratureConfig = Quadrature
"""``model.quadrature``: the former name of :class:`~clothlab.models.irawan.quadrature.Quadrature` (kept for one
release)."""


@dataclass(frozen=True)
class ModelConfig:
    """``model``: kind, weave (``preset:<name>`` or the resolved path of a .wv file, or None), start values."""

    kind: str = DEFAULT_KIND
    weave: str | None = None
    quadrature: Quadrature = field(default_factory=Quadrature)
    params: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)  # passed to the model's constructor (e.g. kang tile_nodes)

    @property
    def weave_preset(self) -> str | None:
        """The preset name when ``weave`` is ``preset:<name>``, else None."""
        if self.weave is not None and self.weave.startswith(PRESET_PREFIX):
            return self.weave[len(PRESET_PREFIX):]
        return None

    @property
    def weave_path(self) -> Path | None:
        """The .wv file when ``weave`` names one, else None."""
        if self.weave is None or self.weave_preset is not None:
            return None
        return Path(self.weave)


@dataclass(frozen=True)
class OptimizerConfig:
    """``fit.optimizer``: nlopt algorithm names (None = skip that stage), evaluation budget, seed, seconds."""

    global_algorithm: str | None = DEFAULT_GLOBAL
    local_algorithm: str | None = DEFAULT_LOCAL
    max_evals: int = 4000
    seed: int = 1
    max_time: float | None = None
    starts: int = 1
    polish: int | None = None  # evaluations of the final restarted polish; None = max_evals // 3, 0 = none
    design: str = "sobol"  # starts 2.. at the points of a scrambled Sobol ("sobol") / Latin hypercube ("lhs") design
    box_check: bool = True  # after the polish: does the optimum move when the box is enlarged?

    @property
    def polish_evals(self) -> int:
        """Evaluations of the final polish: ``polish``, or max_evals // 3 when not given."""
        return self.max_evals // 3 if self.polish is None else self.polish


@dataclass(frozen=True)
class PosteriorConfig:
    """``fit.posterior``: emcee walkers, minimum steps and the cap when running to convergence.

    emcee's affine-invariant ensemble sampler (Foreman-Mackey et al. 2013, "emcee: The MCMC Hammer") refuses
    fewer walkers than twice the free parameters; the validator says so at the line of ``walkers``.
    """

    walkers: int = DEFAULT_WALKERS
    steps: int = DEFAULT_STEPS
    max_steps: int = DEFAULT_MAX_STEPS


#: Orientations the model is averaged over for an isotropic measurement (``fit.orientation_average``).
DEFAULT_ORIENTATION_AVERAGE = 128


@dataclass(frozen=True)
class FitConfig:
    """``fit``: free parameters, their fit bounds (declared units), metric, optimiser, posterior, CV folds and
    fold scheme."""

    free: tuple = ()
    bounds: dict = field(default_factory=dict)
    metric: str = "relative"
    optimizer: OptimizerConfig = field(default_factory=OptimizerConfig)
    posterior: PosteriorConfig | None = None
    cv_folds: int = 0
    cv_scheme: str = "auto"
    cv_refit: str = "neutral"  # CV folds refit from the neutral start ("neutral") or the full optimum ("local")
    loss: str = "squared"  # rho applied to the metric residuals (clothlab.fit.loss)
    loss_scale: float = DEFAULT_LOSS_SCALE
    valid_geometry: bool = False  # default bounds shrunk to the geometry the model accepts (clothlab.fit.problem)
    orientation_average: int = DEFAULT_ORIENTATION_AVERAGE  # for an isotropic measurement (clothlab.fit.problem)


@dataclass(frozen=True)
class ReportConfig:
    """``report``: error percentiles to tabulate, ascending, in [0, 100]."""

    percentiles: tuple = DEFAULT_PERCENTILES


@dataclass(frozen=True)
class SelectConfig:
    """``select``: what ``clothlab select`` / ``fit --select`` tries (clothlab.fit.select, docs/select.md):
    weaves (``preset:<name>`` or resolved .wv paths; empty = every shipped preset), model kinds, orientation
    starts, the per-candidate evaluation budget and CV folds, and the optional checks on top (nested CV outer
    folds, candidate losses and their scales, stability subsamples; 0 / empty = off).  The one definition of
    the selection's defaults: clothlab.fit.select takes this class as its settings."""

    weaves: tuple = ()
    kinds: tuple = DEFAULT_SELECT_KINDS
    orientation_starts: int = 2
    max_evals: int = 600
    cv_folds: int = 5
    nested: int = 0  # outer folds of the nested cross-validation (clothlab.fit.nested); 0: none
    #: candidate losses (clothlab.fit.loss): huber at 0.1 (10 % relative residual) for real measurements
    #: (docs/select.md); empty: fabric.yaml's fit.loss only (what a simulated table with Gaussian noise wants)
    losses: tuple = ("huber",)
    loss_scales: tuple = (0.1,)  # scales tried for huber / cauchy (the CV ranking chooses); empty: fit.loss_scale
    stability: int = 0  # subsamples of the selection-stability check (clothlab.fit.stability); 0: none


@dataclass(frozen=True)
class OutputConfig:
    """``output``: directories under which fits/<name>/ and reports/<name>/ are written (resolved)."""

    fits: Path
    reports: Path


@dataclass(frozen=True)
class Config:
    """A validated fabric.yaml.

    ``path`` is the yaml file (None for :func:`config_from_dict`), ``source`` the label used in messages,
    ``base_dir`` the absolute directory relative paths were resolved against, ``raw`` the mapping as read
    (before defaults and overrides).
    """

    name: str
    path: Path | None
    base_dir: Path
    measurement: MeasurementConfig
    model: ModelConfig
    fit: FitConfig
    report: ReportConfig
    output: OutputConfig
    raw: dict
    source: str = "<dict>"
    select: SelectConfig = field(default_factory=SelectConfig)  # not in canonical(): it changes no fit

    def canonical(self) -> dict:
        """The validated settings as plain JSON data with defaults filled in.

        Paths are given relative to ``base_dir`` and ``output`` is left out, so the result (and
        :attr:`hash`) does not depend on where the project sits on a machine or where results are written.
        """
        model = self.model
        weave = model.weave if model.weave_path is None else self._relative(model.weave_path)
        fit = self.fit
        opt = fit.optimizer
        post = fit.posterior
        return {
            "name": self.name,
            "measurement": {
                "path": self._relative(self.measurement.path),
                "format": self.measurement.format,
                "options": self.measurement.options,
            },
            "model": {
                "kind": model.kind,
                "weave": weave,
                "quadrature": model.quadrature.record(),
                "params": dict(model.params),
                "options": self._relative_options(),
            },
            "fit": {
                "free": list(fit.free),
                "bounds": {k: list(v) for k, v in fit.bounds.items()},
                "metric": fit.metric,
                "optimizer": {
                    "global": opt.global_algorithm,
                    "local": opt.local_algorithm,
                    "max_evals": opt.max_evals,
                    "seed": opt.seed,
                    "max_time": opt.max_time,
                    "starts": opt.starts,
                    "polish": opt.polish_evals,
                    # new settings only when not the default: hashes of older configs kept
                    **({} if opt.design == "sobol" else {"design": opt.design}),
                    **({} if opt.box_check else {"box_check": False}),
                },
                "posterior": None if post is None else {
                    "walkers": post.walkers, "steps": post.steps, "max_steps": post.max_steps,
                },
                "cv_folds": fit.cv_folds,
                **({} if fit.cv_scheme == "auto" else {"cv_scheme": fit.cv_scheme}),  # hashes of older configs kept
                **({} if fit.cv_refit == "neutral" else {"cv_refit": fit.cv_refit}),
                **({} if fit.loss == "squared" else {"loss": fit.loss, "loss_scale": fit.loss_scale}),
                **({"valid_geometry": True} if fit.valid_geometry else {}),
                **({} if fit.orientation_average == DEFAULT_ORIENTATION_AVERAGE
                   else {"orientation_average": fit.orientation_average}),
            },
            "report": {"percentiles": list(self.report.percentiles)},
        }

    @property
    def hash(self) -> str:
        """sha256 (hex) of the canonical JSON of :meth:`canonical` (sorted keys, no whitespace)."""
        text = json.dumps(self.canonical(), sort_keys=True, separators=(",", ":"), allow_nan=False)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()

    def _relative_options(self) -> dict:
        """The model options, file options (the class's ``path_options``) relative to ``base_dir``."""
        from clothlab.models.registry import model_class

        options = dict(self.model.options)
        for name in model_class(self.model.kind).options_class().path_options:
            if options.get(name):
                options[name] = self._relative(Path(options[name]))
        return options

    def _relative(self, path: Path) -> str:
        return Path(os.path.relpath(path, self.base_dir)).as_posix()
