"""DMP: reproduction of a demonstration, goal changes, the 96-D parameter view, zero forcing, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from corl.errors import InputError
from corl.policies import DMP, DMPConfig, basis_functions, forcing_features

T = 2.0
Q = 8


def demonstration(seed: int = 0, n: int = 401):
    """A smooth 8-D demonstration from rest to rest: minimum jerk plus a sine bump per dimension."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, T, n)
    s = t / T
    amp = rng.uniform(0.2, 1.5, Q)
    freq = rng.uniform(0.5, 1.5, Q)
    min_jerk = 10 * s**3 - 15 * s**4 + 6 * s**5
    bump = np.sin(np.pi * s)[:, None] ** 2 * np.sin(2 * np.pi * freq * s[:, None])
    Y = rng.uniform(-1.0, 1.0, Q) + amp * min_jerk[:, None] + 0.3 * amp * bump
    return t, Y


@pytest.fixture(scope="module")
def fitted():
    t, Y = demonstration()
    return t, Y, DMP.fit(t, Y, n_basis=11)


def test_fit_reproduces_demonstration_starts_at_y0_and_converges(fitted):
    t, Y, dmp = fitted
    times, Yr, dYr, _ = dmp.rollout(dt=0.005)
    assert times.shape == t.shape and Yr.shape == Y.shape
    span = Y.max(axis=0) - Y.min(axis=0)
    assert np.max(np.abs(Yr - Y) / span) < 0.02  # 11 bases: about 1 % of each dimension's range
    np.testing.assert_array_equal(Yr[0], Y[0])
    np.testing.assert_array_equal(dYr[0], np.zeros(Q))
    _, Y_long, dY_long, _ = dmp.rollout(dt=0.01, duration=3 * T)
    np.testing.assert_allclose(Y_long[-1], Y[-1], atol=1e-4)
    assert np.max(np.abs(dY_long[-1])) < 1e-3


def test_more_basis_functions_fit_better(fitted):
    t, Y, dmp11 = fitted
    dmp25 = DMP.fit(t, Y, n_basis=25)
    err = [np.max(np.abs(d.rollout(0.005)[1] - Y)) for d in (dmp11, dmp25)]
    assert err[1] < 0.3 * err[0]


def test_rollout_velocities_and_accelerations_match_positions(fitted):
    _, _, dmp = fitted
    dt = 0.002
    _, Y, dY, ddY = dmp.rollout(dt)
    np.testing.assert_allclose(np.gradient(Y, dt, axis=0)[1:-1], dY[1:-1], atol=1e-3 * np.abs(dY).max())
    np.testing.assert_allclose(np.gradient(dY, dt, axis=0)[1:-1], ddY[1:-1], atol=1e-2 * np.abs(ddY).max())


def test_rollout_is_insensitive_to_dt(fitted):
    _, _, dmp = fitted
    _, Y_fine, _, _ = dmp.rollout(0.001)
    _, Y_coarse, _, _ = dmp.rollout(0.05)
    np.testing.assert_allclose(Y_coarse, Y_fine[::50], atol=1e-5)  # RK4 sub-steps


def test_changing_goal_moves_end_point_and_keeps_shape(fitted):
    _, _, dmp = fitted
    delta = np.linspace(-0.5, 0.5, Q)
    moved = dmp.with_goal(dmp.goal + delta)
    _, Y_old, _, _ = dmp.rollout(0.01, duration=3 * T)
    _, Y_new, _, _ = moved.rollout(0.01, duration=3 * T)
    np.testing.assert_allclose(Y_new[-1], dmp.goal + delta, atol=1e-4)
    # Hoffmann form is linear in g: the change is delta times the zero-forcing 0 -> 1 profile s(t).
    _, s, _, _ = DMP.point_to_point(np.zeros(Q), np.ones(Q), dmp.tau, dmp.n_basis).rollout(0.01, 3 * T)
    np.testing.assert_allclose(Y_new - Y_old, s * delta, atol=1e-9)
    # so the shape stays: the motions never differ by more than the goal shift
    assert np.all(np.abs(Y_new - Y_old) <= np.abs(delta) + 1e-9)


def test_params_length_layout_and_round_trip(fitted):
    _, _, dmp = fitted
    p = dmp.params
    assert p.shape == (96,) == (dmp.n_params,)
    np.testing.assert_array_equal(p.reshape(Q, 12)[:, 11], dmp.goal)
    np.testing.assert_array_equal(p.reshape(Q, 12)[:, :11], dmp.weights)
    again = dmp.with_params(p)
    for a, b in zip(dmp.rollout(0.01), again.rollout(0.01)):
        np.testing.assert_array_equal(a, b)
    times, Y = dmp.reference(p, 0.01)
    np.testing.assert_array_equal(Y, dmp.rollout(0.01)[1])
    np.testing.assert_array_equal(dmp.param_scale, again.param_scale)


def test_param_scale_equalises_the_effect_of_weights_and_goal(fitted):
    _, Y, dmp = fitted
    scale = dmp.param_scale
    assert scale.shape == (96,) and np.all(scale > 0)
    span = Y.max(axis=0) - Y.min(axis=0)
    np.testing.assert_allclose(scale.reshape(Q, 12)[:, 11], span)
    # A one-scale change of any weight moves the motion by a similar amount (within a factor 10).
    _, base = dmp.reference(dmp.params, 0.01)
    effects = []
    for i in range(12):
        p = dmp.params.copy()
        p[i] += 0.1 * scale[i]  # dimension 0
        _, Y_i = dmp.reference(p, 0.01, duration=1.5 * T)
        effects.append(np.max(np.abs(Y_i[: len(base), 0] - base[:, 0])) / span[0])
    assert max(effects) < 10 * min(effects)
    assert 0.005 < min(effects) and max(effects) < 0.2


