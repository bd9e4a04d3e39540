"""Weave presets, the .wv reader/writer, the segment constraint and the pattern lookup."""

from __future__ import annotations

import math
from dataclasses import fields, replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clothlab.errors import ConfigError, InputError
from clothlab.weave.lookup import locate_segments, segment_constraint_violations
from clothlab.weave.model import Weave
from clothlab.weave.presets import PRESET_NAMES, get_preset, resolve_weave
from clothlab.weave.wvformat import format_wv, parse_wv, parse_wv_text


def assert_same_weave(a: Weave, b: Weave) -> None:
    """Field-by-field equality (Weave's generated __eq__ cannot compare its ndarray pattern)."""
    for f in fields(Weave):
        if f.name == "pattern":
            assert a.pattern.shape == b.pattern.shape and np.array_equal(a.pattern, b.pattern)
        elif f.compare:
            assert getattr(a, f.name) == getattr(b, f.name), f.name


# --- the reference table (docs/presets.md), typed independently of the .wv files -----
# tile (W, H), alpha, beta, ss, warpArea, weftArea, fineness, dUmax (4), period,
# warp (psi, umax, kappa, w, l), weft (...), number of warp yarns, top pattern row, one centre (yarn, U, V)
TABLE = {
    "cotton-denim": ((3, 6), 0.01, 4.0, 0.0, 5, 1, 3, (0, 0, 0, 0), 0,
                     (-30, 12, 0, 1, 5), (-30, 38, 0, 1, 1), 5, [1, 3, 8], (3, 0.5, 1.0833)),
    "silk-shantung": ((6, 8), 0.02, 1.5, 0.5, 8, 16, 0, (20, 20, 10, 10), 500,
                      (0, 50, -0.5, 2, 4), (0, 23, -0.3, 4, 4), 2, [3, 3, 3, 3, 2, 2], (4, -0.1667, 0.25)),
    "silk-charmeuse": ((5, 10), 0.02, 7.3, 0.5, 9, 1, 3, (0, 0, 0, 0), 0,
                       (0, 40, 2, 1, 9), (0, 60, 0, 1, 1), 9, [10, 2, 4, 6, 8], (6, 0.7, 1.25)),
    "cotton-twill": ((4, 8), 0.01, 4.0, 0.0, 6, 2, 4, (0, 0, 0, 0), 0,
                     (-30, 24, 0, 1, 6), (-30, 36, 0, 2, 1), 6, [7, 2, 4, 6], (5, 0.625, -0.125)),
    "wool-gabardine": ((6, 9), 0.01, 4.0, 0.0, 12, 6, 0, (0, 0, 0, 0), 0,
                       (30, 30, 0, 2, 6), (30, 30, 0, 3, 2), 4, [1, 1, 2, 2, 7, 7], (7, 0.833, 0.833)),
    "polyester-lining": ((2, 2), 0.015, 4.0, 0.5, 1, 1, 0, (8, 8, 6, 6), 50,
                         (0, 22, -0.7, 1, 1), (0, 16, -0.7, 1, 1), 2, [3, 2], (3, 0.25, 0.75)),
}


def test_preset_names_match_the_table():
    assert set(PRESET_NAMES) == set(TABLE) and len(PRESET_NAMES) == 6


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_preset_numbers_match_the_reference_table(name):
    (tile, alpha, beta, ss, warp_area, weft_area, fineness, dumax, period, warp, weft, n_warp, top_row,
     (yarn, cu, cv)) = TABLE[name]
    w = get_preset(name)
    assert (w.tile_width, w.tile_height) == tile
    assert (w.alpha, w.beta, w.delta, w.hwidth) == (alpha, beta, ss, 0.5)
    assert (w.warp_area, w.weft_area, w.fineness, w.dumax, w.period) == (warp_area, weft_area, fineness, dumax,
                                                                         period)
    for geometry, expected in ((w.warp, warp), (w.weft, weft)):
        assert (geometry.psi, geometry.umax, geometry.kappa, geometry.w, geometry.l) == expected
    assert list(w.pattern[0]) == top_row
    assert [s.kind for s in w.segments] == ["warp"] * n_warp + ["weft"] * (len(w.segments) - n_warp)
    seg = next(s for s in w.segments if s.yarn == yarn)
    assert (seg.center_u, seg.center_v) == (cu, cv)
    assert w.name == name


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_declared_areas_match_the_pattern_cell_counts(name):
    """Every published preset's warpArea : weftArea equals its pattern's warp : weft cell count."""
    w = get_preset(name)
    n_warp = TABLE[name][11]
    warp_cells = int(np.sum(w.pattern <= n_warp))  # warp yarns are numbered 1..n_warp in every preset
    assert math.isclose(w.area_share("warp"), warp_cells / w.pattern.size)
    assert math.isclose(w.cell_share("warp"), warp_cells / w.pattern.size)


