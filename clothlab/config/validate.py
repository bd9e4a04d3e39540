"""The rules of fabric.yaml: every key, type, range and cross-field constraint, checked section by section.

:func:`load_config` reads a fabric.yaml (:func:`clothlab.config.linemap.load_yaml_with_lines`), checks it and
returns a frozen :class:`~clothlab.config.schema.Config`; :func:`config_from_dict` checks a Python mapping
the same way.  Every mistake raises :class:`~clothlab.errors.ConfigError` naming the file, the line, the
dotted field (``fit.optimizer.max_evals``), the value found and what was expected.  Model parameter values
and bounds are checked against the model's one declaration of each parameter (for the Irawan-Marschner
model the physical ranges of Irawan & Marschner 2012, Table I); the closed lists of choices are imported
from the modules that own them.  Relative paths (``measurement.path``, a ``.wv`` weave file, ``output.*``)
are relative to the yaml's directory; when ``output`` is absent, results go to ``fits/`` and ``reports/``
under the current directory.

Why not pydantic (v2): its errors can name the file, line and dotted field - an error's ``loc`` is the key
path, which a :class:`~clothlab.config.linemap.LineMap` turns into a line - but only for checks of one
field.  A rule that relates fields (the start value against the fit bounds, ``walkers >= 2 x`` the free
parameters, ``starts <= max_evals``, G_MLSL_LDS with a local polish, parameter names checked against the
table of the ``kind`` chosen in the same file) runs in a model validator, and pydantic reports its error at
the enclosing model (``fit.optimizer``, the line of the section) instead of the field at fault
(``fit.optimizer.local``, the line of the value).  Keeping today's messages - the value with its YAML type,
"did you mean", the allowed range - would also need a custom validator per field, so the rules would be
written twice, once as annotations and once as functions.  The schema stays plain frozen dataclasses and the
rules stay here, in one place.
"""

from __future__ import annotations

import copy
import os
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

from clothlab.config.checks import (
    Location,
    as_choice,
    as_cli_int,
    as_int,
    as_list,
    as_number,
    as_str,
    check_plain_data,
    shown,
    suggest,
)
from clothlab.config.choices import (
    CV_REFITS,
    CV_SCHEMES,
    GLOBAL_ALGORITHMS,
    LOCAL_ALGORITHMS,
    LOSSES,
    METRICS,
    MLSL_LOCAL,
    NEEDS_LOCAL,
    START_DESIGNS,
)
from clothlab.config.linemap import LineMap, dotted, load_yaml_with_lines
from clothlab.config.schema import (
    DEFAULT_MAX_STEPS,
    DEFAULT_PERCENTILES,
    DEFAULT_STEPS,
    DEFAULT_WALKERS,
    PRESET_PREFIX,
    Config,
    FitConfig,
    MeasurementConfig,
    ModelConfig,
    OptimizerConfig,
    OutputConfig,
    PosteriorConfig,
    ReportConfig,
    SelectConfig,
)
from clothlab.errors import ConfigError, InputError, ParameterError
from clothlab.io.loader import check_reader_options
from clothlab.models.base import ORIENTATION
from clothlab.models.irawan.quadrature import RULES, Quadrature
from clothlab.models.registry import (
    MODEL_KINDS,
    WEAVE_STAND_IN,
    check_model_options,
    model_class,
    model_options,
    needs_weave,
)

NAME_PATTERN = re.compile(r"[A-Za-z0-9._-]+")
MAX_NAME_CHARS = 200
MAX_EVALS = 2**31 - 1
"""Most optimiser evaluations of a fit or a candidate (``fit.optimizer.max_evals``, ``--max-evals``,
``select.max_evals``): nlopt's maxeval is a C int.  A budget is an upper bound, not an allocation: the search
stops at convergence (the fits here use 2,000-20,000)."""
MAX_CV_FOLDS = 100_000
"""Most cross-validation folds (``fit.cv_folds``, ``select.cv_folds``; as ``--cv``): each fold is a refit."""
MAX_WALKERS = 4096
"""Most emcee walkers of the posterior (``fit.posterior.walkers``)."""
MAX_POSTERIOR_STEPS = 1_000_000
"""Most posterior steps (``fit.posterior.steps`` and ``max_steps``): a chain of 32 walkers and 6 parameters
at this cap holds 1.5 GB."""
MAX_CHAIN_BYTES = 2 << 30
"""Largest posterior chain kept in memory: max_steps x walkers x (free parameters + 1 noise scale) float64."""
MAX_ORIENTATION_AVERAGE = 1024  # orientations of the isotropic average (each one model evaluation)
SEED_RANGE = (0, 2**32 - 1)  # what nlopt.srand and numpy's legacy seeding both accept
LOSS_SCALE_RANGE = (1e-9, 1e9)  # fit.loss_scale, the metric's units (a denormal scale overflows r / s)


