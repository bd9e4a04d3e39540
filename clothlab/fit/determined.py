"""Which fitted parameters the data do not determine (issue 28 build item 6), from a fit.json-shaped mapping.

A free parameter is flagged **not determined** when

* its component's coefficient is 0 in every channel: the NNLS switched the component off, so nothing the
  parameter shapes reaches the prediction (``ks_warp`` = 0 -> every ``warp.*`` parameter; ``ks_weft`` ->
  ``weft.*``; ``kd`` -> the diffuse term's ``sigma``; an added term's coefficient, e.g. ``sheen`` -> ``sheen.r``);
* the Gauss-Newton Jacobian column is zero (:mod:`clothlab.fit.uncertainty`: "no effect on the residuals
  within the step") - its standard error is then missing;
* or its value lies within :data:`BOUND_FRACTION` (2 %) of the range from a bound (a periodic parameter such as
  ``orientation`` excepted: its box is one period, not a limit): the optimum may lie beyond, so the value is
  the bound's, not the data's.  A value exactly at the bound is the existing "AT BOUND" flag; this one widens
  it to the 2 % band.

The same rule serves the selection table, ``fit_report()`` and the report page (one function on one document,
so they agree).
"""

from __future__ import annotations

import math

BOUND_FRACTION = 0.02
#: coefficient -> prefix (or names) of the parameters of its component
DIFFUSE_PARAMETERS = ("sigma",)


def _zero_coefficients(coefficients: dict) -> list[str]:
    out = []
    for name, per_channel in (coefficients or {}).items():
        values = list(per_channel.values()) if isinstance(per_channel, dict) else [per_channel]
        try:
            if values and all(float(v) == 0.0 for v in values):
                out.append(name)
        except (TypeError, ValueError):
            continue
    return out


def _owned_by(coefficient: str, parameter: str) -> bool:
    """Whether ``parameter`` shapes only the component of ``coefficient`` (module docstring)."""
    if coefficient.startswith("ks_"):
        return parameter.startswith(coefficient[3:] + ".")
    if coefficient == "kd":
        return parameter in DIFFUSE_PARAMETERS
    return parameter.startswith(coefficient + ".")  # an added term's own, e.g. sheen -> sheen.r


def not_determined(fit: dict) -> dict[str, str]:
    """{free parameter: why it is not determined} for a fit.json-shaped ``fit`` (``parameters`` with value,
    lower, upper, free, at_bound; ``coefficients``; ``uncertainty.stderr``), in parameter order."""
    params = _with_transforms(fit)
    zero = _zero_coefficients(fit.get("coefficients") or {})
    unc = fit.get("uncertainty") or {}
    no_effect = set()
    for note in (unc.get("notes") or []) if isinstance(unc, dict) else []:
        if isinstance(note, str) and note.startswith("no effect on the residuals within the step:"):
            no_effect |= {n.strip() for n in note.split(":", 1)[1].split(",")}
    out = {}
    for name, e in params.items():
        if not isinstance(e, dict) or not e.get("free"):
            continue
        reasons = [f"no effect: its component's coefficient {c} is 0" for c in zero if _owned_by(c, name)]
        if not reasons and name in no_effect:
            reasons.append("no effect on the residuals (Gauss-Newton)")
        band = None if e.get("at_bound") else bound_band(name, e)  # at the bound: the AT BOUND flag says it
        if band:
            reasons.append(band)
        if reasons:
            out[name] = "; ".join(reasons)
    return out


def _with_transforms(fit: dict) -> dict:
    """``fit["parameters"]`` with each entry's ``transform`` (log or linear) added from the declared parameters
    of ``fit["model"]["kind"]`` when the entry does not carry one (fit.json does not record it)."""
    params = fit.get("parameters") or {}
    kind = (fit.get("model") or {}).get("kind") if isinstance(fit.get("model"), dict) else None
    if not kind or all(not isinstance(e, dict) or "transform" in e for e in params.values()):
        return params
    try:
        from clothlab.models.registry import model_class

        table = model_class(kind).declared_parameters({})
    except Exception:  # noqa: BLE001 - an unknown kind: linear bands
        return params
    return {n: ({**e, "transform": table[n].transform} if isinstance(e, dict) and "transform" not in e
                and n in table else e) for n, e in params.items()}


def bound_band(name: str, entry: dict, fraction: float = BOUND_FRACTION) -> str | None:
    """"within 2 % of its upper bound (85)" when the value lies that close to a bound (not for a periodic
    parameter, module docstring), else None."""
    if name == "orientation":
        return None
    try:
        value, lo, hi = float(entry["value"]), float(entry["lower"]), float(entry["upper"])
    except (KeyError, TypeError, ValueError):
        return None
    if entry.get("transform") == "log":  # the band in the coordinates the optimiser moves in
        if not (value > 0 and lo > 0):
            return None
        value, lo, hi = math.log(value), math.log(lo), math.log(hi)
    span = hi - lo
    if not span > 0:
        return None
    for side, distance, bound in (("lower", value - lo, lo), ("upper", hi - value, hi)):
        if distance <= fraction * span:
            return f"within {100 * fraction:g} % of its {side} bound ({bound:g})"
    return None


def flag_text(flags: dict[str, str]) -> str:
    """One line for a table cell: ``not determined: weft.umax (...), warp.umax (...)`` (empty for none)."""
    if not flags:
        return ""
    return "NOT DETERMINED: " + ", ".join(f"{n} ({why})" for n, why in flags.items())


__all__ = ["BOUND_FRACTION", "bound_band", "flag_text", "not_determined"]
