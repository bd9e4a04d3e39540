"""The six fabrics of Irawan & Marschner 2012 (sec. 8, Table I) as named weave presets.

The presets are the ``.wv`` files shipped in ``clothlab/weave/data/`` (the one source of truth; their numbers
are the published ones, see docs/presets.md); :func:`get_preset` reads them with
:func:`clothlab.weave.wvformat.parse_wv_text`.  :func:`resolve_weave` interprets the ``weave:`` field of
fabric.yaml: ``preset:<name>`` or a path to a ``.wv`` file.

>>> from clothlab.weave.presets import PRESET_NAMES, get_preset
>>> PRESET_NAMES[:2]
('cotton-denim', 'silk-shantung')
>>> denim = get_preset("cotton-denim")
>>> denim.warp.umax, denim.weft.umax  # Table I, degrees
(12.0, 38.0)
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from pathlib import Path

from clothlab.errors import ConfigError
from clothlab.weave.model import Weave
from clothlab.weave.wvformat import parse_wv, parse_wv_text

PRESET_NAMES = (
    "cotton-denim",
    "silk-shantung",
    "silk-charmeuse",
    "cotton-twill",
    "wool-gabardine",
    "polyester-lining",
)
PRESET_PREFIX = "preset:"


def canonical_preset_name(name: str) -> str:
    """The preset key for ``name`` (case-insensitive; '_' or ' ' accepted for '-'); ConfigError if unknown.

    >>> canonical_preset_name("Silk_Charmeuse")
    'silk-charmeuse'
    >>> canonical_preset_name("linen")
    Traceback (most recent call last):
    ...
    clothlab.errors.ConfigError: field 'weave': unknown weave preset 'linen'; known presets: cotton-denim, ...
    """
    key = str(name).strip().lower().replace("_", "-").replace(" ", "-")
    if key not in PRESET_NAMES:
        raise ConfigError(f"unknown weave preset '{name}'; known presets: {', '.join(PRESET_NAMES)}",
                          field="weave")
    return key


@cache
def _load_preset(key: str) -> Weave:
    resource = resources.files("clothlab.weave").joinpath("data", f"{key}.wv")
    return parse_wv_text(resource.read_text(encoding="utf-8"), source=str(resource))


def get_preset(name: str) -> Weave:
    """The weave of one of the paper's fabrics (:data:`PRESET_NAMES`); angles in degrees, w and l in cells.

    The returned Weave is shared between calls (it is frozen and its pattern array is read-only).

    >>> lining = get_preset("polyester-lining")
    >>> lining.name, lining.pattern.shape, lining.warp.psi
    ('polyester-lining', (2, 2), 0.0)
    >>> get_preset("Polyester Lining") is lining
    True
    """
    return _load_preset(canonical_preset_name(name))


def resolve_weave(spec: str, base_dir) -> Weave:
    """The weave named by fabric.yaml's ``weave:`` field.

    ``spec`` is ``preset:<name>``, ``pattern:<name>`` (:mod:`clothlab.weave.patterns`) or a
    path to a ``.wv`` file, relative to ``base_dir`` (the directory of
    fabric.yaml) unless absolute.  An unknown preset or a missing file raises :class:`ConfigError` naming
    it; errors inside the file raise :class:`~clothlab.errors.InputError` naming file, line and field.

    >>> resolve_weave("preset:cotton-twill", ".").name
    'cotton-twill'
    >>> resolve_weave("pattern:plain", ".").pattern.shape
    (2, 2)
    """
    if not isinstance(spec, str) or not spec.strip():
        raise ConfigError(f"weave must be 'preset:<name>' or the path of a .wv file, got {spec!r}; "
                          f"known presets: {', '.join(PRESET_NAMES)}", field="weave")
    spec = spec.strip()
    if spec.lower().startswith(PRESET_PREFIX):
        return get_preset(spec[len(PRESET_PREFIX):].strip())
    if spec.lower().startswith("pattern:"):  # generated patterns (Chen, Wang & Wang 2024, Table 2)
        from clothlab.weave.patterns import PATTERN_PREFIX, get_pattern

        return get_pattern(spec[len(PATTERN_PREFIX):].strip())
    path = Path(spec).expanduser()
    if not path.is_absolute():
        path = Path(base_dir) / path
    if not path.is_file():
        raise ConfigError(f"weave file '{path}' not found (from weave: {spec!r}); give a .wv file or "
                          f"preset:<name> with one of: {', '.join(PRESET_NAMES)}", field="weave")
    return parse_wv(path)
