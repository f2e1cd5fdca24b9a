"""report.html: one self-contained page per run or study folder, read from the folder's files
only, that renders its plots in a browser (headless Chromium) with no console error."""

from __future__ import annotations

import csv
import json
import re
import shutil
import subprocess
import sys
import tempfile
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bodyfusion.base.errors import FusionError, InputError
from bodyfusion.runner import run
from bodyfusion.evaluation.report import write_report
from bodyfusion.evaluation.report_data import RunFolder, read_folder
from bodyfusion.evaluation.report_figures import nis_means, plan_view
from bodyfusion.evaluation.thinning import MAX_POINTS
from tests.paths import ROOT

CHROMIUM = Path("/usr/bin/chromium")
needs_chromium = pytest.mark.skipif(not CHROMIUM.exists(),
                                    reason="Chromium is not installed at /usr/bin/chromium (apt-get install chromium)")


def walkers_run(folder: Path, duration_s: float = 30.0) -> Path:
    """A run folder: two random walkers 0.5 m apart at most, their exact truth as truth.csv in
    the same folder (the layout's folder is the output folder)."""
    folder.mkdir(parents=True, exist_ok=True)
    t = np.arange(int(duration_s * 100) + 1) / 100.0
    rows = [f"{name},{ti:.2f},{ti:.2f},{0.05 * np.sin(ti):.4f},0" for name in ("walker_1", "walker_2") for ti in t]
    (folder / "truth.csv").write_text("system,t,east_m,north_m,up_m\n" + "\n".join(rows) + "\n")
    walker = (f"{{plugin: random_walk, velocity_mps: [1.0, 0.0, 0.0], rate_hz: 100, duration_s: {duration_s:g}, "
              "increment_variance_m2: 0.0004, initial_variance_m2: 0.01}")
    layout = folder / "walkers.yaml"
    layout.write_text(f"name: walkers\nsystems:\n  walker_1: {walker}\n  walker_2: {walker}\n"
                      "constraints:\n  - {between: [walker_1, walker_2], kind: max, distance_m: 0.5}\n"
                      "fuser: {method: projection, epochs: interval, interval_s: 0.5}\n"
                      "truth: {path: truth.csv, format: long, alignment: first_3m}\n"
                      "output: {plots: false}\n")
    run(layout, out_dir=folder, seed=1)
    return folder


def study_folder(folder: Path) -> Path:
    """A study folder as fusion study leaves it: summary.csv and study.json."""
    folder.mkdir(parents=True, exist_ok=True)
    header = ["layout", "outage_system", "outage_start_s", "outage_duration_s", "metric", "runs", "failed", "mean",
              "sd", "p50", "p90"]
    with (folder / "summary.csv").open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        for layout, scale in (("foot_hand", 1.0), ("dual_foot_hand", 0.7)):
            for d in (0, 30, 60):
                for metric in ("outage.end_error_m", "systems.hand_phone.horizontal_error_m.rmse"):
                    m = scale * (1.0 + 0.05 * d)
                    writer.writerow([layout, "hand_phone", 30, d, metric, 2, 0, m, 0.2 * m, m, 1.2 * m])
    (folder / "study.json").write_text(json.dumps({"name": "outage_smoke", "runs": 12, "done": 12, "failed": 0}))
    return folder


# --------------------------------------------------------------------------- the browser


class _PlotDivs(HTMLParser):
    """Ids of the ``plot-*`` divs of a page and, of those, the ones holding a drawn plotly
    figure (the class ``js-plotly-plot`` and an ``svg.main-svg`` inside)."""

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[tuple[str, str | None]] = []
        self.divs: set[str] = set()
        self.drawn: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        classes = (a.get("class") or "").split()
        ident = a.get("id") if tag == "div" and (a.get("id") or "").startswith("plot-") else None
        if ident:
            self.divs.add(ident)
        if tag == "svg" and "main-svg" in classes:
            self.drawn.update(i for t, i in self.stack if i)
        if ident and "js-plotly-plot" not in classes:
            ident = None
        if tag not in ("meta", "link", "br", "img", "input", "hr"):
            self.stack.append((tag, ident))

    def handle_endtag(self, tag: str) -> None:
        while self.stack:
            if self.stack.pop()[0] == tag:
                break


