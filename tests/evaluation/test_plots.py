"""Figures for papers: every plot takes a run (a ScoredRun: a run's result or what a folder
holds), returns a Figure and draws into a given Axes, saving is separate (PNG, PDF, SVG at a
dpi), σ bands on the error, start and end markers, estimate and truth told apart, methods
compared on one axes, study plots readable at a few runs."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.sections import FiguresConfig
from bodyfusion.base.types import Trajectory, TruthTrack
from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run
from bodyfusion.evaluation.consistency import NeesTrack
from bodyfusion.evaluation.figure_process import FigureProcess
from bodyfusion.evaluation.metrics import score_systems
from bodyfusion.evaluation.scored_run import ScoredTracks
from bodyfusion.evaluation.plots import (
    new_figure,
    plot_against_outage_duration,
    plot_error_cdf,
    plot_error_vs_time,
    plot_method_comparison,
    plot_nees,
    plot_trajectories,
    save_figure,
    write_run_plots,
)

MAGIC = {"png": b"\x89PNG\r\n\x1a\n", "pdf": b"%PDF", "svg": b"<?xml"}


def walk(t: np.ndarray, offset: float = 0.0, sd: float = 0.1) -> Trajectory:
    """A curved walk, ENU m, with a constant one-sigma position ``sd`` (m)."""
    pos = np.column_stack([1.2 * t, 0.5 * np.sin(0.4 * t) + offset, 0.0 * t])
    return Trajectory(t, pos, np.full((t.size, 3), sd))


@pytest.fixture()
def scored():
    """Two feet: estimates 0.1 m off their truths (one of them surveyed points), scored."""
    t = np.linspace(0.0, 10.0, 201)
    truths = {"left": TruthTrack(t, walk(t, 0.15).pos_n), "right": TruthTrack(t[::50], walk(t, -0.15).pos_n[::50],
                                                                               sparse=True)}
    estimates = {"left": walk(t, 0.25), "right": walk(t, -0.05)}
    transform, scores = score_systems(estimates, truths, alignment="none")
    return ScoredTracks(estimates, truths, transform, scores, nees_tracks())


def nees_tracks() -> dict[str, NeesTrack]:
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 100.0, 500)
    return {"a": NeesTrack(t, rng.chisquare(2, t.size)), "b": NeesTrack(t, 10.0 * rng.chisquare(2, t.size))}


def every_plot(scored):
    rts = ScoredTracks({"left": walk(scored.trajectories["left"].t, 0.2)})
    return {
        "trajectories": lambda **kw: plot_trajectories(scored, **kw),
        "methods": lambda **kw: plot_method_comparison({"filter": scored, "rts": rts}, "left", **kw),
        "error_vs_time": lambda **kw: plot_error_vs_time(scored, **kw),
        "error_cdf": lambda **kw: plot_error_cdf(scored, **kw),
        "nees": lambda **kw: plot_nees(scored, **kw),
        "outage": lambda **kw: plot_against_outage_duration({"a": {0.0: [1.0, 1.2], 30.0: [2.0, 2.5]}}, "t", **kw),
    }


@pytest.mark.parametrize("name", ["trajectories", "methods", "error_vs_time", "error_cdf", "nees", "outage"])
def test_every_plot_returns_a_figure_and_draws_into_a_given_axes(scored, name):
    draw = every_plot(scored)[name]
    own = draw()
    assert isinstance(own, Figure) and len(own.axes) == 1 and own.axes[0].lines
    panel = new_figure(12.0, 4.0)
    left, right = panel.subplots(1, 2)
    assert draw(ax=right) is panel
    assert right.lines and not left.lines and len(panel.axes) == 2


def _inside_the_figure(fig: Figure) -> bool:
    """Every drawn artist (titles, labels, tick labels, legend) lies inside the figure, to 1 px."""
    fig.canvas.draw()
    tight = fig.get_tightbbox(fig.canvas.get_renderer())
    width, height = fig.get_size_inches()
    slack = 1.0 / fig.dpi
    return tight.x0 >= -slack and tight.y0 >= -slack and tight.x1 <= width + slack and tight.y1 <= height + slack


@pytest.mark.parametrize("name", ["trajectories", "methods", "error_vs_time", "error_cdf", "nees", "outage"])
def test_every_plot_keeps_its_texts_and_legend_inside_the_figure_and_gives_the_axes_most_of_it(scored, name):
    fig = every_plot(scored)[name]()
    assert _inside_the_figure(fig)
    box = fig.axes[0].get_position(original=True)
    assert box.width > 0.5 and box.height > 0.6


def test_wide_tick_labels_and_long_legend_entries_still_fit():
    t = np.linspace(0.0, 10.0, 101)
    far = Trajectory(t, np.column_stack([-123456.7 + t, 4567890.1 + t, 0 * t]), np.full((t.size, 3), 0.1))
    fig = plot_trajectories(ScoredTracks({"a system named at length for its mounting and firmware": far}))
    assert _inside_the_figure(fig)
    crowded = plot_trajectories(ScoredTracks({f"system {'x' * 70} {k}": walk(t, k) for k in range(3)}))
    assert _inside_the_figure(crowded)  # the Axes would get less than a quarter: constrained layout
    assert fig.axes[0].get_position(original=True).width > 0.4 > crowded.axes[0].get_position(original=True).width


def test_panels_of_a_new_figure_get_constrained_layout(scored):
    panel = new_figure(12.0, 4.0)
    left, right = panel.subplots(1, 2)
    every_plot(scored)["nees"](ax=left)
    every_plot(scored)["error_cdf"](ax=right)
    assert _inside_the_figure(panel)
    assert left.get_position().x1 < right.get_position().x0


def test_nees_axis_labels_its_decades_in_plain_text_and_its_minor_ticks_when_narrow():
    """10ᵏ with Unicode superscripts, no mathtext ($...$, whose first use costs a process
    ~0.2 s); a Monte-Carlo NEES spanning under a decade still gets numbers between decades."""
    fig = plot_nees(ScoredTracks(nees=nees_tracks()))
    fig.canvas.draw()
    ax = fig.axes[0]
    major = [label.get_text() for label in ax.get_yticklabels() if label.get_text()]
    assert "10⁰" in major and "10¹" in major and not any("$" in text for text in major)
    t = np.linspace(0.0, 100.0, 500)
    narrow = plot_nees(ScoredTracks(nees={"mc": NeesTrack(t, np.random.default_rng(0).chisquare(400, t.size) / 200,
                                                          runs=200)}))
    narrow.canvas.draw()
    minor = [label.get_text() for label in narrow.axes[0].get_yticklabels(minor=True) if label.get_text()]
    assert "2" in minor and not any("$" in text for text in minor)


def test_plots_of_nothing_still_render(tmp_path):
    nothing = ScoredTracks()
    for fig in (plot_trajectories(nothing), plot_error_vs_time(nothing), plot_error_cdf(nothing), plot_nees(nothing),
                plot_method_comparison({}, "left"), plot_against_outage_duration({}, "none")):
        assert save_figure(fig, tmp_path / "empty")[0].stat().st_size > 1000


def test_save_figure_writes_each_format_at_the_dpi_beside_the_name(tmp_path):
    fig = plot_error_cdf(ScoredTracks())
    written = save_figure(fig, tmp_path / "sub" / "cdf.png", ["png", "pdf", "svg"], dpi=60)
    assert [p.name for p in written] == ["cdf.png", "cdf.pdf", "cdf.svg"]
    for path in written:
        assert path.read_bytes().startswith(MAGIC[path.suffix[1:]])
    small = written[0].stat().st_size
    assert save_figure(fig, tmp_path / "cdf", dpi=240)[0].stat().st_size > 2 * small
    with pytest.raises(ValueError, match="jpg"):
        save_figure(fig, tmp_path / "cdf", ["jpg"])


def test_a_runs_plots_keep_their_png_names_and_take_the_layouts_formats(scored, tmp_path):
    names = [p.name for p in write_run_plots(tmp_path / "a", scored)]
    assert names == ["trajectory.png", "error_vs_time.png", "error_cdf.png", "nees.png"]
    figures = FiguresConfig(formats=["pdf", "svg"], dpi=80)
    written = write_run_plots(tmp_path / "b", ScoredTracks(scored.trajectories), figures)
    assert [p.name for p in written] == ["trajectory.pdf", "trajectory.svg"]


@pytest.mark.parametrize("is_scored", [True, False])
def test_the_figure_process_writes_the_files_this_process_would(scored, tmp_path, is_scored):
    run = scored if is_scored else ScoredTracks(scored.trajectories)  # the trajectory alone: no second fork
    here = write_run_plots(tmp_path / "here", run)
    with FigureProcess() as beside:  # forked in two halves: the files in the same order, the same bytes
        beside.submit(tmp_path / "beside", run, FiguresConfig())
        written = beside.written()
    assert [p.name for p in written] == [p.name for p in here] == (
        ["trajectory.png", "error_vs_time.png", "error_cdf.png", "nees.png"] if is_scored else ["trajectory.png"])
    assert all(a.read_bytes() == b.read_bytes() for a, b in zip(here, written, strict=True))


def test_a_drawing_error_in_the_figure_process_is_raised_here_with_its_traceback(scored, tmp_path):
    (tmp_path / "a_file").write_text("")
    with FigureProcess() as beside:
        beside.submit(tmp_path / "a_file" / "plots", scored, FiguresConfig())
        with pytest.raises(NotADirectoryError) as raised:
            beside.written()
    assert "in save_figure" in raised.value.__notes__[-1]


def test_the_figure_process_is_not_forked_beside_other_threads():
    import threading

    gate = threading.Event()
    other = threading.Thread(target=gate.wait)
    other.start()
    try:
        assert FigureProcess.start() is None
    finally:
        gate.set()
        other.join()


def test_error_vs_time_shades_the_2drms_band_behind_and_follows_the_errors(scored):
    scores = scored.scores
    wide = {name: Trajectory(e.t, e.pos_n, np.full_like(e.pos_sd, 5.0)) for name, e in scored.trajectories.items()}
    ax = plot_error_vs_time(ScoredTracks(wide, scored.truths, scored.transform, scores)).axes[0]
    bands = [c for c in ax.collections if isinstance(c, PolyCollection)]
    assert len(bands) == 2
    lines = [line for line in ax.lines if line.get_label() in scores]
    assert all(b.get_zorder() < min(line.get_zorder() for line in lines) and b.get_alpha() < 0.5 for b in bands)
    top = bands[0].get_paths()[0].vertices[:, 1].max()
    assert top == pytest.approx(2.0 * np.hypot(5.0, 5.0))  # 2 √(σE² + σN²)
    errors = max(float(np.max(s.horizontal_error_m)) for s in scores.values())
    assert ax.get_ylim()[1] == pytest.approx(1.1 * errors)  # the 14 m band does not flatten 0.1 m errors


def test_plan_view_marks_start_and_end_and_draws_truth_in_another_style_and_colour(scored):
    estimates = scored.trajectories
    ax = plot_trajectories(scored).axes[0]
    estimate = next(line for line in ax.lines if line.get_label().startswith("left (RMSE"))
    truth = next(line for line in ax.lines if line.get_label() == "left truth")
    assert estimate.get_linestyle() == "-" and truth.get_linestyle() == "--"
    assert np.linalg.norm(np.subtract(to_rgb(estimate.get_color()), to_rgb(truth.get_color()))) > 0.1
    start = [line for line in ax.lines if line.get_marker() == "o"]
    end = [line for line in ax.lines if line.get_marker() == "s"]
    assert len(start) == len(end) == 2
    np.testing.assert_allclose(np.ravel(start[0].get_xydata()), estimates["left"].pos_n[0, :2])
    np.testing.assert_allclose(np.ravel(end[0].get_xydata()), estimates["left"].pos_n[-1, :2])
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "start" in labels and "end" in labels and "right truth (surveyed points)" in labels


def test_methods_are_compared_on_one_axes_with_their_rmse_against_the_truth():
    t = np.linspace(0.0, 10.0, 101)
    truth = {"left_foot": TruthTrack(t, walk(t).pos_n)}
    runs = {"filter": ScoredTracks({"left_foot": walk(t, 0.3)}, truth),
            "rts": ScoredTracks({"left_foot": walk(t, 0.1)}), "fb-rts": ScoredTracks({"left_foot": walk(t, 0.05)})}
    fig = plot_method_comparison(runs, "left_foot")
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[:4] == ["truth", "filter (RMSE 0.30 m)", "rts (RMSE 0.10 m)", "fb-rts (RMSE 0.05 m)"]
    colours = {line.get_color() for line in ax.lines if line.get_label() in ("filter", "rts", "fb-rts")
               or "RMSE" in line.get_label()}
    assert len(colours) == 3 and ax.get_title().startswith("left_foot")


def test_study_plot_at_two_runs_keeps_its_legend_outside_and_its_axis_on_the_runs():
    curves = {"foot_hand": {0.0: [1.0, 1.3], 60.0: [3.0, 9.0]}, "dual": {0.0: [0.8, 0.9], 60.0: [2.0, 2.2]}}
    fig = plot_against_outage_duration(curves, "end error")
    fig.canvas.draw()
    ax = fig.axes[0]
    assert ax.get_legend().get_window_extent().x0 >= ax.get_window_extent().x1
    assert ax.get_ylim()[1] == pytest.approx(1.1 * 9.0)  # not the t(1) confidence interval's ±38 m
    assert "n = 2" in ax.get_legend().get_texts()[0].get_text()
    bars = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert bars and all(b.get_zorder() < 2 and b.get_alpha() <= 0.5 for b in bars)


def test_a_layouts_output_figures_set_the_formats_and_dpi_of_the_runs_plots(write_yaml, tmp_path):
    walker = {"plugin": "random_walk", "duration_s": 2.0, "rate_hz": 50}
    layout = {"systems": {"walker": walker}, "output": {"figures": {"formats": ["pdf", "svg"], "dpi": 300}}}
    loaded = load_layout(write_yaml(layout))
    assert loaded.layout.output.figures == FiguresConfig(formats=["pdf", "svg"], dpi=300)
    assert load_layout(write_yaml({"systems": {"walker": walker}})).layout.output.figures == FiguresConfig()
    _, out = run(write_yaml(layout), out_dir=tmp_path / "out")
    assert {p.name for p in out.glob("trajectory.*")} == {"trajectory.pdf", "trajectory.svg"}


@pytest.mark.parametrize("figures, key, reason", [
    ({"formats": ["jpg"]}, "output.figures.formats.0", "'png', 'pdf' or 'svg'"),
    ({"formats": ["png", "png"]}, "output.figures.formats", "named twice"),
    ({"formats": []}, "output.figures.formats", "at least 1"),
    ({"dpi": 10}, "output.figures.dpi", "greater than or equal to 50"),
])
def test_a_bad_figures_section_is_refused_naming_its_key(write_yaml, figures, key, reason):
    layout = {"systems": {"walker": {"plugin": "random_walk"}}, "output": {"figures": figures}}
    with pytest.raises(ConfigError) as err:
        load_layout(write_yaml(layout))
    assert err.value.key == key and reason in err.value.reason


def test_a_system_keeps_its_colour_in_every_figure_png_and_html_even_where_another_is_left_out():
    """Three systems, the first without truth: the scored figures draw only the other two, each in
    the colour the plan view gives it, and the HTML report's figures use the same colours."""
    from bodyfusion.evaluation import report_figures
    from bodyfusion.evaluation.colours import system_colours

    t = np.linspace(0.0, 10.0, 201)
    estimates = {"phone": walk(t, 1.0), "left": walk(t, 0.25), "right": walk(t, -0.05)}
    truths = {"left": TruthTrack(t, walk(t, 0.15).pos_n), "right": TruthTrack(t, walk(t, -0.15).pos_n)}
    transform, scores = score_systems({k: estimates[k] for k in truths}, truths, alignment="none")
    nees = {"left": NeesTrack(t, np.full(t.size, 2.0)), "right": NeesTrack(t, np.full(t.size, 3.0))}
    run_ = ScoredTracks(estimates, truths, transform, scores, nees)
    expected = system_colours(run_)
    assert len(set(expected.values())) == 3

    def drawn(fig: Figure) -> dict[str, tuple]:
        return {line.get_label().split(" ")[0]: to_rgb(line.get_color()) for ax in fig.axes for line in ax.lines
                if line.get_label().split(" ")[0] in expected and line.get_linestyle() in ("-", "steps-post")}

    for fig in (plot_trajectories(run_), plot_error_vs_time(run_), plot_error_cdf(run_), plot_nees(run_)):
        lines = drawn(fig)
        assert lines, fig.axes[0].get_title()
        for name, rgb in lines.items():
            assert rgb == to_rgb(expected[name]), (fig.axes[0].get_title(), name)
    html = {trace.name.split(" ")[0]: trace.line.color for fig in (report_figures.plan_view(run_),
                                                                   report_figures.error_vs_time(run_))
            for trace in fig.data if trace.mode == "lines" and trace.name.split(" ")[0] in expected}
    assert html and all(colour == expected[name] for name, colour in html.items())
    metrics = {"systems": {name: {"health": {"nees": {"mean": 2.0, "profile": {"t_s": [0.0], "mean": [2.0]}}}}
                           if name in nees else {} for name in estimates}}
    (trace, *_) = report_figures.nees_profile(metrics).data
    assert trace.name.startswith("left") and trace.line.color == expected["left"]


def test_a_study_curve_has_one_colour_in_the_png_and_the_html_whatever_the_order_of_its_rows():
    from bodyfusion.evaluation import report_figures

    curves = {"foot_hand": {0.0: [1.0, 1.2], 60.0: [2.0, 2.5]}, "dual_foot_hand": {0.0: [0.8, 0.9], 60.0: [1.1, 1.3]}}
    png = {line.get_label().split(" ")[0]: to_rgb(line.get_color())
           for line in plot_against_outage_duration(curves, "t").axes[0].lines if "(mean" in line.get_label()}
    summary = [{"layout": layout, "outage_duration_s": str(d), "metric": "outage.end_error_m", "mean": str(np.mean(v)),
                "sd": "0.1", "runs": "2", "p90": str(max(v))}
               for layout in ("dual_foot_hand", "foot_hand") for d, v in curves[layout].items()]
    html = {trace.name.split(" ")[0]: to_rgb(trace.line.color)
            for trace in report_figures.study_metric(summary, "outage.end_error_m").data if trace.name.endswith("mean")}
    assert png.keys() == html.keys() == curves.keys() and png == html
