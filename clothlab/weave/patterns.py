"""Generated weave patterns: the seven patterns of Chen, Wang & Wang 2024 (sec. 5.1, Table 2) as weaves
clothlab can name (``weave: pattern:<name>`` in fabric.yaml).

A pattern is a W x H grid of which yarn is on top (warp or weft); each float (a run of cells where one
yarn stays on top, cyclic over the tile) becomes one segment, 1 cell wide and as long as the run, centred
on the run (:class:`clothlab.weave.model.Segment`).  Every warp float of a pattern has the same length
and so has every weft float, so one geometry per yarn type describes the tile (``l`` = float length,
``w`` = 1).  Rows count from the bottom here (V up); the weave's pattern lists them from the top.

===============  =====  ======================================================================================
name             tile   grid (column c, row r from the bottom; warp on top where)
===============  =====  ======================================================================================
plain            2x2    (c + r) even                                                     (floats 1 / 1)
twill-3x3        3x3    (r - c) mod 3 < 2     a 2/1 twill                                (warp 2, weft 1)
twill-5x5        5x5    (r - c) mod 5 < 3     a 3/2 twill                                (warp 3, weft 2)
twill-8x8        8x8    (r - c) mod 8 < 4     a 4/4 twill                                (warp 4, weft 4)
satin-5x5        5x5    r != 2 c mod 5        warp-faced satin, move 2                   (warp 4, weft 1)
satin-8x8        8x8    r != 3 c mod 8        warp-faced satin, move 3                   (warp 7, weft 1)
satin-5x10       5x10   r != 3 c mod 10       warp-faced, 5 wide, 10 high, move 3        (warp 9, weft 1)
===============  =====  ======================================================================================

The paper names the patterns but not their floats (its supplement's Fig. 1 draws them); the twills
above split the repeat as evenly as possible, the satins are the usual warp-faced ones (move numbers 2
and 3); in satin-5x10 five of the ten weft rows lie wholly under the warp and show no segment.
Geometry defaults: psi = 0, umax = 30 deg (Table 2's middle), kappa = 0; fineness 0 (no IM noise).
"""

from __future__ import annotations

import numpy as np

from clothlab.errors import ConfigError
from clothlab.weave.model import Segment, Weave, YarnGeometry

PATTERN_PREFIX = "pattern:"


def _twill(n: int, up: int):
    return lambda c, r: np.mod(r - c, n) < up


PATTERNS = {
    "plain": ((2, 2), lambda c, r: np.mod(c + r, 2) == 0),
    "twill-3x3": ((3, 3), _twill(3, 2)),
    "twill-5x5": ((5, 5), _twill(5, 3)),
    "twill-8x8": ((8, 8), _twill(8, 4)),
    "satin-5x5": ((5, 5), lambda c, r: r != np.mod(2 * c, 5)),
    "satin-8x8": ((8, 8), lambda c, r: r != np.mod(3 * c, 8)),
    "satin-5x10": ((5, 10), lambda c, r: r != np.mod(3 * c, 10)),
}
PATTERN_NAMES = tuple(PATTERNS)


def _runs(line: np.ndarray) -> list[tuple[int, int]]:
    """Cyclic runs of True in a 1-D bool array: (start, length); a line all True is one run from 0."""
    n = line.size
    if line.all():
        return [(0, n)]
    runs = []
    for start in range(n):
        if line[start] and not line[start - 1]:
            length = 1
            while line[(start + length) % n]:
                length += 1
            runs.append((start, length))
    return runs


def weave_from_grid(name: str, warp_up: np.ndarray, *, psi: float = 0.0, umax: float = 30.0) -> Weave:
    """The weave of a (H, W) bool grid, rows from the bottom, True where the warp is on top (module
    docstring); ValueError if the warp (or weft) floats differ in length."""
    height, width = warp_up.shape
    pattern = np.zeros((height, width), dtype=np.int64)  # rows from the bottom while building
    segments, lengths = [], {"warp": set(), "weft": set()}
    for c in range(width):
        for start, length in _runs(warp_up[:, c]):
            segments.append(Segment(len(segments) + 1, "warp", (c + 0.5) / width, (start + 0.5 * length) / height))
            pattern[(start + np.arange(length)) % height, c] = len(segments)
            lengths["warp"].add(length)
    for r in range(height):
        for start, length in _runs(~warp_up[r, :]):
            segments.append(Segment(len(segments) + 1, "weft", (start + 0.5 * length) / width, (r + 0.5) / height))
            pattern[r, (start + np.arange(length)) % width] = len(segments)
            lengths["weft"].add(length)
    if len(lengths["warp"]) != 1 or len(lengths["weft"]) > 1:
        raise ValueError(f"pattern '{name}': float lengths differ within a yarn type {lengths}")
    warp_l = lengths["warp"].pop()
    weft_l = lengths["weft"].pop() if lengths["weft"] else 1
    pattern = pattern[::-1].copy()  # rows from the top, as Weave
    pattern.setflags(write=False)
    return Weave(name=name, pattern=pattern, segments=tuple(segments),
                 warp=YarnGeometry(psi, umax, 0.0, 1.0, float(warp_l)),
                 weft=YarnGeometry(psi, umax, 0.0, 1.0, float(weft_l)),
                 warp_area=float(warp_up.sum()), weft_area=float((~warp_up).sum()), source=f"{PATTERN_PREFIX}{name}")


def get_pattern(name: str) -> Weave:
    """The weave of one of :data:`PATTERN_NAMES` (case-insensitive); ConfigError at ``model.weave`` if unknown."""
    key = str(name).strip().lower().replace("_", "-")
    if key not in PATTERNS:
        raise ConfigError(f"unknown weave pattern '{name}'; known patterns: {', '.join(PATTERN_NAMES)}",
                          field="weave")
    (width, height), warp_on_top = PATTERNS[key]
    c, r = np.meshgrid(np.arange(width), np.arange(height))
    return weave_from_grid(key, np.asarray(warp_on_top(c, r), dtype=bool))
