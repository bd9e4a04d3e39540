"""Colour calibration from a photographed colour chart: reference values, correction, delta E 2000.

The paper put its renderings into the camera's colour space with a colour-chart calibration (Irawan &
Marschner 2012, sec. 8).  This module goes the other way round - from a camera's linear RGB to a standard
space - with colour-science (imported inside the functions; ``import colour`` costs 1-2 s):

- :func:`chart_reference`: the chart's reference values (colour's ``CCS_COLOURCHECKERS``, xyY under the
  chart's illuminant) as linear sRGB (Bradford-adapted to D65) or XYZ adapted to a named illuminant;
  white has Y = 1.
- :func:`fit_correction`: a correction matrix from the measured patches (N, 3) to the reference (N, 3) by
  least squares, ``colour.characterisation.matrix_colour_correction``: 'Cheung 2004' (``terms`` = 3: a 3x3
  matrix, or a polynomial expansion), 'Finlayson 2015' (root-polynomial of ``degree`` 1-4; every term is
  homogeneous of degree 1, so the correction commutes with exposure), 'Vandermonde' (polynomial of
  ``degree``).  Only 3x3 and root-polynomial corrections are scale-invariant: apply the others only to data
  on the chart's exposure scale.
- :meth:`Correction.apply` for (..., 3) tables and images, :meth:`Correction.apply_measurement` for a
  :class:`~clothlab.io.measurement.Measurement` (sigma propagated through the local Jacobian).
- :func:`delta_e_2000`: CIEDE2000 between linear sRGB triplets: RGB (IEC 61966-2-1 primaries, D65 white,
  no transfer function) -> XYZ (white Y = 1) -> CIE Lab with the D65 white -> ``colour.delta_E(...,
  method="CIE 2000")``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from clothlab.errors import InputError

DEFAULT_CHART = "ColorChecker24 - After November 2014"
METHODS = ("Cheung 2004", "Finlayson 2015", "Vandermonde")
SPACES = ("sRGB", "XYZ")
_OBSERVER = "CIE 1931 2 Degree Standard Observer"


def _illuminant_xy(name: str):
    import colour

    table = colour.CCS_ILLUMINANTS[_OBSERVER]
    if name not in table:
        raise InputError(f"unknown illuminant '{name}'; expected one of e.g. D50, D65, A", field="illuminant")
    return np.asarray(table[name], dtype=np.float64)


def chart_reference(name: str = DEFAULT_CHART, illuminant: str | None = "D65", space: str = "sRGB") -> np.ndarray:
    """(N, 3) reference values of a colour chart (24 for a ColorChecker), in the chart's patch order.

    space 'sRGB': linear sRGB (the sRGB white is D65; ``illuminant`` must be 'D65'), Bradford chromatic
    adaptation from the chart's illuminant.  space 'XYZ': CIE XYZ Bradford-adapted to ``illuminant``
    (None: the chart's own illuminant, no adaptation).
    Scale: Y = 1 for the perfect reflecting diffuser.
    """
    import colour

    if name not in colour.CCS_COLOURCHECKERS:
        raise InputError(f"unknown chart '{name}'; expected one of {', '.join(colour.CCS_COLOURCHECKERS)}",
                         field="chart")
    if space not in SPACES:
        raise InputError(f"space '{space}' is not one of {', '.join(SPACES)}", field="space")
    chart = colour.CCS_COLOURCHECKERS[name]
    xyY = np.array(list(chart.data.values()), dtype=np.float64)
    XYZ = colour.xyY_to_XYZ(xyY)
    source = np.asarray(chart.illuminant, dtype=np.float64)
    if space == "sRGB":
        if illuminant != "D65":
            raise InputError(f"sRGB has a D65 white; illuminant '{illuminant}' needs space='XYZ'",
                             field="illuminant")
        return colour.XYZ_to_RGB(XYZ, "sRGB", illuminant=source, chromatic_adaptation_transform="Bradford",
                                 apply_cctf_encoding=False)
    if illuminant is None:
        return XYZ
    target = _illuminant_xy(illuminant)
    return colour.chromatic_adaptation(XYZ, colour.xy_to_XYZ(source), colour.xy_to_XYZ(target),
                                       method="Von Kries", transform="Bradford")


MAX_PATCH_VALUE = 1e30
"""Largest linear camera value of a patch accepted (beyond it delta E 2000 overflows to NaN)."""


def check_patch_value(value: float, **where) -> None:
    """InputError (naming ``where``: path, line, field) unless one patch value is finite, >= 0 and at most
    :data:`MAX_PATCH_VALUE`."""
    if not np.isfinite(value) or value < 0 or value > MAX_PATCH_VALUE:
        raise InputError(f"value {value!r} must be finite, >= 0 and <= {MAX_PATCH_VALUE:g} (linear camera RGB)",
                         **where)


def check_patches(values: np.ndarray, **where) -> None:
    """InputError unless the (N, 3) patches vary: an all-zero chart or one whose patches are all identical
    cannot determine a colour correction (the least-squares system is singular)."""
    values = np.asarray(values, dtype=np.float64)
    if values.size and not values.any():
        raise InputError(f"all {len(values)} patches are zero; expected the photographed chart's values", **where)
    if len(values) > 1 and np.all(values == values[0]):
        raise InputError(f"all {len(values)} patches have the same value {values[0].tolist()}; expected the "
                         "chart's distinct patches", **where)


def _check_rgb(values, name: str, *, rows: int | None = None) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    if array.ndim < 1 or array.shape[-1] != 3:
        raise InputError(f"expected RGB triplets with a last axis of 3, got shape {array.shape}", field=name)
    if rows is not None and array.shape != (rows, 3):
        raise InputError(f"expected shape ({rows}, 3), got {array.shape}", field=name)
    bad = ~np.isfinite(array)
    if bad.any():
        where = np.argwhere(bad.any(axis=-1))[0]
        raise InputError(f"non-finite value (NaN or inf) at index {tuple(int(i) for i in where)}: "
                         f"{array[tuple(where)].tolist()}", field=name)
    return array


def _options(method: str, degree: int | None, terms: int | None) -> dict:
    if method not in METHODS:
        raise InputError(f"method '{method}' is not one of {', '.join(METHODS)}", field="method")
    if method == "Cheung 2004":
        if degree is not None:
            raise InputError("'Cheung 2004' takes terms=, not degree=", field="degree")
        return {"terms": 3 if terms is None else int(terms)}
    if terms is not None:
        raise InputError(f"'{method}' takes degree=, not terms=", field="terms")
    degree = 1 if degree is None else int(degree)
    if method == "Finlayson 2015":
        if degree not in (1, 2, 3, 4):
            raise InputError(f"root-polynomial degree must be 1-4, got {degree}", field="degree")
        return {"degree": degree, "root_polynomial_expansion": True}
    if degree < 1:
        raise InputError(f"Vandermonde degree must be >= 1, got {degree}", field="degree")
    return {"degree": degree}


def delta_e_2000(rgb_a, rgb_b) -> np.ndarray:
    """CIEDE2000 colour difference (...,) between linear sRGB arrays (..., 3) (module docstring)."""
    import colour

    a = _check_rgb(rgb_a, "rgb_a")
    b = _check_rgb(rgb_b, "rgb_b")
    if a.shape != b.shape:
        raise InputError(f"shapes differ: {a.shape} vs {b.shape}", field="rgb_b")
    white = colour.RGB_COLOURSPACES["sRGB"].whitepoint
    lab_a = colour.XYZ_to_Lab(colour.RGB_to_XYZ(a, "sRGB", apply_cctf_decoding=False), white)
    lab_b = colour.XYZ_to_Lab(colour.RGB_to_XYZ(b, "sRGB", apply_cctf_decoding=False), white)
    return np.asarray(colour.delta_E(lab_a, lab_b, method="CIE 2000"), dtype=np.float64)


def _stats(values: np.ndarray) -> dict:
    return {"mean": float(np.mean(values)), "median": float(np.median(values)), "max": float(np.max(values))}


@dataclass(frozen=True)
class Correction:
    """A fitted colour correction: ``matrix`` (3, terms) on the expansion of ``method`` with ``options``.

    ``summary`` (from :func:`fit_correction`): method, options, patches, delta E 2000 of the chart before
    and after (mean / median / max).
    """

    matrix: np.ndarray
    method: str
    options: dict
    summary: dict = field(default_factory=dict)

    @property
    def is_linear(self) -> bool:
        """True for a plain 3x3 matrix (no expansion): exact sigma propagation, any scale."""
        return self.matrix.shape == (3, 3) and self.method != "Vandermonde"

    def apply(self, rgb) -> np.ndarray:
        """Corrected (..., 3) values of camera RGB (..., 3): a table's rows or an (H, W, 3) image."""
        from colour.characterisation import apply_matrix_colour_correction

        rgb = _check_rgb(rgb, "rgb")
        return np.asarray(apply_matrix_colour_correction(rgb, self.matrix, self.method, **self.options),
                          dtype=np.float64)

    def jacobian(self, rgb) -> np.ndarray:
        """(..., 3, 3) d corrected / d rgb (exact for 3x3; central differences otherwise)."""
        rgb = _check_rgb(rgb, "rgb")
        if self.is_linear:
            return np.broadcast_to(self.matrix, (*rgb.shape[:-1], 3, 3)).copy()
        step = 1e-6 * np.maximum(np.abs(rgb), 1e-3)
        columns = []
        for k in range(3):
            delta = np.zeros_like(rgb)
            delta[..., k] = step[..., k]
            columns.append((self.apply(rgb + delta) - self.apply(rgb - delta)) / (2 * step[..., k:k + 1]))
        return np.stack(columns, axis=-1)

    def apply_measurement(self, measurement):
        """A copy of a 3-channel Measurement with corrected values, sigma through the Jacobian (independent
        channel errors assumed) and the correction recorded in its provenance."""
        if measurement.values.shape[1] != 3:
            raise InputError(f"colour correction needs 3 channels, the measurement has "
                             f"{measurement.values.shape[1]} ({', '.join(measurement.channels)})",
                             path=measurement.source, field="channels")
        values = self.apply(measurement.values)
        sigma = None
        if measurement.sigma is not None:
            jac = self.jacobian(measurement.values)
            sigma = np.sqrt(np.einsum("nij,nj->ni", jac**2, np.asarray(measurement.sigma, dtype=np.float64)**2))
        provenance = {**measurement.provenance,
                      "colour_correction": {"method": self.method, "options": dict(self.options),
                                            "matrix": self.matrix.tolist()}}
        return dataclasses.replace(measurement, values=values, sigma=sigma, provenance=provenance)


def fit_correction(measured, reference, method: str = "Cheung 2004", *, degree: int | None = None,
                   terms: int | None = None) -> Correction:
    """Least-squares colour correction from ``measured`` (N, 3) camera RGB to ``reference`` (N, 3).

    Cheung 2004 with terms=3 (default) is the 3x3 matrix; 'Finlayson 2015' with degree=2 the
    root-polynomial correction.  The Correction carries a summary with delta E 2000 before / after
    (measured and corrected values read as linear sRGB against the reference).
    """
    from colour.characterisation import matrix_colour_correction

    measured = _check_rgb(measured, "measured")
    if measured.ndim != 2:
        raise InputError(f"expected (N, 3) patch values, got shape {measured.shape}", field="measured")
    if np.abs(measured).max(initial=0.0) > MAX_PATCH_VALUE:
        raise InputError(f"patch values exceed {MAX_PATCH_VALUE:g}", field="measured")
    check_patches(measured, field="measured")
    reference = _check_rgb(reference, "reference", rows=measured.shape[0])
    options = _options(method, degree, terms)
    with np.errstate(all="ignore"):
        matrix = np.asarray(matrix_colour_correction(measured, reference, method, **options), dtype=np.float64)
    if not np.isfinite(matrix).all():
        raise InputError(f"the {method} fit gives a non-finite correction: the patches do not determine it",
                         field="measured")
    if matrix.shape[1] > measured.shape[0]:
        raise InputError(f"{method} {options} has {matrix.shape[1]} terms but only {measured.shape[0]} "
                         "patches: the fit is under-determined", field="measured")
    correction = Correction(matrix=matrix, method=method, options=options)
    summary = {"method": method, "options": dict(options), "patches": int(measured.shape[0]),
               "matrix": matrix.tolist(), "delta_e_2000_before": _stats(delta_e_2000(measured, reference)),
               "delta_e_2000_after": _stats(delta_e_2000(correction.apply(measured), reference))}
    return dataclasses.replace(correction, summary=summary)
