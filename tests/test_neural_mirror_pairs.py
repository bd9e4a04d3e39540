"""Near-mirror pair sampling (``DataSpec.mirror_share``, ``train-surrogate --mirror-share``;
clothlab.surrogate.data): the share of rows, where their wo lies, their held-out flags, and that the
evaluation queries stay uniform (docs/neural.md, "Retrains with the converged tile average")."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clothlab.surrogate.data import MIN_Z, MIRROR_RADIUS, DataSpec, chunk_queries, heldout_cells, heldout_queries


def _cells(w: np.ndarray, d: int) -> np.ndarray:
    edges = np.linspace(-1.0, 1.0, d + 1)[1:-1]
    return np.searchsorted(edges, w[:, 0], side="right") + d * np.searchsorted(edges, w[:, 1], side="right")


def test_mirror_rows_are_the_share_asked_for_near_the_mirror_direction_with_their_own_held_out_flags():
    plain, mirror = DataSpec(pairs=64, seed=2), DataSpec(pairs=64, seed=2, mirror_share=0.3)
    a, b = chunk_queries(plain, 0, 5), chunk_queries(mirror, 0, 5)
    np.testing.assert_array_equal(a[:, :7], b[:, :7])  # centres, sizes and wi are the plain spec's
    changed = np.any(a[:, 7:10] != b[:, 7:10], axis=1)
    assert changed.sum() == round(0.3 * len(a))
    distance = np.linalg.norm(b[changed, 7:9] + b[changed, 4:6], axis=1)
    assert distance.max() <= MIRROR_RADIUS
    assert distance.mean() == pytest.approx(2.0 / 3.0 * MIRROR_RADIUS, rel=0.1)  # uniform in the disc
    np.testing.assert_allclose(np.linalg.norm(b[:, 7:10], axis=1), 1.0, rtol=1e-12)
    assert b[:, 9].min() >= MIN_Z
    held = heldout_cells(mirror)
    np.testing.assert_array_equal(b[:, 10] > 0.5, held[_cells(b[:, 4:7], 8), _cells(b[:, 7:10], 8)])


def test_the_evaluation_queries_and_the_default_spec_do_not_change():
    plain, mirror = DataSpec(pairs=8, seed=4), DataSpec(pairs=8, seed=4, mirror_share=0.5)
    np.testing.assert_array_equal(heldout_queries(plain, 50, seed=9), heldout_queries(mirror, 50, seed=9))
    assert "mirror_share" not in plain.to_dict()  # specs and sidecars written before the field compare equal
    assert DataSpec(**mirror.to_dict()) == mirror
    with pytest.raises(ValueError, match="mirror_share"):
        DataSpec(mirror_share=1.0)


def test_cli_mirror_share_reaches_the_sidecar_data_spec(tmp_path, capsys):
    from clothlab.cli.main import main

    out = tmp_path / "run"
    args = ["train-surrogate", "preset:silk-shantung", "-o", str(out), "--budget", "0.02", "--labels", "model",
            "--pairs", "4", "--width", "8", "--spatial", "8", "-q"]
    assert main([*args, "--mirror-share", "0.25"]) == 0
    assert json.loads((out / "surrogate.json").read_text())["encoding"]["data_spec"]["mirror_share"] == 0.25
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main([*args, "--force", "--mirror-share", "1"])
    assert exc.value.code == 2
    assert "--mirror-share" in capsys.readouterr().err
