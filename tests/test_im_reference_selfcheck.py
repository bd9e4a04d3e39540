"""Checks of the scalar Irawan-Marschner reference (tests/im_reference.py) against quantities computed
another way: spine geometry (sec. 5.3-5.4), the specular condition (eq. 3), reciprocity, the staple ->
filament limit (eqs. 1, 2), brute-force sampling of the integrals, and the phase function (eq. 7)."""

import math
from functools import partial

import im_reference as ref
import numpy as np
import pytest
from scipy import integrate, special

DEG = math.pi / 180.0


def _direction(theta, phi):
    return (math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta))


def _random_directions(rng, n, max_theta=80 * DEG):
    pairs = []
    for _ in range(n):
        ti, to = (math.acos(rng.uniform(math.cos(max_theta), 1.0)) for _ in range(2))
        pi_, po = rng.uniform(-math.pi, math.pi, size=2)
        pairs.append((_direction(ti, pi_), _direction(to, po)))
    return pairs


def _kappa_for(r_hat, umax):
    """kappa giving axis ratio r_hat = 1 + kappa (1 + cot umax) (sec. 5.4)."""
    return (r_hat - 1.0) / (1.0 + 1.0 / math.tan(umax))


# --------------------------------------------------------------------------------------- spine radius


def _half_length(umax, w, l):
    return 0.5 * l - 0.5 * w * math.sin(umax)


def test_circle_radius_is_l_over_sin_umax():
    for umax, w, l in [(12 * DEG, 1.0, 5.0), (38 * DEG, 1.0, 1.0), (30 * DEG, 2.0, 6.0)]:
        expected = _half_length(umax, w, l) / math.sin(umax)  # sec. 5.3
        for u in (-umax, -0.3 * umax, 0.0, 0.8 * umax):
            assert ref.spine_radius(u, umax, 0.0, w, l) == pytest.approx(expected, rel=1e-14)


PARABOLA_UMAX = 30 * DEG
PARABOLA_KAPPA = -1.0 / (1.0 + 1.0 / math.tan(PARABOLA_UMAX))

SPINES = [  # (label, umax, kappa, w, l); r_hat in the comment
    ("ellipse flat centre", 40 * DEG, 2.0, 1.0, 9.0),  # r_hat ~ 5.4 (charmeuse warp)
    ("ellipse near circle", 50 * DEG, -0.5, 2.0, 4.0),  # r_hat ~ 0.08 (shantung warp)
    ("ellipse r_hat 0.5", 25 * DEG, _kappa_for(0.5, 25 * DEG), 1.0, 3.0),
    ("parabola", PARABOLA_UMAX, PARABOLA_KAPPA, 1.0, 4.0),
    ("hyperbola slight", 23 * DEG, -0.3, 4.0, 4.0),  # r_hat ~ -0.007 (shantung weft)
    ("hyperbola strong", 22 * DEG, -0.7, 1.0, 1.0),  # r_hat ~ -1.43 (polyester lining)
]


def test_parabola_case_hits_r_hat_zero_exactly():
    assert 1.0 + PARABOLA_KAPPA * (1.0 + 1.0 / math.tan(PARABOLA_UMAX)) == 0.0


@pytest.mark.parametrize(("label", "umax", "kappa", "w", "l"), SPINES, ids=[s[0] for s in SPINES])
def test_spine_integrates_back_to_its_half_length(label, umax, kappa, w, l):
    # the spine's tangent angle is u and ds = R du, so its horizontal extent is int_0^umax R cos u du = L
    def radius(u):
        return ref.spine_radius(u, umax, kappa, w, l)

    horizontal, _ = integrate.quad(lambda u: radius(u) * math.cos(u), 0.0, umax, epsabs=0, epsrel=1e-12)
    assert horizontal == pytest.approx(_half_length(umax, w, l), rel=1e-9)
    vertical, _ = integrate.quad(lambda u: radius(u) * math.sin(u), 0.0, umax, epsabs=0, epsrel=1e-12)
    assert math.isfinite(vertical) and vertical > 0.0
    assert radius(0.5 * umax) > 0.0 and radius(-0.5 * umax) == pytest.approx(radius(0.5 * umax), rel=1e-14)


