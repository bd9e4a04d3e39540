"""Read and write weave-description files (``.wv``), the format of the published Irawan-Marschner presets.

The format is the one read by the ``irawan`` cloth plugin of Mitsuba 0.5/0.6 (the presets of Irawan &
Marschner 2012 were released in it)::

    /* comments are C-style block comments */
    weave {
      name = "Polyester lining",
      tileWidth = 2, tileHeight = 2,
      alpha = 0.015, beta = 4, ss = 0.5, hWidth = 0.5,
      warpArea = 1, weftArea = 1,
      fineness = 0,
      dWarpUmaxOverDWarp = 8, dWarpUmaxOverDWeft = 8,
      dWeftUmaxOverDWarp = 6, dWeftUmaxOverDWeft = 6,
      period = 50,
      pattern {
        3, 2,
        1, 4
      },
      yarn { type = warp, psi = 0, umax = 22, kappa = -0.7, width = 1, length = 1,
             centerU = 0.25, centerV = 0.25 },
      ...
    }

Entries of a block are separated by commas (a trailing comma before ``}`` is tolerated here, though
Mitsuba rejects it); ``pattern`` lists ``tileWidth x tileHeight`` yarn numbers row by row *from the top*
of the tile; yarn number ``k`` is the ``k``-th ``yarn`` block (1-based).  ``centerU``/``centerV`` are
tile fractions with V measured from the *bottom* of the tile (values outside [0, 1] are allowed).
When the pattern spans several lines, each line must hold exactly one row (``tileWidth`` numbers);
a one-line pattern (as Mitsuba's own writer emits) is accepted too.

The ``.wv`` of a fit records the IM model's ``filament_arc`` (:data:`clothlab.models.irawan.integrals.FILAMENT_ARCS`)
in a comment, which Mitsuba and this reader skip as any comment, and this reader also recognises::

    /* clothlab: filament_arc = shortened */

(:data:`FILAMENT_ARC_RE`; read into ``Weave.filament_arc``, None when absent).  When the weave has a smoothed
filament yarn (psi = 0, ss > 0) and the arc is ``full`` (the paper's text), the comment says that the
Mitsuba 0.5/0.6 ``irawan`` plugin renders it with the shortened arc instead.

Units and field mapping onto :class:`~clothlab.weave.model.Weave` (no unit conversion: the file's angles are
degrees and so are clothlab's; Mitsuba converts psi, umax and the dUmax fields to radians on reading):

=====================  ==========================  ========  =========================
file field             Weave field                 unit      required / default
=====================  ==========================  ========  =========================
name                   name                        -         default: the file's stem
tileWidth, tileHeight  pattern.shape (W, H)        cells     required
pattern                pattern (H, W), top first   yarn ids  required
alpha, beta            alpha, beta (eq. 7)         1         required
ss                     delta (eq. 9)               1         0
hWidth                 hwidth (eq. 12)             1         0.5
warpArea, weftArea     warp_area, weft_area        1         required, > 0
fineness               fineness (sec. 7.2.1)       1/cell    0 (no intensity noise)
dWarpUmaxOverDWarp...  dumax (4 values)            deg       0
period                 period                      cells     0 (no umax modulation)
yarn.type              Segment.kind                -         required: warp | weft
yarn.psi, yarn.umax    YarnGeometry.psi, .umax     deg       psi 0; umax required
yarn.kappa             YarnGeometry.kappa          1         0
yarn.width, .length    YarnGeometry.w, .l          cells     required
yarn.centerU, centerV  Segment.center_u, center_v  tile      required
=====================  ==========================  ========  =========================

clothlab has exactly two segment types (paper sec. 5: one geometry per segment type), ``warp`` and
``weft``: all yarns of one type must share psi, umax, kappa, width and length (a documented limitation;
a file whose yarns of one type disagree is rejected with a message naming the yarns).  Values are also
checked against the physical ranges declared in :data:`clothlab.weave.parameters.IRAWAN_PARAMS`.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.errors import InputError, ParameterError
from clothlab.untrusted import MAX_YAML_BYTES, parse_number, read_text
from clothlab.weave.model import YARN_KINDS, Segment, Weave, YarnGeometry
from clothlab.weave.parameters import IRAWAN_PARAMS

#: Weave-level scalar fields of the format (file spelling) and the Weave attribute each one fills.
WEAVE_FLOAT_FIELDS = {
    "alpha": "alpha",
    "beta": "beta",
    "ss": "delta",
    "hWidth": "hwidth",
    "warpArea": "warp_area",
    "weftArea": "weft_area",
    "fineness": "fineness",
    "period": "period",
}
#: The four umax-modulation amplitudes, in the order of ``Weave.dumax``.
DUMAX_FIELDS = ("dWarpUmaxOverDWarp", "dWarpUmaxOverDWeft", "dWeftUmaxOverDWarp", "dWeftUmaxOverDWeft")
WEAVE_INT_FIELDS = ("tileWidth", "tileHeight")
YARN_FLOAT_FIELDS = ("psi", "umax", "kappa", "width", "length", "centerU", "centerV")
#: Yarn fields that make up the geometry of a segment type, with their YarnGeometry attribute.
YARN_GEOMETRY_FIELDS = {"psi": "psi", "umax": "umax", "kappa": "kappa", "width": "w", "length": "l"}

WEAVE_REQUIRED = ("tileWidth", "tileHeight", "pattern", "alpha", "beta", "warpArea", "weftArea")
WEAVE_DEFAULTS = {"ss": 0.0, "hWidth": 0.5, "fineness": 0.0, "period": 0.0} | dict.fromkeys(DUMAX_FIELDS, 0.0)
YARN_REQUIRED = ("type", "umax", "width", "length", "centerU", "centerV")
YARN_DEFAULTS = {"psi": 0.0, "kappa": 0.0}

#: Plausible ranges (lo, hi, unit) of the fields IRAWAN_PARAMS does not declare: values outside them are
#: typing or unit mistakes (a modulation amplitude beyond 90 deg, a noise fineness of 1e300 per cell).
FIELD_RANGES = {
    **dict.fromkeys(DUMAX_FIELDS, (-90.0, 90.0, "deg")),
    "fineness": (0.0, 1e3, "1/cell"),
    "period": (0.0, 1e6, "cells"),
    "warpArea": (0.0, 1e6, "(relative weight)"),
    "weftArea": (0.0, 1e6, "(relative weight)"),
    "centerU": (-1e3, 1e3, "cells"),
    "centerV": (-1e3, 1e3, "cells"),
}
MAX_TILE_DIGITS = 6

_WEAVE_KEYS = ("name", *WEAVE_INT_FIELDS, *WEAVE_FLOAT_FIELDS, *DUMAX_FIELDS, "pattern", "yarn")
_YARN_KEYS = ("type", *YARN_FLOAT_FIELDS)

FILAMENT_ARC_RE = re.compile(r"/\*\s*clothlab:\s*filament_arc\s*=\s*(full|shortened)\b")
"""The comment that records a fit's ``filament_arc`` (see the module docstring)."""
_NUMBER_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_UINT_RE = re.compile(r"\+?\d+")
_TOKEN_RE = re.compile(r'(?P<nl>\n)|(?P<ws>[ \t\r\f\v]+)|(?P<comment>/\*)|(?P<string>"[^"\n]*")|'
                       r'(?P<punct>[{}=,])|(?P<word>(?:[^\s{}=,"/]|/(?!\*))+)|(?P<bad>.)')


