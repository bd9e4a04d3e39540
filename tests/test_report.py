"""Tests of clothlab.report: HTML/PNG/JSON report of a saved fit directory, and the comparison page.

The fit directories are synthetic (numpy only, no model code): a cross-shaped anisotropic lobe plus a
diffuse term, 'measured' with multiplicative log-normal noise.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

EXITANT = ((0.0, 0.0), (30.0, 0.0), (30.0, 45.0), (30.0, 90.0), (30.0, 135.0), (60.0, 0.0), (60.0, 90.0))
CHANNELS = ("R", "G", "B")


def _unit(theta, phi):
    t, p = np.deg2rad(theta), np.deg2rad(phi)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def _synthetic_brdf(theta_i, phi_i, theta_o, phi_o):
    """(N, 3) components diffuse, warp bar, weft bar of a cross-shaped synthetic BRDF (1/sr)."""
    h = _unit(theta_i, phi_i) + _unit(theta_o, phi_o)
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    warp = np.exp(-((h[:, 1] / 0.07) ** 2)) * np.exp(-((h[:, 0] / 0.45) ** 2))  # warp yarns run along +y
    weft = np.exp(-((h[:, 0] / 0.10) ** 2)) * np.exp(-((h[:, 1] / 0.30) ** 2))
    return np.stack([np.ones_like(warp), warp, weft], axis=-1)


KD = {"R": 0.12, "G": 0.03, "B": 0.025}
KS_WARP = {"R": 1.5, "G": 0.6, "B": 0.5}
KS_WEFT = {"R": 0.4, "G": 0.2, "B": 0.2}


def _write_csv(path: Path, columns: dict) -> None:
    names = list(columns)
    n = len(next(iter(columns.values())))
    lines = [",".join(names)]
    for k in range(n):
        cells = [columns[c][k] for c in names]
        lines.append(",".join(c if isinstance(c, str) else repr(float(c)) for c in cells))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_synthetic_fit_dir(root, name="synthetic-denim", *, seed=0, n_theta=15, n_phi=15, noise=0.2,
                            fabric="cotton-denim", with_optional=True, paper=True) -> Path:
    """Write fits/<name>/ (fit.json, predictions.csv, slices.csv, trace.csv) from numpy values only; with
    ``paper`` the measurement's provenance names ``fabric`` as the paper fabric the data are."""
    rng = np.random.default_rng(seed)
    fit_dir = Path(root) / name
    fit_dir.mkdir(parents=True)
    ti, pi = np.meshgrid(np.linspace(5.0, 75.0, n_theta), np.arange(n_phi) * 360.0 / n_phi, indexing="ij")
    ti, pi = ti.ravel(), pi.ravel()
    rows = {k: [] for k in ("theta_i", "phi_i", "theta_o", "phi_o")}
    for to, po in EXITANT:
        rows["theta_i"].append(ti)
        rows["phi_i"].append(pi)
        rows["theta_o"].append(np.full_like(ti, to))
        rows["phi_o"].append(np.full_like(ti, po))
    table = {k: np.concatenate(v) for k, v in rows.items()}
    comps = _synthetic_brdf(table["theta_i"], table["phi_i"], table["theta_o"], table["phi_o"])
    for c in CHANNELS:
        parts = comps * np.array([KD[c], KS_WARP[c], KS_WEFT[c]])
        model = parts.sum(axis=1)
        table[f"measured_{c}"] = model * np.exp(noise * rng.standard_normal(model.size))
        table[f"model_{c}"] = model
        if with_optional:
            table[f"sigma_{c}"] = noise * model
            table[f"diffuse_{c}"], table[f"specular_warp_{c}"], table[f"specular_weft_{c}"] = parts.T
    _write_csv(fit_dir / "predictions.csv", table)

    if with_optional:
        signed = np.arange(-89.0, 89.5, 1.0)
        sl = {k: [] for k in ("theta_o", "phi_o", "signed_theta_i")}
        for to, po in EXITANT:
            sl["theta_o"].append(np.full_like(signed, to))
            sl["phi_o"].append(np.full_like(signed, po))
            sl["signed_theta_i"].append(signed)
        sl = {k: np.concatenate(v) for k, v in sl.items()}
        phi_in = np.where(sl["signed_theta_i"] >= 0, sl["phi_o"] + 180.0, sl["phi_o"])
        comps = _synthetic_brdf(np.abs(sl["signed_theta_i"]), phi_in, sl["theta_o"], sl["phi_o"])
        for c in CHANNELS:
            sl[f"model_{c}"] = comps @ np.array([KD[c], KS_WARP[c], KS_WEFT[c]])
        _write_csv(fit_dir / "slices.csv", sl)

        n_eval = 300
        value = 10.0 * np.exp(-np.arange(n_eval) / 60.0) * (1.0 + rng.random(n_eval)) + 0.5
        _write_csv(fit_dir / "trace.csv", {
            "evaluation": np.arange(1, n_eval + 1), "time_s": 0.01 * np.arange(1, n_eval + 1), "value": value,
            "best": np.minimum.accumulate(value), "stage": ["global"] * 200 + ["local"] * 100})

    fit = {
        "name": name, "created": "2025-01-01T12:00:00+00:00", "clothlab_version": "0.1.0",
        "versions": {"numpy": np.__version__, "nlopt": "2.9.1"}, "config_hash": "abc123<&>",
        "config": {"name": fabric, "model": {"kind": "irawan"}},
        "model": {"kind": "irawan", "weave": f"preset:{fabric}", "quadrature": {"rule": "trapezoid", "nodes": 11}},
        "measurement": {"path": "measurements/sim.csv", "n": int(table["theta_i"].size), "channels": list(CHANNELS),
                        "provenance": {"simulated": True, "instrument": "virtual gonioreflectometer",
                                       **({"paper_fabric": fabric} if paper else {})}},
        "parameters": {
            "warp.umax": {"value": 12.3, "unit": "deg", "free": True, "lower": 1, "upper": 85, "start": 30.0,
                          "at_bound": None, "truth": 12.0},
            "warp.kappa": {"value": -0.5, "unit": "", "free": True, "lower": -0.5, "upper": 5.0, "start": 0.0,
                           "at_bound": "lower", "truth": -0.3},
            "alpha": {"value": 0.05, "unit": "", "free": False, "lower": 0.0, "upper": 1.0, "start": 0.05,
                      "at_bound": None},
        },
        "coefficients": {"kd": KD, "ks_warp": KS_WARP, "ks_weft": KS_WEFT},
        "metric": "relative",
        "errors": {"overall": {"p50": 0.1, "p80": 0.2, "p95": 0.3, "mean": 0.12, "n": 10}, "per_channel": {}},
        "objective": {"start": 20.0, "final": 0.51}, "evaluations": 300, "wall_time_s": 3.0, "seed": seed,
        "optimizer": {"global": "GN_CRS2_LM", "local": "LN_BOBYQA", "max_evals": 4000},
        "warnings": ["warp.kappa ended at its lower bound <check>"],
    }
    (fit_dir / "fit.json").write_text(json.dumps(fit, indent=1), encoding="utf-8")
    return fit_dir


