"""Scattered samplings of the virtual gonioreflectometer: distributions, CSV files, the CLI options."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from clothlab.errors import ConfigError, InputError
from clothlab.simulate.sampling import file_sampling, parse_sampling, random_sampling


def test_uniform_and_cosine_directions_follow_their_laws():
    ti, _, to, po = random_sampling(20000, seed=1, distribution="uniform")
    assert stats.kstest(np.cos(np.deg2rad(ti)), "uniform").pvalue > 1e-3  # cos theta uniform: solid angle
    assert stats.kstest(po / 360.0, "uniform").pvalue > 1e-3
    ti, _, _, _ = random_sampling(20000, seed=1, distribution="cosine")
    assert stats.kstest(np.sin(np.deg2rad(ti)) ** 2, "uniform").pvalue > 1e-3  # sin^2 theta uniform
    assert np.all(ti < 90.0) and np.all(to < 90.0)
    a, b = random_sampling(50, seed=7), random_sampling(50, seed=7)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def test_file_sampling_round_trip_and_errors(tmp_path):
    path = tmp_path / "s.csv"
    path.write_text("# pairs\ntheta_i,phi_i,theta_o,phi_o\n10,20,30,40\n0,-90,45.5,10\n")
    ti, pi_, to, po = file_sampling(path)
    assert ti.tolist() == [10.0, 0.0] and pi_.tolist() == [20.0, 270.0] and po.tolist() == [40.0, 10.0]
    path.write_text("theta_i,phi_i,theta_o,phi_o\n10,20,95,40\n")
    with pytest.raises(InputError, match=r"s.csv:2.*theta_o"):
        file_sampling(path)
    for bad in ("random:0", "random:x", "random:5:foo"):
        with pytest.raises(ConfigError):
            parse_sampling(bad)


def test_cli_random_grey_rotated_table(tmp_path):
    from clothlab.cli.main import main
    from clothlab.io.table import read_table

    out = tmp_path / "t.csv"
    assert main(["-q", "simulate", "preset:wool-gabardine", "-o", str(out), "--sampling", "random:30",
                 "--channels", "grey", "--orientation", "37"]) == 0
    m = read_table(out)
    assert m.n == 30 and m.channels == ("grey",) and m.provenance["parameters"]["orientation"] == 37.0


def test_simulated_tables_record_nominal_angles():
    """The virtual gonioreflectometer records angles to 1e-6 deg: the paper grid's rim reads exactly 75 deg (not
    75.00000000000001), every angle is its own rounding, and a random sampling stays above the horizon."""
    from clothlab.simulate.gonio import ANGLE_DECIMALS, MAX_NOMINAL_THETA, nominal_angles, paper_sampling

    angles = paper_sampling()
    assert float(np.max(angles[0])) == 75.0
    for a in angles:
        np.testing.assert_array_equal(a, np.round(a, ANGLE_DECIMALS))
    ti, pi_, to, po = nominal_angles(np.array([89.99999999, 0.0]), np.array([359.9999999, -1e-9]),
                                     np.array([1e-9, 45.0000004]), np.array([720.0, 12.5]))
    assert np.all(ti <= MAX_NOMINAL_THETA) and ti[0] == MAX_NOMINAL_THETA
    assert np.all((pi_ >= 0.0) & (pi_ < 360.0)) and pi_[0] == 0.0
    assert to[0] == 0.0 and to[1] == 45.0 and po[0] == 0.0
