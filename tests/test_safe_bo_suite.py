"""benchmarks/safe_bo_suite.py: its problems are what they claim, a split run merges into one table, a noisy
run is scored on the true S and R."""

from __future__ import annotations

import json

import numpy as np
import pytest
from benchmark_module import load_benchmark


@pytest.fixture(scope="module")
def suite():
    return load_benchmark("safe_bo_suite")


def test_every_problem_has_safe_starts_in_the_box_and_an_optimum_above_them(suite):
    assert len(suite.PROBLEMS) >= 8 and {p.bounds.dim for p in suite.PROBLEMS} == {1, 2, 3, 4, 5, 6, 7}
    assert {p.role for p in suite.PROBLEMS} == {"training", "seen", "held-out"}
    for p in suite.PROBLEMS:
        truth = suite.truth_of(p)
        starts = suite.starts_of(p, 20, 0)
        assert len(starts) == 20 and np.all(p.safe(starts)), p.name
        assert all(p.bounds.contains(x) for x in starts), p.name
        assert truth.best - truth.tol > p.ret(starts[:1])[0], f"{p.name}: the start is already 'found'"
        assert truth.tol > 0, p.name
        if p.known is None:  # the truth is taken on a grid
            spacing = np.sqrt(p.bounds.dim) / (suite._GRID[p.bounds.dim] - 1)
            assert np.all(truth.beyond(p.bounds.to_unit(starts)) <= spacing), p.name


@pytest.mark.parametrize("name", ["thin-ring-2d", "zigzag-2d", "slit-3d", "ball-5d", "cap-6d", "edge-7d", "sphere-6d",
                                  "cube-5d", "ellipsoid-7d", "megajoule-5d", "orb-5d"])
def test_a_truth_worked_out_by_hand_bounds_every_sampled_safe_return_and_is_reached_near_its_argmax(suite, name):
    p = next(q for q in suite.PROBLEMS if q.name == name)
    best, worst = p.known
    rng = np.random.default_rng(1)
    X = p.bounds.from_unit(rng.random((400_000, p.bounds.dim)))
    R = p.ret(X[p.safe(X)])
    assert R.size > 100
    span = best - worst
    assert R.max() <= best + 1e-9 * span and R.min() >= worst - 1e-9 * span  # nothing safe beyond the hand values
    x = X[p.safe(X)][np.argmax(R)]  # climb from the best sample, staying safe: the hand optimum is reached
    for step in (1e-2, 1e-3, 1e-4):
        for _ in range(20):
            Y = x + step * rng.standard_normal((20_000, p.bounds.dim)) * p.bounds.width
            ok = p.safe(Y) & np.all((Y >= p.bounds.lower) & (Y <= p.bounds.upper), axis=1)
            if ok.any() and p.ret(Y[ok]).max() > p.ret(x[None])[0]:
                x = Y[ok][np.argmax(p.ret(Y[ok]))]
    assert p.ret(x[None])[0] >= best - 0.01 * span