def test_zero_forcing_is_monotone_and_converges_to_goal():
    y0 = np.array([0.0, 1.0, -2.0, 0.3])
    g = np.array([1.0, -1.0, -2.0, 0.8])
    config = DMPConfig(alpha_z=25.0, beta_z=25.0 / 4.0)
    dmp = DMP.point_to_point(y0, g, tau=1.0, n_basis=11, config=config)
    _, Y, dY, ddY = dmp.rollout(0.001, duration=3.0)
    np.testing.assert_allclose(Y[-1], g, atol=1e-4)
    direction = np.sign(g - y0)
    assert np.all(np.diff(Y, axis=0) * direction >= -1e-12)  # monotone, no overshoot
    assert np.all((g - Y) * direction >= -1e-12)
    np.testing.assert_array_equal(Y[:, 2], -2.0)  # g == y0 stays put
    assert np.max(np.abs(ddY[0])) < 1e-9  # Hoffmann form: no acceleration jump at t = 0


def test_underdamped_gains_overshoot():
    """The monotonicity above is a property of critical damping, not of the test."""
    underdamped = DMPConfig(alpha_z=25.0, beta_z=25.0, alpha_x=50.0)  # fast phase: nearly a step to g
    critical = DMPConfig(alpha_z=25.0, beta_z=25.0 / 4.0, alpha_x=50.0)
    _, Y_crit, _, _ = DMP.point_to_point([0.0], [1.0], tau=1.0, config=critical).rollout(0.001, duration=3.0)
    assert Y_crit.max() <= 1.0
    dmp = DMP.point_to_point([0.0], [1.0], tau=1.0, config=underdamped)
    _, Y, _, _ = dmp.rollout(0.001, duration=3.0)
    assert Y.max() > 1.01


def test_shape_survives_equal_start_and_goal():
    """A gripper that closes and reopens (g == y0) keeps its shape, unlike f (g - y0) scaling."""
    t = np.linspace(0.0, 1.0, 201)
    Y = (0.08 - 0.06 * np.sin(np.pi * t) ** 2)[:, None]
    dmp = DMP.fit(t, Y, n_basis=11)
    _, Yr, _, _ = dmp.rollout(0.005)
    assert np.max(np.abs(Yr - Y)) < 0.02 * 0.06
    assert dmp.param_scale[-1] == pytest.approx(0.06)


def test_temporal_scaling_slows_the_motion(fitted):
    _, _, dmp = fitted
    _, Y1, _, _ = dmp.rollout(0.01)
    _, Y2, _, _ = dmp.rollout(0.01, tau=2 * dmp.tau)
    np.testing.assert_allclose(Y2[::2], Y1, atol=1e-6)


def test_start_override_moves_the_start(fitted):
    _, _, dmp = fitted
    new_start = dmp.start + 0.2
    _, Y, _, _ = dmp.rollout(0.01, duration=3 * T, start=new_start)
    np.testing.assert_array_equal(Y[0], new_start)
    np.testing.assert_allclose(Y[-1], dmp.goal, atol=1e-4)


def test_basis_centers_even_in_time_and_features_normalised():
    c, h = basis_functions(11, math.log(100.0))
    np.testing.assert_allclose(-np.log(c) / math.log(100.0), np.linspace(0, 1, 11))
    mid = 0.5 * (c[3] + c[4])
    assert math.exp(-h[3] * (mid - c[3]) ** 2) == pytest.approx(0.5)
    x = np.geomspace(1e-6, 1.0, 50)
    Phi = forcing_features(x, c, h)
    np.testing.assert_allclose(Phi.sum(axis=1), x)  # normalised basis times x


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda t, Y: (t, np.where(np.arange(Y.size).reshape(Y.shape) == 7, np.nan, Y)), "NaN"),
        (lambda t, Y: (t[:-1], Y), "shape"),
        (lambda t, Y: (t, Y[None]), "shape"),
        (lambda t, Y: (t[::-1], Y), "increasing"),
    ],
)
def test_bad_demonstration_raises(mutate, match):
    t, Y = demonstration(n=50)
    with pytest.raises(InputError, match=match):
        DMP.fit(*mutate(t, Y))


@pytest.mark.parametrize("n_basis", [1, 0, 2.5, True])
def test_bad_n_basis_raises(n_basis):
    t, Y = demonstration(n=50)
    with pytest.raises(InputError, match="n_basis"):
        DMP.fit(t, Y, n_basis=n_basis)


def test_bad_params_and_config_raise(fitted):
    _, _, dmp = fitted
    with pytest.raises(InputError, match=r"\(96,\)"):
        dmp.with_params(np.zeros(95))
    with pytest.raises(InputError, match="NaN"):
        dmp.with_params(np.full(96, np.nan))
    with pytest.raises(InputError, match="dt"):
        dmp.rollout(0.0)
    with pytest.raises(InputError, match="beta_z"):
        DMPConfig(beta_z=-1.0)
    with pytest.raises(InputError, match="overlap"):
        DMPConfig(overlap=1.0)
    with pytest.raises(InputError, match="goal"):
        DMP(np.zeros((2, 5)), np.zeros(3), np.zeros(2), 1.0)
