"""Model kinds by name (a registry, not an if-chain): ``kind`` in fabric.yaml -> model class."""

from __future__ import annotations

from importlib import import_module

from clothlab.errors import ConfigError

MODEL_KINDS = {
    "irawan": ("clothlab.models.irawan.model", "IrawanModel"),
    "kang": ("clothlab.models.kang.model", "KangModel"),
}


def model_class(kind: str):
    try:
        module, name = MODEL_KINDS[kind]
    except KeyError:
        raise ConfigError(f"unknown model kind {kind!r}; choose one of {', '.join(MODEL_KINDS)}",
                          field="model.kind") from None
    return getattr(import_module(module), name)


def build_model(kind: str, weave, quadrature=None, **options):
    """An instance of the model ``kind`` for ``weave``; ``quadrature`` = (rule, nodes) for integrating models."""
    import inspect

    cls = model_class(kind)
    accepted = [p.name for p in inspect.signature(cls.__init__).parameters.values()
                if p.kind == p.KEYWORD_ONLY]
    for name in options:
        if name not in accepted:
            raise ConfigError(f"model kind {kind!r} takes no option {name!r}; options: {', '.join(accepted) or 'none'}",
                              field=f"model.options.{name}")
    if kind == "irawan":
        from clothlab.models.irawan.model import Quadrature

        q = quadrature if quadrature is None or isinstance(quadrature, Quadrature) else Quadrature(*quadrature)
        return cls(weave, q, **options)
    return cls(weave, **options)
