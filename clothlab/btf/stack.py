"""A BTF image stack read lazily, one image at a time (docs/formats.md, "BTF image stacks").

A stack is a directory of images whose names carry the angles (Bonn UBO2003 / UTIA, see
:mod:`clothlab.btf.names` for the naming and the azimuth convention assumed) or a directory / file with a
manifest.  Images are decoded to linear float32 (:mod:`clothlab.btf.images`) only when asked for, so a
6,561-image stack never sits in memory; :meth:`BtfStack.tile_averages` streams the stack into one averaged
unit tile per image (Irawan & Marschner 2012, sec. 4.2, Fig. 3) and reports its peak memory.
"""

from __future__ import annotations

import sys
import time
import tracemalloc
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clothlab.btf import images as imageio
from clothlab.btf.names import (
    WARP_AXES,
    BtfEntry,
    angle_table,
    entries_from_names,
    find_manifest,
    read_manifest,
)
from clothlab.btf.period import (
    Period,
    autocorrelation,
    average_tiles,
    estimate_period,
    period_from_autocorrelation,
)
from clothlab.errors import InputError
from clothlab.frames import spherical_to_vector


def max_rss_mb() -> float:
    """Peak resident set size of this process so far in MB (nan where the platform cannot tell)."""
    try:
        import resource
    except ImportError:  # Windows
        return float("nan")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10  # bytes on macOS, KiB on Linux


@dataclass
class TileAverages:
    """Result of :meth:`BtfStack.tile_averages`.

    tiles: (N, ny, nx, C) float32 linear averaged unit tiles, in stack order; period: the tile in pixels;
    peak_traced_mb: peak of Python/numpy allocations during the call (tracemalloc); max_rss_mb: peak
    resident memory of the whole process so far (an upper bound of the call's peak, includes the readers).
    """

    tiles: np.ndarray
    entries: list[BtfEntry]
    period: Period
    seconds: float
    peak_traced_mb: float
    max_rss_mb: float
    extra: dict = field(default_factory=dict)

    @property
    def images_per_second(self) -> float:
        return len(self.entries) / self.seconds if self.seconds > 0 else float("inf")

    def summary(self) -> dict:
        """JSON-ready figures for reports and benchmarks (no pixel data)."""
        return {"images": len(self.entries), "tile_shape": list(self.tiles.shape[1:]),
                "period": self.period.to_dict(), "seconds": self.seconds,
                "images_per_second": self.images_per_second, "peak_traced_mb": self.peak_traced_mb,
                "max_rss_mb": self.max_rss_mb, **self.extra}


