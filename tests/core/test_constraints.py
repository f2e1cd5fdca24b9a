"""Property tests for bodyfusion.core.constraints: projection (eqs. 55–60), OSQP QP, cvxpy SOCP.

Hypothesis draws the structure (number of systems, full or block-diagonal Σ,
horizontal or 3-D, lever arms, how far the constraint is violated) and a seed;
numpy generates the numbers from the seed. Σ has eigenvalues (5–60 cm)², so it
is well conditioned and KKT residuals can be checked with Σ⁻¹.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from bodyfusion.core import constraints as fc
from bodyfusion.core.constraints import (
    ConstraintSolution,
    DistanceConstraint,
    ProjectionSolver,
    QpSolver,
    SocpSolver,
    constrained_covariance,
    solve_projection,
    violations,
)
from bodyfusion.core.constraints import kernels as fk
from bodyfusion.core.constraints import qp as fq

TOL = 1e-6
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow])

seeds = st.integers(0, 2**32 - 1)
n_systems = st.integers(2, 4)
flags = st.booleans()


# ---------------------------------------------------------------------------
# problem generators and independent reference computations
# ---------------------------------------------------------------------------


def random_spd(rng: np.random.Generator, n3: int, full: bool) -> np.ndarray:
    def block(k: int) -> np.ndarray:
        q, _ = np.linalg.qr(rng.normal(size=(k, k)))
        return (q * rng.uniform(0.05, 0.6, k) ** 2) @ q.T

    if full:
        return block(n3)
    out = np.zeros((n3, n3))
    for b in range(n3 // 3):
        out[3 * b : 3 * b + 3, 3 * b : 3 * b + 3] = block(3)
    return out


def pair_problem(seed: int, n: int, full: bool, horizontal: bool, lever: bool, kind: str, ratio: float):
    """p̂, Σ and one constraint between two random systems whose constrained
    separation ‖E(p_i + l_i − p_j − l_j)‖ is ``ratio`` times its distance."""
    rng = np.random.default_rng(seed)
    i, j = (int(x) for x in rng.choice(n, 2, replace=False))
    li = rng.normal(scale=0.2, size=3) if lever else None
    lj = rng.normal(scale=0.2, size=3) if lever else None
    d = float(rng.uniform(0.3, 1.5))
    p = rng.normal(scale=2.0, size=3 * n)
    dim = 2 if horizontal else 3
    direction = rng.normal(size=dim)
    direction /= np.linalg.norm(direction)
    base = p[3 * i : 3 * i + 3] + (0 if li is None else li) - (0 if lj is None else lj)
    p[3 * j : 3 * j + dim] = base[:dim] - ratio * d * direction
    c = DistanceConstraint(i, j, kind, d, horizontal=horizontal, lever_i_m=li, lever_j_m=lj)
    return p, random_spd(rng, 3 * n, full), c


def separation(p: np.ndarray, c: DistanceConstraint) -> np.ndarray:
    """E (p_i + l_i − p_j − l_j), computed here independently of the module."""
    li = np.zeros(3) if c.lever_i_m is None else c.lever_i_m
    lj = np.zeros(3) if c.lever_j_m is None else c.lever_j_m
    r = p[3 * c.i : 3 * c.i + 3] + li - p[3 * c.j : 3 * c.j + 3] - lj
    return r[:2] if c.horizontal else r


def g_value(p: np.ndarray, c: DistanceConstraint) -> float:
    """g ≤ 0 form: max ‖r‖ − d, min d − ‖r‖, fixed ‖r‖ − d."""
    nr = float(np.linalg.norm(separation(p, c)))
    return c.distance_m - nr if c.kind == "min" else nr - c.distance_m


def grad_g(p: np.ndarray, c: DistanceConstraint, n: int) -> np.ndarray:
    r = separation(p, c)
    u = r / np.linalg.norm(r)
    out = np.zeros(3 * n)
    out[3 * c.i : 3 * c.i + len(u)] += u
    out[3 * c.j : 3 * c.j + len(u)] -= u
    return -out if c.kind == "min" else out


def check_kkt(sol: ConstraintSolution, p_hat: np.ndarray, sigma: np.ndarray, cons, tol: float = TOL) -> None:
    """Σ⁻¹(p* − p̂) + Σ λ_k ∇g_k(p*) = 0, λ ≥ 0 (max/min), λ_k g_k = 0, feasibility."""
    n = p_hat.shape[0] // 3
    p = sol.p
    lam = sol.multipliers
    assert lam.shape == (len(cons),)
    pull = np.zeros(3 * n)
    for k, c in enumerate(cons):
        g = g_value(p, c)
        if c.kind == "fixed":
            assert abs(g) <= tol
        else:
            assert g <= tol
            assert lam[k] >= -1e-9, f"multiplier {k} has the wrong sign: {lam[k]}"
        if k in sol.active:
            assert abs(g) <= tol, f"active constraint {k} is not tight: g = {g}"
            pull += lam[k] * grad_g(p, c, n)
        else:
            assert lam[k] == 0.0
        assert abs(lam[k] * g) <= tol * (1.0 + abs(lam[k]))  # complementary slackness
    info_step = np.linalg.solve(sigma, p - p_hat)
    resid = info_step + pull
    scale = 1.0 + np.max(np.abs(info_step))
    assert np.max(np.abs(resid)) <= 1e-4 * scale, f"stationarity residual {np.max(np.abs(resid))}"
    # the same condition in metres (no Σ⁻¹): p* − p̂ + Σ Σλ∇g = 0; a position error δ
    # turns the gradients by δ/‖r‖, so the residual allowance grows with λ‖Σ‖
    amplification = 1.0 + np.sum(np.abs(lam)) * np.linalg.norm(sigma, 2)
    assert np.max(np.abs(p - p_hat + sigma @ pull)) <= 10 * tol * amplification
    # the documented identity Σ⁻¹(p* − p̂) = −Jᵀ λ_active
    if sol.active:
        assert np.allclose(-sol.jacobian.T @ lam[sol.active], info_step, atol=1e-4 * scale)


def check_qp_or_fallback(qp: ConstraintSolution, proj: ConstraintSolution, kind: str) -> None:
    """The QP converges by itself; for the non-convex ``min`` (and ``fixed`` from
    inside) strongly violated, nearly degenerate cases may exceed max_iter SQP
    steps (≈ 2 % of random cases with separation < 0.3 d): then it must return
    the projection, flagged."""
    if qp.fallback:
        assert kind in ("min", "fixed")
        assert qp.method == "projection"
        np.testing.assert_allclose(qp.p, proj.p, rtol=0, atol=1e-12)
    else:
        assert qp.converged and qp.method == "qp"


def assert_clean(sol: ConstraintSolution) -> None:
    for arr in (sol.p, sol.gain, sol.multipliers):
        assert np.all(np.isfinite(arr))


# ---------------------------------------------------------------------------
# single max constraint: three methods agree
# ---------------------------------------------------------------------------


@settings(max_examples=30, **SETTINGS)
@given(seeds, n_systems, flags, flags, flags, st.floats(1.02, 3.0))
def test_single_max_constraint_methods_agree(seed, n, full, horizontal, lever, ratio):
    p_hat, sigma, c = pair_problem(seed, n, full, horizontal, lever, "max", ratio)
    cons = [c]
    sols = {
        "projection": solve_projection(p_hat, sigma, cons),
        "qp": QpSolver(n, cons).solve(p_hat, sigma),
        "socp": SocpSolver(n, cons).solve(p_hat, sigma),
    }
    for name, sol in sols.items():
        assert_clean(sol)
        assert sol.method == name and not sol.fallback and sol.converged, name
        assert sol.active == [0]
        assert sol.violation_before_m == pytest.approx((ratio - 1.0) * c.distance_m, rel=1e-6, abs=1e-9)
        assert sol.violation_after_m <= TOL
        assert violations(sol.p, cons)[0] <= TOL
    for a, b in (("projection", "qp"), ("projection", "socp"), ("qp", "socp")):
        assert np.max(np.abs(sols[a].p - sols[b].p)) <= TOL, (a, b)
    assert np.allclose(sols["projection"].gain, sols["qp"].gain, atol=1e-5)


# ---------------------------------------------------------------------------
# KKT conditions (projection and qp), all kinds
# ---------------------------------------------------------------------------


@settings(max_examples=60, **SETTINGS)
@given(seeds, n_systems, flags, flags, flags, st.sampled_from(["max", "min", "fixed"]), st.floats(0.0, 1.0))
def test_kkt_conditions_single_constraint(seed, n, full, horizontal, lever, kind, t):
    if kind == "max":
        ratio = 1.02 + 2.0 * t
    elif kind == "min":
        ratio = 0.1 + 0.85 * t
    else:
        ratio = 0.2 + 2.5 * t
    assume(abs(ratio - 1.0) > 0.02)
    p_hat, sigma, c = pair_problem(seed, n, full, horizontal, lever, kind, ratio)
    proj = solve_projection(p_hat, sigma, [c])
    qp = QpSolver(n, [c]).solve(p_hat, sigma)
    assert proj.converged and not proj.fallback
    check_qp_or_fallback(qp, proj, kind)
    for sol in (proj, qp):
        assert_clean(sol)
        assert sol.active == [0]
        check_kkt(sol, p_hat, sigma, [c])
        # sign convention: max pulls together (λ > 0), min pushes apart (λ > 0 on d − ‖r‖)
        if kind == "fixed":
            assert np.sign(sol.multipliers[0]) == np.sign(ratio - 1.0)
        else:
            assert sol.multipliers[0] > 0.0


# ---------------------------------------------------------------------------
# constrained covariance
# ---------------------------------------------------------------------------


@settings(max_examples=40, **SETTINGS)
@given(seeds, n_systems, flags, flags, flags, st.sampled_from(["max", "min", "fixed"]))
def test_constrained_covariance_psd_and_collapses(seed, n, full, horizontal, lever, kind):
    ratio = {"max": 1.5, "min": 0.5, "fixed": 1.3}[kind]
    p_hat, sigma, c = pair_problem(seed, n, full, horizontal, lever, kind, ratio)
    for sol in (solve_projection(p_hat, sigma, [c]), QpSolver(n, [c]).solve(p_hat, sigma)):
        sig_star = constrained_covariance(sigma, sol.gain)
        assert np.array_equal(sig_star, sig_star.T)
        scale = np.trace(sigma)
        assert np.linalg.eigvalsh(sig_star)[0] >= -1e-9 * scale
        # never more uncertain than before: Σ − Σ* ⪰ 0
        assert np.linalg.eigvalsh(sigma - sig_star)[0] >= -1e-9 * scale
        # variance along the constrained direction collapses
        gk = grad_g(sol.p, c, n)
        assert gk @ sig_star @ gk <= 1e-9 * (gk @ sigma @ gk)
        # and it equals the conditioning formula Σ − Σgᵀ(gΣgᵀ)⁻¹gΣ
        sg = sigma @ gk
        assert np.allclose(sig_star, sigma - np.outer(sg, sg) / (gk @ sg), atol=1e-9 * scale)


def test_constrained_covariance_zero_gain_is_identity():
    rng = np.random.default_rng(1)
    sigma = random_spd(rng, 6, True)
    # to rounding: a BLAS may sum the products with zeros in another order (FMA kernels)
    assert np.allclose(constrained_covariance(sigma, np.zeros((6, 6))), sigma, atol=1e-15 * np.abs(sigma).max(),
                       rtol=1e-15)


# ---------------------------------------------------------------------------
# inactive constraints change nothing
# ---------------------------------------------------------------------------


@settings(max_examples=25, **SETTINGS)
@given(seeds, n_systems, flags, flags, flags, st.sampled_from(["max", "min"]), st.floats(0.0, 1.0))
def test_inactive_constraints_change_nothing(seed, n, full, horizontal, lever, kind, t):
    ratio = 0.1 + 0.85 * t if kind == "max" else 1.05 + 2.0 * t
    p_hat, sigma, c = pair_problem(seed, n, full, horizontal, lever, kind, ratio)
    for sol in (
        solve_projection(p_hat, sigma, [c]),
        QpSolver(n, [c]).solve(p_hat, sigma),
        SocpSolver(n, [c]).solve(p_hat, sigma),
    ):
        assert np.array_equal(sol.p, p_hat)
        assert sol.p is not p_hat
        assert not np.any(sol.gain) and sol.gain.shape == (3 * n, 3 * n)
        assert sol.active == [] and not np.any(sol.multipliers)
        assert sol.violation_before_m == 0.0 and sol.violation_after_m == 0.0
        assert sol.converged and not sol.fallback


# ---------------------------------------------------------------------------
# min and fixed constraints hold after solving
# ---------------------------------------------------------------------------


@settings(max_examples=40, **SETTINGS)
@given(seeds, n_systems, flags, flags, flags, st.sampled_from(["min", "fixed"]), st.floats(0.05, 0.95))
def test_min_and_fixed_constraints_hold(seed, n, full, horizontal, lever, kind, ratio):
    if kind == "fixed" and seed % 2:
        ratio = 1.0 / ratio  # fixed constraints violated from outside too
    p_hat, sigma, c = pair_problem(seed, n, full, horizontal, lever, kind, ratio)
    proj = solve_projection(p_hat, sigma, [c])
    qp = QpSolver(n, [c]).solve(p_hat, sigma)
    assert proj.converged and not proj.fallback
    check_qp_or_fallback(qp, proj, kind)
    for sol in (proj, qp):
        assert_clean(sol)
        assert abs(np.linalg.norm(separation(sol.p, c)) - c.distance_m) <= TOL
        assert violations(sol.p, [c])[0] <= TOL


@pytest.mark.parametrize("kind", ["min", "fixed"])
def test_qp_converges_on_moderate_min_and_fixed(kind):
    """Without falling back, and to the projection's (global) solution."""
    for seed in range(30):
        rng = np.random.default_rng(seed)
        ratio = float(rng.uniform(0.5, 0.95))
        if kind == "fixed" and seed % 2:
            ratio = 1.0 / ratio
        p_hat, sigma, c = pair_problem(seed, 2 + seed % 3, bool(seed % 2), bool(seed % 3), bool(seed % 5), kind, ratio)
        qp = QpSolver(2 + seed % 3, [c]).solve(p_hat, sigma)
        assert qp.converged and not qp.fallback, seed
        assert np.max(np.abs(qp.p - solve_projection(p_hat, sigma, [c]).p)) <= TOL, seed


