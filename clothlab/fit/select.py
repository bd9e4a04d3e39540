"""Model selection: fit a set of candidate weaves, orientations and diffuse terms, rank them, refit the winner
(``clothlab select fabric.yaml`` = ``clothlab fit --select fabric.yaml``; issue 14 item 3, docs/select.md).

Candidates (:func:`candidates`) are the product of

* weaves: ``select.weaves`` (default every shipped preset, :data:`clothlab.weave.presets.PRESET_NAMES`);
* kinds, i.e. the specular model and its diffuse term: ``select.kinds`` (default ``irawan`` - the IM yarn
  highlights with the IM model's Lambertian - and ``irawan+oren-nayar``, the same with an Oren & Nayar
  diffuse, :mod:`clothlab.models.composite`);
* orientation starts: ``select.orientation_starts`` (default 2) starts j = 1..n with ``orientation``
  freed in a box of one period P centred on the start.  The starts are the n best local minima of a scan of
  the objective over :data:`SCAN_POINTS` orientations across one period, the other parameters at their
  starts (:func:`orientation_scan`; the objective is multimodal in the orientation, and a reduced budget
  does not find the basin by itself).  Isotropic kinds get one start and do not free it.

* losses (issue 28): ``--losses`` (default: fabric.yaml's ``fit.loss`` only), huber and cauchy at every
  ``--loss-scales`` value, so the CV ranking chooses the scale.

The free parameters of a candidate are fabric.yaml's ``fit.free`` mapped to the candidate's kind
(:func:`map_free`: a declared name kept, another replaced by its role's counterpart, the models' declared
``im_counterparts`` and ``parameter_concepts``; a name of no model's vocabulary is a ConfigError before any
fit); when that leaves none, its specular part's defaults by config validation's rule
(:func:`clothlab.config.validate.default_free`: for kind neural the parameters its network was trained over);
then its diffuse part's defaults (``sigma``) and ``orientation``; the starts are ``model.params`` restricted
the same way, else the weave's values.

Optional, on top (docs/select.md): nested cross-validation (``SelectConfig.nested``, :mod:`clothlab.fit.nested`)
for the selected model's honest held-out error, selection stability on subsamples (``stability``,
:mod:`clothlab.fit.stability`), and always the residual diagnostics of the top candidates
(:func:`top_residuals`) and the not-determined flags in each row's note (:mod:`clothlab.fit.determined`).

Each candidate is one independent task (:func:`fit_candidate`: a :class:`CandidateTask` in, a
:class:`CandidateResult` out, nothing shared), so a task scheduler can distribute the list.  A candidate is
fitted with a reduced budget (``select.max_evals``, default 600 evaluations, one start, polish
``max_evals // 4``) and cross-validated (``select.cv_folds``, default 5, :mod:`clothlab.fit.crossval`, fold
scheme ``auto``), each fold repeating the candidate's own search with the same budget (:func:`_candidate_cv`).

Ranking (:func:`rank`): by the cross-validated (held-out) mean relative error, candidates whose
cross-validation failed after those with one; the table also lists the information criteria

    AIC = n ln(F) + 2 k,        BIC = n ln(F) + k ln(n)

with F the mean squared metric residual at the optimum (whatever the candidate's loss), n the
number of fitted values (rows x channels) and k the free parameters plus the linear coefficients
(components x channels).  Likelihood assumed: the metric residuals are independent Gaussian with one unknown
variance, profiled out (-2 ln L = n ln F + const), so only differences between candidates on the same data
mean anything.

The winner is refitted with fabric.yaml's own budget, cross-validation and posterior settings (its box in
``orientation`` centred on the candidate's value, so the optimum is interior) and saved as a normal fit
directory, ``fits/<name>/``, with ``selection.csv`` and ``selection.md`` (the comparison table) beside
fit.json, whose key ``selection`` (:func:`selection_summary`) holds the table rows (``candidates``, ranked),
the ranking rule, the likelihood note and the budgets.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from clothlab.config.schema import SelectConfig
from clothlab.config.validate import default_free
from clothlab.fit.metrics import information_criteria
from clothlab.fit.periodic import wrap
from clothlab.models.base import ORIENTATION
from clothlab.models.registry import model_class
from clothlab.progress import Progress, get_logger
from clothlab.weave.presets import PRESET_NAMES, PRESET_PREFIX

log = get_logger(__name__)

#: every shipped preset: the weaves tried when ``select.weaves`` is empty
ALL_PRESETS = tuple(PRESET_PREFIX + name for name in PRESET_NAMES)
#: orientations of the scan that places the orientation starts (every 5 deg over a half turn)
SCAN_POINTS = 36
RANKING = ("cross-validated held-out mean relative error (ascending); candidates whose cross-validation failed "
           "after those with one, by BIC")
LIKELIHOOD = ("AIC = n ln(F) + 2k, BIC = n ln(F) + k ln(n): F the objective at the optimum (mean squared metric "
              "residual), n the fitted values (rows x channels), k the free parameters plus the linear "
              "coefficients (components x channels); residuals assumed independent Gaussian with one unknown "
              "variance (profiled out), so only differences between candidates on the same data mean anything")
TABLE_COLUMNS = ("rank", "candidate", "weave", "kind", "loss", "loss_scale", "free", "orientation_start",
                 "orientation", "cv_mean", "cv_p50", "cv_p80", "in_sample_p50", "in_sample_p80", "objective", "n",
                 "k", "aic", "bic", "cv_scheme", "evaluations", "wall_time_s", "note")


@dataclass(frozen=True)
class Candidate:
    """One candidate: weave (``preset:<name>`` or a .wv path), model kind and which orientation start (1 = the
    scan's best, :func:`orientation_scan`; None: orientation not freed)."""

    weave: str
    kind: str
    orientation_start: int | None = None
    loss: str | None = None  # None: fabric.yaml's fit.loss
    loss_scale: float | None = None  # None: fabric.yaml's fit.loss_scale

    @property
    def name(self) -> str:
        weave = self.weave[len(PRESET_PREFIX):] if self.weave.startswith(PRESET_PREFIX) else self.weave
        start = "" if self.orientation_start is None else f" #{self.orientation_start}"
        loss = ""
        if self.loss is not None:
            loss = f" {self.loss}" + ("" if self.loss in ("squared", "l1") or self.loss_scale is None
                                      else f" {self.loss_scale:g}")
        return f"{weave} {self.kind}{loss}{start}"


#: What :func:`select` tries: the config's own ``select`` section class (one set of defaults,
#: :class:`clothlab.config.schema.SelectConfig`; empty ``weaves``: every shipped preset, :func:`weaves_of`).
SelectSettings = SelectConfig


def weaves_of(settings: SelectConfig) -> tuple:
    """The weaves ``settings`` tries: its ``weaves``, or every shipped preset when it names none."""
    return tuple(settings.weaves) or ALL_PRESETS


@dataclass(frozen=True)
class CandidateTask:
    """Everything one candidate fit needs (picklable: a validated config, a measurement, plain settings);
    ``held_out``: rows the fitted candidate predicts (an outer fold of :mod:`clothlab.fit.nested`)."""

    config: object
    candidate: Candidate
    max_evals: int
    cv_folds: int
    measurement: object = None
    held_out: object = None
    outer_fold: int | None = None


@dataclass
class CandidateResult:
    """What a candidate fit gives the ranking (:data:`TABLE_COLUMNS`) and the winner's refit (``params``)."""

    candidate: Candidate
    row: dict
    params: dict = field(default_factory=dict)
    free: tuple = ()
    period: float = 0.0
    held_out: np.ndarray | None = None  # (N_held, C) prediction of the task's held_out rows


def settings_from_config(config, *, weaves=None, kinds=None, orientation_starts=None, max_evals=None,
                         cv_folds=None, nested=None, losses=None, loss_scales=None,
                         stability=None) -> SelectConfig:
    """The :class:`SelectConfig` of fabric.yaml's ``select`` section (empty ``weaves``: every shipped preset),
    with the given values (command-line options) replacing it."""
    sel = config.select
    return SelectConfig(weaves=tuple(weaves if weaves is not None else sel.weaves) or ALL_PRESETS,
                        kinds=tuple(kinds if kinds is not None else sel.kinds),
                        orientation_starts=int(orientation_starts or sel.orientation_starts),
                        max_evals=int(max_evals or sel.max_evals),
                        cv_folds=int(sel.cv_folds if cv_folds is None else cv_folds),
                        nested=int(sel.nested if nested is None else nested),
                        losses=tuple(losses if losses is not None else sel.losses),
                        loss_scales=tuple(float(x) for x in (loss_scales if loss_scales is not None
                                                             else sel.loss_scales)),
                        stability=int(sel.stability if stability is None else stability))


def check_settings(settings: SelectConfig, base_dir=".") -> None:
    """Input validation before any candidate is fitted: every weave reads (a damaged .wv file is refused here,
    naming its file and line, instead of becoming a "not fitted" row after the other candidates ran)."""
    from clothlab.weave.presets import resolve_weave

    for weave in weaves_of(settings):
        resolve_weave(weave, base_dir)


def candidates(settings: SelectConfig, isotropic: bool = False) -> list[Candidate]:
    """The candidate list (module docstring), in weave, kind, orientation-start order; for an ``isotropic``
    measurement one candidate per weave and kind, the orientation not freed (the fit averages the model over
    it: :mod:`clothlab.fit.problem`)."""
    losses = [(None, None)]
    if settings.losses:
        scales = tuple(settings.loss_scales) or (None,)
        losses = [(loss, None) if loss in ("squared", "l1") else (loss, s) for loss in settings.losses
                  for s in (scales if loss not in ("squared", "l1") else (None,))]
    out = []
    for weave in weaves_of(settings):
        for kind in settings.kinds:
            for loss, scale in losses:
                if isotropic or model_class(kind).orientation_period == 0.0:
                    out.append(Candidate(weave, kind, None, loss, scale))
                    continue
                out += [Candidate(weave, kind, j, loss, scale)
                        for j in range(1, max(1, int(settings.orientation_starts)) + 1)]
    return out


def orientation_scan(config, measurement, n_starts: int, points: int = SCAN_POINTS) -> list[float]:
    """The ``n_starts`` best local minima (deg, best first) of the objective of ``config`` (orientation free
    or not: the other parameters at their starts) over ``points`` orientations spaced evenly over one period
    (a cyclic scan; fewer when there are fewer minima, then the next best points)."""
    from clothlab.fit.problem import build_problem

    problem = build_problem(replace(config, fit=replace(config.fit, free=())), measurement)
    period = problem.model.params[ORIENTATION].period
    grid = np.arange(points) * (period / points)
    values = np.array([problem.solve({**problem.start, ORIENTATION: float(a)}).objective for a in grid])
    minima = [i for i in range(points) if values[i] <= values[i - 1] and values[i] <= values[(i + 1) % points]]
    order = sorted(minima, key=lambda i: values[i]) + sorted(set(range(points)) - set(minima), key=lambda i: values[i])
    return [float(grid[i]) for i in order[:n_starts]]


def orientation_span(kind: str) -> float:
    """The period (deg) of ``orientation`` declared by ``kind`` (the span of its default bounds)."""
    return float(model_class(kind).params[ORIENTATION].period)


def _concept_class(kind: str) -> type:
    """The class whose :attr:`~clothlab.models.base.Model.parameter_concepts` speak for ``kind``: a composite's
    (or a physics term's) specular part, followed to the single model it ends in."""
    cls = model_class(kind)
    while cls.options_class() is not cls:
        cls = cls.options_class()
    return cls


def concepts() -> dict:
    """Every registered kind's vocabulary (issue 28 item 1): concept -> the parameter names any model declares
    for it (the models' :attr:`~clothlab.models.base.Model.parameter_concepts`)."""
    from clothlab.models.registry import MODEL_KINDS

    out: dict = {}
    for kind in MODEL_KINDS:
        for concept, names in _concept_class(kind).parameter_concepts.items():
            out.setdefault(concept, set()).update(names)
    return out


def map_free(kind: str, free, options: dict | None = None) -> tuple[list, dict]:
    """(free, mapping): fabric.yaml's ``fit.free`` names (orientation aside) as parameters of ``kind``: a name
    the kind declares is kept, another is replaced by its concept's counterpart in the kind's model (the models'
    declared ``im_counterparts``, then ``parameter_concepts``: :func:`concepts`)
    (``mapping`` records each replaced name and what it became, possibly nothing).  A name in no concept (or
    a concept the family has no entry for while the kind does not declare the name) raises ConfigError at
    ``fit.free``: never a silent drop."""
    from clothlab.errors import ConfigError

    cls = model_class(kind)
    table = cls.declared_parameters(options or {})
    own = _concept_class(kind)
    vocabulary = None
    out, mapping = [], {}
    for name in free:
        if name == ORIENTATION:
            continue
        if name in table:
            targets = (name,)
        elif name in own.im_counterparts:
            targets = tuple(t for t in own.im_counterparts[name] if t in table)
            mapping[name] = list(targets)
        else:
            vocabulary = vocabulary or concepts()
            concept = next((c for c, names in vocabulary.items() if name in names), None)
            if concept is None:
                known = ", ".join(getattr(p, "name", p) for p in table)
                raise ConfigError(f"fit.free names {name!r}, which model kind {kind!r} does not declare and which "
                                  f"has no counterpart in it (its parameters: {known}); remove it or "
                                  "leave that kind out of select.kinds", field="fit.free")
            targets = tuple(t for t in own.parameter_concepts.get(concept, ()) if t in table)
            mapping[name] = list(targets)
        out += [t for t in targets if t not in out]
    return out, mapping


def free_mapping(config, kinds) -> dict:
    """Per kind, the fit.free names :func:`map_free` replaced and what they became (ConfigError for a name with
    no counterpart, before any candidate is fitted)."""
    out = {}
    for kind in kinds:
        options = config.model.options if kind == config.model.kind else {}
        out[kind] = map_free(kind, config.fit.free, options)[1]
    return out


def _model_parameters(config, kind, weave, options):
    """The parameter names of ``kind`` built on ``weave`` (None when it cannot be built: the fit says why)."""
    from clothlab.config.build import model_from_weave
    from clothlab.errors import ClothlabError

    try:
        model = model_from_weave(weave, config.base_dir, kind=kind, quadrature=config.model.quadrature,
                                 options=options)
    except (ClothlabError, TypeError, ValueError):
        return None
    return {getattr(p, "name", p) for p in model.params}


def candidate_config(config, candidate: Candidate, *, max_evals: int, cv_folds: int, name: str | None = None,
                     start: dict | None = None, optimizer=None, posterior=None, orientation: float = 0.0):
    """``config`` turned into the fit of ``candidate`` (module docstring): kind, weave, free parameters
    (:func:`map_free`), loss, starts and bounds (``orientation``: the start, the box one period about it);
    budget ``max_evals`` (one start, polish max_evals // 4) unless ``optimizer`` is given; CV ``cv_folds``; no
    posterior unless given."""
    cls = model_class(candidate.kind)
    specular = cls.options_class()  # a composite passes the options to its specular part
    options = dict(config.model.options) if cls.kind == config.model.kind or \
        specular is model_class(config.model.kind) else {}
    table = cls.declared_parameters(config.model.options if cls.kind == config.model.kind else {})
    free, _ = map_free(candidate.kind, config.fit.free, config.model.options if cls.kind == config.model.kind
                       else {})
    if not free:  # config validation's rule (kind neural: the parameters its network was trained over)
        free = list(default_free(specular, options))
    # what the kind adds to its specular part brings its own defaults: a composite's diffuse term (sigma), a
    # physics term (sheen.r, smith.alpha: clothlab.models.composite.terms); nothing for a single model
    free += [n for n in cls.default_free if n not in specular.default_free and n not in free and n in table]
    built = _model_parameters(config, candidate.kind, candidate.weave, tuple(sorted(options.items())))
    if built is not None:  # e.g. Kang declares the parameters of the yarn kinds the weave has
        free = [n for n in free if n in built]
    params = {k: v for k, v in config.model.params.items() if k in table and k != ORIENTATION}
    bounds = {k: v for k, v in config.fit.bounds.items() if k in free}
    if candidate.orientation_start is not None:
        free.append(ORIENTATION)
        half = 0.5 * table[ORIENTATION].period
        params[ORIENTATION] = float(orientation)
        if params[ORIENTATION] + half > table[ORIENTATION].valid[1]:  # a full-turn kind's scan start above 180
            params[ORIENTATION] -= 2.0 * half  # one period down: the same orientation, its box inside [-360, 360]
        bounds[ORIENTATION] = (params[ORIENTATION] - half, params[ORIENTATION] + half)
    if start:
        params.update({k: float(v) for k, v in start.items() if k in free})
    if optimizer is None:
        optimizer = replace(config.fit.optimizer, max_evals=int(max_evals), starts=1, polish=int(max_evals) // 4)
    model = replace(config.model, kind=candidate.kind, weave=candidate.weave, params=params, options=options)
    loss = candidate.loss or config.fit.loss
    scale = candidate.loss_scale if candidate.loss_scale is not None else config.fit.loss_scale
    fit = replace(config.fit, free=tuple(free), bounds=bounds, optimizer=optimizer, posterior=posterior,
                  cv_folds=int(cv_folds), loss=loss, loss_scale=float(scale))
    return replace(config, name=name or config.name, model=model, fit=fit)


def fit_candidate(task: CandidateTask) -> CandidateResult:
    """Fit one candidate (an independent task: nothing shared with other candidates) and summarise it as a
    table row; a candidate that cannot be fitted (e.g. an invalid geometry) becomes a row with its reason."""
    from clothlab.errors import ClothlabError
    from clothlab.fit.runner import run_fit

    cand = task.candidate
    started = time.perf_counter()
    row = {c: None for c in TABLE_COLUMNS}
    row.update(candidate=cand.name, weave=cand.weave, kind=cand.kind, orientation_start=cand.orientation_start,
               loss=cand.loss or task.config.fit.loss,
               loss_scale=cand.loss_scale if cand.loss_scale is not None else task.config.fit.loss_scale)
    try:
        cfg = candidate_config(task.config, cand, max_evals=task.max_evals, cv_folds=task.cv_folds)
        if cand.orientation_start is not None:
            starts = orientation_scan(cfg, task.measurement, cand.orientation_start)
            row["orientation_start"] = starts[min(cand.orientation_start, len(starts)) - 1]
            cfg = candidate_config(task.config, cand, max_evals=task.max_evals, cv_folds=task.cv_folds,
                                   orientation=row["orientation_start"])
        row["free"] = " ".join(cfg.fit.free)
        result = run_fit(replace(cfg, fit=replace(cfg.fit, cv_folds=0)), measurement=task.measurement,
                         posterior_progress=False)
        if task.cv_folds >= 2:
            result.cross_validation = _candidate_cv(result, cfg)
    except ClothlabError as exc:
        row.update(note=f"not fitted: {exc}", wall_time_s=time.perf_counter() - started)
        return CandidateResult(cand, row)
    problem = result.problem
    n = int(problem.y.size)
    k = len(problem.free) + int(np.asarray(result.solution.coefficients).size)
    from clothlab.fit.metrics import metric_residuals

    squared = float(np.mean(metric_residuals(problem.y, result.solution.prediction, problem.metric) ** 2))
    aic, bic = information_criteria(squared, n, k)  # F: mean squared metric residual whatever the loss
    params = dict(result.params)
    period = problem.model.fit_period(params)
    if ORIENTATION in problem.free and period:
        params[ORIENTATION] = wrap(params[ORIENTATION], -0.5 * period, period)
    cv = result.cross_validation or {}
    held = cv.get("held_out") or {}
    errors = result.errors["overall"]
    notes = [w for w in result.warnings if "ended at its" in w]
    from clothlab.fit.determined import flag_text, not_determined

    flags = not_determined(_fit_like(result))
    if flags:
        notes.append(flag_text(flags))
    row.update(orientation=params.get(ORIENTATION), cv_mean=held.get("mean"), cv_p50=held.get("p50"),
               cv_p80=held.get("p80"), in_sample_p50=errors.get("p50"), in_sample_p80=errors.get("p80"),
               objective=float(result.optimum.fun), n=n, k=k, aic=aic, bic=bic, cv_scheme=cv.get("scheme"),
               evaluations=int(result.optimum.nevals), wall_time_s=time.perf_counter() - started,
               note="; ".join(([cv["failed"]] if cv.get("failed") else []) + notes) or None)
    held_out = None
    if task.held_out is not None:  # the outer fold's rows, never seen by this fit (clothlab.fit.nested)
        train = problem.solve(result.params)
        held_out = problem.designs([result.params], wi=task.held_out.wi, wo=task.held_out.wo)[0] @ train.coefficients
    return CandidateResult(cand, row, params={n_: float(params[n_]) for n_ in problem.free}, free=problem.free,
                           period=float(period), held_out=held_out)


def _candidate_cv(result, cfg) -> dict:
    """The candidate's cross-validation: each fold repeats the candidate's own search (neutral refit from its
    start values with the candidate budget ``select.max_evals``, :mod:`clothlab.fit.crossval`), so the score
    is that of the procedure the candidate ran - not of a longer search (a plain fit's CV refits with
    :data:`clothlab.fit.crossval.NEUTRAL_EVALS`).  Data too few for the folds: a ``failed`` entry."""
    from clothlab.fit import crossval

    opt = cfg.fit.optimizer
    try:
        return crossval.cross_validate(result.problem, result.params, k=cfg.fit.cv_folds, seed=opt.seed,
                                       percentiles=cfg.report.percentiles, scheme=cfg.fit.cv_scheme,
                                       refit=cfg.fit.cv_refit, optimizer=opt, max_evals=opt.max_evals)
    except crossval.CrossValidationError as exc:
        return {"k": cfg.fit.cv_folds, "failed": str(exc)}


def _fit_like(result) -> dict:
    """The parts of fit.json :func:`clothlab.fit.determined.not_determined` reads, from a FitResult."""
    problem = result.problem
    params = {name: {"value": float(result.params[name]), "lower": float(lo), "upper": float(hi), "free": True,
                     "transform": spec.transform}
              for name, lo, hi, spec in zip(problem.free, problem.lower, problem.upper, problem.specs, strict=True)}
    coefficients = {name: {str(i): float(v) for i, v in enumerate(np.atleast_1d(c))}
                    for name, c in result.coefficients.items()}
    return {"parameters": params, "coefficients": coefficients, "uncertainty": result.uncertainty or {}}


def rank(results: list[CandidateResult]) -> list[CandidateResult]:
    """``results`` ordered by :data:`RANKING`; each row gets its ``rank`` (1 = winner; unfitted rows last)."""
    def key(r):
        row = r.row
        fitted = row["objective"] is not None
        cv = row["cv_mean"]
        return (not fitted, cv is None, cv if cv is not None else 0.0, row["bic"] if fitted else 0.0)

    ordered = sorted(results, key=key)
    for i, r in enumerate(ordered, 1):
        r.row["rank"] = i
    return ordered


@dataclass
class Selection:
    """The outcome of :func:`select`: ranked candidate results, the winner's refit (a FitResult), settings."""

    ranked: list
    winner: object
    settings: SelectConfig
    wall_time: float
    nested: dict | None = None  # fit.json selection.nested (clothlab.fit.nested)
    free_by_kind: dict = field(default_factory=dict)  # kind -> {fit.free name: what it became} (map_free)
    refit: dict | None = None  # the winner's refit against its candidate row (refit_check)
    stability: dict | None = None  # fit.json selection.stability (clothlab.fit.stability)
    top_residuals: list = field(default_factory=list)  # residual diagnostics of the top candidates

    def summary(self) -> dict:
        return selection_summary(self)


def selection_summary(selection: Selection) -> dict:
    """fit.json ``selection``: the ranked table rows (``candidates``; the first is the winner), the ranking
    rule, the likelihood note, the candidates' budget and what was tried."""
    s = selection.settings
    return {"candidates": [dict(r.row) for r in selection.ranked], "winner": selection.ranked[0].row["candidate"],
            "ranking": RANKING, "information_criteria": LIKELIHOOD,
            "budget": {"max_evals": s.max_evals, "starts": 1, "polish": s.max_evals // 4, "cv_folds": s.cv_folds},
            "tried": {"weaves": list(weaves_of(s)), "kinds": list(s.kinds), "orientation_starts": s.orientation_starts,
                      **({"losses": list(s.losses)} if s.losses else {}),
                      **({"loss_scales": list(s.loss_scales)} if s.loss_scales else {})},
            "free_by_kind": selection.free_by_kind, "refit": selection.refit,
            "files": ["selection.csv", "selection.md"], "wall_time_s": selection.wall_time,
            **({"nested": selection.nested} if selection.nested else {}),
            **({"stability": selection.stability} if selection.stability else {}),
            **({"top_residuals": selection.top_residuals} if selection.top_residuals else {})}


def select(config, settings: SelectConfig | None = None, *, measurement=None, run_task=None,
           posterior=None, fits_dir=None, runner=None) -> Selection:
    """Fit every candidate (``run_task``, default :func:`fit_candidate`, maps one task to its result: the
    place for a parallel scheduler), rank them, refit the winner with ``config``'s own budget, CV and
    posterior (or ``posterior`` given here) and return the :class:`Selection`.  Progress: one line per
    candidate.  ``runner`` (:class:`clothlab.parallel.Runner`, e.g. Dask workers): the candidates as one task
    each, results in candidate order, identical to the in-process loop."""
    from clothlab.errors import ConfigError
    from clothlab.fit.runner import run_fit
    from clothlab.io.loader import load_measurement

    started = time.perf_counter()
    settings = settings or config.select
    if measurement is None:
        measurement = load_measurement(config.measurement.path, None if config.measurement.format == "auto"
                                       else config.measurement.format, **config.measurement.options)
    run_task = run_task or fit_candidate
    free_by_kind = free_mapping(config, settings.kinds)  # an unmappable fit.free name: an error before any fit
    tasks = [CandidateTask(config, c, settings.max_evals, settings.cv_folds, measurement)
             for c in candidates(settings, measurement.isotropic)]
    if not tasks:
        raise ConfigError("no candidates: select.weaves and select.kinds must each name at least one",
                          field="select")
    def logged(i, result) -> None:
        row = result.row
        log.info("select: candidate %d/%d %s: cv mean %s, BIC %s%s", i, len(tasks), row["candidate"],
                 _short(row["cv_mean"]), _short(row["bic"]), f" ({row['note']})" if row["note"] else "")

    if runner is not None:
        from clothlab.parallel.runner import raise_failures

        results = raise_failures(runner.map(run_task, tasks, names=[t.candidate.name for t in tasks],
                                            desc="select: candidates"), "candidate fits")
        for i, result in enumerate(results, 1):
            logged(i, result)
    else:
        results = []
        with Progress(len(tasks), "select: candidates", unit="fit") as bar:
            for i, task in enumerate(tasks, 1):
                results.append(run_task(task))
                logged(i, results[-1])
                bar.update(1)
    ranked = rank(results)
    best = ranked[0]
    if best.row["objective"] is None:
        raise ConfigError(f"no candidate could be fitted: {best.row['note']}", field="select")
    log.info("select: winner %s; refitting with the full budget", best.row["candidate"])
    winner_cfg = candidate_config(config, best.candidate, max_evals=config.fit.optimizer.max_evals,
                                  cv_folds=config.fit.cv_folds, start=best.params, optimizer=config.fit.optimizer,
                                  posterior=posterior or config.fit.posterior,
                                  orientation=best.params.get(ORIENTATION, 0.0))  # its box centred there
    nested = None
    if settings.nested >= 2:  # the whole selection again inside each outer fold (clothlab.fit.nested)
        from clothlab.fit.nested import nested_cross_validation, nested_lines

        log.info("select: nested cross-validation, %d outer folds x %d candidates", settings.nested, len(tasks))
        nested = nested_cross_validation(
            config, measurement, settings.nested, candidate_list=[t.candidate for t in tasks],
            make_task=lambda fold, c, train, held: CandidateTask(config, c, settings.max_evals, settings.cv_folds,
                                                                 train, held_out=held, outer_fold=fold),
            run_task=run_task, rank=rank, runner=runner, full_winner=best.row)
        for line in nested_lines(nested):
            log.info("select: %s", line.strip())
    top = top_residuals(config, ranked, measurement)
    stab = None
    if settings.stability >= 1:  # the selection on seeded subsamples of the rows (clothlab.fit.stability)
        from clothlab.fit.stability import stability, stability_lines

        log.info("select: stability, %d subsamples x %d candidates", settings.stability, len(tasks))
        stab = stability(measurement, settings.stability, seed=config.fit.optimizer.seed,
                         candidate_list=[t.candidate for t in tasks],
                         make_task=lambda b, c, rows: CandidateTask(config, c, settings.max_evals, settings.cv_folds,
                                                                    rows),
                         run_task=run_task, rank=rank, runner=runner, nested=nested,
                         periods={k: orientation_span(k) for k in settings.kinds})
        for line in stability_lines(stab):
            log.info("select: %s", line.strip())
    winner = run_fit(winner_cfg, measurement=measurement, fits_dir=fits_dir, runner=runner)
    refit = refit_check(best.row, winner)
    if not refit["not_worse"]:
        winner.warnings.append(refit["note"])
    return Selection(ranked, winner, settings, time.perf_counter() - started, nested=nested,
                     free_by_kind=free_by_kind, refit=refit, stability=stab, top_residuals=top)


TOP = 5


def top_residuals(config, ranked, measurement, top: int = TOP) -> list[dict]:
    """The residual diagnostics (:mod:`clothlab.fit.residuals`) of the ``top`` fitted candidates at their
    candidate optima on all rows: where each one's p80 tail lies and its biases, as
    ``[{"candidate", "summary", "enriched", "tail_threshold"}]`` (one model evaluation each)."""
    from clothlab.errors import ClothlabError
    from clothlab.fit.problem import build_problem
    from clothlab.fit.residuals import diagnostics, summary_sentence

    out = []
    for r in [r for r in ranked if r.row.get("objective") is not None][:top]:
        try:
            cfg = candidate_config(config, r.candidate, max_evals=1, cv_folds=0, start=r.params,
                                   orientation=r.params.get(ORIENTATION, 0.0))
            problem = build_problem(cfg, measurement)
            prediction = problem.solve(problem.model.resolve({**problem.start, **r.params})).prediction
        except ClothlabError as exc:
            out.append({"candidate": r.row["candidate"], "summary": f"not evaluated: {exc}"})
            continue
        m = problem.measurement
        d = diagnostics(m.theta_i, m.phi_i, m.theta_o, m.phi_o, m.values, prediction)
        out.append({"candidate": r.row["candidate"], "summary": summary_sentence(d), "enriched": d["enriched"],
                    "tail_threshold": d["tail_threshold"],
                    "bias": {name: [b["median_r"] for b in f["bins"]] for name, f in d["features"].items()}})
    return out


def refit_check(row: dict, winner) -> dict:
    """The winner's refit against its candidate row: it starts at the candidate's optimum (which its search
    screens first, :func:`clothlab.fit.optimize.multistart_minimize`), so its objective is never larger; the
    in-sample percentiles are listed beside (they need not order as the objective does)."""
    errors = winner.errors["overall"]
    fun = float(winner.optimum.fun)
    worse = row.get("objective") is not None and fun > float(row["objective"]) * (1.0 + 1e-9)
    out = {"candidate_objective": row.get("objective"), "refit_objective": fun, "not_worse": not worse,
           "candidate_in_sample": {"p50": row.get("in_sample_p50"), "p80": row.get("in_sample_p80")},
           "refit_in_sample": {"p50": errors.get("p50"), "p80": errors.get("p80")}}
    out["note"] = (f"the winner's refit objective {fun:.6g} is WORSE than its candidate row's "
                   f"{row.get('objective'):.6g}" if worse else
                   f"the winner's refit objective {fun:.6g} <= its candidate row's {row.get('objective'):.6g}")
    return out


def _short(value) -> str:
    return "-" if value is None else f"{value:.4g}"


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def table_columns(selection: Selection) -> dict:
    """The comparison table as columns (for selection.csv)."""
    return {c: [_cell(r.row[c]) for r in selection.ranked] for c in TABLE_COLUMNS}


DISPLAY_HEAD = ("rank", "candidate", "orientation (deg)", "CV mean %", "CV p50 %", "CV p80 %", "p50 %", "p80 %",
                "k", "AIC", "BIC", "free", "note")


def display_rows(rows) -> list[tuple[str, ...]]:
    """The comparison table's cells under :data:`DISPLAY_HEAD` (errors in %), one tuple of strings per row dict
    of :data:`TABLE_COLUMNS` (a :class:`Selection`'s rows or fit.json ``selection.candidates``; missing
    entries are blank)."""
    def pct(v):
        return "" if v is None else f"{100.0 * v:.2f}"

    def num(v, digits):
        return "" if v is None else f"{v:.{digits}f}"

    return [(str(row.get("rank", "")), str(row.get("candidate", "")), num(row.get("orientation"), 2),
             pct(row.get("cv_mean")), pct(row.get("cv_p50")), pct(row.get("cv_p80")), pct(row.get("in_sample_p50")),
             pct(row.get("in_sample_p80")), "" if row.get("k") is None else str(row["k"]), num(row.get("aic"), 1),
             num(row.get("bic"), 1), str(row.get("free") or ""), str(row.get("note") or "")) for row in rows]


def free_mapping_lines(free_by_kind: dict) -> list[str]:
    """fit.free names a kind does not declare and what each became there (:func:`concepts`), as text lines."""
    lines = []
    for kind, mapping in (free_by_kind or {}).items():
        if mapping:
            parts = [f"{name} -> {', '.join(t) if t else 'none (no counterpart)'}" for name, t in mapping.items()]
            lines.append(f"- {kind}: " + "; ".join(parts))
    return (["", "fit.free mapped per kind (names the kind does not declare):"] + lines) if lines else []


def table_markdown(selection: Selection) -> str:
    """The comparison table as markdown (errors in %), with the ranking rule and the likelihood note."""
    lines = [f"# Model selection: {selection.winner.config.name}", "",
             f"Ranked by {RANKING}.  {LIKELIHOOD}.", "",
             "| " + " | ".join(DISPLAY_HEAD) + " |", "|" + "---|" * len(DISPLAY_HEAD)]
    for cells in display_rows(r.row for r in selection.ranked):
        lines.append("| " + " | ".join(c.replace("|", "/") for c in cells) + " |")
    lines += free_mapping_lines(selection.free_by_kind)
    if selection.refit:
        lines += ["", f"Refit of the winner with the full budget: {selection.refit['note']}."]
    if selection.top_residuals:
        lines += ["", f"Residual diagnostics of the top {len(selection.top_residuals)} candidates "
                      "(clothlab.fit.residuals, at their candidate optima):"]
        lines += [f"- {t['candidate']}: {t['summary']}" for t in selection.top_residuals]
    if selection.nested:
        from clothlab.fit.nested import nested_lines

        lines += [""] + nested_lines(selection.nested)
    if selection.stability:
        from clothlab.fit.stability import stability_lines

        lines += [""] + stability_lines(selection.stability)
    return "\n".join(lines) + "\n"


def save_selection(selection: Selection, *, force: bool = False, fits_dir=None):
    """Write the winner's fit directory (as :func:`clothlab.fit.store.save_fit`, with fit.json ``selection``
    and ``selection.csv``) and ``selection.md`` in it; returns the directory."""
    from clothlab.atomic import atomic_write_text
    from clothlab.fit.store import (
        check_finite_result,
        checkpoint_path,
        fit_summary,
        posterior_files,
        prediction_table,
        slice_table,
        trace_table,
        write_fit_directory,
    )
    from clothlab.weave.wvformat import format_wv

    result = selection.winner
    cfg = result.config
    dest = (fits_dir if fits_dir is not None else cfg.output.fits) / cfg.name
    predictions = prediction_table(result)
    check_finite_result(result, predictions)
    fit = fit_summary(result)
    fit["selection"] = selection_summary(selection)
    extra = {**posterior_files(result), "selection.csv": table_columns(selection)}
    out = write_fit_directory(dest, fit=fit, predictions=predictions, slices=slice_table(result),
                              trace=trace_table(result),
                              config_text=cfg.path.read_text() if cfg.path is not None else None,
                              weave_text=format_wv(result.problem.model.fitted_weave(result.params)), extra=extra,
                              force=force)
    atomic_write_text(out / "selection.md", table_markdown(selection))
    if result.posterior is not None:  # as save_fit: the directory holds the result, the checkpoint has served
        checkpoint_path(cfg, fits_dir).unlink(missing_ok=True)
    return out


__all__ = ["concepts", "map_free", "free_mapping",
           "ALL_PRESETS", "Candidate", "CandidateResult", "CandidateTask", "SelectSettings", "Selection",
           "candidate_config",
           "candidates", "fit_candidate", "information_criteria", "rank", "save_selection",
           "select", "selection_summary", "settings_from_config", "check_settings", "table_columns", "table_markdown",
           "weaves_of"]
