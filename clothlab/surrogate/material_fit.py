"""Fast approximate material fit through a multi-material surrogate (Chen, Wang & Wang 2024, sec. 4.2: the
encoder maps the material to the latent z that the decoder reads).

The material vector m (:func:`clothlab.surrogate.encodings.material_vector`: normalised parameters, then the
pattern descriptor) is the encoder's input.  With encoder and decoder weights fixed, the free parameters'
entries of m (each in [0, 1] between its fit bounds, log-mapped where declared) are fitted to measured
values y (N,) at direction pairs (wi, wo) and one footprint size (the far view by default):

    min over m_free, c >= 0 of  sum_n (sum_k c_k f_k(m; wi_n, wo_n) - y_n)^2

c (the linear coefficients kd, ks_j; eqs. 7-8 of the paper, clothlab's components design) by NNLS at every
step; m_free by Adam on the gradient with c held at its NNLS optimum (at the optimum of the inner problem its
derivative in c vanishes, so this is the gradient of the profile objective), back-propagated through
decoder and encoder by the network's own backward pass (:meth:`SurrogateNetwork.backward`).  Several starts
(a grid over [0, 1]) guard against local minima; the best is returned.  Only meaningful for a network
trained over a range of the free parameters (``clothlab train-surrogate --vary``); a per-fabric network has
seen one material and its encoder does not constrain them.

A residual network (``--residual``) outputs g = T(R(params)) + net(m(params)) (docs/notes/neural-log.md "Residual over
the reflectance model"): the gradient then also has the term dT(R)/dx, by central finite differences of the
exact model R (cheap next to the network's backward pass) in x, the parameter's normalised internal
coordinate.  Decoder inputs that depend on the material (T(R) with ``--residual-input``, the texture probe
with ``--probe-points``) enter the same way: their finite differences times the network's gradient with
respect to its inputs (:meth:`SurrogateNetwork.backward` with ``inputs=True``).  :func:`refine_material`
then fits the exact model from the fast fit's result.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

from clothlab.surrogate.losses import decode_outputs


@dataclass
class MaterialFit:
    """``params``: the fitted free parameters (declared units); ``unit``: their m entries; ``coefficients``
    (C,) by component; ``rms``: root-mean-square residual; ``steps``: Adam steps over all starts; ``fast``:
    the fast fit's results when an exact refinement replaced them."""

    params: dict
    unit: dict
    coefficients: dict
    rms: float
    steps: int
    fast: dict | None = None  # after an exact refinement: the fast fit's params, coefficients and rms


def _design(surrogate, m: np.ndarray, spatial, angular, train: bool, t_reference=None):
    """Components (N, C) at material vector m, and the loss-space values g they were decoded from (g = the
    network's outputs, + T(R) for a residual network)."""
    net = surrogate.network
    index = np.zeros(spatial.shape[0], dtype=np.int64)
    g = net.forward(m[None].astype(net.dtype), index, spatial, angular, train=train,
                    latent_box=surrogate.latent_box).astype(np.float64)
    if t_reference is not None and surrogate.residual:
        g = g + t_reference
    return decode_outputs(g, surrogate._specular, surrogate.k), g


