"""Where a texture point falls in the weave tile, and the geometric constraint of each segment type.

Irawan & Marschner 2012, sec. 5 and 7.2: the cloth surface is tiled by segment rectangles, ``w`` across by
``l`` along the yarn; the texture model (eqs. 11-13) and the Kang shader need, for a texture point, the
segment covering it and the point's coordinates (x across, y along the yarn) from the segment's centre.

Conventions (those of the published weave files):

- ``u`` runs across the tile in the weft direction (fabric x), ``v`` along the warp (fabric y), both in
  tile units; tiles repeat, any real value is allowed.  In cells: ``U = u * tile_width``,
  ``V = v * tile_height``.
- Pattern rows are listed from the *top* of the tile, ``V`` is measured from the *bottom*: the cell
  ``(U, V)`` is ``pattern[H - 1 - floor(V) mod H, floor(U) mod W]``.
- Segment centres are ``(center_u * W, center_v * H)`` cells; the periodic image nearest the point is used.
- Warp: ``x = dU`` (across), ``y = dV`` (along).  Weft: the yarn frame is the fabric frame rotated by
  +90 deg about z (:func:`clothlab.frames.to_yarn_frame`), so ``x = -dV``, ``y = dU``: y always runs
  along the yarn, and directions must be rotated with ``to_yarn_frame(w, 'weft')`` to match.
"""

from __future__ import annotations

import numpy as np

from clothlab.weave.model import YARN_KINDS, Weave


def _segment_tables(weave: Weave):
    """Lookup tables: yarn id -> segment index, and per segment index: centre (cells) and is-weft."""
    ids = np.array([s.yarn for s in weave.segments], dtype=np.int64)
    index_of_id = np.full(max(int(ids.max()), int(weave.pattern.max())) + 1, -1, dtype=np.int64)
    index_of_id[ids] = np.arange(len(ids))
    centre_u = np.array([s.center_u for s in weave.segments]) * weave.tile_width
    centre_v = np.array([s.center_v for s in weave.segments]) * weave.tile_height
    is_weft = np.array([s.kind == "weft" for s in weave.segments])
    return index_of_id, centre_u, centre_v, is_weft


def _nearest_image(d: np.ndarray, period: int) -> np.ndarray:
    """``d`` shifted by a multiple of ``period`` into [-period/2, period/2)."""
    return d - period * np.floor(d / period + 0.5)


def locate_segments(weave: Weave, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The segment covering each texture point and the point's coordinates in that segment (sec. 7.2).

    ``u``, ``v``: texture coordinates in tile units (broadcast together; any real values).
    Returns ``(segment_index, x, y)``: the index into ``weave.segments`` (int) and the local coordinates
    in cells from the segment's centre, ``x`` across and ``y`` along the yarn (see the module docstring).
    """
    u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(v))):
        raise ValueError("texture coordinates u, v must be finite")
    width, height = weave.tile_width, weave.tile_height
    index_of_id, centre_u, centre_v, is_weft = _segment_tables(weave)
    big_u, big_v = u * width, v * height  # cells
    col = np.mod(np.floor(big_u), width).astype(np.int64)
    row = height - 1 - np.mod(np.floor(big_v), height).astype(np.int64)  # rows from the top
    seg = index_of_id[weave.pattern[row, col]]
    if np.any(seg < 0):
        missing = sorted({int(i) for i in weave.pattern[row, col][seg < 0]})
        raise ValueError(f"weave '{weave.name}': pattern yarn ids {missing} have no segment")
    du = _nearest_image(big_u - centre_u[seg], width)
    dv = _nearest_image(big_v - centre_v[seg], height)
    weft = is_weft[seg]
    x = np.where(weft, -dv, du)
    y = np.where(weft, du, dv)
    return seg, x, y


def segment_constraint_violations(weave: Weave) -> list[str]:
    """Messages for each segment type violating (w/2) sin(umax) < l/2 (paper sec. 5.3); empty if none.

    Where it fails, the torus radius R = (l/2 - (w/2) sin umax) / sin umax is not positive and the
    segment's curved cylinder does not fit its rectangle (the published renderer then returns zero).
    """
    messages = []
    for kind in YARN_KINDS:
        g = weave.geometry(kind)
        projected = g.w * np.sin(np.deg2rad(g.umax))
        if projected >= g.l:
            messages.append(
                f"weave '{weave.name}', {kind} yarn: w sin(umax) = {g.w:g} * sin({g.umax:g} deg) = "
                f"{projected:.4g} >= l = {g.l:g}; the segment constraint (w/2) sin(umax) < l/2 of "
                "Irawan & Marschner sec. 5.3 fails (the torus radius R would be <= 0)")
    return messages