def test_fixed_constraint_is_always_active():
    """Satisfied exactly at p̂: nothing moves, but the distance is information (μ ≠ 0)."""
    p_hat = np.array([0.0, 0.0, 0.0, 0.6, 0.8, 0.3])
    sigma = np.diag([0.04, 0.09, 0.01, 0.05, 0.02, 0.01])
    c = DistanceConstraint(0, 1, "fixed", 1.0)
    for sol in (solve_projection(p_hat, sigma, [c]), QpSolver(2, [c]).solve(p_hat, sigma)):
        assert sol.active == [0]
        assert np.allclose(sol.p, p_hat, atol=1e-12)
        assert np.any(sol.gain)


# ---------------------------------------------------------------------------
# several constraints at once
# ---------------------------------------------------------------------------


def triangle_problem(seed: int, full: bool, horizontal: bool):
    rng = np.random.default_rng(seed)
    p_hat = rng.normal(scale=1.0, size=9)
    sigma = random_spd(rng, 9, full)
    cons = []
    for i, j in ((0, 1), (0, 2), (1, 2)):
        dim = 2 if horizontal else 3
        dist = float(np.linalg.norm(p_hat[3 * i : 3 * i + dim] - p_hat[3 * j : 3 * j + dim]))
        cons.append(DistanceConstraint(i, j, "max", dist * float(rng.uniform(0.3, 0.95)), horizontal=horizontal))
    return p_hat, sigma, cons


