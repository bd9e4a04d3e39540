"""fabric.yaml: schema, loading and validation (DESIGN.md "What flows through the program", principle 7).

``load_config(path)`` reads a fabric.yaml, checks every key against the schema below and returns a frozen
:class:`Config`.  Every mistake raises :class:`~clothlab.errors.ConfigError` naming the file, the line (from
PyYAML's node marks), the dotted field (``fit.optimizer.max_evals``), the value found and what was expected.
Model parameter values and bounds are checked against the model's one declaration of each parameter
(:data:`clothlab.models.irawan.parameters.IRAWAN_PARAMS`, DESIGN.md principle 4).  The key-by-key reference
is docs/fabric-yaml.md.

Relative paths (``measurement.path``, a ``.wv`` weave file, ``output.*``) are relative to the yaml's
directory; when ``output`` is absent, results go to ``fits/`` and ``reports/`` under the current directory.
Angles are in degrees, as declared by the parameter table.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import json
import math
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from clothlab.errors import ConfigError, ParameterError
from clothlab.models.registry import DEFAULT_KIND, MODEL_KINDS, model_class

FORMATS = ("auto", "clothlab", "astm", "pabopto")
QUADRATURE_RULES = ("trapezoid", "gauss", "support", "adaptive")
METRICS = ("relative", "log", "cube-root")
GLOBAL_ALGORITHMS = ("GN_CRS2_LM", "GN_DIRECT_L", "GN_ISRES", "GN_ESCH", "G_MLSL_LDS")
LOCAL_ALGORITHMS = ("LN_BOBYQA", "LN_NELDERMEAD", "LN_SBPLX", "LN_COBYLA", "LN_PRAXIS")
NEEDS_LOCAL = ("G_MLSL_LDS",)  # MLSL runs its local searches with the local algorithm
PRESET_PREFIX = "preset:"
NAME_PATTERN = re.compile(r"[A-Za-z0-9._-]+")
NODES_RANGE = (2, 1000)
SEED_RANGE = (0, 2**32 - 1)  # what nlopt.srand and numpy's legacy seeding both accept

DEFAULT_PERCENTILES = (50.0, 80.0, 95.0)
DEFAULT_WALKERS = 32
DEFAULT_STEPS = 4000
DEFAULT_MAX_STEPS = 20000


# ----------------------------------------------------------------------------------------------------------
# The validated configuration


@dataclass(frozen=True)
class MeasurementConfig:
    """``measurement``: the data file or directory (resolved), its format and the loader's options."""

    path: Path
    format: str = "auto"
    options: dict = field(default_factory=dict)


@dataclass(frozen=True)
class QuadratureConfig:
    """``model.quadrature``: the rule integrating over the yarn's fibre positions and its node count."""

    rule: str = "trapezoid"
    nodes: int = 11


@dataclass(frozen=True)
class ModelConfig:
    """``model``: kind, weave (``preset:<name>`` or the resolved path of a .wv file, or None), start values."""

    kind: str = DEFAULT_KIND
    weave: str | None = None
    quadrature: QuadratureConfig = field(default_factory=QuadratureConfig)
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

    global_algorithm: str | None = "GN_CRS2_LM"
    local_algorithm: str | None = "LN_BOBYQA"
    max_evals: int = 4000
    seed: int = 1
    max_time: float | None = None
    starts: int = 1
    polish: int | None = None  # evaluations of the final restarted polish; None = max_evals // 3, 0 = none

    @property
    def polish_evals(self) -> int:
        return self.max_evals // 3 if self.polish is None else self.polish


@dataclass(frozen=True)
class PosteriorConfig:
    """``fit.posterior``: emcee walkers, minimum steps and the cap when running to convergence."""

    walkers: int = DEFAULT_WALKERS
    steps: int = DEFAULT_STEPS
    max_steps: int = DEFAULT_MAX_STEPS


