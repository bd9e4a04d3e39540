"""``model.options.filament_arc: full | shortened`` of the IM model (issue 14 item 8).

The renderer users render the exported ``.wv`` in (Mitsuba 0.5/0.6 ``irawan``) evaluates a smoothed filament
spine's radius of curvature on the shortened arc (1 - delta) umax: r_hat, L and t_max of sec. 5.4 use it and
|u| is clamped to it; the paper's text (``full``, the default) uses the whole arc.  The independent check
below is written here from that description and the paper's equations (eq. 2, 4, 6, 7, 8, 9 and the three
spine branches of sec. 5.4) with scipy.integrate.quad; it calls no clothlab kernel.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import i0e

from clothlab.errors import ConfigError, GeometryWarning
from clothlab.frames import spherical_to_vector, to_yarn_frame
from clothlab.models.irawan.model import IrawanModel, Quadrature
from clothlab.models.registry import build_model
from clothlab.weave.presets import PRESET_NAMES, get_preset
from clothlab.weave.wvformat import format_wv, parse_wv_text

FILAMENT_PRESETS = [n for n in PRESET_NAMES if get_preset(n).warp.psi == 0.0 and get_preset(n).weft.psi == 0.0]
ACCURATE = Quadrature("support", 48)  # Gauss-Legendre on the lit arc (analytic there): ~1e-12 here


# ------------------------------------------------------------------ the renderer's form, written from the text

def renderer_radius(u, umax, kappa, w, l, delta):
    """R(u) on the shortened arc m = (1 - delta) umax with |u| clamped to m (sec. 5.4's branches)."""
    m = (1.0 - delta) * umax
    u = min(abs(u), m)
    a = 0.5 * w
    L = 0.5 * l - a * math.sin(m)  # sec. 5.3, on the shortened arc
    r_hat = 1.0 + kappa * (1.0 + 1.0 / math.tan(m))  # sec. 5.4
    if r_hat == 1.0:  # circle
        return L / math.sin(m)
    if r_hat > 0.0:  # ellipse
        t, t_max = math.atan(r_hat * math.tan(u)), math.atan(r_hat * math.tan(m))
        b = L / math.sin(t_max)
        a_hat = b / r_hat
        return (b * b * math.cos(t) ** 2 + a_hat * a_hat * math.sin(t) ** 2) ** 1.5 / (a_hat * b)
    if r_hat < 0.0:  # hyperbola
        t, t_max = -math.atanh(r_hat * math.tan(u)), -math.atanh(r_hat * math.tan(m))
        b = L / math.sinh(t_max)
        a_hat = b / r_hat
        return -(b * b * math.cosh(t) ** 2 + a_hat * a_hat * math.sinh(t) ** 2) ** 1.5 / (a_hat * b)
    return 2.0 * L / (2.0 * math.tan(m)) * (1.0 + math.tan(u) ** 2) ** 1.5  # parabola


def renderer_filament(wi, wo, params, kind):
    """f_c I_j of one filament segment type (eq. 2 with eqs. 4, 6, 8, 9; f_c of eq. 7) by quad over v."""
    umax, kappa = math.radians(params[f"{kind}.umax"]), params[f"{kind}.kappa"]
    w, l, delta = params[f"{kind}.w"], params[f"{kind}.l"], params["delta"]
    a = 0.5 * w
    yi, yo = to_yarn_frame(wi[None, :], kind)[0], to_yarn_frame(wo[None, :], kind)[0]
    s = yi + yo
    length = float(np.linalg.norm(s))
    h = s / length
    u = math.atan(h[1] / h[2])  # eq. 4
    if abs(u) >= umax:
        return 0.0
    x = (abs(u) - (1.0 - delta) * umax) / (delta * umax)
    x = min(max(x, 0.0), 1.0)
    fade = 1.0 - x * x * (3.0 - 2.0 * x)  # eq. 9
    cross = math.cos(u) * h[2] + math.sin(u) * h[1]  # eq. 6: |(t x h)_x|, t = (0, cos u, -sin u)
    radius = renderer_radius(u, umax, kappa, w, l, delta)

    def integrand(v):
        n = np.array([math.sin(v), math.sin(u) * math.cos(v), math.cos(u) * math.cos(v)])
        ci, cr = max(float(yi @ n), 0.0), max(float(yo @ n), 0.0)
        if ci <= 0.0 or cr <= 0.0:
            return 0.0
        return a * (radius + a * math.cos(v)) / (length * cross) * ci * cr / (ci + cr) * fade  # eqs. 6, 8, 9

    zeros = [math.atan(-(d[1] * math.sin(u) + d[2] * math.cos(u)) / d[0]) for d in (yi, yo) if d[0] != 0.0]
    value = quad(integrand, -0.5 * math.pi, 0.5 * math.pi, points=zeros or None, epsabs=0.0, epsrel=1e-12,
                 limit=200)[0]
    beta = params["beta"]
    f_c = params["alpha"] + math.exp(beta * (-float(wi @ wo) - 1.0)) / (2.0 * math.pi * i0e(beta))  # eq. 7
    return f_c * value


def _directions(umax_deg, delta):
    """Seeded pairs plus pairs whose specular u (eq. 4, warp frame) lies on the faded ends
    (1 - delta) umax < |u| < umax, where the two arcs differ."""
    rng = np.random.default_rng(14)
    wi = spherical_to_vector(rng.uniform(0, 80, 24), rng.uniform(0, 360, 24))
    wo = spherical_to_vector(rng.uniform(0, 80, 24), rng.uniform(0, 360, 24))
    ends = []
    for frac in (0.55, 0.7, 0.85, 0.95):
        u = math.radians(umax_deg) * (1.0 - delta + delta * frac)
        for theta, phi in ((30.0, 0.0), (50.0, 20.0), (15.0, 70.0)):
            h = np.array([0.0, math.sin(u), math.cos(u)])  # warp frame = fabric frame
            a = spherical_to_vector([theta], [phi])[0]
            b = 2.0 * (a @ h) * h - a  # mirror of a about h: (a + b) / |a + b| = h
            if a[2] > 0.05 and b[2] > 0.05:
                ends.append((a, b))
    return np.vstack([wi, [e[0] for e in ends]]), np.vstack([wo, [e[1] for e in ends]])


@pytest.mark.parametrize("name", FILAMENT_PRESETS)
def test_shortened_agrees_with_an_independent_quadrature_of_the_renderers_form(name):
    weave = get_preset(name)
    assert weave.delta > 0.0  # the option matters on these presets
    params = IrawanModel(weave).default_parameters()
    shortened = IrawanModel(weave, ACCURATE, filament_arc="shortened")
    full = IrawanModel(weave, ACCURATE)
    differs = 0
    for kind in ("warp", "weft"):
        wi, wo = _directions(params[f"{kind}.umax"], params["delta"])
        images = to_yarn_frame(np.eye(3), kind)  # row k: basis vector k in the yarn frame
        wi, wo = wi @ images.T, wo @ images.T  # fabric-frame pairs that are the above in this yarn's frame
        expected = np.array([renderer_filament(a, b, params, kind) for a, b in zip(wi, wo, strict=True)])
        got = shortened.components(wi, wo, normalised=False, warn=False)[f"specular_{kind}"]
        scale = expected.max()
        assert scale > 0.0
        np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-6 * scale)
        other = full.components(wi, wo, normalised=False, warn=False)[f"specular_{kind}"]
        differs += int(np.sum(np.abs(other - expected) > 1e-2 * np.abs(expected)))
    assert differs >= 6  # the test sees the difference between the arcs (on the faded ends)


