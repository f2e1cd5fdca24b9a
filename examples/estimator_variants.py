"""KF, cKF, EnEKF and cEnEKF on both feet, with and without the inter-foot distance constraint.

The dual-foot papers' tables ([Xu2024] MDC-KF / MDC-cKF, [Deng2026] DC-KF … DC-cEnEKF)
compare estimators that all run under a distance constraint (DC); this example also runs
each estimator on independent feet, so the constraint's own share is measured.

1. Simulation (``configs/sim_dual_foot_consumer_walk.yaml``): a 240 m open route (~195 s)
   at 100 Hz with a consumer-grade IMU on each foot (preset ``consumer``: gyro bias
   instability 100 °/h, angle random walk 1 °/√h, accelerometer bias instability 2 mg,
   turn-on biases) and the coloured stance noise of both papers (each foot drifts in stance
   with an AR(1) velocity, colour factor 0.9, driving σ 5 mm/s). Each seed draws new sensor
   errors, stance drift and ensemble draws. Per estimator kind (``filter.kind``: ekf, ckf,
   enekf, cenekf) and constraint variant: horizontal RMSE per foot (mean ± sd over seeds),
   the end-of-walk error, the fraction of constraint epochs at which the constraint was
   active (metrics.json ``constraints``: activations / epochs; the epochs are the stance
   starts of either foot), and paired differences (same seed, same data) with their
   standard errors: DC − independent per kind, cKF − KF and cEnEKF − EnEKF.
2. The shared dual-foot Vicon walk (``configs/dual_foot_vicon.yaml``, its 0.6 m limit,
   positions-only correction) with and without the constraint; the ensemble kinds over
   ``--vicon-seeds`` filter seeds, the others are deterministic.

Constraint variants (``constraints[0]`` of the layout, ``fuser.method: projection``):

* ``independent``: ``fuser.method: none`` — each foot on its own.
* ``DC projection``: ``kind: max`` at the layout's limit (1.0 m on the simulation) with
  ``fuser.inequality: projection`` — an active limit puts the estimate on the bound and
  collapses its covariance across it, as both papers do ([Xu2024] §3.2, [Deng2026] §3.3).
  Neither paper states its limit; 1.0 m holds at every instant of the simulated walk (its
  true separation at the constraint epochs, the stance starts, is 0.37–0.92 m, median
  0.75 m: a 0.8 m limit would be broken by the truth itself).
* ``DC truncation``: the same limit with ``fuser.inequality: truncation``, the project's
  default ([Simon2010]: the mean and covariance of the estimate's density cut at the bound).
* ``min ≥ 0.2``: ``kind: min``, 0.2 m (projection) — the feet never overlap.
* ``MDC = 0.2``: ``kind: fixed``, 0.2 m — the [Xu2024] constraint as stated (below).
* ``fixed = DC``: ``kind: fixed`` at the DC's 1.0 m.

The "minimum distance constraint" and the project's kinds. [Xu2024] §3.2 names its
constraint after "a minimum distance between the feet on the plane observed during human
walking", but states it as an equality, ‖P_L − P_R‖² − d_c² = 0 with d_c "the minimum
distance", enforced "when at least one foot lands on the ground". So it is not
``min`` (‖r‖ ≥ d: the physical reading, an inequality that is almost never active, since
estimated feet seldom come closer than a step width) but ``fixed`` (‖r‖ = d). An equality
holds only at the instants where the true separation is d_c — for the minimum (the step
width, 0.2 m here) when the swinging foot passes the standing one, mid-swing. The fuser's
epochs are stance starts, where the true separation is about a step (0.37–0.92 m here), so
the equality there is a wrong measurement with no noise, off by 0.2–0.7 m at every epoch.
The fuser trusts it fully; with ``correct: all`` each correction is spread through the
covariance into velocity, attitude and biases, and the filters diverge (RMSE ~10⁴ m on this
walk; 120–340 m with ``correct: positions``, KF, seeds 0–3). At the DC's 1.0 m the equality
pushes the feet apart instead. On the 60 m coloured-stance walk
(``configs/sim_dual_foot_coloured_stance.yaml``) the equality at 0.2 m gives 3.3–3.9 m
against 0.04–0.06 m for independent feet (seeds 0–4). The equality would need epochs at
the moments of minimum separation (mid-swing), which the fuser does not offer; ``max`` (and
``min``) hold at every instant and are the ones to use.

What a distance constraint cannot see. It measures p_L − p_R only; the feet's common
error, the midpoint (e_L + e_R)/2, moves no constraint. A DC that removed the whole
difference would leave each foot with about the independent feet's midpoint error, so its
gain is about the share of the error the two feet do not have in common (for
independent, identically distributed feet the midpoint's RMS error is 1/√2 of one foot's: a
29 % cut). The table prints the independent feet's midpoint RMSE beside the DC's per-foot
RMSE. A heading drift common to both feet (a shared magnetic or turn-rate error) would be
invisible altogether.

Noise pairing, the same for every run: the white-noise kinds (ekf, enekf) take the stance
noise's stationary σ (``zupt_sigma_mps`` = σ_ξ / √(1 − α²)); the coloured kinds (ckf,
cenekf) take α and the driving σ_ξ. So each pair sees the same marginal stance noise and
differs only in modelling its colour. Simulation: α = 0.9, σ_ξ = 5 mm/s (the truth's);
Vicon: α = 0.9 with the stationary σ of the layout's default 0.01 m/s.

Printed beside: the papers' own left-foot tables (different walks, sensors and tuning: for
reference, not comparable numbers; their "mean" is (east RMSE + north RMSE) / 2). Note that
[Xu2024]'s 9.83 → 6.18 m (path 1) is MDC-KF → MDC-cKF, both constrained: the colour model's
gain, not the constraint's.

Usage: python examples/estimator_variants.py [--seeds 20] [--vicon-seeds 5] [--jobs 1] [--quick]
(--quick: 3 seeds, KF and cKF only, one Vicon seed: under a minute.) Run time with one
process: 65 s per seed (the ensemble kinds, 100 members, dominate; KF and cKF take a few
seconds), 24 minutes for the default 20 seeds and the Vicon walk.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from bodyfusion.core.layout import load_layout
from bodyfusion.reproduce.dual_foot import ALPHA, FEET, filter_overrides, run_figures
from bodyfusion.runner import run_layout
from bodyfusion.sim import simulate

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "configs" / "sim_dual_foot_consumer_walk.yaml"
VICON = ROOT / "configs" / "dual_foot_vicon.yaml"
KINDS = {"ekf": "KF", "ckf": "cKF", "enekf": "EnEKF", "cenekf": "cEnEKF"}
SIM_SIGMA_XI = 0.005  # the scenario's driving σ (m/s)
VICON_SIGMA_STATIONARY = 0.01  # the layout's default ZUPT σ (m/s)
DC_LIMIT_M = 1.0  # the scenario's max constraint (m)
MDC_DISTANCE_M = 0.2  # the walk's step width: its minimum separation on straight legs (m)

VARIANTS: dict[str, tuple[str, list[str]]] = {
    "none": ("independent", ["fuser.method=none"]),
    "dc": ("DC projection", ["fuser.inequality=projection"]),
    "dc_trunc": ("DC truncation", ["fuser.inequality=truncation"]),
    "min": (f"min ≥ {MDC_DISTANCE_M:g}", ["fuser.inequality=projection", "constraints.0.kind=min",
                                         f"constraints.0.distance_m={MDC_DISTANCE_M}"]),
    "fixed": (f"MDC = {MDC_DISTANCE_M:g}", ["constraints.0.kind=fixed", f"constraints.0.distance_m={MDC_DISTANCE_M}"]),
    "fixed_dc": ("fixed = DC", ["constraints.0.kind=fixed"]),
}
"""Constraint variant → (label, ``--set`` overrides of the layout; its own limit unless given)."""
_EQUALITIES = ("none", "dc", "dc_trunc", "min", "fixed", "fixed_dc")
SIM_VARIANTS = {"ekf": _EQUALITIES, "ckf": _EQUALITIES, "enekf": ("none", "dc", "dc_trunc"),
                "cenekf": ("none", "dc", "dc_trunc")}
"""Variants run per kind on the simulation: the min and fixed ones with the MDC paper's own filters."""
VICON_VARIANTS = ("none", "dc", "dc_trunc")

