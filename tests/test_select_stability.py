"""Selection stability (issue 28 item 3, clothlab.fit.stability)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from clothlab.config import apply_overrides, load_config
from clothlab.fit.select import SelectSettings, select
from clothlab.fit.stability import orientation_range, subsample_masks, tally, verdict

EXAMPLE = Path(__file__).parent.parent / "measurements" / "scattered-twill" / "fabric.yaml"


def test_orientation_ranges_wrap_into_the_period():
    assert orientation_range(10.0, 180.0) == "0..30"
    assert orientation_range(190.0, 180.0) == "0..30"  # one period on: the same model
    assert orientation_range(-89.0, 180.0) == "-90..-60"
    assert orientation_range(None, 180.0) is None


def test_verdict_needs_a_clear_majority():
    rows = [{"weave": "preset:a", "kind": "irawan", "loss": "squared", "orientation": 10.0},
            {"weave": "preset:b", "kind": "irawan", "loss": "huber", "loss_scale": 0.1, "orientation": 12.0},
            {"weave": "preset:a", "kind": "irawan", "loss": "squared", "orientation": 100.0},
            {"weave": "preset:c", "kind": "irawan", "loss": "squared", "orientation": 14.0}]
    counts = tally(rows, {"irawan": 180.0})
    assert counts["weave"] == {"preset:a": 2, "preset:b": 1, "preset:c": 1}
    assert counts["loss"] == {"squared": 3, "huber 0.1": 1}
    v = verdict(counts, 4)
    assert v["weave"].startswith("NOT DETERMINED")  # 2 of 4 is no clear majority
    assert v["kind"] == "irawan wins 4 of 4" and v["orientation range"] == "0..30 wins 3 of 4"


def test_subsamples_are_seeded_and_of_the_stated_size():
    a, b = subsample_masks(205, 3, seed=1), subsample_masks(205, 3, seed=1)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert all(int(m.sum()) == 164 for m in a) and not np.array_equal(a[0], a[1])


def test_stability_runs_inside_select_and_lands_in_the_summary(tmp_path):
    cfg = apply_overrides(load_config(EXAMPLE), max_evals=60)
    cfg = replace(cfg, fit=replace(cfg.fit, posterior=None, cv_folds=0))
    settings = SelectSettings(weaves=("preset:wool-gabardine", "preset:cotton-denim"), kinds=("irawan",),
                              orientation_starts=1, max_evals=40, cv_folds=2, stability=3, losses=())
    s = select(cfg, settings, fits_dir=tmp_path)
    stab = s.summary()["stability"]
    assert stab["repeats"] == 3 and stab["fits"] == 6 and len(stab["winners"]) == 3
    assert sum(stab["counts"]["weave"].values()) == 3
    # the simulated table is wool-gabardine: the truth's weave wins the subsamples
    assert stab["counts"]["weave"].get("preset:wool-gabardine", 0) >= 2
    top = s.summary()["top_residuals"]
    assert [t["candidate"] for t in top] == [r.row["candidate"] for r in s.ranked]
    assert all("p80 tail" in t["summary"] and t["tail_threshold"] > 0 for t in top)
    from clothlab.report import html

    page = "".join(html._stability_section(stab))
    assert "Selection stability" in page and "wool-gabardine" in page


def test_winners_are_tallied_by_weave_family_too():
    """The family of the IM paper's fabrics (sec. 8: cotton twill, denim and gabardine twills; polyester lining and
    shantung plain; charmeuse satin) and of a generated pattern (its name's first word)."""
    from clothlab.fit.stability import weave_family

    rows = [{"weave": w, "kind": "irawan", "loss": "squared"} for w in
            ("preset:cotton-twill", "preset:wool-gabardine", "pattern:twill-3x3", "preset:silk-shantung",
             "pattern:satin-5x5")]
    counts = tally(rows)
    assert counts["weave family"] == {"twill": 3, "plain": 1, "satin": 1}
    assert verdict(counts, 5)["weave family"] == "twill wins 3 of 5"
    assert weave_family("/some/path/my.wv") == "other" and weave_family(None) is None
