"""nnls_small against scipy.optimize.nnls (an independent active-set solver), per channel."""

import time

import numpy as np
import pytest
from scipy.optimize import nnls

from clothlab.fit.nnls import nnls_small


def _objective(A, y, w, coef):
    return float(np.sum((w * (A @ coef - y)) ** 2))


def _check_against_scipy(A, y, w):
    """A (N, k, C), y, w (N, C): compare objective values channel by channel."""
    coef, residual_norm = nnls_small(A, y, w)
    assert coef.shape == (A.shape[1], y.shape[1])
    assert residual_norm.shape == (y.shape[1],)
    for c in range(y.shape[1]):
        A_c, y_c, w_c = A[:, :, c], y[:, c], w[:, c]
        x_ref, _ = nnls(A_c * w_c[:, None], y_c * w_c)
        f_ref = _objective(A_c, y_c, w_c, x_ref)
        f_ours = _objective(A_c, y_c, w_c, coef[:, c])
        scale = float(np.sum((w_c * y_c) ** 2))
        assert np.all(coef[:, c] >= 0)
        assert abs(f_ours - f_ref) <= 1e-9 * f_ref + 1e-13 * scale, (c, f_ours, f_ref)
        assert residual_norm[c] ** 2 == pytest.approx(f_ours, rel=1e-9, abs=1e-13 * scale)


CASES = ["generic", "rank-deficient", "zero-column", "all-negative", "few-rows"]


@pytest.mark.parametrize("case", CASES)
def test_matches_scipy_nnls(case):
    rng = np.random.default_rng(CASES.index(case))
    for _ in range(60):
        k = int(rng.integers(1, 7))
        n = int(rng.integers(2, 6)) if case == "few-rows" else int(rng.integers(k + 1, 80))
        C = 3
        A = rng.normal(size=(n, k, C))
        y = rng.normal(size=(n, C))
        w = rng.uniform(0.05, 3.0, size=(n, C))
        if case == "rank-deficient" and k > 1:
            A[:, -1] = 2.0 * A[:, 0]
            if k > 2:
                A[:, 1] = A[:, 0] - A[:, -1]  # = -A[:, 0]: three dependent columns
        elif case == "zero-column":
            A[:, int(rng.integers(k))] = 0.0
        elif case == "all-negative":
            A, y = np.abs(A), -np.abs(y)  # the optimum is x = 0
        _check_against_scipy(A, y, w)


def test_all_negative_gives_zero_and_data_norm():
    rng = np.random.default_rng(3)
    A = rng.uniform(0.1, 1.0, size=(40, 3))
    y = -rng.uniform(0.1, 1.0, size=(40, 2))
    coef, residual_norm = nnls_small(A, y)
    assert np.all(coef == 0.0)
    np.testing.assert_allclose(residual_norm, np.linalg.norm(y, axis=0), rtol=1e-12)


def test_shared_design_recovers_exact_coefficients():
    rng = np.random.default_rng(4)
    A = rng.uniform(size=(200, 3))
    truth = np.array([[0.5, 0.0, 2.0], [0.1, 0.3, 0.0], [0.0, 1.0, 0.7]])  # (k, C)
    y = A @ truth
    w = 1.0 / np.maximum(y, 0.05)
    coef, residual_norm = nnls_small(A, y, w)
    np.testing.assert_allclose(coef, truth, atol=1e-10)
    assert np.all(residual_norm < 1e-10)


def test_shared_and_per_channel_designs_agree():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(50, 4))
    y = rng.normal(size=(50, 3))
    w = rng.uniform(0.5, 2.0, size=(50, 3))
    shared = nnls_small(A, y, w)
    per_channel = nnls_small(np.repeat(A[:, :, None], 3, axis=2), y, w)
    np.testing.assert_allclose(shared[0], per_channel[0], atol=1e-12)
    np.testing.assert_allclose(shared[1], per_channel[1], rtol=1e-12)