# ---------------------------------------------------------------------------------------------------------
# Tokens


@dataclass(frozen=True)
class _Token:
    kind: str  # 'word' | 'string' | '{' | '}' | '=' | ',' | 'eof'
    text: str
    line: int

    def describe(self) -> str:
        return "the end of the file" if self.kind == "eof" else f"'{self.text}'"


def _tokenize(text: str, source: str) -> list[_Token]:
    tokens: list[_Token] = []
    line, pos = 1, 0
    while pos < len(text):
        m = _TOKEN_RE.match(text, pos)
        kind = m.lastgroup
        if kind == "nl":
            line += 1
        elif kind == "comment":
            end = text.find("*/", m.end())
            if end < 0:
                raise InputError("comment '/*' is never closed with '*/'", path=source, line=line)
            line += text.count("\n", pos, end)
            pos = end + 2
            continue
        elif kind == "string":
            tokens.append(_Token("string", m.group()[1:-1], line))
        elif kind == "punct":
            tokens.append(_Token(m.group(), m.group(), line))
        elif kind == "word":
            tokens.append(_Token("word", m.group(), line))
        elif kind == "bad":
            what = "unterminated string (no closing '\"' on this line)" if m.group() == '"' else \
                f"unexpected character {m.group()!r}"
            raise InputError(what, path=source, line=line)
        pos = m.end()
    tokens.append(_Token("eof", "", line))
    _check_braces(tokens, source)
    return tokens


