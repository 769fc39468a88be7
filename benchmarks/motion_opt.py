"""Motion optimization at robot scale (Eq. 7-9, Eq. 6): corl's banded SQP vs CasADi + Ipopt.

    python benchmarks/motion_opt.py [--repeats 7] [--json PATH]

Problem: a 7-DoF arm (spatial revolute chain, z/y axes alternating, closed-form geometric
Jacobian and Hessian), a cubic B-spline with P control points (n = 7 P), T = 5 s, K = 2 P time
steps. Cost: squared accelerations (Eq. 9). Equalities: start and goal configuration fixed, and the
hand at a task-space point at t_c = 0.45 T (Eq. 6) that the demonstration misses by ~8 cm.
Start: the least-squares B-spline fit of a scripted, non-smooth demonstration (waypoints joined
by straight lines). Compared at P = 150 (n = 1050) and P = 1500 (n = 10500).

corl: :func:`corl.trajectory.solve` on a :class:`corl.trajectory.features.TrajectoryProblem`
with ``SolverConfig.trajectory()``: SQP (Newton-KKT) steps with the constraint curvature from the
closed-form fk Hessian (fk and its Hessian share one pass over the chain at the same q, as a
user's kinematics would), the start and goal rows eliminated from the band, the band condensed on
the contact's window (:mod:`corl.trajectory.solver.kkt`), max|h| <= 1e-8. The scaling table also
shows the augmented-Lagrangian path (``method="al"``, one run per size) for comparison.
CasADi + Ipopt: the identical NLP (same A, same equalities, same start) with the exact Hessian,
tol 1e-9; its time is the ``solver(...)`` call only - building the expression graph and the
``nlpsol`` object is excluded. corl and CasADi runs alternate; times are medians over repeats.

"one SQP step" is what one iteration of the solver costs at the solution: evaluate r, h and their
Jacobians, assemble the banded KKT Hessian, factorize, solve for the step and multipliers (median
of many). Beside it, the floor it is compared with: LAPACK ``dpbtrf`` of the same KKT Hessian (the
same n, band and values), measured in the same run. The versions of corl's libraries
(:func:`corl.versions.library_versions`), CasADi and Ipopt are printed first.
OPENBLAS_NUM_THREADS=1 is set before numpy is imported (a threaded banded factorization was 30x
slower).
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
_LAST_CHAIN: list = [None, None]  # (q as bytes, chain): fk and fk_hessian at the same q share one pass


def _chain(q: np.ndarray) -> tuple[tuple[float, float, float], list]:
    """Hand position y and, per joint i, (origin p_i, axis a_i) as 6 Python floats, for q (7,).

    On Python floats (7 small rotations: numpy's per-call overhead would dominate). The solver asks
    for fk and then its Hessian at the same q, so the last chain is kept."""
    key = q.tobytes()
    if _LAST_CHAIN[0] == key:
        return _LAST_CHAIN[1]
    chain = _chain_at(q)
    _LAST_CHAIN[0], _LAST_CHAIN[1] = key, chain
    return chain


def _chain_at(q: np.ndarray) -> tuple[tuple[float, float, float], list]:
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
    return (px, py, pz), frames


def fk(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hand position y (3,) and geometric Jacobian dy/dq (3, 7): column i = a_i x (y - p_i)."""
    (px, py, pz), frames = _chain(q)
    J = [[0.0] * Q for _ in range(3)]
    for i, (ox, oy, oz, ax, ay, az) in enumerate(frames):
        dx, dy, dz = px - ox, py - oy, pz - oz
        J[0][i], J[1][i], J[2][i] = ay * dz - az * dy, az * dx - ax * dz, ax * dy - ay * dx
    return np.array([px, py, pz]), np.array(J)


def fk_hessian(q: np.ndarray) -> np.ndarray:
    """d^2 y / dq^2 (3, 7, 7) of the chain: entry (i, j) is a_min(i,j) x J_max(i,j), since turning
    joint j moves the axis a_i and origin of every later joint i rigidly (a_j x), and only y otherwise."""
    (px, py, pz), frames = _chain(q)
    cols = []  # J_j = a_j x (y - p_j)
    for ox, oy, oz, ax, ay, az in frames:
        dx, dy, dz = px - ox, py - oy, pz - oz
        cols.append((ay * dz - az * dy, az * dx - ax * dz, ax * dy - ay * dx))
    H = [[[0.0] * Q for _ in range(Q)] for _ in range(3)]
    Hx, Hy, Hz = H
    for i, (_, _, _, ax, ay, az) in enumerate(frames):
        for j in range(i, Q):
            jx, jy, jz = cols[j]
            Hx[i][j] = Hx[j][i] = ay * jz - az * jy
            Hy[i][j] = Hy[j][i] = az * jx - ax * jz
            Hz[i][j] = Hz[j][i] = ax * jy - ay * jx
    return np.array(H)


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


def kkt_model(problem, w, lam):
    """The SQP's KKT model at (w, lam), as its first try builds it (mu on the scale of H_J)."""
    from corl.trajectory.solver.model import compute_grams, evaluate_problem, max_diagonal
    from corl.trajectory.solver.sqp import KKTModel

    pt = evaluate_problem(problem, w)
    _, H_J, gram = compute_grams(pt)
    return pt, KKTModel(pt, lam, max_diagonal(H_J) / max_diagonal(gram), True, False)


def newton_step_ms(problem, w, lam, repeats: int) -> float:
    """One SQP iteration as the solver takes it at (w, lam): evaluate r, h and their Jacobians, the
    banded KKT Hessian H = 2 A^T A + sum_i lam_i d2h_i + 2 mu Jh^T Jh, its banded Cholesky and the
    Schur-complement solve for the step and the new multipliers. Median over ``repeats``."""
    from corl.trajectory.solver.kkt import constrained_step

    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        pt, model = kkt_model(problem, w, lam)
        d, _, _, _ = constrained_step(model.H, model.g, model.support, model.Js, pt.h, structure=model.structure)
        times.append(time.perf_counter() - t0)
    assert np.all(np.isfinite(d))
    return float(np.median(times) * 1e3)


def cholesky_ms(problem, w, lam, repeats: int) -> tuple[float, int]:
    """The floor: LAPACK ``dpbtrf`` of the same KKT Hessian (the same band, n and values) at (w, lam),
    as scipy calls it (with its copy of the input). Median over ``repeats``; and the bandwidth."""
    from scipy.linalg.lapack import dpbtrf

    _, model = kkt_model(problem, w, lam)
    ab = model.H.band()  # H_J + 2 mu Jh^T Jh + curvature in band storage
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        _, info = dpbtrf(ab, lower=1)
        times.append(time.perf_counter() - t0)
    assert info == 0
    return float(np.median(times) * 1e3), ab.shape[0] - 1


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


def casadi_versions() -> str:
    """"CasADi x, Ipopt y (linear solver)", or why not: Ipopt's banner of a one-variable solve, read
    from file descriptor 1 (Ipopt prints from C)."""
    try:
        import casadi as ca
    except ImportError:
        return "casadi not installed"
    import re
    import tempfile

    x = ca.SX.sym("x")
    solver = ca.nlpsol("v", "ipopt", {"x": x, "f": x**2}, {"ipopt.print_level": 5, "print_time": False, "ipopt.sb": "no"})
    saved = os.dup(1)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 1)
        try:
            solver(x0=1.0)
        finally:
            os.dup2(saved, 1)
            os.close(saved)
        tmp.seek(0)
        banner = tmp.read().decode(errors="replace")
    version = re.search(r"Ipopt version ([0-9.]+)", banner)
    linear = re.search(r"linear solver (\S+ [0-9.]+)", banner)
    ipopt = f"Ipopt {version.group(1)}" if version else "Ipopt (version not reported)"
    return f"CasADi {ca.__version__}, {ipopt}" + (f" ({linear.group(1).rstrip('.')})" if linear else "")


