"""A trained surrogate answering footprint queries: network + encodings + what its outputs mean.

``Surrogate.query(centre, size, wi, wo, material)`` returns the (N, C) components (1/sr) of footprints of
side ``size`` tiles centred at ``centre`` (tiles) for fabric-frame directions; material latents are encoded
once (Chen, Wang & Wang 2024, sec. 4.3: "only the decoder needs to be evaluated during rendering").
Inference runs in float32 in chunks of ``chunk`` rows (1-2 k rows keep a layer's activations in cache).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clothlab.neural.encodings import BLOB_BINS, direction_features, spatial_features, yarn_features
from clothlab.neural.inference import DecoderPlan
from clothlab.neural.losses import K_SPECULAR, decode_outputs, is_specular
from clothlab.neural.network import SurrogateNetwork

CHUNK = 2048


@dataclass
class Surrogate:
    """``materials``: the encoder inputs (M, n_material) of the materials it was trained on, in order;
    ``encoding``: the input settings recorded in the sidecar (half_vector, parameter names, ...)."""

    network: SurrogateNetwork
    component_names: tuple[str, ...]
    materials: np.ndarray
    encoding: dict = field(default_factory=dict)
    k: float = K_SPECULAR

    def __post_init__(self):
        self._specular = is_specular(self.component_names)
        self._bias = None
        self._plans = {}
        self._weave_cache = None

    @property
    def half_vector(self) -> bool:
        return bool(self.encoding.get("half_vector", True))

    @property
    def position_bins(self) -> int:
        """One-blob bins of each of u, v (8 in the paper; files without the setting have 8)."""
        return int(self.encoding.get("position_bins", BLOB_BINS))

    @property
    def size_bins(self) -> int:
        return int(self.encoding.get("size_bins", BLOB_BINS))

    @property
    def yarn_bins(self) -> int:
        """One-blob bins of the yarn-local coordinates (0: no yarn features; :func:`.yarn_features`)."""
        return int(self.encoding.get("yarn_bins", 0))

    def _weave(self):
        """The weave of the yarn features, parsed once from the ``.wv`` text recorded in the encoding."""
        if self._weave_cache is None:
            from clothlab.weave.wvformat import parse_wv_text

            if "weave_wv" not in self.encoding:
                raise ValueError("yarn features need the weave: encoding['weave_wv'] (the .wv text)")
            self._weave_cache = parse_wv_text(self.encoding["weave_wv"], source="surrogate sidecar")
        return self._weave_cache

    def fusion_biases(self) -> np.ndarray:
        """(M, width) per-material constant of the first fusion layer (computed once)."""
        if self._bias is None:
            self._bias = self.network.fusion_bias(self.network.encode(self.materials))
            self._plans = {}
        return self._bias

    def reset(self) -> None:
        """Forget the cached latents and inference plans (after the weights changed)."""
        self._bias, self._plans = None, {}

    def features(self, centre, size, wi, wo) -> tuple[np.ndarray, np.ndarray]:
        """float32 spatial and direction features of queries."""
        dt = self.network.dtype
        centre = np.atleast_2d(centre)
        spatial = spatial_features(centre, np.atleast_1d(size), self.position_bins, self.size_bins)
        if self.yarn_bins:
            extent = {k: tuple(v) for k, v in self.encoding["yarn_extent"].items()}
            spatial = np.concatenate([spatial, yarn_features(self._weave(), centre, extent, self.yarn_bins)], axis=1)
        return (spatial.astype(dt),
                direction_features(np.atleast_2d(wi), np.atleast_2d(wo), self.half_vector).astype(dt))

    def latent(self, material) -> np.ndarray:
        """z (latent,) of a trained material's row or of an encoder input vector."""
        if isinstance(material, int | np.integer):
            return self.network.encode(self.materials[int(material)][None])[0]
        return self.network.encode(np.asarray(material, dtype=np.float64).reshape(1, -1))[0]

    def query_latent(self, z, centre, size, wi, wo) -> np.ndarray:
        """:meth:`query` with the decoder reading latent ``z`` (latent,) directly (Fig. 8's interpolation)."""
        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        plan = DecoderPlan(self.network, self.network.fusion_bias(np.asarray(z).reshape(1, -1))[0])
        spatial, angular = self.features(centre, size, wi, wo)
        out = np.concatenate([plan(spatial[i:i + CHUNK], angular[i:i + CHUNK]) for i in range(0, len(wi), CHUNK)])
        values = decode_outputs(out.astype(np.float64), self._specular, self.k)
        return np.where(((wi[:, 2] > 0.0) & (wo[:, 2] > 0.0))[:, None], values, 0.0)

    def _plan(self, material) -> DecoderPlan:
        """The decoder plan of material row ``material`` (int, cached) or of an encoder input vector (new)."""
        if not isinstance(material, int | np.integer):
            vector = np.asarray(material, dtype=np.float64).reshape(1, -1)
            return DecoderPlan(self.network, self.network.fusion_bias(self.network.encode(vector))[0])
        plan = self._plans.get(int(material))
        if plan is None:
            plan = self._plans[int(material)] = DecoderPlan(self.network, self.fusion_biases()[material])
        return plan

    def outputs(self, spatial: np.ndarray, angular: np.ndarray, material=0, chunk: int = CHUNK):
        """Raw network outputs (N, C) of prepared features, chunk by chunk; ``material``: a trained
        material's row, or an encoder input vector (n_material,) of another material."""
        plan = self._plan(material)
        n = spatial.shape[0]
        out = np.empty((n, len(self.component_names)), dtype=self.network.dtype)
        for start in range(0, n, chunk):
            stop = min(n, start + chunk)
            out[start:stop] = plan(spatial[start:stop], angular[start:stop])
        return out

    def query(self, centre, size, wi, wo, material=0, chunk: int = CHUNK) -> np.ndarray:
        """(N, C) components (1/sr, float64) of box footprints; back-facing pairs give 0."""
        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        spatial, angular = self.features(centre, size, wi, wo)
        values = decode_outputs(self.outputs(spatial, angular, material, chunk).astype(np.float64), self._specular,
                                self.k)
        front = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
        return np.where(front[:, None], values, 0.0)

    def components(self, centre, size, wi, wo, material=0) -> dict[str, np.ndarray]:
        """:meth:`query` as a dict of components."""
        values = self.query(centre, size, wi, wo, material)
        return {name: values[:, i] for i, name in enumerate(self.component_names)}
