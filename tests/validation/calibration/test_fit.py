"""Levenberg-Marquardt of calibrate on models whose answer is known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from validation.calibration.fit import FitProblem, levenberg_marquardt


def linear_problem(rng, *, free_scale=False):
    """y(θ) = B θ + c on (2, 12) bins with unequal σ: weighted least squares is the exact answer."""
    basis = rng.standard_normal((2, 12, 3))
    offset = 5.0 + rng.random((2, 12))
    sigma = 0.05 + 0.1 * rng.random((2, 12))
    truth = np.array([0.3, -1.2, 2.0])
    data = basis @ truth + offset + sigma * rng.standard_normal((2, 12))
    return FitProblem(names=["a", "b", "c"], start=np.zeros(3), model=lambda t: basis @ t + offset,
                      jacobian=lambda t: basis, data=data, stderr=sigma, free_scale=free_scale), basis, offset


def test_a_linear_model_gives_weighted_least_squares_and_its_covariance(rng):
    problem, basis, offset = linear_problem(rng)
    outcome = levenberg_marquardt(problem)
    whitened = (basis / problem.stderr[..., None]).reshape(-1, 3)
    target = ((problem.data - offset) / problem.stderr).ravel()
    solution = np.linalg.lstsq(whitened, target, rcond=None)[0]
    covariance = np.linalg.inv(whitened.T @ whitened)
    assert outcome.converged and outcome.degenerate == []
    # converged: within STEP_TOLERANCE (1e-3) of a standard error of the minimum
    errors = np.sqrt(np.diag(covariance))
    assert np.all(np.abs([outcome.values[k] for k in "abc"] - solution) < 1e-3 * errors)
    assert outcome.covariance == pytest.approx(covariance, rel=1e-9)
    assert outcome.chi2 == pytest.approx(float(np.sum((whitened @ solution - target) ** 2)), abs=1e-6)


def test_two_keys_that_move_the_model_alike_are_one_direction(rng):
    """y = (a + 2 b) g + 1: along (2, -1) nothing changes; c moves nothing at all."""
    g = 1.0 + rng.random((1, 8))
    jacobian = np.stack([g, 2 * g, np.zeros_like(g)], axis=-1)
    problem = FitProblem(names=["a", "b", "c"], start=np.zeros(3), model=lambda t: (t[0] + 2 * t[1]) * g + 1.0,
                         jacobian=lambda t: jacobian, data=3 * g + 1.0, stderr=np.full(g.shape, 0.1),
                         free_scale=False)
    outcome = levenberg_marquardt(problem)
    directions = sorted((d.direction for d in outcome.degenerate), key=len)
    assert directions[0] == {"c": 1.0}
    assert directions[1] == pytest.approx({"a": 2 / np.sqrt(5), "b": -1 / np.sqrt(5)})
    assert all(outcome.stderr[k] is None for k in "abc") and outcome.determined == []
    # the fit still fits the combination the data fix, to 1e-3 of its error σ / |g|
    assert abs(outcome.values["a"] + 2 * outcome.values["b"] - 3.0) < 1e-3 * 0.1 / np.linalg.norm(g)


def test_fewer_bins_than_parameters_leave_a_direction(rng):
    g = np.array([[1.0, 2.0]])
    problem = FitProblem(names=["a", "b", "c"], start=np.zeros(3),
                         model=lambda t: t[0] * g + t[1] * g**2 + t[2] + 1.0,
                         jacobian=lambda t: np.stack([g, g**2, np.ones_like(g)], -1), data=g + 1.0,
                         stderr=np.full(g.shape, 0.1), free_scale=False)
    outcome = levenberg_marquardt(problem)
    (direction,) = outcome.degenerate
    vector = np.array([direction.direction[k] for k in "abc"])
    assert np.abs(np.stack([g, g**2, np.ones_like(g)], -1)[0] @ vector).max() < 1e-12    # moves no bin