class BtfStack:
    """Image entries with angles (clothlab convention, degrees) and lazy access to their linear pixels.

    ``crop`` = (x0, y0, width, height) in pixels applies to every image.  ``encoding``: 'auto' (8/16-bit
    = sRGB, decoded; half/float = linear), 'srgb' or 'linear'.  ``warp_axis``: the image axis along the
    warp ('vertical' or 'horizontal').  With ``check=True`` every image header is read once at
    construction, so a missing or unreadable file or a size / channel mismatch is reported before any work.
    """

    def __init__(self, entries, *, crop=None, warp_axis: str = "vertical", encoding: str = "auto",
                 source=None, check: bool = True):
        self.entries: list[BtfEntry] = list(entries)
        if not self.entries:
            raise InputError("the BTF stack holds no images", path=source)
        if warp_axis not in WARP_AXES:
            raise InputError(f"warp_axis '{warp_axis}' is not one of {', '.join(WARP_AXES)}", path=source,
                             field="warp_axis")
        if encoding not in imageio.ENCODINGS:
            raise InputError(f"encoding '{encoding}' is not one of {', '.join(imageio.ENCODINGS)}", path=source,
                             field="encoding")
        self.warp_axis = warp_axis
        self.encoding = encoding
        self.source = None if source is None else Path(source)
        self.info = imageio.read_info(self.entries[0].path)
        if check:
            for entry in self.entries[1:]:
                self._check_info(entry.path, imageio.read_info(entry.path))
        self.crop = None if crop is None else tuple(int(c) for c in crop)
        if self.crop is not None:
            imageio.crop_slices(self.crop, self.info.width, self.info.height, self.entries[0].path)

    @classmethod
    def open(cls, path, *, manifest=None, crop=None, warp_axis: str | None = None, encoding: str = "auto",
             check: bool = True, grid: bool | None = None) -> BtfStack:
        """Open a stack directory (manifest.yaml / manifest.csv inside, else angles from the file names)
        or a manifest file.  ``warp_axis`` defaults to the manifest's, else 'vertical'.  ``grid``: the
        completeness check of a name-based stack (:func:`clothlab.btf.names.entries_from_names`: None =
        when the names look like a light x view grid, True = always, False = never)."""
        path = Path(path)
        if manifest is None:
            if path.is_file():
                manifest = path
            elif path.is_dir():
                manifest = find_manifest(path)
            else:
                raise InputError("BTF stack directory or manifest not found", path=path)
        if manifest is not None:
            entries, declared = read_manifest(manifest)
            if warp_axis is not None and warp_axis != declared:
                raise InputError(f"warp_axis '{warp_axis}' was asked for but the manifest declares '{declared}'",
                                 path=manifest, field="warp_axis")
            return cls(entries, crop=crop, warp_axis=declared, encoding=encoding, source=manifest, check=check)
        warp_axis = warp_axis or "vertical"
        return cls(entries_from_names(path, warp_axis=warp_axis, grid=grid), crop=crop, warp_axis=warp_axis,
                   encoding=encoding, source=path, check=check)

    # -- geometry of the images ------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.entries)

    @property
    def width(self) -> int:
        return self.crop[2] if self.crop else self.info.width

    @property
    def height(self) -> int:
        return self.crop[3] if self.crop else self.info.height

    @property
    def channels(self) -> int:
        return self.info.channels

    @property
    def angles(self) -> np.ndarray:
        """(N, 4) theta_i, phi_i, theta_o, phi_o in degrees, clothlab convention."""
        return angle_table(self.entries)

    @property
    def wi(self) -> np.ndarray:
        a = self.angles
        return spherical_to_vector(a[:, 0], a[:, 1])

    @property
    def wo(self) -> np.ndarray:
        a = self.angles
        return spherical_to_vector(a[:, 2], a[:, 3])

    def _check_info(self, path: Path, info: imageio.ImageInfo) -> None:
        first = self.info
        if (info.width, info.height) != (first.width, first.height):
            raise InputError(f"image is {info.width} x {info.height} px but the stack's first image "
                             f"{self.entries[0].path.name} is {first.width} x {first.height} px", path=path)
        if info.channels != first.channels:
            raise InputError(f"image has {info.channels} channel(s) but the stack's first image "
                             f"{self.entries[0].path.name} has {first.channels}", path=path)

    # -- pixels ------------------------------------------------------------------------------------------
    def image(self, index: int) -> np.ndarray:
        """Linear float32 (height, width, channels) pixels of image ``index`` (cropped)."""
        entry = self.entries[index]
        pixels, info = imageio.read_image(entry.path, crop=None, encoding=self.encoding)
        self._check_info(entry.path, info)
        if self.crop is not None:
            pixels = np.ascontiguousarray(pixels[imageio.crop_slices(self.crop, info.width, info.height)])
        return pixels

    def __iter__(self) -> Iterator[tuple[BtfEntry, np.ndarray]]:
        for index, entry in enumerate(self.entries):
            yield entry, self.image(index)

    def estimate_period(self, *, images: int = 8, min_period: float = 3.0, ratio: float = 0.9) -> Period:
        """Weave period (pixels) from the mean autocorrelation of up to ``images`` evenly spread images."""
        picks = np.unique(np.linspace(0, len(self) - 1, min(images, len(self))).round().astype(int))
        total, used = None, 0
        for index in picks:
            try:
                ac = autocorrelation(self.image(int(index)))
            except ValueError:  # a constant (e.g. black) image carries no pattern
                continue
            total = ac if total is None else total + ac
            used += 1
        if total is None:
            raise InputError("every sampled image is constant: no weave pattern to find the period from",
                             path=self.source)
        return period_from_autocorrelation(total / used, min_period=min_period, ratio=ratio, path=self.source)

    def tile_average(self, index: int, period=None, *, samples=None, origin=(0.0, 0.0)) -> np.ndarray:
        """Averaged unit tile (ny, nx, C) of one image; ``period`` (Period or (px, py)) defaults to the
        image's own estimate."""
        pixels = self.image(index)
        path = self.entries[index].path
        if period is None:
            period = estimate_period(pixels, path=path)
        return average_tiles(pixels, period, samples=samples, origin=origin, path=path)

    def tile_averages(self, period=None, *, samples=None, origin=(0.0, 0.0), reference_images: int = 8,
                      progress: Callable[[int, int], None] | None = None,
                      max_tile_bytes: int = 2**31) -> TileAverages:
        """Stream the stack into one averaged unit tile per image (one image in memory at a time).

        ``period`` (Period or (px, py) pixels) defaults to :meth:`estimate_period` over
        ``reference_images`` images, so every tile has the same shape.  ``progress(done, total)`` is called
        after each image.  Reports the time and peak memory (see :class:`TileAverages`).
        """
        start = time.perf_counter()
        tracing = tracemalloc.is_tracing()
        if tracing:
            tracemalloc.reset_peak()
        else:
            tracemalloc.start()
        try:
            if period is None:
                period = self.estimate_period(images=reference_images)
            elif not isinstance(period, Period):
                period = Period(px=float(period[0]), py=float(period[1]))
            nx, ny = samples if samples is not None else (max(1, round(period.px)), max(1, round(period.py)))
            need = len(self) * nx * ny * self.channels * 4
            if need > max_tile_bytes:
                raise InputError(f"{len(self)} tiles of {nx} x {ny} px need {need / 2**20:.0f} MB, more than "
                                 f"max_tile_bytes = {max_tile_bytes / 2**20:.0f} MB; crop or pass a period",
                                 path=self.source, field="period")
            tiles = np.empty((len(self), ny, nx, self.channels), dtype=np.float32)
            for index, (entry, pixels) in enumerate(self):
                tiles[index] = average_tiles(pixels, period, samples=(nx, ny), origin=origin, path=entry.path)
                del pixels
                if progress is not None:
                    progress(index + 1, len(self))
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            if not tracing:
                tracemalloc.stop()
        return TileAverages(tiles=tiles, entries=list(self.entries), period=period,
                            seconds=time.perf_counter() - start, peak_traced_mb=peak / 2**20,
                            max_rss_mb=max_rss_mb())
