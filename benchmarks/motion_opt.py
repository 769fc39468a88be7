"""Motion optimization at robot scale (Eq. 7-9, Eq. 6): corl's banded SQP vs CasADi + Ipopt.

    python benchmarks/motion_opt.py [--repeats 7] [--json PATH]

Problem: a 7-DoF arm (spatial revolute chain, z/y axes alternating, closed-form geometric
Jacobian), a cubic B-spline with P control points (n = 7 P), T = 5 s, K = 2 P time steps.
Cost: squared accelerations (Eq. 9). Equalities: start and goal configuration fixed, and the
hand at a task-space point at t_c = 0.45 T (Eq. 6) that the demonstration misses by ~8 cm.
Start: the least-squares B-spline fit of a scripted, non-smooth demonstration (waypoints joined
by straight lines).

corl: :func:`corl.trajectory.solve` on a :class:`corl.trajectory.features.TrajectoryProblem`
with ``SolverConfig.trajectory()``: SQP (Newton-KKT) steps with the constraint curvature from the
closed-form fk Hessian, one banded Cholesky per step and the Schur complement on the few
constraint rows (:mod:`corl.trajectory.solver.sqp`), max|h| <= 1e-8. The scaling table also shows the
augmented-Lagrangian path (``method="al"``, one run per size) for comparison.
CasADi + Ipopt: the identical NLP (same A, same equalities, same start) with the exact Hessian,
tol 1e-9; its time is the ``solver(...)`` call only - building the expression graph and the
``nlpsol`` object is excluded. Times are medians over repeats. OPENBLAS_NUM_THREADS=1 is set
before numpy is imported (a threaded banded factorization was 30x slower).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from dataclasses import replace

os.environ["OPENBLAS_NUM_THREADS"] = "1"

import numpy as np  # noqa: E402

from corl.trajectory import SolverConfig, project, solve  # noqa: E402
from corl.trajectory.bspline import BSpline  # noqa: E402
from corl.trajectory.features import (  # noqa: E402
    TaskSpaceFeature,
    TrajectoryProblem,
    acceleration_feature,
    configuration_feature,
)

Q = 7
T = 5.0
T_CONTACT = 0.45 * T
AXES = "zyzyzyz"  # joint i rotates about this axis of its own frame, then the link goes along its z
LINKS_LIST = [0.33, 0.0, 0.40, 0.0, 0.39, 0.0, 0.13]
OFFSET = np.array([0.05, -0.04, 0.06])  # the contact target relative to the demonstration's hand
CONFIG = SolverConfig.trajectory()
AL_CONFIG = replace(CONFIG, method="al")  # the augmented Lagrangian, for the scaling comparison


# -- 7-DoF forward kinematics --------------------------------------------------------------------
def fk(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hand position y (3,) and geometric Jacobian dy/dq (3, 7): column i = a_i x (y - p_i).

    On Python floats (7 small rotations: numpy's per-call overhead would dominate).
    """
    R = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    px = py = pz = 0.0
    frames = []
    for qi, axis, length in zip(q.tolist(), AXES, LINKS_LIST):
        c, s = math.cos(qi), math.sin(qi)
        k = 2 if axis == "z" else 1  # rotation axis = column k of R
        frames.append((px, py, pz, R[0][k], R[1][k], R[2][k]))
        if axis == "z":  # R <- R Rz(q): columns 0, 1 rotate
            R = [[r[0] * c + r[1] * s, -r[0] * s + r[1] * c, r[2]] for r in R]
        else:  # R <- R Ry(q): columns 2, 0 rotate
            R = [[r[0] * c - r[2] * s, r[1], r[0] * s + r[2] * c] for r in R]
        px, py, pz = px + length * R[0][2], py + length * R[1][2], pz + length * R[2][2]
    J = [[0.0] * Q for _ in range(3)]
    for i, (ox, oy, oz, ax, ay, az) in enumerate(frames):
        dx, dy, dz = px - ox, py - oy, pz - oz
        J[0][i], J[1][i], J[2][i] = ay * dz - az * dy, az * dx - ax * dz, ax * dy - ay * dx
    return np.array([px, py, pz]), np.array(J)