def test_circle_vertical_extent():
    umax, w, l = 30 * DEG, 2.0, 6.0
    radius = _half_length(umax, w, l) / math.sin(umax)
    vertical, _ = integrate.quad(lambda u: ref.spine_radius(u, umax, 0.0, w, l) * math.sin(u), 0.0, umax)
    assert vertical == pytest.approx(radius * (1.0 - math.cos(umax)), rel=1e-12)


def test_spine_shape_follows_kappa():
    # kappa > 0: flatter at the centre (larger R at u = 0 than at the ends); kappa < 0: the reverse
    umax = 35 * DEG
    for kappa, centre_flatter in [(1.0, True), (-0.3, False), (_kappa_for(0.0, umax), False)]:
        r0 = ref.spine_radius(0.0, umax, kappa, 1.0, 4.0)
        r_end = ref.spine_radius(umax, umax, kappa, 1.0, 4.0)
        assert (r0 > r_end) == centre_flatter


def test_ellipse_and_hyperbola_approach_parabola():
    umax, w, l = 30 * DEG, 1.0, 4.0
    for u in (0.0, 0.5 * umax, umax):
        parabola = ref.spine_radius(u, umax, PARABOLA_KAPPA, w, l)
        for r_hat in (1e-6, -1e-6):
            near = ref.spine_radius(u, umax, _kappa_for(r_hat, umax), w, l)
            assert near == pytest.approx(parabola, rel=1e-5)


def test_spine_radius_rejects_impossible_geometry():
    with pytest.raises(ValueError, match="does not fit"):
        ref.spine_radius(0.0, 36 * DEG, 0.0, 2.0, 1.0)  # cotton-twill weft: w sin(umax) > l
    for kappa in (-1.0, -1.5):  # kappa = -1: the hyperbola's atanh reaches +-1
        with pytest.raises(ValueError, match="kappa"):
            ref.spine_radius(0.0, 30 * DEG, kappa, 1.0, 4.0)


def test_hyperbola_is_defined_for_all_kappa_above_minus_one():
    # |r_hat tan umax| < 1  <=>  kappa > -1, so the hyperbola branch stays finite right up to the limit
    for umax in (10 * DEG, 45 * DEG, 80 * DEG):
        kappa = -1.0 + 1e-6
        assert abs((1.0 + kappa * (1.0 + 1.0 / math.tan(umax))) * math.tan(umax)) < 1.0
        for u in (0.0, 0.5 * umax, umax):
            radius = ref.spine_radius(u, umax, kappa, 0.2, 4.0)
            assert math.isfinite(radius) and radius > 0.0


# ------------------------------------------------------------------------------------- specular curve


def test_staple_v_solves_h_dot_t_and_faces_h():
    rng = np.random.default_rng(3)
    checked = 0
    for wi, wo in _random_directions(rng, 20):
        h, _ = ref._half_vector(wi, wo)
        rho, gamma = math.hypot(h[1], h[2]), math.atan2(h[2], h[1])
        for psi in (0.4, -0.25, 0.05):
            for u in np.linspace(-1.2, 1.2, 41):
                v = ref._staple_v(float(u), h, psi)
                in_support = abs(math.cos(u + gamma)) <= abs(math.sin(psi)) / rho
                if abs(abs(math.cos(u + gamma)) * rho - abs(math.sin(psi))) > 1e-12:
                    assert (v is not None) == in_support
                if v is None:
                    continue
                # fibre tangent of sec. 5.2
                t = (
                    -math.cos(v) * math.sin(psi),
                    math.cos(u) * math.cos(psi) + math.sin(u) * math.sin(v) * math.sin(psi),
                    -math.sin(u) * math.cos(psi) + math.cos(u) * math.sin(v) * math.sin(psi),
                )
                assert ref._dot(h, t) == pytest.approx(0.0, abs=1e-12)
                assert ref._dot(h, ref._normal(float(u), v)) >= -1e-12
                assert -math.pi < v <= math.pi
                checked += 1
    assert checked > 100