# ---------------------------------------------------------------------------------------------- tests

import pytest  # noqa: E402

from clothlab.errors import InputError, ResultExistsError  # noqa: E402
from clothlab.report import build, plots  # noqa: E402

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SMALL = {"n_theta": 5, "n_phi": 8}  # 40 incident directions per exitant direction keeps the tests fast


def _independent_percentiles(fit_dir: Path, channels=CHANNELS, qs=(50, 80, 95)):
    """Percentiles of |model - measured| / measured read back with numpy's own CSV reader."""
    table = np.genfromtxt(fit_dir / "predictions.csv", delimiter=",", names=True)
    per = {c: np.abs(table[f"model_{c}"] - table[f"measured_{c}"]) / table[f"measured_{c}"] for c in channels}
    pooled = np.concatenate(list(per.values()))
    return ({q: np.percentile(pooled, q) for q in qs},
            {c: {q: np.percentile(e, q) for q in qs} for c, e in per.items()})


def _leftovers(reports_dir: Path):
    """Hidden temporary entries (atomic-write leftovers) in a reports directory."""
    return [p.name for p in reports_dir.iterdir() if p.name.startswith(".")] if reports_dir.exists() else []


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    fit_dir = write_synthetic_fit_dir(root / "fits", **SMALL)
    report = build.build_report(fit_dir, root / "reports")
    return fit_dir, report


