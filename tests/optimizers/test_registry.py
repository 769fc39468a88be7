"""make_optimizer and corl.optimize: the safe optimizer on its own, and its errors."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

import corl
from corl.errors import InputError, RolloutError
from corl.optimizers.base import BlackBoxOptimizer, StopReason
from corl.optimizers.bo import PIBUOptimizer
from corl.optimizers.registry import OptimizerSettings, register_optimizer
from corl.problem import Bounds, Outcome
from corl.tasks.synthetic import distance_to_safe, return_of

LOW, HIGH = [-math.pi], [math.pi]


def synthetic(theta):
    """The paper's 1-D problem as a plain function: (success, return)."""
    t = float(theta[0])
    ok = -1.5 < t < 2.5
    return ok, (return_of(t) if ok else None)


def test_optimize_finds_the_paper_optimum_safely_from_a_start():
    result = corl.optimize(synthetic, (LOW, HIGH), [1.8], budget=40, seed=0)  # CORL, the default
    assert abs(result.theta[0]) < 0.02 and result.return_ > 0.99
    assert result.optimizer.name == "CORL"
    assert result.stop_reason in (StopReason.CONVERGED, StopReason.NO_IMPROVEMENT) and result.trials < 40
    failed = result.optimizer.X_[~result.optimizer.success_, 0]
    assert result.failures == len(failed) <= 3 and all(distance_to_safe(t) < 0.3 for t in failed)
    assert np.array_equal(result.optimizer.X_[0], [1.8])  # the start is trial 1


@pytest.mark.parametrize("name", sorted(corl.OPTIMIZERS))
def test_every_method_runs_from_a_start_within_its_budget(name):
    result = corl.optimize(synthetic, (LOW, HIGH), [1.8], method=name, budget=25, seed=1)
    assert result.trials <= 25 and isinstance(result.stop_reason, StopReason)
    assert result.return_ >= return_of(1.8)  # never worse than the start


def test_f_may_return_an_outcome_and_the_callback_sees_every_trial():
    seen = []
    result = corl.optimize(lambda t: Outcome(*synthetic(t)), (LOW, HIGH), [0.5], budget=8, seed=0,
                           callback=lambda x, o: seen.append((x.copy(), o.success)))
    assert len(seen) == result.trials


def test_bad_arguments_are_clear_errors():
    with pytest.raises(InputError, match="start is not a point of the box"):
        corl.make_optimizer("PIBU", (LOW, HIGH), [4.0])
    with pytest.raises(InputError, match="no width in coordinate"):
        corl.make_optimizer("PIBU", ([0.0, 1.0], [1.0, 1.0]), [0.5, 1.0])
    with pytest.raises(InputError, match="unknown optimizer 'PIBO'; choose one of PIBU"):
        corl.make_optimizer("PIBO", (LOW, HIGH), [0.0])
    with pytest.raises(InputError, match="budget"):
        corl.make_optimizer("PIBU", (LOW, HIGH), [0.0], budget=0)
    with pytest.raises(InputError, match="pair"):
        corl.make_optimizer("PIBU", 3.0, [0.0])
    with pytest.raises(InputError, match="OptimizerSettings"):
        corl.make_optimizer("PIBU", (LOW, HIGH), [0.0], settings={"lengthscale": 1})


def test_a_failing_start_of_a_safe_method_is_an_error_that_keeps_the_optimizer():
    with pytest.raises(InputError, match="start .* failed") as info:
        corl.optimize(synthetic, (LOW, HIGH), [3.0], budget=10)
    opt = info.value.optimizer
    assert opt.stop_reason is StopReason.NO_SAFE_POINT and opt.n_evals == 3  # the start, and twice more (start_retries)
    opt.tell([0.5], synthetic([0.5]))  # usable: a success lets it go on
    assert not opt.done
    # a method that ignores safety just goes on from a failing start
    assert corl.optimize(synthetic, (LOW, HIGH), [3.0], method="CMA", budget=10, seed=0).trials == 10