# Left-foot RMSEs (m): east, north, mean. Deng et al., "Distance Constraint Ensemble Kalman
# Filter for Pedestrian Localization", Micromachines 2026, 17(4), 436, Tables 3–5.
PAPER_DC_ENEKF = {
    "Path 1": {"DC-KF": (20.25, 5.32, 12.79), "DC-cKF": (7.34, 2.72, 5.03), "DC-EnEKF": (9.48, 4.49, 6.99),
               "DC-cEnEKF": (4.76, 2.52, 3.64)},
    "Path 2": {"DC-KF": (12.55, 17.53, 15.04), "DC-cKF": (7.93, 3.37, 5.51), "DC-EnEKF": (5.79, 3.08, 4.44),
               "DC-cEnEKF": (3.85, 2.13, 2.99)},
    "Path 3": {"DC-KF": (25.93, 21.70, 47.63), "DC-cKF": (16.23, 12.23, 14.23),
               "DC-EnEKF": (12.63, 10.93, 11.78), "DC-cEnEKF": (10.73, 8.26, 9.50)},
}
# Left-foot RMSEs (m): Xu et al., "Dual Foot-Mounted Localisation Scheme Employing a
# Minimum-Distance-Constraint Kalman Filter Under Coloured Measurement Noise",
# Micromachines 2024, 15(11), 1346, Tables 3, 5, 7 (MDC-KF, MDC-cKF).
PAPER_MDC_CKF = {
    "Path 1": {"MDC-KF": (13.8807, 5.7767, 9.8287), "MDC-cKF": (7.8685, 4.4977, 6.1831)},
    "Path 2": {"MDC-KF": (9.3362, 5.0087, 7.1724), "MDC-cKF": (7.4472, 4.7290, 6.0881)},
    "Path 3": {"MDC-KF": (8.5421, 7.7795, 8.1608), "MDC-cKF": (6.8992, 4.6638, 5.7815)},
}

