"""Bench section ``btf``: memory and throughput of BTF stack streaming (6,561 images of 256 x 256 px loaded
and tile-averaged under a 2 GB peak; 200 images in the quick run).

A synthetic stack is written to a temporary directory as 8-bit sRGB PNGs in UTIA layout on the UTIA 81 x 81
direction sampling (theta 0/15/30/45/60/75 deg with 1/6/12/18/20/24 azimuths), each a periodic weave-like
pattern of known period (px, py) whose brightness depends on the angles.  The stack is then opened (all
headers checked) and streamed through :meth:`clothlab.btf.stack.BtfStack.tile_averages`.
"""

from __future__ import annotations

import struct
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

#: UTIA sampling: polar angle (deg) -> number of equally spaced azimuths.
UTIA_RINGS = ((0, 1), (15, 6), (30, 12), (45, 18), (60, 20), (75, 24))
BENCH_PERIOD = (23.7, 19.3)  # px, py of the synthetic pattern (pixels)
QUICK_IMAGES = 200


def utia_directions() -> np.ndarray:
    """(81, 2) theta, phi in degrees of the UTIA BTF sampling."""
    return np.array([(theta, k * 360.0 / n) for theta, n in UTIA_RINGS for k in range(n)])


def synthetic_weave(size: int, period=BENCH_PERIOD) -> np.ndarray:
    """(size, size) pattern in [0, 1] periodic with (px, py): a plain-weave-like checker of soft bumps."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    u, v = 2 * np.pi * x / period[0], 2 * np.pi * y / period[1]
    pattern = 0.5 + 0.25 * np.cos(u) * np.cos(v) + 0.15 * np.cos(u + v) + 0.1 * np.sin(2 * u - v)
    return np.clip(pattern, 0.0, 1.0)


def png_bytes(pixels: np.ndarray, level: int = 1) -> bytes:
    """A minimal 8-bit RGB PNG (filter 0, zlib ``level``): the benchmark's fixture writer, ~10x faster than
    OpenImageIO's PNG output for 256 x 256 images, so generating 6,561 images does not dominate the run."""
    height, width, _ = pixels.shape

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    rows = np.concatenate([np.zeros((height, 1), np.uint8), pixels.reshape(height, -1)], axis=1)
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows.tobytes(), level))
            + chunk(b"IEND", b""))


def write_synthetic_stack(directory, n_images: int, size: int, *, seed: int = 0) -> list[Path]:
    """Write ``n_images`` 8-bit PNGs (UTIA names) of :func:`synthetic_weave` into ``directory``: a complete
    light x view grid (the loader rejects an incomplete one), all 81 x 81 for 6,561 images, else the first V
    views x the first L lights of the sampling with V L = ``n_images`` and L the largest divisor <= 40 (a
    sub-grid that does not claim the full sampling; 200 = 5 x 40)."""
    directory = Path(directory)
    directions = utia_directions()
    total = len(directions)
    if not 1 <= n_images <= total**2:
        raise ValueError(f"at most {total ** 2} images on the UTIA sampling, asked {n_images}")
    if n_images == total**2:
        n_views, n_lights = total, total
    else:
        n_lights = next((d for d in range(min(40, n_images), 0, -1) if n_images % d == 0 and n_images // d <= 40),
                        None)
        if n_lights is None:
            raise ValueError(f"{n_images} images do not make a sub-grid of at most 40 x 40 directions")
        n_views = n_images // n_lights
    pairs = [(li, vi) for vi in range(n_views) for li in range(n_lights)]
    base = synthetic_weave(size)
    tint = np.array([1.0, 0.8, 0.6])
    rng = np.random.default_rng(seed)
    noise_bank = rng.integers(-6, 7, size=(4, size, size, 3), dtype=np.int16)
    paths = []
    for k, (li, vi) in enumerate(pairs):
        (tl, pl), (tv, pv) = directions[li], directions[vi]
        brightness = 0.3 + 0.6 * np.cos(np.deg2rad(tl)) * (0.5 + 0.5 * np.cos(np.deg2rad(pl - pv)))
        pixels = np.clip(np.rint(255 * brightness * base[:, :, None] * tint) + noise_bank[k % 4], 0, 255)
        folder = directory / f"tv{tv:03.0f}_pv{pv:03.0f}"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"tl{tl:03.0f}_pl{pl:03.0f}_tv{tv:03.0f}_pv{pv:03.0f}.png"
        path.write_bytes(png_bytes(pixels.astype(np.uint8)))
        paths.append(path)
    return paths


def btf_memory_benchmark(n_images: int = 6561, size: int = 256, *, quick: bool = False, directory=None) -> dict:
    """Generate, open and tile-average a synthetic stack; return timings, images/s and peak memory (MB).

    quick: 200 images (the default test).  directory: where to write the stack (default: a temporary
    directory, removed afterwards).  ``passed`` = process peak RSS below 2048 MB and the period found
    within 0.1 px of the true one.
    """
    from clothlab.btf.stack import BtfStack

    if quick:
        n_images = min(n_images, QUICK_IMAGES)
    with tempfile.TemporaryDirectory(prefix="clothlab-btf-bench-", dir=directory) as tmp:
        start = time.perf_counter()
        write_synthetic_stack(tmp, n_images, size)
        generate = time.perf_counter() - start
        start = time.perf_counter()
        stack = BtfStack.open(tmp)
        open_seconds = time.perf_counter() - start
        result = stack.tile_averages()
    period_error = max(abs(result.period.px - BENCH_PERIOD[0]), abs(result.period.py - BENCH_PERIOD[1]))
    figures = {
        "n_images": n_images, "size": size, "generate_seconds": generate, "open_seconds": open_seconds,
        "tile_average_seconds": result.seconds, "images_per_second": result.images_per_second,
        "peak_traced_mb": result.peak_traced_mb, "max_rss_mb": result.max_rss_mb,
        "tile_shape": list(result.tiles.shape[1:]), "period_found": [result.period.px, result.period.py],
        "period_true": list(BENCH_PERIOD), "limit_mb": 2048.0,
    }
    figures["passed"] = bool(result.max_rss_mb < 2048.0 and period_error < 0.1)
    return figures


def run(context) -> dict:
    return btf_memory_benchmark(quick=context.quick)


def lines(f: dict) -> list[str]:
    return [f"== BTF stack: {f['n_images']} images of {f['size']} x {f['size']} px ==",
            f"  {f['images_per_second']:.0f} images/s (tile averaging), open {f['open_seconds']:.1f} s, generate "
            f"{f['generate_seconds']:.1f} s; peak traced {f['peak_traced_mb']:.0f} MB, process peak RSS "
            f"{f['max_rss_mb']:.0f} MB (limit {f['limit_mb']:.0f} MB); period {f['period_found'][0]:.3f} x "
            f"{f['period_found'][1]:.3f} px (true {f['period_true'][0]} x {f['period_true'][1]}); "
            f"{'PASS' if f['passed'] else 'FAIL'}"]