def test_one_channel_input_gives_vector():
    rng = np.random.default_rng(6)
    A = rng.normal(size=(30, 2))
    y = rng.normal(size=30)
    coef, residual_norm = nnls_small(A, y)
    x_ref, r_ref = nnls(A, y)
    assert coef.shape == (2,) and isinstance(residual_norm, float)
    assert residual_norm == pytest.approx(r_ref, rel=1e-9)


def test_non_finite_channel_is_nan_without_warning():
    rng = np.random.default_rng(7)
    A = rng.uniform(size=(20, 3))
    y = rng.uniform(size=(20, 3))
    y[4, 1] = np.nan
    coef, residual_norm = nnls_small(A, y)
    assert np.isnan(coef[:, 1]).all() and np.isnan(residual_norm[1])
    assert np.isfinite(coef[:, [0, 2]]).all() and np.isfinite(residual_norm[[0, 2]]).all()


@pytest.mark.parametrize("A_shape, y_shape, w_shape", [((10, 3), (9, 2), None), ((10, 7), (10, 2), None),
                                                       ((10, 3, 4), (10, 2), None), ((10, 3), (10, 2), (10, 3))])
def test_bad_shapes_raise(A_shape, y_shape, w_shape):
    w = None if w_shape is None else np.ones(w_shape)
    with pytest.raises(ValueError):
        nnls_small(np.ones(A_shape), np.ones(y_shape), w)


def test_fast_enough_for_an_objective():
    rng = np.random.default_rng(8)
    A = rng.uniform(size=(1575, 3))
    y = rng.uniform(0.01, 1.0, size=(1575, 3))
    w = 1.0 / y
    nnls_small(A, y, w)
    runs = []
    for _ in range(5):
        start = time.process_time()
        for _ in range(50):
            nnls_small(A, y, w)
        runs.append((time.process_time() - start) / 50)
    assert min(runs) < 2e-3  # measured ~0.3 ms; generous for loaded CI machines


def test_sets_match_scipy_per_set_and_channel():
    """nnls_sets (J designs shared by the channels) against scipy.optimize.nnls problem by problem."""
    from clothlab.fit.nnls import nnls_sets

    rng = np.random.default_rng(9)
    designs = rng.uniform(size=(5, 120, 3))
    designs[2, :, 1] = 0.0  # a zero column
    designs[3, :, 2] = 3.0 * designs[3, :, 0]  # dependent columns
    y = rng.uniform(0.05, 1.0, size=(120, 3))
    w = 1.0 / y
    coef, residual_norm = nnls_sets(designs, y, w)
    assert coef.shape == (5, 3, 3) and residual_norm.shape == (5, 3)
    for j in range(5):
        for c in range(3):
            x_ref, r_ref = nnls(designs[j] * w[:, c, None], y[:, c] * w[:, c])
            f = _objective(designs[j], y[:, c], w[:, c], coef[j, :, c])
            assert np.all(coef[j, :, c] >= 0)
            assert f == pytest.approx(r_ref**2, rel=1e-10)
            assert residual_norm[j, c] ** 2 == pytest.approx(f, rel=1e-12)


def test_careful_path_when_the_check_fails(monkeypatch):
    """Every problem re-solved by the QR path (the fast path's check forced to fail) gives the same optimum;
    and a nearly collinear design (cosine 1 - 1e-12) still matches scipy."""
    import clothlab.fit.nnls as nn

    rng = np.random.default_rng(10)
    A = rng.uniform(size=(300, 3))
    y = A @ np.array([0.3, 0.0, 1.2]) + 0.01 * rng.normal(size=300)
    fast, fast_r = nn.nnls_small(A, y)
    monkeypatch.setattr(nn, "_CHECK_RTOL", -1.0)
    careful, careful_r = nn.nnls_small(A, y)
    np.testing.assert_allclose(careful, fast, rtol=1e-9, atol=1e-12)
    assert careful_r == pytest.approx(fast_r, rel=1e-9)
    monkeypatch.undo()
    B = A.copy()
    B[:, 1] = B[:, 0] * (1.0 + 1e-6 * rng.normal(size=300))
    coef, r = nn.nnls_small(B, y)
    _, r_ref = nnls(B, y)
    assert r == pytest.approx(r_ref, rel=1e-8)


