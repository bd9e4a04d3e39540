"""Reading at the edge, once: strict numbers, bounded files, bounded YAML and JSON (docs/design.md principle 7).

Every input family (tables, fabric.yaml, scene files, .wv, BTF manifests, colour charts, fit directories)
reads its bytes and numbers through this module, so the same rules hold everywhere:

- a **number** is plain decimal notation, ``[+-]digits[.digits][e[+-]digits]``, at most
  :data:`MAX_NUMBER_CHARS` characters, finite; Python-only spellings (``0_1``, ``nan``, ``infinity``,
  non-ASCII digits) are refused rather than read;
- a **file** must be a regular file (not ``/dev/zero``, a FIFO or a directory) no larger than the limit of
  its family, decoded as UTF-8 (a leading byte-order mark is dropped), lines at most :data:`MAX_LINE_CHARS`;
- a **YAML** document is read by a safe loader with YAML 1.2-like scalars: integers ``[-+]digits`` (at
  most :data:`MAX_INT_DIGITS` digits), floats in the decimal notation above plus ``.inf``/``.nan`` (which
  the validators then reject as not finite), no timestamps, no sexagesimal or underscored numbers (those
  stay strings, so a validator says "expected a number"); nesting at most :data:`MAX_DEPTH` levels and at
  most :data:`MAX_NODES` nodes after alias expansion (the "billion laughs" tree is refused before anything
  expands it);
- a **JSON** document has the same depth bound.

Every refusal is an :class:`~clothlab.errors.InputError` (or the ``error`` class the caller passes) naming
the file and, where known, the line.
"""

from __future__ import annotations

import math
import os
import re
import stat
from pathlib import Path

from clothlab.errors import ClothlabError, InputError

MAX_NUMBER_CHARS = 64
"""Longest numeric field accepted (a float64 needs at most 24 characters in repr)."""
MAX_INT_DIGITS = 30
"""Most digits of a YAML integer (a count, a seed, an evaluation budget)."""
MAX_LINE_CHARS = 1 << 16
"""Longest line of a text file, in characters."""
MAX_TABLE_BYTES = 1 << 30
"""Largest measurement table or colour chart read (1 GiB)."""
MAX_YAML_BYTES = 16 << 20
"""Largest YAML file (fabric.yaml, scene, table header, BTF manifest) read (16 MiB)."""
MAX_DEPTH = 64
"""Deepest nesting of YAML / JSON collections."""
MAX_NODES = 1_000_000
"""Most YAML nodes after alias expansion."""

_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NUMERIC_CHARS = re.compile(r"[^0-9eE+\-.,\s]")
"""Any character that cannot occur in a row of plain decimal numbers (a row holding one needs the slow,
field-by-field strict parse)."""


def parse_number(text: str, *, error=InputError, **where) -> float:
    """A finite float from one field in plain decimal notation, or ``error`` naming ``where``."""
    text = text.strip()
    if not text:
        raise error("empty field; expected a number", **where)
    shown = text if len(text) <= 40 else text[:37] + "..."
    if len(text) > MAX_NUMBER_CHARS:
        raise error(f"value {shown!r} has {len(text)} characters; a number has at most {MAX_NUMBER_CHARS}",
                    **where)
    if text.lower().lstrip("+-") in ("nan", "inf", "infinity"):
        raise error(f"value {shown} is not finite; expected a finite number", **where)
    if not _NUMBER.fullmatch(text):
        raise error(f"value {shown!r} is not a number in decimal notation (e.g. 0.25, -3, 1.5e-3)", **where)
    value = float(text)
    if not math.isfinite(value):
        raise error(f"value {shown!r} overflows a 64-bit float; expected a finite number", **where)
    return value


def plain_numeric_text(text: str) -> bool:
    """True when ``text`` holds only characters of plain decimal numbers, separators and white space."""
    return _NUMERIC_CHARS.search(text) is None


# ---------------------------------------------------------------------------------------------------------
# Files