def test_report_page_holds_parameters_and_independent_percentiles(built):
    fit_dir, report = built
    page = (report / "index.html").read_text(encoding="utf-8")
    for name in ("warp.umax", "warp.kappa", "alpha", "kd", "ks_warp", "ks_weft"):
        assert name in page
    overall, per_channel = _independent_percentiles(fit_dir)
    for q in (50, 80, 95):
        assert f"{100 * overall[q]:.1f} %" in page
        for c in CHANNELS:
            assert f"{100 * per_channel[c][q]:.1f} %" in page
    assert "SIMULATED data" in page
    assert "at lower bound" in page  # warp.kappa sits at its lower bound
    assert "18 %" in page and "34 %" in page  # the paper's cotton-denim figures are quoted
    assert "records overall p50 = 0.1" in page  # fit.json's recorded errors disagree with predictions.csv


def test_report_escapes_text_from_the_fit_file(built):
    page = (built[1] / "index.html").read_text(encoding="utf-8")
    assert "abc123&lt;&amp;&gt;" in page and "abc123<&>" not in page
    assert "&lt;check&gt;" in page and "<check>" not in page


def test_report_figures_are_valid_pngs_referenced_by_the_page(built):
    report = built[1]
    page = (report / "index.html").read_text(encoding="utf-8")
    pngs = sorted(report.glob("*.png"))
    assert {p.stem for p in pngs} == {"hemispheres", "slices", "error_histogram", "parameters", "trace"}
    for png in pngs:
        data = png.read_bytes()
        assert data[:8] == PNG_SIGNATURE and len(data) > 1000
        assert f'src="{png.name}"' in page


def test_summary_json_parses_and_matches_independent_values(built):
    fit_dir, report = built
    summary = json.loads((report / "summary.json").read_text(encoding="utf-8"))
    overall, per_channel = _independent_percentiles(fit_dir)
    for q in (50, 80, 95):
        assert summary["errors"]["overall"][f"p{q}"] == pytest.approx(overall[q], rel=1e-12)
        assert summary["errors"]["per_channel"]["G"][f"p{q}"] == pytest.approx(per_channel["G"][q], rel=1e-12)
    assert summary["errors"]["overall"]["n"] == 7 * 40 * 3
    fit = json.loads((fit_dir / "fit.json").read_text(encoding="utf-8"))
    assert summary["parameters"] == fit["parameters"]
    assert summary["coefficients"] == fit["coefficients"]
    assert summary["timing"]["evaluations"] == 300
    assert summary["measurement"]["simulated"] is True


def test_rerun_needs_force_and_force_replaces(tmp_path):
    fit_dir = write_synthetic_fit_dir(tmp_path / "fits", with_optional=False, **SMALL)
    reports = tmp_path / "reports"
    report = build.build_report(fit_dir, reports)
    with pytest.raises(ResultExistsError):
        build.build_report(fit_dir, reports)
    fit = json.loads((fit_dir / "fit.json").read_text(encoding="utf-8"))
    fit["warnings"] = ["a brand-new warning"]
    (fit_dir / "fit.json").write_text(json.dumps(fit), encoding="utf-8")
    assert "a brand-new warning" not in (report / "index.html").read_text(encoding="utf-8")
    assert build.build_report(fit_dir, reports, force=True) == report
    assert "a brand-new warning" in (report / "index.html").read_text(encoding="utf-8")
    assert _leftovers(reports) == []


def test_failure_midway_leaves_no_partial_report(tmp_path, monkeypatch):
    fit_dir = write_synthetic_fit_dir(tmp_path / "fits", **SMALL)
    reports = tmp_path / "reports"

    def broken(*args, **kwargs):
        raise RuntimeError("plot failed")

    monkeypatch.setattr(plots, "plot_fit_trace", broken)  # the last figure: the others are already written
    with pytest.raises(RuntimeError, match="plot failed"):
        build.build_report(fit_dir, reports)
    assert not (reports / "synthetic-denim").exists()
    assert _leftovers(reports) == []


