"""Simulated BTF stacks: images of any texture-evaluating callable, written as a loadable stack.

``evaluate(u, v, wi, wo)`` is supplied by the caller (e.g. the Irawan-Marschner texture model,
:mod:`clothlab.models.irawan.texture`, wrapped with its parameters and coefficients).  It receives

- ``u, v``: (H, W) float64 texture coordinates in weave tiles, u along the weft (fabric x) and v along
  the warp (fabric y), as :mod:`clothlab.weave.lookup`;
- ``wi, wo``: (3,) unit vectors in the fabric frame (:mod:`clothlab.frames`),

and returns (H, W, C) (or (H * W, C), or (H, W)) linear values, e.g. BRDF in 1/sr.

Image geometry (the loader's convention, :mod:`clothlab.btf.names`): the warp runs along the image's
vertical axis, image top = +y (warp), image right = +x (weft).  The pixel in column j, row i (row 0 at the
top) of an image of W x H pixels is sampled at its centre:

    u = u0 + (j + 0.5) / W * repeats_u,      v = v0 + (H - i - 0.5) / H * repeats_v

with (u0, v0) = ``offset`` in tiles.  UTIA names then carry clothlab's azimuths unchanged.

The stack is built in a hidden temporary directory and renamed into place when complete
(:func:`clothlab.atomic.atomic_directory`), so it is atomic as a whole (and hence per file); an existing
stack is kept unless ``overwrite=True``.
"""

from __future__ import annotations

import datetime as _dt
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_directory, atomic_write_text
from clothlab.btf.images import linear_to_srgb, write_image
from clothlab.btf.names import ANGLE_FIELDS, format_angle
from clothlab.errors import InputError, ResultExistsError
from clothlab.frames import spherical_to_vector

NAMINGS = ("utia", "bonn")
MANIFEST_NAME = "manifest.yaml"


def _pair(value, name: str) -> tuple:
    values = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if values.shape == (1,):
        values = np.repeat(values, 2)
    if values.shape != (2,) or not np.all(np.isfinite(values)):
        raise InputError(f"{name} must be one number or a pair, got {value!r}", field=name)
    return tuple(float(x) for x in values)


def direction_table(directions) -> np.ndarray:
    """(N, 4) theta_i, phi_i, theta_o, phi_o in degrees (clothlab convention) from an (N, 4) array-like
    or any object with theta_i, phi_i, theta_o, phi_o attributes (a Measurement, a BtfStack's entries)."""
    if all(hasattr(directions, name) for name in ANGLE_FIELDS):
        table = np.stack([np.asarray(getattr(directions, n), dtype=np.float64) for n in ANGLE_FIELDS], axis=1)
    else:
        table = np.asarray(directions, dtype=np.float64)
        if table.ndim == 1 and table.shape == (4,):
            table = table[None, :]
    if table.ndim != 2 or table.shape[1] != 4 or table.shape[0] == 0:
        raise InputError(f"directions must be (N, 4) theta_i, phi_i, theta_o, phi_o in degrees, got shape "
                         f"{np.shape(table)}", field="directions")
    if not np.all(np.isfinite(table)):
        raise InputError("directions hold non-finite angles", field="directions")
    bad = (table[:, [0, 2]] < 0) | (table[:, [0, 2]] >= 90)
    if bad.any():
        row = int(np.nonzero(bad.any(axis=1))[0][0])
        raise InputError(f"direction {row}: polar angles must lie in [0, 90) deg, got {table[row].tolist()}",
                         field="directions")
    table[:, [1, 3]] = np.mod(table[:, [1, 3]], 360.0)
    return table


def image_name(angles, naming: str, index: int, suffix: str) -> str:
    """Relative file name of one image, angles in the names (UTIA or Bonn UBO2003 layout)."""
    tl, pl, tv, pv = (format_angle(a) for a in angles)
    folder = f"tv{tv}_pv{pv}"
    if naming == "utia":
        return f"{folder}/tl{tl}_pl{pl}_tv{tv}_pv{pv}{suffix}"
    return f"{folder}/{index:05d} tl{tl} pl{pl} tv{tv} pv{pv}{suffix}"