@pytest.mark.parametrize("name", FILAMENT_PRESETS)
def test_shortened_on_every_path_the_same(name):
    """The batched moments path (fits), the per-set kernel (albedo, yarn_integral) and the texture points
    share the one arc helper; all give the same I_j."""
    from clothlab.models.irawan.integrals import yarn_specular

    weave = get_preset(name)
    model = IrawanModel(weave, ACCURATE, filament_arc="shortened")
    params = model.default_parameters()
    wi, wo = _directions(params["warp.umax"], params["delta"])
    batched = model.components(wi, wo, normalised=False, warn=False)["specular_warp"]
    direct = yarn_specular(wi, wo, params, "warp", ACCURATE, "shortened")
    np.testing.assert_allclose(batched, direct, rtol=1e-10, atol=1e-14 * batched.max())


def test_option_is_accepted_validated_and_recorded(tmp_path):
    weave = get_preset("polyester-lining")
    model = build_model("irawan", weave, ("trapezoid", 11), filament_arc="shortened")
    assert model.filament_arc == "shortened"
    assert model.settings()["options"] == {"filament_arc": "shortened"}
    assert IrawanModel.describe_settings(model.settings()) == "trapezoid 11, filament_arc=shortened"
    assert model.with_quadrature("support", 8).filament_arc == "shortened"
    assert model.texture().filament_arc == "shortened"
    with pytest.raises(ConfigError, match="filament_arc must be one of full, shortened"):
        build_model("irawan", weave, None, filament_arc="half")
    with pytest.raises(ConfigError, match="no option 'tile_nodes'"):
        build_model("irawan", weave, None, tile_nodes=3)