def test_failed_forced_rebuild_keeps_the_old_report(tmp_path, monkeypatch):
    fit_dir = write_synthetic_fit_dir(tmp_path / "fits", with_optional=False, **SMALL)
    reports = tmp_path / "reports"
    report = build.build_report(fit_dir, reports)
    before = (report / "index.html").read_bytes()
    monkeypatch.setattr(plots, "plot_parameters", lambda fit: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        build.build_report(fit_dir, reports, force=True)
    assert (report / "index.html").read_bytes() == before
    assert _leftovers(reports) == []


@pytest.mark.parametrize("broken_file, content, expect", [
    ("fit.json", None, "fit.json: file not found"),
    ("fit.json", '{"name": "x", "parameters": {', "fit.json:1: invalid JSON"),
    ("fit.json", '{"name": "../escape"}', "field 'name'"),
    ("predictions.csv", None, "predictions.csv: file not found"),
    ("predictions.csv", "theta_i,phi_i,theta_o,phi_o,measured_R,model_R\n1,2,3,4,0.5,0.4\n1,2,3,x4,0.5,0.4\n",
     "predictions.csv:3, field 'phi_o': value 'x4' is not a number"),
    ("predictions.csv", "theta_i,phi_i,theta_o,measured_R,model_R\n1,2,3,0.5,0.4\n", "missing column(s) ['phi_o']"),
    ("predictions.csv", "theta_i,phi_i,theta_o,phi_o,measured_R,model_R\n1,2,3,4,0.5,0.4\n",
     "column(s) ['measured_G', 'model_G'"),
])
def test_bad_input_names_the_file(tmp_path, broken_file, content, expect):
    fit_dir = write_synthetic_fit_dir(tmp_path / "fits", with_optional=False, **SMALL)
    target = fit_dir / broken_file
    if content is None:
        target.unlink()
    else:
        target.write_text(content, encoding="utf-8")
    with pytest.raises(InputError) as info:
        build.build_report(fit_dir, tmp_path / "reports")
    assert expect in str(info.value)
    assert not (tmp_path / "reports").exists() or list((tmp_path / "reports").iterdir()) == []


def test_comparison_lists_every_fit_with_the_papers_figures(tmp_path):
    fits = [write_synthetic_fit_dir(tmp_path / "fits", name=n, fabric=f, seed=k, with_optional=False, **SMALL)
            for k, (n, f) in enumerate([("denim-a", "cotton-denim"), ("lining-b", "Polyester_Lining"),
                                        ("mystery-c", "burlap")])]
    out = build.build_comparison(fits, tmp_path / "reports")
    page = (out / "index.html").read_text(encoding="utf-8")
    for name in ("denim-a", "lining-b", "mystery-c"):
        assert name in page
    for paper_value in ("18 %", "34 %", "19 %", "39 %"):
        assert paper_value in page
    assert "real measurements" in page
    for fit_dir in fits:
        overall, _ = _independent_percentiles(fit_dir)
        assert f"{100 * overall[80]:.1f} %" in page
    png = (out / "comparison.png").read_bytes()
    assert png[:8] == PNG_SIGNATURE and len(png) > 1000
    rows = json.loads((out / "summary.json").read_text(encoding="utf-8"))["rows"]
    assert [r["paper"] for r in rows] == [[18.0, 34.0], [19.0, 39.0], None]
    assert [r["free"] for r in rows] == [2, 2, 2]
    with pytest.raises(ResultExistsError):
        build.build_comparison(fits, tmp_path / "reports")


def test_projection_puts_warp_up_and_plane_coordinates_are_signed_towards_the_mirror():
    x, y = plots.tangent_plane_xy([30.0, 30.0], [90.0, 0.0])
    assert np.allclose([x[0], y[0]], [0.0, 0.5]) and np.allclose([x[1], y[1]], [0.5, 0.0])
    # exitant azimuth 90 (along the warp): the mirror side is azimuth 270
    signed, distance = plots.incidence_plane_coordinates([40.0, 40.0, 40.0], [270.0, 90.0, 0.0], 30.0, 90.0)
    assert np.allclose(signed[:2], [40.0, -40.0]) and np.allclose(distance[:2], 0.0, atol=1e-12)
    assert distance[2] == pytest.approx(40.0)  # perpendicular to the plane: off by theta itself


def test_hemisphere_discs_mark_the_exitant_direction_in_tangent_plane_coordinates(built):
    from matplotlib.figure import Figure

    from clothlab.report.data import load_fit_dir

    record = load_fit_dir(built[0])
    fig = plots.plot_hemisphere_comparison(record.predictions, channel="R")
    assert isinstance(fig, Figure)
    images = {im.get_gid(): im for ax in fig.axes for im in ax.get_images()}
    assert len([g for g in images if g and g.startswith("disc:")]) == 3 * len(EXITANT)
    left, right, bottom, top = images["disc:measured:30:90"].get_extent()
    cx, cy, r = 0.5 * (left + right), 0.5 * (bottom + top), 0.5 * (right - left)
    crosses = np.concatenate([line.get_xydata() for ax in fig.axes for line in ax.get_lines()
                              if line.get_marker() == "x"])
    # theta_o = 30, phi_o = 90: on the warp axis, sin(30 deg) = 0.5 of the radius above the disc centre
    assert np.min(np.hypot(crosses[:, 0] - cx, crosses[:, 1] - (cy + 0.5 * r))) < 1e-9


def test_hemisphere_plot_survives_data_that_cannot_be_triangulated():
    n = 6
    table = {"theta_i": np.linspace(10, 60, n), "phi_i": np.zeros(n), "theta_o": np.zeros(n),
             "phi_o": np.zeros(n), "measured_Y": np.linspace(0.1, 1.0, n), "model_Y": np.linspace(0.12, 0.9, n)}
    fig = plots.plot_hemisphere_comparison(table)  # collinear incident directions: scatter fallback
    assert len(fig.axes) >= 3


def test_comparison_columns_show_the_model_setting_and_the_optimisation_time_alone():
    from clothlab.report.data import fabric_name, model_setting, optimisation_seconds

    im = {"name": "x", "model": {"kind": "irawan", "weave": "preset:cotton-denim",
                                 "quadrature": {"rule": "gauss", "nodes": 7}},
          "wall_time_s": 500.0, "timings": {"optimisation_s": 12.5, "posterior_s": 480.0, "total_s": 500.0}}
    kang = {"name": "cotton-denim-kang", "config": {"name": "cotton-denim-kang"},
            "model": {"kind": "kang", "weave": "preset:cotton-denim", "options": {"tile_nodes": 4}},
            "wall_time_s": 30.0}
    assert model_setting(im) == "gauss 7" and model_setting(kang) == "tile_nodes=4"
    assert optimisation_seconds(im) == 12.5 and optimisation_seconds(kang) == 30.0
    assert fabric_name(im) == fabric_name(kang) == "cotton-denim"


def test_posterior_table_shows_every_interval_column_of_a_saved_posterior():
    from clothlab.report import html

    posterior = json.loads((Path(__file__).resolve().parents[1] / "fits" / "cotton-denim" / "posterior.json")
                           .read_text())
    page = "".join(html._posterior_section(posterior))
    for entry in posterior["parameters"].values():
        for key in ("p2.5", "p16", "median", "p84", "p97.5"):
            assert f">{html.fmt_number(entry[key])}<" in page, key


def test_comparison_of_simulated_fits_says_which_model_made_the_data(tmp_path):
    root = Path(__file__).resolve().parents[1] / "fits"
    out = build.build_comparison([root / "polyester-lining", root / "polyester-lining-kang"], tmp_path)
    page = (out / "index.html").read_text(encoding="utf-8")
    assert "generated by the irawan model" in page and "alternating=True" in page


# ------------------------------------------------------------------- page polish (issue 26 item 5)

def _page_of(tmp_path, **changes):
    """The report page (render_report_html) of the synthetic fit with ``changes`` applied to its fit.json."""
    from clothlab.report import html

    fit = json.loads((write_synthetic_fit_dir(tmp_path / "fits", **SMALL) / "fit.json").read_text())
    fit.update(changes)
    return html.render_report_html(fit, {}, {"errors": fit["errors"], "notes": ["slices.csv is absent"]})


def _sections(page: str) -> dict:
    """{h2 heading: the page text from it to the next h2}."""
    parts = page.split("<h2>")[1:]
    return {p.split("</h2>", 1)[0]: p.split("</h2>", 1)[1] for p in parts}


def _header_row(page: str, key: str) -> str:
    start = page.index(f"<tr><td><b>{key}</b></td><td>") + len(f"<tr><td><b>{key}</b></td><td>")
    depth, pos = 1, start  # the cell may hold nested tables: find its matching </td>
    while depth:
        nxt_open, nxt_close = page.find("<td", pos), page.find("</td>", pos)
        if nxt_open != -1 and nxt_open < nxt_close:
            depth, pos = depth + 1, nxt_open + 3
        else:
            depth, pos = depth - 1, nxt_close + 5
    return page[start:pos - 5]


def test_provenance_row_is_a_table_not_a_python_dict(tmp_path):
    provenance = {"instrument": "gonio <A>", "isotropic": True, "bsdf_grid": {"phi_i": 5, "samples": [8, 8]},
                  "source_header": {"angle_unit": "rad", "azimuth_offset": 12.5}}
    fit = json.loads((write_synthetic_fit_dir(tmp_path / "f0", **SMALL) / "fit.json").read_text())
    page = _page_of(tmp_path, measurement={**fit["measurement"], "provenance": provenance})
    cell = _header_row(page, "provenance")
    assert cell.startswith('<table class="kv">')
    assert "{" not in cell and "}" not in cell and "'" not in cell  # no dict / str repr
    for key in provenance:  # every key a row header of the table
        assert f"<th>{key}</th>" in cell
    assert "<th>phi_i</th><td>5</td>" in cell and "<th>samples</th><td>8, 8</td>" in cell  # nested: a table
    assert "<th>azimuth_offset</th><td>12.5</td>" in cell
    assert "gonio &lt;A&gt;" in cell


def test_dimensionless_units_show_as_a_dash(tmp_path):
    from clothlab.report import html

    parameters = {"a.ratio": {"value": 0.5, "unit": "1", "free": True, "lower": 0, "upper": 1, "start": 0.2},
                  "b.angle": {"value": 30.0, "unit": "deg", "free": True, "lower": 0, "upper": 90, "start": 10},
                  "c.none": {"value": 2.0, "free": False, "lower": 0, "upper": 5, "start": 2.0}}
    page = _page_of(tmp_path, parameters=parameters)
    rows = {name: page.split(f"<code>{name}</code>", 1)[1].split("</tr>", 1)[0] for name in parameters}
    cells = {name: [c.split(">", 1)[1] for c in row.split("</td>")[1:3]] for name, row in rows.items()}
    assert cells["a.ratio"][1] == "-" and cells["b.angle"][1] == "deg" and cells["c.none"][1] == ""
    assert ">1</td><td>free" not in page
    posterior = {"parameters": {"a.ratio": {"unit": "1", "p2.5": 0.1, "p16": 0.2, "median": 0.3, "p84": 0.4,
                                            "p97.5": 0.5, "optimum": 0.3}}, "convergence": {}}
    table = "".join(html._posterior_section(posterior))
    assert "<code>a.ratio</code></td><td>-</td>" in table


def test_informational_messages_are_notes_not_warnings(tmp_path):
    arc = ("silk warp/weft: fitted with filament_arc: full (the paper's text, R(u) on the whole arc); the exported "
           "weave.wv is rendered by the Mitsuba 0.5/0.6 irawan plugin on the shortened arc")
    bound = "warp.kappa ended at its lower bound <check>"
    page = _page_of(tmp_path, warnings=[bound, arc])
    sections = _sections(page)
    assert "Warnings from the fit" in sections and "Notes" in sections
    assert "lower bound &lt;check&gt;" in sections["Warnings from the fit"]
    assert "filament_arc" not in sections["Warnings from the fit"]
    assert "fitted with filament_arc: full" in sections["Notes"] and "slices.csv is absent" in sections["Notes"]
    only_notes = _sections(_page_of(tmp_path / "b", warnings=[arc]))
    assert "Warnings from the fit" not in only_notes and "filament_arc" in only_notes["Notes"]
