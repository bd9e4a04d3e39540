"""The surrogate's architecture (Chen, Wang & Wang 2024, sec. 4.2, Fig. 3), forward and backward.

    encoder   m (material vector) -> lrelu FC(enc_width) -> residual block (2 x FC enc_width) -> FC -> z
    fusion    [z, one-blob(u, v, size)] -> lrelu FC(width) -> lrelu FC(spatial)    ("two FC layers")
    angular   [spatial feature, direction features] -> lrelu FC(width) -> residual block (2 x FC width)
              -> lrelu FC(width) -> FC(n_out)              ("five FC layers with one skip connection")

The encoder runs once per material (the M rows of ``material``); each query row names its material by
``index``.  At inference the latent part of the first fusion layer (z W_z + b) is a per-material constant
(:meth:`SurrogateNetwork.fusion_bias`), so a query costs only the decoder
(:class:`clothlab.surrogate.inference.DecoderPlan`).  The paper does not state the decoder widths; ``width`` /
``spatial`` are chosen by measurement (docs/notes/neural-log.md).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from clothlab.surrogate.layers import Dense, DenseAct, Residual


@dataclass(frozen=True)
class Architecture:
    """Input sizes and layer widths.  ``n_material``: material vector length; ``n_spatial``: one-blob
    channels; ``n_angular``: direction features; ``n_out``: components."""

    n_material: int
    n_spatial: int
    n_angular: int
    n_out: int
    enc_width: int = 128
    latent: int = 64
    width: int = 64
    spatial: int = 32

    def to_dict(self) -> dict:
        return asdict(self)

    def decoder_flops(self) -> int:
        """Multiply-adds x 2 of one decoder query (the latent term precomputed)."""
        w, s = self.width, self.spatial
        macs = self.n_spatial * w + w * s + (s + self.n_angular) * w + 3 * w * w + w * self.n_out
        return 2 * macs


class SurrogateNetwork:
    """The encoder / decoder network of ``arch``; parameters in ``dtype`` (float32 to train and run)."""

    def __init__(self, arch: Architecture, seed: int = 0, dtype=np.float32):
        self.arch = arch
        rng = np.random.default_rng(seed)
        a = arch
        self.layers = {
            "enc_in": DenseAct(a.n_material, a.enc_width, rng, dtype),
            "enc_res": Residual(a.enc_width, rng, dtype),
            "enc_out": Dense(a.enc_width, a.latent, rng, dtype),
            "fuse1": DenseAct(a.latent + a.n_spatial, a.width, rng, dtype),
            "fuse2": DenseAct(a.width, a.spatial, rng, dtype),
            "ang1": DenseAct(a.spatial + a.n_angular, a.width, rng, dtype),
            "ang_res": Residual(a.width, rng, dtype),
            "ang4": DenseAct(a.width, a.width, rng, dtype),
            "ang5": Dense(a.width, a.n_out, rng, dtype),
        }
        self._cache = None

    # ------------------------------------------------------------------ parameters

    @property
    def dtype(self):
        return self.layers["ang5"].params["W"].dtype

    def params(self) -> dict[str, np.ndarray]:
        """Every parameter tensor by name (``layer.param``); the arrays themselves (updates act in place)."""
        return {f"{name}.{k}": v for name, layer in self.layers.items() for k, v in layer.params.items()}

    def grads(self) -> dict[str, np.ndarray]:
        """The gradients of the last :meth:`backward`, named as :meth:`params`."""
        return {f"{name}.{k}": v for name, layer in self.layers.items() for k, v in layer.grads.items()}

    def set_params(self, values: dict[str, np.ndarray]) -> None:
        """Copy ``values`` (all names of :meth:`params`, same shapes) into the parameters."""
        params = self.params()
        missing = set(params) - set(values)
        if missing:
            raise ValueError(f"missing parameter tensors: {', '.join(sorted(missing))}")
        for name, target in params.items():
            value = np.asarray(values[name])
            if value.shape != target.shape:
                raise ValueError(f"parameter {name}: shape {value.shape}, expected {target.shape}")
            target[...] = value

    def n_parameters(self, decoder_only: bool = False) -> int:
        return sum(v.size for k, v in self.params().items() if not (decoder_only and k.startswith("enc")))

    # ------------------------------------------------------------------ forward / backward

    def encode(self, material: np.ndarray, train: bool = False) -> np.ndarray:
        """Latent vectors z (M, latent) of material vectors (M, n_material)."""
        L = self.layers
        x = np.asarray(material, dtype=self.dtype)
        return L["enc_out"].forward(L["enc_res"].forward(L["enc_in"].forward(x, train), train), train)

    def decode(self, z_rows: np.ndarray, spatial: np.ndarray, angular: np.ndarray, train: bool = False):
        """Network outputs (B, n_out) of per-row latents (B, latent), one-blob (B, n_spatial), directions."""
        L = self.layers
        feature = L["fuse2"].forward(L["fuse1"].forward(np.concatenate([z_rows, spatial], axis=1), train), train)
        x = L["ang1"].forward(np.concatenate([feature, angular], axis=1), train)
        return L["ang5"].forward(L["ang4"].forward(L["ang_res"].forward(x, train), train), train)

    def forward(self, material, index, spatial, angular, train: bool = False, latent_box=None) -> np.ndarray:
        """Outputs (B, n_out): ``material`` (M, n_material), ``index`` (B,) into it, ``spatial``, ``angular``;
        ``latent_box``: (lo, hi) (latent,) that z is clipped to (:meth:`Surrogate.latent_box`; the backward
        pass then passes no gradient through a clipped entry)."""
        dt = self.dtype
        z = self.encode(material, train)
        inside = None
        if latent_box is not None:
            lo, hi = latent_box
            inside = (z >= lo) & (z <= hi)
            z = np.clip(z, lo, hi).astype(dt)
        index = np.asarray(index, dtype=np.int64)
        if train:
            self._cache = (index, z.shape[0], inside)
        return self.decode(z[index], np.asarray(spatial, dtype=dt), np.asarray(angular, dtype=dt), train)

    def backward(self, d_out: np.ndarray, inputs: bool = False):
        """Gradients of a scalar loss with d loss / d output = ``d_out`` (B, n_out), after a training forward;
        returns d loss / d material vectors (M, n_material) (the fast material fit uses it), and with
        ``inputs`` also d loss / d the query inputs: (d material, d spatial (B, n_spatial), d angular (B,
        n_angular))."""
        L = self.layers
        index, n_materials, inside = self._cache
        d = L["ang1"].backward(L["ang_res"].backward(L["ang4"].backward(L["ang5"].backward(d_out))))
        d_fused = L["fuse1"].backward(L["fuse2"].backward(d[:, :self.arch.spatial]))
        d_z_rows = d_fused[:, :self.arch.latent]
        d_z = np.zeros((n_materials, self.arch.latent), dtype=d_z_rows.dtype)
        np.add.at(d_z, index, d_z_rows)
        if inside is not None:
            d_z *= inside
        d_material = L["enc_in"].backward(L["enc_res"].backward(L["enc_out"].backward(d_z)))
        if inputs:
            return d_material, d_fused[:, self.arch.latent:], d[:, self.arch.spatial:]
        return d_material

    # ------------------------------------------------------------------ inference

    def fusion_bias(self, z: np.ndarray) -> np.ndarray:
        """z W_z + b of the first fusion layer (M, width): the per-material part of every query."""
        p = self.layers["fuse1"].params
        return np.asarray(z, dtype=self.dtype) @ p["W"][:self.arch.latent] + p["b"]