def check_regular_file(path, *, limit: int, what: str = "file", error=InputError) -> Path:
    """``path`` as a Path after checking it is an existing regular file of at most ``limit`` bytes."""
    path = Path(path)
    if "\x00" in str(path):
        raise error(f"{what} name holds a NUL byte", path=repr(str(path)))
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise error(f"{what} not found", path=path) from None
    except OSError as exc:
        raise error(f"cannot open the {what}: {exc.strerror or exc}", path=path) from None
    if stat.S_ISDIR(info.st_mode):
        raise error(f"is a directory, expected a {what}", path=path)
    if not stat.S_ISREG(info.st_mode):
        raise error(f"is not a regular file (a device, FIFO or socket); expected a {what}", path=path)
    if info.st_size > limit:
        raise error(f"{what} is {info.st_size} bytes; at most {limit} are read", path=path)
    return path


def read_bounded_bytes(path, *, limit: int, what: str = "file", error=InputError) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (checked before and while reading)."""
    path = check_regular_file(path, limit=limit, what=what, error=error)
    try:
        with open(path, "rb") as handle:
            # read what stat reported (Python allocates the whole request up front, so never ask for the
            # limit itself), then in bounded chunks only if the file grew meanwhile
            size = os.fstat(handle.fileno()).st_size
            chunks = [handle.read(min(size, limit) + 1)]
            total = len(chunks[0])
            while total > size and total <= limit:
                chunk = handle.read(min(1 << 20, limit + 1 - total))
                if not chunk:
                    break
                chunks.append(chunk)
                total += len(chunk)
            data = chunks[0] if len(chunks) == 1 else b"".join(chunks)
    except OSError as exc:
        raise error(f"cannot read the {what}: {exc.strerror or exc}", path=path) from None
    if len(data) > limit:
        raise error(f"{what} grew past {limit} bytes while being read", path=path)
    return data


def decode_text(data: bytes, *, path, what: str = "file", error=InputError) -> str:
    """UTF-8 text of ``data`` without a leading byte-order mark; long lines and other encodings refused."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise error(f"{what} is UTF-16 text; save it as UTF-8", path=path, line=1)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise error(f"not UTF-8 text (byte {data[exc.start]:#04x} at offset {exc.start}); save the {what} "
                    "as UTF-8", path=path, line=line) from None
    if text.startswith("\ufeff"):
        text = text[1:]
    if "\x00" in text:
        offset = text.index("\x00")
        raise error(f"NUL character at offset {offset}; expected text", path=path,
                    line=text.count("\n", 0, offset) + 1)
    if len(text) > MAX_LINE_CHARS:
        for lineno, line in enumerate(text.split("\n"), 1):
            if len(line) > MAX_LINE_CHARS:
                raise error(f"line has {len(line)} characters; at most {MAX_LINE_CHARS}", path=path,
                            line=lineno)
    return text


def read_text(path, *, limit: int = MAX_YAML_BYTES, what: str = "file", error=InputError) -> str:
    """:func:`read_bounded_bytes` then :func:`decode_text`."""
    data = read_bounded_bytes(path, limit=limit, what=what, error=error)
    return decode_text(data, path=path, what=what, error=error)


# ---------------------------------------------------------------------------------------------------------
# YAML and JSON


def _loader_class():
    import yaml

    class StrictLoader(yaml.SafeLoader):
        """PyYAML's safe loader with strict numeric scalars and no timestamps (see the module docstring)."""

    StrictLoader.yaml_implicit_resolvers = {
        first: [(tag, regexp) for tag, regexp in resolvers
                if tag not in ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float",
                               "tag:yaml.org,2002:timestamp")]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
    }
    StrictLoader.add_implicit_resolver(
        "tag:yaml.org,2002:int", re.compile(r"^[-+]?[0-9]+$"), list("-+0123456789"))
    StrictLoader.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^(?:[-+]?(?:[0-9]+\.[0-9]*|\.[0-9]+|[0-9]+)(?:[eE][-+]?[0-9]+)?"
                   r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"),
        list("-+0123456789."))

    def construct_int(loader, node):
        text = loader.construct_scalar(node)
        digits = len(text.lstrip("+-"))
        if digits > MAX_INT_DIGITS:
            raise yaml.constructor.ConstructorError(
                None, None, f"an integer of {digits} digits (at most {MAX_INT_DIGITS})", node.start_mark)
        return int(text)

    def construct_float(loader, node):
        text = loader.construct_scalar(node)
        if len(text) > MAX_NUMBER_CHARS:
            raise yaml.constructor.ConstructorError(
                None, None, f"a number of {len(text)} characters (at most {MAX_NUMBER_CHARS})", node.start_mark)
        lowered = text.lower()
        if lowered.endswith((".inf", ".nan")):
            return float(lowered.replace(".", ""))
        return float(text)

    StrictLoader.add_constructor("tag:yaml.org,2002:int", construct_int)
    StrictLoader.add_constructor("tag:yaml.org,2002:float", construct_float)
    return StrictLoader


