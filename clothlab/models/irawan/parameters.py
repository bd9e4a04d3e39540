"""The Irawan-Marschner model's parameters (paper Table I): the fields of a weave, declared in
:mod:`clothlab.weave.parameters` (the ``.wv`` format checks against the same declarations)."""

from clothlab.weave.parameters import FIBRE_SPECS, IRAWAN_PARAMS, apply_parameters, weave_parameters

__all__ = ["FIBRE_SPECS", "IRAWAN_PARAMS", "apply_parameters", "weave_parameters"]