def test_staple_integrand_matches_bounded_form():
    # G_v A = a (R + a cos v) / |sin psi| * ci cr / (ci + cr)^2 since ci + cr = |wi + wo| (n.h)
    rng = np.random.default_rng(4)
    umax, kappa, w, l, psi = 0.6, 0.5, 1.0, 5.0, -0.3
    compared = 0
    for wi, wo in _random_directions(rng, 30):
        h, _ = ref._half_vector(wi, wo)
        for u in np.linspace(-umax, umax, 25):
            value = ref.staple_integrand(float(u), wi, wo, psi, umax, kappa, w, l)
            v = ref._staple_v(float(u), h, psi)
            if v is None or abs(v) >= 0.5 * math.pi:
                assert value == 0.0
                continue
            n = ref._normal(float(u), v)
            ci, cr = max(ref._dot(wi, n), 0.0), max(ref._dot(wo, n), 0.0)
            bounded = 0.0 if ci * cr == 0 else ci * cr / (ci + cr) ** 2
            a = 0.5 * w
            bounded *= a * (ref.spine_radius(float(u), umax, kappa, w, l) + a * math.cos(v)) / abs(math.sin(psi))
            assert value == pytest.approx(bounded, rel=1e-9, abs=1e-14)
            compared += value > 0
    assert compared > 20


# -------------------------------------------------------------------------------------------- integral

STAPLE = dict(psi=-30 * DEG, umax=24 * DEG, kappa=0.0, w=1.0, l=6.0, alpha=0.01, beta=4.0, delta=0.0)
STAPLE_CURVED = dict(psi=20 * DEG, umax=40 * DEG, kappa=-0.3, w=2.0, l=4.0, alpha=0.02, beta=2.0, delta=0.0)
FILAMENT = dict(psi=0.0, umax=40 * DEG, kappa=2.0, w=1.0, l=9.0, alpha=0.02, beta=7.3, delta=0.0)


def test_reciprocity():
    rng = np.random.default_rng(5)
    for params in (STAPLE, STAPLE_CURVED, FILAMENT):
        nonzero = 0
        for wi, wo in _random_directions(rng, 8):
            forward, _ = ref.specular_reference(wi, wo, psi_threshold=1e-3, **params)
            backward, _ = ref.specular_reference(wo, wi, psi_threshold=1e-3, **params)
            assert forward >= 0.0
            assert backward == pytest.approx(forward, rel=1e-7, abs=1e-300)
            nonzero += forward > 0
        assert nonzero >= 4


def test_staple_tends_to_filament_as_psi_goes_to_zero():
    rng = np.random.default_rng(6)
    params = {k: v for k, v in FILAMENT.items() if k != "psi"}
    compared = 0
    for wi, wo in _random_directions(rng, 12, max_theta=70 * DEG):
        filament, _ = ref.specular_reference(wi, wo, psi=0.0, psi_threshold=1e-6, **params)
        if filament < 1e-3:
            continue
        # the deviation is first order in psi (about psi times a geometry-dependent factor of order 1) ...
        for psi, tolerance in ((0.003, 5e-3), (1e-4, 2e-4)):
            staple, _ = ref.specular_reference(wi, wo, psi=psi, psi_threshold=1e-6, **params)
            assert staple / filament == pytest.approx(1.0, abs=tolerance)
        # ... and odd in psi: the +-psi average is second order
        plus, _ = ref.specular_reference(wi, wo, psi=1e-3, psi_threshold=1e-6, **params)
        minus, _ = ref.specular_reference(wi, wo, psi=-1e-3, psi_threshold=1e-6, **params)
        assert 0.5 * (plus + minus) / filament == pytest.approx(1.0, abs=5e-5)
        compared += 1
    assert compared >= 3


def _midpoint(func, lo, hi, n):
    step = (hi - lo) / n
    return step * sum(func(lo + (k + 0.5) * step) for k in range(n))


def test_staple_quad_matches_dense_midpoint_sampling():
    pairs = [
        (_direction(40 * DEG, 10 * DEG), _direction(35 * DEG, 190 * DEG)),
        (_direction(60 * DEG, 80 * DEG), _direction(50 * DEG, -100 * DEG)),
        (_direction(20 * DEG, 120 * DEG), _direction(65 * DEG, -45 * DEG)),
    ]
    for params, some_pairs in ((STAPLE, pairs[:2]), (STAPLE_CURVED, pairs[1:])):
        geometry = {k: params[k] for k in ("psi", "umax", "kappa", "w", "l")}
        for wi, wo in some_pairs:
            value, abserr = ref.specular_reference(wi, wo, psi_threshold=1e-3, **params)
            f_c = ref.phase(wi, wo, params["alpha"], params["beta"])
            umax = params["umax"]
            brute = _midpoint(partial(ref._staple_integrand, wi=wi, wo=wo, **geometry), -umax, umax, 200_000)
            assert brute > 0.0
            assert value == pytest.approx(f_c * brute, rel=1e-4)
            assert abserr <= 1e-8 * value