Run = dict[str, float]
"""One run's figures (:func:`bodyfusion.reproduce.dual_foot.run_figures`)."""


def run_variants(config: Path, sigma_xi: float, seed: int,
                 plan: dict[str, Iterable[str]]) -> dict[tuple[str, str], Run]:
    """(kind, variant) → figures, each kind and variant of ``plan`` run on ``config`` with ``seed``."""
    return {(kind, variant): run_figures(run_layout(
                load_layout(config, VARIANTS[variant][1] + filter_overrides(kind, sigma_xi)), seed=seed))
            for kind, variants in plan.items() for variant in variants}


def simulation_seed(seed: int, plan: dict[str, Iterable[str]] | None = None,
                    scenario: Path = SCENARIO) -> dict[tuple[str, str], Run]:
    """Simulate ``scenario`` with ``seed`` and run ``plan`` (default :data:`SIM_VARIANTS`) on it
    (filter seed = seed)."""
    logging.disable(logging.WARNING)  # the drifting stance's levelling notes, once per run
    with tempfile.TemporaryDirectory() as tmp:
        sim = simulate(scenario, Path(tmp), seed=seed)
        return run_variants(sim.config_path, SIM_SIGMA_XI, seed, plan or SIM_VARIANTS)


def vicon_seed(seed: int, kinds: Iterable[str] = tuple(KINDS)) -> dict[tuple[str, str], Run]:
    """The Vicon walk with and without its constraint; the deterministic kinds at seed 0 only."""
    logging.disable(logging.WARNING)
    kinds = [k for k in kinds if seed == 0 or k in ("enekf", "cenekf")]
    return run_variants(VICON, VICON_SIGMA_STATIONARY * np.sqrt(1.0 - ALPHA**2), seed,
                        {k: VICON_VARIANTS for k in kinds})


def collect(runs: list[dict[tuple[str, str], Run]]) -> dict[tuple[str, str], dict[str, np.ndarray]]:
    """(kind, variant) → figure → (runs,) array over the runs that have it."""
    keys = sorted({key for r in runs for key in r}, key=lambda k: (list(KINDS).index(k[0]), list(VARIANTS).index(k[1])))
    return {key: {f: np.array([r[key][f] for r in runs if key in r]) for f in runs[0][next(iter(runs[0]))]}
            for key in keys}