class _Validator:
    """The rules of each section; builds the :class:`Config` of one document or mapping."""

    def __init__(self, data: Any, lines: LineMap, base_dir: Path, path: Path | None):
        self.data = data
        self.lines = lines
        self.source = lines.source
        self.base_dir = base_dir
        self.path = path

    # -- helpers --------------------------------------------------------------------------------------------

    def at(self, path: tuple, key: bool = False) -> Location:
        """The location of the value at ``path`` (of its key with ``key=True``)."""
        return Location(self.source, dotted(path), self.lines.line(path, key=key))

    def section(self, value: Any, path: tuple, keys, required=()) -> dict:
        """Check that ``value`` is a mapping with only ``keys`` and all of ``required``; return it."""
        if not isinstance(value, dict):
            raise self.at(path).error(f"expected a mapping, got {shown(value)}")
        for key in value:
            if key not in keys:
                raise self.at(path + (key,), key=True).error(
                    f"unknown key '{key}'{suggest(key, keys)}; allowed here: {', '.join(keys)}"
                )
        for key in required:
            if key not in value:
                where = self.at(path, key=True)
                raise ConfigError(f"missing required key '{key}'", path=where.source, line=where.line,
                                  field=dotted(path + (key,)))
        return value

    def resolve(self, written: str, at: Location) -> Path:
        """``written`` relative to the yaml's directory ('~' expanded), normalised but not symlink-resolved."""
        if not written or "\0" in written:
            raise at.error(f"expected a path, got {written!r}")
        try:
            expanded = Path(written).expanduser()
        except RuntimeError as exc:  # '~user' with an unknown user
            raise at.error(f"cannot expand {written!r}: {exc}") from None
        return Path(os.path.normpath(self.base_dir / expanded))

    @staticmethod
    def is_there(path: Path, need_file: bool) -> bool:
        try:
            return path.is_file() if need_file else path.exists()
        except (OSError, ValueError):  # e.g. a name too long for the file system
            return False

    # -- sections -------------------------------------------------------------------------------------------

    def config(self) -> Config:
        top = self.data
        if not isinstance(top, dict):
            found = "an empty document" if top is None else shown(top)
            raise ConfigError(f"expected a mapping of settings (name:, measurement:, ...), got {found}",
                              path=self.source, line=self.lines.line(()))
        self.section(top, (), ("name", "measurement", "model", "fit", "report", "output", "select"),
                     required=("name", "measurement"))
        name = as_str(top["name"], self.at(("name",)))
        if len(name) > MAX_NAME_CHARS:
            raise self.at(("name",)).error(
                f"the name has {len(name)} characters; at most {MAX_NAME_CHARS} (it names the fits/ and reports/ "
                "directories and their hidden siblings, within the file system's 255-byte limit)")
        if not NAME_PATTERN.fullmatch(name) or name in (".", ".."):
            raise self.at(("name",)).error(
                f"{name!r} is not a valid name: use letters, digits, '.', '_' and '-' only "
                "(it names the fits/ and reports/ directories)"
            )
        measurement = self.measurement(top["measurement"])
        model = self.model(top.get("model", {}))
        fit = self.fit(top.get("fit", {}), model)
        if ORIENTATION in fit.free and ORIENTATION not in model.params:  # listed only when given: start at 0
            model = replace(model, params={**model.params, ORIENTATION: 0.0})
        report = self.report(top.get("report", {}))
        output = self.output(top.get("output", {}))
        select = self.select(top.get("select", {}) or {})
        return Config(name=name, path=self.path, base_dir=self.base_dir, measurement=measurement,
                      model=model, fit=fit, report=report, output=output, raw=copy.deepcopy(top),
                      source=self.source, select=select)

    def select(self, value: Any) -> SelectConfig:
        """``select``: weaves (preset:<name> or .wv files), kinds, orientation_starts, max_evals, cv_folds, and
        the checks on top: nested (outer folds), losses, loss_scales, stability (subsamples) - the bounds of the
        CLI's --nested, --losses, --loss-scales and --stability."""
        p = ("select",)
        s = self.section(value, p, ("weaves", "kinds", "orientation_starts", "max_evals", "cv_folds", "nested",
                                    "losses", "loss_scales", "stability"))
        d = SelectConfig()
        weaves = tuple(self.weave(w, self.at(p + ("weaves", i)))
                       for i, w in enumerate(as_list(s.get("weaves", []), self.at(p + ("weaves",)))))
        if "weaves" in s and not weaves:  # absent = every shipped preset; an empty list says nothing to try
            raise self.at(p + ("weaves",)).error("expected at least one weave (preset:<name>, pattern:<name> or a "
                                                 ".wv file), got []; leave select.weaves out to try every preset")
        kinds = tuple(as_choice(k, self.at(p + ("kinds", i)), MODEL_KINDS)
                      for i, k in enumerate(as_list(s.get("kinds", list(d.kinds)), self.at(p + ("kinds",)))))
        if not kinds:
            raise self.at(p + ("kinds",)).error("expected at least one model kind, got []")
        self._once_each(p, (("weaves", weaves), ("kinds", kinds)))  # a candidate fitted twice ranks against itself
        starts = as_int(s.get("orientation_starts", d.orientation_starts), self.at(p + ("orientation_starts",)), 1, 8)
        max_evals = as_int(s.get("max_evals", d.max_evals), self.at(p + ("max_evals",)), 1, MAX_EVALS)
        cv_folds = as_int(s.get("cv_folds", d.cv_folds), self.at(p + ("cv_folds",)), 0, MAX_CV_FOLDS)
        if cv_folds == 1:
            raise self.at(p + ("cv_folds",)).error("expected 0 (no cross-validation) or at least 2 folds, got 1")
        nested = as_int(s.get("nested", d.nested), self.at(p + ("nested",)), 0, 100)
        if nested == 1:
            raise self.at(p + ("nested",)).error("expected 0 (no nested cross-validation) or at least 2 outer "
                                                 "folds, got 1")
        losses = tuple(as_choice(k, self.at(p + ("losses", i)), LOSSES)
                       for i, k in enumerate(as_list(s.get("losses", list(d.losses)), self.at(p + ("losses",)))))
        scales = tuple(self._loss_scale(x, self.at(p + ("loss_scales", i))) for i, x in
                       enumerate(as_list(s.get("loss_scales", list(d.loss_scales)), self.at(p + ("loss_scales",)))))
        self._once_each(p, (("losses", losses), ("loss_scales", scales)))
        stability = as_int(s.get("stability", d.stability), self.at(p + ("stability",)), 0, 1000)
        return SelectConfig(weaves, kinds, starts, max_evals, cv_folds, nested, losses, scales, stability)

    def _once_each(self, p: tuple, lists) -> None:
        """ConfigError at the second entry of any (key, items) list that names an item twice."""
        for key, items in lists:
            for i, item in enumerate(items):
                if item in items[:i]:
                    raise self.at(p + (key, i)).error(f"{item!r} is listed twice (as entry {items.index(item)})")

    @staticmethod
    def _loss_scale(value: Any, at) -> float:
        """A huber / cauchy scale in :data:`LOSS_SCALE_RANGE` (the metric's units): ``fit.loss_scale`` and the
        entries of ``select.loss_scales``."""
        scale = as_number(value, at)
        if not LOSS_SCALE_RANGE[0] <= scale <= LOSS_SCALE_RANGE[1]:
            lo, hi = LOSS_SCALE_RANGE
            raise at.error(f"expected a scale in [{lo:g}, {hi:g}] (the metric's units, e.g. 0.1 = 10 %), got {scale:g}")
        return scale

    def measurement(self, value: Any) -> MeasurementConfig:
        p = ("measurement",)
        m = self.section(value, p, ("path", "format", "options"), required=("path",))
        written = as_str(m["path"], self.at(p + ("path",)))
        resolved = self.resolve(written, self.at(p + ("path",)))
        if not self.is_there(resolved, need_file=False):
            raise self.at(p + ("path",)).error(
                f"measurement not found: {resolved} (from {written!r}, relative to {self.base_dir})"
            )
        fmt = as_choice(m.get("format", MeasurementConfig.format), self.at(p + ("format",)), _format_choices())
        options = m.get("options", {})
        if options is None:
            options = {}
        if not isinstance(options, dict):
            raise self.at(p + ("options",)).error(f"expected a mapping, got {shown(options)}")
        check_plain_data(options, self.at(p + ("options",)))
        self.reader_options(resolved, fmt, options, p + ("options",))
        return MeasurementConfig(path=resolved, format=fmt, options=copy.deepcopy(options))

    def reader_options(self, path: Path, fmt: str, options: dict, p: tuple) -> None:
        """``measurement.options`` checked against the reader of the (given or detected) format, at their
        lines in fabric.yaml."""
        if not options:
            return
        try:
            check_reader_options(path, fmt, options)
        except InputError as exc:
            if exc.field in options:
                where = self.at(p + (exc.field,))
                raise ConfigError(exc.detail, path=where.source, line=where.line,
                                  field=dotted(p + (exc.field,))) from None
            # the measurement itself is unreadable: loading it reports that, naming the file

    def model_options(self, kind: str, options: dict, p: tuple) -> dict:
        """``model.options``: each value of the type of its default where it has one (the YAML's types), then
        the registry's one check of the options (:func:`clothlab.models.registry.check_model_options`) reported
        at their lines; options the model names in ``path_options`` (files) are resolved against the yaml's
        directory and must exist.  Returns the options so resolved."""
        declared = model_options(kind)
        for name, value in options.items():
            default, at = declared.get(name), self.at(p + (name,))
            if isinstance(default, bool):
                if not isinstance(value, bool):
                    raise at.error(f"expected true or false, got {shown(value)}")
            elif isinstance(default, int):
                as_int(value, at)
            elif isinstance(default, float):
                as_number(value, at)
            elif isinstance(default, str):
                as_str(value, at)
        try:
            check_model_options(kind, options)
        except ConfigError as exc:
            name = (exc.field or "").removeprefix("model.options.")
            if name in options and name not in declared:  # an unknown option: at its key, with a suggestion
                raise self.at(p + (name,), key=True).error(exc.detail + suggest(name, declared)) from None
            raise self.at(p + (name,) if name in options else p).error(exc.detail) from None
        resolved = copy.deepcopy(options)
        for name in model_class(kind).options_class().path_options:
            value, at = options.get(name), self.at(p + (name,))
            if value is not None:
                path = self.resolve(as_str(value, at), at)
                if not self.is_there(path, need_file=True):
                    raise at.error(f"file not found: {path} (from {value!r}, relative to {self.base_dir})")
                resolved[name] = str(path)
        return resolved

    def model(self, value: Any) -> ModelConfig:
        p = ("model",)
        m = self.section(value, p, ("kind", "weave", "quadrature", "params", "options"))
        kind = as_choice(m.get("kind", ModelConfig.kind), self.at(p + ("kind",)), MODEL_KINDS)
        weave = None
        if m.get("weave") is not None:
            weave = self.weave(m["weave"], self.at(p + ("weave",)))
        elif not needs_weave(kind):  # lambert, oren-nayar: the weave changes nothing; a stand-in is recorded
            weave = self.weave(WEAVE_STAND_IN, self.at(p, key=True))
        else:
            where = self.at(p, key=True)
            raise ConfigError(f"missing required key 'weave' (preset:<name> or a .wv file) for kind {kind}",
                              path=where.source, line=where.line, field="model.weave")
        q = self.section(m.get("quadrature", {}), p + ("quadrature",), ("rule", "nodes"))
        quadrature = checked_quadrature(q, self.at(p + ("quadrature", "rule")), self.at(p + ("quadrature", "nodes")))
        params = m.get("params", {}) or {}
        if not isinstance(params, dict):
            raise self.at(p + ("params",)).error(f"expected a mapping, got {shown(params)}")
        options = m.get("options", {}) or {}
        if not isinstance(options, dict):
            raise self.at(p + ("options",)).error(f"expected a mapping, got {shown(options)}")
        check_plain_data(options, self.at(p + ("options",)))
        options = self.model_options(kind, options, p + ("options",))
        table = self.declared(kind, options)
        if table is None:
            check_plain_data(params, self.at(p + ("params",)))
            checked = copy.deepcopy(params)
        else:
            checked = {}
            for name, v in params.items():
                at_key = self.at(p + ("params", name), key=True)
                self.known_parameter(name, table, at_key)
                at = self.at(p + ("params", name))
                as_number(v, at)
                checked[name] = _check_parameter(table, name, v, at)
        return ModelConfig(kind=kind, weave=weave, quadrature=quadrature, params=checked,
                           options=copy.deepcopy(options))

    def declared(self, kind: str, options: dict):
        """The parameter declarations of ``kind`` for these (resolved) ``model.options`` (e.g. kind neural:
        its network's target kind's); a ConfigError of the model is reported at the option it names."""
        try:
            return model_class(kind).declared_parameters(options)
        except ConfigError as exc:
            option = (exc.field or "").removeprefix("model.options.")
            at = self.at(("model", "options", option)) if option in options else self.at(("model", "options"))
            raise at.error(exc.detail) from None

    def weave(self, value: Any, at: Location) -> str:
        """``preset:<name>`` (spelled as clothlab.weave.presets accepts it) -> ``preset:<key>``; a .wv file ->
        its resolved path."""
        text = as_str(value, at).strip()
        if text.lower().startswith(PRESET_PREFIX):
            from clothlab.weave.presets import PRESET_NAMES, canonical_preset_name

            preset = text[len(PRESET_PREFIX):].strip()
            try:
                return PRESET_PREFIX + canonical_preset_name(preset)
            except ConfigError:
                raise at.error(f"unknown preset {preset!r}{suggest(preset, PRESET_NAMES)}; "
                               f"known presets: {', '.join(PRESET_NAMES)}") from None
        if text.lower().startswith("pattern:"):  # a generated pattern (clothlab.weave.patterns)
            from clothlab.weave.patterns import PATTERN_NAMES, PATTERN_PREFIX, get_pattern

            name = text[len(PATTERN_PREFIX):].strip()
            try:
                return PATTERN_PREFIX + get_pattern(name).name
            except ConfigError:
                raise at.error(f"unknown pattern {name!r}{suggest(name, PATTERN_NAMES)}; "
                               f"known patterns: {', '.join(PATTERN_NAMES)}") from None
        resolved = self.resolve(text, at)
        if not self.is_there(resolved, need_file=True):
            raise at.error(f"weave file not found: {resolved} (from {text!r}, relative to {self.base_dir}); "
                           f"give a .wv file or preset:<name>")
        return str(resolved)

    def known_parameter(self, name: Any, table, at: Location) -> str:
        if not isinstance(name, str) or name not in table:
            raise at.error(f"unknown parameter {name!r}{suggest(name, table.names())}; "
                           f"known: {', '.join(table.names())}")
        return name

    def fit(self, value: Any, model: ModelConfig) -> FitConfig:
        p = ("fit",)
        f = self.section(value, p, ("free", "bounds", "metric", "optimizer", "posterior", "cv_folds",
                                    "cv_scheme", "cv_refit", "loss", "loss_scale", "valid_geometry",
                                    "orientation_average"))
        table = self.declared(model.kind, model.options)
        free = self.free(f.get("free", list(default_free(model_class(model.kind), model.options))), table)
        bounds = self.bounds(f.get("bounds", {}) or {}, table, free, model.params)
        for name in free:  # explicit bounds were checked against the start above; the declared ones here
            if table is not None and name not in bounds and name in model.params:
                lo, hi = table[name].bounds
                if not lo <= model.params[name] <= hi:
                    raise self.at(("model", "params", name)).error(
                        f"start value {model.params[name]:g} of free parameter {name} lies outside its default fit "
                        f"bounds [{lo:g}, {hi:g}]; move it inside or set fit.bounds.{name}")
        metric = as_choice(f.get("metric", FitConfig.metric), self.at(p + ("metric",)), METRICS)
        optimizer = self.optimizer(f.get("optimizer", {}))
        posterior = self.posterior(f.get("posterior"), free)
        cv_folds = f.get("cv_folds", 0)
        at = self.at(p + ("cv_folds",))
        if cv_folds is None or cv_folds is False:
            cv_folds = 0
        as_int(cv_folds, at, 0, MAX_CV_FOLDS)
        if cv_folds == 1:
            raise at.error("expected 0 (no cross-validation) or at least 2 folds, got 1")
        cv_scheme = as_choice(f.get("cv_scheme", FitConfig.cv_scheme), self.at(p + ("cv_scheme",)), CV_SCHEMES)
        cv_refit = as_choice(f.get("cv_refit", FitConfig.cv_refit), self.at(p + ("cv_refit",)), CV_REFITS)
        loss = as_choice(f.get("loss", FitConfig.loss), self.at(p + ("loss",)), LOSSES)
        loss_scale = self._loss_scale(f.get("loss_scale", FitConfig.loss_scale), self.at(p + ("loss_scale",)))
        valid_geometry = f.get("valid_geometry", FitConfig.valid_geometry)
        if not isinstance(valid_geometry, bool):
            raise self.at(p + ("valid_geometry",)).error(f"expected true or false, got {shown(valid_geometry)}")
        orientation_average = f.get("orientation_average", FitConfig.orientation_average)
        as_int(orientation_average, self.at(p + ("orientation_average",)), 2, MAX_ORIENTATION_AVERAGE)
        return FitConfig(free=free, bounds=bounds, metric=metric, optimizer=optimizer, posterior=posterior,
                         cv_folds=cv_folds, cv_scheme=cv_scheme, cv_refit=cv_refit, loss=loss, loss_scale=loss_scale,
                         valid_geometry=valid_geometry, orientation_average=orientation_average)

    def free(self, value: Any, table) -> tuple:
        p = ("fit", "free")
        names = as_list(value, self.at(p))
        out: list[str] = []
        for i, name in enumerate(names):
            at = self.at(p + (i,))
            as_str(name, at)
            if table is not None:
                self.known_parameter(name, table, at)
            if name in out:
                raise at.error(f"parameter {name!r} is listed twice")
            out.append(name)
        return tuple(out)

    def bounds(self, value: Any, table, free: tuple, params: dict) -> dict:
        p = ("fit", "bounds")
        if not isinstance(value, dict):
            raise self.at(p).error(f"expected a mapping of parameter: [lower, upper], got {shown(value)}")
        out = {}
        for name, pair in value.items():
            key_at = self.at(p + (name,), key=True)
            if table is not None:
                self.known_parameter(name, table, key_at)
            if name not in free:
                raise key_at.error(f"bounds given for {name!r}, which is not in fit.free ({', '.join(free)})")
            at = self.at(p + (name,))
            if not isinstance(pair, list) or len(pair) != 2:
                raise at.error(f"expected [lower, upper], got {shown(pair)}")
            lo, hi = (as_number(x, self.at(p + (name, i))) for i, x in enumerate(pair))
            if table is not None:
                for i, x in enumerate(pair):
                    _check_parameter(table, name, x, self.at(p + (name, i)))
            if not lo < hi:
                raise at.error(f"lower bound must be below the upper bound, got [{lo:g}, {hi:g}]")
            if name in params and not lo <= params[name] <= hi:
                raise at.error(f"start value model.params.{name} = {params[name]:g} lies outside "
                               f"these bounds [{lo:g}, {hi:g}]")
            out[name] = (lo, hi)
        return out

    def optimizer(self, value: Any) -> OptimizerConfig:
        p = ("fit", "optimizer")
        o = self.section(value, p, ("global", "local", "max_evals", "seed", "max_time", "starts", "polish", "design",
                                    "box_check"))
        d = OptimizerConfig()
        g = as_choice(o.get("global", d.global_algorithm), self.at(p + ("global",)), GLOBAL_ALGORITHMS,
                      allow_null=True)
        loc = as_choice(o.get("local", d.local_algorithm), self.at(p + ("local",)), LOCAL_ALGORITHMS,
                        allow_null=True)
        if g is None and loc is None:
            raise self.at(p, key=True).error("global and local are both null: no optimiser would run")
        if g in NEEDS_LOCAL and loc is None:
            raise self.at(p + ("local",)).error(f"{g} needs a local polish after its {MLSL_LOCAL} multistart; "
                                                f"give one of {', '.join(LOCAL_ALGORITHMS)}")
        max_evals = as_int(o.get("max_evals", d.max_evals), self.at(p + ("max_evals",)), 1, MAX_EVALS)
        seed = as_int(o.get("seed", d.seed), self.at(p + ("seed",)), *SEED_RANGE)
        max_time = o.get("max_time")
        if max_time is not None:
            at = self.at(p + ("max_time",))
            max_time = as_number(max_time, at)
            if max_time <= 0:
                raise at.error(f"expected a positive number of seconds or null, got {max_time:g}")
        starts = as_int(o.get("starts", d.starts), self.at(p + ("starts",)), 1, 64)
        if starts > max_evals:
            raise self.at(p + ("starts",)).error(f"{starts} starts need at least as many evaluations; max_evals is "
                                                 f"{max_evals}")
        polish = o.get("polish")
        if polish is not None:
            polish = as_int(polish, self.at(p + ("polish",)), 0, MAX_EVALS)
        design = as_choice(o.get("design", d.design), self.at(p + ("design",)), START_DESIGNS)
        box_check = o.get("box_check", d.box_check)
        if not isinstance(box_check, bool):
            raise self.at(p + ("box_check",)).error(f"expected true or false, got {shown(box_check)}")
        return OptimizerConfig(g, loc, max_evals, seed, max_time, starts, polish, design, box_check)

    def posterior(self, value: Any, free: tuple) -> PosteriorConfig | None:
        p = ("fit", "posterior")
        if value is None or value is False:
            return None
        o = {} if value is True else self.section(value, p, ("walkers", "steps", "max_steps"))
        if not free:
            raise self.at(p).error("a posterior needs at least one parameter in fit.free")
        walkers_at = self.at(p + ("walkers",))
        walkers = as_int(o.get("walkers", max(DEFAULT_WALKERS, 2 * len(free))), walkers_at, 1, MAX_WALKERS)
        if walkers < 2 * len(free):
            raise walkers_at.error(f"walkers = {walkers} is below 2 x {len(free)} free parameters "
                                   f"= {2 * len(free)} (emcee needs at least twice as many walkers)")
        steps = as_int(o.get("steps", DEFAULT_STEPS), self.at(p + ("steps",)), 1, MAX_POSTERIOR_STEPS)
        max_at = self.at(p + ("max_steps",))
        max_steps = as_int(o.get("max_steps", max(DEFAULT_MAX_STEPS, steps)), max_at, 1, MAX_POSTERIOR_STEPS)
        if max_steps < steps:
            raise max_at.error(f"max_steps = {max_steps} is below steps = {steps}")
        chain = max_steps * walkers * (len(free) + 1) * 8
        if chain > MAX_CHAIN_BYTES:
            raise (max_at if "max_steps" in o else walkers_at).error(
                f"a chain of {max_steps} steps x {walkers} walkers x {len(free) + 1} coordinates holds "
                f"{chain / 2**30:.1f} GiB; at most {MAX_CHAIN_BYTES / 2**30:g} GiB (fewer steps or walkers)")
        return PosteriorConfig(walkers, steps, max_steps)

    def report(self, value: Any) -> ReportConfig:
        p = ("report",)
        r = self.section(value, p, ("percentiles",))
        values = as_list(r.get("percentiles", list(DEFAULT_PERCENTILES)), self.at(p + ("percentiles",)))
        if not values:
            raise self.at(p + ("percentiles",)).error("expected at least one percentile, got []")
        out: list[float] = []
        for i, v in enumerate(values):
            at = self.at(p + ("percentiles", i))
            x = as_number(v, at)
            if not 0.0 <= x <= 100.0:
                raise at.error(f"percentile must lie in [0, 100], got {v!r}")
            if x in out:
                raise at.error(f"percentile {v!r} is listed twice")
            out.append(x)
        return ReportConfig(tuple(sorted(out)))

    def output(self, value: Any) -> OutputConfig:
        p = ("output",)
        o = self.section(value, p, ("fits", "reports"))
        dirs = {}
        for key in ("fits", "reports"):
            if o.get(key) is None:
                dirs[key] = Path.cwd() / key
            else:
                at = self.at(p + (key,))
                dirs[key] = self.resolve(as_str(o[key], at), at)
        return OutputConfig(**dirs)


