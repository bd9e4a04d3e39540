"""A trained surrogate answering footprint queries: network + encodings + what its outputs mean.

``Surrogate.query(centre, size, wi, wo, material)`` returns the (N, C) components (1/sr) of footprints of
side ``size`` tiles centred at ``centre`` (tiles) for fabric-frame directions; material latents are encoded
once (Chen, Wang & Wang 2024, sec. 4.3: "only the decoder needs to be evaluated during rendering").
Inference runs in float32 in chunks of ``chunk`` rows (1-2 k rows keep a layer's activations in cache).

Residual over the reflectance model (``encoding["residual"]``, issue 10 build item 2; not in the paper):
the reflectance model R(wi, wo) is exactly the whole-tile footprint average (the texture-average =
reflectance identity of Irawan & Marschner 2012), so the network predicts a correction in the loss space
of eqs. 9-11: g_c = T_c(R_c(wi, wo)) + net_c, T_c(x) = ln(k x + 1) for specular components and x for
diffuse (:func:`clothlab.surrogate.losses.encode_targets`).  ``encoding["residual_input"]`` also appends
T(R) to the direction features.  R comes from ``references`` (one label source per trained material, e.g.
:class:`clothlab.surrogate.labels.ModelLabels`; attached by the caller, this package does not build models)
or, for another material, from the ``reference`` values handed to :meth:`Surrogate.query`.

Texture probe (``encoding["probe_points"]`` = n > 0; not in the paper): T of the noise-free texture at the
n x n midpoints of the footprint (:class:`clothlab.surrogate.labels.TextureProbe`) is appended to the direction
features.  It tells the decoder where the yarn highlights lie in the footprint, which the position one-blob
of 8 bins cannot resolve below ~0.12 tile (docs/notes/neural-log.md, "Texture probe").  The values come from
``probes`` (one per trained material, attached by the caller) or from ``probe`` handed to :meth:`query`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clothlab.surrogate.encodings import BLOB_BINS, direction_features, spatial_features, yarn_features
from clothlab.surrogate.inference import DecoderPlan
from clothlab.surrogate.losses import K_SPECULAR, decode_outputs, encode_targets, is_specular
from clothlab.surrogate.network import SurrogateNetwork
from clothlab.surrogate.threads import one_blas_thread

CHUNK = 2048
OUTPUT_MARGIN = float(np.log(2.0))  # loss-space margin of the output cap above the largest training target
LATENT_MARGIN = 0.1  # share of each latent entry's trained range added on both sides of the latent box


@dataclass
class Surrogate:
    """``materials``: the encoder inputs (M, n_material) of the materials it was trained on, in order;
    ``encoding``: the input settings recorded in the sidecar (half_vector, parameter names, ...)."""

    network: SurrogateNetwork
    component_names: tuple[str, ...]
    materials: np.ndarray
    encoding: dict = field(default_factory=dict)
    k: float = K_SPECULAR
    references: list | None = None  # per trained material: (wi, wo, centre, size) -> (N, C) R (residual only)
    probes: list | None = None  # per trained material: (wi, wo, centre, size) -> (N, n^2 C) texture (probe only)

    def __post_init__(self):
        self._specular = is_specular(self.component_names)
        self._bias = None
        self._plans = {}
        self._box = None
        self._weave_cache = None
        self._yarn_tables = None

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

    @property
    def residual(self) -> bool:
        """The outputs are corrections over T(R) (module docstring; files without the setting: False)."""
        return bool(self.encoding.get("residual", False))

    @property
    def residual_input(self) -> bool:
        """T(R) is also an input of the angular decoder (files without the setting: False)."""
        return bool(self.encoding.get("residual_input", False))

    @property
    def probe_points(self) -> int:
        """Texture probe points per side (0: no probe; files without the setting have none)."""
        return int(self.encoding.get("probe_points", 0) or 0)

    def transformed_probe(self, centre, size, wi, wo, material=0, probe=None) -> np.ndarray | None:
        """T of the texture probe (N, n^2 C) float64 (None without a probe): ``probe`` (N, n^2 C) texture values
        (1/sr) if given, else ``probes[material]`` of a trained row."""
        n = self.probe_points
        if not n:
            return None
        if probe is None:
            if not isinstance(material, int | np.integer) or not self.probes:
                raise ValueError("this surrogate reads a texture probe: attach `probes` "
                                 "(clothlab.models.neural.model.load_neural) or pass the texture's values as `probe`")
            probe = self.probes[int(material)](np.atleast_2d(wi), np.atleast_2d(wo), np.atleast_2d(centre),
                                               np.atleast_1d(size))
        return encode_targets(np.asarray(probe, dtype=np.float64), np.tile(self._specular, n * n), self.k)

    def transformed_reference(self, centre, size, wi, wo, material=0, reference=None) -> np.ndarray | None:
        """T(R) (N, C) float64 of the reflectance model for the queries (None when the network uses no
        R): ``reference`` (N, C) R values (1/sr) if given, else ``references[material]`` of a trained row."""
        if not (self.residual or self.residual_input):
            return None
        if reference is None:
            if not isinstance(material, int | np.integer) or not self.references:
                raise ValueError("this surrogate is a residual over the reflectance model: attach `references` "
                                 "(clothlab.models.neural.model.load_neural) or pass the model's values as "
                                 "`reference`")
            reference = self.references[int(material)](np.atleast_2d(wi), np.atleast_2d(wo), np.atleast_2d(centre),
                                                       np.atleast_1d(size))
        return encode_targets(np.asarray(reference, dtype=np.float64), self._specular, self.k)

    def _weave(self):
        """The weave of the yarn features, parsed once from the ``.wv`` text recorded in the encoding."""
        if self._weave_cache is None:
            from clothlab.weave.wvformat import parse_wv_text

            if "weave_wv" not in self.encoding:
                raise ValueError("yarn features need the weave: encoding['weave_wv'] (the .wv text)")
            self._weave_cache = parse_wv_text(self.encoding["weave_wv"], source="surrogate sidecar")
        return self._weave_cache

    def trained_rows(self) -> np.ndarray:
        """Indices of the materials the network was trained on (all rows but ``encoding["heldout_materials"]``
        and ``encoding["heldout_pattern"]``)."""
        held = set(self.encoding.get("heldout_materials") or ()) | set(self.encoding.get("heldout_pattern") or ())
        return np.array([m for m in range(self.materials.shape[0]) if m not in held], dtype=np.int64)

    @property
    def latent_box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, hi) (latent,) of a multi-material network (>= 2 trained materials; None otherwise): per entry
        the range of the trained materials' latents widened by :data:`LATENT_MARGIN` of it on both sides.  The
        latent of any other material (a held-out row, an encoder input vector) is clipped to it: after long
        training the encoder can send a material between trained ones far outside their latents (a norm of 50
        against at most 3 for the trained ones, measured), where the decoder was never trained; clipped, it
        stays among them (docs/notes/neural-log.md, "Latent box").  A one-material network's encoder says nothing about
        other materials and is left as it is."""
        if self._box is None:
            rows = self.trained_rows()
            if rows.size < 2:
                self._box = False
            else:
                z = self.network.encode(self.materials[rows]).astype(np.float64)
                lo, hi = z.min(axis=0), z.max(axis=0)
                pad = LATENT_MARGIN * (hi - lo)
                self._box = (lo - pad, hi + pad)
        return self._box or None

    def clip_latent(self, z: np.ndarray) -> np.ndarray:
        """Latents (..., latent) clipped to :attr:`latent_box` (unchanged without one), in the network's dtype."""
        box = self.latent_box
        z = z if box is None else np.clip(z, box[0], box[1])
        return np.asarray(z, dtype=self.network.dtype)

    def fusion_biases(self) -> np.ndarray:
        """(M, width) per-material constant of the first fusion layer (computed once; latents of held-out rows
        clipped to :attr:`latent_box`)."""
        if self._bias is None:
            self._bias = self.network.fusion_bias(self.clip_latent(self.network.encode(self.materials)))
            self._plans = {}
        return self._bias

    def reset(self) -> None:
        """Forget the cached latents, latent box and inference plans (after the weights changed)."""
        self._bias, self._plans, self._box = None, {}, None

    def features(self, centre, size, wi, wo, t_reference=None, t_probe=None) -> tuple[np.ndarray, np.ndarray]:
        """float32 spatial and direction features of queries (``t_reference``: T(R) (N, C), appended to the
        direction features when ``residual_input``; ``t_probe``: T of the texture probe, appended after it)."""
        dt = self.network.dtype
        spatial, angular = self._base_features(centre, size, wi, wo)
        if self.residual_input:
            if t_reference is None:
                raise ValueError("this network reads T(R) as an input: give t_reference")
            angular = np.concatenate([angular, t_reference], axis=1)
        if self.probe_points:
            if t_probe is None:
                raise ValueError("this network reads a texture probe as an input: give t_probe")
            angular = np.concatenate([angular, t_probe], axis=1)
        return spatial.astype(dt, copy=False), angular.astype(dt, copy=False)

    def _base_features(self, centre, size, wi, wo) -> tuple[np.ndarray, np.ndarray]:
        """Spatial (one-blob position and size, yarn features) and direction features in the network's dtype:
        one compiled pass (:mod:`clothlab.surrogate.fast_features`; the values of :meth:`reference_features`)."""
        from clothlab.surrogate.fast_features import features, yarn_tables

        if self.yarn_bins and self._yarn_tables is None:
            extent = {k: tuple(v) for k, v in self.encoding["yarn_extent"].items()}
            self._yarn_tables = yarn_tables(self._weave(), extent)
        return features(centre, size, wi, wo, self.position_bins, self.size_bins, self.yarn_bins, self.half_vector,
                        self._yarn_tables, self.network.dtype)

    def reference_features(self, centre, size, wi, wo) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_base_features` by the numpy encodings (float64, then the network's dtype): the definition
        the compiled pass is tested against."""
        dt = self.network.dtype
        centre = np.atleast_2d(centre)
        spatial = spatial_features(centre, np.atleast_1d(size), self.position_bins, self.size_bins)
        if self.yarn_bins:
            extent = {k: tuple(v) for k, v in self.encoding["yarn_extent"].items()}
            spatial = np.concatenate([spatial, yarn_features(self._weave(), centre, extent, self.yarn_bins)], axis=1)
        angular = direction_features(np.atleast_2d(wi), np.atleast_2d(wo), self.half_vector)
        return spatial.astype(dt), angular.astype(dt)

    def latent(self, material) -> np.ndarray:
        """z (latent,) of a trained material's row or of an encoder input vector."""
        if isinstance(material, int | np.integer):
            return self.clip_latent(self.network.encode(self.materials[int(material)][None]))[0]
        return self.clip_latent(self.network.encode(np.asarray(material, dtype=np.float64).reshape(1, -1)))[0]

    def query_latent(self, z, centre, size, wi, wo, reference=None, probe=None) -> np.ndarray:
        """:meth:`query` with the decoder reading latent ``z`` (latent,) directly (Fig. 8's interpolation);
        a residual network needs the ``reference`` values (N, C) of the material meant, a probing one its
        ``probe`` values."""
        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        plan = DecoderPlan(self.network, self.network.fusion_bias(np.asarray(z).reshape(1, -1))[0])
        t_ref = self.transformed_reference(centre, size, wi, wo, material=None, reference=reference)
        t_probe = self.transformed_probe(centre, size, wi, wo, material=None, probe=probe)
        spatial, angular = self.features(centre, size, wi, wo, t_ref, t_probe)
        out = np.concatenate([plan(spatial[i:i + CHUNK], angular[i:i + CHUNK]) for i in range(0, len(wi), CHUNK)])
        return self._values(out, t_ref, wi, wo)

    @property
    def output_cap(self) -> np.ndarray | None:
        """(C,) upper bound of the loss-space outputs g (``encoding["output_max"]``: the largest T(label) of
        the training rows per component, recorded by :func:`clothlab.surrogate.training.train`) plus ln 2, i.e.
        about twice the largest training label; None for files without it (no cap)."""
        top = self.encoding.get("output_max")
        return None if top is None else np.asarray(top, dtype=np.float64) + OUTPUT_MARGIN

    def _values(self, out: np.ndarray, t_reference, wi, wo) -> np.ndarray:
        """Components (N, C) float64 from raw outputs: + T(R) when residual, capped (:attr:`output_cap`: an
        input far outside the training data must not exponentiate to 1e9), decoded (eq. 9 inverted), 0 for
        back-facing pairs."""
        g = out.astype(np.float64)
        if self.residual:
            g += t_reference
        cap = self.output_cap
        if cap is not None:
            g = np.minimum(g, cap)
        values = decode_outputs(g, self._specular, self.k)
        return np.where(((wi[:, 2] > 0.0) & (wo[:, 2] > 0.0))[:, None], values, 0.0)

    def _plan(self, material) -> DecoderPlan:
        """The decoder plan of material row ``material`` (int, cached) or of an encoder input vector (new)."""
        if not isinstance(material, int | np.integer):
            vector = np.asarray(material, dtype=np.float64).reshape(1, -1)
            return DecoderPlan(self.network, self.network.fusion_bias(self.clip_latent(self.network.encode(vector)))[0])
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
        with one_blas_thread():
            for start in range(0, n, chunk):
                stop = min(n, start + chunk)
                out[start:stop] = plan(spatial[start:stop], angular[start:stop])
        return out

    def query(self, centre, size, wi, wo, material=0, chunk: int = CHUNK, reference=None, probe=None) -> np.ndarray:
        """(N, C) components (1/sr, float64) of box footprints; back-facing pairs give 0.  ``reference``:
        the reflectance model's (N, C) values for a residual network queried at a material vector; ``probe``:
        the texture probe's values (N, n^2 C) for a probing network queried at a material vector."""
        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        t_ref = self.transformed_reference(centre, size, wi, wo, material, reference)
        t_probe = self.transformed_probe(centre, size, wi, wo, material, probe)
        spatial, angular = self.features(centre, size, wi, wo, t_ref, t_probe)
        return self._values(self.outputs(spatial, angular, material, chunk), t_ref, wi, wo)

    def components(self, centre, size, wi, wo, material=0, reference=None, probe=None) -> dict[str, np.ndarray]:
        """:meth:`query` as a dict of components."""
        values = self.query(centre, size, wi, wo, material, reference=reference, probe=probe)
        return {name: values[:, i] for i, name in enumerate(self.component_names)}