def texture_coordinates(size: tuple[int, int], tile_repeats: tuple[float, float],
                        offset: tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) (H, W) at pixel centres for an image of ``size`` = (W, H) (see the module docstring)."""
    width, height = size
    u = offset[0] + (np.arange(width) + 0.5) / width * tile_repeats[0]
    v = offset[1] + (height - np.arange(height) - 0.5) / height * tile_repeats[1]
    return np.broadcast_to(u[None, :], (height, width)).copy(), np.broadcast_to(v[:, None], (height, width)).copy()


def _evaluate_image(evaluate, u, v, wi, wo, index: int) -> np.ndarray:
    height, width = u.shape
    values = np.asarray(evaluate(u, v, wi, wo), dtype=np.float64)
    if values.shape == (height, width):
        values = values[:, :, None]
    elif values.ndim == 2 and values.shape[0] == height * width:
        values = values.reshape(height, width, -1)
    if values.ndim != 3 or values.shape[:2] != (height, width):
        raise InputError(f"evaluate returned shape {values.shape} for direction {index}; expected "
                         f"({height}, {width}, C), ({height * width}, C) or ({height}, {width})", field="evaluate")
    if not np.all(np.isfinite(values)):
        raise InputError(f"evaluate returned non-finite values for direction {index}", field="evaluate")
    return values


def write_btf_stack(directory, evaluate, *, directions, size, tile_repeats, naming: str = "utia",
                    exr: bool = True, manifest: bool = True, overwrite: bool = False, half: bool = True,
                    offset=(0.0, 0.0), channel_names=None, provenance: dict | None = None) -> Path:
    """Write a simulated BTF stack of ``evaluate`` (see the module docstring) and return its directory.

    directions: (N, 4) theta_i, phi_i, theta_o, phi_o in degrees, clothlab convention (or an object with
    those attributes).  size: W or (W, H) pixels.  tile_repeats: weave tiles across the image, one number
    or (across the width, across the height).  naming: 'utia' or 'bonn'.  exr: linear EXR ('half' or
    float), else 16-bit sRGB-encoded PNG (values clipped to [0, 1]).  manifest: also write manifest.yaml
    (files, angles, convention, how the images were made, plus ``provenance``).
    """
    if naming not in NAMINGS:
        raise InputError(f"naming '{naming}' is not one of {', '.join(NAMINGS)}", field="naming")
    directory = Path(directory)
    table = direction_table(directions)
    width, height = (int(s) for s in _pair(size, "size"))
    if width < 1 or height < 1:
        raise InputError(f"size must be positive pixels, got {size!r}", field="size")
    repeats = _pair(tile_repeats, "tile_repeats")
    offset = _pair(offset, "offset")
    suffix = ".exr" if exr else ".png"
    names = [image_name(row, naming, k, suffix) for k, row in enumerate(table)]
    if len(set(names)) != len(names):
        seen = set()
        duplicate = next(n for n in names if n in seen or seen.add(n))
        raise InputError(f"two directions give the same file name '{duplicate}' (angles equal to 1e-4 deg)",
                         field="directions")
    exists = directory.exists() and (not directory.is_dir() or any(directory.iterdir()))
    if exists and not overwrite:
        raise ResultExistsError(f"{directory} already exists; pass overwrite=True to replace the stack",
                                path=directory)
    u, v = texture_coordinates((width, height), repeats, offset)
    wi_all = spherical_to_vector(table[:, 0], table[:, 1])
    wo_all = spherical_to_vector(table[:, 2], table[:, 3])
    pixel_type = ("half" if half else "float") if exr else "uint16"
    clipped = 0
    channels = None
    with atomic_directory(directory, force=directory.exists()) as tmp:
        for index, name in enumerate(names):
            values = _evaluate_image(evaluate, u, v, wi_all[index], wo_all[index], index)
            if channels is None:
                channels = values.shape[2]
            elif values.shape[2] != channels:
                raise InputError(f"evaluate returned {values.shape[2]} channels for direction {index}, "
                                 f"{channels} before", field="evaluate")
            attributes = {f"clothlab:{k}": float(a) for k, a in zip(ANGLE_FIELDS, table[index], strict=True)}
            if not exr:
                clipped += int(np.count_nonzero((values < 0) | (values > 1)))
                values = linear_to_srgb(np.clip(values, 0.0, 1.0))
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            write_image(tmp / name, values, pixel_type=pixel_type, attributes=attributes,
                        channel_names=channel_names)
        if manifest:
            atomic_write_text(tmp / MANIFEST_NAME, _manifest_text(
                names, table, evaluate=evaluate, size=(width, height), repeats=repeats, offset=offset,
                pixel_type=pixel_type, naming=naming, channels=channels,
                clipped_fraction=clipped / (len(names) * width * height * channels), provenance=provenance))
    return directory


def _manifest_text(names, table, *, evaluate, size, repeats, offset, pixel_type, naming, channels,
                   clipped_fraction, provenance) -> str:
    import yaml

    from clothlab import __version__

    how = {
        "generator": "clothlab.btf.write.write_btf_stack",
        "clothlab_version": __version__,
        "created_utc": _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat(),
        "evaluate": f"{getattr(evaluate, '__module__', '?')}.{getattr(evaluate, '__qualname__', repr(evaluate))}",
        "size_px": list(size),
        "tile_repeats": list(repeats),
        "offset_tiles": list(offset),
        "texture_coordinates": "u = u0 + (col + 0.5) / W * repeats_u (image right = weft, +x); "
                               "v = v0 + (H - row - 0.5) / H * repeats_v (image up = warp, +y); tiles",
        "pixels": f"{pixel_type}, " + ("linear" if pixel_type in ("half", "float") else
                                       "sRGB-encoded, clipped to [0, 1]"),
        "channels": channels,
        "naming": naming,
    }
    if pixel_type == "uint16":
        how["clipped_fraction"] = clipped_fraction
    document = {
        "clothlab_btf_manifest": 1,
        "warp_axis": "vertical",
        "azimuth": {"zero": "weft", "sense": "ccw"},
        "simulated": how,
        "provenance": _plain(provenance or {}),
        "images": [{"file": name, **{k: float(a) for k, a in zip(ANGLE_FIELDS, row, strict=True)}}
                   for name, row in zip(names, table, strict=True)],
    }
    return yaml.safe_dump(document, sort_keys=False)


def _plain(value):
    """YAML-safe copy of provenance (numpy scalars/arrays to Python numbers/lists, others to str)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return str(value)
