"""Reports of scattered samplings, and the report's labels and polish (clothlab.report).

The scattered set is written here: 205 random direction pairs, one channel named "grey", the IM model of the
cotton-twill preset with 5 % multiplicative noise, saved as a clothlab table and read back with the loader;
its fit directory holds the generating model as the fit (fit.json, predictions.csv, weave.wv), so the report
draws a known model without running an optimiser.
"""

from __future__ import annotations

import json
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from clothlab.errors import GeometryWarning
from clothlab.report import build, html, plots
from clothlab.report.data import paper_fabric, selection_rows, shown_channel
from clothlab.report.sampling import (
    MAX_GRID_DIRECTIONS,
    MAX_PANELS,
    MIN_GRID_ROWS,
    WINDOW_DEG,
    representative_incidents,
    sampling_layout,
)

ROOT = Path(__file__).resolve().parents[1]
TRUTH = {"kd": 0.2, "ks_warp": 0.3, "ks_weft": 0.2}


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk (bytes 16-24), independent of matplotlib and PIL."""
    data = path.read_bytes()[:24]
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def _random_directions(rng, n):
    """Directions uniform in projected solid angle up to 84 deg (cos-weighted, like a goniometer's spread)."""
    u = rng.random(n) * np.sin(np.deg2rad(84.0)) ** 2
    return np.rad2deg(np.arcsin(np.sqrt(u))), rng.random(n) * 360.0


def write_scattered_fit_dir(root: Path, n: int = 205, seed: int = 7) -> Path:
    from clothlab.fit.store import write_fit_directory
    from clothlab.frames import spherical_to_vector
    from clothlab.io.loader import load_measurement
    from clothlab.io.table import write_table
    from clothlab.models.components import combine
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.simulate.gonio import NoiseModel, simulate
    from clothlab.weave.presets import get_preset
    from clothlab.weave.wvformat import format_wv

    rng = np.random.default_rng(seed)
    ti, pi = _random_directions(rng, n)
    to, po = _random_directions(rng, n)
    weave = get_preset("cotton-twill")
    model = IrawanModel(weave)
    coefficients = {k: np.array([v]) for k, v in TRUTH.items()}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        m = simulate(model, {}, coefficients, channels=("grey",), noise=NoiseModel(multiplicative=0.05, seed=seed),
                     sampling=(ti, pi, to, po), provenance={"sample_name": "scattered test set"})
        table = write_table(m, root / "scattered.csv")
        m = load_measurement(table)
        wi, wo = spherical_to_vector(m.theta_i, m.phi_i), spherical_to_vector(m.theta_o, m.phi_o)
        predicted = combine(model.components(wi, wo, {}), coefficients)[:, 0]
    params = model.default_parameters()
    fit = {
        "name": "scattered-twill", "config": {"name": "cotton-twill"},
        "model": {"kind": "irawan", "weave": "preset:cotton-twill", "quadrature": {"rule": "trapezoid", "nodes": 11}},
        "measurement": {"path": str(table), "n": int(len(m.theta_i)), "channels": ["grey"],
                        "provenance": dict(m.provenance)},
        "parameters": {k: {"value": float(v), "free": k == "alpha", "lower": 0.0, "upper": 1.0} for k, v in
                       params.items()},
        "coefficients": {k: {"grey": v} for k, v in TRUTH.items()}, "metric": "relative",
    }
    predictions = {"theta_i": m.theta_i, "phi_i": m.phi_i, "theta_o": m.theta_o, "phi_o": m.phi_o,
                   "measured_grey": m.values[:, 0], "model_grey": predicted}
    dest = root / "fits" / fit["name"]
    write_fit_directory(dest, fit=fit, predictions=predictions, slices={"theta_o": [0.0], "phi_o": [0.0],
                                                                       "signed_theta_i": [0.0], "model_grey": [0.1]},
                        trace={"evaluation": [1, 2], "time_s": [0.1, 0.2], "value": [1.0, 0.5], "best": [1.0, 0.5],
                               "stage": ["global#1", "polish"]},
                        config_text=None, weave_text=format_wv(weave))
    return dest


@pytest.fixture(scope="module")
def scattered(tmp_path_factory):
    root = tmp_path_factory.mktemp("scattered")
    fit_dir = write_scattered_fit_dir(root)
    return fit_dir, build.build_report(fit_dir, root / "reports")


def test_scattered_report_has_fixed_panels_short_pngs_the_channel_name_and_no_paper_figures(scattered):
    fit_dir, report = scattered
    summary = json.loads((report / "summary.json").read_text())
    assert summary["sampling"]["kind"] == "scattered"
    assert {"hemispheres", "residuals", "parity", "error_histogram", "parameters", "trace"} <= set(summary["figures"])
    for png in report.glob("*.png"):
        width, height = png_size(png)
        assert height < 3000 and width < 3000, (png.name, width, height)
    page = (report / "index.html").read_text()
    assert "grey" in page and "luminance" not in page
    # the preset (and the config name) is the paper's cotton-twill, but the data are not the paper's fabric
    assert summary["paper_errors_percent"] is None
    assert "21 %" not in page and "the paper's Irawan-Marschner fit" not in page
    assert "scattered:" in page


def test_scattered_panels_are_few_and_hold_the_samples_within_their_window(scattered):
    from clothlab.report.data import load_fit_dir
    from clothlab.report.sampling import angle_between, unit_vectors

    table = load_fit_dir(scattered[0]).predictions
    panels = representative_incidents(table)
    assert 1 <= len(panels) <= MAX_PANELS
    samples = unit_vectors(table["theta_i"], table["phi_i"])
    for panel in panels:  # independent angle computation: arccos of the dot product
        centre = unit_vectors([panel.theta_i], [panel.phi_i])[0]
        within = np.flatnonzero(np.rad2deg(np.arccos(np.clip(samples @ centre, -1, 1))) <= WINDOW_DEG + 1e-9)
        assert set(within) == set(panel.rows)
    # greedy set cover: the first choice covers the most samples of any candidate
    candidates = unit_vectors(table["theta_i"], table["phi_i"])
    counts = (angle_between(candidates[:, None, :], samples[None, :, :]) <= WINDOW_DEG).sum(axis=1)
    assert max(len(p.rows) for p in panels) == counts.max()


def test_scattered_model_map_is_the_model_at_the_panel_direction(scattered):
    from clothlab.fit.store import load_fitted
    from clothlab.frames import spherical_to_vector
    from clothlab.models.components import combine
    from clothlab.report.data import load_fit_dir
    from clothlab.report.model_on_grid import load_fitted_model
    from clothlab.report.scatter_plots import exitant_disc_grid, model_maps

    record = load_fit_dir(scattered[0])
    panel = representative_incidents(record.predictions)[0]
    model, why = load_fitted_model(scattered[0])
    assert why is None
    image = model_maps(model, [panel], "grey", pixels=21)[0]
    inside, wo = exitant_disc_grid(21)
    raw, params, coefficients, _ = load_fitted(scattered[0])
    wi = np.repeat(spherical_to_vector([panel.theta_i], [panel.phi_i]), len(wo), axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        expected = combine(raw.components(wi, wo, params), coefficients)[:, 0]
    assert np.allclose(image[inside], expected, rtol=1e-12) and np.isnan(image[~inside]).all()


def test_shipped_examples_are_grid_sampled_and_keep_the_grid_figures(tmp_path):
    from clothlab.report.data import load_fit_dir

    record = load_fit_dir(ROOT / "fits" / "polyester-lining")
    layout = sampling_layout(record.predictions)
    assert layout.kind == "grid" and layout.exitant_directions == 7 and layout.min_rows == 225
    names = [name for name, _ in build._figure_jobs(record, (50, 80, 95), layout, [])]
    assert names == ["hemispheres", "slices", "error_histogram", "parameters", "trace", "corner"]


def test_layout_rule_boundaries():
    def table(n_exitant, rows):
        theta_o = np.repeat(np.linspace(0, 60, n_exitant), rows)
        return {"theta_i": np.tile(np.linspace(5, 75, rows), n_exitant), "phi_i": np.zeros(n_exitant * rows),
                "theta_o": theta_o, "phi_o": np.zeros(n_exitant * rows)}

    assert sampling_layout(table(MAX_GRID_DIRECTIONS, MIN_GRID_ROWS)).kind == "grid"
    assert sampling_layout(table(MAX_GRID_DIRECTIONS + 1, MIN_GRID_ROWS)).kind == "scattered"
    assert sampling_layout(table(3, MIN_GRID_ROWS - 1)).kind == "scattered"


def test_many_exitant_directions_and_many_parameters_stay_under_3000_px(tmp_path):
    rng = np.random.default_rng(1)
    n_exitant, rows = 40, 30
    t = {"theta_i": rng.random(n_exitant * rows) * 80, "phi_i": rng.random(n_exitant * rows) * 360,
         "theta_o": np.repeat(np.linspace(0, 70, n_exitant), rows), "phi_o": np.zeros(n_exitant * rows)}
    t["measured_Y"] = 0.1 + rng.random(t["theta_i"].size)
    t["model_Y"] = t["measured_Y"] * 1.05
    build.save_figure(plots.plot_hemisphere_comparison(t), tmp_path / "h.png")
    samples = {f"p{k}": rng.standard_normal(400) for k in range(16)}
    build.save_figure(plots.plot_corner(samples, {}, {}), tmp_path / "c.png")
    for name in ("h.png", "c.png"):
        assert png_size(tmp_path / name)[1] < 3000


def test_log_ticks_label_a_range_under_a_decade():
    for vmin, vmax in ((0.12, 0.5), (0.031, 0.034), (2e-5, 3.0), (1.0, 1.01)):
        ticks = plots.log_ticks(vmin, vmax)
        assert len(ticks) >= 2 and len(ticks) <= 6
        assert all(vmin * (1 - 1e-6) <= t <= vmax * (1 + 1e-6) or len(ticks) == 3 for t in ticks)
        assert all(plots.tick_labels(ticks))
    assert plots.log_ticks(1e-4, 1.0) == [1e-4, 1e-3, 1e-2, 1e-1, 1.0]


def test_narrow_log_colour_bar_has_tick_labels():
    n = 60
    rng = np.random.default_rng(0)
    t = {"theta_i": rng.random(n) * 80, "phi_i": rng.random(n) * 360, "theta_o": np.zeros(n), "phi_o": np.zeros(n),
         "measured_grey": 0.2 + 0.05 * rng.random(n)}
    t["model_grey"] = t["measured_grey"] * 1.01
    fig = plots.plot_hemisphere_comparison(t)
    fig.canvas.draw() if hasattr(fig.canvas, "draw") else None
    bars = [ax for ax in fig.axes if "BRDF" in ax.get_xlabel()]
    assert len(bars) == 1 and "grey" in bars[0].get_xlabel()
    labels = [label.get_text() for label in bars[0].get_xticklabels()]
    assert len([x for x in labels if x]) >= 2


def test_channel_label_is_the_name_given():
    assert shown_channel(("grey",)) == ("grey", "grey")
    assert shown_channel(("R", "G", "B"))[1] == "mean of R, G, B"


def test_paper_figures_follow_the_provenance_not_the_preset():
    base = {"name": "cotton-twill", "config": {"name": "cotton-twill"},
            "model": {"kind": "irawan", "weave": "preset:cotton-twill"}}
    assert paper_fabric({**base, "measurement": {"provenance": {"sample_name": "lab twill"}}}) is None
    assert paper_fabric({**base, "measurement": {"provenance": {"paper_fabric": "Cotton Twill"}}}) == "cotton-twill"
    assert paper_fabric({**base, "measurement": {"provenance": {"paper_fabric": "none",
                                                                "generator": "clothlab simulate"}}}) is None
    shipped = json.loads((ROOT / "fits" / "cotton-twill" / "fit.json").read_text())  # clothlab's own example
    assert paper_fabric(shipped) == "cotton-twill"


def test_kang_rows_do_not_show_the_papers_im_figures(tmp_path):
    out = build.build_comparison([ROOT / "fits" / "polyester-lining", ROOT / "fits" / "polyester-lining-kang"],
                                 tmp_path)
    rows = json.loads((out / "summary.json").read_text())["rows"]
    assert [r["paper"] for r in rows] == [[19.0, 39.0], None]
    page = (out / "index.html").read_text()
    assert "comparison: comparison" not in page and "clothlab comparison of 2 fits" in page
    assert "white-space: nowrap" in page


def test_selection_section_renders_when_present_and_not_otherwise():
    fit = json.loads((ROOT / "fits" / "scattered-twill" / "fit.json").read_text())
    candidates = fit["selection"]["candidates"]
    assert len(selection_rows(fit)) == len(candidates) >= 2
    text = "".join(html._selection_section(fit))
    assert "runners-up" in text and fit["selection"]["ranking"] in text
    first, second = candidates[0], candidates[1]
    assert f"{first['candidate']} (winner, this fit)" in text and f"{second['candidate']} (winner" not in text
    assert text.index(first["candidate"]) < text.index(second["candidate"])  # ranked order kept
    for row in (first, second):  # errors in %, as selection.md shows them
        assert f"{100 * row['cv_mean']:.2f}" in text and f"{row['aic']:.1f}" in text
    table = text[text.index("<table>"):]
    assert table.index("CV mean %") < table.index("<th>AIC") < table.index("<th>BIC")
    assert html._selection_section({}) == [] and html._selection_section({"selection": "x"}) == []


def test_polish_of_the_page_text():
    conv = {"parameters": {}, "convergence": {"converged": True, "stop_reason": "converged", "steps": 10}}
    text = "".join(html._posterior_section(conv))
    assert "converged (converged)" not in text and "Convergence: converged" in text
    assert html.stage_times({"optimisation_s": 14.632694102999949, "posterior_s": 203.69, "total_s": 1}) == \
        "optimisation 14.6 s; posterior 204 s"
    header = "".join(html._header_section({"name": "x", "model": {}, "measurement": {}}))
    assert "<th></th>" not in header
    params = {"parameters": {"a": {"value": 1.0, "free": True, "lower": 0, "upper": 2}}}
    assert "status" not in "".join(html._parameter_section(params))


def test_trace_colours_of_polish_and_the_first_global_start_differ():
    trace = {"evaluation": np.arange(6.0), "time_s": np.arange(6.0), "value": np.linspace(2, 1, 6),
             "best": np.linspace(2, 1, 6), "stage": np.array(["global#1", "global#1", "local#1", "local#1",
                                                              "polish", "polish"])}
    fig = plots.plot_fit_trace(trace)
    colours = {line.get_label(): line.get_color() for line in fig.axes[0].get_lines()
               if line.get_label().startswith("best so far")}
    assert len(set(colours.values())) == 3, colours


def test_every_shipped_scene_comment_command_parses():
    import shlex

    from clothlab.cli.main import build_parser
    from clothlab.cli.render import DEFAULT_DIR

    commands = [line.split("#", 1)[1].strip() for scene in [*(ROOT / "measurements").glob("*/scene*.yaml"),
                                                             *(ROOT / "measurements" / "scenes").glob("*.yaml")]
                for line in scene.read_text().splitlines() if line.lstrip().startswith("#   clothlab render")]
    assert commands
    for command in commands:
        args = build_parser().parse_args(shlex.split(command)[1:])
        assert args.output is not None or DEFAULT_DIR.name == "renders"
    args = build_parser().parse_args(["render", "x/scene.yaml"])
    assert args.output is None  # the default stem renders/<scene stem> is applied in cli.render.run
