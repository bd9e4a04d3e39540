"""Saving and loading a surrogate: ``NAME.npz`` (the parameter tensors and material vectors; no pickle) and
``NAME.json`` beside it (architecture, encodings, components, data hash, metrics).  Both written atomically.

Reading is strict (docs/design.md principle 7; :mod:`clothlab.untrusted`): the sidecar is read first and checked
against a schema (:func:`read_sidecar`: types, ranges, widths at most :data:`MAX_WIDTH`, parameters at most
:data:`MAX_PARAMETERS`, the architecture consistent with the encoding), then the ``.npz`` is read with the
member shapes the architecture implies (:func:`clothlab.untrusted.read_npz`: size checked before reading,
members bounded before inflating, no pickle, float32/float64 only, every value finite and at most
:data:`MAX_WEIGHT` in magnitude), and the loaded network must give finite outputs.  Every refusal is an
:class:`~clothlab.errors.InputError` naming the file and the field (a sidecar key as a dotted path such as
``architecture.width``, or the weights' member such as ``param/ang5.b``).  Keys the schema does not know are
ignored (metrics and notes of later versions)."""

from __future__ import annotations

import functools
import io
import json
import math
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import InputError
from clothlab.surrogate.encodings import n_direction_features, n_yarn_features
from clothlab.surrogate.network import Architecture, SurrogateNetwork
from clothlab.surrogate.surrogate import Surrogate
from clothlab.surrogate.threads import one_blas_thread
from clothlab.untrusted import MAX_YAML_BYTES, NPY_HEADER_BYTES, load_json_file, read_npz

FORMAT = "clothlab-neural-surrogate/1"
MAX_WIDTH = 4096
"""Largest input size or layer width of a surrogate's architecture (``train-surrogate --width`` / ``--spatial``
take up to 4,096; the shipped networks: at most 128)."""
MAX_PARAMETERS = 1 << 27
"""Most parameter values of a surrogate (134 M, 512 MiB in float32: ``--width 4096 --spatial 4096``, the
largest decoder train-surrogate takes, has 86 M; the shipped networks: 70,563)."""
MAX_MATERIALS = 1 << 16
"""Most material rows (encoder inputs) of a surrogate (``--vary`` grids have at most 4,096; ``--draw`` more)."""
MAX_BINS = 256
"""Most one-blob bins per input (position, size, yarn coordinates; the paper: 8; ``--yarn-bins`` up to 256)."""
MAX_PROBE_POINTS = 8
"""Most texture probe points per side."""
MAX_PATTERN_ORDER = 8
"""Highest Fourier order of the pattern descriptor (:func:`clothlab.surrogate.encodings.pattern_descriptor`)."""
MAX_WEIGHT = 1e4
"""Largest magnitude of a stored parameter or material value (trained networks stay below 10)."""
MIN_K_SPECULAR, MAX_K_SPECULAR = 1e-3, 1e6
"""Range of ``k_specular``, the k of the specular output transform ln(k x + 1) (eq. 9; default 100)."""
DTYPES = ("float32", "float64")
ARCHITECTURE_KEYS = ("n_material", "n_spatial", "n_angular", "n_out", "enc_width", "latent", "width", "spatial")


def save_surrogate(surrogate: Surrogate, path, *, data_hash: str = "", metrics: dict | None = None) -> Path:
    """Write ``path`` (.npz) and its ``.json`` sidecar; returns the .npz path."""
    path = Path(path).with_suffix(".npz")
    arrays = {f"param/{k}": v for k, v in surrogate.network.params().items()}
    arrays["materials"] = np.asarray(surrogate.materials, dtype=np.float64)
    buffer = io.BytesIO()
    np.savez(buffer, allow_pickle=False, **arrays)
    atomic_write_bytes(path, buffer.getvalue())
    sidecar = {"format": FORMAT, "architecture": surrogate.network.arch.to_dict(),
               "dtype": str(surrogate.network.dtype), "components": list(surrogate.component_names),
               "k_specular": surrogate.k, "encoding": surrogate.encoding, "data_sha256": data_hash,
               "parameters": surrogate.network.n_parameters(),
               "decoder_parameters": surrogate.network.n_parameters(decoder_only=True),
               "metrics": metrics or {}}
    atomic_write_bytes(path.with_suffix(".json"), (json.dumps(sidecar, indent=2) + "\n").encode())
    return path


