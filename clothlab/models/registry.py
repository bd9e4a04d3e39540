"""Model kinds by name (a registry, not an if-chain): ``kind`` in fabric.yaml -> model class.

This is the only place that knows which kinds exist; everything else asks the model
(:class:`clothlab.models.base.Model`).  A new model is one package plus one line here.
"""

from __future__ import annotations

import inspect
from importlib import import_module

from clothlab.errors import ConfigError

MODEL_KINDS = {
    "irawan": ("clothlab.models.irawan.model", "IrawanModel"),
    "kang": ("clothlab.models.kang.model", "KangModel"),
    "lambert": ("clothlab.models.baselines.lambert", "LambertModel"),
    "oren-nayar": ("clothlab.models.baselines.oren_nayar", "OrenNayarModel"),
    "surface": ("clothlab.models.surface.model", "SurfaceModel"),
    "neural": ("clothlab.models.neural.model", "NeuralModel"),
}
#: Composite kinds (clothlab.models.composite): name -> (specular kind, diffuse kind).
COMPOSITE_KINDS = {f"{s}+{d}": (s, d) for s in ("irawan", "kang") for d in ("lambert", "oren-nayar")}
MODEL_KINDS.update({name: ("clothlab.models.composite.model", "composite_class") for name in COMPOSITE_KINDS})
#: Physics options (clothlab.models.composite.terms, issue 28): name -> (base kind, term).
TERM_KINDS = {f"{b}+{t}": (b, t) for b in ("irawan+oren-nayar",)
              for t in ("sheen", "fresnel", "fresnel-smith", "tilt", "retro")}
#: terms over a term kind (issue 28 session 14): the sheen with the grazing Fresnel factor, the tilt, the retro
TERM_KINDS.update({f"irawan+oren-nayar+sheen+{t}": ("irawan+oren-nayar+sheen", t)
                   for t in ("fresnel", "tilt", "retro")})
TERM_KINDS.update({f"irawan+oren-nayar+sheen+retro+{t}": ("irawan+oren-nayar+sheen+retro", t)
                   for t in ("fresnel", "fresnel-eta")})
TERM_KINDS["irawan+oren-nayar+sheen+fresnel-eta"] = ("irawan+oren-nayar+sheen", "fresnel-eta")
MODEL_KINDS.update({name: ("clothlab.models.composite.terms", "term_class") for name in TERM_KINDS})
DEFAULT_KIND = "irawan"
#: the kinds ``clothlab select`` tries unless select.kinds says otherwise: the IM yarn highlights over an
#: Oren-Nayar base with a fibre sheen and the grazing Fresnel factor (index free), without and with an
#: opposition surge (docs/select.md, session 14: under nested CV on both shared CUReT fabrics, with the huber
#: loss, this pair beat irawan+oren-nayar / irawan+oren-nayar+sheen in p80 and mean on both, median on one)
DEFAULT_SELECT_KINDS = ("irawan+oren-nayar+sheen+fresnel-eta", "irawan+oren-nayar+sheen+retro+fresnel-eta")
#: kinds whose reflectance does not depend on the weave (fabric.yaml may leave ``model.weave`` out)
WEAVE_FREE_KINDS = ("lambert", "oren-nayar")
#: the weave recorded for a weave-free kind given none (the model ignores it; docs/fabric-yaml.md)
WEAVE_STAND_IN = "pattern:plain"
#: The kind of Irawan & Marschner 2012, the paper whose figures the reports show as references (sec. 8) and whose
#: scene coefficients (kd, ks_warp, ks_weft) the other kinds' shaders map from (:data:`FROM_IRAWAN`).
PAPER_KIND = "irawan"

#: Shaders by name (``clothlab render --shader``; a kind offers its shaders here, beside its model line):
#: shader -> (the kind whose models it shades, its shading policy in :data:`clothlab.render.shade.POLICIES`).
#: The default kind's shaders shade the scene's own fabric (its fit, of any kind whose texture the renderer
#: blends, or the default kind); another kind's shade the scene's fabric as that kind (:data:`FROM_IRAWAN`).
SHADERS = {
    "im-lod": ("irawan", "lod"),
    "im-texture": ("irawan", "texture"),
    "im-reflectance": ("irawan", "reflectance"),
    "kang-lod": ("kang", "filtered-lod"),
    "kang-texture": ("kang", "filtered-texture"),
    "surface-lod": ("surface", "lod"),
    "surface-texture": ("surface", "texture"),
    "neural-lod": ("neural", "network-lod"),
}
#: A scene's IM fabric as another kind (that kind's shaders in an IM scene): kind -> (module, function), the
#: function ``(weave, coefficients, params=None) -> (model, params, coefficients)``.
FROM_IRAWAN = {
    "kang": ("clothlab.models.kang.from_irawan", "from_irawan"),
    "surface": ("clothlab.models.surface.from_irawan", "from_irawan"),
}


