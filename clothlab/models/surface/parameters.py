"""Parameter declarations of the fabric surface model (Chen, Wang & Wang 2024, sec. 3.1, Table 1; Jin et al.
2022 geometry).

Per yarn type k (warp, weft): the yarn geometry (twist psi and inclination umax, which place the ply normal
n_p and orientation t_p) and the appearance parameters of Table 1 that are not linear (roughness alpha,
height-field scaling beta); kd and ks are the linear coefficients.  Fabric-wide: the gap ratio (the paper's
data use 0.2) and the blend weight w of the eq. 1 diffuse term.  Fit ranges follow Table 2 (psi in
[-30, 30] deg, umax U(15, 45) deg, alpha U(0.1, 1), beta U(0, 2)), widened a little.
"""

from __future__ import annotations

from clothlab.params import ParamSpec, ParamTable
from clothlab.weave.model import YARN_KINDS

#: smallest roughness the model accepts (eq. 2: D ~ 1 / alpha^3 at its peak)
ALPHA_MIN = 1e-3


def _yarn_specs(kind: str) -> list[ParamSpec]:
    return [
        ParamSpec(f"{kind}.psi", "deg", (-80.0, 80.0), (-45.0, 45.0), 0.0, "linear",
                  f"{kind} twist: the ply orientation t_p turned by psi about n_p from the yarn axis"),
        ParamSpec(f"{kind}.umax", "deg", (0.0, 80.0), (5.0, 60.0), 30.0, "linear",
                  f"{kind} inclination: largest tilt of the yarn axis along the segment (eq. 11 u range)"),
        ParamSpec(f"{kind}.alpha", "1", (ALPHA_MIN, 1.0), (0.05, 1.0), 0.5, "log",
                  f"{kind} roughness alpha of the fibre microflake distribution (eq. 2, S = diag(1, 1, alpha^2))"),
        ParamSpec(f"{kind}.beta", "1", (0.0, 4.0), (0.0, 2.0), 1.0, "linear",
                  f"{kind} height-field scaling beta applied to n_p and t_p (sec. 3.1)"),
    ]


FABRIC_SPECS = [
    ParamSpec("gap", "1", (0.01, 0.9), (0.01, 0.5), 0.2, "linear",
              "gap ratio: fraction of each yarn's width that is gap (no reflecting surface; sec. 5.1: 0.2); > 0: at "
              "g = 0 the eq. 11 height field is unbounded at the yarn edge"),
    ParamSpec("blend", "1", (0.0, 1.0), (0.0, 1.0), 0.5, "linear",
              "weight w of the ply-normal Lambertian in the blended diffuse term (eq. 1)"),
]

SURFACE_PARAMS = ParamTable([s for kind in YARN_KINDS for s in _yarn_specs(kind)] + FABRIC_SPECS)


def weave_parameters(weave) -> dict[str, float]:
    """Every parameter at its default, with psi and umax of each yarn type taken from the weave (clipped into
    the declared range)."""
    values = {spec.name: float(spec.default) for spec in SURFACE_PARAMS}
    for kind in YARN_KINDS:
        g = weave.geometry(kind)
        for name, value in (("psi", g.psi), ("umax", g.umax)):
            lo, hi = SURFACE_PARAMS[f"{kind}.{name}"].valid
            values[f"{kind}.{name}"] = float(min(max(value, lo), hi))
    return values


#: Chen, Wang & Wang 2024, Table 2: the training distribution of the yarn parameters, per yarn type
TABLE2_PSI = (-30.0, 0.0, 30.0)  # deg, one of
TABLE2_UNIFORM = {"umax": (15.0, 45.0), "alpha": (0.1, 1.0), "beta": (0.0, 2.0)}  # deg, 1, 1


def draw_table2(rng, n: int, base: dict | None = None) -> list[dict[str, float]]:
    """``n`` parameter sets drawn from Table 2 (Chen, Wang & Wang 2024): per yarn type psi in {-30, 0, 30}
    deg, umax U(15, 45) deg, alpha U(0.1, 1), beta U(0, 2); the other parameters (gap, blend) from ``base``
    (default: the declared defaults).  ``rng``: a numpy Generator (the draw is reproducible from its seed)."""
    fixed = {spec.name: float(spec.default) for spec in SURFACE_PARAMS} | dict(base or {})
    out = []
    for _ in range(int(n)):
        q = dict(fixed)
        for kind in YARN_KINDS:
            q[f"{kind}.psi"] = float(rng.choice(TABLE2_PSI))
            for name, (lo, hi) in TABLE2_UNIFORM.items():
                q[f"{kind}.{name}"] = float(rng.uniform(lo, hi))
        out.append(q)
    return out