def both_feet(figures: dict[str, np.ndarray], what: str = "rmse") -> np.ndarray:
    """Per run, the two feet's ``what`` (rmse, end) averaged, m."""
    return 0.5 * (figures[f"{what}_{FEET[0]}"] + figures[f"{what}_{FEET[1]}"])


def fmt(a: np.ndarray, width: int = 6, digits: int = 2) -> str:
    """mean ± sd (sd omitted for a single run)."""
    if a.size > 1:
        return f"{a.mean():{width}.{digits}f} ± {a.std(ddof=1):{width - 1}.{digits}f}"
    return f"{a.mean():{width}.{digits}f}" + " " * (width + 2)


def compact(x: float) -> str:
    """A figure that may have diverged: fixed-point up to 1 km, else scientific."""
    return f"{x:8.2f}" if abs(x) < 1000 else f"{x:8.1e}"


def print_table(title: str, table: dict[tuple[str, str], dict[str, np.ndarray]]) -> None:
    """Per kind and variant: horizontal RMSE per foot, end error, constraint-active fraction."""
    print(title)
    print(f"{'kind':7s} {'constraint':14s} {'left RMSE (m)':>17s} {'right RMSE (m)':>17s} "
          f"{'end error (m)':>17s} {'active (%)':>15s}")
    for (kind, variant), f in table.items():
        active = np.divide(f["activations"], f["epochs"], out=np.zeros_like(f["epochs"]), where=f["epochs"] > 0)
        cells = [f[f"rmse_{FEET[0]}"], f[f"rmse_{FEET[1]}"], both_feet(f, "end")]
        if max(c.mean() for c in cells) < 1000:
            text = " ".join(f"{fmt(c):>17s}" for c in cells)
        else:  # diverged: means only
            text = " ".join(f"{compact(c.mean()):>17s}" for c in cells)
        act = fmt(100 * active, 5, 1) if variant != "none" else "—"
        print(f"{KINDS[kind]:7s} {VARIANTS[variant][0]:14s} {text} {act:>15s}")
    print()


def paired(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float, float, int]:
    """Paired a − b over seeds: mean difference, its standard error, the relative change
    mean(a)/mean(b) − 1 and its delta-method standard error, and how many seeds have a < b."""
    d = a - b
    n = d.size
    se = d.std(ddof=1) / np.sqrt(n) if n > 1 else float("nan")
    ratio = a.mean() / b.mean()
    if n > 1:
        cov = np.cov(a, b, ddof=1)
        var = (cov[0, 0] - 2 * ratio * cov[0, 1] + ratio**2 * cov[1, 1]) / (n * b.mean() ** 2)
        se_ratio = float(np.sqrt(max(var, 0.0)))
    else:
        se_ratio = float("nan")
    return float(d.mean()), float(se), float(ratio - 1.0), se_ratio, int(np.sum(d < 0))


def verdict(mean: float, se: float) -> str:
    if not np.isfinite(se):
        return "one run"
    return ("lower, gap > 2 standard errors" if mean < -2 * se else
            "higher, gap > 2 standard errors" if mean > 2 * se else "within 2 standard errors")


def print_paired(table: dict[tuple[str, str], dict[str, np.ndarray]],
                 pairs: list[tuple[tuple[str, str], tuple[str, str]]]) -> None:
    """Paired differences of the horizontal RMSE (both feet averaged per run)."""
    print("Paired differences of the horizontal RMSE (both feet averaged), same seed and data:")
    for a, b in pairs:
        if a not in table or b not in table:
            continue
        d, se, rel, se_rel, lower = paired(both_feet(table[a]), both_feet(table[b]))
        name = f"{KINDS[a[0]]} {VARIANTS[a[1]][0]} − {KINDS[b[0]]} {VARIANTS[b[1]][0]}"
        rel_text = f"{100 * rel:+.1f} % ± {100 * se_rel:.1f} %" if abs(rel) < 10 else f"×{rel + 1:.3g}"
        print(f"  {name:38s} {compact(d)} m (se {compact(se).strip()} m), {rel_text}, "
              f"{lower}/{table[a]['epochs'].size} seeds lower: {verdict(d, se)}")
    print()


