"""Correctness checks of the plugin the renderer's way (docs/mitsuba.md "Correctness"): Mitsuba's chi-square
test of the sampler (:func:`chi2_check`), weight = eval / pdf (:func:`weight_check`), the white furnace
(:func:`furnace_check`) and reciprocity (:func:`reciprocity_check`).  They need a JIT variant (``llvm_ad_rgb``;
Mitsuba's chi-square test runs on Dr.Jit arrays): call :func:`clothlab.mitsuba.use_variant` first.
"""

from __future__ import annotations

import math

import numpy as np


def direction(theta_deg: float, phi_deg: float) -> list[float]:
    """The unit vector at polar angle theta, azimuth phi (deg) of Mitsuba's local frame (= the fabric frame at
    warp angle 0)."""
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]


def plugin_dict(**props) -> dict:
    """A ``type: clothlab`` plugin dict with ``props`` (fit=..., preset=..., kind=..., lod=...)."""
    return {"type": "clothlab", **{k: v for k, v in props.items() if v is not None}}


def chi2_check(bsdf: dict, theta_deg: float, phi_deg: float = 17.0, *, sample_count: int = 200_000,
               seed: int = 0, uv=(0.37, 0.61), test_count: int = 1) -> dict:
    """Mitsuba's chi-square goodness-of-fit test (``mitsuba.chi2.ChiSquareTest`` with its ``BSDFAdapter``) of
    the plugin's ``sample`` against its ``pdf`` at the incident direction (theta, phi) and texture point ``uv``
    (the adapter drops samples of weight 0; at uv = (0.5, 0.5), a cell corner, kind surface's texture is 0):
    {passed, p_value, messages}; significance 1 % over ``test_count`` tests (Mitsuba's Sidak correction)."""
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    sample, pdf = BSDFAdapter("clothlab", bsdf, wi=direction(theta_deg, phi_deg), uv=list(uv))
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3,
                         sample_count=int(sample_count), seed=int(seed))
    passed = bool(test.run(significance_level=0.01, test_count=int(test_count), quiet=True))
    return {"passed": passed, "p_value": float(test.p_value) if test.p_value is not None else float("nan"),
            "theta_deg": float(theta_deg), "phi_deg": float(phi_deg), "sample_count": int(sample_count),
            "messages": test.messages.strip()}


def _si(n: int, wi, uv=(0.37, 0.61)):
    import drjit as dr
    import mitsuba as mi

    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*[mi.Float(np.full(n, c)) for c in wi]) if np.ndim(wi) == 1 else \
        mi.Vector3f(mi.Float(wi[:, 0]), mi.Float(wi[:, 1]), mi.Float(wi[:, 2]))
    si.uv = mi.Point2f(float(uv[0]), float(uv[1]))
    return si


def _vec(a):
    import mitsuba as mi

    return mi.Vector3f(mi.Float(a[:, 0]), mi.Float(a[:, 1]), mi.Float(a[:, 2]))


def _rgb(x) -> np.ndarray:
    return np.asarray(x.numpy(), dtype=np.float64).reshape(3, -1).T


def weight_check(bsdf: dict, theta_deg: float, phi_deg: float = 17.0, *, n: int = 20_000, seed: int = 1) -> dict:
    """``sample``'s weight against ``eval / pdf`` at the sampled directions: the largest relative difference
    (float32 arithmetic: ~1e-6) and the share of samples with pdf > 0."""
    import mitsuba as mi

    plugin = mi.load_dict(bsdf)
    rng = np.random.default_rng(seed)
    ctx = mi.BSDFContext()
    si = _si(n, direction(theta_deg, phi_deg))
    bs, weight = plugin.sample(ctx, si, mi.Float(rng.random(n)), mi.Point2f(mi.Float(rng.random(n)),
                                                                             mi.Float(rng.random(n))))
    value, pdf = plugin.eval_pdf(ctx, si, bs.wo)
    w, v = _rgb(weight), _rgb(value)
    p, ps = np.asarray(pdf.numpy(), dtype=np.float64), np.asarray(bs.pdf.numpy(), dtype=np.float64)
    ok = ps > 0.0
    expected = v[ok] / p[ok, None]
    scale = np.maximum(np.abs(expected), 1e-6 * max(float(np.abs(expected).max()), 1e-30))
    return {"max_relative_difference": float(np.max(np.abs(w[ok] - expected) / scale)) if ok.any() else 0.0,
            "pdf_relative_difference": float(np.max(np.abs(p[ok] - ps[ok]) / ps[ok])) if ok.any() else 0.0,
            "sampled_share": float(ok.mean())}