def default_free(cls, options: dict | None = None) -> tuple:
    """The parameters a fit of model class ``cls`` frees when fabric.yaml names none: ``cls.declared_free(
    options)`` where the class has it (kind neural: those its network was trained over, read from
    ``options["weights"]``), else ``cls.default_free``.  Shared by config validation and ``clothlab select``."""
    return tuple(cls.declared_free(options))


def _check_parameter(table, name: str, value: float, at: Location) -> float:
    """The declared physical range check (ParamSpec.check), as a ConfigError at ``at``."""
    try:
        return table[name].check(value, at.field)
    except ParameterError as exc:
        raise at.error(exc.detail) from None


def checked_quadrature(given: dict, rule_at: Location, nodes_at: Location) -> Quadrature:
    """The :class:`Quadrature` of ``given`` (``rule``, ``nodes``; a missing one takes the default): the class's
    own check, the one shared with the API and fit.json, its error raised at the value's location (a misspelt
    rule with a suggestion)."""
    try:
        return Quadrature.from_record(given)
    except ParameterError as exc:
        if exc.field == "model.quadrature.rule":
            raise rule_at.error(exc.detail + suggest(given.get("rule"), RULES)) from None
        raise nodes_at.error(exc.detail) from None


def _format_choices() -> tuple:
    """The measurement formats the loader reads, and ``auto`` (imported on use: it loads numpy)."""
    from clothlab.io.loader import FORMAT_CHOICES

    return FORMAT_CHOICES


