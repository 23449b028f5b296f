"""Levenberg–Marquardt on the exact Jacobian: the scene's free parameters and a scale fitted to data.

The model of the data is s · y(θ): y the exact model of the scene with the
free parameters θ (keys of docs/design.md section 9,
:mod:`analytic.operator.parameters`) and s a free overall scale (data /
model; fixed at 1 when asked). The fit minimises

    χ²(θ, s) = Σ_n ((d_n - s y_n(θ)) / σ_n)²

over the bins with a standard error σ_n > 0, by Levenberg–Marquardt with
Marquardt's scaling: each iteration solves the damped normal equations of
the whitened Jacobian A = [s ∂y/∂θ, y] / σ (:func:`analytic.jacobian`) with
unit-norm columns, in the span of its singular vectors whose singular
value is above :data:`DEGENERATE_RATIO` times the largest. The directions
below it (two keys that move y identically, a key that moves no light in
the window) are *not determined by the data*: they are reported as
directions, and the keys they involve get no value (:class:`Degenerate`).
The covariance of the determined parameters is (AᵀA)⁺ at the solution,
in the parameters' units; with σ the data's own errors it is not rescaled
by χ²/dof (the verdict of section 6 judges whether the errors are right).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from analytic.errors import SceneError

__all__ = ["FitProblem", "FitOutcome", "Degenerate", "levenberg_marquardt", "DEGENERATE_RATIO", "MAX_ITERATIONS",
           "STEP_TOLERANCE", "STALL_TOLERANCE", "SCALE"]

#: A whitened, column-normalised singular value below this share of the largest is a direction the data do
#: not fix: the columns are parallel to within this angle (radians), so a combination along it would carry a
#: standard error over 1/DEGENERATE_RATIO times those of its keys alone. The Jacobian's own error (the
#: scene's tolerance per entry, 1e-6 by default) stays far below it.
DEGENERATE_RATIO = 1e-4

#: Most iterations (each one model; a Jacobian where the last one no longer predicts the fall of χ²).
MAX_ITERATIONS = 60

#: Converged when Gauss-Newton's next step is shorter than this many standard errors (its length measured by
#: the fit's covariance), so that χ² would fall by less than its square.
STEP_TOLERANCE = 1e-3

#: Most steps taken with the Jacobian of an earlier point before it is computed again.
STALE_STEPS = 4

#: Where no step lowers χ² any more (the model's error at its tolerance is what remains), converged when
#: Gauss-Newton's step is shorter than this many standard errors: a bias the verdict could never see.
STALL_TOLERANCE = 0.05

#: The name of the overall scale among the fitted parameters.
SCALE = "scale"


@dataclass(frozen=True)
class Degenerate:
    """A direction of (θ, s) the data do not fix.

    Attributes
    ----------
    direction : dict
        ``{name: component}``, a unit vector in the parameters' units
        (components below 1e-6 left out); ``"scale"`` names the scale.
    """

    direction: dict

    @property
    def names(self) -> list[str]:
        return list(self.direction)

    def text(self) -> str:
        """``0.707 source.intensity - 0.707 scale``: the direction, for reports."""
        terms = [f"{'-' if value < 0 else '+'} {abs(value):.3g} {name}" for name, value in self.direction.items()]
        return " ".join(terms).lstrip("+ ")


@dataclass
class FitProblem:
    """What is fitted: a model of named parameters, the data and their standard errors.

    Attributes
    ----------
    names : list of str
        The free parameters (keys), in order.
    start : numpy.ndarray
        Their starting values, in their units.
    model : callable
        ``theta -> (K, N)`` y(θ); raises SceneError for values the scene refuses.
    jacobian : callable
        ``theta -> (K, N, P)`` ∂y/∂θ at θ.
    data, stderr : numpy.ndarray
        ``(K, N)`` the data and their standard errors (units of y); bins
        with σ = 0 are not fitted.
    free_scale : bool
        Fit the overall scale s (else s = 1).
    """

    names: list
    start: np.ndarray
    model: object
    jacobian: object
    data: np.ndarray
    stderr: np.ndarray
    free_scale: bool = True
    reweight: object = None
    start_scale: float | None = None


#: Most rounds of reweighting (Poisson data: σ² from the fitted mean, until the fit stops moving).
MAX_REWEIGHTS = 8


@dataclass(frozen=True)
class FitOutcome:
    """The fit's result.

    Attributes
    ----------
    values : dict
        ``{name: value}`` of every parameter and of ``"scale"`` (the model's
        values there: for an undetermined key, one point of the degenerate set).
    stderr : dict
        ``{name: standard error}``; None for a name a degenerate direction involves.
    covariance : numpy.ndarray
        ``(Q, Q)`` covariance of :attr:`determined` (in that order).
    determined : list of str
        The names with a value the data fix.
    degenerate : list of Degenerate
    chi2 : float
        χ² at the solution over :attr:`bins` bins.
    bins : int
        Bins fitted (σ > 0).
    start_chi2 : float
        χ² at the start (the scale fitted there when it is free).
    converged : bool
        Steps below :data:`STEP_TOLERANCE` standard errors within :data:`MAX_ITERATIONS`.
    iterations : int
    model, start_model : numpy.ndarray
        ``(K, N)`` s y(θ) at the solution and at the start.
    """

    values: dict
    stderr: dict
    covariance: np.ndarray
    determined: list
    degenerate: list
    chi2: float
    bins: int
    start_chi2: float
    converged: bool
    iterations: int
    model: np.ndarray
    start_model: np.ndarray

    @property
    def chi2_dof(self) -> float:
        """χ² / (bins - determined parameters); inf when none are left."""
        dof = self.bins - len(self.determined)
        return float(self.chi2 / dof) if dof > 0 else float("inf")


def _best_scale(data, y, weights) -> float:
    """The scale s minimising Σ w (d - s y)² (1 when y carries no light)."""
    norm = float(np.sum(weights * y * y))
    return float(np.sum(weights * y * data) / norm) if norm > 0 else 1.0


class _Whitened:
    """The whitened system at one point: residual r and Jacobian A with unit-norm columns (norms ``norms``)."""

    def __init__(self, problem: FitProblem, mask, theta, scale, y, jacobian):
        sigma = problem.stderr[mask]
        self.residual = (problem.data[mask] - scale * y[mask]) / sigma
        columns = [scale * jacobian[..., p][mask] / sigma for p in range(len(theta))]
        if problem.free_scale:
            columns.append(y[mask] / sigma)
        matrix = np.stack(columns, axis=-1)
        self.norms = np.linalg.norm(matrix, axis=0)
        lit = self.norms > 0
        normalised = np.zeros_like(matrix)
        normalised[:, lit] = matrix[:, lit] / self.norms[lit]
        u, singular, vt = np.linalg.svd(normalised, full_matrices=False)
        if vt.shape[0] < matrix.shape[1]:    # fewer bins than parameters: the rest of the space is undetermined
            from scipy.linalg import null_space

            vt = np.vstack([vt, null_space(vt).T])
            singular = np.concatenate([singular, np.zeros(vt.shape[0] - singular.size)])
        kept = singular > DEGENERATE_RATIO * max(float(singular[0]), np.finfo(float).tiny)
        self.u, self.singular, self.v = u[:, kept[:u.shape[1]]], singular[kept], vt[kept].T
        self.null = vt[~kept].T          # (Q, d) normalised directions the data do not fix

    def step(self, damping: float) -> np.ndarray:
        """The damped Gauss–Newton step in the parameters' units (min-norm in the normalised ones)."""
        s = self.singular
        normalised = self.v @ ((s / (s * s + damping)) * (self.u.T @ self.residual))
        return self._units(normalised)

    def predicted(self, damping: float) -> float:
        """χ² the linear model predicts after :meth:`step` (``damping``)."""
        s = self.singular
        projected = self.u.T @ self.residual
        shrink = damping / (s * s + damping)
        return float(np.sum(self.residual**2) - np.sum(projected**2) + np.sum((shrink * projected) ** 2))

    def _units(self, normalised):
        scale = np.where(self.norms > 0, self.norms, 1.0)
        return normalised / scale

    def covariance(self) -> np.ndarray:
        """(AᵀA)⁺ in the parameters' units, over the determined span."""
        inner = (self.v / self.singular**2) @ self.v.T
        scale = np.where(self.norms > 0, self.norms, 1.0)
        return inner / np.outer(scale, scale)

    def degenerate(self, names) -> list:
        """Each undetermined direction in the parameters' units, as a :class:`Degenerate`."""
        found = []
        for column in self.null.T:
            vector = self._units(column)
            vector /= np.linalg.norm(vector)
            sign = 1.0 if vector[np.argmax(np.abs(vector))] > 0 else -1.0
            # a key is involved by its share of the normalised direction (its units could hide it: an
            # intensity of 1e8 W/sr beside a scale of 1)
            found.append(Degenerate({name: float(sign * value) for name, value, share in zip(names, vector, column)
                                     if abs(share) > 1e-6}))
        return found