_LOADER = None


def strict_loader(text: str):
    """A PyYAML loader instance over ``text`` with clothlab's strict scalar rules (call ``dispose()``)."""
    global _LOADER
    if _LOADER is None:
        _LOADER = _loader_class()
    return _LOADER(text)


def check_node_bounds(root, *, path=None, error=InputError) -> None:
    """``error`` if the composed YAML tree ``root`` nests deeper than :data:`MAX_DEPTH` or expands (aliases
    followed) to more than :data:`MAX_NODES` nodes.  Iterative, and linear in the written nodes."""
    import yaml

    if root is None:
        return
    sizes: dict[int, int] = {}
    stack = [(root, 1, False)]
    while stack:
        node, depth, done = stack.pop()
        children = []
        if isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        elif isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        if done:
            total = 1 + sum(sizes.get(id(c), 1) for c in children)
            sizes[id(node)] = total
            if total > MAX_NODES:
                raise error(f"the YAML document expands to more than {MAX_NODES} nodes (aliases followed); "
                            "refused", path=path, line=node.start_mark.line + 1)
            continue
        if id(node) in sizes:
            continue
        if depth > MAX_DEPTH:
            raise error(f"YAML collections nested more than {MAX_DEPTH} deep", path=path,
                        line=node.start_mark.line + 1)
        sizes.setdefault(id(node), 1)  # an alias cycle counts once (the line map reports cycles)
        stack.append((node, depth, True))
        stack.extend((c, depth + 1, False) for c in children if id(c) not in sizes)


def yaml_error(exc, *, path, error=InputError, what: str = "YAML") -> ClothlabError:
    """A clothlab error naming the file and line of a PyYAML exception."""
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    context = getattr(exc, "context", None)
    message = f"not valid {what}: {problem}" + (f" ({context})" if context else "")
    return error(message, path=path, line=None if mark is None else mark.line + 1)


def compose_yaml(text: str, *, path=None, error=InputError):
    """``(node, loader)``: the composed, bounds-checked node tree of one YAML document (dispose the loader)."""
    import yaml

    if len(text) > MAX_YAML_BYTES:
        raise error(f"YAML text of {len(text)} characters; at most {MAX_YAML_BYTES}", path=path)
    if not _json_depth_ok(text):  # flow collections nested deeper than the bound: refuse before composing
        raise error(f"YAML collections nested more than {MAX_DEPTH} deep", path=path)
    try:
        loader = strict_loader(text)
    except yaml.YAMLError as exc:  # a character YAML does not allow (a control character)
        position = getattr(exc, "position", None)
        line = None if position is None else text.count("\n", 0, position) + 1
        raise error(f"not valid YAML: a character YAML does not allow ({getattr(exc, 'character', '?')!r})",
                    path=path, line=line) from None
    try:
        node = loader.get_single_node()
        check_node_bounds(node, path=path, error=error)
    except yaml.YAMLError as exc:
        loader.dispose()
        raise yaml_error(exc, path=path, error=error) from None
    except RecursionError:
        loader.dispose()
        raise error(f"YAML collections nested too deeply (at most {MAX_DEPTH} levels)", path=path) from None
    except BaseException:
        loader.dispose()
        raise
    return node, loader


def construct_yaml(loader, node, *, path=None, error=InputError):
    """The Python data of a composed node (``compose_yaml``); errors name the file and line."""
    import yaml

    try:
        return None if node is None else loader.construct_document(node)
    except yaml.YAMLError as exc:
        raise yaml_error(exc, path=path, error=error) from None
    except (ValueError, TypeError, RecursionError) as exc:
        raise error(f"YAML value cannot be read ({exc})", path=path) from None
    finally:
        loader.dispose()


def load_yaml_text(text: str, *, path=None, error=InputError):
    """The data of one YAML document under the strict rules and bounds of this module."""
    node, loader = compose_yaml(text, path=path, error=error)
    return construct_yaml(loader, node, path=path, error=error)