@settings(max_examples=40, **SETTINGS)
@given(seeds, flags, flags)
def test_three_pairwise_max_constraints(seed, full, horizontal):
    p_hat, sigma, cons = triangle_problem(seed, full, horizontal)
    assume(np.all(violations(p_hat, cons) > 1e-3))  # all three violated
    proj = solve_projection(p_hat, sigma, cons)
    qp = QpSolver(3, cons).solve(p_hat, sigma)
    for sol in (proj, qp):
        assert_clean(sol)
        assert sol.converged and not sol.fallback
        assert np.all(violations(sol.p, cons) <= TOL)
        check_kkt(sol, p_hat, sigma, cons)
    assert np.max(np.abs(proj.p - qp.p)) <= 1e-5
    assert sorted(proj.active) == sorted(qp.active)


@settings(max_examples=8, **SETTINGS)
@given(seeds, flags)
def test_three_pairwise_max_constraints_socp(seed, full):
    p_hat, sigma, cons = triangle_problem(seed, full, True)
    assume(np.all(violations(p_hat, cons) > 1e-3))
    proj = solve_projection(p_hat, sigma, cons)
    socp = SocpSolver(3, cons).solve(p_hat, sigma)
    assert socp.converged and not socp.fallback
    assert np.max(np.abs(proj.p - socp.p)) <= 1e-5


