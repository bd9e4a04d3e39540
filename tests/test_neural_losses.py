"""The training loss of the numpy surrogate (Chen, Wang & Wang 2024, eqs. 9-11) and its highlight weights
(clothlab.surrogate.losses; docs/neural.md "Small footprints")."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.surrogate.losses import (
    K_SPECULAR,
    column_weights,
    decode_outputs,
    encode_targets,
    highlight_weights,
    is_specular,
    loss_and_gradient,
)

NAMES = ("diffuse", "specular_warp", "specular_weft")


def _labels(rng, n):
    """Component labels (n, 3) 1/sr: a diffuse column and specular columns spanning dark to strong highlights."""
    return np.column_stack([rng.uniform(0.1, 0.5, n), 10.0 ** rng.uniform(-3, 2, n), 10.0 ** rng.uniform(-3, 2, n)])


def test_highlight_weights_are_one_plus_the_squared_scaled_label_on_specular_columns_only():
    specular = is_specular(NAMES)
    values = np.array([[0.3, 0.0, 4.0], [2.0, -1.0, 0.5]])
    w = highlight_weights(values, specular, 2.0)
    np.testing.assert_allclose(w, [[1.0, 1.0, 5.0], [1.0, 1.0, 1.0625]], rtol=1e-15)
    assert highlight_weights(values, specular, None) is None
    with pytest.raises(ValueError, match="highlight scale"):
        highlight_weights(values, specular, 0.0)


def test_weighted_log_loss_is_the_linear_space_error_at_strong_highlights():
    """For labels x >> scale and small residuals, scale^2 w (dg)^2 is (x_pred - x)^2 in linear space (the
    motivation in losses' docstring), computed here from the decoded outputs."""
    rng = np.random.default_rng(0)
    specular = is_specular(NAMES)
    x = np.column_stack([np.full(50, 0.3), rng.uniform(20, 100, 50), rng.uniform(20, 100, 50)])
    t = encode_targets(x, specular)
    y = t + 1e-3 * rng.standard_normal(t.shape)
    scale = 0.5
    weighted = highlight_weights(x, specular, scale) * (y - t) ** 2
    linear = (decode_outputs(y, specular) - x) ** 2 / scale ** 2
    np.testing.assert_allclose(weighted[:, 1:], linear[:, 1:], rtol=0.01)


@pytest.mark.parametrize("scale", [None, 0.7])
def test_loss_and_gradient_match_the_written_out_loss_and_central_differences(scale):
    """Eq. 11 with row weights r: sum_c lambda_c mean_b r_bc (y - t)^2, written out in float64; its gradient
    against central differences (the network's backward is unchanged, so d loss / d outputs is the check)."""
    rng = np.random.default_rng(1)
    specular = is_specular(NAMES)
    x = _labels(rng, 30)
    t = encode_targets(x, specular)
    y = t + 0.3 * rng.standard_normal(t.shape)
    lam = column_weights(specular)
    r = highlight_weights(x, specular, scale)
    rows = np.ones_like(y) if r is None else r

    def loss(out) -> float:
        return float(sum(lam[c] * np.mean(rows[:, c] * (out[:, c] - t[:, c]) ** 2) for c in range(3)))

    value, grad = loss_and_gradient(y, t, lam, r)
    assert value == pytest.approx(loss(y), rel=1e-12)
    h = 1e-6
    numeric = np.zeros_like(y)
    for i in np.ndindex(y.shape):
        up, down = y.copy(), y.copy()
        up[i] += h
        down[i] -= h
        numeric[i] = (loss(up) - loss(down)) / (2 * h)
    np.testing.assert_allclose(grad, numeric, rtol=1e-6, atol=1e-6 * np.abs(numeric).max())
    assert K_SPECULAR == 100.0  # eq. 9's k for a BRDF


def test_training_with_highlight_weights_records_the_scale_and_lowers_the_strong_highlight_error():
    """A tiny network trained on synthetic labels with and without the weights (same data, steps and seed):
    a dim background whose log varies over 2 decades (which the log loss spends capacity on) plus a narrow
    strong highlight (which carries most of sum f^2).  The sidecar encoding records the scale, and the
    relative RMSE of f is lower with the weights."""
    from clothlab.surrogate.data import COLUMNS
    from clothlab.surrogate.training import TrainSpec, errors_by_size, train

    rng = np.random.default_rng(2)
    n = 3000
    u, v = rng.random(n), rng.random(n)
    normal = np.column_stack([np.zeros(n), np.zeros(n), np.ones(n)])
    background = 10.0 ** (-2 + np.sin(2 * np.pi * 3 * v) * np.cos(2 * np.pi * 2 * u))
    highlight = 40.0 * np.exp(-0.5 * ((u - 0.3) / 0.02) ** 2) * (0.5 + 0.5 * np.cos(2 * np.pi * v))
    labels = np.column_stack([np.full(n, 0.2), background + highlight, np.full(n, 0.01)])
    data = np.column_stack([np.zeros(n), u, v, np.full(n, 0.05), normal, normal, np.zeros(n), labels])
    assert data.shape[1] == len(COLUMNS) + 3
    errors = {}
    for scale in (None, 1.0):
        spec = TrainSpec(width=16, spatial=8, enc_width=4, latent=4, batch=512, steps=300, lr=1e-2,
                         position_bins=16, highlight_scale=scale, half_vector=False)
        result = train(data, NAMES, np.zeros((1, 2)), spec)
        assert result.surrogate.encoding["highlight_scale"] == scale
        errors[scale] = errors_by_size(result.surrogate, data, np.arange(n), bins=(0.01, 1.0))[0]["relative_rmse"]
    assert errors[1.0] < 0.75 * errors[None]


def test_cli_records_the_highlight_scale_and_refuses_a_non_positive_one(tmp_path, capsys):
    """``train-surrogate --highlight-scale X`` reaches the training spec and the sidecar; X <= 0 is a
    one-line usage error naming the option."""
    import json

    from clothlab.cli.main import main

    out = tmp_path / "run"
    args = ["train-surrogate", "preset:silk-shantung", "-o", str(out), "--budget", "0.02", "--labels", "model",
            "--pairs", "4", "--width", "8", "--spatial", "8", "-q", "--residual"]
    assert main([*args, "--highlight-scale", "2"]) == 0
    assert json.loads((out / "surrogate.json").read_text())["encoding"]["highlight_scale"] == 2.0
    assert json.loads((out / "training.json").read_text())["train_spec"]["highlight_scale"] == 2.0
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main([*args, "--force", "--highlight-scale", "0"])
    assert exc.value.code == 2
    assert "--highlight-scale" in capsys.readouterr().err