def compare(P: int, repeats: int) -> dict:
    """corl and CasADi + Ipopt on the problem with P control points, runs interleaved (median ms);
    one SQP step and its floor, dpbtrf of the same band, measured in the same run."""
    spline, problem, w0, target = build(P)
    run, build_s = casadi_solver(spline, problem, w0, target)
    corl_runs, casadi_runs = [], []
    for _ in range(repeats):
        corl_runs.append(solve_corl(problem, w0))
        if run is not None:
            casadi_runs.append(run())
    result = corl_runs[0][0]
    step_repeats = max(20, 2000 // P)
    out = {
        "P": P, "n": spline.n, "result": result, "problem": problem, "spline": spline, "w0": w0, "target": target,
        "corl_ms": float(np.median([ms for _, ms in corl_runs])),
        "step_ms": newton_step_ms(problem, result.w, result.multipliers, step_repeats),
        "casadi_ms": None, "casadi": None, "casadi_build_s": build_s,
    }
    out["cholesky_ms"], out["bandwidth"] = cholesky_ms(problem, result.w, result.multipliers, step_repeats)
    if casadi_runs:
        w_ca, J_ca, _, stats = casadi_runs[0]
        out["casadi_ms"] = float(np.median([o[2] for o in casadi_runs]))
        out["casadi"] = {"J": J_ca, "iterations": stats["iter_count"], "status": stats["return_status"],
                         "error": float(np.abs(problem.equalities(w_ca)[0]).max())}
    return out


def print_table(cases: list[dict]) -> None:
    """corl beside CasADi + Ipopt for each case, with the targets of the comparison."""
    head = "".join(format("P = %d, n = %d" % (c["P"], c["n"]), ">30") for c in cases)
    print(f"{'':<44}{head}")
    print(f"{'':<44}" + "".join(f"{'corl':>14}{'casadi+ipopt':>16}" for _ in cases))

    def row(label, corl, casadi, fmt):
        cells = "".join(f"{format(a, fmt):>14}{(format(b, fmt) if b is not None else 'n/a'):>16}" for a, b in zip(corl, casadi))
        print(f"{label:<44}{cells}")

    row("time to converge [ms]", [c["corl_ms"] for c in cases], [c["casadi_ms"] for c in cases], ".2f")
    row("Newton iterations", [c["result"].iterations for c in cases], [c["casadi"] and c["casadi"]["iterations"] for c in cases], "d")
    row("final max|h|", [c["result"].constraint_error for c in cases], [c["casadi"] and c["casadi"]["error"] for c in cases], ".1e")
    row("J", [c["result"].cost for c in cases], [c["casadi"] and c["casadi"]["J"] for c in cases], ".6f")

    def single(label, values, fmt):
        print(f"{label:<44}" + "".join(f"{(format(v, fmt) if v is not None else 'n/a'):>14}{'':>16}" for v in values))

    single("corl / casadi+ipopt time (target <= 0.30)", [c["corl_ms"] / c["casadi_ms"] if c["casadi_ms"] else None for c in cases], ".3f")
    single("relative J difference", [abs(c["result"].cost - c["casadi"]["J"]) / c["casadi"]["J"] if c["casadi"] else None for c in cases], ".1e")
    single("one SQP step [ms] (target <= 0.5 at n=1050)", [c["step_ms"] for c in cases], ".3f")
    single("banded Cholesky, dpbtrf same band [ms]", [c["cholesky_ms"] for c in cases], ".3f")
    single("  its bandwidth u", [c["bandwidth"] for c in cases], "d")
    single("SQP step / Cholesky (target <= 3)", [c["step_ms"] / c["cholesky_ms"] for c in cases], ".2f")


def main() -> None:
    import corl.versions

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--json", type=str, default=None)
    args = ap.parse_args()

    print("versions:", ", ".join(f"{k} {v}" for k, v in corl.versions.library_versions().items()))
    print("versions:", casadi_versions())
    cases = [compare(150, args.repeats), compare(1500, max(3, args.repeats // 2))]
    first = cases[0]
    result, spline = first["result"], first["spline"]
    print(f"7-DoF arm, contact at t_c = {T_CONTACT:g} s; P = 150 (n = {spline.n}, K = 300) and P = 1500 (n = 10500, K = 3000)")
    print(f"corl: {result.status}")
    print("per-iteration report at P = 150 (iteration, outer, J, max|h|, ||step||):")
    for rec in result.history:
        print(f"  {rec.iteration:3d} {rec.outer:2d}  J = {rec.cost:14.6f}  max|h| = {rec.constraint_error:.2e}  step = {rec.step_norm:.2e}")
    for c in cases:
        if c["casadi"] is None:
            print("casadi not installed (pip install 'corl-skills[bench]'); CasADi + Ipopt columns skipped")
            break
        print(f"casadi+ipopt at P = {c['P']}: {c['casadi']['status']}, graph + nlpsol build {c['casadi_build_s'] * 1e3:.0f} ms (excluded)")
    print()
    print_table(cases)

    # Eq. 18 (Alg. 1, step 2): a new theta moves the contact target by ~2 cm; project w* onto it.
    w0, target = first["w0"], first["target"]
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
    print()
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
            "versions": corl.versions.library_versions(),
            "casadi": casadi_versions(),
            "cases": [
                {k: c[k] for k in ("P", "n", "corl_ms", "casadi_ms", "step_ms", "cholesky_ms", "bandwidth")}
                | {"iterations": c["result"].iterations, "J_corl": c["result"].cost,
                   "error": c["result"].constraint_error, "casadi_result": c["casadi"]}
                for c in cases
            ],
            "scaling_ms": scaling,
            "project_ms": project_ms,
        }
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()
