"""What a training run learns, decided once: the materials of a run (``--vary`` grids, Table-2 draws), the
label source of each material and the reflectance model the labels, the residual base and the far view rest
on (Chen, Wang & Wang 2024, sec. 5.1; issue 23 item 5).  ``clothlab train-surrogate`` parses its options and
calls these; they take model objects from the caller (this package sits below :mod:`clothlab.models`).

The tile average (issue 23 item 5).  A footprint of whole tiles averages the texture model exactly to its
tile average, which for the IM texture is f_c I_j / a_j with the yarn integral I_j of eq. 10 exact
(:mod:`clothlab.models.irawan.texture`).  The reflectance model integrates I_j with its quadrature, and the
default trapezoid rule of 11 nodes is 0.9-1.2 % relative RMS (up to 3.4-3.7 % for single pairs) from the
texture's own average.  Networks trained from session 13 on therefore use the kind's model with
its kind's ``tile_average_quadrature`` (IM: trapezoid, 41 nodes: 0.22-0.26 % from a 65,536-point texture average,
within 2-3x of that reference's own noise; docs/neural.md "The tile average") for the whole-tile part of
the labels, the residual base and the far view's R, and record it in the sidecar
(``encoding.reference_quadrature``): it is the network's configured reflectance model, the one a query
evaluates (:func:`clothlab.models.neural.model.reference_model`).
"""

from __future__ import annotations

import itertools
import math
import re
import zlib

import numpy as np

from clothlab.errors import ConfigError
from clothlab.untrusted import parse_number

LABEL_CHOICES = ("mc", "sat", "model")
"""``--labels``: stratified MC of the texture with the whole tiles from the tile average, summed-area
tables, or the reflectance model itself (footprint-independent)."""
MAX_VARY_STEPS = 64
"""Most values N of one ``--vary NAME=LO:HI:N``."""
MAX_VARY_MATERIALS = 4096
"""Most materials of a ``--vary`` grid, the held-out midpoints included (each one is labelled)."""


def tile_average_model(model):
    """``model`` integrating with its kind's declared ``tile_average_quadrature`` (itself when it declares
    none: :class:`clothlab.models.base.Model`): the network's configured reflectance model (module docstring)."""
    rule = model.tile_average_quadrature
    return model if rule is None else model.with_quadrature(*rule)


def reference_quadrature(model) -> dict | None:
    """The sidecar's ``encoding.reference_quadrature`` of a configured model: {"rule", "nodes"}, or None
    for a model that integrates nothing."""
    q = model.quadrature  # declared on Model (None for a model that integrates nothing)
    return None if q is None else {"rule": str(q.rule), "nodes": int(q.nodes)}


def label_source(choice: str, model, params: dict, samples: int, seed: int, *, footprint_estimate=None):
    """The label source of one material (:mod:`clothlab.surrogate.labels`) for ``--labels`` ``choice``:
    ``model`` is the network's configured model (:func:`tile_average_model`), whose texture is sampled and
    whose reflectance model gives the whole tiles of ``mc`` labels; ``footprint_estimate``: the footprint
    estimator of ``sat`` labels (``clothlab.footprint.footprint_components``, handed in by the caller)."""
    from clothlab.surrogate.labels import FootprintLabels, ModelLabels, TextureMonteCarloLabels

    if choice not in LABEL_CHOICES:
        raise ConfigError(f"unknown label source {choice!r}; choose one of {', '.join(LABEL_CHOICES)}",
                          field="--labels")
    if choice == "model":
        return ModelLabels(model, params)
    if not model.has_texture:
        raise ConfigError(f"model kind {model.kind!r} has no texture model to average over footprints; "
                          "use --labels model", field="--labels")
    texture = model.texture(seed=seed)
    if choice == "sat":
        if footprint_estimate is None:
            raise ConfigError("the footprint estimator (clothlab.footprint) is not available; use --labels mc",
                              field="--labels")
        return FootprintLabels(footprint_estimate, texture, params, method="sat")
    return TextureMonteCarloLabels(texture, params, samples=max(2, samples), seed=seed,
                                   tile_average=ModelLabels(model, params))