def print_common_mode(table: dict[tuple[str, str], dict[str, np.ndarray]]) -> None:
    """The independent feet's midpoint error (what a distance constraint cannot see) beside
    one independent foot's and one constrained foot's RMSE."""
    print("What a distance constraint cannot see: RMSE of the independent feet's midpoint (m):")
    print(f"{'kind':7s} {'one foot, independent':>24s} {'midpoint, independent':>24s} {'one foot, DC proj.':>20s}")
    for kind in KINDS:
        if (kind, "none") in table and (kind, "dc") in table:
            ind, dc = table[kind, "none"], table[kind, "dc"]
            print(f"{KINDS[kind]:7s} {fmt(both_feet(ind)):>24s} {fmt(ind['mid_rmse']):>24s} {fmt(both_feet(dc)):>20s}")
    print()


def print_papers() -> None:
    print("The papers' own left-foot RMSEs (m; their walks, sensors and tuning — reference only):")
    print(f"{'':22s} {'method':10s} {'east':>8s} {'north':>8s} {'mean':>8s}")
    for source, tables in (("DC-EnEKF 2026", PAPER_DC_ENEKF), ("MDC-cKF 2024", PAPER_MDC_CKF)):
        for path, rows in tables.items():
            for label, (e, n, m) in rows.items():
                print(f"{source + ', ' + path:22s} {label:10s} {e:8.2f} {n:8.2f} {m:8.2f}")
    print("(DC-EnEKF paper, Table 5: the DC-KF mean 47.63 is printed as published; (25.93 + 21.70)/2 = 23.82.)")
    print("(Every row is constrained: MDC-KF → MDC-cKF, 9.83 → 6.18 m, is the colour model's gain, not the DC's.)")


def run_all(fn: Callable[[int], dict], seeds: range, jobs: int) -> list[dict]:
    """``fn`` over ``seeds``, in this process or in ``jobs`` worker processes."""
    if jobs <= 1:
        return [fn(s) for s in seeds]
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        return list(pool.map(fn, seeds))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="simulation seeds 0 … N−1")
    parser.add_argument("--vicon-seeds", type=int, default=5, help="filter seeds of the ensemble kinds on Vicon (0: skip)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes")
    parser.add_argument("--quick", action="store_true", help="3 seeds, KF and cKF only, one Vicon seed")
    args = parser.parse_args()
    kinds = ("ekf", "ckf") if args.quick else tuple(KINDS)
    seeds = 3 if args.quick else args.seeds
    vicon_seeds = min(args.vicon_seeds, 1) if args.quick else args.vicon_seeds
    plan = {k: SIM_VARIANTS[k] for k in kinds}

    t0 = time.perf_counter()
    sim = collect(run_all(partial(simulation_seed, plan=plan), range(seeds), args.jobs))
    t_sim = time.perf_counter() - t0
    print_table(f"Simulation: {SCENARIO.name}, consumer IMU, 240 m, coloured stance noise "
                f"(α = {ALPHA}, σ_ξ = {SIM_SIGMA_XI * 1e3:g} mm/s), {seeds} seeds, mean ± sd:", sim)
    pairs = [((k, v), (k, "none")) for k in kinds for v in SIM_VARIANTS[k] if v != "none"]
    pairs += [(("ckf", v), ("ekf", v)) for v in ("none", "dc", "dc_trunc")]
    pairs += [(("cenekf", v), ("enekf", v)) for v in ("none", "dc", "dc_trunc")]
    print_paired(sim, pairs)
    print_common_mode(sim)

    if vicon_seeds > 0:
        t1 = time.perf_counter()
        vicon = collect(run_all(partial(vicon_seed, kinds=kinds), range(vicon_seeds), args.jobs))
        t_vicon = time.perf_counter() - t1
        print_table(f"Dual-foot Vicon walk (Hu & Hu 2025), 0.6 m limit, positions-only correction; "
                    f"ensemble kinds over {vicon_seeds} filter seeds, mean ± sd:", vicon)
        print_paired(vicon, [((k, v), (k, "none")) for k in kinds for v in ("dc", "dc_trunc")])
    else:
        t_vicon = 0.0
    print_papers()
    print(f"\nRun time: simulation {t_sim:.0f} s ({t_sim / seeds:.1f} s per seed), Vicon {t_vicon:.0f} s, "
          f"{args.jobs} process(es).")


if __name__ == "__main__":
    main()