def test_a_problem_failing_the_check_gets_the_qr_answer_not_the_fast_paths(monkeypatch):
    """The fallback runs and its answer is the one returned: with the check forced to fail (``_CHECK_RTOL`` < 0)
    and the fast path's answer replaced by a wrong one (every coefficient 1, score 0), every problem must still
    come out at scipy's optimum, which only the QR re-solve of the flagged problems can give.  Weighted rows,
    a shared design, per-channel designs and a set of designs (issue 25: the fallback never running survived)."""
    import clothlab.fit.nnls as nn
    from clothlab.fit import nnls_kernels

    real = nnls_kernels.normal_equations_nnls

    def wrong_fast_path(*args):
        coef, score, status = real(*args)
        finite = status != 2
        coef[finite], score[finite] = 1.0, 0.0
        return coef, score, status

    monkeypatch.setattr(nnls_kernels, "normal_equations_nnls", wrong_fast_path)
    monkeypatch.setattr(nn, "_CHECK_RTOL", -1.0)
    rng = np.random.default_rng(11)
    A = rng.uniform(size=(150, 3))
    truth = np.array([[0.5, 0.0, 2.0], [0.1, 0.3, 0.0], [0.0, 1.0, 0.7]])  # (k, C): x = 1 is far from it
    y = A @ truth + 0.01 * rng.normal(size=(150, 3))
    w = rng.uniform(0.2, 3.0, size=(150, 3))
    for design in (A, np.repeat(A[:, :, None], 3, axis=2) * rng.uniform(0.5, 1.5, size=(1, 3, 3))):
        coef, residual_norm = nn.nnls_small(design, y, w)
        for c in range(3):
            A_c = design if design.ndim == 2 else design[:, :, c]
            _, r_ref = nnls(A_c * w[:, c, None], y[:, c] * w[:, c])
            assert _objective(A_c, y[:, c], w[:, c], coef[:, c]) == pytest.approx(r_ref**2, rel=1e-9)
            assert residual_norm[c] == pytest.approx(r_ref, rel=1e-9)
    designs = rng.uniform(size=(2, 150, 3))
    coef, residual_norm = nn.nnls_sets(designs, y, w)
    for j in range(2):
        for c in range(3):
            _, r_ref = nnls(designs[j] * w[:, c, None], y[:, c] * w[:, c])
            assert residual_norm[j, c] == pytest.approx(r_ref, rel=1e-9)


def test_the_fast_path_answers_well_conditioned_problems_itself():
    """The QR re-solve is for the rare ill-conditioned problem: on well-conditioned weighted designs whose columns
    differ in scale by up to 10^4, the compiled path's own answer passes its check (status 0) and is scipy's
    optimum (its column scaling undone: a scaled answer would fail the check and cost a QR solve every time)."""
    import clothlab.fit.nnls as nn
    from clothlab.fit import nnls_kernels

    rng = np.random.default_rng(12)
    for k in range(1, 7):
        A = rng.uniform(size=(120, k)) * 10.0 ** rng.uniform(-2.0, 2.0, size=k)
        y = rng.uniform(0.05, 1.0, size=(120, 3))
        w = 1.0 / y
        coef, score, status = nnls_kernels.normal_equations_nnls(
            np.ascontiguousarray(A.T[None]), np.zeros(3, dtype=np.int64), np.arange(3, dtype=np.int64),
            np.ascontiguousarray(y.T), np.ascontiguousarray(w.T), nn._CHECK_RTOL)
        assert status.tolist() == [0, 0, 0], k
        for c in range(3):
            _, r_ref = nnls(A * w[:, c, None], y[:, c] * w[:, c])
            assert _objective(A, y[:, c], w[:, c], coef[c]) == pytest.approx(r_ref**2, rel=1e-9)
            assert score[c] == pytest.approx(r_ref**2, rel=1e-9)