class MaterialObjective:
    """The profile objective F(x) = min over c >= 0 of mean_n (sum_k c_k f_k(x; wi_n, wo_n) - y_n)^2 of the
    free entries x of the material vector (module docstring), and its gradient.

    Terms that depend on x outside the network, each differentiated by central finite differences of step
    ``step`` in x (x is affine in each parameter's internal, possibly log, coordinate; one-sided at the bounds
    0 and 1), times the network's gradient with respect to them:

    - ``reference``: a callable x -> R (N, C) of the exact model at the parameters of x, for a residual network
      (g = T(R) + net, docs/notes/neural-log.md "Residual over the reflectance model") and for one that reads T(R) as a
      decoder input (``--residual-input``);
    - ``probe``: a callable x -> the texture probe's values (N, n^2 C) at the parameters of x, for a network
      that reads the probe as a decoder input (``--probe-points``; docs/notes/neural-log.md "Texture probe")."""

    def __init__(self, surrogate, wi, wo, values, base_vector: np.ndarray, free_index: dict, *, size: float = 4.5,
                 reference=None, probe=None, step: float = 1e-4):
        if (surrogate.residual or surrogate.residual_input) and reference is None:
            raise ValueError("a network over the reflectance model (--residual, --residual-input) needs "
                             "`reference`: the exact model's values at trial parameters")
        if surrogate.probe_points and probe is None:
            raise ValueError("a probing network (--probe-points) needs `probe`: the texture probe's values at "
                             "trial parameters")
        self.surrogate, self.step = surrogate, float(step)
        self.reference = reference if (surrogate.residual or surrogate.residual_input) else None
        self.probe = probe if surrogate.probe_points else None
        self.wi, self.wo = np.atleast_2d(wi), np.atleast_2d(wo)
        self.y = np.asarray(values, dtype=np.float64).reshape(-1)
        n = self.y.size
        self.centre, self.size = np.full((n, 2), 0.5), np.full(n, size)
        self.names = list(free_index)
        self.pos = np.array([free_index[k] for k in self.names], dtype=np.int64)
        self.base = np.array(base_vector, dtype=np.float64)
        self.spatial = self.angular = None  # fixed unless the decoder reads x-dependent inputs
        if not (surrogate.residual_input or surrogate.probe_points):
            self.spatial, self.angular = surrogate.features(self.centre, self.size, self.wi, self.wo)

    def _vector(self, x) -> np.ndarray:
        m = self.base.copy()
        m[self.pos] = x
        return m

    def _inputs(self, x):
        """(T(R) (N, C) or None, T(probe) (N, n^2 C) or None) at x: the x-dependent terms of the network."""
        x = np.asarray(x, dtype=np.float64)
        args = (self.centre, self.size, self.wi, self.wo)
        t_ref = None if self.reference is None else self.surrogate.transformed_reference(
            *args, material=None, reference=np.asarray(self.reference(x), dtype=np.float64))
        t_probe = None if self.probe is None else self.surrogate.transformed_probe(
            *args, material=None, probe=np.asarray(self.probe(x), dtype=np.float64))
        return t_ref, t_probe

    def _features(self, t_ref, t_probe):
        if self.angular is not None:
            return self.spatial, self.angular
        return self.surrogate.features(self.centre, self.size, self.wi, self.wo, t_ref, t_probe)

    def solve(self, x) -> tuple[float, np.ndarray, np.ndarray]:
        """(F(x), NNLS coefficients (C,), components (N, C)) without gradient."""
        t_ref, t_probe = self._inputs(x)
        spatial, angular = self._features(t_ref, t_probe)
        comps, _ = _design(self.surrogate, self._vector(x), spatial, angular, False, t_ref)
        c, res = nnls(comps, self.y)
        return float(res ** 2 / self.y.size), c, comps

    def __call__(self, x) -> float:
        return self.solve(x)[0]

    def value_and_gradient(self, x) -> tuple[float, np.ndarray]:
        """F(x) and dF/dx (c held at its NNLS optimum: the profile objective's gradient, envelope theorem):
        back-propagated through decoder and encoder, plus the x-dependent terms (T(R), the probe) by their
        finite differences times their gradient (the residual's d g, the network's d input)."""
        x = np.asarray(x, dtype=np.float64)
        sur, n = self.surrogate, self.y.size
        t_ref, t_probe = self._inputs(x)
        spatial, angular = self._features(t_ref, t_probe)
        comps, g = _design(sur, self._vector(x), spatial, angular, True, t_ref)
        c, res = nnls(comps, self.y)
        r = comps @ c - self.y
        d_comp = 2.0 * r[:, None] * c[None, :] / n
        # d comp / d g: exp(g) / k where the specular decoding (exp(g) - 1) / k is positive, 1 for diffuse
        d_g = np.where(sur._specular, d_comp * np.exp(g) / sur.k * (g > 0.0), d_comp)
        d_material, _, d_angular = sur.network.backward(d_g.astype(sur.network.dtype), inputs=True)
        grad = d_material[0, self.pos].astype(np.float64)
        if t_ref is None and t_probe is None:
            return float(res ** 2 / n), grad
        # the decoder's x-dependent inputs are the last columns of the angular features: T(R), then T(probe)
        d_angular = d_angular.astype(np.float64)
        n_probe = 0 if t_probe is None else t_probe.shape[1]
        n_ref = t_ref.shape[1] if sur.residual_input else 0
        first = d_angular.shape[1] - n_probe - n_ref
        d_ref = (d_g if sur.residual else 0.0) + (d_angular[:, first:first + n_ref] if n_ref else 0.0)
        d_probe = d_angular[:, first + n_ref:]
        for j in range(x.size):
            lo, hi = max(0.0, x[j] - self.step), min(1.0, x[j] + self.step)
            xl, xh = x.copy(), x.copy()
            xl[j], xh[j] = lo, hi
            (ref_h, probe_h), (ref_l, probe_l) = self._inputs(xh), self._inputs(xl)
            if t_ref is not None:
                grad[j] += float(np.sum(d_ref * (ref_h - ref_l))) / (hi - lo)
            if t_probe is not None:
                grad[j] += float(np.sum(d_probe * (probe_h - probe_l))) / (hi - lo)
        return float(res ** 2 / n), grad


