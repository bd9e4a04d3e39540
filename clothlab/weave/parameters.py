"""Parameter declarations of a weave's fields: the Irawan-Marschner model's parameters (paper Table I).

They live with the weave because the ``.wv`` format checks its fields against them; the IM model
(:mod:`clothlab.models.irawan`) declares exactly these parameters.

Angles in degrees, ``w`` and ``l`` in weave-tile cells (only the ratio w / l enters the reflectance
model).  ``valid`` is the physical range, ``bounds`` the default fit bounds.
"""

from __future__ import annotations

from clothlab.params import ParamSpec, ParamTable
from clothlab.weave.model import YARN_KINDS, Weave

FIBRE_SPECS = [
    ParamSpec("alpha", "1", (0.0, 100.0), (0.0, 0.5), 0.05, "linear", "uniform scattering, eq. 7"),
    ParamSpec("beta", "1", (0.0, 1e5), (0.5, 60.0), 4.0, "log", "forward scattering, eq. 7", open_lower=True),
    ParamSpec("delta", "1", (0.0, 1.0), (0.0, 0.95), 0.3, "linear", "filament smoothing, eq. 9",
              open_upper=True),
    ParamSpec("hwidth", "1", (0.0, 1.0), (0.05, 1.0), 0.5, "linear",
              "highlight band width / segment size, eq. 12 (texture model only)", open_lower=True),
]


UMAX_LOWEST_DEG = 1e-9
"""Smallest umax accepted (deg).  The model is at its umax -> 0 limit long before it: the components agree to
float64 precision from 1e-6 deg down to 1e-100 deg, but below about 1e-150 deg the yarn integrals underflow
(0 / 0, an infinite specular albedo), so a smaller value is refused rather than evaluated."""


def _yarn_specs(kind: str) -> list[ParamSpec]:
    return [
        ParamSpec(f"{kind}.psi", "deg", (-90.0, 90.0), (-60.0, 60.0), 0.0, "linear",
                  "fibre twist angle, sec. 5.2", open_lower=True, open_upper=True),
        ParamSpec(f"{kind}.umax", "deg", (UMAX_LOWEST_DEG, 90.0), (1.0, 85.0), 30.0, "linear",
                  "maximum inclination angle, sec. 5.2", open_upper=True),
        ParamSpec(f"{kind}.kappa", "1", (-1.0, 1e3), (-0.95, 4.0), 0.0, "linear",
                  "spine curvature, sec. 5.4", open_lower=True),
        ParamSpec(f"{kind}.w", "cell", (0.0, 1e3), (0.1, 20.0), 1.0, "log",
                  "segment rectangle width, sec. 5.3", open_lower=True),
        ParamSpec(f"{kind}.l", "cell", (0.0, 1e3), (0.1, 20.0), 1.0, "log",
                  "segment rectangle length, sec. 5.3", open_lower=True),
    ]


IRAWAN_PARAMS = ParamTable(FIBRE_SPECS + [s for kind in YARN_KINDS for s in _yarn_specs(kind)])


def weave_parameters(weave: Weave) -> dict[str, float]:
    """The parameter dict (declared units) of a weave: fibre parameters and both segment types."""
    out = {"alpha": weave.alpha, "beta": weave.beta, "delta": weave.delta, "hwidth": weave.hwidth}
    for kind in YARN_KINDS:
        g = weave.geometry(kind)
        out.update({f"{kind}.psi": g.psi, f"{kind}.umax": g.umax, f"{kind}.kappa": g.kappa,
                    f"{kind}.w": g.w, f"{kind}.l": g.l})
    return {k: float(v) for k, v in out.items()}


def apply_parameters(weave: Weave, params: dict[str, float]) -> Weave:
    """A copy of ``weave`` with the given parameters (declared units) set."""
    from dataclasses import replace

    fibre = {k: float(v) for k, v in params.items() if "." not in k}
    weave = replace(weave, **fibre) if fibre else weave
    for kind in YARN_KINDS:
        changes = {k.split(".", 1)[1]: float(v) for k, v in params.items() if k.startswith(kind + ".")}
        if changes:
            weave = weave.with_geometry(kind, **changes)
    return weave