def test_filament_quad_matches_dense_midpoint_sampling():
    for delta in (0.0, 0.5):
        geometry = dict(umax=FILAMENT["umax"], kappa=FILAMENT["kappa"], w=FILAMENT["w"], l=FILAMENT["l"])
        for wi, wo in [
            (_direction(40 * DEG, 80 * DEG), _direction(30 * DEG, -70 * DEG)),
            (_direction(70 * DEG, 20 * DEG), _direction(10 * DEG, -100 * DEG)),
        ]:
            params = {**FILAMENT, "delta": delta}
            value, _ = ref.specular_reference(wi, wo, psi_threshold=1e-3, **params)
            f_c = ref.phase(wi, wo, params["alpha"], params["beta"])
            integrand = partial(ref.filament_integrand, wi=wi, wo=wo, delta=delta, **geometry)
            brute = _midpoint(integrand, -math.pi / 2, math.pi / 2, 20_000)
            assert brute > 0.0
            assert value == pytest.approx(f_c * brute, rel=1e-6)


def test_filament_smoothing_fades_to_zero_at_umax():
    # specular u = pi/2 - gamma (eq. 4); choose h so that u sits inside the fade band of width delta umax
    umax, delta = 0.5, 0.5
    geometry = dict(umax=umax, kappa=0.0, w=1.0, l=4.0)
    values = []
    for u_star in (0.2, 0.3, 0.4, 0.49):
        h = (0.0, math.sin(u_star), math.cos(u_star))  # pi/2 - atan2(h_z, h_y) = u_star
        wi = (0.3, h[1], h[2])
        wi = tuple(c / math.sqrt(sum(x * x for x in wi)) for c in wi)
        wo = tuple(2.0 * ref._dot(wi, h) * hc - ic for hc, ic in zip(h, wi, strict=True))
        smooth = ref.filament_integrand(0.1, wi, wo, delta=delta, **geometry)
        sharp = ref.filament_integrand(0.1, wi, wo, delta=0.0, **geometry)
        x = (u_star - (1 - delta) * umax) / (delta * umax)
        ramp = 1.0 if x <= 0 else 1.0 - (3 * x * x - 2 * x**3)
        assert smooth == pytest.approx(sharp * ramp, rel=1e-12)
        values.append(smooth)
    assert values[0] > values[1] > values[2] > values[3] > 0.0
    assert values[3] < 0.01 * values[0]


# ----------------------------------------------------------------------------------------------- phase


def test_phase_lobe_is_normalised_von_mises():
    # wi, wo in the x-z plane just above the horizon: wi.wo = cos s, so the lobe angle x = pi - s
    # sweeps (2 eps, pi]; the von Mises lobe integrates to 1 over the circle, i.e. to 1/2 over [0, pi]
    eps = 1e-9
    wi = (math.cos(eps), 0.0, math.sin(eps))

    def lobe(s, beta):
        return ref.phase(wi, (math.cos(eps + s), 0.0, math.sin(eps + s)), 0.0, beta)

    for beta in (0.5, 4.0, 7.3):
        half, _ = integrate.quad(lobe, 0.0, math.pi - 2 * eps, args=(beta,), epsabs=0, epsrel=1e-12)
        assert 2.0 * half == pytest.approx(1.0, rel=1e-8)
        wo = _direction(0.7, 0.0)
        direct = 0.03 + math.exp(-beta * math.cos(0.7)) / (2 * math.pi * special.i0(beta))
        assert ref.phase((0.0, 0.0, 1.0), wo, 0.03, beta) == pytest.approx(direct, rel=1e-13)
    assert math.isfinite(ref.phase((0.0, 0.0, 1.0), (0.0, 0.0, 1.0), 0.0, 5000.0))