def furnace_check(bsdf: dict, theta_deg: float, phi_deg: float = 17.0, *, n: int = 200_000,
                  seed: int = 2, grid: int = 256) -> dict:
    """The white furnace at one incident direction: the albedo a = integral f_r cos over the hemisphere,
    estimated through the plugin (mean of ``sample``'s weights, per channel, with its standard error) and by the
    midpoint rule on a ``grid`` x 2 ``grid`` (cos theta, phi) grid of the plugin material's own values at the same
    point (the model's own energy).  The plugin adds no energy when its estimate agrees with the model's."""
    import mitsuba as mi

    plugin = mi.load_dict(bsdf)
    rng = np.random.default_rng(seed)
    si = _si(n, direction(theta_deg, phi_deg))
    _, weight = plugin.sample(mi.BSDFContext(), si, mi.Float(rng.random(n)),
                              mi.Point2f(mi.Float(rng.random(n)), mi.Float(rng.random(n))))
    w = _rgb(weight)
    estimate, error = w.mean(axis=0), w.std(axis=0) / math.sqrt(n)
    z = (np.arange(grid) + 0.5) / grid
    phi = (np.arange(2 * grid) + 0.5) * math.pi / grid
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1.0 - zz * zz)
    light = np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    view = np.broadcast_to(np.asarray(direction(theta_deg, phi_deg)), light.shape)
    u, v = _tile_point(plugin, (0.37, 0.61), len(light))
    f = plugin.material.values(light, view, u, v, np.zeros(len(light)))
    model = (f * light[:, 2:3]).sum(axis=0) * (2.0 * math.pi / (2 * grid * grid))
    return {"plugin_albedo": estimate.tolist(), "plugin_standard_error": error.tolist(), "model_albedo": model.tolist(),
            "theta_deg": float(theta_deg)}


def _tile_point(plugin, uv, n):
    tiles = plugin._tiles(np.asarray([uv], dtype=np.float64) - 0.5)
    return np.full(n, tiles[0, 0]), np.full(n, tiles[0, 1])


def reciprocity_check(bsdf: dict, *, n: int = 2000, seed: int = 3) -> float:
    """The largest relative difference between f_r(a, b) and f_r(b, a) over ``n`` random pairs of the upper
    hemisphere, both through the plugin's ``eval`` (which returns f_r |cos wo|)."""
    import mitsuba as mi

    plugin = mi.load_dict(bsdf)
    rng = np.random.default_rng(seed)

    def hemisphere():
        z = rng.uniform(0.05, 1.0, n)
        p = rng.uniform(0.0, 2.0 * math.pi, n)
        s = np.sqrt(1.0 - z * z)
        return np.stack([s * np.cos(p), s * np.sin(p), z], axis=1)

    a, b = hemisphere(), hemisphere()
    ctx = mi.BSDFContext()
    fab = _rgb(plugin.eval(ctx, _si(n, a), _vec(b))) / b[:, 2:3]
    fba = _rgb(plugin.eval(ctx, _si(n, b), _vec(a))) / a[:, 2:3]
    scale = np.maximum(np.maximum(np.abs(fab), np.abs(fba)), 1e-6 * max(float(np.abs(fab).max()), 1e-30))
    return float(np.max(np.abs(fab - fba) / scale))
