"""calibrate: a perturbed capture recovered within its stated errors, and directions the data cannot fix.

The data are the exact model of a perturbed scene plus Gaussian noise of known σ: the estimates are then
asymptotically normal about the truth with the covariance the fit states, so over independent seeds each
parameter's z = (fitted - true) / stated error lands in |z| < 1 at the normal law's rate (a binomial count)
and Σ z² follows χ² with one degree of freedom per seed.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from analytic.operator.parameters import with_values
from analytic.operator.matrix_free import forward
from analytic.scenes.scene_file import scene_from_dict
from validation.calibration import UNDETERMINED, calibrate

PERIOD = 0.05


def small_scene(illumination=None, sensors=((0.2, 0.7, 1.0), (0.8, 0.3, 0.9), (0.5, 0.2, 1.1)), count=24):
    """One pixel (the model's cheapest), three sensors at different heights, a pulse whose binned response is
    smooth in time zero (a square: an impulse's bins have kinks where an edge meets the first arrival)."""
    return scene_from_dict({
        "plane": {"size": 1.0, "pixels": 1, "reflectance": 0.5},
        "source": {"position": [0.5, 0.5, 1.0], "intensity": 1.0},
        "illumination": illumination or {"waveform": "square", "width": PERIOD},
        "sensors": {"positions": [list(p) for p in sensors]},
        "sampling": {"period": PERIOD, "start": 1.85, "count": count}})


#: The perturbation: sensor 0 raised by 2 mm, time zero early by 0.3 of a bin (what calibrate must find).
TRUTH = {"sensors.positions.0.z": 1.002, "sampling.start": 1.85 - 0.3 * PERIOD}


def noisy_capture(scene, truth, seed, share=0.01):
    """The model of ``scene`` moved to ``truth`` plus Gaussian noise of σ = share x its peak; (data, σ)."""
    y = forward(with_values(scene, truth))
    sigma = share * float(y.max())
    data = y + sigma * np.random.default_rng(seed).standard_normal(y.shape)
    return data, np.full(y.shape, sigma)


def z_scores(result, truth) -> dict:
    scores = {key: (result.parameters[key]["value"] - value) / result.parameters[key]["stderr"]
              for key, value in truth.items()}
    scores["scale"] = (result.scale["value"] - 1.0) / result.scale["stderr"]
    return scores


def test_a_perturbed_capture_is_recovered_within_its_errors():
    scene = small_scene()
    data, sigma = noisy_capture(scene, TRUTH, seed=1)
    result = calibrate(scene, data, list(TRUTH), stderr=sigma)
    assert result.converged and result.agrees and result.verdict
    # the start was 0.3 bin and 2 mm off, tens of errors: the fit moved there, not nowhere
    assert abs(TRUTH["sampling.start"] - 1.85) > 20 * result.parameters["sampling.start"]["stderr"]
    assert all(abs(z) < 4.5 for z in z_scores(result, TRUTH).values()), z_scores(result, TRUTH)
    assert result.parameters["sampling.start"]["start"] == 1.85
    assert result.scene.sampling.start_opl == result.parameters["sampling.start"]["value"]
    # the start did not fit (many standard errors), the fitted model does
    assert result.start_chi2_dof > 10 and result.chi2_dof < 2


def test_a_fixed_scale_is_held_and_stated():
    scene = small_scene()
    data, sigma = noisy_capture(scene, TRUTH, seed=2)
    result = calibrate(scene, data, list(TRUTH), stderr=sigma, fixed_scale=True)
    assert result.scale == {"value": 1.0, "stderr": 0.0}
    assert result.verdict
    assert "scale" not in result.covariance["names"] and len(result.covariance["matrix"]) == 2


def test_the_intensity_and_the_free_scale_are_one_direction_not_two_numbers():
    """y is proportional to the source's intensity I, so I and the scale s move it identically: along
    (dI, ds) ∝ (I, -s) (from d(s I) = 0) the data say nothing. Time zero stays determined."""
    scene = small_scene()
    data, sigma = noisy_capture(scene, {"sampling.start": TRUTH["sampling.start"]}, seed=3)
    result = calibrate(scene, data, ["source.intensity", "sampling.start"], stderr=sigma)
    entry = result.parameters["source.intensity"]
    assert entry["value"] is None and entry["stderr"] is None and entry["determined"] is False
    assert result.scale["value"] is None
    assert result.parameters["sampling.start"]["value"] is not None
    (direction,) = result.degenerate
    components = direction["direction"]
    assert set(components) == {"source.intensity", "scale"}
    # the fit's point of the set: I in the fitted scene, s = its model / that scene's y
    intensity, fitted_y = result.scene.intensity, forward(result.scene)
    scale = float(np.sum(result.model * fitted_y) / np.sum(fitted_y**2))
    assert components["scale"] / components["source.intensity"] == pytest.approx(-scale / intensity, rel=1e-6)
    assert UNDETERMINED in result.summary() and "source.intensity" in direction["text"]
    assert "source.intensity" not in result.covariance["names"]


def test_a_sensor_whose_light_misses_the_window_is_not_determined():
    """Sensor 1 is so far that its light arrives after the window: its row of y and of ∂y/∂θ are zero, so
    its height is reported as not determined (the direction is that key alone), the others are fitted."""
    scene = small_scene(sensors=((0.2, 0.7, 1.0), (0.5, 0.5, 9.0), (0.8, 0.3, 0.9)))
    data, sigma = noisy_capture(scene, {"sensors.positions.0.z": 1.002}, seed=4)
    assert not np.any(forward(scene)[1])
    result = calibrate(scene, data, ["sensors.positions.0.z", "sensors.positions.1.z"], stderr=sigma)
    assert result.parameters["sensors.positions.1.z"]["value"] is None
    assert [d["direction"] for d in result.degenerate] == [{"sensors.positions.1.z": 1.0}]
    assert abs(result.parameters["sensors.positions.0.z"]["value"] - 1.002) < \
        4.5 * result.parameters["sensors.positions.0.z"]["stderr"]


@pytest.mark.slow
# analytic.jacobian's Richardson differences (illumination.fwhm's column) assemble the model at 1e-10, which
# some pieces of a moved scene stop short of: its warning, not this test's subject
@pytest.mark.filterwarnings("ignore::analytic.operator.system.QuadratureWarning")
@pytest.mark.parametrize("illumination, truth, seeds", [
    (None, TRUTH, 40),
    ({"waveform": "gaussian", "fwhm": 0.06}, {**TRUTH, "illumination.fwhm": 0.066}, 24),
], ids=["square: sensor height and time zero", "gaussian: and a wider pulse"])
def test_stated_errors_cover_at_the_normal_rate(illumination, truth, seeds):
    scene = small_scene(illumination)
    scores = {key: [] for key in [*truth, "scale"]}
    for seed in range(seeds):
        data, sigma = noisy_capture(scene, truth, seed=100 + seed)
        result = calibrate(scene, data, list(truth), stderr=sigma)
        assert result.converged
        for key, z in z_scores(result, truth).items():
            scores[key].append(z)
    # Bonferroni over the parameters and the two statistics: a correct fit fails with probability ≤ 1e-3
    level = 1e-3 / (2 * len(scores))
    low, high = stats.binom.interval(1 - level, seeds, stats.norm.cdf(1) - stats.norm.cdf(-1))
    chi2_low, chi2_high = stats.chi2.ppf([level / 2, 1 - level / 2], seeds)
    for key, values in scores.items():
        values = np.array(values)
        inside = int(np.sum(np.abs(values) < 1))
        assert low <= inside <= high, (key, inside, (low, high), values)
        assert chi2_low <= float(np.sum(values**2)) <= chi2_high, (key, np.sum(values**2), values)


def test_photon_counts_are_fitted_by_their_poisson_likelihood():
    """Counts without dead time: c ~ Poisson(C (p y + b)). The fit recovers time zero and the sensor within the
    errors the Fisher information gives, and the deviance test accepts the fitted histogram."""
    from analytic.measurement.detector import Detector, expected_counts

    detector = Detector(photons=0.05, background=1e-4, cycles=2e5, dead_time="none", seed=0)
    scene = small_scene().replace(detector=detector)
    expected = expected_counts(forward(with_values(scene, TRUTH)), detector)
    histogram = np.random.default_rng(8).poisson(expected).astype(np.float64)
    result = calibrate(scene, histogram, list(TRUTH), counts=True)
    assert result.converged and result.agrees, result.summary()
    assert all(abs(z) < 4.5 for z in z_scores(result, TRUTH).values()), z_scores(result, TRUTH)
    # σ² of each bin is its fitted mean (in y's units: C (p y + b) / (C p)²), not the counts' own
    fitted = expected_counts(result.model, detector)
    assert np.allclose(result.stderr, np.sqrt(fitted) / (detector.cycles * detector.photons), rtol=1e-12)


@pytest.mark.slow
def test_a_render_of_the_perturbed_scene_is_recovered():
    """A Monte Carlo render (the project's renderer, 32 replicas) of the perturbed scene: its own errors
    (the replicas' spread, Student's t with 31 degrees of freedom) weight the fit, which finds the sensor and
    time zero to micrometres, within a few of the errors it states."""
    import transient

    scene = small_scene()
    render = transient.render(with_values(scene, TRUTH), spp=2**20, seed=3)
    result = calibrate(scene, render.replica_means, list(TRUTH))
    assert result.converged and result.agrees, result.summary()
    # |t| beyond 4.5 at 31 degrees of freedom: probability 1e-4 per parameter
    assert all(abs(z) < 4.5 for z in z_scores(result, TRUTH).values()), z_scores(result, TRUTH)
    assert result.parameters["sampling.start"]["stderr"] < 1e-4 * PERIOD


def test_replicas_too_noisy_to_weight_any_bin_are_refused():
    """Replicas whose spread is over 0.1 of every bin's value: check judges none of their bins, and the fit has
    none it could trust the error of."""
    from analytic.errors import DataError

    scene = small_scene()
    y = forward(scene)
    replicas = y + float(y.max()) * np.random.default_rng(9).standard_normal((8, *y.shape))
    with pytest.raises(DataError, match="none can weight the fit"):
        calibrate(scene, replicas, ["sampling.start"])