# ---------------------------------------------------------------------------
# degenerate geometry
# ---------------------------------------------------------------------------


@settings(max_examples=25, **SETTINGS)
@given(seeds, n_systems, flags, flags, st.sampled_from(["min", "fixed"]))
def test_degenerate_coincident_systems(seed, n, full, horizontal, kind):
    rng = np.random.default_rng(seed)
    p_hat = rng.normal(scale=2.0, size=3 * n)
    i, j = (int(x) for x in rng.choice(n, 2, replace=False))
    p_hat[3 * j : 3 * j + 3] = p_hat[3 * i : 3 * i + 3]  # p_i == p_j exactly
    sigma = random_spd(rng, 3 * n, full)
    c = DistanceConstraint(i, j, kind, float(rng.uniform(0.1, 1.0)), horizontal=horizontal)
    assert violations(p_hat, [c])[0] == pytest.approx(c.distance_m)
    for sol in (
        solve_projection(p_hat, sigma, [c]),
        ProjectionSolver(n, [c]).solve(p_hat, sigma),
        QpSolver(n, [c]).solve(p_hat, sigma),
        SocpSolver(n, [c]).solve(p_hat, sigma),  # may fall back: still must hold
    ):
        assert_clean(sol)
        assert violations(sol.p, [c])[0] <= TOL
        assert abs(np.linalg.norm(separation(sol.p, c)) - c.distance_m) <= TOL


