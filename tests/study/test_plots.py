"""A study's plots: one per outage metric, in the study file's figure formats."""

from __future__ import annotations

from bodyfusion.base.sections import FiguresConfig
from bodyfusion.study.plots import write_plots


def rows() -> list[dict]:
    return [{"status": "ok", "layout": "foot_hand", "param.fuser.method": method, "outage.system": "hand_phone",
             "outage.duration_s": d, "outage.end_error_m": 1.0 + 0.02 * d + 0.1 * seed,
             "outage.max_error_m": 1.5 + 0.03 * d + 0.1 * seed}
            for method in ("projection", "none") for d in (0.0, 30.0, 60.0) for seed in (0, 1)]


def test_study_plots_are_written_in_the_study_files_formats(tmp_path):
    written = write_plots(tmp_path, rows(), ["param.fuser.method"], FiguresConfig(formats=["svg", "pdf"], dpi=80))
    assert [p.name for p in written] == ["end_error_vs_outage.svg", "end_error_vs_outage.pdf",
                                         "max_error_vs_outage.svg", "max_error_vs_outage.pdf"]
    assert [p.name for p in write_plots(tmp_path, rows(), ["param.fuser.method"])] == [
        "end_error_vs_outage.png", "max_error_vs_outage.png"]