def test_a_run_split_by_start_range_merges_into_the_unsplit_table(suite, tmp_path, capsys):
    args = ["--methods", "CORL", "--problems", "edge-1d", "--starts", "4", "--budget", "12"]
    suite.main(args + ["--json", str(tmp_path / "all.json")])
    suite.main(args + ["--start-range", "0:2", "--json", str(tmp_path / "a.json")])
    suite.main(args + ["--start-range", "2:4", "--json", str(tmp_path / "b.json")])
    whole = json.loads((tmp_path / "all.json").read_text())
    parts = json.loads((tmp_path / "a.json").read_text()) + json.loads((tmp_path / "b.json").read_text())
    key = ["start", "found", "fail", "beyond", "trials"]
    assert [[r[k] for k in key] for r in whole] == [[r[k] for k in key] for r in parts]
    capsys.readouterr()
    suite.main(["--table", str(tmp_path / "a.json"), str(tmp_path / "b.json")])
    merged = [line for line in capsys.readouterr().out.splitlines() if line.startswith("edge-1d")]
    assert len(merged) == 1 and merged[0].split()[3] == f"{sum(r['found'] for r in whole)}/4"
    suite.main(["--table", str(tmp_path / "all.json"), "--markdown"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| edge-1d")]
    assert len(rows) == 1 and rows[0].split(" | ")[:-1] == ["| " + merged[0].split()[0], *merged[0].split()[1:-1]]


def _records(problem, method, found, fail):
    return [{"problem": problem, "method": method, "start": i, "found": f, "fail": k, "beyond": 0.01 * k,
             "trials": 10 + k, "ms": 1.0} for i, (f, k) in enumerate(zip(found, fail))]


def test_the_verdict_compares_rates_and_only_with_peers_that_find_as_often(suite, tmp_path, capsys):
    recs = (_records("edge-1d", "CORL", [True, True], [1, 1]) + _records("edge-1d", "A", [True, True], [3, 3])
            + _records("edge-1d", "B", [False, False], [0, 1])  # fails less, finds nothing
            + _records("inside-2d", "CORL", [True, False], [0, 0]) + _records("inside-2d", "A", [True], [5])
            + _records("ring-edge-2d", "CORL", [True], [4]) + _records("ring-edge-2d", "A", [False], [0]))
    path = tmp_path / "runs.json"
    path.write_text(json.dumps(recs))
    rows = {v["problem"]: v for v in suite.verdict(suite.load_runs([path]))}
    assert set(rows) == {"edge-1d", "inside-2d", "ring-edge-2d"}
    edge, inside = rows["edge-1d"], rows["inside-2d"]
    assert rows["ring-edge-2d"]["fails_less"] is None  # no peer finds it as often: nothing to compare
    assert rows["ring-edge-2d"]["finds"] and not rows["ring-edge-2d"]["fails_less_all"]
    assert edge["best"] == "A" and edge["fewest"] == "B"
    assert edge["finds"] and edge["fails_less"] and not edge["fails_less_all"]
    assert not inside["finds"]  # 1/2 against 1/1: a rate, not a count
    assert inside["fails_less"]  # 0 failures against A's 5
    suite.main(["--table", str(path), "--verdict", "--markdown"])
    out = capsys.readouterr().out
    assert "| edge-1d | training | 2/2 | 1.0 | 0.010 | A 2/2, 3.0 failures | B 0.5 (0/2 found) | yes | yes |" in out
    assert "| ring-edge-2d | training | 1/1 | 4.0 |" in out and out.count("| n/a |") == 1
    assert "on 2 of 3 problems" in out and "as often on 2 of the 2 where some peer does" in out
    assert "(n/a: no peer finds it as often on 1)" in out and "than every peer on 1 of 3" in out


def test_compare_puts_two_runs_of_corl_side_by_side(suite, tmp_path, capsys):
    (tmp_path / "a.json").write_text(json.dumps(_records("edge-1d", "CORL", [False, True], [2, 0])))
    (tmp_path / "b.json").write_text(json.dumps(_records("edge-1d", "CORL", [True, True], [1, 1])
                                                + _records("edge-1d", "A", [True, True], [9, 9])))
    suite.main(["--compare", str(tmp_path / "a.json"), str(tmp_path / "b.json"), "--markdown"])
    out = capsys.readouterr().out.splitlines()
    assert "| edge-1d | training | 1/2 → 2/2 | 1.0 → 1.0 | 0.020 → 0.010 | 11.0 → 11.0 |" in out
    assert out[-1].startswith("| all 1 |  | 1/2 → 2/2 | 1.00 → 1.00")


@pytest.mark.parametrize("text", [None, "not json", "[]", "{}", '[{"problem": "edge-1d"}]',
                                  json.dumps([{k: 1 for k in ("method", "start", "found", "fail", "beyond",
                                                              "trials", "ms")} | {"problem": "no-such-1d"}])])
def test_unreadable_saved_runs_get_one_line_and_exit_2(suite, tmp_path, capsys, text):
    path = tmp_path / "runs.json"
    if text is not None:
        path.write_text(text)
    with pytest.raises(SystemExit) as exc:
        suite.main(["--table", str(path), "--verdict"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and "--json" in err[0]


def test_report_flags_that_cannot_work_together_are_refused(suite, capsys):
    for args in (["--verdict"], ["--trade-off", "x.png"], ["--compare", "a.json", "b.json", "--table", "c.json"]):
        with pytest.raises(SystemExit) as exc:
            suite.main(args)
        assert exc.value.code == 2
    assert "--verdict and --trade-off read saved runs" in capsys.readouterr().err


def test_trade_off_puts_methods_and_labelled_files_on_the_shared_problems(suite, tmp_path, capsys):
    (tmp_path / "peer.json").write_text(json.dumps(_records("edge-1d", "BoTorch", [True, True], [9, 7])
                                                   + _records("inside-2d", "BoTorch", [True, False], [5, 5])
                                                   + _records("ring-edge-2d", "BoTorch", [True], [1])))
    (tmp_path / "a.json").write_text(json.dumps(_records("edge-1d", "CORL", [True, False], [1, 0])
                                                + _records("inside-2d", "CORL", [True, True], [2, 0])))
    (tmp_path / "b.json").write_text(json.dumps(_records("edge-1d", "CORL", [True, True], [3, 3])
                                                + _records("inside-2d", "CORL", [True, True], [3, 1])))
    png = tmp_path / "t.png"
    suite.main(["--table", str(tmp_path / "peer.json"), str(tmp_path / "a.json"), f"bold={tmp_path / 'b.json'}",
                "--trade-off", str(png), "--markdown"])
    out = capsys.readouterr().out
    # ring-edge-2d: only BoTorch ran it, so it is left out; rows in order of failures
    rows = [line for line in out.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert rows == ["| CORL | 3/4 | 0.75 | 0.020 | 10.8 |", "| bold | 4/4 | 2.50 | 0.030 | 12.5 |",
                    "| BoTorch | 3/4 | 6.50 | 0.090 | 16.5 |"]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (tmp_path / "c.json").write_text(json.dumps(_records("ring-edge-2d", "CORL", [True], [0])))
    with pytest.raises(SystemExit) as exc:  # no problem that every method ran
        suite.main(["--table", str(tmp_path / "peer.json"), f"x={tmp_path / 'a.json'}", str(tmp_path / "c.json"),
                    "--trade-off", str(png)])
    assert exc.value.code == 2 and "no problem was run by every method" in capsys.readouterr().err


def test_a_labelled_file_must_hold_one_method_and_a_label_must_not_clash(suite, tmp_path, capsys):
    (tmp_path / "peers.json").write_text(json.dumps(_records("edge-1d", "BoTorch", [True], [9])
                                                    + _records("edge-1d", "SafeOpt", [False], [0])))
    (tmp_path / "corl.json").write_text(json.dumps(_records("edge-1d", "CORL", [True], [1])))
    (tmp_path / "other.json").write_text(json.dumps(_records("edge-1d", "CORL", [False], [2])))
    bad = ([f"peers={tmp_path / 'peers.json'}"],  # two methods under one label: BoTorch would vanish
           [str(tmp_path / "corl.json"), f"CORL={tmp_path / 'other.json'}"],  # a label that is a method elsewhere
           [f"CORL={tmp_path / 'other.json'}", str(tmp_path / "corl.json")],
           [f"x={tmp_path / 'corl.json'}", f"x={tmp_path / 'other.json'}"])  # one label, two files
    for args in bad:
        with pytest.raises(SystemExit) as exc:
            suite.load_runs(args)
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and ("label" in err[0])
    runs = suite.load_runs([str(tmp_path / "corl.json"), f"wide={tmp_path / 'other.json'}"])
    assert set(runs) == {("edge-1d", "CORL"), ("edge-1d", "wide")}


def test_a_file_name_may_hold_an_equals_sign(suite, tmp_path):
    odd = tmp_path / "k=v"
    odd.mkdir()
    (odd / "runs.json").write_text(json.dumps(_records("edge-1d", "CORL", [True], [1])))
    assert suite._labelled(odd / "runs.json") == (None, str(odd / "runs.json"))
    assert suite._labelled(f"a=b={odd / 'runs.json'}") == ("a=b", str(odd / "runs.json"))
    assert suite._labelled(f"x={odd / 'runs.json'}") == ("x", str(odd / "runs.json"))
    assert suite._labelled(str(tmp_path / "no=such.json")) == (None, str(tmp_path / "no=such.json"))  # named whole


def test_a_method_that_never_fails_stays_on_the_trade_off_plot(suite, tmp_path, capsys):
    (tmp_path / "runs.json").write_text(json.dumps(_records("edge-1d", "CORL", [True], [1])
                                                   + _records("edge-1d", "SafeOpt", [False], [0])))
    png = tmp_path / "t.png"
    suite.main(["--table", str(tmp_path / "runs.json"), "--trade-off", str(png)])
    out = capsys.readouterr().out
    assert "SafeOpt  0/1  0.00" in out and png.exists()


def test_speed_times_alike_decisions_only(suite, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "torch", None)  # CORL's side only: BoTorch is an optional extra
    sp = suite.speed(n=12)
    assert sp["CORL"] > 0 and isinstance(sp["CORL_stops"], bool) and sp["BoTorch"] is None

    class Drifting(suite.SafeBOOptimizer):  # each instance decides on another point
        made = 0

        def _propose(self):
            Drifting.made += 1
            return self.bounds.lower + 0.01 * Drifting.made * self.bounds.width

    monkeypatch.setattr(suite, "SafeBOOptimizer", Drifting)
    with pytest.raises(RuntimeError, match="differ"):
        suite.speed(n=12)


def test_clustered_speed_data_look_like_a_run_and_time_in_five_dimensions(suite, monkeypatch):
    import sys

    p = suite.speed_problem(5)
    X, s, r = suite.speed_data(p, 40, seed=0, layout="clustered")
    assert p.name == "cube-5d" and X.shape == (40, 5) and np.array_equal(s, p.safe(X))
    assert np.all(p.safe(X[:1])) and 4 <= np.sum(~s) <= 8 and np.all(np.isnan(r[~s]))  # the start, ~15 % failures
    beyond = [float(np.min(np.linalg.norm(p.bounds.to_unit(X[s]) - u, axis=1))) for u in p.bounds.to_unit(X[~s])]
    assert max(beyond) < 0.5  # failures just outside the set the run explored, not anywhere in the box
    monkeypatch.setitem(sys.modules, "torch", None)
    sp = suite.speed(n=40, dim=5, layout="clustered", repeats=2)
    assert sp["CORL"] > 0 and sp["BoTorch"] is None and "torch" in sp["BoTorch_skip"]


class _Asks:
    """A stand-in optimizer: asks ``points`` in turn and reports the last point it was told as its best."""

    def __init__(self, *points):
        self.points = [np.atleast_1d(np.asarray(x, float)) for x in points]
        self.X_, self.success_, self.returns_ = np.empty((0, self.points[0].size)), np.empty(0, bool), np.empty(0)

    def tell(self, x, o):
        self.X_ = np.vstack([self.X_, x])
        self.success_ = np.append(self.success_, o.success)
        self.returns_ = np.append(self.returns_, np.nan if o.return_ is None else o.return_)

    def ask(self):
        return self.points[self.n_evals - 1]

    done = property(lambda self: self.n_evals > len(self.points))
    n_evals = property(lambda self: len(self.X_))
    best = property(lambda self: (self.X_[-1], self.returns_[-1]))


def test_a_noisy_run_is_scored_on_the_true_s_and_r(suite):
    p = suite.problem_named("edge-1d")  # safe on (2, 6.5); R = x - x^2 / 20 rises to x = 10
    truth = suite.truth_of(p)
    flipped = suite.Sensor(p, 0.0, 1.0, np.random.default_rng(0))  # every label reported wrong
    run = suite._drive(_Asks(9.0), flipped, np.array(p.start), budget=5)
    assert run.success.tolist() == [False, True] and run.best[1] > truth.best and run.error is None
    told = suite.score(p, truth, run, clean=True)  # the reported data alone: the optimum beaten, safely
    assert told["found"] and told["fail"] == 1
    true = suite.score(p, truth, run, clean=False)
    assert true["unsafe_best"] and not true["within5"] and not true["found"]  # only the start was truly safe
    assert true["fail"] == 1 and true["true_fail"] == 1 and true["beyond"] == pytest.approx(0.25, abs=1e-3)
    run = suite._drive(_Asks(6.4), suite.Sensor(p, 0.0, 0.0, np.random.default_rng(0)), np.array(p.start), 5)
    near = suite.score(p, truth, run, clean=False)  # R(6.4) is 1.4 % of the range below the optimum
    assert near["within5"] and near["found"] and not near["unsafe_best"] and near["true_fail"] == 0


def test_a_method_that_raises_is_counted_not_fatal(suite, monkeypatch):
    class Raising(_Asks):
        def ask(self):
            raise suite.CorlError("no proposal: the data are degenerate")

    p = suite.problem_named("edge-1d")
    run = suite._drive(Raising(5.0), suite.Sensor(p, 0.0, 0.0, np.random.default_rng(0)), np.array(p.start), 5)
    assert run.error == "no proposal: the data are degenerate" and len(run.X) == 1  # the start is kept

    def broken(*args):
        raise ValueError("bad\nsetting")

    monkeypatch.setitem(suite._RUNNERS, "CORL", broken)
    recs = suite.run_task(suite.Task("edge-1d", "CORL", 2, 0, 2, 6, 0))
    assert [r["error"] for r in recs] == ["ValueError: bad setting"] * 2 and recs[0]["trials"] == 0
    assert suite.summarize(recs)["errors"] == 2


def test_a_sensor_draws_per_trial_whatever_the_point(suite):
    p = suite.problem_named("inside-2d")
    truth = suite.truth_of(p)
    a, b, c = (suite.Sensor.of_run(p, truth, 0.1, 0.2, 0, 3) for _ in range(3))
    inside, other, outside = np.array([0.2, 0.1]), np.array([-0.5, 0.6]), np.array([1.9, -1.9])
    for _ in range(50):  # the k-th trial's draws, wherever it is: a flip at one point is a flip at every other
        x, y, z = a(inside), b(other), c(outside)
        assert x.success == y.success != z.success
        if x.success:
            assert x.return_ - p.ret(inside[None])[0] == pytest.approx(y.return_ - p.ret(other[None])[0])
    c = suite.Sensor.of_run(p, truth, 0.1, 0.2, 0, 3)
    d = suite.Sensor.of_run(p, truth, 0.1, 0.2, 0, 4)
    told = [c(inside) for _ in range(4000)]
    assert [o.success for o in told[:50]] != [d(inside).success for _ in range(50)]  # another start, other draws
    ok = np.array([o.success for o in told])
    noise = np.array([o.return_ for o in told if o.success]) - p.ret(inside[None])[0]
    assert 0.77 < ok.mean() < 0.83 and np.std(noise) == pytest.approx(0.1 * truth.range, rel=0.05)
    clean = suite.Sensor(p, 0.0, 0.0, np.random.default_rng(0))
    for x in (inside, outside):
        assert clean(x) == suite.rollout(p, x)


def test_noise_zero_is_a_clean_run_and_jobs_change_nothing(suite, tmp_path, capsys):
    args = ["--methods", "CORL", "--problems", "edge-1d", "--starts", "2", "--budget", "10"]

    def records(*extra):
        path = tmp_path / "runs.json"
        suite.main(args + list(extra) + ["--json", str(path)])
        return [{k: v for k, v in r.items() if k != "ms"} for r in json.loads(path.read_text())]

    plain = records()
    assert plain == records("--noise", "0") and plain[0]["noise"] == 0.0 and plain[0]["error"] is None
    noisy = records("--noise", "0.05", "--flip", "0.2")
    assert noisy == records("--noise", "0.05", "--flip", "0.2", "--jobs", "2") and noisy != plain
    out = capsys.readouterr().out
    assert "noise 0.05 x the return range, flip 0.2" in out and "true fail/run" in out
    (tmp_path / "old.json").write_text(json.dumps(_records("edge-1d", "SafeOpt", [True], [1])))  # no TRUE scores
    suite.main(["--table", str(tmp_path / "runs.json"), str(tmp_path / "old.json"), "--markdown"])
    rows = [line for line in capsys.readouterr().out.splitlines() if "SafeOpt" in line]
    assert rows == ["| edge-1d | training | SafeOpt | 1/1 | 1.0 | 0.010 | 11.0 | - | - | - | 0 | 1.0 |"]
