"""The one way from a description to a model: a validated fabric.yaml, a fit directory, or a weave alone.

- :func:`model_from_config` - the model of a :class:`~clothlab.config.schema.Config`: its kind, its weave
  resolved against the yaml's own directory (``config.base_dir``, the directory every relative path of
  fabric.yaml is resolved against), its :class:`~clothlab.models.irawan.quadrature.Quadrature` and options;
- :func:`model_from_fit` - the model of a fit directory's fit.json and weave.wv (the file options' copies
  resolved against the fit directory, so the directory is self-contained);
- :func:`model_from_weave` - a weave named on the command line (``preset:<name>``, ``pattern:<name>``, a .wv
  file) or given as a :class:`~clothlab.weave.model.Weave`, with the registry's default kind.

All three build through :func:`build`, the only call of :func:`clothlab.models.registry.build_model` outside
models/ on these paths; the registry checks the options (once), :class:`Quadrature` the quadrature (once), and
the quadrature's defaults are the class's.

>>> model = model_from_weave("preset:cotton-twill", quadrature=Quadrature("gauss", 8))
>>> model.kind, model.quadrature
('irawan', Quadrature(rule='gauss', nodes=8))
"""

from __future__ import annotations

from pathlib import Path

from clothlab.errors import InputError, ParameterError
from clothlab.models.irawan.quadrature import Quadrature
from clothlab.models.registry import DEFAULT_KIND, build_model, model_class
from clothlab.weave.presets import resolve_weave
from clothlab.weave.wvformat import parse_wv


def build(kind: str, weave, quadrature: Quadrature | None = None, options: dict | None = None):
    """The model ``kind`` of ``weave`` (a Weave) integrating with ``quadrature`` (None: the model's default,
    ``Quadrature()``; a model that integrates nothing ignores it) and ``model.options`` ``options``."""
    return build_model(kind, weave, quadrature, **dict(options or {}))


def model_from_config(config, quadrature: Quadrature | None = None):
    """The model of a validated fabric.yaml (``quadrature`` replaces the configured one when given)."""
    m = config.model
    return build(m.kind, resolve_weave(m.weave, config.base_dir), quadrature or m.quadrature, m.options)


def model_from_weave(weave, base_dir=".", *, kind: str = DEFAULT_KIND, quadrature: Quadrature | None = None,
                     options: dict | None = None):
    """The model ``kind`` of ``weave``: a Weave, or fabric.yaml's ``weave:`` spelling (``preset:<name>``,
    ``pattern:<name>``, a .wv file relative to ``base_dir``)."""
    if isinstance(weave, str):
        weave = resolve_weave(weave, base_dir)
    return build(kind, weave, quadrature, options)


def model_from_fit(fit: dict, fit_dir):
    """The model of a fit directory: ``fit`` is its fit.json (read), the weave its ``weave.wv``.

    The quadrature is fit.json's ``model.quadrature`` (a model that integrates records it), else the recorded
    configuration's, else the default; the options are ``model.options`` as fitted, else the configuration's,
    their files (the class's ``path_options``) relative to the fit directory.  InputError naming fit.json and
    the field for an entry missing or out of range."""
    fit_dir = Path(fit_dir)
    weave_path = fit_dir / "weave.wv"
    if not weave_path.is_file():
        raise InputError("weave.wv is missing from the fit directory", path=weave_path)
    try:
        entry = fit["model"]
        kind = entry["kind"]
        configured = (fit.get("config") or {}).get("model") or {}
        record = entry.get("quadrature") or configured.get("quadrature")
        options = dict(entry.get("options") or configured.get("options") or {})
        for name in model_class(kind).options_class().path_options:  # copies in the fit directory
            if options.get(name) and not Path(options[name]).is_absolute():
                options[name] = str(fit_dir / options[name])
        quadrature = Quadrature.from_record(record)
    except ParameterError as exc:
        raise InputError(exc.detail, path=fit_dir / "fit.json", field=exc.field) from None
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"fit.json lacks or mangles a required entry ({exc})", path=fit_dir / "fit.json") from None
    return build(kind, parse_wv(weave_path), quadrature, options)