def fit_material(objective: MaterialObjective, *, steps: int = 150, lr: float = 0.05, starts: int = 3) -> MaterialFit:
    """Minimise ``objective`` (:class:`MaterialObjective`) over its free entries in [0, 1] by projected Adam
    from a grid of ``starts`` values per free entry; the best end point is returned."""
    grid = (np.arange(starts) + 0.5) / starts
    best, total = None, 0
    for start in itertools.product(grid, repeat=len(objective.names)):
        x = np.array(start, dtype=np.float64)
        m1, m2 = np.zeros_like(x), np.zeros_like(x)
        for t in range(1, steps + 1):
            _, g = objective.value_and_gradient(x)
            m1 = 0.9 * m1 + 0.1 * g  # Adam (bias-corrected), projected onto [0, 1]
            m2 = 0.999 * m2 + 0.001 * g * g
            x = np.clip(x - lr * (m1 / (1 - 0.9 ** t)) / (np.sqrt(m2 / (1 - 0.999 ** t)) + 1e-12), 0.0, 1.0)
        total += steps
        value, c, _ = objective.solve(x)
        if best is None or value < best[0]:
            best = (value, x.copy(), c)
    value, x, c = best
    return MaterialFit(params={}, unit=dict(zip(objective.names, x.tolist(), strict=True)),
                       coefficients=dict(zip(objective.surrogate.component_names, c.tolist(), strict=True)),
                       rms=float(np.sqrt(value)), steps=total)


def unit_to_parameter(spec, t: float) -> float:
    """The parameter value (declared unit) at normalised coordinate t of ``spec`` (inverse of
    :func:`clothlab.surrogate.encodings.normalised_parameters`)."""
    lo, hi = (float(spec.to_internal(b)) for b in spec.bounds)
    return float(spec.from_internal(lo + t * (hi - lo)))


def refine_material(model, wi, wo, values, params: dict, free, *, max_nfev: int = 60) -> tuple[dict, dict, float]:
    """Refine the ``free`` parameters with the exact ``model`` (its far view, ``model.components``) from
    ``params`` (e.g. the fast fit's): bounded least squares (scipy ``least_squares``, trust-region
    reflective) in the normalised coordinates, coefficients by NNLS at every evaluation.  Returns (parameters,
    coefficients by component, RMS residual)."""
    from scipy.optimize import least_squares

    from clothlab.surrogate.encodings import normalised_parameters

    y = np.asarray(values, dtype=np.float64).reshape(-1)
    free = list(free)
    table = model.params

    def design(x):
        p = {**params, **{k: unit_to_parameter(table[k], t) for k, t in zip(free, x, strict=True)}}
        comps = model.components(wi, wo, p, warn=False)
        return np.column_stack([np.asarray(comps[c]).reshape(-1) for c in model.component_names]), p

    def residual(x):
        a, _ = design(x)
        c, _ = nnls(a, y)
        return a @ c - y

    x0 = np.clip(normalised_parameters(params, table, free), 1e-6, 1 - 1e-6)
    result = least_squares(residual, x0, bounds=(0.0, 1.0), max_nfev=max_nfev, diff_step=1e-4)
    a, p = design(result.x)
    c, res = nnls(a, y)
    return p, dict(zip(model.component_names, c.tolist(), strict=True)), float(res / np.sqrt(y.size))