def fk_hessian(q: np.ndarray) -> np.ndarray:
    """d^2 y / dq^2 (3, 7, 7) of the chain: entry (i, j) is a_min(i,j) x J_max(i,j), since turning
    joint j moves the axis a_i and origin of every later joint i rigidly (a_j x), and only y otherwise."""
    y, J = fk(q)
    axes = np.empty((Q, 3))
    R = np.eye(3)
    for i, axis in enumerate(AXES):
        axes[i] = R[:, 2] if axis == "z" else R[:, 1]
        c, s = math.cos(q[i]), math.sin(q[i])
        Ri = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) if axis == "z" else np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
        R = R @ Ri
    cols = J.T  # (7, 3)
    a, b = axes[:, None, :], cols[None, :, :]  # cross(a_i, J_j) for all i, j: (7, 7, 3)
    C = np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2], a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)
    return np.moveaxis(C[_LOW, _HIGH], -1, 0)


_LOW, _HIGH = np.minimum.outer(np.arange(Q), np.arange(Q)), np.maximum.outer(np.arange(Q), np.arange(Q))


def fk_casadi(q):
    """The same chain on a CasADi symbol q (7,)."""
    import casadi as ca

    R = ca.DM.eye(3)
    p = ca.DM.zeros(3)
    for i, axis in enumerate(AXES):
        c, s = ca.cos(q[i]), ca.sin(q[i])
        if axis == "z":
            Ri = ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
        else:
            Ri = ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))
        R = ca.mtimes(R, Ri)
        p = p + LINKS_LIST[i] * R[:, 2]
    return p


# -- the problem -----------------------------------------------------------------------------------
def demonstration(times: np.ndarray) -> np.ndarray:
    """Scripted, non-smooth joint trajectory (K+1, 7): straight lines between 6 waypoints."""
    waypoints = np.array(
        [
            [0.0, 0.3, 0.0, -1.2, 0.0, 0.8, 0.0],
            [0.3, 0.6, 0.2, -1.0, 0.3, 0.9, 0.2],
            [0.6, 0.8, 0.1, -0.7, 0.2, 1.1, 0.5],
            [0.7, 0.9, -0.2, -0.5, -0.1, 1.0, 0.6],
            [0.5, 0.6, -0.3, -0.8, -0.3, 0.7, 0.3],
            [0.2, 0.4, 0.0, -1.1, 0.0, 0.8, 0.1],
        ]
    )
    s = np.linspace(0.0, T, len(waypoints))
    return np.stack([np.interp(times, s, waypoints[:, j]) for j in range(Q)], axis=1)


def build(P: int):
    """(spline, problem, w0, target) for P control points."""
    spline = BSpline(P, Q, T)
    dense = np.linspace(0.0, T, 4 * P)
    demo = demonstration(dense)
    w0 = spline.fit(dense, demo)
    demo[0], demo[-1] = spline.positions(w0, [0.0, T])  # start and goal: where the fit starts and ends
    x_contact = spline.positions(w0, [T_CONTACT])[0]
    target = fk(x_contact)[0] + OFFSET
    problem = TrajectoryProblem(
        spline.n,
        costs=[acceleration_feature(spline, 2 * P)],
        equalities=[
            configuration_feature(spline, 0.0, demo[0]),
            configuration_feature(spline, T, demo[-1]),
            TaskSpaceFeature(spline, fk, [T_CONTACT], target, fk_hessian=fk_hessian),
        ],
    )
    return spline, problem, w0, target


def solve_corl(problem, w0, config=CONFIG):
    t0 = time.perf_counter()
    result = solve(problem, w0, config=config)
    return result, (time.perf_counter() - t0) * 1e3