def test_degenerate_isotropic_separates_east():
    """No preferred axis (S ∝ I) and no history: the documented direction is east."""
    p_hat = np.array([1.0, 2.0, 0.0, 1.0, 2.0, 0.0])
    sigma = 0.01 * np.eye(6)
    c = DistanceConstraint(0, 1, "min", 0.4)
    for sol in (solve_projection(p_hat, sigma, [c]), QpSolver(2, [c]).solve(p_hat, sigma)):
        assert np.allclose(sol.p[:3] - sol.p[3:], [0.4, 0.0, 0.0], atol=1e-9)
        assert np.allclose(sol.p[:3] + sol.p[3:], p_hat[:3] + p_hat[3:], atol=1e-12)
    # a hint (e.g. the previous solution's direction) replaces east
    sol = solve_projection(p_hat, sigma, [c], hint_directions=[[0.0, 1.0, 0.0]])
    assert np.allclose(sol.p[:3] - sol.p[3:], [0.0, 0.4, 0.0], atol=1e-9)


def test_degenerate_uses_previous_direction():
    sigma = 0.01 * np.eye(6)
    c = DistanceConstraint(0, 1, "min", 0.4)
    solver = ProjectionSolver(2, [c])
    solver.solve(np.array([0.0, 0.0, 0.0, 0.0, -0.1, 0.0]), sigma)  # separated along north
    sol = solver.solve(np.array([1.0, 1.0, 0.0, 1.0, 1.0, 0.0]), sigma)  # then coincident
    assert np.allclose(sol.p[:3] - sol.p[3:], [0.0, 0.4, 0.0], atol=1e-9)


@settings(max_examples=15, **SETTINGS)
@given(seeds, n_systems, flags, st.sampled_from(["max", "min", "fixed"]))
def test_qp_variants_agree(seed, n, lever, kind):
    """The default QP (started at the projection: one QP certifies it), OSQP through
    its public API, and the SQP started at p̂ (independent of the projection) agree."""
    ratio = {"max": 1.6, "min": 0.6, "fixed": 1.4}[kind]
    p_hat, sigma, c = pair_problem(seed, n, True, True, lever, kind, ratio)
    ref = QpSolver(n, [c]).solve(p_hat, sigma)
    public = QpSolver(n, [c], fast_calls=False).solve(p_hat, sigma)
    independent = QpSolver(n, [c], start="p_hat").solve(p_hat, sigma)
    for sol in (ref, public, independent):
        assert sol.converged and not sol.fallback and sol.method == "qp"
    np.testing.assert_allclose(public.p, ref.p, rtol=0, atol=1e-9)
    assert np.max(np.abs(independent.p - ref.p)) <= TOL
    assert ref.iterations == 1
    with pytest.raises(ValueError):
        QpSolver(n, [c], start="somewhere")


