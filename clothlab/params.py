"""Parameter declarations: each model parameter is declared once (docs/design.md principle 4).

A :class:`ParamSpec` holds the name, unit, physical range (what validation accepts), the default fit
bounds, the default value and the transform used by the optimiser.  Fitting, priors, validation, the CLI
help and reports all read these declarations.  Values are kept in the declared unit (degrees for angles)
everywhere a user sees them; models convert at their entry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clothlab.errors import ParameterError


@dataclass(frozen=True)
class ParamSpec:
    """One parameter.  ``valid`` is the physical range; ``open_lower``/``open_upper`` exclude an endpoint."""

    name: str
    unit: str
    valid: tuple[float, float]
    bounds: tuple[float, float]
    default: float
    transform: str = "linear"  # 'linear' | 'log'
    doc: str = ""
    open_lower: bool = False
    open_upper: bool = False
    #: the period (declared unit) of a periodic parameter (e.g. an angle about the normal), else None: a fit
    #: whose bounds span one period treats the bounds as the same point, not as limits (clothlab.fit.periodic)
    period: float | None = None

    def check(self, value: float, where: str = "") -> float:
        """Return ``value`` as float or raise :class:`ParameterError` naming the parameter and its range."""
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ParameterError(f"{self.name} must be a number, got {value!r}", field=where or self.name) from None
        lo, hi = self.valid
        bad_lo = x <= lo if self.open_lower else x < lo
        bad_hi = x >= hi if self.open_upper else x > hi
        if not math.isfinite(x) or bad_lo or bad_hi:
            lb = "(" if self.open_lower else "["
            rb = ")" if self.open_upper else "]"
            raise ParameterError(
                f"{self.name} = {value!r} {self.unit} is outside its physical range {lb}{lo:g}, {hi:g}{rb}"
                + (f" ({self.doc})" if self.doc else ""),
                field=where or self.name,
            )
        return x

    def to_internal(self, x):
        """Map a value in the declared unit to the optimiser's coordinate (log where declared)."""
        return np.log(x) if self.transform == "log" else np.asarray(x, dtype=np.float64)

    def from_internal(self, y):
        return np.exp(y) if self.transform == "log" else np.asarray(y, dtype=np.float64)


class ParamTable:
    """An ordered collection of declarations with lookup by name."""

    def __init__(self, specs):
        self.specs = {s.name: s for s in specs}

    def __getitem__(self, name: str) -> ParamSpec:
        try:
            return self.specs[name]
        except KeyError:
            raise ParameterError(
                f"unknown parameter '{name}'; known: {', '.join(self.specs)}", field=name
            ) from None

    def __contains__(self, name: str) -> bool:
        return name in self.specs

    def __iter__(self):
        return iter(self.specs.values())

    def names(self) -> list[str]:
        return list(self.specs)

    def validate(self, values: dict, where: str = "") -> dict:
        """Check every known value; unknown names raise.  Returns a new dict of floats."""
        out = {}
        for name, value in values.items():
            out[name] = self[name].check(value, f"{where}{name}" if where else name)
        return out
