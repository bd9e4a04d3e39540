"""Saving and loading a surrogate: ``NAME.npz`` (the parameter tensors and material vectors; no pickle) and
``NAME.json`` beside it (architecture, encodings, components, data hash, metrics).  Both written atomically."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import InputError
from clothlab.neural.network import Architecture, SurrogateNetwork
from clothlab.neural.surrogate import Surrogate

FORMAT = "clothlab-neural-surrogate/1"


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


def load_surrogate(path) -> tuple[Surrogate, dict]:
    """The surrogate saved at ``path`` (.npz or .json) and its sidecar; InputError naming the file if it is
    missing, of another format or does not match its sidecar."""
    path = Path(path)
    npz, sidecar_path = path.with_suffix(".npz"), path.with_suffix(".json")
    for p in (npz, sidecar_path):
        if not p.exists():
            raise InputError("surrogate file not found", path=p)
    try:
        sidecar = json.loads(sidecar_path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON ({exc.msg})", path=sidecar_path, line=exc.lineno) from None
    if sidecar.get("format") != FORMAT:
        raise InputError(f"format {sidecar.get('format')!r}, expected {FORMAT!r}", path=sidecar_path, field="format")
    try:
        arch = Architecture(**sidecar["architecture"])
        network = SurrogateNetwork(arch, dtype=np.dtype(sidecar.get("dtype", "float32")).type)
        with np.load(npz, allow_pickle=False) as data:
            network.set_params({k.removeprefix("param/"): data[k] for k in data.files if k.startswith("param/")})
            materials = data["materials"]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"weights do not match the sidecar's architecture: {exc}", path=npz) from None
    surrogate = Surrogate(network, tuple(sidecar["components"]), materials, dict(sidecar.get("encoding", {})),
                          float(sidecar.get("k_specular", 100.0)))
    return surrogate, sidecar
