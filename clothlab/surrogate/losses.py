"""The training loss of Chen, Wang & Wang 2024, eqs. 9-11.

Specular components are compared after the log mapping g(x) = ln(k x + 1) (eq. 9, k = 100 for a BRDF): the
network's specular outputs *are* g-values, :func:`decode_outputs` inverts the mapping.  Diffuse components
use a plain MSE (eq. 10).  Eq. 11 sums lambda_S Loss_S over the specular and lambda_C Loss_C over the
diffuse components, each a mean over the batch (lambda_S = 0.4, lambda_C = 0.1).
"""

from __future__ import annotations

import numpy as np

K_SPECULAR = 100.0
LAMBDA_SPECULAR = 0.4
LAMBDA_DIFFUSE = 0.1


def is_specular(names) -> np.ndarray:
    """(C,) True for the components trained with the log loss (names starting with ``specular``)."""
    return np.array([str(n).startswith("specular") for n in names])


def encode_targets(values: np.ndarray, specular: np.ndarray, k: float = K_SPECULAR) -> np.ndarray:
    """Training targets (B, C): g(x) = ln(k x + 1) for specular columns (x clipped at 0), x for diffuse."""
    values = np.asarray(values)
    return np.where(specular, np.log1p(k * np.maximum(values, 0.0)), values).astype(values.dtype)


def decode_outputs(outputs: np.ndarray, specular: np.ndarray, k: float = K_SPECULAR) -> np.ndarray:
    """Component values (B, C) from network outputs: (exp(y) - 1) / k for specular (>= 0), y for diffuse."""
    return np.where(specular, np.maximum(np.expm1(outputs), 0.0) / k, outputs)


def column_weights(specular: np.ndarray) -> np.ndarray:
    """lambda per column (eq. 11)."""
    return np.where(specular, LAMBDA_SPECULAR, LAMBDA_DIFFUSE)


def highlight_weights(values: np.ndarray, specular: np.ndarray, scale: float | None) -> np.ndarray | None:
    """(B, C) row weights 1 + (x / scale)^2 of the specular columns (x: the label, 1/sr, clipped at 0), 1 for
    diffuse (module docstring); None when ``scale`` is None (the paper's loss)."""
    if scale is None:
        return None
    if not scale > 0.0:
        raise ValueError(f"highlight scale must be > 0 (1/sr), got {scale}")
    x = np.maximum(np.asarray(values, dtype=np.float64), 0.0) / scale
    return np.where(specular, 1.0 + x * x, 1.0)


def loss_and_gradient(outputs: np.ndarray, targets: np.ndarray, weights: np.ndarray, row_weights=None):
    """Eq. 11 on encoded targets: (loss, d loss / d outputs), loss = sum_c w_c mean_b r_bc (y - t)^2, with
    ``row_weights`` r (B, C) (:func:`highlight_weights`; None: 1)."""
    r = outputs - targets
    n = r.shape[0]
    wr = r if row_weights is None else r * np.asarray(row_weights, dtype=r.dtype)
    loss = float(np.sum(weights * np.mean(np.multiply(r, wr, dtype=np.float64), axis=0)))
    return loss, (wr * (2.0 / n) * weights).astype(outputs.dtype)
