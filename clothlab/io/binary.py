"""Binary reflectance files, read once at the edge: bounded bytes, typed arrays, errors at a byte offset.

Shared by the MERL (:mod:`clothlab.io.merl`), UTIA (:mod:`clothlab.io.utia`) and RGL-EPFL tensor-file
(:mod:`clothlab.io.rglbsdf`) loaders (docs/formats.md, "Tabulated BRDF databases").  Every refusal is an
:class:`~clothlab.errors.InputError` that names the file and the byte offset of the culprit (docs/design.md
principle 7).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from clothlab.errors import InputError
from clothlab.io.table import MAX_VALUE, MIN_VALUE
from clothlab.untrusted import MAX_TABLE_BYTES, read_bounded_bytes


def read_binary(path, *, what: str) -> bytes:
    """The bytes of a regular binary file of at most :data:`clothlab.untrusted.MAX_TABLE_BYTES` bytes."""
    return read_bounded_bytes(path, limit=MAX_TABLE_BYTES, what=what)


def check_size(data: bytes, expected: int, *, path, what: str) -> None:
    """InputError unless ``data`` holds exactly ``expected`` bytes (truncated, or trailing bytes)."""
    if len(data) < expected:
        raise InputError(f"truncated {what}: the file ends at byte offset {len(data)}, the layout needs "
                         f"{expected} bytes", path=path)
    if len(data) > expected:
        raise InputError(f"{len(data) - expected} trailing bytes after byte offset {expected}, where the "
                         f"{what} layout ends", path=path)


def array_at(data: bytes, offset: int, dtype: str, count: int, *, path, what: str) -> np.ndarray:
    """``count`` items of ``dtype`` (a little-endian numpy type string) from byte ``offset``, as a copy."""
    size = np.dtype(dtype).itemsize * count
    if offset + size > len(data):
        raise InputError(f"truncated {what}: {count} x {np.dtype(dtype).name} from byte offset {offset} need "
                         f"{size} bytes, the file ends at byte offset {len(data)}", path=path)
    return np.frombuffer(data, dtype=dtype, count=count, offset=offset).copy()


def check_values(values: np.ndarray, *, path, offset: int, itemsize: int, name: Callable[[int], str],
                 allow_negative: bool, what: str = "value") -> None:
    """InputError at the first non-finite, huge (> 1e30), denormal or (unless ``allow_negative``) negative
    entry of the flat array ``values`` stored from byte ``offset``; ``name(k)`` names entry k for the message.
    """
    flat = np.ravel(values)
    magnitude = np.abs(flat)
    checks = [(~np.isfinite(flat), "is not finite; expected a finite number")]
    if not allow_negative:
        checks.append((flat < 0.0, "is negative; a BRDF value must be >= 0"))
    checks += [(np.isfinite(flat) & (magnitude > MAX_VALUE), f"exceeds {MAX_VALUE:g} in magnitude"),
               ((magnitude > 0.0) & (magnitude < MIN_VALUE), "is denormal; write 0 or a normal number")]
    for mask, reason in checks:
        hits = np.flatnonzero(mask)
        if len(hits):
            k = int(hits[0])
            raise InputError(f"{what} {float(flat[k])!r} at byte offset {offset + itemsize * k} ({name(k)}) "
                             f"{reason}", path=path, field=name(k))