def test_staple_yarns_and_zero_smoothing_ignore_the_option():
    wi, wo = _directions(30.0, 0.5)
    for name in ("cotton-denim", "wool-gabardine"):  # staple: eq. 9 does not apply
        weave = get_preset(name)
        a = IrawanModel(weave).components(wi, wo, warn=False)
        b = IrawanModel(weave, filament_arc="shortened").components(wi, wo, warn=False)
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    weave = get_preset("polyester-lining")
    a = IrawanModel(weave).components(wi, wo, {"delta": 0.0}, warn=False)
    b = IrawanModel(weave, filament_arc="shortened").components(wi, wo, {"delta": 0.0}, warn=False)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])


def test_wv_export_records_the_arc_and_warns_on_a_mismatch():
    weave = get_preset("silk-charmeuse")
    params = IrawanModel(weave).default_parameters()
    for arc in ("full", "shortened"):
        text = format_wv(IrawanModel(weave, filament_arc=arc).fitted_weave(params))
        assert f"/* clothlab: filament_arc = {arc} */" in text
        assert ("shortened arc (1 - ss) umax" in text) == (arc == "full")  # the export note
        back = parse_wv_text(text, "fit.wv")
        assert back.filament_arc == arc and back == weave
        other = "full" if arc == "shortened" else "shortened"
        with pytest.warns(GeometryWarning, match=f"fitted with filament_arc: {arc} but this model evaluates "
                                                 f"filament_arc: {other}"):
            IrawanModel(back, filament_arc=other)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            IrawanModel(back, filament_arc=arc)  # the matching arc: no warning
    assert parse_wv_text(format_wv(weave), "plain.wv").filament_arc is None  # presets record none
    bad = format_wv(IrawanModel(weave).fitted_weave(params)) + "/* clothlab: filament_arc = shortened */"
    with pytest.raises(Exception, match="records filament_arc twice"):
        parse_wv_text(bad, "twice.wv")


def test_fit_note_says_the_renderer_uses_the_other_arc():
    weave = get_preset("polyester-lining")
    params = IrawanModel(weave).default_parameters()
    notes = IrawanModel(weave).geometry_warnings(params)
    assert any("rendered by the Mitsuba 0.5/0.6 irawan plugin on the shortened arc" in n for n in notes)
    assert not any("irawan plugin" in n for n in IrawanModel(weave, filament_arc="shortened").geometry_warnings(params))
    assert not any("irawan plugin" in n for n in IrawanModel(get_preset("cotton-denim")).geometry_warnings(
        IrawanModel(get_preset("cotton-denim")).default_parameters()))


def test_fabric_yaml_option_is_checked_at_its_line(tmp_path):
    from clothlab.config import load_config

    data = Path(__file__).resolve().parents[1] / "measurements" / "polyester-lining" / "noisy.csv"
    text = ("name: pl\n"
            f"measurement: {{path: {data}}}\n"
            "model:\n"
            "  kind: irawan\n"
            "  weave: preset:polyester-lining\n"
            "  options: {filament_arc: %s}\n")
    (tmp_path / "ok.yaml").write_text(text % "shortened")
    assert load_config(tmp_path / "ok.yaml").model.options == {"filament_arc": "shortened"}
    (tmp_path / "bad.yaml").write_text(text % "half")
    with pytest.raises(ConfigError) as err:
        load_config(tmp_path / "bad.yaml")
    assert "bad.yaml:6" in str(err.value) and "model.options.filament_arc" in str(err.value)
    assert "filament_arc must be one of full, shortened, got 'half'" in str(err.value)


def test_a_saved_fit_is_rebuilt_with_its_arc(tmp_path):
    """fit.json's model settings (options) and weave.wv rebuild the model with the arc it was fitted with."""
    import json

    from clothlab.fit.store import load_fitted

    weave = get_preset("polyester-lining")
    model = IrawanModel(weave, filament_arc="shortened")
    params = model.default_parameters()
    fit = {"model": {"kind": "irawan", **model.settings()},
           "parameters": {k: {"value": v} for k, v in params.items()},
           "measurement": {"channels": ["grey"]},
           "coefficients": {"kd": {"grey": 0.1}, "ks_warp": {"grey": 0.2}, "ks_weft": {"grey": 0.2}}}
    (tmp_path / "fit.json").write_text(json.dumps(fit))
    (tmp_path / "weave.wv").write_text(format_wv(model.fitted_weave(params)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the recorded arc matches: no mismatch warning
        rebuilt, *_ = load_fitted(tmp_path)
    assert rebuilt.filament_arc == "shortened" and rebuilt.weave.filament_arc == "shortened"