def test_a_nan_from_f_or_an_exception_in_f_keeps_the_pending_trial():
    calls = []

    def flaky(theta):
        calls.append(theta)
        return (True, math.nan) if len(calls) == 3 else synthetic(theta)

    with pytest.raises(InputError, match="bad value in trial 3.*finite return") as info:
        corl.optimize(flaky, (LOW, HIGH), [1.0], budget=10, seed=0)
    opt = info.value.optimizer
    assert opt.n_evals == 2 and np.array_equal(opt.ask(), calls[2])  # the NaN trial is still pending
    opt.tell(calls[2], synthetic(calls[2]))
    assert opt.n_evals == 3

    def broken(theta):
        raise OSError("robot offline")

    with pytest.raises(RolloutError, match="robot offline") as info:
        corl.optimize(broken, (LOW, HIGH), [1.0], budget=10)
    assert info.value.optimizer.n_evals == 0 and np.array_equal(info.value.optimizer.ask(), [1.0])


def test_for_box_settings_scale_with_the_box():
    box = Bounds([0.0, -5.0], [0.2, 5.0])
    s = OptimizerSettings.for_box(box)
    np.testing.assert_allclose(s.regression.lengthscale, [0.02, 1.0])
    np.testing.assert_allclose(s.classifier.lengthscale, [0.02, 1.0])
    assert s.distance_scale == (0.2, 10.0)
    opt = corl.make_optimizer("PIBU", box, [0.1, 0.0])
    assert opt.config.distance_scale == (0.2, 10.0) and opt.max_evals == 50


def test_the_registry_takes_a_new_method_by_name():
    @register_optimizer("PIBU-test-only")
    def build(bounds, start, *, budget, rng, settings):
        return PIBUOptimizer(bounds, settings.bo(), max_evals=budget, seed=rng, start=start)

    try:
        opt = corl.make_optimizer("PIBU-test-only", (LOW, HIGH), [0.5], budget=3)
        assert isinstance(opt, BlackBoxOptimizer) and np.array_equal(opt.ask(), [0.5])
    finally:
        corl.OPTIMIZERS.pop("PIBU-test-only")


def test_import_corl_stays_light():
    code = "import sys, corl; print(sorted(m for m in ('scipy', 'cma', 'corl.gp', 'corl.loop') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    assert callable(corl.optimize) and callable(corl.make_optimizer)