def _damped_step(problem, system, theta, scale, chi2, damping, chi2_of):
    """Marquardt's search along the damped steps: (the point accepted, or {}; its predicted and actual fall of
    χ²), with the damping to use next under ``"damping"``."""
    while damping < 1e12:
        step = system.step(damping)
        trial_theta = theta + step[:len(theta)]
        trial_scale = scale + step[len(theta)] if problem.free_scale else 1.0
        try:
            trial_y = problem.model(trial_theta)
        except SceneError:               # a step the scene refuses (a sensor through the plane): shorter
            damping *= 10.0
            continue
        trial_chi2 = chi2_of(trial_scale * trial_y)
        if trial_chi2 < chi2:
            predicted = chi2 - system.predicted(damping)
            return ({"theta": trial_theta, "scale": trial_scale, "y": trial_y, "chi2": trial_chi2,
                     "damping": max(damping / 10.0, 1e-9)}, predicted, chi2 - trial_chi2)
        damping *= 10.0
    return {"damping": 1e-3}, 0.0, 0.0


def levenberg_marquardt(problem: FitProblem) -> FitOutcome:
    """Fit ``problem`` (see the module's docstring); a :class:`FitOutcome`.

    With ``problem.reweight`` (model -> σ, Poisson data: σ² is the mean), the fit is repeated with σ from
    the fitted model until a round starts at its minimum (iteratively reweighted least squares: its fixed
    point solves the Poisson likelihood's score equations, Σ (c - μ) ∂μ/∂θ / μ = 0, and (AᵀA)⁻¹ is then
    the inverse Fisher information), at most :data:`MAX_REWEIGHTS` rounds.

    Raises
    ------
    SceneError
        The starting values themselves are refused by the scene.
    """
    outcome = _fit_once(problem)
    first, rounds, total = outcome, 1, outcome.iterations
    while problem.reweight is not None and outcome.converged and rounds < MAX_REWEIGHTS:
        problem = replace(problem, stderr=problem.reweight(outcome.model),
                          start=np.array([outcome.values[name] for name in problem.names]),
                          start_scale=outcome.values[SCALE])
        outcome = _fit_once(problem)
        rounds, total = rounds + 1, total + outcome.iterations
        if outcome.iterations == 1:        # the new weights moved the minimum by under STEP_TOLERANCE errors
            break
    else:
        if problem.reweight is not None and outcome.converged:
            outcome = replace(outcome, converged=False)      # the weights never settled
    return replace(outcome, start_chi2=first.start_chi2, start_model=first.start_model, iterations=total)


