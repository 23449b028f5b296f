"""Judging counts: the deviance test's false-alarm rate holds on simulated captures, wrong models fail,
and fits of scale, offset and pulse width diagnose a capture whose filter differs from its claim."""

from __future__ import annotations

import math

import numpy as np
import pytest

from analytic.measurement.detector import Detector, draw_counts, expected_counts
from analytic.errors import DataError
from analytic.scenes.common import Illumination, Sampling, Scene
from validation.check.counts import SceneModel, deviance, fit_counts, judge_counts

EXPECTED = np.array([[0.5, 3.0, 12.0, 40.0, 55.0, 30.0, 9.0, 2.0, 0.3, 0.0],
                     [0.0, 1.0, 5.0, 22.0, 60.0, 41.0, 15.0, 4.0, 1.0, 0.2]])


def _rejections(detector, expected, alpha, captures, draws, seed):
    rng = np.random.default_rng(seed)
    failed = 0
    for i in range(captures):
        if detector.dead_time == "none":
            counts = rng.poisson(expected)
        else:
            p = expected / detector.cycles
            counts = np.array([rng.multinomial(int(detector.cycles), np.append(row, 1 - row.sum()))[:-1] for row in p])
        failed += not judge_counts(counts, expected, detector, false_alarm=alpha, draws=draws, seed=1000 + i).agrees
    return failed


@pytest.mark.parametrize("dead_time", ["none", "cycle"])
def test_false_alarm_rate_holds_on_simulated_captures(dead_time):
    """300 captures drawn from the model: the share that fails is α within 3 binomial standard errors."""
    alpha, captures = 0.1, 300
    detector = Detector(photons=1.0, cycles=400, dead_time=dead_time)
    expected = EXPECTED if dead_time == "none" else expected_counts(EXPECTED / 400, detector)
    failed = _rejections(detector, expected, alpha, captures, draws=400, seed=5)
    spread = math.sqrt(captures * alpha * (1 - alpha))
    assert abs(failed - alpha * captures) <= 3 * spread, failed


@pytest.mark.parametrize("dead_time", ["none", "cycle"])
def test_a_wrong_model_fails(dead_time):
    detector = Detector(photons=1.0, cycles=4000, dead_time=dead_time, seed=2)
    truth = expected_counts(EXPECTED / 400, detector)
    counts = draw_counts(EXPECTED / 400, detector)
    assert judge_counts(counts, truth, detector, false_alarm=0.01).agrees
    late = np.roll(truth, 1, axis=1)            # one bin late
    assert not judge_counts(counts, late, detector, false_alarm=0.01).agrees
    dim = 0.85 * truth if dead_time == "none" else expected_counts(0.85 * EXPECTED / 400, detector)
    assert not judge_counts(counts, dim, detector, false_alarm=0.01).agrees


def test_impossible_counts_and_bad_inputs_are_named():
    detector = Detector(photons=1.0, cycles=10, dead_time="cycle")
    assert deviance(np.array([[1, 0]]), np.array([[0.0, 1.0]]), Detector(photons=1.0)) == math.inf
    for counts, message in ((np.array([[1.5, 0]]), "whole number"), (np.array([[-1, 0]]), "whole number"),
                            (np.array([[1, 0, 0]]), "shape"), (np.array([[11, 0]]), "more counts than")):
        with pytest.raises(DataError, match=message):
            judge_counts(counts, np.array([[1.0, 1.0]]), detector)
    with pytest.raises(DataError, match="draws"):
        judge_counts(np.array([[1, 0]]), np.array([[1.0, 1.0]]), detector, false_alarm=0.001, draws=100)


class PathsModel:
    """A cheap exact model for the fit's logic: a few path lengths through the scene's pulse, binned exactly.

    y_n(δ, fwhm) = Σ_j w_j κ_n(τ_j) with the bin edges moved by δ: what :class:`SceneModel` gives for a
    scene whose light leaves along these paths (the interface ``fit_counts`` reads).
    """

    def __init__(self, scene, paths, weights):
        self.scene, self.paths, self.weights, self.cache = scene, np.asarray(paths), np.asarray(weights), {}

    def __call__(self, offset_opl=0.0, fwhm=None, tail=None):
        from analytic.waveforms import make_waveform

        key = (offset_opl, fwhm, tail)
        if key not in self.cache:
            sampling = self.scene.sampling
            shifted = Sampling(bin_width_opl=sampling.bin_width_opl, start_opl=sampling.start_opl + offset_opl,
                               count=sampling.count)
            pulse = make_waveform(Illumination(waveform="gaussian", fwhm=fwhm or self.scene.illumination.fwhm),
                                  sampling.bin_width_opl)
            self.cache[key] = (pulse.kernel(self.paths, shifted) @ self.weights)[None, :]
        return self.cache[key]


def _scene(**changes):
    return Scene(**{"size": 1.0, "pixels": 4, "reflectance": 0.6, "source": (0.4, 0.5, 0.9),
                    "sensors": [(0.6, 0.4, 0.8)], "illumination": Illumination(waveform="gaussian", fwhm=0.06),
                    "sampling": Sampling(bin_width_opl=0.02, start_opl=1.55, count=60), "tolerance": 1e-6,
                    **changes})


def _diagnose(model, cycles):
    """Counts through fwhm 0.09 m, offset 0.01 m, scale 0.8 against a claim of 0.06 m: judged, then fitted."""
    y = model()
    detector = Detector(photons=3000.0 / (cycles * y.max()), background=0.02, cycles=cycles, dead_time="cycle",
                        seed=9)
    counts = draw_counts(0.8 * model(offset_opl=0.01, fwhm=0.09), detector)
    claimed = judge_counts(counts, expected_counts(y, detector), detector)
    assert not claimed.agrees and claimed.p_value < 1e-3
    found = fit_counts(counts, model, detector, fit=("scale", "offset_opl", "fwhm"))
    assert found.verdict.agrees, found
    for name, value in (("scale", 0.8), ("offset_opl", 0.01), ("fwhm", 0.09)):
        assert abs(found.parameters[name] - value) <= 4 * found.stderr[name], (name, found.parameters, found.stderr)
    # the errors are honest and small enough to tell the claimed width from the true one
    assert abs(found.parameters["fwhm"] - 0.06) > 5 * found.stderr["fwhm"]
    return found


def test_fit_diagnoses_a_capture_whose_filter_differs_from_its_claim():
    _diagnose(PathsModel(_scene(), np.linspace(1.8, 2.3, 40), np.linspace(1.0, 0.2, 40)), cycles=1e5)


@pytest.mark.slow
def test_fit_diagnoses_a_scene_capture_through_the_exact_model():
    """The same diagnosis with every trial model a forward run of the scene (SceneModel)."""
    _diagnose(SceneModel(_scene()), cycles=1e5)