@dataclass(frozen=True)
class FitConfig:
    """``fit``: free parameters, their fit bounds (declared units), metric, optimiser, posterior, CV folds."""

    free: tuple = ()
    bounds: dict = field(default_factory=dict)
    metric: str = "relative"
    optimizer: OptimizerConfig = field(default_factory=OptimizerConfig)
    posterior: PosteriorConfig | None = None
    cv_folds: int = 0


@dataclass(frozen=True)
class ReportConfig:
    """``report``: error percentiles to tabulate, ascending, in [0, 100]."""

    percentiles: tuple = DEFAULT_PERCENTILES


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
                "quadrature": {"rule": model.quadrature.rule, "nodes": model.quadrature.nodes},
                "params": dict(model.params),
                "options": dict(model.options),
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
                },
                "posterior": None if post is None else {
                    "walkers": post.walkers, "steps": post.steps, "max_steps": post.max_steps,
                },
                "cv_folds": fit.cv_folds,
            },
            "report": {"percentiles": list(self.report.percentiles)},
        }

    @property
    def hash(self) -> str:
        """sha256 (hex) of the canonical JSON of :meth:`canonical` (sorted keys, no whitespace)."""
        text = json.dumps(self.canonical(), sort_keys=True, separators=(",", ":"), allow_nan=False)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()

    def _relative(self, path: Path) -> str:
        return Path(os.path.relpath(path, self.base_dir)).as_posix()


# ----------------------------------------------------------------------------------------------------------
# Where a value came from: source file, line, dotted field


@dataclass(frozen=True)
class _Field:
    """The location of one value, able to build the ConfigError that names it."""

    source: str | None
    field: str
    line: int | None = None

    def error(self, message: str) -> ConfigError:
        return ConfigError(message, path=self.source, line=self.line, field=self.field)


def _dotted(keys: tuple) -> str:
    out = ""
    for k in keys:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return out


class _Lines:
    """Line numbers (1-based) of every key and value of a composed YAML document, by key path."""

    def __init__(self, root=None, source: str | None = None):
        self.source = source
        self.key_lines: dict[tuple, int] = {}
        self.value_lines: dict[tuple, int] = {}
        self._open: set[int] = set()  # nodes being walked (an alias to one of them is a cycle)
        self._done: set[int] = set()  # nodes walked already (aliases are not walked again)
        if root is not None:
            self._walk(root, ())

    def _walk(self, node, path: tuple, merged: bool = False) -> None:

        if not merged or path not in self.value_lines:
            self.value_lines[path] = node.start_mark.line + 1
        if id(node) in self._open:
            raise ConfigError("a YAML alias refers to the structure containing it (a cycle)",
                              path=self.source, line=node.start_mark.line + 1, field=_dotted(path) or None)
        if id(node) in self._done and not merged:
            return
        self._open.add(id(node))
        try:
            self._walk_children(node, path, merged)
        finally:
            self._open.discard(id(node))
        self._done.add(id(node))

    def _walk_children(self, node, path: tuple, merged: bool) -> None:
        import yaml

        if isinstance(node, yaml.MappingNode):
            merges = []
            seen: dict[str, int] = {}
            for key_node, value_node in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    merges.append(value_node)
                    continue
                if not isinstance(key_node, yaml.ScalarNode):
                    continue
                key = key_node.value
                line = key_node.start_mark.line + 1
                if key in seen and not merged:
                    raise ConfigError(
                        f"duplicate key '{key}' (first given on line {seen[key]})",
                        path=self.source, line=line, field=_dotted(path + (key,)),
                    )
                seen[key] = line
                sub = path + (key,)
                if merged and sub in self.key_lines:
                    continue  # an explicit key wins over a merged one
                self.key_lines[sub] = line
                self._walk(value_node, sub, merged)
            for m in merges:  # YAML merge keys ('<<: *anchor'): lines of the anchor's keys
                for part in m.value if isinstance(m, yaml.SequenceNode) else [m]:
                    self._walk(part, path, merged=True)
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                self._walk(item, path + (i,), merged)

    def line(self, path: tuple, key: bool = False) -> int | None:
        """Line of the value at ``path`` (of its key with ``key=True``); else the line of the nearest
        parent's key (a default or a missing key has no line of its own)."""
        table = self.key_lines if key else self.value_lines
        if path in table:
            return table[path]
        return self.line(path[:-1], key=True) if len(path) > 1 else None