# ----------------------------------------------------------------------------------------------------------
# Public entry points


def load_config(path) -> Config:
    """Read and validate a fabric.yaml; relative paths in it are resolved against its directory."""
    path = Path(path)
    data, lines = load_yaml_with_lines(path)
    return _Validator(data, lines, path.absolute().parent, path).config()


def config_from_dict(d: dict, source: str = "<dict>", base_dir=".") -> Config:
    """Validate a mapping with the fabric.yaml schema (API and tests); paths are relative to ``base_dir``."""
    return _Validator(d, LineMap(source=source), Path(base_dir).absolute(), None).config()


def override_quadrature(quadrature: Quadrature | None = None, *, rule=None, nodes=None) -> Quadrature:
    """``quadrature`` (None: the default) with the command line's ``--rule`` / ``--nodes`` (None keeps its own;
    ``nodes`` also as decimal text), checked as in the yaml; errors name the option."""
    given = (quadrature or Quadrature()).record()
    if rule is not None:
        given["rule"] = rule
    if nodes is not None:
        given["nodes"] = as_cli_int(nodes, Location(None, "--nodes"))
    return checked_quadrature(given, Location(None, "--rule"), Location(None, "--nodes"))


def apply_overrides(config: Config, *, rule=None, nodes=None, max_evals=None, seed=None) -> Config:
    """A copy of ``config`` with command-line overrides (``--rule --nodes --max-evals --seed``) applied.

    Values are checked as in the yaml; errors name the option, e.g. field ``--nodes``.
    """
    optimizer = config.fit.optimizer
    quadrature = override_quadrature(config.model.quadrature, rule=rule, nodes=nodes)
    if max_evals is not None:
        optimizer = replace(optimizer, max_evals=as_cli_int(max_evals, Location(None, "--max-evals"), 1, MAX_EVALS))
    if seed is not None:
        optimizer = replace(optimizer, seed=as_cli_int(seed, Location(None, "--seed"), *SEED_RANGE))
    return replace(
        config,
        model=replace(config.model, quadrature=quadrature),
        fit=replace(config.fit, optimizer=optimizer),
    )