def parameter_shapes(arch: dict) -> dict[str, tuple[int, ...]]:
    """The shape of every parameter tensor of the network of ``arch``, named as
    :meth:`clothlab.surrogate.network.SurrogateNetwork.params` (the encoder's 4 dense layers, the 2 fusion
    layers, the 5 angular layers; Chen, Wang & Wang 2024, Fig. 3), known before anything is allocated."""
    a = {k: arch.get(k, getattr(Architecture, k, 0)) for k in ARCHITECTURE_KEYS}
    e, w, s = a["enc_width"], a["width"], a["spatial"]
    dense = {"enc_in": (a["n_material"], e), "enc_res.1": (e, e), "enc_res.2": (e, e), "enc_out": (e, a["latent"]),
             "fuse1": (a["latent"] + a["n_spatial"], w), "fuse2": (w, s), "ang1": (s + a["n_angular"], w),
             "ang_res.1": (w, w), "ang_res.2": (w, w), "ang4": (w, w), "ang5": (w, a["n_out"])}
    shapes = {}
    for name, (n_in, n_out) in dense.items():
        shapes[f"{name}.W"], shapes[f"{name}.b"] = (n_in, n_out), (n_out,)
    return shapes


def parameter_count(arch: dict) -> int:
    """Parameter values of the network of ``arch`` (:func:`parameter_shapes`)."""
    return sum(math.prod(shape) for shape in parameter_shapes(arch).values())


def pattern_length(order: int) -> int:
    """Values of the pattern descriptor of Fourier ``order``
    (:func:`clothlab.surrogate.encodings.pattern_descriptor`)."""
    return 1 + 2 * (order + order * (2 * order + 1))