def test_the_readme_example_prints_what_the_readme_says(capsys):
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    section = readme.split("## The safe optimizer on its own", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    expected = code.strip().splitlines()[-1].lstrip("# ").split()
    exec(compile(code, "README.md", "exec"), {})
    printed = capsys.readouterr().out.replace("[", "").replace("]", "").split()
    theta, ret, reason, trials, failures = printed
    assert f"{float(theta):.4f}" == expected[0].strip("[]") and f"{float(ret):.5f}" == expected[1]
    assert [reason, trials, failures] == expected[2:]


# -- every setting and argument checked where it is given (corl.checks) --------------------------
BAD_SETTINGS = [("ucb_kappa", math.nan, "ucb_kappa must be a finite number"),
                ("ucb_kappa", math.inf, "ucb_kappa must be a finite number"),
                ("ucb_kappa", -1.0, "ucb_kappa must be in [0, inf)"),
                ("cma_sigma0", 0.0, "cma_sigma0 must be in (0, inf)"),
                ("cma_sigma0", math.nan, "cma_sigma0 must be a finite number"),
                ("failure_return", "x", "failure_return must be a number, got 'x'"),
                ("failure_return", -math.inf, "failure_return must be a finite number"),
                ("stop_distance", "0.1", "stop_distance must be a number, got '0.1'"),
                ("step_distance", math.inf, "step_distance must be a finite number"),
                ("distance_scale", (1.0, math.nan), "distance_scale[1] must be a finite number"),
                ("distance_scale", "ab", "distance_scale must be a positive number or a sequence"),
                ("confirm", 1.5, "confirm must be a whole number"),
                ("label_noise", 0.5, "label_noise (how often the success sensor errs) must be in [0, 0.5)"),
                ("sal", 3, "sal must be a corl.optimizers.sal.SALConfig or None, got int"),
                ("regression", "fitted", "regression must be a corl.settings.RegressionConfig, got str"),
                ("ucb_kapa", 1.0, "has no setting 'ucb_kapa'")]


@pytest.mark.parametrize("field, value, words", BAD_SETTINGS, ids=[f"{f}={v!r}" for f, v, _ in BAD_SETTINGS])
def test_optimizer_settings_refuse_a_bad_value_in_one_line(field, value, words):
    with pytest.raises(InputError) as info:
        OptimizerSettings(**{field: value})
    assert "\n" not in str(info.value) and words in str(info.value)


@pytest.mark.parametrize("field", ["failure_return", "ucb_kappa", "cma_sigma0", "confirm", "label_noise"])
@pytest.mark.parametrize("value", [math.nan, math.inf, -1.0, 0.0, 0.3, 0.5, 2.5, "1", True, None])
def test_a_setting_gets_the_same_answer_from_method_and_optimizer_settings(field, value):
    from corl.settings import MethodSettings

    answers = []
    for owner in (MethodSettings, OptimizerSettings):
        try:
            owner(**{field: value})
            answers.append("accepted")
        except InputError as exc:
            answers.append(str(exc).replace(owner.__name__, "Settings"))
    if not (field == "failure_return" and value is None):  # None: the optimizers' units-free failure score
        assert answers[0] == answers[1]


def test_a_built_in_optimizer_is_replaced_only_when_asked():
    builder = corl.OPTIMIZERS["CORL"]
    with pytest.raises(InputError, match="'CORL' is one of corl's own optimizers; .* replace=True"):
        register_optimizer("CORL")
    assert corl.OPTIMIZERS["CORL"] is builder
    try:
        mine = register_optimizer("CORL", replace=True)(lambda *a, **k: builder(*a, **k))
        assert corl.OPTIMIZERS["CORL"] is mine
    finally:
        corl.OPTIMIZERS["CORL"] = builder
    with pytest.raises(InputError, match="builder of optimizer 'PIBU-test-only' must be a function"):
        register_optimizer("PIBU-test-only")(3)
    assert "PIBU-test-only" not in corl.OPTIMIZERS


def test_optimize_refuses_f_and_callback_that_are_no_functions_before_any_trial():
    calls = []

    def f(theta):
        calls.append(theta)
        return synthetic(theta)

    with pytest.raises(InputError, match="callback must be a function .* got int 3"):
        corl.optimize(f, (LOW, HIGH), [0.0], callback=3)
    with pytest.raises(InputError, match="f must be a function"):
        corl.optimize(3, (LOW, HIGH), [0.0])
    assert calls == []


def test_an_optimizer_told_without_an_outcome_says_what_to_give():
    opt = corl.make_optimizer("SAL", (LOW, HIGH), [0.0])
    for args in ((None,), (Outcome(True, 1.0),)):
        with pytest.raises(InputError, match=r"takes the point and its outcome, tell\(x, outcome\)"):
            opt.tell(*args)
    with pytest.raises(InputError, match="x must be 1 numbers .* got NoneType None"):
        opt.tell(None, Outcome(True, 1.0))  # not 'NaN' values
    assert opt.n_evals == 0


def test_settings_for_another_box_are_refused_when_the_optimizer_is_made():
    three = OptimizerSettings.for_box(Bounds([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]))
    for name in ("PIBU", "SAL", "CMA"):
        with pytest.raises(InputError, match="lengthscale has 3 values but theta has 2 dimensions"):
            corl.make_optimizer(name, ([0.0, 0.0], [1.0, 1.0]), [0.5, 0.5], settings=three)
    fitted = OptimizerSettings.for_box(Bounds([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]), fitted=True)
    with pytest.raises(InputError, match="distance_scale has 3 values but the box has 2 dimensions"):
        corl.make_optimizer("CORL", ([0.0, 0.0], [1.0, 1.0]), [0.5, 0.5], settings=fitted)


def test_a_start_just_outside_the_box_says_by_how_much():
    with pytest.raises(InputError, match=r"\(coordinate 0, 1.000000001, is 1e-09 above 1.0\)"):
        corl.make_optimizer("CORL", ([0.0, 0.0], [1.0, 1.0]), [1.0 + 1e-9, 0.5])

