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

    def constant(name):
        raise ValueError(f"{name} is not a finite number")

    try:
        return json.loads(text, parse_constant=constant)
    except json.JSONDecodeError as exc:
        raise error(f"invalid JSON: {exc.msg} (column {exc.colno})", path=path, line=exc.lineno) from None
    except (ValueError, RecursionError) as exc:
        raise error(f"invalid JSON: {exc}", path=path) from None


def load_json_file(path, *, error=InputError, what: str = "JSON file", limit: int = MAX_YAML_BYTES):
    """:func:`load_json_text` of a bounded regular UTF-8 file."""
    return load_json_text(read_text(path, limit=limit, what=what, error=error), path=path, error=error)
