"""Quadrature rules for the reflectance integrals of eq. 10 (Irawan & Marschner 2012, sec. 7.3).

Pure quadrature (nodes and weights); the integrands are in :mod:`clothlab.models.irawan.kernels`.

Rules (``rule`` in fabric.yaml ``model.quadrature``):

- ``trapezoid`` - n equally spaced nodes including both ends; the paper's recommendation is n = 11.
- ``gauss`` - n-node Gauss-Legendre over the whole interval.
- ``support`` - the accurate rule: the interval is split where the integrand jumps or kinks (closed form,
  computed by the caller per direction: ends of the specular support, the visibility cut |v| = pi/2,
  zeros of the clamped cosines), and each piece gets n Gauss-Legendre nodes after the map
  u = a + (b - a) (1 - cos(pi t)) / 2, which clusters nodes at the piece ends and removes the square-root
  behaviour of v(u) at the support ends (eq. 3's arccos).
- ``adaptive`` - the support rule with n doubled (4, 8, ..., 128 nodes per piece) until every direction's
  value changes by less than ``ADAPTIVE_RTOL`` relative.

:class:`Quadrature` is the one form of the choice (fabric.yaml ``model.quadrature``, ``--rule`` / ``--nodes``,
fit.json ``model.quadrature`` and the API), with its one validation and its defaults.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from clothlab.errors import ParameterError

RULES = ("trapezoid", "gauss", "support", "adaptive")
ADAPTIVE_RTOL = 1e-7
ADAPTIVE_MAX_NODES = 128
NODES_RANGE = (2, 1000)
"""Nodes a :class:`Quadrature` takes (per piece for ``support`` / ``adaptive``), for every rule
(docs/fabric-yaml.md)."""


@dataclass(frozen=True)
class Quadrature:
    """A quadrature choice: ``rule`` in :data:`RULES` and ``nodes`` in :data:`NODES_RANGE` (per piece for
    support / adaptive).  The defaults are the paper's recommendation for eq. 10 (Irawan & Marschner 2012,
    sec. 7.3): the trapezoidal rule with 11 samples.  The one check of a quadrature for fabric.yaml, the
    command line, fit.json and the API: ParameterError at ``model.quadrature.rule`` / ``.nodes``.

    >>> Quadrature()
    Quadrature(rule='trapezoid', nodes=11)
    >>> Quadrature("gauss", 1)
    Traceback (most recent call last):
    ...
    clothlab.errors.ParameterError: field 'model.quadrature.nodes': expected an integer in [2, 1000], got 1
    """

    rule: str = "trapezoid"
    nodes: int = 11

    def __post_init__(self):
        if not isinstance(self.rule, str) or self.rule not in RULES:
            raise ParameterError(f"unknown quadrature rule {self.rule!r}; expected one of {', '.join(RULES)}",
                                 field="model.quadrature.rule")
        lo, hi = NODES_RANGE
        if isinstance(self.nodes, bool) or not isinstance(self.nodes, numbers.Integral) or \
                not lo <= self.nodes <= hi:
            raise ParameterError(f"expected an integer in [{lo}, {hi}], got {self.nodes!r}",
                                 field="model.quadrature.nodes")
        object.__setattr__(self, "nodes", int(self.nodes))  # a numpy integer is stored as int

    def record(self) -> dict:
        """The JSON form (fabric.yaml's and fit.json's ``model.quadrature``): ``{"rule": ..., "nodes": ...}``."""
        return {"rule": self.rule, "nodes": self.nodes}

    @classmethod
    def from_record(cls, record: dict | None) -> Quadrature:
        """The quadrature of a :meth:`record` (a missing entry, or a missing record, takes the default).

        >>> Quadrature.from_record({"rule": "gauss", "nodes": 15}), Quadrature.from_record(None)
        (Quadrature(rule='gauss', nodes=15), Quadrature(rule='trapezoid', nodes=11))
        """
        record = {} if record is None else record
        return cls(**{key: record[key] for key in ("rule", "nodes") if key in record})


@lru_cache(maxsize=64)
def unit_rule(rule: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights on [0, 1] for ``trapezoid`` or ``gauss`` (also the per-piece rule of ``support``)."""
    if n < 1 or (rule == "trapezoid" and n < 2):
        raise ValueError(f"quadrature rule {rule!r} needs more nodes than {n}")
    if rule == "trapezoid":
        t = np.linspace(0.0, 1.0, n)
        w = np.full(n, 1.0 / (n - 1))
        w[[0, -1]] *= 0.5
        return t, w
    if rule in ("gauss", "support", "adaptive"):
        x, w = np.polynomial.legendre.leggauss(n)
        return 0.5 * (x + 1.0), 0.5 * w
    raise ValueError(f"unknown quadrature rule {rule!r}; choose one of {', '.join(RULES)}")


def interval_rule(rule: str, n: int, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (n,) and weights (n,) of ``trapezoid`` or ``gauss`` over [lo, hi]."""
    t, w = unit_rule(rule, n)
    return lo + (hi - lo) * t, (hi - lo) * w


@lru_cache(maxsize=64)
def cosine_mapped_unit_rule(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n-node Gauss-Legendre on [0, 1] after the map s = (1 - cos(pi t)) / 2 (nodes cluster at both ends;
    the per-piece rule of ``support``)."""
    t, w = unit_rule("gauss", n)
    s = 0.5 * (1.0 - np.cos(np.pi * t))
    return s, w * 0.5 * np.pi * np.sin(np.pi * t)


def piecewise_rule(breaks: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights (N, P*n) for per-direction pieces given by sorted ``breaks`` (N, P+1).

    Zero-length pieces get zero weights, so every direction carries the same number of nodes (vectorised).
    """
    s, w = cosine_mapped_unit_rule(n)
    a = breaks[:, :-1, None]
    length = np.diff(breaks, axis=1)[:, :, None]
    nodes = a + length * s
    weights = length * w
    shape = (breaks.shape[0], -1)
    return nodes.reshape(shape), weights.reshape(shape)


def compact_breaks(lo, hi, candidates: np.ndarray) -> np.ndarray:
    """Sorted breakpoints (N, M+2): lo, the candidates strictly inside (lo, hi), hi, padded with hi.

    ``lo``, ``hi`` are scalars or (N,); ``candidates`` (N, K) may hold values anywhere (or NaN).  The
    number of columns is 2 + the largest number of interior candidates over all directions.
    """
    lo = np.broadcast_to(np.asarray(lo, dtype=np.float64), candidates.shape[:1])
    hi = np.broadcast_to(np.asarray(hi, dtype=np.float64), candidates.shape[:1])
    inside = (candidates > lo[:, None]) & (candidates < hi[:, None])
    padded = np.where(inside, candidates, hi[:, None])
    padded.sort(axis=1)
    m = int(inside.sum(axis=1).max(initial=0))
    return np.concatenate([lo[:, None], padded[:, :m], hi[:, None]], axis=1)