@pytest.mark.parametrize(
    "seed, n, full, horizontal, lever, kind, ratio",
    [
        (262144, 3, True, True, False, "min", 0.6),  # Hessian at the solution ⪰ 0.09 I only
        (2315959471, 4, True, False, True, "min", 0.6),  # 3-D: negative curvature on the way
        (4272175087, 3, True, True, False, "fixed", 0.1),  # pushed apart from 0.07 m
        (1547493211, 3, True, True, False, "min", 0.02),  # nearly coincident: a saddle near p̂
    ],
    ids=["weak_curvature_at_solution", "negative_curvature_3d", "fixed_pushed_apart", "saddle_near_p_hat"],
)
def test_qp_from_p_hat_keeps_min_curvature(seed, n, full, horizontal, lever, kind, ratio):
    """The SQP from p̂ with pushing-apart limits (``min``, ``fixed`` inside) takes
    Newton steps with the constraint's negative curvature, cut only where the
    Hessian would drop below 0.01 I: it reaches the projection's (global) minimum
    in a few QPs. Cutting it to keep ⪰ 0.1 I made these converge linearly or creep
    along the constraint (20+ QPs, then the fallback), or stop at the saddle point
    0.68 m from the solution (the last)."""
    p_hat, sigma, c = pair_problem(seed, n, full, horizontal, lever, kind, ratio)
    ref = solve_projection(p_hat, sigma, [c])
    sol = QpSolver(n, [c], start="p_hat").solve(p_hat, sigma)
    assert sol.converged and not sol.fallback and sol.iterations <= 10
    assert np.max(np.abs(sol.p - ref.p)) <= TOL
    check_kkt(sol, p_hat, sigma, [c])


def test_qp_from_p_hat_is_a_local_method():
    """What ``start="p_hat"`` guarantees for a ``min`` limit: a KKT point, not the
    global minimum. Coincident systems separate along the hint (east) although
    the pair is least certain north-south: a saddle point of the non-convex
    problem (negative curvature along the limit) where the projection, whose
    single-constraint solve is global, separates north. test_qp_variants_agree's
    random problems are never so symmetric."""
    p_hat = np.array([1.0, 2.0, 0.0, 1.0, 2.0, 0.0])
    sigma = np.diag([0.01, 0.04, 0.01, 0.01, 0.04, 0.01])
    c = DistanceConstraint(0, 1, "min", 0.4)
    local = QpSolver(2, [c], start="p_hat").solve(p_hat, sigma)
    ref = QpSolver(2, [c]).solve(p_hat, sigma)
    assert local.converged and not local.fallback
    check_kkt(local, p_hat, sigma, [c])
    assert np.allclose(local.p[:3] - local.p[3:], [0.4, 0.0, 0.0], atol=TOL)
    assert np.allclose(ref.p[:3] - ref.p[3:], [0.0, 0.4, 0.0], atol=TOL)


def test_qp_certifies_with_osqp(monkeypatch):
    """Started at the projection, the QP still solves its own QP with OSQP: one solve
    when the start is the KKT point; from a start off by a millimetre that QP does
    not settle it, and the SQP takes more steps to the same answer."""
    p_hat, sigma, c = pair_problem(5, 2, True, True, True, "max", 1.5)
    exact = solve_projection(p_hat, sigma, [c])
    qp = QpSolver(2, [c])
    calls = []
    osqp_solve = qp._qp
    monkeypatch.setattr(qp, "_qp", lambda *args: calls.append(1) or osqp_solve(*args))
    sol = qp.solve(p_hat, sigma)
    assert len(calls) == 1 and sol.iterations == 1 and sol.method == "qp" and not sol.fallback
    assert 0.0 < np.max(np.abs(sol.p - exact.p)) <= TOL  # OSQP's point, not a copy

    certify_start, projection = fq._qp_start_pair, fq.project

    def start_off(*args):
        out = certify_start(*args)
        args[6].p0[:] += 1e-3  # the projection p0 (the start record's)
        return out

    def projection_off(*args, **kwargs):
        ref, dirs = projection(*args, **kwargs)
        ref.p = ref.p + 1e-3
        return ref, dirs

    monkeypatch.setattr(fq, "_qp_start_pair", start_off)
    monkeypatch.setattr(fq, "project", projection_off)
    calls.clear()
    sol = qp.solve(p_hat, sigma)
    assert sol.method == "qp" and not sol.fallback and sol.converged
    assert sol.iterations >= 2 and len(calls) == 1 + sol.iterations
    assert np.max(np.abs(sol.p - exact.p)) <= TOL
    check_kkt(sol, p_hat, sigma, [c])


@pytest.mark.parametrize("dim", [2, 3])
def test_symmetric_eigen_kernel(dim):
    """The projection's Jacobi eigen-solver against numpy, distinct and repeated eigenvalues."""
    rng = np.random.default_rng(dim)
    q, _ = np.linalg.qr(rng.normal(size=(dim, dim)))
    for ev in (rng.uniform(0.1, 1.0, dim), np.full(dim, 0.3), np.r_[0.5, np.full(dim - 1, 0.2)]):
        S = np.zeros((3, 3))
        S[:dim, :dim] = (q * ev) @ q.T
        w, Q = np.empty(3), np.empty((3, 3))
        fk._sym_eig(S, dim, w, Q)
        w, Q = w[:dim], Q[:dim, :dim]
        np.testing.assert_allclose(w, np.sort(ev)[::-1], rtol=0, atol=1e-14)
        assert np.all(np.diff(w) <= 0.0)
        np.testing.assert_allclose(Q @ Q.T, np.eye(dim), rtol=0, atol=1e-14)
        np.testing.assert_allclose((Q * w[:, None]).T @ Q, S[:dim, :dim], rtol=0, atol=1e-14)