def _check_braces(tokens: list[_Token], source: str) -> None:
    """Report unbalanced braces where they happen (blocks nest at most two deep: weave > pattern | yarn)."""
    stack: list[_Token] = []
    for i, tok in enumerate(tokens):
        if tok.kind == "{":
            if len(stack) == 2:
                opener = stack[-1]
                raise InputError(f"unbalanced braces: the '{{' of line {opener.line} is not closed before "
                                 f"the '{{' of line {tok.line} (blocks cannot nest here)",
                                 path=source, line=opener.line)
            stack.append(tok)
        elif tok.kind == "}":
            if not stack:
                raise InputError("unbalanced braces: this '}' has no matching '{'", path=source, line=tok.line)
            stack.pop()
            if not stack and tokens[i + 1].kind != "eof":
                nxt = tokens[i + 1]
                raise InputError(f"unexpected {nxt.describe()} after the end of the weave block "
                                 f"(closed on line {tok.line})", path=source, line=nxt.line)
    if stack:
        raise InputError(f"unbalanced braces: the '{{' of line {stack[-1].line} is never closed",
                         path=source, line=stack[-1].line)


# ---------------------------------------------------------------------------------------------------------
# Syntax: tokens -> raw fields


@dataclass
class _Value:
    value: object
    line: int


@dataclass
class _Block:
    line: int
    fields: dict[str, _Value]


