"""Parameter declarations of the Kang fabric shader (Kang 2010 as extended in "Real-time level-of-detail
fabric rendering", secs. 3-4).

Exponents are expressed in the *yarn frame* (``nx`` across the yarn, ``ny`` along it,
clothlab.frames.to_yarn_frame).  Kang's alternating anisotropy (sec. 3.3: a weft point uses the distribution
rotated by 90 deg, x and y exchanged) is ``weft.nx = warp.nx, weft.ny = warp.ny``: with the model option
``alternating=True`` (the default, the paper's model) the weft exponents are not parameters at all
(:data:`KANG_ALTERNATING_PARAMS`, naming them raises a ParameterError that says why);
``alternating=False`` declares four independent exponents (:data:`KANG_PARAMS`, a generalisation of Kang).

The yarn-geometry ranges keep the perturbed normal of eqs. 3-4 a unit vector: with ``c_f, c_y <= 0.7``,
delta_x^2 + delta_y^2 <= 0.98 < 1, so its z (the ambient-occlusion term) stays >= 0.14.
"""

from __future__ import annotations

from clothlab.errors import ParameterError
from clothlab.params import ParamSpec, ParamTable
from clothlab.weave.model import YARN_KINDS

#: largest fibre / yarn curvature (eqs. 3-4) for which the perturbed normal stays a unit vector.
MAX_CURVATURE = 0.7


def _exponent_specs(kind: str) -> list[ParamSpec]:
    return [
        ParamSpec(f"{kind}.nx", "1", (0.0, 1e4), (0.5, 1000.0), 1.0, "log",
                  f"{kind} microfacet exponent across the yarn (eq. 2, x)"),
        ParamSpec(f"{kind}.ny", "1", (0.0, 1e4), (0.5, 1000.0), 30.0, "log",
                  f"{kind} microfacet exponent along the yarn (eq. 2, y)"),
    ]


GEOMETRY_SPECS = [
    ParamSpec("n_strands", "1/cell", (1.0, 1000.0), (1.0, 64.0), 6.0, "log",
              "number of fibre strands N_xi: fibre ridges per cell along the yarn (eqs. 3-4)"),
    ParamSpec("fibre_curvature", "1", (0.0, MAX_CURVATURE), (0.0, MAX_CURVATURE), 0.3, "linear",
              "fibre curvature c_f: amplitude of the along-yarn normal tilt (eqs. 3-4)"),
    ParamSpec("yarn_curvature", "1", (0.0, MAX_CURVATURE), (0.0, MAX_CURVATURE), 0.5, "linear",
              "yarn curvature c_y: across-yarn normal tilt at the yarn edge (eqs. 3-4)"),
    ParamSpec("fibre_slope", "1", (-10.0, 10.0), (-3.0, 3.0), 0.5, "linear",
              "fibre slope s_f: shear of the fibre ridges, cells along per cell across (eqs. 3-4)"),
    ParamSpec("fresnel_f0", "1", (0.0, 1.0), (0.0, 1.0), 0.04, "linear",
              "Schlick Fresnel reflectance at normal incidence (eq. 1, F)"),
    ParamSpec("noise", "1", (0.0, 1.0), (0.0, 1.0), 0.1, "linear",
              "per-yarn intensity noise amplitude: factor 1 + noise (2 xi - 1) in [1 - noise, 1 + noise], mean 1 "
              "(sec. 5.2)"),
]

#: the weft exponents of the alternating form and the warp exponents they are tied to (sec. 3.3).
TIED_EXPONENTS = {"weft.nx": "warp.nx", "weft.ny": "warp.ny"}


class AlternatingParamTable(ParamTable):
    """KANG_PARAMS without the weft exponents, which Kang's alternating anisotropy ties to the warp's.

    Looking up (or validating a value of) ``weft.nx`` / ``weft.ny`` raises a ParameterError naming the
    parameter and saying why, so a fabric.yaml that lists them under fit.free or model.params fails clearly.
    """

    def __getitem__(self, name: str) -> ParamSpec:
        if name in TIED_EXPONENTS:
            raise ParameterError(
                f"{name} is not a parameter of the alternating Kang model (model.options.alternating: true, the "
                f"default): the weft lobe is the warp lobe rotated by 90 deg, so {name} = {TIED_EXPONENTS[name]} "
                f"(sec. 3.3); remove {name} from fit.free / model.params, or set model.options.alternating: false "
                "for independent weft exponents", field=name)
        return super().__getitem__(name)


KANG_PARAMS = ParamTable([s for kind in YARN_KINDS for s in _exponent_specs(kind)] + GEOMETRY_SPECS)
KANG_ALTERNATING_PARAMS = AlternatingParamTable([s for s in KANG_PARAMS if s.name not in TIED_EXPONENTS])


def default_parameters(table: ParamTable = KANG_PARAMS) -> dict[str, float]:
    """Every parameter declared in ``table`` at its default (declared units)."""
    return {spec.name: float(spec.default) for spec in table}


def resolve_parameters(params: dict | None, table: ParamTable = KANG_PARAMS) -> dict[str, float]:
    """Defaults overridden by ``params``, validated against ``table`` (ParameterError names the field)."""
    values = default_parameters(table)
    values.update(table.validate(params or {}))
    return values
