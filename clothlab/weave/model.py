"""Weave patterns: the tile, which yarn covers each cell, and the geometry of each yarn segment type.

Irawan & Marschner 2012, sec. 3.1 and 5: a fabric is a repeating tile of *segment rectangles*; each visible
yarn segment is a curved cylinder whose geometry (twist psi, maximum inclination umax, spine curvature
kappa, width w, length l) is shared by all segments of one *segment type*.  clothlab has two segment types,
``warp`` and ``weft`` (as every fabric of the paper), plus the per-fabric fibre parameters alpha, beta,
delta (eqs. 7, 9) and the texture fields (hWidth, areas, noise) of the published weave files.

Units: angles in degrees (as in the weave files and fabric.yaml), ``w`` and ``l`` in tile cells.
Pattern rows are listed from the top of the tile; segment centres are tile fractions with V measured from
the bottom of the tile (values outside [0, 1] occur and wrap around the tile).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

YARN_KINDS = ("warp", "weft")


@dataclass(frozen=True)
class YarnGeometry:
    """Geometry of one segment type (paper Table I): psi, umax in degrees; kappa unitless; w, l in cells."""

    psi: float
    umax: float
    kappa: float
    w: float
    l: float


@dataclass(frozen=True)
class Segment:
    """One yarn segment of the tile: its 1-based id in the pattern, its kind and its centre (tile fractions)."""

    yarn: int
    kind: str
    center_u: float
    center_v: float


@dataclass(frozen=True, eq=False)
class Weave:
    """A weave tile with its segments, the two segment types and the fibre/texture parameters."""

    name: str
    pattern: np.ndarray  # (H, W) int, 1-based segment ids, row 0 = top of the tile
    segments: tuple[Segment, ...]
    warp: YarnGeometry
    weft: YarnGeometry
    alpha: float = 0.05  # uniform scattering (eq. 7)
    beta: float = 4.0  # forward scattering (eq. 7)
    delta: float = 0.0  # filament smoothing (eq. 9), the weave files' 'ss'
    hwidth: float = 0.5  # highlight band width as a fraction of the segment (eq. 12)
    warp_area: float = 1.0
    weft_area: float = 1.0
    fineness: float = 0.0  # intensity-noise cells per unit (sec. 7.2.1); 0 = none
    dumax: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # warp<-warp, warp<-weft, weft<-warp, weft<-weft
    period: float = 0.0  # Perlin period of the umax modulation; 0 = none
    source: str | None = field(default=None, compare=False)
    #: the IM model's ``filament_arc`` a fit used (``full`` | ``shortened``), recorded by the ``.wv`` export of a
    #: fit (a comment the format's readers skip); None when not recorded (presets, hand-written files)
    filament_arc: str | None = field(default=None, compare=False)

    def __eq__(self, other) -> bool:
        if not isinstance(other, Weave):
            return NotImplemented
        names = [f.name for f in fields(self) if f.compare and f.name != "pattern"]
        return np.array_equal(self.pattern, other.pattern) and all(
            getattr(self, n) == getattr(other, n) for n in names)

    __hash__ = None

    @property
    def tile_width(self) -> int:
        return int(self.pattern.shape[1])

    @property
    def tile_height(self) -> int:
        return int(self.pattern.shape[0])

    def geometry(self, kind: str) -> YarnGeometry:
        if kind == "warp":
            return self.warp
        if kind == "weft":
            return self.weft
        raise ValueError(f"yarn kind must be 'warp' or 'weft', got {kind!r}")

    def area_share(self, kind: str) -> float:
        """The fraction of the tile covered by ``kind`` (from warpArea / weftArea, as the published renderer)."""
        total = self.warp_area + self.weft_area
        return (self.warp_area if kind == "warp" else self.weft_area) / total

    def cell_share(self, kind: str) -> float:
        """The fraction of pattern cells covered by segments of ``kind`` (a check on the declared areas)."""
        kinds = {s.yarn: s.kind for s in self.segments}
        cells = np.vectorize(lambda y: kinds.get(int(y), ""))(self.pattern)
        return float(np.mean(cells == kind))

    def with_geometry(self, kind: str, **changes) -> Weave:
        """A copy with some fields of one segment type changed."""
        return replace(self, **{kind: replace(self.geometry(kind), **changes)})
