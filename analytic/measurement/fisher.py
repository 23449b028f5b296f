"""The Fisher information each sample of y carries, under the scene's noise or its photon-counting detector.

Every measurement model of this package makes the samples independent given
y (the detector's cycles are independent, and within a cycle a first-photon
detector is a sequence of Bernoulli trials, one per bin, each seen only while
no earlier bin fired), and each sample depends on its own y_n alone. The
Fisher information of the data about any parameters θ is then

    F = Jᵀ diag(w) J,   J = ∂y/∂θ  (rows (k, n)),

with one weight w_n per sample: the information about y_n itself. This
module gives w (docs/design.md sections 8 and 9):

- ``[noise] kind = "gaussian"``: w = 1 / σ² (σ = 0: every w infinite);
- ``[noise] kind = "poisson"``: the counts c = Poisson(p max(y, 0)) (p the
  photons per unit of y, the data c / p): w = p / y for y > 0;
- ``[detector] dead_time = "none"``: c = Poisson(C λ), λ = p max(y, 0) + b:
  w = C p² / λ;
- ``[detector] dead_time = "cycle"``: per cycle the first photon's bin is
  multinomial with p_n = e^{-Λ_n} (1 - e^{-λ_n}) (Coates). Bin n is a
  Bernoulli trial of success 1 - e^{-λ_n}, seen with probability e^{-Λ_n}
  (no photon before it), so over C cycles the information about λ is
  diagonal, C e^{-Λ_n} e^{-λ_n} / (1 - e^{-λ_n}) = C e^{-Λ_{n+1}} / (1 - e^{-λ_n}),
  and w = p² times that. At low flux it is the Poisson C p² / λ; once
  earlier bins fire in most cycles (pile-up) the late bins' information
  falls as e^{-Λ_{n+1}}.

A sample whose y is negative (a pulse's undershoot) emits no photons: the
clip max(y, 0) has slope 0 there, w = 0. A sample expecting no photons at
all (y = 0 and no background) has w = inf: any change of y that reaches it
would show as a photon where none can occur, so the data fix that change
exactly (the bound is the limit as the background goes to 0;
:mod:`analytic.inversion.bounds` treats such rows as constraints).
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from .detector import Detector, rates, sums_before

__all__ = ["sample_weights", "measurement_of", "MEASUREMENTS", "describe_measurement"]

#: What the data are: ``auto`` (the detector's counts when the scene has ``[detector]``, else ``[noise]``).
MEASUREMENTS = ("auto", "noise", "detector")


def measurement_of(scene, measurement: str = "auto"):
    """The scene's ``Noise`` or ``Detector`` that the data carry, as ``measurement`` asks.

    Raises
    ------
    SceneError
        The scene has no such table (``noise`` or ``detector`` named), or neither.
    """
    if measurement not in MEASUREMENTS:
        raise SceneError("measurement", f"must be one of {', '.join(map(repr, MEASUREMENTS))}, got {measurement!r}")
    noise, detector = getattr(scene, "noise", None), getattr(scene, "detector", None)
    if measurement == "detector" or (measurement == "auto" and detector is not None):
        if detector is None:
            raise SceneError("detector", "the scene has no [detector] table: give one (photons, background, "
                                         "cycles, dead_time) or bound the [noise]'s data instead")
        return detector
    if noise is None:
        raise SceneError("noise", "the scene states no noise, so its data are exact and no bound applies: "
                                  "add a [noise] table (sigma, or kind = \"poisson\" with photons) or a "
                                  "[detector]")
    return noise


def describe_measurement(model) -> str:
    """The measurement model in a few words (for reports and crb.json)."""
    if isinstance(model, Detector):
        return (f"photon counts, {model.photons:g} photons per unit of y, background {model.background:g} per "
                f"bin, {model.cycles:g} cycles, dead time {model.dead_time}")
    if model.kind == "gaussian":
        return f"Gaussian noise, sigma = {model.sigma:g}"
    return f"Poisson noise, {model.photons:g} photons per unit of y"


def sample_weights(y, model) -> np.ndarray:
    """w_n, the Fisher information of sample n about y_n, ``y.shape`` (per unit of y squared).

    Parameters
    ----------
    y : array_like
        ``(..., N)`` noiseless samples, units of y (bins along the last axis, in time order: the
        dead-time detector's arming depends on it).
    model : Noise or Detector
        The scene's ``[noise]`` or ``[detector]`` (:func:`measurement_of`).

    Returns
    -------
    numpy.ndarray
        float64, >= 0; inf where the sample fixes y_n exactly (σ = 0, or no photon expected).
    """
    y = np.asarray(y, dtype=np.float64)
    if not isinstance(model, Detector):
        if model.kind == "gaussian":
            with np.errstate(divide="ignore"):
                return np.full(y.shape, 1.0 / model.sigma**2 if model.sigma > 0 else np.inf)
        # counts c = Poisson(p y), data c / p: (∂ E c / ∂y)² / var c = p² / (p y) = p / y
        with np.errstate(divide="ignore"):
            return np.where(y > 0, model.photons / np.where(y > 0, y, 1.0), np.where(y == 0, np.inf, 0.0))
    lam = rates(y, model)
    slope = np.where(y >= 0, model.photons, 0.0)            # ∂λ/∂y through max(y, 0)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        if model.dead_time == "none":
            per_rate = model.cycles / lam
        else:
            # C e^{-Λ_{n+1}} / (1 - e^{-λ_n}); e^{-Λ} underflows to 0 where earlier bins always fire
            per_rate = model.cycles * np.exp(-(sums_before(lam) + lam)) / -np.expm1(-lam)
        # no photon expected: the sample fixes y exactly, if the detector is ever armed there
        armed = np.exp(-sums_before(lam)) > 0 if model.dead_time == "cycle" else True
        per_rate = np.where(lam > 0, per_rate, np.where(armed, np.inf, 0.0))
        weights = np.where(slope > 0, slope**2 * per_rate, 0.0)
    return np.where(np.isnan(weights), 0.0, weights)
