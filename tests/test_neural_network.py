"""The numpy network: hand-written backward pass against central finite differences (float64), the
residual block's definition, the fast inference path, Adam against its written-out update, the loss of
Chen, Wang & Wang 2024 eqs. 9-11."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.surrogate.inference import DecoderPlan
from clothlab.surrogate.layers import LEAK, Residual
from clothlab.surrogate.losses import column_weights, decode_outputs, encode_targets, is_specular, loss_and_gradient
from clothlab.surrogate.network import Architecture, SurrogateNetwork
from clothlab.surrogate.optimizer import Adam, step_schedule

ARCH = Architecture(n_material=5, n_spatial=6, n_angular=4, n_out=3, enc_width=8, latent=6, width=7, spatial=5)


def _batch(rng, n=9, m=3):
    return (rng.standard_normal((m, ARCH.n_material)), rng.integers(0, m, n), rng.random((n, ARCH.n_spatial)),
            rng.standard_normal((n, ARCH.n_angular)), rng.standard_normal((n, ARCH.n_out)))


def _loss(net, batch):
    material, index, spatial, angular, target = batch
    out = net.forward(material, index, spatial, angular)
    return float(np.sum(np.square(out - target)))


def _perturbed(rng, seed):
    """A float64 network whose parameters (biases included) are moved off their initial values, so that every
    path is exercised."""
    net = SurrogateNetwork(ARCH, seed=seed, dtype=np.float64)
    for p in net.params().values():
        p += 0.1 * rng.standard_normal(p.shape)
    return net


def _central_differences(loss, array, h=1e-6):
    """d loss() / d array by central differences of step h, perturbing ``array`` in place entry by entry."""
    numeric = np.zeros_like(array)
    for i in np.ndindex(array.shape):
        keep = array[i]
        array[i] = keep + h
        up = loss()
        array[i] = keep - h
        down = loss()
        array[i] = keep
        numeric[i] = (up - down) / (2 * h)
    return numeric


def test_gradient_matches_central_differences_for_every_tensor():
    rng = np.random.default_rng(3)
    net = _perturbed(rng, seed=1)
    batch = _batch(rng)
    material, index, spatial, angular, target = batch
    out = net.forward(material, index, spatial, angular, train=True)
    net.backward(2.0 * (out - target))
    grads = {k: v.copy() for k, v in net.grads().items()}
    assert len(grads) == 2 * len(net.layers) + 4  # two residual blocks hold two layers each
    for name, p in net.params().items():
        numeric = _central_differences(lambda: _loss(net, batch), p)
        rel = np.linalg.norm(grads[name] - numeric) / max(np.linalg.norm(numeric), 1e-12)
        assert rel <= 1e-5, (name, rel)


def test_material_vector_gradient_matches_central_differences():
    """backward() returns d loss / d material vectors: what the fast material fit descends on."""
    rng = np.random.default_rng(4)
    net = _perturbed(rng, seed=2)
    batch = _batch(rng)
    material, index, spatial, angular, target = batch
    out = net.forward(material, index, spatial, angular, train=True)
    d_material = net.backward(2.0 * (out - target))
    numeric = _central_differences(lambda: _loss(net, batch), material)
    assert np.linalg.norm(d_material - numeric) / np.linalg.norm(numeric) <= 1e-5


def test_query_input_gradients_match_central_differences():
    """backward(inputs=True) also returns d loss / d spatial and angular inputs per row: what the fast fit of a
    network with material-dependent decoder inputs (texture probe, T(R) as an input) descends on."""
    rng = np.random.default_rng(5)
    net = _perturbed(rng, seed=3)
    batch = _batch(rng)
    material, index, spatial, angular, target = batch
    out = net.forward(material, index, spatial, angular, train=True)
    d_material, d_spatial, d_angular = net.backward(2.0 * (out - target), inputs=True)
    np.testing.assert_array_equal(d_material, net.backward(2.0 * (out - target)))
    for array, analytic in ((spatial, d_spatial), (angular, d_angular)):
        numeric = _central_differences(lambda: _loss(net, batch), array)
        assert analytic.shape == array.shape
        assert np.linalg.norm(analytic - numeric) / np.linalg.norm(numeric) <= 1e-5


def test_residual_block_adds_the_skip_before_the_last_activation():
    rng = np.random.default_rng(0)
    block = Residual(4, rng, np.float64)
    x = rng.standard_normal((5, 4))
    p = block.params
    hidden = x @ p["1.W"] + p["1.b"]
    hidden = np.where(hidden > 0, hidden, LEAK * hidden)
    pre = x + hidden @ p["2.W"] + p["2.b"]
    np.testing.assert_allclose(block.forward(x), np.where(pre > 0, pre, LEAK * pre), rtol=1e-12)


def test_fast_inference_path_equals_the_training_forward():
    rng = np.random.default_rng(2)
    net = SurrogateNetwork(ARCH, seed=4, dtype=np.float32)
    material, index, spatial, angular, _ = _batch(rng, n=50, m=1)
    full = net.forward(material, np.zeros(50, dtype=int), spatial, angular)
    bias = net.fusion_bias(net.encode(material))[0]
    plan = DecoderPlan(net, bias)
    for rows in (slice(0, 50), slice(0, 7), slice(10, 50)):  # buffers resized and reused
        fast = plan(spatial[rows].astype(np.float32), angular[rows].astype(np.float32))
        assert full.dtype == fast.dtype == np.float32
        np.testing.assert_allclose(fast, full[rows], rtol=1e-5, atol=1e-5)


def test_adam_first_steps_match_the_written_out_update():
    p = {"a.W": np.array([1.0, -2.0]), "a.b": np.array([0.5])}
    opt = Adam(p, lr=0.1, weight_decay=0.01)
    g1 = {"a.W": np.array([0.3, -0.1]), "a.b": np.array([2.0])}
    g2 = {"a.W": np.array([-0.2, 0.4]), "a.b": np.array([1.0])}
    w, b = np.array([1.0, -2.0]), np.array([0.5])
    m_w = v_w = m_b = v_b = 0.0
    for t, g in enumerate((g1, g2), start=1):
        opt.step({k: v.copy() for k, v in g.items()})
        m_w = 0.9 * m_w + 0.1 * g["a.W"]
        v_w = 0.999 * v_w + 0.001 * g["a.W"] ** 2
        m_b = 0.9 * m_b + 0.1 * g["a.b"]
        v_b = 0.999 * v_b + 0.001 * g["a.b"] ** 2
        w = w - 0.1 * ((m_w / (1 - 0.9 ** t)) / (np.sqrt(v_w / (1 - 0.999 ** t)) + 1e-8) + 0.01 * w)
        b = b - 0.1 * (m_b / (1 - 0.9 ** t)) / (np.sqrt(v_b / (1 - 0.999 ** t)) + 1e-8)  # no decay on biases
        np.testing.assert_allclose(p["a.W"], w, rtol=1e-12)
        np.testing.assert_allclose(p["a.b"], b, rtol=1e-12)


def test_step_schedule_multiplies_by_gamma_at_the_milestones():
    assert step_schedule(0.05, 0.0) == pytest.approx(0.05)
    assert step_schedule(0.05, 0.59) == pytest.approx(0.05)
    assert step_schedule(0.05, 0.6) == pytest.approx(0.01)
    assert step_schedule(0.05, 0.95) == pytest.approx(0.002)


def test_loss_is_eq_11_with_the_log_mapped_specular():
    names = ("diffuse", "specular_warp", "specular_weft")
    spec = is_specular(names)
    truth = np.array([[0.3, 0.5, 0.0], [0.2, 2.0, 0.1]])
    targets = encode_targets(truth, spec)
    np.testing.assert_allclose(targets[:, 1], np.log(100 * truth[:, 1] + 1))
    np.testing.assert_allclose(decode_outputs(targets, spec), truth, atol=1e-12)
    pred = targets + np.array([[0.1, -0.2, 0.3], [0.0, 0.4, -0.1]])
    loss, grad = loss_and_gradient(pred, targets, column_weights(spec))
    expected = 0.1 * np.mean([0.01, 0.0]) + 0.4 * np.mean([0.04, 0.16]) + 0.4 * np.mean([0.09, 0.01])
    assert loss == pytest.approx(expected)
    h = 1e-7
    bumped = pred.copy()
    bumped[1, 1] += h
    assert grad[1, 1] == pytest.approx((loss_and_gradient(bumped, targets, column_weights(spec))[0] - loss) / h,
                                       rel=1e-5)


def test_latent_box_clips_z_and_passes_no_gradient_through_clipped_entries():
    """forward(latent_box=(lo, hi)) decodes clip(z, lo, hi); backward's d material then matches central
    differences of that clipped network (entries outside the box contribute nothing), and a box holding every
    z changes nothing."""
    rng = np.random.default_rng(6)
    net = _perturbed(rng, seed=4)
    material, index, spatial, angular, target = _batch(rng)
    z = net.encode(material)
    lo, hi = np.quantile(z, 0.3, axis=0), np.quantile(z, 0.7, axis=0)
    assert np.any(z < lo) and np.any(z > hi)
    wide = (z.min(axis=0) - 1.0, z.max(axis=0) + 1.0)
    np.testing.assert_array_equal(net.forward(material, index, spatial, angular, latent_box=wide),
                                  net.forward(material, index, spatial, angular))
    clipped = np.clip(z, lo, hi)
    expected = net.decode(clipped[index], spatial, angular)
    np.testing.assert_allclose(net.forward(material, index, spatial, angular, latent_box=(lo, hi)), expected,
                               rtol=1e-12)

    def loss():
        return float(np.sum(np.square(net.forward(material, index, spatial, angular, latent_box=(lo, hi)) - target)))

    out = net.forward(material, index, spatial, angular, train=True, latent_box=(lo, hi))
    d_material = net.backward(2.0 * (out - target))
    numeric = _central_differences(loss, material)
    assert np.linalg.norm(d_material - numeric) <= 1e-5 * np.linalg.norm(numeric)