def needs_weave(kind: str) -> bool:
    """Whether fabric.yaml must name a weave for ``kind`` (every kind but :data:`WEAVE_FREE_KINDS`)."""
    return kind not in WEAVE_FREE_KINDS


def model_class(kind: str):
    """The model class registered as ``kind`` (ConfigError at ``model.kind`` for an unknown one).

    >>> model_class("kang").__name__, model_class("irawan+lambert").__name__
    ('KangModel', 'Composite[irawan+lambert]')
    >>> model_class("phong")
    Traceback (most recent call last):
    ...
    clothlab.errors.ConfigError: field 'model.kind': unknown model kind 'phong'; choose one of irawan, kang, ...
    """
    try:
        module, name = MODEL_KINDS[kind]
    except KeyError:
        raise ConfigError(f"unknown model kind {kind!r}; choose one of {', '.join(MODEL_KINDS)}",
                          field="model.kind") from None
    if kind in COMPOSITE_KINDS:
        return getattr(import_module(module), name)(kind, *(model_class(part) for part in COMPOSITE_KINDS[kind]))
    if kind in TERM_KINDS:
        return getattr(import_module(module), name)(kind, model_class(TERM_KINDS[kind][0]), TERM_KINDS[kind][1])
    return getattr(import_module(module), name)


def build_model(kind: str, weave, quadrature=None, **options):
    """An instance of the model ``kind`` for ``weave``; ``quadrature`` a
    :class:`~clothlab.models.irawan.quadrature.Quadrature` (or None: the default) for integrating models (a
    (rule, nodes) pair is taken too); fabric.yaml and fit directories build through :mod:`clothlab.config.build`.

    >>> from clothlab.models.irawan.quadrature import Quadrature
    >>> from clothlab.weave.presets import get_preset
    >>> model = build_model("irawan", get_preset("cotton-twill"), Quadrature("gauss", 8))
    >>> model.component_names  # the linear parts whose coefficients a fit solves (kd, ks_warp, ks_weft)
    ('diffuse', 'specular_warp', 'specular_weft')
    >>> build_model("irawan", get_preset("cotton-twill"), tile_nodes=3)
    Traceback (most recent call last):
    ...
    clothlab.errors.ConfigError: field 'model.options.tile_nodes': model kind 'irawan' takes no option ...
    """
    check_model_options(kind, options)
    return model_class(kind).from_config(weave, quadrature, **options)


def model_options(kind: str) -> dict:
    """{name: default} of the ``model.options`` of ``kind``: the keyword-only constructor arguments of its
    options class (a composite passes its options to its specular part)."""
    takes = model_class(kind).options_class()
    return {p.name: p.default for p in inspect.signature(takes.__init__).parameters.values()
            if p.kind == p.KEYWORD_ONLY}


def check_model_options(kind: str, options: dict) -> None:
    """The one check of ``model.options`` (fabric.yaml validation and :func:`build_model`): every name is an
    option of ``kind``, every value passes the class's ``check_option`` and together they pass its
    ``check_options`` (Model: no check); ConfigError at ``model.options.<name>``."""
    takes = model_class(kind).options_class()
    accepted = model_options(kind)
    for name, value in options.items():
        if name not in accepted:
            raise ConfigError(f"model kind {kind!r} takes no option {name!r}; options: {', '.join(accepted) or 'none'}",
                              field=f"model.options.{name}")
        try:
            takes.check_option(name, value)  # the model's own value checks (sizes bounded; Model: none)
        except ConfigError as exc:
            raise ConfigError(exc.detail, path=exc.path, line=exc.line, field=f"model.options.{name}") from None
    takes.check_options(options)


def shader(name: str) -> tuple[str, str]:
    """(kind, shading policy) of the shader ``name`` (:data:`SHADERS`; ConfigError at ``shader`` otherwise).

    >>> shader("kang-lod")
    ('kang', 'filtered-lod')
    """
    try:
        return SHADERS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown shader {name!r}; choose one of {', '.join(SHADERS)}", field="shader") from None


def from_irawan(kind: str, weave, coefficients: dict, params: dict | None = None):
    """(model, parameters, coefficients) of kind ``kind`` for ``weave`` standing in for an Irawan-Marschner
    fabric with coefficients ``coefficients`` (kd, ks_warp, ks_weft; the kind's own mapping, :data:`FROM_IRAWAN`)
    and the kind's parameters ``params`` (None: its defaults).  ConfigError for a kind without a mapping."""
    try:
        module, name = FROM_IRAWAN[kind]
    except KeyError:
        raise ConfigError(f"model kind {kind!r} has no mapping from an Irawan-Marschner fabric; kinds with one: "
                          f"{', '.join(FROM_IRAWAN)}", field="model.kind") from None
    return getattr(import_module(module), name)(weave, coefficients, params)
