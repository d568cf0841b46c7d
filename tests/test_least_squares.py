"""fricli.least_squares: the bounded Levenberg-Marquardt solver behind identify."""

import numpy as np
import pytest
from scipy.optimize import least_squares as scipy_least_squares

from fricli import least_squares

UNBOUNDED = (-np.inf, np.inf)


def rosenbrock(x):
    return np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]])


def test_rosenbrock_from_the_classic_start():
    res = least_squares.solve(rosenbrock, np.array([-1.2, 1.0]), UNBOUNDED)
    assert res.status > 0
    np.testing.assert_allclose(res.x, [1.0, 1.0], atol=1e-6)
    assert res.cost < 1e-12


def decay_problem(seed):
    """y = a exp(-t/tau) + c with noise; parameters of very different scales (tau ~ 1e-3 s)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 0.01, 400)
    a, tau, c = rng.uniform(1e3, 5e3), rng.uniform(5e-4, 3e-3), rng.uniform(-2, 2)
    y = a * np.exp(-t / tau) + c + rng.normal(0, 5.0, len(t))
    return lambda x: x[0] * np.exp(-t / x[1]) + x[2] - y


@pytest.mark.parametrize("seed", range(5))
def test_reaches_scipys_minimum_on_badly_scaled_problems(seed):
    fun = decay_problem(seed)
    x0 = np.array([1e3, 1e-3, 0.0])
    bounds = (np.array([0.0, 1e-5, -np.inf]), np.array([np.inf, 1.0, np.inf]))
    ours = least_squares.solve(fun, x0, bounds)
    ref = scipy_least_squares(fun, x0, bounds=bounds, method="trf", x_scale="jac")
    assert ours.status > 0
    assert ours.cost <= ref.cost * (1 + 1e-9)
    np.testing.assert_allclose(ours.x, ref.x, rtol=1e-5)


def test_a_bound_that_binds_holds_and_is_where_scipy_stops():
    fun = decay_problem(0)
    x0 = np.array([1e3, 1e-3, 4.0])
    bounds = (np.array([0.0, 1e-5, 3.0]), np.array([np.inf, 1.0, np.inf]))   # c is below 2 in truth
    ours = least_squares.solve(fun, x0, bounds)
    ref = scipy_least_squares(fun, x0, bounds=bounds, method="trf", x_scale="jac")
    assert ours.x[2] == 3.0
    assert ours.cost <= ref.cost * (1 + 1e-9)
    np.testing.assert_allclose(ours.x, ref.x, rtol=1e-5)


def test_stopped_by_max_nfev_reports_it_and_keeps_the_best_point():
    x0 = np.array([-1.2, 1.0])
    res = least_squares.solve(rosenbrock, x0, UNBOUNDED, max_nfev=8)
    assert res.status == 0
    assert res.nfev == 8
    assert res.cost < 0.5 * np.sum(rosenbrock(x0) ** 2)
    assert res.cost == pytest.approx(0.5 * np.sum(rosenbrock(res.x) ** 2))


def test_a_start_point_outside_the_box_is_moved_into_it():
    res = least_squares.solve(lambda x: x - 2.0, np.array([10.0]), (np.array([-1.0]), np.array([1.0])))
    assert res.x[0] == 1.0
    assert res.status > 0


def test_non_finite_residuals_at_the_start_are_an_error():
    with pytest.raises(ValueError, match="not finite"):
        least_squares.solve(lambda x: np.array([np.nan, x[0]]), np.array([1.0]), UNBOUNDED)


def test_non_finite_trial_points_are_refused_not_taken():
    # log(x) is nan for x < 0: steps that cross zero must be refused and the fit still converge
    y = np.log(np.array([0.5, 0.6, 0.7]))
    with np.errstate(invalid="ignore"):
        res = least_squares.solve(lambda x: np.log(x[0] * np.array([5.0, 6.0, 7.0])) - y, np.array([3.0]),
                                  UNBOUNDED)
    assert res.status > 0
    np.testing.assert_allclose(res.x, [0.1], rtol=1e-6)