# ---------------------------------------------------------------------------
# solver failure → projection fallback
# ---------------------------------------------------------------------------


def _one_violated(seed: int = 3):
    return pair_problem(seed, 2, True, True, True, "max", 1.4)


def test_qp_max_iter_zero_falls_back_to_projection():
    p_hat, sigma, c = _one_violated()
    qp = QpSolver(2, [c], max_iter=0)
    sol = qp.solve(p_hat, sigma)
    ref = solve_projection(p_hat, sigma, [c])
    assert sol.fallback and sol.method == "projection" and qp.fallbacks == 1
    np.testing.assert_allclose(sol.p, ref.p, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sol.gain, ref.gain, rtol=0, atol=1e-12)


@pytest.mark.parametrize("mode", ["status", "raise"])
def test_qp_osqp_failure_falls_back(monkeypatch, mode):
    p_hat, sigma, c = _one_violated()
    qp = QpSolver(2, [c])

    def broken(*args, **kwargs):
        if mode == "raise":
            raise RuntimeError("solver crashed")
        return 7, np.full(6, np.nan), np.full(1, np.nan)  # OSQP_MAX_ITER_REACHED

    monkeypatch.setattr(qp, "_qp", broken)
    sol = qp.solve(p_hat, sigma)
    ref = solve_projection(p_hat, sigma, [c])
    assert sol.fallback and sol.method == "projection"
    np.testing.assert_allclose(sol.p, ref.p, rtol=0, atol=1e-12)
    assert sol.violation_after_m <= TOL


def test_socp_failure_falls_back(monkeypatch):
    import cvxpy as cp

    p_hat, sigma, c = _one_violated()
    socp = SocpSolver(2, [c])
    assert socp.is_dpp()

    def broken(*args, **kwargs):
        raise cp.error.SolverError("solver crashed")

    monkeypatch.setattr(socp._problem, "solve", broken)
    sol = socp.solve(p_hat, sigma)
    assert sol.fallback and sol.method == "projection" and socp.fallbacks == 1
    np.testing.assert_allclose(sol.p, solve_projection(p_hat, sigma, [c]).p, rtol=0, atol=1e-12)


def test_fallback_field_defaults_false():
    p_hat, sigma, c = _one_violated()
    assert solve_projection(p_hat, sigma, [c]).fallback is False


# ---------------------------------------------------------------------------
# smaller properties
# ---------------------------------------------------------------------------


def test_violations_signs_and_lever_arms():
    li, lj = np.array([0.1, 0.0, 0.5]), np.array([0.0, -0.2, 0.0])
    p = np.array([0.0, 0.0, 0.0, 0.3, 0.0, 2.0])
    # E(p_i + l_i − p_j − l_j) = (0.1 − 0.3, 0 + 0.2) → ‖·‖ = √0.08
    r = np.sqrt(0.08)
    cons = [
        DistanceConstraint(0, 1, "max", 0.2, lever_i_m=li, lever_j_m=lj),
        DistanceConstraint(0, 1, "min", 0.2, lever_i_m=li, lever_j_m=lj),
        DistanceConstraint(0, 1, "fixed", 0.2, lever_i_m=li, lever_j_m=lj),
        DistanceConstraint(0, 1, "max", 1.0, horizontal=False),  # 3-D: √(0.09 + 4)
    ]
    np.testing.assert_allclose(violations(p, cons), [r - 0.2, 0.2 - r, r - 0.2, np.sqrt(4.09) - 1.0])


def test_lever_arms_move_the_constrained_points():
    li, lj = np.array([-0.3, 0.0, 0.0]), np.array([0.3, 0.0, 0.0])
    p_hat = np.array([0.0, 0.0, 0.0, 0.5, 0.0, 0.0])  # constrained points −0.3 and 0.8: 1.1 m apart
    sigma = 0.01 * np.eye(6)
    c = DistanceConstraint(0, 1, "max", 0.8, lever_i_m=li, lever_j_m=lj)
    sol = solve_projection(p_hat, sigma, [c])
    # equal variances: each moves 0.15 m towards the other along east
    np.testing.assert_allclose(sol.p, [0.15, 0, 0, 0.35, 0, 0], atol=1e-12)
    assert sol.multipliers[0] == pytest.approx(0.3 / (2 * 0.01))