def load_yaml_file(path, *, error=InputError, what: str = "YAML file", limit: int = MAX_YAML_BYTES):
    """The data of a YAML file (regular, bounded size, UTF-8) under the strict rules of this module."""
    text = read_text(path, limit=limit, what=what, error=error)
    return load_yaml_text(text, path=path, error=error)


def _json_depth_ok(text: str) -> bool:
    """False when '[' / '{' outside double-quoted strings nest deeper than :data:`MAX_DEPTH` (JSON exactly,
    YAML flow collections conservatively)."""
    if text.count("[") + text.count("{") <= MAX_DEPTH:
        return True
    depth = deepest = 0
    in_string = escape = False
    for ch in text:
        if in_string:
            if escape:
                escape = False
            elif ch == "\\":
                escape = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
            if deepest > MAX_DEPTH:
                return False
        elif ch in "]}":
            depth -= 1
    return True


def load_json_text(text: str, *, path=None, error=InputError):
    """The data of a JSON document: depth at most :data:`MAX_DEPTH`, integers at most 4300 digits, no NaN."""
    import json

    if not _json_depth_ok(text):
        raise error(f"invalid JSON: nested more than {MAX_DEPTH} levels deep", path=path)

    class Constant(str):  # NaN / Infinity / -Infinity, kept in place to name its dotted field
        pass

    try:
        data = json.loads(text, parse_constant=Constant)
    except json.JSONDecodeError as exc:
        raise error(f"invalid JSON: {exc.msg} (column {exc.colno})", path=path, line=exc.lineno) from None
    except (ValueError, RecursionError) as exc:
        raise error(f"invalid JSON: {exc}", path=path) from None
    stack = [((), data)]
    while stack:  # depth first, in document order
        where, value = stack.pop()
        if isinstance(value, Constant):
            raise error(f"invalid JSON: {value} is not a finite number", path=path,
                        field=".".join(map(str, where)) or None)
        if isinstance(value, dict | list):
            items = value.items() if isinstance(value, dict) else enumerate(value)
            stack.extend(reversed([(where + (k,), v) for k, v in items]))
    return data


def load_json_file(path, *, error=InputError, what: str = "JSON file", limit: int = MAX_YAML_BYTES):
    """:func:`load_json_text` of a bounded regular UTF-8 file."""
    return load_json_text(read_text(path, limit=limit, what=what, error=error), path=path, error=error)


# ---------------------------------------------------------------------------------------------------------
# NumPy .npz archives (the surrogate's weights)

MAX_NPZ_BYTES = 1 << 30
"""Largest ``.npz`` archive read (1 GiB); each member is further bounded by the shape its caller expects."""
NPY_HEADER_BYTES = 1 << 16
"""Most bytes of a member's ``.npy`` header (format 1.0 allows 65,535; numpy writes 128)."""
NPZ_FLOAT_DTYPES = ("float32", "float64")


