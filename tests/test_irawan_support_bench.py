"""The speed section's support-vs-trapezoid-11 table (issue 12 item 4): structure only, no timing asserted
(speed targets live in ``clothlab bench``, never in timed tests)."""

from __future__ import annotations

from clothlab.studies import model_speed


def test_support_vs_trapezoid_table():
    out = model_speed.support_vs_trapezoid(quick=True, fabrics=("cotton-denim",))
    row = out["cotton-denim"]
    for mode in ("warm", "cold"):
        r = row[mode]
        assert r["trapezoid11_ms"] > 0
        for n in model_speed.SUPPORT_NODES:
            assert r[f"support{n}_ms"] > 0 and r[f"support{n}_ratio"] > 0
    assert set(row["within_target"]) == set(model_speed.SUPPORT_NODES)
    text = "\n".join(model_speed.support_lines(out))
    assert "support rule vs trapezoid-11" in text and "cotton-denim       warm" in text
    assert "within the target (warm): support-4 on" in text
