"""s004: [Shen2025] Table 2 — the forward filter (ZUPT), RTS, FB and FB-RTS on the paper's walk.

The walk is the paper's simulation (``fbrts_paper_sim.yaml``: a 783.36 m square walked 8 times
at 125 Hz, 1 s swings, ICM-20948 errors of the paper's Table 1 plus a 10 mg accelerometer bias).
Two units wear it, seed by seed:

- ``datasheet``: the unit is the datasheet — what the simulator draws is what the filter is told.
- ``real unit`` (the table): the unit differs from its datasheet the way a real MEMS part does,
  and the filter is told the datasheet only: scale factors and axis misalignments per seed
  (:data:`REAL_UNIT`), each bias drifting while the part warms up (the simulator's warm-up term,
  :mod:`bodyfusion.sim.imu`), and white noise above the datasheet's density.

Each seed's forward run is smoothed by each smoother from its record
(:func:`~bodyfusion.plugins.foot_ins.smoothing.smooth_record`); the horizontal error is taken
against the truth at every IMU sample, no alignment (the paper's reading).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from bodyfusion.core.layout import SmootherConfig
from bodyfusion.plugins.foot_ins.smoothing import smooth_record
from bodyfusion.reproduce.scenarios import over_seeds, run_simulated, simulate
from bodyfusion.reproduce.table import Cell, seed_sd
from bodyfusion.sim.imu import ImuErrorConfig

PAPER = "s004"
SCENARIO = "fbrts_paper_sim.yaml"
CASES = ("ZUPT", "RTS", "FB", "FB-RTS")
METRICS = ("h_mean_m", "h_rmse_m", "h_max_m")
TABLE_2 = {"ZUPT": (1.07, 1.32, 2.94), "RTS": (0.596, 0.723, 1.64), "FB": (0.426, 0.520, 1.23),
           "FB-RTS": (0.362, 0.460, 1.19)}
"""[Shen2025] Table 2: horizontal mean, RMSE and maximum error (m) of each algorithm."""
SMOOTHERS = {"RTS": SmootherConfig(kind="rts"), "FB": SmootherConfig(kind="fb"),
             "FB-RTS": SmootherConfig(kind="fb-rts")}


@dataclass(frozen=True)
class UnitSpread:
    """How a real unit departs from its datasheet (σ of each per-seed draw, per axis)."""

    scale_ppm: float = 3000.0
    """Scale factor error: 0.3 %, the residual of a user calibration (ICM-20948 datasheet
    tolerance ±0.5 % accelerometer, ±1.5 % gyroscope before it)."""
    misalignment_mrad: float = 2.0
    """Cross-axis coupling (datasheet: ±2 % before calibration)."""
    acc_warmup_mps2: float = 0.049
    """Accelerometer bias drift while warming up: 5 mg (datasheet 0.80 mg/°C over a 6 °C rise)."""
    gyro_warmup_radps: float = math.radians(0.05)
    """Gyroscope bias drift while warming up: 0.05 °/s (datasheet ±0.05 °/s/°C, calibrated part)."""
    warmup_tau_s: float = 300.0
    """Time constant of the warm-up (s)."""
    noise_factor: float = 1.5
    """White noise density over the datasheet's."""


REAL_UNIT = UnitSpread()
DATASHEET = ImuErrorConfig(preset="icm20948")
"""The unit's datasheet (the scenario's preset): what the filter is told."""