def read_npz(path, members: dict, *, limit: int = MAX_NPZ_BYTES, what: str = "weights file", error=InputError,
             dtypes=NPZ_FLOAT_DTYPES, magnitude: float | None = None) -> dict:
    """The arrays of an ``.npz`` archive whose members are exactly ``members`` = {name: shape}.

    Checked before anything is decompressed: the file is regular and at most ``limit`` bytes, it is a zip
    archive (not truncated: the central directory is read first), it holds exactly the expected members
    (``name.npy``, stored or deflated, not encrypted), and each member's declared uncompressed size
    (``ZipInfo.file_size``) is at most its shape's bytes plus a header.  Then each member is inflated with
    a read bounded by that size (a member lying about its size is cut there and refused: no zip bomb), its
    ``.npy`` header is parsed without pickle, and it must hold ``dtypes`` with exactly the expected shape,
    every value finite and, with ``magnitude``, at most that in absolute value.  Every refusal is ``error``
    naming the file (``path=``) and the member (``field=``)."""
    import ast
    import io
    import zipfile

    import numpy as np

    data = read_bounded_bytes(path, limit=limit, what=what, error=error)
    path = Path(path)
    if not data:
        raise error(f"empty {what}; expected a .npz archive", path=path)
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        infos = archive.infolist()
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, ValueError, OSError, NotImplementedError) as exc:
        raise error(f"not a .npz archive (truncated or not a zip file: {exc})", path=path) from None
    found = {}
    for info in infos:
        name = info.filename.removesuffix(".npy")
        if name not in members:
            shown = info.filename if len(info.filename) <= 60 else info.filename[:57] + "..."
            raise error(f"unexpected member {shown!r} (expected {len(members)} arrays)", path=path, field=shown)
        if name in found:
            raise error("member stored twice", path=path, field=name)
        found[name] = info
    missing = [name for name in members if name not in found]
    if missing:
        raise error(f"missing array{'s' if len(missing) > 1 else ''} {', '.join(missing[:3])}"
                    f"{' ...' if len(missing) > 3 else ''}", path=path, field=missing[0])
    out = {}
    for name, shape in members.items():
        info = found[name]
        count = math.prod(shape)
        bound = NPY_HEADER_BYTES + 10 + 8 * count  # the largest dtype accepted is 8 bytes
        if info.flag_bits & 0x1:
            raise error("member is encrypted", path=path, field=name)
        if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
            raise error(f"member uses compression method {info.compress_type} (stored or deflated only)",
                        path=path, field=name)
        if info.file_size > bound:
            raise error(f"member declares {info.file_size} bytes uncompressed; an array of shape {tuple(shape)} "
                        f"needs at most {bound}", path=path, field=name)
        try:
            with archive.open(info) as handle:
                raw = handle.read(bound + 1)
        except (zipfile.BadZipFile, EOFError, ValueError, OSError, RuntimeError, NotImplementedError) as exc:
            raise error(f"member cannot be read (corrupt or truncated archive: {exc})", path=path,
                        field=name) from None
        if len(raw) > bound:
            raise error(f"member inflates past {bound} bytes (an array of shape {tuple(shape)}); refused",
                        path=path, field=name)
        out[name] = _npy_array(raw, shape, path=path, name=name, error=error, dtypes=dtypes,
                               magnitude=magnitude, literal=ast.literal_eval, np=np)
    return out


def _npy_array(raw: bytes, shape, *, path, name, error, dtypes, magnitude, literal, np):
    """The array of one ``.npy`` member (bytes), header parsed as a Python literal (never unpickled)."""
    if raw[:6] != b"\x93NUMPY" or len(raw) < 10:
        raise error("member is not a .npy array", path=path, field=name)
    major = raw[6]
    if major == 1:
        header_len, start = int.from_bytes(raw[8:10], "little"), 10
    elif major in (2, 3):
        header_len, start = int.from_bytes(raw[8:12], "little"), 12
    else:
        raise error(f"member is .npy format version {major} (1 to 3 are read)", path=path, field=name)
    if header_len > NPY_HEADER_BYTES or start + header_len > len(raw):
        raise error("member's .npy header is truncated or too long", path=path, field=name)
    try:
        header = literal(raw[start:start + header_len].decode("latin-1"))
        descr, fortran, found_shape = header["descr"], header["fortran_order"], tuple(header["shape"])
        dtype = np.dtype(descr)
    except (ValueError, SyntaxError, TypeError, KeyError, MemoryError, RecursionError):
        raise error("member's .npy header cannot be read", path=path, field=name) from None
    if dtype.hasobject or dtype.name not in dtypes or dtype.shape or dtype.names:
        raise error(f"member holds dtype {dtype.str!r} ({dtype.name}); expected {' or '.join(dtypes)}", path=path,
                    field=name)
    if not isinstance(fortran, bool) or found_shape != tuple(shape):
        raise error(f"member has shape {found_shape}, expected {tuple(shape)}", path=path, field=name)
    body = raw[start + header_len:]
    if len(body) != dtype.itemsize * math.prod(shape):
        raise error(f"member holds {len(body)} data bytes, expected {dtype.itemsize * math.prod(shape)} "
                    "(truncated or padded)", path=path, field=name)
    array = np.frombuffer(body, dtype=dtype).reshape(shape, order="F" if fortran else "C")
    array = array.astype(dtype.newbyteorder("="))
    finite = np.isfinite(array)
    if not finite.all():
        index = tuple(int(i) for i in np.argwhere(~finite)[0])
        raise error(f"member holds {array[index]!r} at index {index}; every value must be finite", path=path,
                    field=name)
    if magnitude is not None and array.size and float(np.max(np.abs(array))) > magnitude:
        index = tuple(int(i) for i in np.unravel_index(int(np.argmax(np.abs(array))), array.shape))
        raise error(f"member holds {float(array[index]):.6g} at index {index}; values beyond +-{magnitude:g} are "
                    "not a trained network's", path=path, field=name)
    return array