def material_grid(table, base: dict, vary) -> tuple[list[dict], list[int]]:
    """Parameter sets of ``--vary NAME=LO:HI:N`` (all combinations, then the held-out midpoints) and the
    indices of the held-out ones; ``[base], []`` without ``--vary``.  LO and HI are plain decimal numbers
    (:func:`clothlab.untrusted.parse_number`) inside NAME's fit bounds with LO < HI, N an integer from 2 to
    :data:`MAX_VARY_STEPS`, NAME a parameter given once; the grid holds at most :data:`MAX_VARY_MATERIALS`
    materials.  ConfigError at ``--vary`` otherwise."""
    axes, mids = [], []
    for text in vary:
        shown = repr(text) if len(text) <= 60 else repr(text[:57] + "...")
        parts = text.split("=", 1)
        pieces = parts[1].split(":") if len(parts) == 2 else []
        if len(pieces) != 3:
            raise ConfigError(f"expected NAME=LO:HI:N, got {shown}", field="--vary")
        name = parts[0].strip()
        if name not in table.names():
            varied = ", ".join(n for n in table.names() if n != "orientation")
            raise ConfigError(f"unknown parameter {name[:60]!r} in {shown}; parameters: {varied}", field="--vary")
        if name in [a[0] for a in axes]:
            raise ConfigError(f"parameter {name!r} is varied twice", field="--vary")
        if name == "orientation":  # models.base.ORIENTATION: a rotation of the directions, not an encoder input
            raise ConfigError("orientation is a rotation applied outside the network and cannot be varied",
                              field="--vary")
        try:
            lo, hi = (parse_number(x, error=ConfigError, field="--vary") for x in pieces[:2])
        except ConfigError as exc:
            raise ConfigError(f"{shown}: LO and HI: {exc.detail}", field="--vary") from None
        if not re.fullmatch(r"[0-9]{1,6}", pieces[2].strip()):
            raise ConfigError(f"N = {pieces[2][:20]!r} in {shown} is not an integer from 2 to {MAX_VARY_STEPS}",
                              field="--vary")
        n = int(pieces[2])
        spec = table[name]
        if not 2 <= n <= MAX_VARY_STEPS or not (spec.bounds[0] <= lo < hi <= spec.bounds[1]):
            raise ConfigError(f"{name}: need 2 <= N <= {MAX_VARY_STEPS} and {spec.bounds[0]:g} <= LO < HI <= "
                              f"{spec.bounds[1]:g}, got {shown}", field="--vary")
        steps = [len(a[1]) for a in axes] + [n]
        total = math.prod(steps) + math.prod(k - 1 for k in steps)
        if total > MAX_VARY_MATERIALS:
            raise ConfigError(f"the --vary grid has {total} materials (with its held-out midpoints); at most "
                              f"{MAX_VARY_MATERIALS}", field="--vary")
        t = np.linspace(spec.to_internal(lo), spec.to_internal(hi), 2 * n - 1)
        values = [float(spec.from_internal(x)) for x in t]
        axes.append((name, values[::2]))
        mids.append((name, values[1::2]))
    if not axes:
        return [dict(base)], []
    sets = [dict(base, **dict(zip([a[0] for a in axes], combo, strict=True)))
            for combo in itertools.product(*[a[1] for a in axes])]
    held = [dict(base, **dict(zip([a[0] for a in mids], combo, strict=True)))
            for combo in itertools.product(*[a[1] for a in mids])]
    return sets + held, list(range(len(sets), len(sets) + len(held)))


def material_draw(weave_name: str, base: dict, n: int, share: float, seed: int, *, draw,
                  heldout_all: bool = False):
    """``n`` parameter sets for one weave from ``draw(rng, n, base)`` (e.g.
    :func:`clothlab.models.surface.parameters.draw_table2`, Table 2; ``rng`` seeded by (seed, weave name),
    ``base`` the weave's gap and blend) and the indices of the held-out ones: a seeded ``share`` of them (at
    least one when n >= 2), or all with ``heldout_all``."""
    rng = np.random.default_rng([seed, 104723, zlib.crc32(weave_name.encode())])
    sets = draw(rng, n, base={k: base[k] for k in ("gap", "blend") if k in base})
    if heldout_all:
        return sets, list(range(n))
    k = 0 if n < 2 else min(n - 1, max(1, int(round(share * n))))
    return sets, sorted(int(i) for i in rng.permutation(n)[:k])
