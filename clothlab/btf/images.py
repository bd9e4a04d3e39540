"""Image files through OpenImageIO, with the reader's error state checked (docs/libraries.md, docs/formats.md).

Reading returns linear float32 (H, W, C): 8/16-bit integer images (PNG, JPEG, TIFF) are sRGB-encoded and are
decoded with the exact sRGB EOTF (IEC 61966-2-1); half/float images (EXR, float TIFF) are linear already.
A reader can return pixels for a truncated file (JPEG does), so the error flag is checked after every read
and any error becomes an :class:`~clothlab.errors.InputError` naming the file.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.errors import InputError

ENCODINGS = ("auto", "srgb", "linear")
MAX_IMAGE_BYTES = 2 << 30
"""Largest decoded image (float32 pixels, after the crop's rows are selected) read at once (2 GiB)."""


def check_image_memory(width: int, height: int, channels: int, *, path=None, cropped: bool = False) -> None:
    """InputError naming the image and the ``crop`` option when decoding would exceed :data:`MAX_IMAGE_BYTES`."""
    need = int(width) * int(height) * max(int(channels), 1) * 4
    if need > MAX_IMAGE_BYTES:
        raise InputError(f"decoding {width} x {height} pixels x {channels} channels needs {need / 2**30:.1f} GiB "
                         f"(at most {MAX_IMAGE_BYTES / 2**30:.0f} GiB); "
                         + ("choose a smaller crop" if cropped else "give a crop (x0, y0, width, height)"),
                         path=path, field="crop")


@dataclass(frozen=True)
class ImageInfo:
    """Header facts of one image: size in pixels, channel count and names, stored pixel type."""

    width: int
    height: int
    channels: int
    channel_names: tuple[str, ...]
    pixel_type: str  # OpenImageIO type name: uint8, uint16, half, float, ...

    @property
    def is_integer(self) -> bool:
        return self.pixel_type.startswith(("uint", "int"))


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """sRGB EOTF (IEC 61966-2-1): V <= 0.04045 -> V / 12.92, else ((V + 0.055) / 1.055) ** 2.4; in place-safe."""
    encoded = np.asarray(encoded)
    low = encoded <= 0.04045
    out = np.empty_like(encoded)
    out[low] = encoded[low] / 12.92
    out[~low] = ((encoded[~low] + 0.055) / 1.055) ** 2.4
    return out


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """Inverse sRGB EOTF: L <= 0.0031308 -> 12.92 L, else 1.055 L ** (1 / 2.4) - 0.055."""
    linear = np.asarray(linear)
    low = linear <= 0.0031308
    out = np.empty_like(linear)
    out[low] = linear[low] * 12.92
    out[~low] = 1.055 * np.power(linear[~low], 1.0 / 2.4) - 0.055
    return out


def _open(path: Path):
    import OpenImageIO as oiio

    if not path.is_file():
        raise InputError("image file not found", path=path)
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InputError(f"cannot open image: {oiio.geterror() or 'unknown reader error'}", path=path)
    return inp


def _info(inp) -> ImageInfo:
    spec = inp.spec()
    return ImageInfo(width=int(spec.width), height=int(spec.height), channels=int(spec.nchannels),
                     channel_names=tuple(spec.channelnames), pixel_type=str(spec.format))


def read_info(path) -> ImageInfo:
    """The header of an image (size, channels, pixel type) without reading its pixels."""
    path = Path(path)
    inp = _open(path)
    try:
        return _info(inp)
    finally:
        inp.close()


def read_image(path, *, crop=None, encoding: str = "auto") -> tuple[np.ndarray, ImageInfo]:
    """Linear float32 pixels (H, W, C) of an image and its header.

    ``crop`` = (x0, y0, width, height) in pixels of the full image (x = column, y = row from the top).
    ``encoding``: 'auto' (integer = sRGB, float = linear), 'srgb' or 'linear'.
    """
    import OpenImageIO as oiio

    if encoding not in ENCODINGS:
        raise ValueError(f"encoding must be one of {ENCODINGS}, got {encoding!r}")
    path = Path(path)
    inp = _open(path)
    try:
        info = _info(inp)
        decode = encoding == "srgb" or (encoding == "auto" and info.is_integer)
        lut = _srgb_table(info.pixel_type) if decode else None
        pixel_type = info.pixel_type if lut is not None else oiio.FLOAT
        rows = columns = None
        if crop is not None:  # decode only the crop's rows (a scanline ROI read), then cut its columns
            rows, columns = crop_slices(crop, info.width, info.height, path)
        height = info.height if rows is None else rows.stop - rows.start
        check_image_memory(info.width, height, info.channels, path=path, cropped=crop is not None)
        if rows is None:
            pixels = inp.read_image(pixel_type)
        else:
            pixels = inp.read_scanlines(0, 0, rows.start, rows.stop, 0, 0, info.channels, pixel_type)
        failed = inp.has_error
        message = inp.geterror() if failed else ""
    finally:
        inp.close()
    if pixels is None or failed:
        raise InputError(f"cannot read the image (truncated or corrupt file?): "
                         f"{message.strip() or 'reader returned no pixels'}", path=path)
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if columns is not None:
        pixels = pixels[:, columns]
    if lut is not None:
        return lut[pixels], info  # exact decoding of every code value, and fast
    pixels = pixels.astype(np.float32, copy=False)
    if decode:
        pixels = srgb_to_linear(pixels)
    return np.ascontiguousarray(pixels), info


@functools.cache
def _srgb_table(pixel_type: str) -> np.ndarray | None:
    """Linear float32 value of every code of an 8/16-bit unsigned type (sRGB EOTF), None for others."""
    bits = {"uint8": 8, "uint16": 16}.get(pixel_type)
    if bits is None:
        return None
    codes = np.arange(2**bits, dtype=np.float64) / (2**bits - 1)
    table = srgb_to_linear(codes).astype(np.float32)
    table.setflags(write=False)
    return table


def crop_slices(crop, width: int, height: int, path=None) -> tuple[slice, slice]:
    """Row and column slices of ``crop`` = (x0, y0, w, h); InputError if it leaves the image."""
    try:
        x0, y0, w, h = (int(c) for c in crop)
    except (TypeError, ValueError):
        raise InputError(f"crop must be (x0, y0, width, height) in pixels, got {crop!r}", path=path,
                         field="crop") from None
    if w <= 0 or h <= 0 or x0 < 0 or y0 < 0 or x0 + w > width or y0 + h > height:
        raise InputError(f"crop (x0={x0}, y0={y0}, width={w}, height={h}) does not fit the {width} x {height} "
                         "image", path=path, field="crop")
    return slice(y0, y0 + h), slice(x0, x0 + w)


def write_image(path, pixels: np.ndarray, *, pixel_type: str = "half", attributes: dict | None = None,
                channel_names=None) -> Path:
    """Write (H, W, C) pixels with OpenImageIO; the format follows the suffix (EXR: 'half' or 'float').

    Integer pixel types ('uint8', 'uint16') expect values already encoded in [0, 1].  String and number
    ``attributes`` are stored in the header (EXR keeps them).  Not atomic by itself: write into a temporary
    directory (:func:`clothlab.atomic.atomic_directory`) or rename afterwards.
    """
    import OpenImageIO as oiio

    path = Path(path)
    pixels = np.asarray(pixels, dtype=np.float32)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    height, width, channels = pixels.shape
    spec = oiio.ImageSpec(width, height, channels, pixel_type)
    if channel_names is None:
        channel_names = ("R", "G", "B", "A")[:channels] if channels in (3, 4) else (
            ("Y",) if channels == 1 else tuple(f"C{k}" for k in range(channels)))
    spec.channelnames = tuple(channel_names)
    for key, value in (attributes or {}).items():
        spec.attribute(key, value if isinstance(value, int | float) else str(value))
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise InputError(f"cannot create an image writer: {oiio.geterror()}", path=path)
    try:
        ok = out.open(str(path), spec) and out.write_image(pixels)
        message = "" if ok else out.geterror()
    finally:
        out.close()
    if not ok:
        raise InputError(f"cannot write the image: {message}", path=path)
    return path
