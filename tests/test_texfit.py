"""Texture fitting: simulate -> load -> fit round trip (issue 4 must-show), directions, plots, errors."""

import json

import numpy as np
import pytest

from clothlab.btf import BtfStack
from clothlab.errors import InputError, ResultExistsError
from clothlab.presets import get_preset
from clothlab.texfit.fit import fit_btf_command, fit_texture, offset_error_cells, pattern_translations
from clothlab.texfit.simulate_btf import TextureLayout, fig4_directions, load_source, simulate_btf

OFFSET_TOL_CELLS = 0.1  # recovered tile offset within a tenth of a weave cell (modulo the weave's symmetries)
HWIDTH_TOL = 0.03


@pytest.fixture(scope="module")
def denim_stack(tmp_path_factory):
    truth = TextureLayout(offset=(0.37, 0.21), hwidth=0.35, noise=True, seed=5)
    path = simulate_btf("preset:cotton-denim", tmp_path_factory.mktemp("btf") / "denim", n_directions=8,
                        size=36, tile_repeats=3, layout=truth)
    return path, truth


def test_fig4_directions_are_half_circles_by_elevation():
    table = fig4_directions(16)
    assert table.shape == (16, 4)
    # theta_i = 90 - elevation for the paper's four elevations, four azimuths each over [0, 180] deg
    assert sorted(set(table[:, 0].tolist())) == [15.0, 30.0, 45.0, 60.0]
    for theta in (15.0, 30.0, 45.0, 60.0):
        phi = np.sort(table[table[:, 0] == theta, 1])
        np.testing.assert_allclose(phi, [0.0, 60.0, 120.0, 180.0])
    assert np.all(table[:, 2:] == 0.0)
    with pytest.raises(InputError):
        fig4_directions(3)


def test_pattern_translations_of_plain_weave_and_denim():
    # a plain weave is invariant under a shift of one cell along both axes; the 3 x 6 denim twill under
    # (1 cell, 2 cells) steps; wool gabardine's pattern has none
    np.testing.assert_allclose(pattern_translations(get_preset("polyester-lining")), [[0, 0], [0.5, 0.5]])
    np.testing.assert_allclose(pattern_translations(get_preset("cotton-denim")),
                               [[0, 0], [1 / 3, 1 / 3], [2 / 3, 2 / 3]])
    assert len(pattern_translations(get_preset("wool-gabardine"))) == 1


def test_simulated_stack_records_truth_and_loads(denim_stack):
    path, truth = denim_stack
    stack = BtfStack.open(path)
    assert len(stack) == 8 and (stack.width, stack.height) == (36, 36)
    import yaml

    texture = yaml.safe_load((path / "manifest.yaml").read_text())["provenance"]["texture"]
    assert texture["offset"] == [0.37, 0.21] and texture["hwidth"] == 0.35 and texture["seed"] == 5
    with pytest.raises(ResultExistsError):
        simulate_btf("preset:cotton-denim", path, n_directions=8, size=36, tile_repeats=3, layout=truth)


def test_round_trip_recovers_offset_and_hwidth(denim_stack):
    path, truth = denim_stack
    result = fit_texture(path, "preset:cotton-denim", free=("offset", "hwidth"), starts=1, max_evals=80)
    weave = get_preset("cotton-denim")
    assert offset_error_cells(result.offset, truth.offset, weave) < OFFSET_TOL_CELLS
    assert abs(result.hwidth - truth.hwidth) < HWIDTH_TOL
    # the exponential noise (mean 1, sd 1) is detected in the residuals
    assert result.noise["present"] and 0.6 < result.noise["amplitude"] < 1.5
    # and the kd recovered by NNLS is the preset's (noise only touches the specular part)
    from clothlab.examples import YARN_COLOURS

    np.testing.assert_allclose(result.coefficients["kd"], YARN_COLOURS["cotton-denim"]["kd"], rtol=0.05)


def test_wrong_offset_fits_worse(denim_stack):
    # the objective prefers the truth to a shift of half a cell by > 0.1 of the data's energy (the truth's own
    # value, ~0.25, is the exponential noise the noise-free model cannot follow)
    from clothlab.texfit.fit import _Problem

    path, truth = denim_stack
    src = load_source("preset:cotton-denim")
    problem = _Problem(BtfStack.open(path), src, (3.0, 1.5), ("offset", "hwidth"), ())
    good = problem.solve({**problem.start, "u0": 0.37, "v0": 0.21, "hwidth": 0.35})[0]
    bad = problem.solve({**problem.start, "u0": 0.37 + 0.5 / 3, "v0": 0.21, "hwidth": 0.35})[0]
    assert good < bad - 0.1


def test_noise_free_stack_reports_no_noise(tmp_path):
    truth = TextureLayout(offset=(0.6, 0.1), noise=False)
    path = simulate_btf("preset:polyester-lining", tmp_path / "poly", n_directions=8, size=32, tile_repeats=4,
                        layout=truth)
    result = fit_texture(path, "preset:polyester-lining", free=("offset",), starts=1, max_evals=40)
    assert offset_error_cells(result.offset, truth.offset, get_preset("polyester-lining")) < OFFSET_TOL_CELLS
    assert result.noise["present"] is False and result.noise["amplitude"] < 0.05
    # noise-free model at the very pixel centres: tile averages agree to half-float precision
    assert result.errors["overall"]["tile"]["p95"] < 0.01
    assert len(result.errors["images"]) == 8


def test_fit_btf_command_writes_json_and_png(denim_stack, tmp_path, monkeypatch, capsys):
    import clothlab.texfit.fit as texfit

    path, _ = denim_stack
    original = texfit.fit_texture
    monkeypatch.setattr(texfit, "fit_texture", lambda s, f: original(s, f, free=("offset",), starts=1, max_evals=20))
    out = tmp_path / "out"
    assert fit_btf_command(path, "preset:cotton-denim", out) == 0
    document = json.loads((out / "texfit.json").read_text())
    assert len(document["errors"]["images"]) == 8 and "p80" in document["errors"]["images"][0]["tile"]
    assert (out / "tiles.png").stat().st_size > 1000
    assert "offset" in capsys.readouterr().out
    with pytest.raises(ResultExistsError):
        fit_btf_command(path, "preset:cotton-denim", out)


def test_bad_source_is_a_clear_error(denim_stack):
    with pytest.raises(InputError, match="neither a fit directory"):
        fit_texture(denim_stack[0], "no-such-fabric")