def test_preset_lookup_is_forgiving_about_spelling_and_strict_about_names():
    assert get_preset("Cotton_Denim") is get_preset("cotton-denim")
    assert get_preset(" WOOL GABARDINE ").name == "wool-gabardine"
    with pytest.raises(ConfigError) as err:
        get_preset("linen")
    assert "linen" in str(err.value) and all(n in str(err.value) for n in PRESET_NAMES)


def test_preset_pattern_cannot_be_modified():
    with pytest.raises(ValueError):
        get_preset("polyester-lining").pattern[0, 0] = 9


def test_resolve_weave_presets_and_files(tmp_path):
    assert resolve_weave("preset:silk_charmeuse", tmp_path) is get_preset("silk-charmeuse")
    (tmp_path / "weaves").mkdir()
    (tmp_path / "weaves" / "mine.wv").write_text(format_wv(get_preset("cotton-twill")))
    assert_same_weave(resolve_weave("weaves/mine.wv", tmp_path), get_preset("cotton-twill"))
    with pytest.raises(ConfigError, match="nope.wv"):
        resolve_weave("weaves/nope.wv", tmp_path)
    with pytest.raises(ConfigError, match="preset 'satin'"):
        resolve_weave("preset:satin", tmp_path)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_round_trip_of_every_preset(name):
    w = get_preset(name)
    assert_same_weave(parse_wv_text(format_wv(w)), w)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 0.95), st.floats(0.01, 80.0), st.floats(-0.9, 5.0), st.floats(0.1, 5.0),
       st.floats(-3.0, 3.0), st.floats(0.01, 1.0))
def test_round_trip_is_exact_for_arbitrary_floats(alpha, umax, kappa, length, center, hwidth):
    base = get_preset("silk-shantung")
    segments = (replace(base.segments[0], center_u=center),) + base.segments[1:]
    w = replace(base.with_geometry("weft", umax=umax, kappa=kappa, l=length), alpha=alpha, hwidth=hwidth,
                segments=segments)
    assert_same_weave(parse_wv_text(format_wv(w)), w)


# --- the file format -------------------------------------------------------------------------------------

MITSUBA_STYLE = """/* A plain weave written the way Mitsuba's own writer lays it out: one-line pattern */
weave {
  name = "plain",
  tileWidth = 2,
  tileHeight = 2,
  alpha = 0.015,
  beta = 4,
  warpArea = 1,
  weftArea = 1,
  pattern {
    3, 2, 1, 4
  },
  yarn {
    type = warp,
    umax = 22, /* kappa and psi left at their default 0 */
    width = 1,
    length = 1,
    centerU = .25,
    centerV = .25
  },
  yarn { type = warp, umax = 22, width = 1, length = 1, centerU = 0.75, centerV = 0.75 },
  yarn { type = weft, psi = 0, umax = 16, kappa = -0.7, width = 1, length = 1, centerU = 0.25, centerV = 0.75 },
  yarn { type = weft, psi = 0, umax = 16, kappa = -0.7, width = 1, length = 1, centerU = 0.75, centerV = 0.25 }
}
"""


def test_parse_mitsuba_layout_and_defaults():
    w = parse_wv_text(MITSUBA_STYLE)
    assert w.name == "plain"
    assert w.pattern.tolist() == [[3, 2], [1, 4]]
    assert (w.warp.psi, w.warp.kappa, w.warp.umax) == (0.0, 0.0, 22.0)
    assert (w.weft.kappa, w.weft.umax) == (-0.7, 16.0)
    assert (w.delta, w.hwidth, w.fineness, w.dumax, w.period) == (0.0, 0.5, 0.0, (0.0,) * 4, 0.0)
    assert w.segments[0].center_u == 0.25