def unit_overrides(seed: int, spread: UnitSpread = REAL_UNIT) -> list[str]:
    """Scenario overrides that make the simulated unit of ``seed`` a real one (its scale factors
    and misalignments drawn from ``SeedSequence([seed, 2025])``)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 2025]))
    sheet = DATASHEET.resolve()
    key = "systems.foot.imu"
    out = []
    for sensor, unit, errors in (("acc", "mps2", sheet.acc), ("gyro", "radps", sheet.gyro)):
        scale = [round(float(v), 1) for v in rng.normal(0.0, spread.scale_ppm, 3)]
        tilt = [round(float(v), 4) for v in rng.normal(0.0, spread.misalignment_mrad, 6)]
        warm = spread.acc_warmup_mps2 if sensor == "acc" else spread.gyro_warmup_radps
        out += [f"{key}.{sensor}_scale_ppm={scale}", f"{key}.{sensor}_misalignment_mrad={tilt}",
                f"{key}.{sensor}_bias_warmup_{unit}={warm!r}",
                f"{key}.{sensor}_bias_warmup_tau_s={spread.warmup_tau_s!r}",
                f"{key}.{sensor}_noise_density={errors.noise_density * spread.noise_factor!r}"]
    return out


def datasheet_filter() -> list[str]:
    """Layout overrides that tell the filter the datasheet's white noise (a simulation writes
    the simulated unit's into its layout)."""
    sheet = DATASHEET.resolve()
    return [f"systems.foot.filter.acc_noise_density={sheet.acc.noise_density!r}",
            f"systems.foot.filter.gyro_noise_density={sheet.gyro.noise_density!r}"]


def seed_errors(seed: int, real_unit: bool) -> dict[str, tuple[float, float, float]]:
    """One seed: algorithm → horizontal (mean, RMSE, max) error (m) — the smoothers keep the
    filter's track where they decline (``smooth_record`` says why in its diagnostics) — and the
    filter's error along the walked direction (``ZUPT along-track``: the stride length's) and
    across it (``ZUPT cross-track``: the heading's), while walking."""
    sim_overrides = unit_overrides(seed) if real_unit else []
    sim = simulate(SCENARIO, seed, sim_overrides)
    result = run_simulated(sim, ["smoother.kind=none", *datasheet_filter()])
    rec = result.systems["foot"].smoothing_record()
    truth = result.truths["foot"]
    t = rec["t"]
    true_en = np.column_stack([np.interp(t, truth.t, truth.pos_n[:, k]) for k in range(2)])

    def errors(x: np.ndarray) -> tuple[float, float, float]:
        e = np.hypot(*(x[:, 0:2] - true_en).T)
        return float(e.mean()), float(np.sqrt(np.mean(e**2))), float(e.max())

    out = {"ZUPT": errors(rec["hist_x"])}
    for case, cfg in SMOOTHERS.items():
        smoothed = smooth_record(rec, cfg).x
        out[case] = errors(rec["hist_x"] if smoothed is None else smoothed)
    # the filter's error across and along the walked direction (the truth's over ±1 s)
    k = max(int(round(len(t) / (t[-1] - t[0]))), 1)
    ahead, behind = np.minimum(np.arange(len(t)) + k, len(t) - 1), np.maximum(np.arange(len(t)) - k, 0)
    tangent = true_en[ahead] - true_en[behind]
    length = np.hypot(*tangent.T)
    walking = length > 0.1
    tangent = tangent[walking] / length[walking, None]
    e = (rec["hist_x"][:, 0:2] - true_en)[walking]
    along = np.sum(e * tangent, axis=1)
    across = tangent[:, 0] * e[:, 1] - tangent[:, 1] * e[:, 0]
    for case, part in (("ZUPT along-track", along), ("ZUPT cross-track", across)):
        out[case] = (float(np.abs(part).mean()), float(np.sqrt(np.mean(part**2))), float(np.abs(part).max()))
    return out


def reproduce(seeds: int = 10, jobs: int = 1) -> tuple[list[Cell], str]:
    """Table 2's cells from the real unit over ``seeds`` seeds, and the comparison text (which
    also gives the datasheet unit's figures)."""
    runs = {real: over_seeds(partial(seed_errors, real_unit=real), seeds, jobs) for real in (True, False)}
    cells = [Cell.over_seeds(PAPER, case, metric, TABLE_2[case][k], [r[case][k] for r in runs[True]])
             for case in CASES for k, metric in enumerate(METRICS)]
    return cells, _text(runs, seeds)


