"""Latent interpolation between two materials (Chen, Wang & Wang 2024, Fig. 8): the decoder reads
z(t) = (1 - t) z_a + t z_b, the latents of two trained materials; set beside it the surrogate queried at the
material vector interpolated linearly (through the encoder), and the exact model at the parameters
interpolated in the same normalised coordinates (log-mapped where declared: :mod:`.encodings`) - "the
model's own interpolation".  Far-view footprint (4.5 tiles) at a few fixed direction pairs; values are
f = the sum of the components (unit coefficients, 1/sr).
"""

from __future__ import annotations

import numpy as np

from clothlab.surrogate.material_fit import unit_to_parameter

#: (wi, wo) of the curves: the mirror configuration at 30 deg, a grazing mirror pair, an off-specular pair
PAIRS = (((0.5, 0.0, 0.866), (-0.5, 0.0, 0.866)), ((0.0, 0.8, 0.6), (0.0, -0.8, 0.6)),
         ((0.4, 0.3, 0.866), (0.2, -0.5, 0.843)))
FAR = 4.5


def latent_interpolation(surrogate, model, row_a: int, row_b: int, params_a: dict, params_b: dict,
                         names, steps: int = 11) -> dict:
    """Curves along t in [0, 1] for materials ``row_a``, ``row_b`` of ``surrogate`` (their parameters
    ``params_a``, ``params_b`` of ``model``); ``names``: the encoder's parameter order."""
    wi = np.array([p[0] for p in PAIRS], dtype=np.float64)
    wo = np.array([p[1] for p in PAIRS], dtype=np.float64)
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    n = len(wi)
    centre, size = np.full((n, 2), 0.5), np.full(n, FAR)
    z_a, z_b = surrogate.latent(row_a), surrogate.latent(row_b)
    m_a, m_b = surrogate.materials[row_a], surrogate.materials[row_b]
    table = model.params
    differing = [k for k in names if params_a[k] != params_b[k]]
    t_values = np.linspace(0.0, 1.0, steps)
    latent, encoder, exact, params = [], [], [], []
    for t in t_values:
        p = dict(params_a)
        for k in differing:
            i = list(names).index(k)
            p[k] = unit_to_parameter(table[k], (1 - t) * m_a[i] + t * m_b[i])
        params.append({k: p[k] for k in differing})
        comps = model.components(wi, wo, p, warn=False)
        # a residual network corrects the reflectance model: R at the interpolated parameters
        reference = (np.stack([np.asarray(comps[c], dtype=np.float64).reshape(-1) for c in surrogate.component_names],
                              axis=1) if surrogate.residual else None)
        latent.append(surrogate.query_latent((1 - t) * z_a + t * z_b, centre, size, wi, wo,
                                             reference=reference).sum(axis=1))
        encoder.append(surrogate.query(centre, size, wi, wo, material=(1 - t) * m_a + t * m_b,
                                       reference=reference).sum(axis=1))
        exact.append(sum(np.asarray(comps[c]) for c in model.component_names))
    return {"t": t_values.tolist(), "pairs": [[list(a), list(b)] for a, b in zip(wi, wo, strict=True)],
            "params": params, "latent": np.array(latent).tolist(), "encoder": np.array(encoder).tolist(),
            "model": np.array(exact).tolist(), "rows": [int(row_a), int(row_b)]}


def plot_latent_interpolation(curves: dict, path) -> None:
    """PNG: one panel per direction pair, f along t: latent interpolation, encoder, exact model."""
    import io
    from pathlib import Path

    from matplotlib.figure import Figure

    from clothlab.atomic import atomic_write_bytes

    t = curves["t"]
    latent, encoder, exact = (np.array(curves[k]) for k in ("latent", "encoder", "model"))
    figure = Figure(figsize=(4.0 * latent.shape[1], 3.4), layout="constrained")
    axes = np.atleast_1d(figure.subplots(1, latent.shape[1]))
    for j, ax in enumerate(axes):
        ax.plot(t, exact[:, j], "k-", label="model at interpolated parameters")
        ax.plot(t, latent[:, j], "o-", color="C2", ms=3.5, label="decoder at interpolated z (Fig. 8)")
        ax.plot(t, encoder[:, j], "s--", color="C1", ms=3, mfc="none", label="encoder at interpolated m")
        wi, wo = curves["pairs"][j]
        ax.set_title(f"wi ({wi[0]:.2f}, {wi[1]:.2f}, {wi[2]:.2f}), wo ({wo[0]:.2f}, {wo[1]:.2f}, {wo[2]:.2f})",
                     fontsize=8)
        ax.set_xlabel("t (material a -> b)")
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("f, far view (1/sr)")
    axes[0].legend(fontsize=7)
    ends = curves["params"][0], curves["params"][-1]
    figure.suptitle("latent interpolation: " + ", ".join(f"{k} {ends[0][k]:.3g} -> {ends[1][k]:.3g}" for k in ends[0]),
                    fontsize=9)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=100)
    atomic_write_bytes(Path(path), buffer.getvalue())