class _Reader:
    """Turns key paths into :class:`_Field` locations for one document."""

    def __init__(self, source: str, lines: _Lines):
        self.source = source
        self.lines = lines

    def at(self, path: tuple, key: bool = False) -> _Field:
        return _Field(self.source, _dotted(path), self.lines.line(path, key=key))


# ----------------------------------------------------------------------------------------------------------
# Value checks, shared by the yaml and the command-line overrides

_TYPE_NAMES = {bool: "true/false", int: "integer", float: "number", str: "string", list: "list",
               dict: "mapping", type(None): "null"}


def _shown(value: Any) -> str:
    name = _TYPE_NAMES.get(type(value), type(value).__name__)
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({name})"


def _suggest(word: Any, choices) -> str:
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def _as_str(value: Any, at: _Field) -> str:
    if not isinstance(value, str):
        hint = "; quote it" if isinstance(value, int | float | bool) else ""
        raise at.error(f"expected a string, got {_shown(value)}{hint}")
    return value


def _as_int(value: Any, at: _Field, lo: int | None = None, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise at.error(f"expected an integer, got {_shown(value)}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        if hi is None:
            expected = f">= {lo}"
        elif lo is None:
            expected = f"<= {hi}"
        else:
            expected = f"in [{lo}, {hi}]"
        raise at.error(f"expected an integer {expected}, got {value}")
    return value


def _as_number(value: Any, at: _Field) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise at.error(f"expected a number, got {_shown(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise at.error(f"expected a finite number, got {value!r}")
    return x


def _as_choice(value: Any, at: _Field, choices, allow_null: bool = False):
    if value is None and allow_null:
        return None
    if not isinstance(value, str) or value not in choices:
        allowed = ", ".join(choices) + (", or null" if allow_null else "")
        raise at.error(f"unknown value {value!r}; expected one of {allowed}{_suggest(value, choices)}")
    return value


def _as_list(value: Any, at: _Field) -> list:
    if not isinstance(value, list):
        raise at.error(f"expected a list, got {_shown(value)}")
    return value


def _check_plain_data(value: Any, at: _Field) -> None:
    """Options and kang parameters are passed on as they are; they must be JSON-like data (for the hash)."""
    if isinstance(value, dict):
        for k, v in value.items():
            if not isinstance(k, str):
                raise at.error(f"keys must be strings, got {_shown(k)}")
            _check_plain_data(v, at)
    elif isinstance(value, list):
        for v in value:
            _check_plain_data(v, at)
    elif isinstance(value, float) and not math.isfinite(value):
        raise at.error(f"expected a finite number, got {value!r}")
    elif not isinstance(value, str | int | float | bool | type(None)):
        raise at.error(f"expected plain data (strings, numbers, lists, mappings), got {_shown(value)}")


# ----------------------------------------------------------------------------------------------------------
# The schema, section by section


class _Validator:
    def __init__(self, data: Any, reader: _Reader, base_dir: Path, path: Path | None):
        self.data = data
        self.r = reader
        self.base_dir = base_dir
        self.path = path

    # -- helpers --------------------------------------------------------------------------------------------

    def section(self, value: Any, path: tuple, keys, required=()) -> dict:
        """Check that ``value`` is a mapping with only ``keys`` and all of ``required``; return it."""
        if not isinstance(value, dict):
            raise self.r.at(path).error(f"expected a mapping, got {_shown(value)}")
        for key in value:
            if key not in keys:
                raise self.r.at(path + (key,), key=True).error(
                    f"unknown key '{key}'{_suggest(key, keys)}; allowed here: {', '.join(keys)}"
                )
        for key in required:
            if key not in value:
                where = self.r.at(path, key=True)
                raise ConfigError(f"missing required key '{key}'", path=where.source, line=where.line,
                                  field=_dotted(path + (key,)))
        return value

    def resolve(self, written: str, at: _Field) -> Path:
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
            found = "an empty document" if top is None else _shown(top)
            raise ConfigError(f"expected a mapping of settings (name:, measurement:, ...), got {found}",
                              path=self.r.source, line=self.r.lines.line(()))
        self.section(top, (), ("name", "measurement", "model", "fit", "report", "output"),
                     required=("name", "measurement"))
        name = _as_str(top["name"], self.r.at(("name",)))
        if not NAME_PATTERN.fullmatch(name) or name in (".", ".."):
            raise self.r.at(("name",)).error(
                f"{name!r} is not a valid name: use letters, digits, '.', '_' and '-' only "
                "(it names the fits/ and reports/ directories)"
            )
        measurement = self.measurement(top["measurement"])
        model = self.model(top.get("model", {}))
        fit = self.fit(top.get("fit", {}), model)
        report = self.report(top.get("report", {}))
        output = self.output(top.get("output", {}))
        return Config(name=name, path=self.path, base_dir=self.base_dir, measurement=measurement,
                      model=model, fit=fit, report=report, output=output, raw=copy.deepcopy(top),
                      source=self.r.source)

    def measurement(self, value: Any) -> MeasurementConfig:
        p = ("measurement",)
        m = self.section(value, p, ("path", "format", "options"), required=("path",))
        written = _as_str(m["path"], self.r.at(p + ("path",)))
        resolved = self.resolve(written, self.r.at(p + ("path",)))
        if not self.is_there(resolved, need_file=False):
            raise self.r.at(p + ("path",)).error(
                f"measurement not found: {resolved} (from {written!r}, relative to {self.base_dir})"
            )
        fmt = _as_choice(m.get("format", "auto"), self.r.at(p + ("format",)), FORMATS)
        options = m.get("options", {})
        if options is None:
            options = {}
        if not isinstance(options, dict):
            raise self.r.at(p + ("options",)).error(f"expected a mapping, got {_shown(options)}")
        _check_plain_data(options, self.r.at(p + ("options",)))
        return MeasurementConfig(path=resolved, format=fmt, options=copy.deepcopy(options))

    def model(self, value: Any) -> ModelConfig:
        p = ("model",)
        m = self.section(value, p, ("kind", "weave", "quadrature", "params", "options"))
        kind = _as_choice(m.get("kind", DEFAULT_KIND), self.r.at(p + ("kind",)), MODEL_KINDS)
        weave = None
        if m.get("weave") is not None:
            weave = self.weave(m["weave"], self.r.at(p + ("weave",)))
        else:
            where = self.r.at(p, key=True)
            raise ConfigError(f"missing required key 'weave' (preset:<name> or a .wv file) for kind {kind}",
                              path=where.source, line=where.line, field="model.weave")
        q = self.section(m.get("quadrature", {}), p + ("quadrature",), ("rule", "nodes"))
        rule = _as_choice(q.get("rule", "trapezoid"), self.r.at(p + ("quadrature", "rule")), QUADRATURE_RULES)
        nodes = _as_int(q.get("nodes", 11), self.r.at(p + ("quadrature", "nodes")), *NODES_RANGE)
        params = m.get("params", {}) or {}
        if not isinstance(params, dict):
            raise self.r.at(p + ("params",)).error(f"expected a mapping, got {_shown(params)}")
        table = _param_table(kind)
        if table is None:
            _check_plain_data(params, self.r.at(p + ("params",)))
            checked = copy.deepcopy(params)
        else:
            checked = {}
            for name, v in params.items():
                at_key = self.r.at(p + ("params", name), key=True)
                self.known_parameter(name, table, at_key)
                at = self.r.at(p + ("params", name))
                _as_number(v, at)
                checked[name] = _check_parameter(table, name, v, at)
        options = m.get("options", {}) or {}
        if not isinstance(options, dict):
            raise self.r.at(p + ("options",)).error(f"expected a mapping, got {_shown(options)}")
        _check_plain_data(options, self.r.at(p + ("options",)))
        return ModelConfig(kind=kind, weave=weave, quadrature=QuadratureConfig(rule, nodes), params=checked,
                           options=copy.deepcopy(options))

    def weave(self, value: Any, at: _Field) -> str:
        """``preset:<name>`` (spelled as clothlab.weave.presets accepts it) -> ``preset:<key>``; a .wv file ->
        its resolved path."""
        text = _as_str(value, at).strip()
        if text.lower().startswith(PRESET_PREFIX):
            from clothlab.weave.presets import PRESET_NAMES, canonical_preset_name

            preset = text[len(PRESET_PREFIX):].strip()
            try:
                return PRESET_PREFIX + canonical_preset_name(preset)
            except ConfigError:
                raise at.error(f"unknown preset {preset!r}{_suggest(preset, PRESET_NAMES)}; "
                               f"known presets: {', '.join(PRESET_NAMES)}") from None
        resolved = self.resolve(text, at)
        if not self.is_there(resolved, need_file=True):
            raise at.error(f"weave file not found: {resolved} (from {text!r}, relative to {self.base_dir}); "
                           f"give a .wv file or preset:<name>")
        return str(resolved)

    def known_parameter(self, name: Any, table, at: _Field) -> str:
        if not isinstance(name, str) or name not in table:
            raise at.error(f"unknown parameter {name!r}{_suggest(name, table.names())}; "
                           f"known: {', '.join(table.names())}")
        return name

    def fit(self, value: Any, model: ModelConfig) -> FitConfig:
        p = ("fit",)
        f = self.section(value, p, ("free", "bounds", "metric", "optimizer", "posterior", "cv_folds"))
        table = _param_table(model.kind)
        free = self.free(f.get("free", list(model_class(model.kind).default_free)), table)
        bounds = self.bounds(f.get("bounds", {}) or {}, table, free, model.params)
        for name in free:  # explicit bounds were checked against the start above; the declared ones here
            if table is not None and name not in bounds and name in model.params:
                lo, hi = table[name].bounds
                if not lo <= model.params[name] <= hi:
                    raise self.r.at(("model", "params", name)).error(
                        f"start value {model.params[name]:g} of free parameter {name} lies outside its default fit "
                        f"bounds [{lo:g}, {hi:g}]; move it inside or set fit.bounds.{name}")
        metric = _as_choice(f.get("metric", "relative"), self.r.at(p + ("metric",)), METRICS)
        optimizer = self.optimizer(f.get("optimizer", {}))
        posterior = self.posterior(f.get("posterior"), free)
        cv_folds = f.get("cv_folds", 0)
        at = self.r.at(p + ("cv_folds",))
        if cv_folds is None or cv_folds is False:
            cv_folds = 0
        _as_int(cv_folds, at, 0)
        if cv_folds == 1:
            raise at.error("expected 0 (no cross-validation) or at least 2 folds, got 1")
        return FitConfig(free=free, bounds=bounds, metric=metric, optimizer=optimizer, posterior=posterior,
                         cv_folds=cv_folds)

    def free(self, value: Any, table) -> tuple:
        p = ("fit", "free")
        names = _as_list(value, self.r.at(p))
        out: list[str] = []
        for i, name in enumerate(names):
            at = self.r.at(p + (i,))
            _as_str(name, at)
            if table is not None:
                self.known_parameter(name, table, at)
            if name in out:
                raise at.error(f"parameter {name!r} is listed twice")
            out.append(name)
        return tuple(out)

    def bounds(self, value: Any, table, free: tuple, params: dict) -> dict:
        p = ("fit", "bounds")
        if not isinstance(value, dict):
            raise self.r.at(p).error(f"expected a mapping of parameter: [lower, upper], got {_shown(value)}")
        out = {}
        for name, pair in value.items():
            key_at = self.r.at(p + (name,), key=True)
            if table is not None:
                self.known_parameter(name, table, key_at)
            if name not in free:
                raise key_at.error(f"bounds given for {name!r}, which is not in fit.free ({', '.join(free)})")
            at = self.r.at(p + (name,))
            if not isinstance(pair, list) or len(pair) != 2:
                raise at.error(f"expected [lower, upper], got {_shown(pair)}")
            lo, hi = (_as_number(x, self.r.at(p + (name, i))) for i, x in enumerate(pair))
            if table is not None:
                for i, x in enumerate(pair):
                    _check_parameter(table, name, x, self.r.at(p + (name, i)))
            if not lo < hi:
                raise at.error(f"lower bound must be below the upper bound, got [{lo:g}, {hi:g}]")
            if name in params and not lo <= params[name] <= hi:
                raise at.error(f"start value model.params.{name} = {params[name]:g} lies outside "
                               f"these bounds [{lo:g}, {hi:g}]")
            out[name] = (lo, hi)
        return out

    def optimizer(self, value: Any) -> OptimizerConfig:
        p = ("fit", "optimizer")
        o = self.section(value, p, ("global", "local", "max_evals", "seed", "max_time", "starts", "polish"))
        d = OptimizerConfig()
        g = _as_choice(o.get("global", d.global_algorithm), self.r.at(p + ("global",)), GLOBAL_ALGORITHMS,
                       allow_null=True)
        loc = _as_choice(o.get("local", d.local_algorithm), self.r.at(p + ("local",)), LOCAL_ALGORITHMS,
                         allow_null=True)
        if g is None and loc is None:
            raise self.r.at(p, key=True).error("global and local are both null: no optimiser would run")
        if g in NEEDS_LOCAL and loc is None:
            raise self.r.at(p + ("local",)).error(f"{g} runs its local searches with the local algorithm; "
                                                  f"give one of {', '.join(LOCAL_ALGORITHMS)}")
        max_evals = _as_int(o.get("max_evals", d.max_evals), self.r.at(p + ("max_evals",)), 1)
        seed = _as_int(o.get("seed", d.seed), self.r.at(p + ("seed",)), *SEED_RANGE)
        max_time = o.get("max_time")
        if max_time is not None:
            at = self.r.at(p + ("max_time",))
            max_time = _as_number(max_time, at)
            if max_time <= 0:
                raise at.error(f"expected a positive number of seconds or null, got {max_time:g}")
        starts = _as_int(o.get("starts", d.starts), self.r.at(p + ("starts",)), 1, 64)
        if starts > max_evals:
            raise self.r.at(p + ("starts",)).error(f"{starts} starts need at least as many evaluations; max_evals is "
                                                   f"{max_evals}")
        polish = o.get("polish")
        if polish is not None:
            polish = _as_int(polish, self.r.at(p + ("polish",)), 0)
        return OptimizerConfig(g, loc, max_evals, seed, max_time, starts, polish)

    def posterior(self, value: Any, free: tuple) -> PosteriorConfig | None:
        p = ("fit", "posterior")
        if value is None or value is False:
            return None
        o = {} if value is True else self.section(value, p, ("walkers", "steps", "max_steps"))
        if not free:
            raise self.r.at(p).error("a posterior needs at least one parameter in fit.free")
        walkers_at = self.r.at(p + ("walkers",))
        walkers = _as_int(o.get("walkers", max(DEFAULT_WALKERS, 2 * len(free))), walkers_at, 1)
        if walkers < 2 * len(free):
            raise walkers_at.error(f"walkers = {walkers} is below 2 x {len(free)} free parameters "
                                   f"= {2 * len(free)} (emcee needs at least twice as many walkers)")
        steps = _as_int(o.get("steps", DEFAULT_STEPS), self.r.at(p + ("steps",)), 1)
        max_at = self.r.at(p + ("max_steps",))
        max_steps = _as_int(o.get("max_steps", max(DEFAULT_MAX_STEPS, steps)), max_at, 1)
        if max_steps < steps:
            raise max_at.error(f"max_steps = {max_steps} is below steps = {steps}")
        return PosteriorConfig(walkers, steps, max_steps)

    def report(self, value: Any) -> ReportConfig:
        p = ("report",)
        r = self.section(value, p, ("percentiles",))
        values = _as_list(r.get("percentiles", list(DEFAULT_PERCENTILES)), self.r.at(p + ("percentiles",)))
        if not values:
            raise self.r.at(p + ("percentiles",)).error("expected at least one percentile, got []")
        out: list[float] = []
        for i, v in enumerate(values):
            at = self.r.at(p + ("percentiles", i))
            x = _as_number(v, at)
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
                at = self.r.at(p + (key,))
                dirs[key] = self.resolve(_as_str(o[key], at), at)
        return OutputConfig(**dirs)


def _param_table(kind: str):
    """The parameter declarations of model ``kind`` (the registry's class)."""
    return model_class(kind).declared_parameters()


def _check_parameter(table, name: str, value: float, at: _Field) -> float:
    """The declared physical range check (ParamSpec.check), as a ConfigError at ``at``."""
    try:
        return table[name].check(value, at.field)
    except ParameterError as exc:
        raise at.error(exc.detail) from None


# ----------------------------------------------------------------------------------------------------------
# Public entry points


def load_config(path) -> Config:
    """Read and validate a fabric.yaml; relative paths in it are resolved against its directory."""
    import yaml

    path = Path(path)
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"configuration file not found: {path.absolute()}", path=source) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read the configuration file: {exc}", path=source) from None
    lines = _Lines(source=source)
    loader = yaml.SafeLoader(text)
    try:
        node = loader.get_single_node()
        if node is not None:
            lines._walk(node, ())
        data = None if node is None else loader.construct_document(node)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        problem = getattr(exc, "problem", None) or str(exc)
        context = getattr(exc, "context", None)
        message = f"YAML syntax error: {problem}" + (f" ({context})" if context else "")
        raise ConfigError(message, path=source, line=None if mark is None else mark.line + 1) from None
    finally:
        loader.dispose()
    base_dir = path.absolute().parent
    return _Validator(data, _Reader(source, lines), base_dir, path).config()


def config_from_dict(d: dict, source: str = "<dict>", base_dir=".") -> Config:
    """Validate a mapping with the fabric.yaml schema (API and tests); paths are relative to ``base_dir``."""
    return _Validator(d, _Reader(source, _Lines()), Path(base_dir).absolute(), None).config()


def _as_cli_int(value: Any, at: _Field, lo: int, hi: int | None = None) -> int:
    if isinstance(value, str):
        try:
            value = int(value.strip())
        except ValueError:
            raise at.error(f"expected an integer, got {value!r}") from None
    return _as_int(value, at, lo, hi)


def apply_overrides(config: Config, *, rule=None, nodes=None, max_evals=None, seed=None) -> Config:
    """A copy of ``config`` with command-line overrides (``--rule --nodes --max-evals --seed``) applied.

    Values are checked as in the yaml; errors name the option, e.g. field ``--nodes``.
    """
    quadrature = config.model.quadrature
    optimizer = config.fit.optimizer
    if rule is not None:
        quadrature = replace(quadrature, rule=_as_choice(rule, _Field(None, "--rule"), QUADRATURE_RULES))
    if nodes is not None:
        quadrature = replace(quadrature, nodes=_as_cli_int(nodes, _Field(None, "--nodes"), *NODES_RANGE))
    if max_evals is not None:
        optimizer = replace(optimizer, max_evals=_as_cli_int(max_evals, _Field(None, "--max-evals"), 1))
    if seed is not None:
        optimizer = replace(optimizer, seed=_as_cli_int(seed, _Field(None, "--seed"), *SEED_RANGE))
    return replace(
        config,
        model=replace(config.model, quadrature=quadrature),
        fit=replace(config.fit, optimizer=optimizer),
    )