# (replace this, with that, expected line, expected field, words the message must contain)
BAD_FILES = [
    ("  beta = 4,", "  beta = 4,\n  gamma = 2,", 7, "gamma", ["unknown field 'gamma'"]),
    ("  hWidth = 0.5,", "  hwidth = 0.5,", 7, "hwidth", ["did you mean 'hWidth'"]),
    ("  alpha = 0.01,\n", "", 1, "alpha", ["required field 'alpha' is missing"]),
    ("    centerV = 0.75\n", "", 15, "centerV", ["required field 'centerV'", "yarn 1"]),
    ("    3, 2, 1,\n    4, 1, 1\n", "    3, 2, 1, 4,\n    1, 1\n", 12, "pattern",
     ["row 1", "holds 4", "tileWidth = 3"]),
    ("    3, 2, 1,\n    4, 1, 1\n", "    3, 2, 1,\n    4, 1, 1,\n    1, 1, 1\n", 11, "pattern",
     ["9 yarn numbers", "3 x 2 = 6"]),
    ("    4, 1, 1\n", "    4, 1, 7\n", 13, "pattern", ["yarn 7", "4 yarn blocks"]),
    ("  beta = 4,", "  beta = four,", 6, "beta", ["expected a number", "'four'"]),
    ("    umax = 12,", "    umax = 12deg,", 18, "umax", ["expected a number", "'12deg'"]),
    ("0.2 }\n}\n", "0.2 }\n", 1, None, ["'{' of line 1 is never closed"]),
    ("0.2 }\n}\n", "0.2 }\n}\n}\n", 28, None, ["'}'", "after the end of the weave block"]),
    ("    centerV = 0.75\n  },", "    centerV = 0.75\n  ,", 15, None, ["not closed before", "line 24"]),
    ("    type = warp,", "    type = wrap,", 16, "type", ["'warp' or 'weft'", "'wrap'"]),
    ("  yarn { type = warp, psi = -30, umax = 12,", "  yarn { type = warp, psi = -30, umax = 14,", 24, "umax",
     ["warp yarns disagree in umax", "yarn 1", "12", "yarn 2", "14", "limitation"]),
    ("  tileWidth = 3,", "  tileWidth = 2.5,", 3, "tileWidth", ["positive integer"]),
    ("  ss = 0,", "  ss = 0, /* unfinished", 8, None, ["never closed"]),
    ("  beta = 4,", "  beta = 4", 7, "beta", ["expected ',' or '}'"]),
    ("  beta = 4,", "  beta = 4,\n  beta = 5,", 7, "beta", ["given twice", "line 6"]),
    ("    kappa = 0,", "    kappa = -2,", 19, "kappa", ["physical range"]),
]

BASE = """weave {
  name = "test",
  tileWidth = 3,
  tileHeight = 2,
  alpha = 0.01,
  beta = 4,
  hWidth = 0.5,
  ss = 0,
  warpArea = 4,
  weftArea = 2,
  pattern {
    3, 2, 1,
    4, 1, 1
  },
  yarn {
    type = warp,
    psi = -30,
    umax = 12,
    kappa = 0,
    width = 1, length = 2,
    centerU = 0.5,
    centerV = 0.75
  },
  yarn { type = warp, psi = -30, umax = 12, kappa = 0, width = 1, length = 2, centerU = 0.1, centerV = 0.2 },
  yarn { type = weft, psi = -30, umax = 30, kappa = 0, width = 1, length = 1, centerU = 0.1, centerV = 0.7 },
  yarn { type = weft, psi = -30, umax = 30, kappa = 0, width = 1, length = 1, centerU = 0.1, centerV = 0.2 }
}
"""


def test_base_file_is_valid():
    w = parse_wv_text(BASE)
    assert w.pattern.shape == (2, 3) and len(w.segments) == 4


@pytest.mark.parametrize("old,new,line,field,words", BAD_FILES)
def test_errors_name_file_line_and_field(tmp_path, old, new, line, field, words):
    assert old in BASE
    path = tmp_path / "bad.wv"
    path.write_text(BASE.replace(old, new, 1))
    with pytest.raises(InputError) as err:
        parse_wv(path)
    e = err.value
    assert e.path == str(path) and e.line == line and e.field == field, str(e)
    assert str(path) in str(e) and f":{line}" in str(e)
    for word in words:
        assert word in str(e)


def test_missing_file_and_missing_kind(tmp_path):
    with pytest.raises(InputError, match="not found"):
        parse_wv(tmp_path / "absent.wv")
    only_warp = BASE.replace("type = weft", "type = warp").replace("umax = 30", "umax = 12").replace(
        "length = 1", "length = 2")
    with pytest.raises(InputError, match="no weft yarn"):
        parse_wv_text(only_warp, source="x.wv")


# --- segment constraint (sec. 5.3) -----------------------------------------------------------------------


def test_only_the_twill_weft_violates_the_segment_constraint():
    for name in PRESET_NAMES:
        messages = segment_constraint_violations(get_preset(name))
        if name != "cotton-twill":
            assert messages == [], name
    (message,) = segment_constraint_violations(get_preset("cotton-twill"))
    assert 2 * math.sin(math.radians(36)) > 1  # the published numbers: w = 2, umax = 36 deg, l = 1
    for word in ("cotton-twill", "weft", "2 * sin(36 deg)", "1.176", "l = 1", "5.3"):
        assert word in message