def render(page: Path, profile: Path) -> tuple[_PlotDivs, list[str]]:
    """Load ``page`` in headless Chromium: the plot divs of the DOM it built, and the console
    messages it logged (``CONSOLE`` lines of its log on stderr)."""
    proc = subprocess.run(
        [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0", "--dump-dom", page.resolve().as_uri()],
        capture_output=True, text=True, timeout=180, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    dom = _PlotDivs()
    dom.feed(proc.stdout)
    return dom, [line for line in proc.stderr.splitlines() if ":CONSOLE" in line]


@needs_chromium
def test_the_browser_check_fails_on_a_page_with_a_script_error_or_an_undrawn_plot(tmp_path):
    page = tmp_path / "broken.html"
    page.write_text('<html><body><div id="plot-a"></div><script>throw new Error("broken page")</script>'
                    "</body></html>")
    dom, console = render(page, tmp_path / "profile")
    assert dom.divs == {"plot-a"} and not dom.drawn
    assert any("Uncaught Error: broken page" in line for line in console)


@needs_chromium
def test_a_run_report_draws_every_plot_in_chromium_without_console_errors(tmp_path):
    folder = walkers_run(tmp_path / "run")
    page = write_report(folder)
    dom, console = render(page, tmp_path / "profile")
    assert console == []
    assert {"plot-trajectory", "plot-error", "plot-nees", "plot-constraints"} <= dom.divs
    assert dom.drawn == dom.divs


@needs_chromium
def test_a_study_report_draws_every_metric_in_chromium_without_console_errors(tmp_path):
    page = write_report(study_folder(tmp_path / "study"))
    dom, console = render(page, tmp_path / "profile")
    assert console == []
    assert dom.divs == {"plot-metric-0", "plot-metric-1"} and dom.drawn == dom.divs
    text = page.read_text()
    assert "outage_smoke" in text and "dual_foot_hand" in text and "outage_duration_s" in text


# --------------------------------------------------------------------------- the page


def test_the_report_is_one_file_that_needs_no_network(tmp_path):
    page = write_report(walkers_run(tmp_path / "run"))
    text = page.read_text()
    assert re.search(r"<(script|link|img|iframe)\b[^>]*\b(src|href)\s*=", text) is None  # nothing fetched
    assert text.count("<script") >= 5 and "Plotly.newPlot" in text
    assert 3e6 < page.stat().st_size < 8e6  # plotly.js (about 4.8 MB) and the data


def test_the_report_scores_the_folder_as_the_run_did_from_truth_csv_or_tum(tmp_path):
    folder = walkers_run(tmp_path / "run")
    metrics = json.loads((folder / "metrics.json").read_text())
    content = read_folder(folder)
    assert isinstance(content, RunFolder) and content.truth_source == "truth.csv"
    for name, score in content.tracks.scores.items():
        recorded = metrics["systems"][name]["horizontal_error_m"]
        assert score.metrics["horizontal_error_m"]["rmse"] == pytest.approx(recorded["rmse"], abs=1e-4)
    shutil.rmtree(folder / "tum", ignore_errors=True)
    (folder / "tum").mkdir()
    for name, truth in content.tracks.truths.items():
        rows = np.column_stack([truth.t, truth.pos_n, np.zeros((truth.t.size, 3)), np.ones(truth.t.size)])
        np.savetxt(folder / "tum" / f"{name}_truth.txt", rows)
    (folder / "truth.csv").unlink()
    from_tum = read_folder(folder)
    assert from_tum.truth_source == "tum/<system>_truth.txt"
    assert from_tum.tracks.scores["walker_1"].metrics["horizontal_error_m"] == pytest.approx(
        content.tracks.scores["walker_1"].metrics["horizontal_error_m"])


def test_a_run_folder_without_truth_shows_the_uncertainty_alone(tmp_path):
    folder = walkers_run(tmp_path / "run")
    (folder / "truth.csv").unlink()
    shutil.rmtree(folder / "tum", ignore_errors=True)  # its truth copy, where the run writes one
    text = write_report(folder).read_text()
    assert "no truth in this folder" in text and "plot-error" in text


def test_long_series_are_thinned_for_the_page(tmp_path):
    content = read_folder(walkers_run(tmp_path / "run", duration_s=450.0))  # 45,001 samples per walker
    assert len(content.tracks.trajectories["walker_1"].t) > 2 * MAX_POINTS
    assert all(len(trace.x) <= MAX_POINTS for trace in plan_view(content.tracks).data)


def test_nis_means_are_drawn_beside_their_dimension():
    metrics = {"systems": {"left_foot": {"health": {"nis": {
        "zupt": {"dof": 3, "expected": 3.0, "count": 3171, "mean": 0.66, "beyond_gate": 3},
        "zaru": {"dof": 3, "expected": 3.0, "count": 0, "mean": None, "beyond_gate": 0}}}}},
        "aiding": {"tag": {"health": {"nis": {"range": {"dof": 1, "expected": 1.0, "count": 40, "mean": 1.3}}}}}}
    bars, expected = nis_means(metrics).data
    assert list(bars.x) == ["left_foot · zupt", "tag · range"] and list(bars.y) == [0.66, 1.3]
    assert list(expected.y) == [3.0, 1.0]
    assert nis_means({"systems": {"a": {"health": {}}}}) is None


# --------------------------------------------------------------------------- the command


def fusion(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bodyfusion.cli", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, check=False)


def test_fusion_report_writes_report_html_into_the_folder(tmp_path):
    folder = study_folder(tmp_path / "study")
    proc = fusion("report", folder)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"wrote {folder / 'report.html'}"


@pytest.mark.parametrize("make, missing", [
    (lambda p: p, "no metrics.json"),
    (lambda p: (p / "metrics.json").write_text("{}") and p, "no trajectories.csv"),
    (lambda p: (p / "metrics.json").write_text("{oops") and p, "metrics.json:1: not JSON"),
    (lambda p: p / "absent", "no such folder"),
])
def test_a_folder_that_is_not_a_run_or_study_is_refused_in_one_line(tmp_path, make, missing):
    folder = make(tmp_path)
    proc = fusion("report", folder)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.count("\n") == 1 and str(folder) in proc.stderr and missing in proc.stderr, proc.stderr
    with pytest.raises(FusionError, match=re.escape(missing)):
        write_report(folder)



def test_the_study_figures_draw_one_statistic_in_html_and_png(tmp_path):
    """The HTML study figure's bars are the 95 % confidence interval of the mean, as the PNG plots
    draw it (Student t over the runs), not ± 1 sd."""
    import numpy as np
    from scipy import stats

    from bodyfusion.evaluation.report_figures import confidence_half_width, study_metric

    values = np.array([1.2, 0.8, 1.5, 1.1, 0.9])
    lo, hi = stats.t.interval(0.95, values.size - 1, loc=values.mean(), scale=stats.sem(values))
    assert confidence_half_width(float(values.std(ddof=1)), values.size) == pytest.approx((hi - lo) / 2)
    assert confidence_half_width(0.3, 1) is None
    summary = [{"layout": "walk", "outage_duration_s": str(d), "metric": "outage.end_error_m", "runs": "5",
                "failed": "0", "mean": "1.0", "sd": "0.2", "p50": "1.0", "p90": "1.3"} for d in (0, 30)]
    fig = study_metric(summary, "outage.end_error_m")
    bars = fig.data[0].error_y.array
    assert list(bars) == pytest.approx([confidence_half_width(0.2, 5)] * 2)
    assert "95 % confidence interval" in fig.layout.title.text


def test_a_geo_referenced_run_has_a_map_in_longitude_and_latitude_and_one_without_has_none(tmp_path):
    import pymap3d

    from bodyfusion.evaluation.report_figures import map_view
    from bodyfusion.sim import simulate

    sim = simulate(ROOT / "configs" / "foot_hand_gnss_outage.yaml", tmp_path / "sim", seed=0)
    run(sim.config_path, ["output.plots=false"], out_dir=tmp_path / "out")
    content = read_folder(tmp_path / "out")
    origin = content.tracks.frame.geodetic_origin
    fig = map_view(content.tracks)
    hand = next(trace for trace in fig.data if trace.name == "hand_phone")
    lat, lon, _ = pymap3d.enu2geodetic(*content.tracks.trajectories["hand_phone"].pos_n[0], *origin)
    assert hand.x[0] == pytest.approx(lon, abs=1e-9) and hand.y[0] == pytest.approx(lat, abs=1e-9)
    assert fig.layout.yaxis.scaleratio == pytest.approx(1.0 / np.cos(np.radians(origin[0])))
    assert {t.name for t in fig.data} >= {"left_foot", "hand_phone", "left_foot truth"}
    page = write_report(tmp_path / "out")
    assert 'id="plot-map"' in page.read_text()
    if CHROMIUM.exists():
        dom, console = render(page, tmp_path / "profile")
        assert console == [] and "plot-map" in dom.drawn
    assert map_view(read_folder(walkers_run(tmp_path / "walkers")).tracks) is None
    assert 'id="plot-map"' not in write_report(tmp_path / "walkers").read_text()


@pytest.fixture(scope="module")
def vicon_run_folder(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("vicon_run")
    run(ROOT / "configs" / "dual_foot_vicon.yaml", ["output.plots=false"], out_dir=folder)
    return folder


def _key_paths(doc: object, path: tuple = ()) -> list[tuple]:
    """Every key path of a JSON document (a list by its first item)."""
    found = [path] if path else []
    if isinstance(doc, dict):
        for key, value in doc.items():
            found += _key_paths(value, (*path, key))
    elif isinstance(doc, list) and doc:
        found += _key_paths(doc[0], (*path, 0))
    return found


@pytest.mark.slow
@settings(max_examples=30, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_metrics_json_of_another_shape_is_one_error_naming_it(vicon_run_folder, data):
    """Any value of metrics.json replaced by a JSON value of another kind: the report is written
    or refused naming metrics.json (an InputError), never another exception."""
    doc = json.loads((vicon_run_folder / "metrics.json").read_text())
    path = data.draw(st.sampled_from(_key_paths(doc)))
    value = data.draw(st.sampled_from([None, 5, -1.0, 1e308, "x", True, [], [1, "a"], {}, {"k": 1}]))
    *head, last = path
    parent = doc
    for key in head:
        parent = parent[key]
    parent[last] = value
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "run"
        shutil.copytree(vicon_run_folder, folder)
        (folder / "metrics.json").write_text(json.dumps(doc))
        try:
            write_report(folder)
        except InputError as err:
            assert err.path.endswith("metrics.json"), err
