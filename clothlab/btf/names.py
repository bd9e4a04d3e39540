"""Angles of BTF images: from Bonn UBO2003 / UTIA file names or from a manifest (docs/formats.md, "BTF image stacks").

File-name layouts (one image per light/view pair, angles in degrees):

- Bonn UBO2003: ``tv030_pv030/00008 tl000 pl000 tv030 pv030.jpg``
- UTIA:         ``tv000_pv000/tl000_pl000_tv000_pv000.png`` (or ``.exr``)

``tl``/``pl`` are the light (incident) polar angle / azimuth, ``tv``/``pv`` the view (exitant) ones.  The
four fields may be separated by spaces or underscores; clothlab's own writer may add a decimal part
(``tl022.5``).  A parent directory named ``tvNNN_pvNNN`` must agree with the file name.

Azimuth convention assumed for the names (stated, not documented by the databases themselves): phi is
measured counter-clockwise, seen from above the sample (from the camera), from the image's +column
direction ("image right"); phi = 90 deg points to the image top.  With the warp along the image's vertical
axis (the default, ``warp_axis="vertical"``, image top = +y = warp) image right is the weft (+x), so the
names' azimuths already are clothlab azimuths (zero = weft, counter-clockwise).  With
``warp_axis="horizontal"`` (image right = warp) the zero is the warp: phi_clothlab = phi_name + 90 deg.

Manifests list ``file -> theta_i, phi_i, theta_o, phi_o`` (degrees) and may declare their azimuth convention
relative to the fabric (``zero``: weft | x | warp | y, ``sense``: ccw | cw) and the image axis that carries
the warp (``warp_axis``: vertical | horizontal):

YAML::

    clothlab_btf_manifest: 1
    warp_axis: vertical
    azimuth: {zero: weft, sense: ccw}
    images:
      - {file: tv000_pv000/tl000_pl000_tv000_pv000.exr, theta_i: 0, phi_i: 0, theta_o: 0, phi_o: 0}

CSV (``# key: value`` lines before the header)::

    # warp_axis: vertical
    # azimuth_zero: weft
    # azimuth_sense: ccw
    file,theta_i,phi_i,theta_o,phi_o
    tv000_pv000/tl000_pl000_tv000_pv000.exr,0,0,0,0
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.errors import InputError
from clothlab.frames import AZIMUTH_SENSE, AZIMUTH_ZERO, azimuth_to_clothlab
from clothlab.untrusted import MAX_YAML_BYTES, compose_yaml, construct_yaml, parse_number, read_text

#: Image file suffixes a stack may hold (lower case).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr")
#: Manifest file names looked for inside a stack directory, in this order.
MANIFEST_NAMES = ("manifest.yaml", "manifest.yml", "manifest.csv")
WARP_AXES = ("vertical", "horizontal")
ANGLE_FIELDS = ("theta_i", "phi_i", "theta_o", "phi_o")

_NUMBER = r"(\d+(?:\.\d+)?)"
_ANGLES = re.compile(rf"tl{_NUMBER}[ _]+pl{_NUMBER}[ _]+tv{_NUMBER}[ _]+pv{_NUMBER}", re.IGNORECASE)
_VIEW_DIR = re.compile(rf"^tv{_NUMBER}[ _]+pv{_NUMBER}$", re.IGNORECASE)
_DUPLICATE_DIGITS = 6  # angle sets equal to 1e-6 deg are duplicates


@dataclass(frozen=True)
class BtfEntry:
    """One image of a stack: its path and the light/view directions in clothlab's convention (degrees)."""

    path: Path
    theta_i: float
    phi_i: float
    theta_o: float
    phi_o: float

    @property
    def angles(self) -> tuple[float, float, float, float]:
        return (self.theta_i, self.phi_i, self.theta_o, self.phi_o)


def parse_angles(name: str) -> tuple[float, float, float, float] | None:
    """(theta_i, phi_i, theta_o, phi_o) in degrees as written in a Bonn/UTIA file name, or None."""
    match = _ANGLES.search(Path(name).name)
    return None if match is None else tuple(float(g) for g in match.groups())