def test_constraint_boundary():
    lining = get_preset("polyester-lining")  # w = 2, l = 1: the bound is umax = 30 deg
    assert len(segment_constraint_violations(lining.with_geometry("warp", w=2.0, umax=30.5, l=1.0))) == 1
    assert segment_constraint_violations(lining.with_geometry("warp", w=2.0, umax=29.5, l=1.0)) == []


# --- pattern lookup ---------------------------------------------------------------------------------------

#: The published centres are rounded to 3-4 digits (e.g. 0.167 for 1/6: 0.002 cells off in gabardine).
ROUNDING_TOLERANCE = 0.005


def rectangle_excess(weave: Weave, u, v) -> float:
    """How far (cells) the farthest point lies outside the w x l rectangle of the segment found for it."""
    seg, x, y = locate_segments(weave, u, v)
    half_w = np.array([weave.geometry(s.kind).w for s in weave.segments])[seg] / 2
    half_l = np.array([weave.geometry(s.kind).l for s in weave.segments])[seg] / 2
    return float(max(np.max(np.abs(x) - half_w), np.max(np.abs(y) - half_l)))


def dense_grid(weave: Weave, per_cell: int = 12):
    """Points on and between cell boundaries over tiles -2..1 in u and -1..1 in v."""
    u = np.arange(-2 * weave.tile_width * per_cell, 2 * weave.tile_width * per_cell + 1) / (
        weave.tile_width * per_cell)
    v = np.arange(-weave.tile_height * per_cell, 2 * weave.tile_height * per_cell + 1) / (
        weave.tile_height * per_cell)
    return np.meshgrid(u, v)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_every_point_lies_in_the_rectangle_of_its_segment(name):
    """All six presets tile exactly (up to the rounding of the published centres)."""
    w = get_preset(name)
    u, v = dense_grid(w)
    assert rectangle_excess(w, u, v) <= ROUNDING_TOLERANCE


def test_rectangle_check_detects_a_misplaced_centre():
    w = get_preset("polyester-lining")
    moved = (replace(w.segments[0], center_u=0.75),) + w.segments[1:]
    u, v = dense_grid(w)
    assert rectangle_excess(replace(w, segments=moved), u, v) > 0.4


def test_lookup_spot_values():
    denim = get_preset("cotton-denim")  # bottom-left cell is yarn 2 (warp), centre (0.1667, -0.25)
    seg, x, y = locate_segments(denim, [0.1, -0.9], [0.05, 3.05])
    assert [denim.segments[i].yarn for i in seg] == [2, 2]
    np.testing.assert_allclose(x, [0.3 - 0.5001] * 2, atol=1e-12)  # U = 0.3, centre U = 0.5001
    np.testing.assert_allclose(y, [0.3 + 1.5] * 2, atol=1e-12)  # V = 0.3, centre V = -1.5

    lining = get_preset("polyester-lining")  # rows from the top: 3 2 / 1 4
    seg, _, _ = locate_segments(lining, [0.25, 0.75, 0.25, 0.75], [0.75, 0.75, 0.25, 0.25])
    assert [lining.segments[i].yarn for i in seg] == [3, 2, 1, 4]
    seg, x, y = locate_segments(lining, 0.85, 0.2)  # weft 4, centre (1.5, 0.5) cells, point (1.7, 0.4)
    assert lining.segments[int(seg)].yarn == 4
    np.testing.assert_allclose([x, y], [0.1, 0.2], atol=1e-12)  # weft: x = -dV, y = dU

    shantung = get_preset("silk-shantung")  # yarn 4: weft centred at U = -1 cell, outside the tile
    seg, x, y = locate_segments(shantung, 0.1, 0.1)  # point (0.6, 0.8) cells
    assert shantung.segments[int(seg)].yarn == 4
    np.testing.assert_allclose([x, y], [-(0.8 - 2.0), 0.6 + 1.0], atol=1e-3)


def test_lookup_is_periodic_and_vectorised():
    w = get_preset("silk-charmeuse")
    rng = np.random.default_rng(3)
    u, v = rng.uniform(-3, 3, 500), rng.uniform(-3, 3, 500)
    seg0, x0, y0 = locate_segments(w, u, v)
    seg1, x1, y1 = locate_segments(w, u + 7, v - 4)
    assert seg0.shape == (500,) and seg0.dtype.kind == "i"
    assert np.array_equal(seg0, seg1)
    np.testing.assert_allclose(x0, x1, atol=1e-9)
    np.testing.assert_allclose(y0, y1, atol=1e-9)
