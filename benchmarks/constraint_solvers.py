"""Time the distance-constraint solvers on a two-foot problem.

Two systems (3-D positions), random SPD Σ (6x6, full: cross-covariances
between the feet), one horizontal max constraint d = 0.8 m violated by
≈ 0.2 m. A pool of random problems is cycled; every method is warmed up,
then each solve is timed with time.perf_counter_ns. The same pool with the
feet 0.6 m apart (constraint inactive: the early exit that most epochs take)
is timed too. Prints median and p99 µs per epoch for each method and, as the
last line,

    projection_us=<median> qp_us=<median> socp_us=<median>

(the inactive-epoch medians on the line above it)

Run: PYTHONPATH=. python3 benchmarks/constraint_solvers.py [--n 5000] [--seed 0]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from bodyfusion.core.constraints import DistanceConstraint, ProjectionSolver, QpSolver, SocpSolver, solve_projection


def random_problem(rng: np.random.Generator, d: float = 0.8, excess: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """Two feet d + excess (± 5 cm) apart horizontally; Σ with std 5–50 cm, random axes."""
    q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    ev = rng.uniform(0.05, 0.5, size=6) ** 2
    sigma = (q * ev) @ q.T
    p1 = rng.normal(scale=20.0, size=3)
    az = rng.uniform(0.0, 2.0 * np.pi)
    sep = d + excess + rng.uniform(-0.05, 0.05)
    p2 = p1 + np.array([sep * np.cos(az), sep * np.sin(az), rng.normal(scale=0.05)])
    return np.concatenate([p1, p2]), sigma


def inactive(problem: tuple[np.ndarray, np.ndarray], sep: float = 0.6) -> tuple[np.ndarray, np.ndarray]:
    """The same problem with the feet ``sep`` apart horizontally (below d)."""
    p_hat, sigma = problem
    p = p_hat.copy()
    h = p[3:5] - p[0:2]
    p[3:5] = p[0:2] + sep * h / np.linalg.norm(h)
    return p, sigma


def time_method(solve, problems, repeats: int) -> tuple[np.ndarray, int]:
    for p_hat, sigma in problems[: min(50, len(problems))]:  # warm-up
        solve(p_hat, sigma)
    out = np.empty(repeats, dtype=np.int64)
    fallbacks = 0
    n = len(problems)
    for k in range(repeats):
        p_hat, sigma = problems[k % n]
        t0 = time.perf_counter_ns()
        sol = solve(p_hat, sigma)
        out[k] = time.perf_counter_ns() - t0
        fallbacks += bool(sol.fallback)
    return out / 1e3, fallbacks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=5000, help="timed solves per fast method")
    ap.add_argument("--n-socp", type=int, default=300, help="timed solves for the SOCP")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    rng = np.random.default_rng(args.seed)
    problems = [random_problem(rng) for _ in range(500)]
    satisfied = [inactive(problem) for problem in problems]
    cons = [DistanceConstraint(0, 1, "max", 0.8)]

    proj = ProjectionSolver(2, cons)
    qp = QpSolver(2, cons)  # starts from the projection: one QP certifies it
    qp_indep = QpSolver(2, cons, start="p_hat")
    warnings.simplefilter("ignore")  # cvxpy accuracy chatter; fallbacks are counted instead
    socp = SocpSolver(2, cons)

    results = {}
    results["projection (function)"] = time_method(lambda p, s: solve_projection(p, s, cons), problems, args.n)
    results["projection"] = time_method(proj.solve, problems, args.n)
    results["projection, inactive"] = time_method(proj.solve, satisfied, args.n)
    results["qp"] = time_method(qp.solve, problems, args.n)
    results["qp, inactive"] = time_method(qp.solve, satisfied, args.n)
    results["qp (start=p_hat)"] = time_method(qp_indep.solve, problems, args.n)
    results["socp"] = time_method(socp.solve, problems, args.n_socp)

    # agreement check on the pool
    others = {"qp": qp, "qp (start=p_hat)": qp_indep, "socp": socp}
    worst = dict.fromkeys(others, 0.0)
    for p_hat, sigma in problems[:100]:
        ref = proj.solve(p_hat, sigma).p
        for name, solver in others.items():
            worst[name] = max(worst[name], float(np.max(np.abs(solver.solve(p_hat, sigma).p - ref))))

    print(f"two systems, one max constraint d=0.8 m violated by ~0.2 m (inactive: 0.6 m apart); "
          f"{len(problems)} random problems")
    print(f"{'method':<24}{'median_us':>12}{'p99_us':>12}{'fallbacks':>11}")
    for name, (us, fb) in results.items():
        print(f"{name:<24}{np.median(us):12.1f}{np.percentile(us, 99):12.1f}{fb:11d}")
    print("max |p - p_projection| over 100 problems: "
          + ", ".join(f"{name} {err:.2e} m" for name, err in worst.items()))
    med = {name: np.median(us) for name, (us, _) in results.items()}
    print(f"projection_inactive_us={med['projection, inactive']:.1f} qp_inactive_us={med['qp, inactive']:.1f}")
    print(f"projection_us={med['projection']:.1f} qp_us={med['qp']:.1f} socp_us={med['socp']:.1f}")


if __name__ == "__main__":
    main()