def name_convention(warp_axis: str) -> dict:
    """The fabric-relative azimuth convention of Bonn/UTIA names for a given warp image axis (see module doc)."""
    _check_warp_axis(warp_axis, None)
    return {"zero": "weft" if warp_axis == "vertical" else "warp", "sense": "ccw"}


def format_angle(value: float) -> str:
    """An angle for a file name: ``030`` for integer degrees, ``022.5`` otherwise (at most 4 decimals)."""
    value = round(float(value), 4)
    if value < 0:
        raise ValueError(f"angles in BTF names are non-negative degrees, got {value}")
    if value == int(value):
        return f"{int(value):03d}"
    return f"{value:08.4f}".rstrip("0")


def is_image(path: Path) -> bool:
    return path.suffix.lower() in IMAGE_SUFFIXES and not path.name.startswith(".")


def find_manifest(directory: Path) -> Path | None:
    """The manifest inside a stack directory (:data:`MANIFEST_NAMES`), or None."""
    for name in MANIFEST_NAMES:
        if (directory / name).is_file():
            return directory / name
    return None


def entries_from_names(directory, *, warp_axis: str = "vertical", grid: bool | None = None) -> list[BtfEntry]:
    """Entries of every image below ``directory`` whose names carry the angles (sorted by path).

    Completeness (:func:`check_grid`): Bonn / UTIA stacks are light x view grids, so a missing image is an
    error naming the file expected.  ``grid`` None checks when the names look like a grid (a light direction
    shared by two views); True always; False never (a scattered sampling, e.g. clothlab's writer without a
    manifest, has every view with its own lights).
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise InputError("BTF stack directory not found", path=directory)
    convention = name_convention(warp_axis)
    entries, raw = [], []
    for path in sorted(p for p in directory.rglob("*") if p.is_file() and is_image(p)):
        rel = path.relative_to(directory)
        if any(part.startswith(".") for part in rel.parts):
            continue
        angles = parse_angles(path.name)
        if angles is None:
            raise InputError(
                "cannot read the angles from the file name: expected 'tlNNN plNNN tvNNN pvNNN' (spaces or "
                "underscores, Bonn UBO2003 / UTIA naming) or a manifest.yaml / manifest.csv in the stack "
                "directory", path=path)
        view_dir = _VIEW_DIR.match(path.parent.name)
        if view_dir is not None and path.parent != directory:
            tv, pv = (float(g) for g in view_dir.groups())
            if (tv, pv) != angles[2:]:
                raise InputError(
                    f"view angles in the file name (tv {angles[2]:g}, pv {angles[3]:g}) disagree with its "
                    f"directory '{path.parent.name}' (tv {tv:g}, pv {pv:g})", path=path)
        entries.append(_entry(path, angles, convention, path))
        raw.append((path, angles))
    if not entries:
        raise InputError(
            f"no images ({', '.join(IMAGE_SUFFIXES)}) found in the BTF stack directory", path=directory)
    check_duplicates(entries)
    if grid is not False:
        check_grid(directory, raw, required=bool(grid))
    return entries


#: The 81 directions of the Bonn UBO2003 / UTIA sampling: polar angle -> azimuth step (deg); 1 + 6 + 12 +
#: 18 + 20 + 24 = 81 directions, each stack 81 x 81 = 6,561 images.
UTIA_RINGS = {0.0: 360.0, 15.0: 60.0, 30.0: 30.0, 45.0: 20.0, 60.0: 18.0, 75.0: 15.0}


def utia_directions() -> list[tuple[float, float]]:
    """The 81 (theta, phi) directions (deg) of the Bonn / UTIA sampling, as written in the file names."""
    return [(theta, float(phi)) for theta, step in UTIA_RINGS.items() for phi in np.arange(0.0, 360.0, step)]


def _key(theta, phi) -> tuple[float, float]:
    return (round(float(theta), 4), round(float(phi) % 360.0, 4))


def check_grid(directory, raw, *, required: bool = False) -> None:
    """InputError naming the first missing file when a name-based stack is not a complete light x view grid.

    ``raw``: (path, (tl, pl, tv, pv) as written in the name).  Every view must carry the same lights (the
    union over views) - checked when ``required`` or when some light is shared by two views; and a stack
    whose directions all lie on the 81-direction Bonn / UTIA sampling and which holds more than half of its
    6,561 images claims that sampling, so all 81 x 81 must be there (this finds a whole missing view
    directory too).  A subset of a few views, e.g. one view of a database, is checked as its own grid.
    """
    views: dict[tuple, dict[tuple, Path]] = {}
    for path, (tl, pl, tv, pv) in raw:
        views.setdefault(_key(tv, pv), {})[_key(tl, pl)] = path
    lights = {light for per_view in views.values() for light in per_view}
    shared = len(raw) > len(lights)
    full = {_key(t, p) for t, p in utia_directions()}
    claims_full = lights <= full and set(views) <= full and len(raw) > len(full) ** 2 // 2
    product_lights, product_views = _claimed_product(lights), _claimed_product(set(views))
    if claims_full:
        expected_views, expected_lights = sorted(full), sorted(full)
    elif required or shared or product_lights or product_views:
        expected_views = sorted(product_views or views)
        expected_lights = sorted(product_lights or lights)
    else:
        return
    missing = [(view, light) for view in expected_views for light in expected_lights
               if light not in views.get(view, {})]
    if not missing:
        return
    view, light = missing[0]
    expected = _expected_path(Path(directory), views.get(view), raw[0][0], light, view)
    what = ("the 81 x 81 Bonn UBO2003 / UTIA sampling (its directions all lie on that grid)" if claims_full else
            f"a {len(expected_views)}-view x {len(expected_lights)}-light grid (the lights of every view"
            + (", every polar angle at every azimuth" if product_lights or product_views else "") + ")")
    more = f"; {len(missing) - 1} more image(s) missing" if len(missing) > 1 else ""
    shown = expected.relative_to(directory) if expected.is_relative_to(directory) else expected
    raise InputError(
        f"missing image: expected '{shown}'"
        f" (light tl {light[0]:g} pl {light[1]:g}, view tv {view[0]:g} pv {view[1]:g}) to complete {what}{more}; "
        "a stack that is not a light x view grid needs a manifest", path=expected)


PRODUCT_COVERAGE = 0.75
"""A set of directions off the pole filling at least this share (and not all) of the product of its polar
angles and azimuths claims that product grid: the rest are missing images (e.g. Fig. 4's elevations x
azimuths with one image deleted).  A sampling that is not such a grid needs a manifest."""


def _claimed_product(directions: set) -> set | None:
    """The polar x azimuth grid (the pole, theta = 0, kept as one direction) that ``directions`` claim but do
    not fill, or None: at least two polar angles and two azimuths off the pole, and a coverage of at least
    :data:`PRODUCT_COVERAGE` of their product."""
    off_pole = {d for d in directions if d[0] != 0.0}
    thetas, phis = {t for t, _ in off_pole}, {p for _, p in off_pole}
    grid = {(t, p) for t in thetas for p in phis}
    if len(thetas) < 2 or len(phis) < 2 or off_pole == grid or len(off_pole) < PRODUCT_COVERAGE * len(grid):
        return None
    return grid | (directions - off_pole)


def _expected_path(directory: Path, same_view: dict | None, template: Path, light, view) -> Path:
    """The file name a missing (light, view) image would have, in the style of a file of the same view (or,
    for a view with no image at all, of ``template`` in a sibling ``tvNNN_pvNNN`` directory)."""
    sibling = next(iter(same_view.values())) if same_view else template
    name = sibling.name
    match = _ANGLES.search(name)
    numbers = iter((light[0], light[1], view[0], view[1]))
    angles = re.sub(_NUMBER, lambda _m: format_angle(next(numbers)), match.group(0))
    prefix = re.sub(r"\d", "#", name[: match.start()])  # an image index (Bonn) is unknown
    parent = sibling.parent
    if not same_view and parent != directory and _VIEW_DIR.match(parent.name):
        sep = re.search(r"[ _]+", parent.name).group(0)
        parent = parent.parent / f"tv{format_angle(view[0])}{sep}pv{format_angle(view[1])}"
    return parent / (prefix + angles + name[match.end():])


def read_manifest(path) -> tuple[list[BtfEntry], str]:
    """Entries (clothlab convention) and the warp image axis declared by a YAML or CSV manifest."""
    path = Path(path)
    if not path.is_file():
        raise InputError("BTF manifest not found", path=path)
    if path.suffix.lower() in (".yaml", ".yml"):
        header, rows = _read_yaml_manifest(path)
    elif path.suffix.lower() == ".csv":
        header, rows = _read_csv_manifest(path)
    else:
        raise InputError(f"unknown manifest type '{path.suffix}': expected .yaml, .yml or .csv", path=path)
    warp_axis = str(header.get("warp_axis", "vertical")).strip().lower()
    _check_warp_axis(warp_axis, path)
    zero = str(header.get("azimuth_zero", "weft")).strip().lower()
    sense = str(header.get("azimuth_sense", "ccw")).strip().lower()
    if zero not in AZIMUTH_ZERO:
        raise InputError(f"azimuth zero '{zero}' is not one of {', '.join(AZIMUTH_ZERO)}", path=path,
                         field="azimuth.zero")
    if sense not in AZIMUTH_SENSE:
        raise InputError(f"azimuth sense '{sense}' is not one of {', '.join(AZIMUTH_SENSE)}", path=path,
                         field="azimuth.sense")
    convention = {"zero": zero, "sense": sense}
    entries = []
    root = path.parent
    first_line: dict[Path, int | None] = {}
    for line, row in rows:
        name = row.get("file")
        if name is None or not isinstance(name, str) or not name.strip():
            raise InputError(f"manifest row has no 'file' name (found {name!r})", path=path, line=line,
                             field="file")
        angles = [_angle(row.get(field_name), path=path, line=line, field=field_name)
                  for field_name in ANGLE_FIELDS]
        image = root / name.strip()
        if image in first_line:
            where = "" if first_line[image] is None else f" (first on line {first_line[image]})"
            raise InputError(f"image {name.strip()!r} is listed twice{where}: one image holds one angle set",
                             path=path, line=line, field="file")
        first_line[image] = line
        entries.append(_entry(image, tuple(angles), convention, path, line=line))
    if not entries:
        raise InputError("manifest lists no images", path=path)
    check_duplicates(entries)
    return entries, warp_axis


def _angle(value, **where) -> float:
    """An angle in degrees from a manifest cell: a YAML number, or text in plain decimal notation."""
    if isinstance(value, str):
        return parse_number(value, **where)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"expected an angle in degrees, found {value!r}", **where)
    return float(value)


def check_duplicates(entries: list[BtfEntry]) -> None:
    """InputError naming both files when two entries carry the same four angles."""
    seen: dict[tuple, Path] = {}
    for entry in entries:
        key = tuple(round(a, _DUPLICATE_DIGITS) for a in entry.angles)
        if key in seen:
            raise InputError(
                f"duplicate angle set (theta_i, phi_i, theta_o, phi_o) = {tuple(float(a) for a in key)} deg, "
                f"also carried by {seen[key]}", path=entry.path)
        seen[key] = entry.path


def _entry(path: Path, angles, convention: dict, source: Path, line: int | None = None) -> BtfEntry:
    theta_i, phi_i, theta_o, phi_o = angles
    for name, value in zip(ANGLE_FIELDS, angles, strict=True):
        if not math.isfinite(value):
            raise InputError(f"angle {name} is {value}; expected a finite number of degrees", path=source,
                             line=line, field=name)
    for name, value in (("theta_i", theta_i), ("theta_o", theta_o)):
        if not 0.0 <= value <= 90.0:
            raise InputError(f"{name} = {value:g} deg lies outside [0, 90] deg", path=source, line=line,
                             field=name)
    phi_i, phi_o = (float(azimuth_to_clothlab(p, **convention)) for p in (phi_i, phi_o))
    return BtfEntry(path, float(theta_i), phi_i, float(theta_o), phi_o)


def _check_warp_axis(warp_axis: str, path) -> None:
    if warp_axis not in WARP_AXES:
        raise InputError(f"warp_axis '{warp_axis}' is not one of {', '.join(WARP_AXES)}", path=path,
                         field="warp_axis")


def _read_yaml_manifest(path: Path) -> tuple[dict, list[tuple[int | None, dict]]]:
    import yaml

    node, loader = compose_yaml(read_text(path, limit=MAX_YAML_BYTES, what="BTF manifest"), path=path)
    item_lines = []
    if isinstance(node, yaml.MappingNode):
        for key, value in node.value:
            if key.value == "images" and isinstance(value, yaml.SequenceNode):
                item_lines = [item.start_mark.line + 1 for item in value.value]
    data = construct_yaml(loader, node, path=path)
    if not isinstance(data, dict) or not isinstance(data.get("images"), list):
        raise InputError("expected a mapping with an 'images' list of {file, theta_i, phi_i, theta_o, phi_o}",
                         path=path, field="images")
    azimuth = data.get("azimuth") or {}
    if not isinstance(azimuth, dict):
        raise InputError(f"expected a mapping {{zero, sense}}, found {azimuth!r}", path=path, field="azimuth")
    header = {"warp_axis": data.get("warp_axis", "vertical"), "azimuth_zero": azimuth.get("zero", "weft"),
              "azimuth_sense": azimuth.get("sense", "ccw")}
    rows = []
    for index, row in enumerate(data["images"]):
        line = item_lines[index] if index < len(item_lines) else None
        if not isinstance(row, dict):
            raise InputError(f"images[{index}] is {row!r}; expected a mapping with file and four angles",
                             path=path, line=line, field=f"images[{index}]")
        rows.append((line, row))
    return header, rows


def _read_csv_manifest(path: Path) -> tuple[dict, list[tuple[int | None, dict]]]:
    header: dict = {}
    lines = read_text(path, limit=MAX_YAML_BYTES, what="BTF manifest").splitlines()
    body_start = 0
    for number, text in enumerate(lines):
        stripped = text.strip()
        if stripped.startswith("#"):
            key, sep, value = stripped.lstrip("#").partition(":")
            if sep:
                header[key.strip().lower()] = value.strip()
            continue
        if stripped:
            body_start = number
            break
    else:
        raise InputError("manifest has no header row 'file,theta_i,phi_i,theta_o,phi_o'", path=path)
    reader = csv.reader(lines[body_start:])
    columns = [c.strip().lower() for c in next(reader)]
    missing = [c for c in ("file", *ANGLE_FIELDS) if c not in columns]
    if missing:
        raise InputError(f"header lacks column(s) {', '.join(missing)}; found {', '.join(columns)}", path=path,
                         line=body_start + 1)
    rows = []
    for offset, values in enumerate(reader, start=2):
        if not values or not "".join(values).strip() or values[0].lstrip().startswith("#"):
            continue
        if len(values) != len(columns):
            raise InputError(f"expected {len(columns)} fields, found {len(values)}", path=path,
                             line=body_start + offset)
        rows.append((body_start + offset, dict(zip(columns, values, strict=True))))
    return header, rows


def angle_table(entries: list[BtfEntry]) -> np.ndarray:
    """(N, 4) float64 array of (theta_i, phi_i, theta_o, phi_o) in degrees."""
    return np.array([e.angles for e in entries], dtype=np.float64).reshape(-1, 4)
