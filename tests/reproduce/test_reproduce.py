"""``fusion reproduce``: each paper's table beside ours, from seeds simulated in memory."""

from __future__ import annotations

import csv
from importlib.resources import files

import numpy as np
import pytest
import yaml

from bodyfusion.reproduce import PAPERS, reproduce
from bodyfusion.reproduce import dual_foot, kfsc2015, shen2025
from bodyfusion.reproduce.table import COLUMNS, Cell, write_reproduction
from tests.paths import ROOT
from tests.test_cli import assert_one_line_user_error
from tests.test_cli_conventions import fusion_here

SCENARIOS = ("fbrts_paper_sim.yaml", "sim_dual_foot_consumer_walk.yaml", "foot_hand_gnss_outage.yaml",
             "paper_constraint_monte_carlo.yaml")


@pytest.mark.parametrize("name", SCENARIOS)
def test_the_packaged_scenarios_are_the_repository_configs(name):
    packaged = yaml.safe_load(files("bodyfusion.examples").joinpath("files", name).read_text())
    assert packaged == yaml.safe_load((ROOT / "configs" / name).read_text())


def test_a_cell_is_the_mean_and_sample_sd_over_seeds_and_the_table_says_what_is_absent(tmp_path):
    cells = [Cell.over_seeds("s004", "RTS", "h_rmse_m", 0.723, [1.0, 2.0, 4.0]),
             Cell.over_seeds("s002", "after constraint", "rmse_m", None, [3.0])]
    assert cells[0].our_value == pytest.approx(7.0 / 3.0)
    assert cells[0].our_sd == pytest.approx(np.std([1, 2, 4], ddof=1))
    assert cells[1].our_sd is None and cells[1].n_seeds == 1
    write_reproduction(tmp_path, cells, "# text")
    with (tmp_path / "table.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == COLUMNS
    assert rows[0]["paper_value"] == "0.723" and rows[0]["n_seeds"] == "3"
    assert rows[1]["paper_value"] == "" and rows[1]["our_sd"] == ""
    readme = (tmp_path / "README.md").read_text()
    assert readme.startswith("# text") and "| RTS | h_rmse_m | 0.723 | 2.333 ± 1.5 | 3 |" in readme


def test_a_real_unit_is_drawn_per_seed_and_the_filter_keeps_the_datasheet():
    assert shen2025.unit_overrides(3) == shen2025.unit_overrides(3) != shen2025.unit_overrides(4)
    told = dict(o.split("=", 1) for o in shen2025.datasheet_filter())
    drawn = dict(o.split("=", 1) for o in shen2025.unit_overrides(3))
    assert float(drawn["systems.foot.imu.acc_noise_density"]) == pytest.approx(
        1.5 * float(told["systems.foot.filter.acc_noise_density"]))
    assert float(drawn["systems.foot.imu.gyro_bias_warmup_radps"]) > 0


@pytest.mark.slow
def test_s004_one_seed_every_smoother_runs_and_the_real_unit_is_the_worse():
    real, sheet = shen2025.seed_errors(0, True), shen2025.seed_errors(0, False)
    for case in (*shen2025.CASES, "ZUPT along-track", "ZUPT cross-track"):
        mean, rmse, worst = real[case]
        assert 0 < mean <= rmse <= worst
    assert real["ZUPT"][1] > 3 * sheet["ZUPT"][1]
    # the error while walking splits into its parts along and across the walked direction
    parts = real["ZUPT along-track"][1] ** 2 + real["ZUPT cross-track"][1] ** 2
    assert 0.8 * real["ZUPT"][1] ** 2 < parts < 1.2 * real["ZUPT"][1] ** 2
    assert sheet["RTS"][1] <= sheet["ZUPT"][1]


@pytest.mark.slow
def test_s001_from_the_command_line_writes_the_papers_cases_beside_ours(tmp_path):
    proc = fusion_here("reproduce", "s001", "--out", tmp_path, "--seeds", "2")
    assert proc.returncode == 0, proc.stderr
    with (tmp_path / "table.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["case"], r["metric"]) for r in rows] == [
        (case, metric) for case in ("MDC-KF", "MDC-cKF") for metric in (*dual_foot.METRICS, "active_fraction")]
    by = {(r["case"], r["metric"]): r for r in rows}
    assert float(by["MDC-KF", "mean_rmse_m"]["paper_value"]) == pytest.approx(9.8287)
    assert by["MDC-KF", "active_fraction"]["paper_value"] == ""
    assert all(r["n_seeds"] == "2" and float(r["our_value"]) > 0 for r in rows)
    readme = (tmp_path / "README.md").read_text()
    assert "MDC-KF → MDC-cKF" in readme and "| MDC-cKF | mean_rmse_m | 6.183 |" in readme
    again = fusion_here("reproduce", "s001", "--out", tmp_path, "--seeds", "1")  # refused before the work
    assert again.returncode == 2 and "holds README.md, table.csv" in again.stderr
    assert (tmp_path / "README.md").read_text() == readme


@pytest.mark.slow
def test_s002_the_constraint_bounds_the_phone_in_an_outage_and_halves_the_walkers_variance():
    mc = [kfsc2015.monte_carlo_errors(seed, duration_s=60.0) for seed in range(4)]
    for run in mc:
        assert len(run["before constraint"]) == len(run["after constraint"]) == 2
    outage = kfsc2015.outage_errors(0)
    for duration in kfsc2015.OUTAGES_S:
        assert outage[f"after constraint {duration:g}"] < outage[f"before constraint {duration:g}"]


@pytest.mark.parametrize(("args", "key"), [(("s999",), "PAPER"), (("s004", "--seeds", "0"), "--seeds"),
                                          (("all", "--jobs", "0"), "--jobs")])
def test_a_bad_paper_or_count_is_one_line(tmp_path, args, key):
    proc = fusion_here("reproduce", *args, "--out", tmp_path)
    assert proc.returncode == 2
    assert_one_line_user_error(proc, key)
    assert not (tmp_path / "table.csv").exists()


def test_every_paper_is_reproducible():
    assert PAPERS == ("s000", "s001", "s002", "s004")
    with pytest.raises(Exception, match="s000, s001, s002, s004 or all"):
        reproduce("s003", "/nonexistent")
