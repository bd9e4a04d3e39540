"""Weave period by autocorrelation and unit-tile averaging (Irawan & Marschner 2012, sec. 4.2 and Fig. 3).

The paper recovers the regular weave pattern of a macro photograph "by averaging all the unit tiles in the
measured image".  Here the tile is found from the image itself:

1. :func:`autocorrelation` - the 2-D autocorrelation of the (channel-mean, mean-removed) image by FFT with
   zero padding (no wrap-around), normalised by the energies of the two overlapping windows of each lag,
   so a perfectly periodic image scores exactly 1 at every lattice vector.
2. :func:`period_from_autocorrelation` - the axis-aligned periods px (along image columns) and py (along rows)
   are the lags of the highest local maximum of the lag-axis profiles; a divisor of that lag whose peak
   reaches ``ratio`` x its height is preferred (so 2 px is never reported for px).  Sub-pixel refinement:
   a parabola through each harmonic peak k p (k = 1 .. as many as fit in half the image) and the
   least-squares fit pos_k = k p.  The 2-D fundamental lattice vectors (twills are sheared lattices) are the
   shortest two independent lags among the 2-D peaks that reach ``ratio`` x the highest one.
3. :func:`average_tiles` - resamples every whole tile on an (ny, nx) grid of spacing (py / ny, px / nx)
   with bilinear interpolation and averages them into one tile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clothlab.errors import InputError


@dataclass(frozen=True)
class Period:
    """Weave tile of an image in pixels: px along columns (x), py along rows (y).

    ``lattice`` (2, 2): two fundamental lattice vectors as rows (dx, dy) in pixels, or None when no 2-D
    lattice was resolved; ``strength``: the normalised autocorrelation at (px, 0) and (0, py).
    """

    px: float
    py: float
    lattice: np.ndarray | None = None
    strength: tuple[float, float] = (float("nan"), float("nan"))

    def to_dict(self) -> dict:
        return {"px": self.px, "py": self.py, "strength": list(self.strength),
                "lattice": None if self.lattice is None else self.lattice.tolist()}


def grey(image: np.ndarray) -> np.ndarray:
    """Channel mean of an (H, W) or (H, W, C) image as float64 (H, W)."""
    image = np.asarray(image)
    return image.astype(np.float64) if image.ndim == 2 else image.mean(axis=2, dtype=np.float64)


def _window_sums(squares: np.ndarray, dy: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """Sums of ``squares`` over rows [max(0, -dy), H - max(0, dy)) x cols [max(0, -dx), W - max(0, dx))."""
    height, width = squares.shape
    table = np.zeros((height + 1, width + 1))
    table[1:, 1:] = squares.cumsum(axis=0).cumsum(axis=1)
    r0, r1 = np.maximum(0, -dy), height - np.maximum(0, dy)
    c0, c1 = np.maximum(0, -dx), width - np.maximum(0, dx)
    return table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0]


def autocorrelation(image: np.ndarray) -> np.ndarray:
    """Normalised autocorrelation (2 h + 1, 2 w + 1) for lags |dy| <= h = H // 2, |dx| <= w = W // 2.

    Centred: element [h + dy, w + dx] is sum g(p) g(p + d) / sqrt(E1 E2) over the overlap of the image and
    its shift by d, with g the mean-removed channel mean and E1, E2 the energies of g in the two overlapping
    windows (normalised cross-correlation).  It is exactly 1 at a lattice vector of a periodic image whatever
    part of a period the overlap holds, so the peaks are not biased by partial periods at the image border.
    """
    g = grey(image)
    g = g - g.mean()
    height, width = g.shape
    shape = (2 * height, 2 * width)
    spectrum = np.fft.rfft2(g, s=shape)
    ac = np.fft.irfft2(spectrum * np.conj(spectrum), s=shape)
    h, w = height // 2, width // 2
    ac = np.roll(ac, (h, w), axis=(0, 1))[: 2 * h + 1, : 2 * w + 1]
    dy = np.arange(-h, h + 1)[:, None]
    dx = np.arange(-w, w + 1)[None, :]
    squares = g * g
    energy = _window_sums(squares, dy, dx) * _window_sums(squares, -dy, -dx)
    if not energy[h, w] > 0:
        raise ValueError("the image is constant: no pattern to correlate")
    return ac / np.sqrt(np.maximum(energy, 1e-300 * energy[h, w]))


def _parabola_peak(values: np.ndarray, index: int) -> float:
    """Sub-pixel position of a local maximum at ``index`` (parabola through three samples)."""
    if index <= 0 or index >= len(values) - 1:
        return float(index)
    left, mid, right = values[index - 1], values[index], values[index + 1]
    denom = left - 2.0 * mid + right
    if denom >= 0:
        return float(index)
    return index + 0.5 * (left - right) / denom


def _local_maxima(profile: np.ndarray, start: int) -> np.ndarray:
    inner = np.arange(max(start, 1), len(profile) - 1)
    keep = (profile[inner] > profile[inner - 1]) & (profile[inner] >= profile[inner + 1])
    return inner[keep]


def axis_period(profile: np.ndarray, *, min_period: float = 3.0, ratio: float = 0.9) -> tuple[float, float]:
    """Fundamental period (samples, sub-pixel) and its correlation from a 1-D autocorrelation profile.

    ``profile[k]`` is the correlation at lag k >= 0.  Returns (nan, nan) when the profile has no peak.
    """
    profile = np.asarray(profile, dtype=np.float64)
    peaks = _local_maxima(profile, math.ceil(min_period))
    if peaks.size == 0:
        return float("nan"), float("nan")
    best = int(peaks[np.argmax(profile[peaks])])
    height = profile[best]
    fundamental = best
    for k in range(int(best // min_period), 1, -1):  # the largest divisor first = the shortest period
        target = best / k
        near = peaks[np.abs(peaks - target) <= max(1.0, 0.1 * target)]
        if near.size and profile[near].max() >= ratio * height:
            fundamental = int(near[np.argmax(profile[near])])
            break
    # least-squares fit of harmonic peak positions pos_k = k p (refinement)
    p0 = _parabola_peak(profile, fundamental)
    orders, positions = [], []
    for k in range(1, int((len(profile) - 2) // p0) + 1):
        centre = int(round(k * p0))
        reach = max(1, int(math.ceil(0.15 * p0)))
        lo, hi = max(1, centre - reach), min(len(profile) - 2, centre + reach)
        if lo > hi:
            break
        index = lo + int(np.argmax(profile[lo: hi + 1]))
        if index in (lo, hi) and hi - lo >= 2:  # the window edge, not a peak
            continue
        if profile[index] < 0.5 * ratio * height:
            continue
        orders.append(k)
        positions.append(_parabola_peak(profile, index))
    orders_arr, positions_arr = np.asarray(orders, float), np.asarray(positions, float)
    period = float(orders_arr @ positions_arr / (orders_arr @ orders_arr)) if orders else p0
    return period, float(profile[fundamental])


def lattice_vectors(ac: np.ndarray, *, min_period: float = 3.0, ratio: float = 0.9) -> np.ndarray | None:
    """The two shortest independent lags (rows (dx, dy), pixels) among the high 2-D autocorrelation peaks."""
    h, w = (ac.shape[0] - 1) // 2, (ac.shape[1] - 1) // 2
    inner = ac[1:-1, 1:-1]
    is_peak = np.ones(inner.shape, dtype=bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                is_peak &= inner >= ac[1 + dr: ac.shape[0] - 1 + dr, 1 + dc: ac.shape[1] - 1 + dc]
    rows, cols = np.nonzero(is_peak)
    rows, cols = rows + 1, cols + 1
    dy, dx = rows - h, cols - w
    far = np.hypot(dx, dy) >= min_period
    rows, cols, dy, dx = rows[far], cols[far], dy[far], dx[far]
    if rows.size == 0:
        return None
    values = ac[rows, cols]
    strong = values >= ratio * values.max()
    rows, cols = rows[strong], cols[strong]
    order = np.argsort(np.hypot(cols - w, rows - h), kind="stable")
    vectors = []
    for r, c in zip(rows[order], cols[order], strict=True):
        vec = np.array([_parabola_peak(ac[r], c) - w, _parabola_peak(ac[:, c], r) - h])
        if not vectors:
            vectors.append(vec)
            continue
        a = vectors[0]
        if abs(a[0] * vec[1] - a[1] * vec[0]) > 0.2 * np.linalg.norm(a) * np.linalg.norm(vec):
            vectors.append(vec)
            break
    if len(vectors) < 2:
        return None
    lattice = np.array(vectors)
    lattice[lattice[:, 1] < 0] *= -1  # point both vectors downwards (dy >= 0)
    return lattice


def period_from_autocorrelation(ac: np.ndarray, *, min_period: float = 3.0, ratio: float = 0.9,
                                path=None) -> Period:
    """:class:`Period` from a centred autocorrelation (:func:`autocorrelation`); InputError if none is found."""
    h, w = (ac.shape[0] - 1) // 2, (ac.shape[1] - 1) // 2
    px, sx = axis_period(ac[h, w:], min_period=min_period, ratio=ratio)
    py, sy = axis_period(ac[h:, w], min_period=min_period, ratio=ratio)
    if not (np.isfinite(px) and np.isfinite(py)):
        raise InputError(
            f"no periodic weave pattern found (autocorrelation has no peak between {min_period:g} px and half the "
            f"image along {'columns' if not np.isfinite(px) else 'rows'}); pass the period in pixels", path=path)
    return Period(px=px, py=py, lattice=lattice_vectors(ac, min_period=min_period, ratio=ratio),
                  strength=(sx, sy))


def estimate_period(image: np.ndarray, *, min_period: float = 3.0, ratio: float = 0.9, path=None) -> Period:
    """Weave period (pixels) of an (H, W[, C]) image; see the module docstring for the method."""
    return period_from_autocorrelation(autocorrelation(image), min_period=min_period, ratio=ratio, path=path)


def tile_grid(length: int, period: float, samples: int, origin: float = 0.0) -> np.ndarray:
    """Sample positions (tiles, samples) of every whole tile along one axis (pixel centres at integers)."""
    step = period / samples
    last = origin + (samples - 1) * step  # last sample of the first tile
    tiles = int(math.floor((length - 1 - last) / period + 1e-9)) + 1 if last <= length - 1 else 0
    return origin + np.arange(tiles)[:, None] * period + np.arange(samples)[None, :] * step


def tile_weights(length: int, period: float, samples: int, origin: float = 0.0) -> tuple[np.ndarray, int]:
    """(samples, length) matrix A with (A @ f)[j] = mean over whole tiles k of f linearly interpolated at
    origin + k period + j period / samples, and the number of whole tiles (0: none fits)."""
    coords = tile_grid(length, period, samples, origin)
    tiles = coords.shape[0]
    weights = np.zeros((samples, length))
    if tiles == 0:
        return weights, 0
    base = np.clip(np.floor(coords).astype(np.intp), 0, max(length - 2, 0))
    frac = coords - base
    rows = np.broadcast_to(np.arange(samples)[None, :], coords.shape)
    np.add.at(weights, (rows, base), (1.0 - frac) / tiles)
    np.add.at(weights, (rows, np.minimum(base + 1, length - 1)), frac / tiles)
    return weights, tiles


def average_tiles(image: np.ndarray, period, *, samples: tuple[int, int] | None = None,
                  origin: tuple[float, float] = (0.0, 0.0), path=None) -> np.ndarray:
    """Average of all whole unit tiles of an (H, W, C) image (paper Fig. 3) -> (ny, nx, C) float32.

    ``period``: a :class:`Period` or (px, py) in pixels; ``samples`` (nx, ny) defaults to
    (round(px), round(py)); ``origin`` (x0, y0) is the pixel position of the first tile's corner.
    Bilinear interpolation at the sub-pixel tile grid; interpolation and averaging are linear and separable,
    so the tile is Ay @ image @ Ax^T with the (n, length) weight matrices of :func:`tile_weights`.
    """
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 2:
        image = image[:, :, None]
    px, py = (period.px, period.py) if isinstance(period, Period) else (float(period[0]), float(period[1]))
    if not (px >= 1.0 and py >= 1.0):
        raise InputError(f"tile period must be at least 1 pixel, got px={px:g}, py={py:g}", path=path,
                         field="period")
    nx, ny = samples if samples is not None else (max(1, round(px)), max(1, round(py)))
    height, width, _ = image.shape
    ax, tiles_x = tile_weights(width, px, nx, origin[0])
    ay, tiles_y = tile_weights(height, py, ny, origin[1])
    if tiles_x == 0 or tiles_y == 0:
        raise InputError(f"the {width} x {height} image holds no whole {px:.3g} x {py:.3g} px tile", path=path,
                         field="period")
    # einsum (not BLAS matmul): small products, and OpenBLAS threads stall badly on a busy machine
    rows = np.einsum("ih,hwc->iwc", ay.astype(np.float32), image)  # (ny, W, C)
    return np.einsum("jw,iwc->ijc", ax.astype(np.float32), rows).astype(np.float32)