def test_psd_sigma_without_inverse():
    """Σ singular (exactly known heights): QP whitens with a PSD square root."""
    rng = np.random.default_rng(7)
    sigma = random_spd(rng, 6, False)
    sigma[2, :] = sigma[:, 2] = 0.0
    sigma[5, :] = sigma[:, 5] = 0.0
    p_hat = np.array([0.0, 0.0, 1.0, 1.2, 0.4, 0.0])
    c = DistanceConstraint(0, 1, "max", 0.8)
    proj = solve_projection(p_hat, sigma, [c])
    qp = QpSolver(2, [c]).solve(p_hat, sigma)
    assert not qp.fallback and qp.converged
    assert np.max(np.abs(proj.p - qp.p)) <= TOL
    assert proj.p[2] == 1.0 and proj.p[5] == 0.0  # zero-variance components stay


@pytest.mark.parametrize("scheme", ["newton", "fixed_point"])
def test_schemes_agree_on_easy_problem(scheme):
    p_hat = np.array([0.0, 0.0, 0.0, 1.0, 0.5, 0.0])
    sigma = np.diag([0.02, 0.03, 0.01, 0.03, 0.02, 0.01])
    c = DistanceConstraint(0, 1, "max", 0.8)
    ref = QpSolver(2, [c]).solve(p_hat, sigma)
    sol = solve_projection(p_hat, sigma, [c], scheme=scheme, max_iter=200)
    assert sol.converged
    assert np.max(np.abs(sol.p - ref.p)) <= 1e-5


def test_constraint_validation_and_equality():
    with pytest.raises(ValueError):
        DistanceConstraint(0, 1, "between", 1.0)
    with pytest.raises(ValueError):
        DistanceConstraint(1, 1, "max", 1.0)
    with pytest.raises(ValueError):
        DistanceConstraint(0, 1, "max", 0.0)
    with pytest.raises(ValueError):
        DistanceConstraint(0, 1, "min", -0.1)
    with pytest.raises(ValueError):
        DistanceConstraint(0, 1, "max", 1.0, lever_i_m=np.zeros(2))
    a = DistanceConstraint(0, 1, "max", 1.0, lever_i_m=[0.0, 0.1, 0.0])
    b = DistanceConstraint(0, 1, "max", 1.0, lever_i_m=np.array([0.0, 0.1, 0.0]))
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1
    assert a != DistanceConstraint(0, 1, "max", 1.0)
    with pytest.raises(ValueError):
        solve_projection(np.zeros(6), np.eye(6), [DistanceConstraint(0, 2, "max", 1.0)])
    with pytest.raises(ValueError):
        solve_projection(np.full(6, np.nan), np.eye(6), [DistanceConstraint(0, 1, "max", 1.0)])
    sigma = np.eye(6)
    sigma[4, 1] = np.inf
    for solver in (ProjectionSolver(2, [DistanceConstraint(0, 1, "max", 1.0)]),
                   QpSolver(2, [DistanceConstraint(0, 1, "max", 1.0)])):
        with pytest.raises(ValueError):
            solver.solve(np.zeros(6), sigma)


def test_module_exports():
    for name in fc.__all__:
        assert hasattr(fc, name)


@pytest.mark.parametrize("method", ["projection", "qp", "socp"])
def test_every_method_is_a_constraint_solver_built_from_the_layout(method):
    """One protocol: the fuser, the smoothed tracks' constraints and the compile-ahead build any
    method the same way, and each reaches the same point on the same problem."""
    from bodyfusion.core.constraints.solvers import ConstraintSolver, constraint_solver, distance_constraints
    from bodyfusion.core.layout import ConstraintConfig, FuserConfig

    if method == "socp":
        pytest.importorskip("cvxpy")
    cons = distance_constraints([ConstraintConfig(between=["a", "b"], kind="max", distance_m=1.0)], ["a", "b"])
    solver = constraint_solver(method, 2, cons, FuserConfig(method=method))
    assert isinstance(solver, ConstraintSolver) and solver.method == method
    p_hat = np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0])
    reference = constraint_solver("projection", 2, cons, FuserConfig()).solve(p_hat, np.eye(6))
    np.testing.assert_allclose(solver.solve(p_hat, np.eye(6)).p, reference.p, atol=1e-6)