class _Schema:
    """Checks of one sidecar's values; every failure an InputError naming the file and the dotted field."""

    def __init__(self, path: Path):
        self.path = path

    def fail(self, field: str, message: str):
        raise InputError(message, path=self.path, field=field)

    def mapping(self, value, field: str, *, required: bool = True) -> dict:
        if value is None and not required:
            return {}
        if not isinstance(value, dict):
            self.fail(field, f"expected a mapping, got {_shown(value)}")
        return value

    def integer(self, value, field: str, lo: int, hi: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(field, f"expected an integer, got {_shown(value)}")
        if not lo <= value <= hi:
            self.fail(field, f"{_shown(value)} is outside [{lo}, {hi}]")
        return value

    def number(self, value, field: str, lo: float, hi: float, *, open_lo: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(field, f"expected a number, got {_shown(value)}")
        value = float(value)
        if not math.isfinite(value):
            self.fail(field, f"{value!r} is not finite")
        tiny = np.finfo(np.float64).tiny
        if value != 0.0 and abs(value) < tiny:
            self.fail(field, f"{value!r} is a denormal number (below {tiny:g} in magnitude)")
        if not (lo < value if open_lo else lo <= value) or not value <= hi:
            self.fail(field, f"{value!r} is outside {'(' if open_lo else '['}{lo:g}, {hi:g}]")
        return value

    def boolean(self, value, field: str) -> bool:
        if not isinstance(value, bool):
            self.fail(field, f"expected true or false, got {_shown(value)}")
        return value

    def string(self, value, field: str, *, limit: int = 256) -> str:
        if not isinstance(value, str):
            self.fail(field, f"expected a string, got {_shown(value)}")
        if len(value) > limit:
            self.fail(field, f"a string of {len(value)} characters (at most {limit})")
        return value

    def strings(self, value, field: str, *, most: int, unique: bool = False) -> list:
        if not isinstance(value, list):
            self.fail(field, f"expected a list of strings, got {_shown(value)}")
        if len(value) > most:
            self.fail(field, f"{len(value)} items (at most {most})")
        for i, item in enumerate(value):
            self.string(item, f"{field}[{i}]")
        if unique and len(set(value)) < len(value):
            self.fail(field, f"a name is listed twice: {', '.join(value)}")
        return value

    def numbers(self, value, field: str, *, most: int) -> dict:
        """A mapping name -> finite number (parameter values)."""
        value = self.mapping(value, field)
        if len(value) > most:
            self.fail(field, f"{len(value)} entries (at most {most})")
        for name, v in value.items():
            self.number(v, f"{field}.{name}", -1e300, 1e300)
        return value

    def indices(self, value, field: str, n: int) -> list:
        if not isinstance(value, list):
            self.fail(field, f"expected a list of material rows, got {_shown(value)}")
        for i, item in enumerate(value):
            self.integer(item, f"{field}[{i}]", 0, n - 1)
        return value


def _shown(value) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 40 else text[:37] + '...'}"


def read_sidecar(path) -> dict:
    """The checked ``.json`` sidecar of a surrogate (module docstring): InputError naming the file and the
    dotted field of the first value outside the schema."""
    path = Path(path).with_suffix(".json")
    try:
        sidecar = load_json_file(path, what="surrogate sidecar", limit=MAX_YAML_BYTES)
    except InputError as exc:
        if exc.line is None and exc.field is None and "not a finite number" in exc.detail:
            raise InputError(exc.detail, path=path, line=_constant_line(path)) from None
        raise
    check = _Schema(path)
    check.mapping(sidecar, "format")
    if sidecar.get("format") != FORMAT:
        check.fail("format", f"not a surrogate sidecar: format {_shown(sidecar.get('format'))}, expected {FORMAT!r} "
                             "(written by clothlab train-surrogate)")
    arch = check.mapping(sidecar.get("architecture"), "architecture")
    for key in arch:
        if key not in ARCHITECTURE_KEYS:
            check.fail(f"architecture.{key}", f"unknown architecture key {key!r}; keys: {', '.join(ARCHITECTURE_KEYS)}")
    for key in ARCHITECTURE_KEYS:
        if key in arch or key in ARCHITECTURE_KEYS[:4]:
            if key not in arch:
                check.fail(f"architecture.{key}", "missing (an input size of the network)")
            check.integer(arch[key], f"architecture.{key}", 1, MAX_WIDTH)
    count = parameter_count(arch)
    if count > MAX_PARAMETERS:
        check.fail("architecture", f"the architecture has {count} parameters; at most {MAX_PARAMETERS} are read")
    if "parameters" in sidecar and check.integer(sidecar["parameters"], "parameters", 0, 1 << 62) != count:
        check.fail("parameters", f"{sidecar['parameters']} parameters recorded, the architecture has {count}")
    dtype = sidecar.get("dtype", "float32")
    if dtype not in DTYPES:
        check.fail("dtype", f"dtype {_shown(dtype)}; expected one of {', '.join(DTYPES)}")
    components = check.strings(sidecar.get("components"), "components", most=MAX_WIDTH, unique=True)
    if len(components) != arch["n_out"]:
        check.fail("components", f"{len(components)} components, the architecture has n_out = {arch['n_out']}")
    if "k_specular" in sidecar:
        check.number(sidecar["k_specular"], "k_specular", MIN_K_SPECULAR, MAX_K_SPECULAR)
    for key in ("data_sha256",):
        if key in sidecar:
            check.string(sidecar[key], key)
    check.mapping(sidecar.get("metrics"), "metrics", required=False)
    _check_encoding(check, check.mapping(sidecar.get("encoding"), "encoding", required=False), arch)
    if sidecar.get("estimator_choice") is not None:  # neural-lod's per-weave crossovers (optional)
        from clothlab.surrogate.estimator_choice import check_choice

        check_choice(check, sidecar["estimator_choice"])
    return sidecar


def _constant_line(path: Path) -> int | None:
    """The line of the first NaN / Infinity constant outside a JSON string (the strict reader refuses them
    without a position); the file has been read within its bound already."""
    import re

    text = path.read_text(encoding="utf-8-sig")
    for match in re.finditer(r'"(?:[^"\\]|\\.)*"|(-?Infinity|NaN)', text):
        if match.group(1):
            return text.count("\n", 0, match.start()) + 1
    return None


def materials_count(encoding: dict) -> int:
    """Rows of the material matrix of a (checked) encoding: one per ``materials_params`` entry, else 1."""
    return len(encoding["materials_params"]) if "materials_params" in encoding else 1


def _check_encoding(check: _Schema, enc: dict, arch: dict) -> None:
    """The encoding's values and their agreement with the architecture's input sizes."""
    at = "encoding."
    n_out = arch["n_out"]
    for key in ("kind", "weave", "labels", "heldout_pattern_name"):
        if key in enc:
            check.string(enc[key], at + key)
    if "weave_wv" in enc:
        _check_wv(check, enc["weave_wv"], at + "weave_wv")
    names = None
    if "parameters" in enc:
        names = check.strings(enc["parameters"], at + "parameters", most=MAX_WIDTH, unique=True)
    order = check.integer(enc.get("pattern_order", 2), at + "pattern_order", 0, MAX_PATTERN_ORDER)
    if names is not None and len(names) + pattern_length(order) != arch["n_material"]:
        check.fail("architecture.n_material", f"n_material = {arch['n_material']}, but {len(names)} parameters and "
                   f"a pattern descriptor of order {order} ({pattern_length(order)} values) make "
                   f"{len(names) + pattern_length(order)}")
    if "params" in enc:
        check.numbers(enc["params"], at + "params", most=MAX_WIDTH)
    if enc.get("reference_quadrature") is not None:  # the configured R's quadrature (surrogate.materials)
        quadrature = check.mapping(enc["reference_quadrature"], at + "reference_quadrature")
        check.string(quadrature.get("rule"), at + "reference_quadrature.rule", limit=32)
        check.integer(quadrature.get("nodes"), at + "reference_quadrature.nodes", 1, 1000)
    n = 1
    if "materials_params" in enc:
        sets = enc["materials_params"]
        if not isinstance(sets, list) or not sets:
            check.fail(at + "materials_params", f"expected a non-empty list of parameter sets, got {_shown(sets)}")
        if len(sets) > MAX_MATERIALS:
            check.fail(at + "materials_params", f"{len(sets)} materials (at most {MAX_MATERIALS})")
        for i, q in enumerate(sets):
            check.numbers(q, f"{at}materials_params[{i}]", most=MAX_WIDTH)
        n = len(sets)
    for key in ("heldout_materials", "heldout_pattern"):
        if key in enc and enc[key] is not None:
            check.indices(enc[key], at + key, n)
    weaves = None
    if "weaves_wv" in enc:
        weaves = check.mapping(enc["weaves_wv"], at + "weaves_wv")
        for name, text in weaves.items():
            _check_wv(check, text, f"{at}weaves_wv.{name}")
    if "materials_weave" in enc and enc["materials_weave"] is not None:
        owners = check.strings(enc["materials_weave"], at + "materials_weave", most=MAX_MATERIALS)
        if len(owners) != n:
            check.fail(at + "materials_weave", f"{len(owners)} entries for {n} materials")
        for i, name in enumerate(owners):
            if weaves is None or name not in weaves:
                check.fail(f"{at}materials_weave[{i}]", f"weave {name!r} is not in encoding.weaves_wv")
    if "patterns" in enc:
        check.strings(enc["patterns"], at + "patterns", most=MAX_MATERIALS)
    flags = {key: check.boolean(enc.get(key, default), at + key)
             for key, default in (("half_vector", True), ("residual", False), ("residual_input", False))}
    bins = {key: check.integer(enc.get(key, default), at + key, low, MAX_BINS)
            for key, default, low in (("position_bins", 8, 1), ("size_bins", 8, 1), ("yarn_bins", 0, 0))}
    probe = enc.get("probe_points", 0)
    probe = check.integer(0 if probe is None else probe, at + "probe_points", 0, MAX_PROBE_POINTS)
    if enc.get("highlight_scale") is not None:
        check.number(enc["highlight_scale"], at + "highlight_scale", 0.0, 1e6, open_lo=True)
    if enc.get("output_max") is not None:
        top = enc["output_max"]
        if not isinstance(top, list) or len(top) != n_out:
            check.fail(at + "output_max", f"expected a list of {n_out} numbers (one per component), got {_shown(top)}")
        for i, v in enumerate(top):
            check.number(v, f"{at}output_max[{i}]", -1e6, 1e6)
    if bins["yarn_bins"]:
        extent = check.mapping(enc.get("yarn_extent"), at + "yarn_extent")
        for kind in ("warp", "weft"):
            pair = extent.get(kind)
            if not isinstance(pair, list) or len(pair) != 2:
                check.fail(f"{at}yarn_extent.{kind}", f"expected [half width, half length] (cells), got {_shown(pair)}")
            for i, v in enumerate(pair):
                check.number(v, f"{at}yarn_extent.{kind}[{i}]", 0.0, 1e6, open_lo=True)
        if "weave_wv" not in enc:
            check.fail(at + "weave_wv", "yarn features (encoding.yarn_bins > 0) need the weave's .wv text")
    spatial = 2 * bins["position_bins"] + bins["size_bins"] + n_yarn_features(bins["yarn_bins"])
    if spatial != arch["n_spatial"]:
        check.fail("architecture.n_spatial", f"n_spatial = {arch['n_spatial']}, but the encoding's one-blob bins "
                   f"(2 x {bins['position_bins']} position, {bins['size_bins']} size, yarn {bins['yarn_bins']}) "
                   f"make {spatial}")
    angular = (n_direction_features(flags["half_vector"]) + (n_out if flags["residual_input"] else 0)
               + probe * probe * n_out)
    if angular != arch["n_angular"]:
        check.fail("architecture.n_angular", f"n_angular = {arch['n_angular']}, but the encoding's direction features "
                   f"(half_vector {flags['half_vector']}, residual_input {flags['residual_input']}, probe_points "
                   f"{probe}) make {angular}")
    needs_weave = flags["residual"] or flags["residual_input"] or probe
    if needs_weave and "weave_wv" not in enc and not (weaves and "materials_weave" in enc):
        check.fail(at + "weave_wv", "a residual or probing network needs the weave's .wv text")


def _check_wv(check: _Schema, text, field: str) -> None:
    """A recorded ``.wv`` text must parse (:func:`clothlab.weave.wvformat.parse_wv_text`); its error is given
    at the sidecar's field, with the line of the ``.wv`` text."""
    check.string(text, field, limit=MAX_YAML_BYTES)
    problem = _wv_problem(text)
    if problem is not None:
        check.fail(field, problem)


@functools.lru_cache(maxsize=64)
def _wv_problem(text: str) -> str | None:
    """Why a ``.wv`` text does not parse (None when it does); remembered per text (a sidecar is read by
    config validation and again by the model)."""
    from clothlab.weave.wvformat import parse_wv_text

    try:
        parse_wv_text(text, source="encoding")
    except InputError as exc:
        return f"line {exc.line} of the .wv text" + (f", field {exc.field!r}" if exc.field else "") + f": {exc.detail}"
    return None


def load_surrogate(path) -> tuple[Surrogate, dict]:
    """The surrogate saved at ``path`` (.npz or .json) and its checked sidecar (module docstring); InputError
    naming the file and the field or member if either file is missing, malformed, outside its bounds or does
    not match the other."""
    path = Path(path)
    npz = path.with_suffix(".npz")
    sidecar = read_sidecar(path)
    arch = Architecture(**sidecar["architecture"])
    members = {f"param/{k}": shape for k, shape in parameter_shapes(sidecar["architecture"]).items()}
    members["materials"] = (materials_count(sidecar.get("encoding") or {}), arch.n_material)
    # the largest archive these members make (8-byte values, headers, zip entries): larger files are not read,
    # and the network is allocated only once the archive holds them
    limit = sum(NPY_HEADER_BYTES + 512 + 8 * math.prod(shape) for shape in members.values()) + (1 << 16)
    arrays = read_npz(npz, members, what="surrogate weights", magnitude=MAX_WEIGHT, limit=limit)
    network = SurrogateNetwork(arch, dtype=np.dtype(sidecar.get("dtype", "float32")).type)
    network.set_params({k.removeprefix("param/"): v for k, v in arrays.items() if k.startswith("param/")})
    materials = arrays["materials"].astype(np.float64)
    _check_outputs(network, materials, npz)
    surrogate = Surrogate(network, tuple(sidecar["components"]), materials, dict(sidecar.get("encoding") or {}),
                          float(sidecar.get("k_specular", 100.0)))
    return surrogate, sidecar


def _check_outputs(network: SurrogateNetwork, materials: np.ndarray, path: Path) -> None:
    """InputError naming the weights if the network's latents or outputs are not finite at its materials
    (finite but huge weights overflow float32), on a fixed set of mid-range inputs."""
    a = network.arch
    rows = materials[: min(len(materials), 64)]
    scales = np.array([[1.0], [0.5], [-0.5], [0.25]], dtype=network.dtype)  # 4 direction sets per material
    angular = np.tile(np.linspace(-0.5, 0.9, a.n_angular, dtype=network.dtype) * scales, (len(rows), 1))
    spatial = np.full((len(angular), a.n_spatial), 0.5, dtype=network.dtype)
    with np.errstate(all="ignore"), one_blas_thread():  # tiny products: threads only contend
        z = network.encode(rows)
        finite = bool(np.isfinite(z).all())
        if finite:
            finite = bool(np.isfinite(network.decode(np.repeat(z, len(scales), axis=0), spatial, angular)).all())
    if not finite:
        raise InputError("the network's outputs overflow (not finite) at its own materials: the weights are not a "
                         "trained surrogate's", path=path, field="param")