def _text(runs: dict[bool, list[dict]], seeds: int) -> str:
    """What matches, what does not, and why, from the per-seed RMSEs."""
    def rmse(real: bool, case: str) -> np.ndarray:
        return np.array([r[case][1] for r in runs[real]])

    lines = ["# s004 — [Shen2025] forward–backward navigation and RTS smoothing (Table 2)", "",
             f"Horizontal error against the truth at every sample, {seeds} seeds, on the paper's simulated walk "
             "(783.36 m square, 125 Hz). The table is the real unit: scale factors (σ 0.3 %), misalignments "
             "(σ 2 mrad), a warm-up bias drift (σ 5 mg, 0.05 °/s, τ 300 s) and 1.5 × the datasheet's white noise, "
             "the filter told the datasheet. RMSE per algorithm (mean ± sd over seeds), each step's paired gain "
             "(mean ± sd of the per-seed difference), and the filter's RMSE along the walked direction (the stride "
             "length's error) and across it (the heading's):", ""]
    verdicts = {}
    for real, label in ((True, "real unit"), (False, "datasheet unit")):
        lines.append(f"- {label}: " + ", ".join(
            f"{case} {rmse(real, case).mean():.4f} ± {seed_sd(rmse(real, case)):.4f}" for case in CASES)
            + f" m; ZUPT along the walked direction {rmse(real, 'ZUPT along-track').mean():.4f} m, across it "
            f"{rmse(real, 'ZUPT cross-track').mean():.4f} m")
        gains = [(a, b, rmse(real, a) - rmse(real, b)) for a, b in zip(CASES, CASES[1:])]
        lines.append("  - gains: " + ", ".join(f"{a} → {b} {g.mean() * 1000:+.1f} ± {seed_sd(g) * 1000:.1f} mm"
                                             for a, b, g in gains))
        spread = max(seed_sd(rmse(real, case)) for case in CASES)
        verdicts[label] = (all(g.mean() > 0 for _, _, g in gains), all(g.mean() > spread for _, _, g in gains),
                           spread)
    ordered, beyond, spread = verdicts["real unit"]
    along, across = (float(np.mean(rmse(True, f"ZUPT {d}-track") ** 2)) for d in ("along", "cross"))
    heading = across / (along + across)
    lines += ["", "Paper: ZUPT 1.32 > RTS 0.723 > FB 0.520 > FB-RTS 0.460 m RMSE (−65 % from ZUPT to FB-RTS).",
              f"Ours, real unit: the ordering ZUPT > RTS > FB > FB-RTS {'holds' if ordered else 'does not hold'}; "
              f"{'every' if beyond else 'not every'} step's gain is larger than the seed-to-seed spread "
              f"({spread:.4f} m, the largest sd of an algorithm's RMSE).", "",
              f"Why. Of the real unit's squared filter error while walking, {heading:.0%} is across the walked "
              f"direction — heading: a gyroscope's scale factor and warm-up on the square's turns and between "
              f"them — and {1 - heading:.0%} along it — stride length: an accelerometer's scale factor and "
              "misalignment on each stride, and the heading error of the legs walked before. Neither is observed by a "
              "zero-velocity update — a scale factor of the accelerometer lengthens a stride without leaving a "
              "velocity error at the next stance, and heading is unobservable — so no smoother, which only "
              "redistributes what the updates observed, removes them; the backward pass starts from the forward "
              "heading and retraces the same gyroscope data, so fusing the two passes averages nothing "
              "independent in either. What a smoother can remove, the velocity error a swing builds up and the "
              "next stance reveals, this filter already moves into position through its position–velocity "
              "cross-covariance at that update (the segment smoothers move the horizontal track by centimetres "
              "within the swings); the whole-run RTS adds the later updates' bias information. The paper's "
              "gains need a forward filter that leaves most of each stride's revealed error in position.", ""]
    return "\n".join(lines)