class _Parser:
    def __init__(self, tokens: list[_Token], source: str):
        self.tokens = tokens
        self.pos = 0
        self.source = source

    def next(self) -> _Token:
        tok = self.tokens[self.pos]
        self.pos += 1
        return tok

    def fail(self, message: str, tok: _Token, field: str | None = None):
        raise InputError(message, path=self.source, line=tok.line, field=field)

    def expect(self, kind: str, after: str, field: str | None = None) -> _Token:
        tok = self.next()
        if tok.kind != kind:
            self.fail(f"expected '{kind}' {after}, found {tok.describe()}", tok, field)
        return tok

    def parse_file(self) -> tuple[_Block, list[_Block], list[tuple[int, int]]]:
        head = self.next()
        if head.kind != "word" or head.text != "weave":
            self.fail(f"a weave file starts with 'weave {{', found {head.describe()}", head)
        self.expect("{", "after 'weave'")
        weave = _Block(head.line, {})
        yarns: list[_Block] = []
        pattern: list[tuple[int, int]] = []
        for key in self.entries(_WEAVE_KEYS, "weave"):
            if key.text == "pattern":
                self.once(weave, key, "weave")
                weave.fields["pattern"] = _Value(None, key.line)
                pattern = self.pattern_block()
            elif key.text == "yarn":
                self.expect("{", "after 'yarn'", field=f"yarn {len(yarns) + 1}")
                yarns.append(self.yarn_block(key, len(yarns) + 1))
            else:
                self.once(weave, key, "weave")
                weave.fields[key.text] = _Value(self.scalar(key), key.line)
        return weave, yarns, pattern

    def entries(self, allowed: tuple[str, ...], block: str):
        """Yield the key token of each entry of a block; the caller consumes the entry's value."""
        while True:
            key = self.next()
            if key.kind == "}":
                return
            if key.kind != "word":
                self.fail(f"expected a field name in the {block} block, found {key.describe()}", key)
            if key.text not in allowed:
                close = difflib.get_close_matches(key.text, allowed, n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                self.fail(f"unknown field '{key.text}' in the {block} block{hint}; known fields: "
                          f"{', '.join(allowed)}", key, field=key.text)
            yield key
            sep = self.next()
            if sep.kind == "}":
                return
            if sep.kind != ",":
                self.fail(f"expected ',' or '}}' after the '{key.text}' entry, found {sep.describe()}", sep,
                          field=key.text)

    def once(self, block: _Block, key: _Token, name: str) -> None:
        if key.text in block.fields:
            self.fail(f"field '{key.text}' given twice in the {name} block "
                      f"(first on line {block.fields[key.text].line})", key, field=key.text)

    def scalar(self, key: _Token) -> _Token:
        self.expect("=", f"after '{key.text}'", field=key.text)
        value = self.next()
        if value.kind not in ("word", "string"):
            self.fail(f"expected a value after '{key.text} =', found {value.describe()}", value, field=key.text)
        return value

    def pattern_block(self) -> list[tuple[int, int]]:
        self.expect("{", "after 'pattern'", field="pattern")
        ids: list[tuple[int, int]] = []
        while True:
            tok = self.next()
            if tok.kind == "}" and ids:
                return ids
            if (tok.kind != "word" or not _UINT_RE.fullmatch(tok.text) or len(tok.text) > MAX_TILE_DIGITS
                    or int(tok.text) < 1):
                self.fail(f"pattern entries must be yarn numbers (integers >= 1), found {tok.describe()}",
                          tok, field="pattern")
            ids.append((int(tok.text), tok.line))
            sep = self.next()
            if sep.kind == "}":
                return ids
            if sep.kind != ",":
                self.fail(f"expected ',' or '}}' between pattern entries, found {sep.describe()}", sep,
                          field="pattern")

    def yarn_block(self, key: _Token, number: int) -> _Block:
        block = _Block(key.line, {})
        for field_tok in self.entries(_YARN_KEYS, f"yarn {number}"):
            self.once(block, field_tok, f"yarn {number}")
            block.fields[field_tok.text] = _Value(self.scalar(field_tok), field_tok.line)
        return block


# ---------------------------------------------------------------------------------------------------------
# Semantics: raw fields -> Weave


def _number(tok: _Token, field: str, source: str) -> float:
    """A finite number in plain decimal notation (:func:`clothlab.untrusted.parse_number`), within the
    plausible range of ``field`` where :data:`FIELD_RANGES` declares one."""
    if tok.kind != "word" or not _NUMBER_RE.fullmatch(tok.text):
        raise InputError(f"expected a number, found {tok.describe()}", path=source, line=tok.line, field=field)
    value = parse_number(tok.text, path=source, line=tok.line, field=field)
    if field in FIELD_RANGES:
        lo, hi, unit = FIELD_RANGES[field]
        if not lo <= value <= hi:
            raise InputError(f"value {value:g} is outside the plausible range [{lo:g}, {hi:g}] {unit}",
                             path=source, line=tok.line, field=field)
    return value


def _positive_int(tok: _Token, field: str, source: str) -> int:
    if tok.kind == "word" and _UINT_RE.fullmatch(tok.text) and len(tok.text) > MAX_TILE_DIGITS:
        raise InputError(f"{field} of {len(tok.text)} digits; a tile has at most {10**MAX_TILE_DIGITS - 1} cells "
                         "per side", path=source, line=tok.line, field=field)
    if tok.kind != "word" or not _UINT_RE.fullmatch(tok.text) or int(tok.text) < 1:
        raise InputError(f"expected a positive integer, found {tok.describe()}", path=source, line=tok.line,
                         field=field)
    return int(tok.text)


def _require(block: _Block, names, what: str, source: str) -> None:
    for name in names:
        if name not in block.fields:
            raise InputError(f"required field '{name}' is missing from the {what} block (opened on line "
                             f"{block.line})", path=source, line=block.line, field=name)


def _check_range(param: str, value: float, line: int, field: str, source: str) -> None:
    try:
        IRAWAN_PARAMS[param].check(value, field)
    except ParameterError as err:
        raise InputError(err.detail, path=source, line=line, field=field) from None


def _build_pattern(ids: list[tuple[int, int]], width: int, height: int, block: _Block, source: str) -> np.ndarray:
    if len(ids) != width * height:
        raise InputError(f"pattern holds {len(ids)} yarn numbers, expected tileWidth x tileHeight = "
                         f"{width} x {height} = {width * height}", path=source,
                         line=block.fields["pattern"].line, field="pattern")
    lines = sorted({line for _, line in ids})
    if len(lines) > 1:  # a multi-line pattern: one row per line
        for row, line in enumerate(lines, start=1):
            count = sum(1 for _, ln in ids if ln == line)
            if count != width:
                raise InputError(f"pattern row {row} holds {count} yarn numbers, expected tileWidth = {width} "
                                 "(one row per line, rows listed from the top of the tile)",
                                 path=source, line=line, field="pattern")
    pattern = np.array([i for i, _ in ids], dtype=np.int64).reshape(height, width)
    pattern.setflags(write=False)
    return pattern


def _segment_geometry(kind: str, yarns: list[tuple[int, _Block, dict]], source: str) -> YarnGeometry:
    """The one geometry shared by all yarns of ``kind``; disagreement is an InputError naming the yarns."""
    of_kind = [(n, b, v) for n, b, v in yarns if v["type"] == kind]
    if not of_kind:
        raise InputError(f"no {kind} yarn is declared; clothlab needs both segment types (warp and weft)",
                         path=source, field="yarn")
    first_n, first_b, first_v = of_kind[0]
    for n, b, v in of_kind[1:]:
        for name in YARN_GEOMETRY_FIELDS:
            if v[name] != first_v[name]:
                raise InputError(
                    f"{kind} yarns disagree in {name}: yarn {first_n} (line {first_b.line}) has "
                    f"{first_v[name]:g}, yarn {n} (line {b.line}) has {v[name]:g}; clothlab has one geometry "
                    f"per segment type (warp, weft), so all {kind} yarns must share psi, umax, kappa, width "
                    "and length (a documented limitation)", path=source, line=b.line, field=name)
    return YarnGeometry(**{attr: first_v[name] for name, attr in YARN_GEOMETRY_FIELDS.items()})


def _yarn_values(number: int, block: _Block, source: str) -> dict:
    _require(block, YARN_REQUIRED, f"yarn {number}", source)
    type_tok = block.fields["type"].value
    if type_tok.text not in YARN_KINDS or type_tok.kind != "word":
        raise InputError(f"yarn {number}: type must be 'warp' or 'weft', found {type_tok.describe()}",
                         path=source, line=type_tok.line, field="type")
    values: dict = {"type": type_tok.text} | YARN_DEFAULTS
    for name in YARN_FLOAT_FIELDS:
        if name in block.fields:
            values[name] = _number(block.fields[name].value, name, source)
    for name, attr in YARN_GEOMETRY_FIELDS.items():
        line = block.fields[name].line if name in block.fields else block.line
        _check_range(f"{values['type']}.{attr}", values[name], line, name, source)
    return values


def parse_wv_text(text: str, source: str = "<string>") -> Weave:
    """Parse the text of a ``.wv`` weave file into a :class:`Weave` (angles in degrees, w/l in cells).

    Raises :class:`InputError` naming ``source``, the line and the field for any syntax or value error.
    """
    source = str(source)
    weave_block, yarn_blocks, pattern_ids = _Parser(_tokenize(text, source), source).parse_file()
    _require(weave_block, WEAVE_REQUIRED, "weave", source)
    if not yarn_blocks:
        raise InputError("the weave block declares no yarn", path=source, line=weave_block.line, field="yarn")
    fields = weave_block.fields

    width = _positive_int(fields["tileWidth"].value, "tileWidth", source)
    height = _positive_int(fields["tileHeight"].value, "tileHeight", source)
    pattern = _build_pattern(pattern_ids, width, height, weave_block, source)

    values = dict(WEAVE_DEFAULTS)
    for name in (*WEAVE_FLOAT_FIELDS, *DUMAX_FIELDS):
        if name in fields:
            values[name] = _number(fields[name].value, name, source)
    for name in ("ss", "hWidth", "alpha", "beta"):
        line = fields[name].line if name in fields else weave_block.line
        _check_range(WEAVE_FLOAT_FIELDS[name], values[name], line, name, source)
    for name in ("warpArea", "weftArea"):
        if not values[name] > 0:
            raise InputError(f"{name} must be > 0 (a relative area weight), found "
                             f"{values[name]:g}", path=source, line=fields[name].line, field=name)
    for name in ("fineness", "period"):
        if values[name] < 0:
            raise InputError(f"{name} must be >= 0 (0 = none), found {values[name]:g}", path=source,
                             line=fields[name].line, field=name)

    yarns = [(n, b, _yarn_values(n, b, source)) for n, b in enumerate(yarn_blocks, start=1)]
    for yarn_id, line in pattern_ids:
        if yarn_id > len(yarns):
            raise InputError(f"pattern refers to yarn {yarn_id} but only {len(yarns)} yarn blocks are declared",
                             path=source, line=line, field="pattern")
    warp = _segment_geometry("warp", yarns, source)
    weft = _segment_geometry("weft", yarns, source)

    if "name" in fields:
        name_tok = fields["name"].value
        if name_tok.kind != "string":
            raise InputError(f"name must be a quoted string, found {name_tok.describe()}", path=source,
                             line=name_tok.line, field="name")
        name = name_tok.text
    else:
        name = Path(source).stem

    segments = tuple(Segment(n, v["type"], v["centerU"], v["centerV"]) for n, _, v in yarns)
    arcs = set(FILAMENT_ARC_RE.findall(text))
    if len(arcs) > 1:
        raise InputError(f"the file records filament_arc twice with different values ({', '.join(sorted(arcs))})",
                         path=source, field="filament_arc")
    return Weave(
        name=name, pattern=pattern, segments=segments, warp=warp, weft=weft,
        dumax=tuple(values[name] for name in DUMAX_FIELDS),
        source=source, filament_arc=next(iter(arcs), None),
        **{attr: values[key] for key, attr in WEAVE_FLOAT_FIELDS.items()},
    )


def parse_wv(path) -> Weave:
    """Read a ``.wv`` weave file (see the module docstring for the format and units)."""
    text = read_text(path, limit=MAX_YAML_BYTES, what="weave file")
    return parse_wv_text(text, source=str(path))


# ---------------------------------------------------------------------------------------------------------
# Writer


def _fmt(x: float) -> str:
    """Shortest text that reads back to the same float64 (integers without a decimal point)."""
    x = float(x)
    if x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def _smoothed_filaments(weave: Weave) -> list[str]:
    """The segment types on which ``filament_arc`` matters: filament (psi = 0, as the renderer decides) with
    smoothing ss > 0."""
    return [kind for kind in YARN_KINDS if weave.delta > 0.0 and weave.geometry(kind).psi == 0.0]


def _filament_arc_lines(weave: Weave) -> list[str]:
    """The comment recording ``weave.filament_arc`` (none when not recorded)."""
    if weave.filament_arc is None:
        return []
    out = [f"  /* clothlab: filament_arc = {weave.filament_arc} */"]
    kinds = _smoothed_filaments(weave)
    if weave.filament_arc == "full" and kinds:
        out.append(f"  /* note: fitted on the full arc (the paper's text); the Mitsuba 0.5/0.6 irawan plugin "
                   f"evaluates the {'/'.join(kinds)} spine on the shortened arc (1 - ss) umax, so its highlight "
                   "shape differs from the fit's (refit with model.options.filament_arc: shortened) */")
    return out


def format_wv(weave: Weave) -> str:
    """The ``.wv`` text of ``weave``; ``parse_wv_text(format_wv(w))`` gives back the same weave.

    Segments are written in the order of their yarn numbers and renumbered 1..n (pattern remapped) if
    their numbers are not already consecutive.  ``weave.filament_arc``, when set, is written as a comment
    (module docstring).
    """
    if '"' in weave.name or "\n" in weave.name:
        raise InputError(f"a weave name cannot contain '\"' or a line break: {weave.name!r}", field="name")
    segments = sorted(weave.segments, key=lambda s: s.yarn)
    renumber = {s.yarn: k for k, s in enumerate(segments, start=1)}
    try:
        pattern = np.vectorize(lambda y: renumber[int(y)], otypes=[np.int64])(weave.pattern)
    except KeyError as err:
        raise InputError(f"the pattern refers to yarn {err.args[0]}, which has no segment", field="pattern") from None
    out = [
        "weave {",
        f'  name = "{weave.name}",',
        "",
        "  /* Tile size of the weave pattern (cells) */",
        f"  tileWidth = {weave.tile_width},",
        f"  tileHeight = {weave.tile_height},",
        "",
        "  /* Uniform and forward scattering (eq. 7) */",
        f"  alpha = {_fmt(weave.alpha)},",
        f"  beta = {_fmt(weave.beta)},",
        "",
        "  /* Filament smoothing (eq. 9, the paper's delta) */",
        f"  ss = {_fmt(weave.delta)},",
        *_filament_arc_lines(weave),
        "",
        "  /* Highlight width as a fraction of the segment (eq. 12) */",
        f"  hWidth = {_fmt(weave.hwidth)},",
        "",
        "  /* Relative areas of warp and weft */",
        f"  warpArea = {_fmt(weave.warp_area)},",
        f"  weftArea = {_fmt(weave.weft_area)},",
        "",
        "  /* Noise: intensity-noise fineness; umax modulation (degrees) and its period */",
        f"  fineness = {_fmt(weave.fineness)},",
        *(f"  {name} = {_fmt(value)}," for name, value in zip(DUMAX_FIELDS, weave.dumax, strict=True)),
        f"  period = {_fmt(weave.period)},",
        "",
        "  /* Weave pattern: yarn numbers, rows from the top of the tile */",
        "  pattern {",
        ",\n".join("    " + ", ".join(str(int(i)) for i in row) for row in pattern),
        "  },",
        "",
        "  /* Yarn segments: angles in degrees, width/length in cells, centre in tile fractions (V from the",
        "     bottom of the tile) */",
    ]
    blocks = []
    for k, seg in enumerate(segments, start=1):
        g = weave.geometry(seg.kind)
        blocks.append(f"  /* {k} */ yarn {{ type = {seg.kind}, psi = {_fmt(g.psi)}, umax = {_fmt(g.umax)}, "
                      f"kappa = {_fmt(g.kappa)}, width = {_fmt(g.w)}, length = {_fmt(g.l)}, "
                      f"centerU = {_fmt(seg.center_u)}, centerV = {_fmt(seg.center_v)} }}")
    out.append(",\n".join(blocks))
    out.append("}")
    return "\n".join(out) + "\n"