def newton_step_ms(problem, w, lam, repeats: int) -> float:
    """One SQP iteration as the solver takes it at (w, lam): evaluate r, h and their Jacobians, the
    banded KKT Hessian H = 2 A^T A + sum_i lam_i d2h_i + 2 mu Jh^T Jh, its banded Cholesky and the
    Schur-complement solve for the step and the new multipliers."""
    from corl.trajectory.solver.kkt import constrained_step
    from corl.trajectory.solver.model import compute_grams, evaluate_problem, max_diagonal
    from corl.trajectory.solver.sqp import KKTModel

    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        pt = evaluate_problem(problem, w)
        _, H_J, gram = compute_grams(pt)
        model = KKTModel(pt, lam, max_diagonal(H_J) / max_diagonal(gram), True, False)
        d, _, _, _ = constrained_step(model.H, model.g, model.support, model.Js, pt.h)
        times.append(time.perf_counter() - t0)
    assert np.all(np.isfinite(d))
    return float(np.median(times) * 1e3)


def casadi_solver(spline, problem, w0, target):
    """(solve callable, build seconds) for the identical NLP with Ipopt (exact Hessian), or None."""
    try:
        import casadi as ca
    except ImportError:
        return None, 0.0
    t0 = time.perf_counter()
    A = problem._cost_linear.A.tocoo()
    Aeq = problem._eq_linear.A.tocoo()
    beq = problem._eq_linear.b
    w = ca.SX.sym("w", spline.n)
    Ad = ca.DM.triplet(A.row.tolist(), A.col.tolist(), A.data.tolist(), A.shape[0], A.shape[1])
    Aeqd = ca.DM.triplet(Aeq.row.tolist(), Aeq.col.tolist(), Aeq.data.tolist(), Aeq.shape[0], Aeq.shape[1])
    r = ca.mtimes(Ad, w)
    B = spline.basis([T_CONTACT]).toarray()[0]
    active = np.flatnonzero(B)
    x_c = sum(float(B[p]) * w[p * Q : (p + 1) * Q] for p in active)
    g = ca.vertcat(ca.mtimes(Aeqd, w) - beq, fk_casadi(x_c) - target)
    nlp = {"x": w, "f": ca.dot(r, r), "g": g}
    opts = {
        "ipopt.print_level": 0,
        "print_time": False,
        "ipopt.tol": 1e-9,
        "ipopt.constr_viol_tol": 1e-8,
        "ipopt.hessian_approximation": "exact",
        "ipopt.sb": "yes",
    }
    solver = ca.nlpsol("ipopt", "ipopt", nlp, opts)
    build_s = time.perf_counter() - t0
    nbound = g.shape[0]

    def run():
        t1 = time.perf_counter()
        sol = solver(x0=w0, lbg=np.zeros(nbound), ubg=np.zeros(nbound))
        ms = (time.perf_counter() - t1) * 1e3
        stats = solver.stats()
        return np.asarray(sol["x"]).ravel(), float(sol["f"]), ms, stats

    return run, build_s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--json", type=str, default=None)
    args = ap.parse_args()

    spline, problem, w0, target = build(150)
    runs = [solve_corl(problem, w0) for _ in range(args.repeats)]
    result = runs[0][0]
    corl_ms = float(np.median([ms for _, ms in runs]))
    step_ms = newton_step_ms(problem, result.w, result.multipliers, 50)
    print(f"7-DoF arm, P = 150 control points, n = {spline.n}, K = 300, contact at t_c = {T_CONTACT:g} s")
    print(f"corl: {result.status}")
    print("per-iteration report (iteration, outer, J, max|h|, ||step||):")
    for rec in result.history:
        print(f"  {rec.iteration:3d} {rec.outer:2d}  J = {rec.cost:14.6f}  max|h| = {rec.constraint_error:.2e}  step = {rec.step_norm:.2e}")

    run, build_s = casadi_solver(spline, problem, w0, target)
    casadi_ms = J_casadi = None
    if run is None:
        print("casadi not installed (pip install 'corl[bench]'); CasADi + Ipopt column skipped")
    else:
        outs = [run() for _ in range(args.repeats)]
        w_ca, J_casadi, _, stats = outs[0]
        casadi_ms = float(np.median([o[2] for o in outs]))
        h_ca = np.abs(problem.equalities(w_ca)[0]).max()
        print(
            f"casadi+ipopt: {stats['return_status']}, {stats['iter_count']} iterations, max|h| = {h_ca:.1e}, "
            f"graph + nlpsol build {build_s * 1e3:.0f} ms (excluded)"
        )

    print()
    print(f"{'':<24}{'corl':>14}{'casadi+ipopt':>16}")
    print(f"{'time to converge [ms]':<24}{corl_ms:>14.2f}{(casadi_ms or float('nan')):>16.2f}")
    iters_ca = stats["iter_count"] if run is not None else float("nan")
    print(f"{'Newton iterations':<24}{result.iterations:>14d}{iters_ca:>16}")
    print(f"{'final max|h|':<24}{result.constraint_error:>14.1e}{(h_ca if run else float('nan')):>16.1e}")
    print(f"{'J':<24}{result.cost:>14.6f}{(J_casadi if run else float('nan')):>16.6f}")
    ratio = casadi_ms / corl_ms if casadi_ms else None
    if ratio:
        print(f"ratio casadi / corl: {ratio:.2f}x   (relative J difference {abs(result.cost - J_casadi) / J_casadi:.1e})")
    print(f"one SQP step (evaluate + banded KKT Hessian + banded Cholesky + Schur solve): {step_ms:.3f} ms  (target < 1 ms)")

    # Eq. 18 (Alg. 1, step 2): a new theta moves the contact target by ~2 cm; project w* onto it.
    moved = TrajectoryProblem(
        spline.n,
        costs=[acceleration_feature(spline, 2)],
        equalities=[
            configuration_feature(spline, 0.0, spline.positions(w0, [0.0])[0]),
            configuration_feature(spline, T, spline.positions(w0, [T])[0]),
            TaskSpaceFeature(spline, fk, [T_CONTACT], target + np.array([0.01, 0.0, -0.02])),
        ],
    )
    projections = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        projected = project(moved, result.w)
        projections.append((time.perf_counter() - t0) * 1e3)
    project_ms = float(np.median(projections))
    print(
        f"Eq. 18 projection of w* onto a contact moved by 2 cm (n = {spline.n}): {project_ms:.2f} ms, "
        f"max|h| = {projected.constraint_error:.1e}, ||w - w*|| = {np.linalg.norm(projected.w - result.w):.3f}"
    )

    print()
    print(f"{'P':>6}{'n':>8}{'iterations':>12}{'ms':>10}{'ms / n * 1000':>16}{'AL iterations':>15}{'AL ms':>10}")
    scaling = {}
    for P in (50, 150, 500, 1500):
        _, prob, w_init, _ = build(P)
        times = [solve_corl(prob, w_init) for _ in range(max(3, args.repeats // 2))]
        ms = float(np.median([t for _, t in times]))
        scaling[str(P)] = ms
        res = times[0][0]
        al, al_ms = solve_corl(prob, w_init, AL_CONFIG)
        print(
            f"{P:>6}{P * Q:>8}{res.iterations:>12}{ms:>10.2f}{ms / (P * Q) * 1000:>16.3f}{al.iterations:>15}{al_ms:>10.1f}"
            f"   {'ok' if res.converged else res.status}"
        )

    if args.json:
        out = {
            "corl_ms": corl_ms,
            "casadi_ms": casadi_ms,
            "ratio": ratio,
            "newton_step_ms": step_ms,
            "iterations": result.iterations,
            "error": result.constraint_error,
            "J_corl": result.cost,
            "J_casadi": J_casadi,
            "scaling_ms": scaling,
            "project_ms": project_ms,
        }
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()