def _fit_once(problem: FitProblem) -> FitOutcome:
    """One Levenberg-Marquardt fit with ``problem.stderr`` held."""
    mask = problem.stderr > 0
    weights = np.where(mask, 1.0 / np.where(mask, problem.stderr, 1.0) ** 2, 0.0)
    names = list(problem.names) + ([SCALE] if problem.free_scale else [])
    theta = np.array(problem.start, dtype=np.float64)
    y = problem.model(theta)
    scale = (1.0 if not problem.free_scale else problem.start_scale if problem.start_scale is not None
             else _best_scale(problem.data, y, weights))
    start_model = scale * y

    def chi2_of(model):
        return float(np.sum(weights * (problem.data - model) ** 2))

    chi2 = start_chi2 = chi2_of(start_model)
    damping, converged, iterations = 1e-3, False, 0
    derivative = problem.jacobian(theta)
    fresh = True                         # ``derivative`` is the Jacobian at ``theta`` (not an earlier point's)
    stale = 0                            # steps taken since it was
    system = _Whitened(problem, mask, theta, scale, y, derivative)
    while iterations < MAX_ITERATIONS:
        iterations += 1
        # Gauss-Newton's own step, measured by its covariance (its Mahalanobis length is |Uᵀ r|), under
        # STEP_TOLERANCE: the minimum, to that share of a standard error, once judged with the Jacobian there
        if float(np.linalg.norm(system.u.T @ system.residual)) <= STEP_TOLERANCE:
            if fresh:
                converged = True
                break
        else:
            accepted, predicted, gained = _damped_step(problem, system, theta, scale, chi2, damping, chi2_of)
            damping = accepted.pop("damping")
            if accepted:
                theta, scale, y, chi2 = accepted["theta"], accepted["scale"], accepted["y"], accepted["chi2"]
                # the Jacobian of an earlier point serves while the model stays as linear as it predicts (the
                # fall of χ² within a factor 2 of the predicted one: a larger fall too says the model has
                # curved away from it) and the steps still gain (under STEP_TOLERANCE² is what convergence
                # leaves), for at most STALE_STEPS steps
                stale += 1
                if (0.5 * predicted <= gained <= 2.0 * predicted and predicted > STEP_TOLERANCE**2
                        and stale <= STALE_STEPS):
                    system = _Whitened(problem, mask, theta, scale, y, derivative)
                    fresh = False
                    continue
            elif fresh:
                # no damped step lowers χ² (the model's own error, its tolerance, is what is left): the minimum
                # when Gauss-Newton's step is within STALL_TOLERANCE of a standard error, else a stall
                converged = float(np.linalg.norm(system.u.T @ system.residual)) <= STALL_TOLERANCE
                break
        derivative = problem.jacobian(theta)
        fresh, damping, stale = True, min(damping, 1e-3), 0     # a new Jacobian is trusted afresh
        system = _Whitened(problem, mask, theta, scale, y, derivative)
    degenerate = system.degenerate(names)
    involved = {name for direction in degenerate for name in direction.names}
    covariance = system.covariance()
    keep = [i for i, name in enumerate(names) if name not in involved]
    values = dict(zip(names, [*map(float, theta), *([scale] if problem.free_scale else [])]))
    stderr = {name: (float(np.sqrt(max(covariance[i, i], 0.0))) if name not in involved else None)
              for i, name in enumerate(names)}
    if not problem.free_scale:
        values[SCALE], stderr[SCALE] = 1.0, 0.0
    return FitOutcome(values=values, stderr=stderr, covariance=covariance[np.ix_(keep, keep)],
                      determined=[names[i] for i in keep], degenerate=degenerate, chi2=chi2_of(scale * y),
                      bins=int(mask.sum()), start_chi2=start_chi2, converged=converged, iterations=iterations,
                      model=scale * y, start_model=start_model)
