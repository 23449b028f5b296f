"""The built-in suite's captures through a relay wall: the poses it promises, each agreeing with our renderer
at the suite's sample count by the replicas' test, and a model without the wall's cosine failing it."""

import functools

import numpy as np
import pytest

from analytic.geometry import PointPairs
from analytic.scenes.relay_wall import RelayWallScene
from analytic.operator.system import rectangle_matrix
from analytic.operator.matrix_free import forward
from analytic.waveforms import make_waveform
from transient.render import render
from validation.judging.compare import MIN_CHECK_SAMPLES, compare_transients
from validation.runs.suite import MINIMUM_SAMPLES, RELAY_WALL_SAMPLES, relay_wall_cases, validation_suite

CASES = relay_wall_cases()


def test_the_suite_holds_the_six_poses_and_both_scans_with_the_legs_counted():
    suite = {scene.name: spp for scene, spp in validation_suite() if isinstance(scene, RelayWallScene)}
    assert suite == dict.fromkeys(CASES, RELAY_WALL_SAMPLES)
    poses = {"nlos-grazing", "nlos-tilted", "nlos-near-wall", "nlos-far", "nlos-tiny", "nlos-confocal"}
    assert poses <= set(CASES)
    assert CASES["nlos-confocal"].scan.type == "confocal"
    for name, scan_type in (("nlos-single-legs", "single"), ("nlos-exhaustive-legs", "exhaustive")):
        assert CASES[name].scan.type == scan_type and CASES[name].scan.account_first_and_last_bounces
    # the poses are what their names say, from the scenes' own numbers
    grazing = CASES["nlos-grazing"]
    normal = np.cross(grazing.u, grazing.v) / np.linalg.norm(np.cross(grazing.u, grazing.v))
    assert abs(normal[2]) < 1e-12                                # its face is perpendicular to the wall
    tilted = CASES["nlos-tilted"]
    assert 0.3 < np.arccos(np.cross(tilted.u, tilted.v)[2] / -np.linalg.norm(np.cross(tilted.u, tilted.v))) < 1.0
    assert CASES["nlos-near-wall"].center[2] <= 0.05 and CASES["nlos-far"].center[2] >= 40.0
    assert max(np.linalg.norm(CASES["nlos-tiny"].u), np.linalg.norm(CASES["nlos-tiny"].v)) <= 1e-3


@functools.lru_cache(maxsize=None)
def _case(name):
    """A suite case rendered at the suite's count: (scene, render), rendered once per test session."""
    scene = CASES[name]
    return scene, render(scene, spp=RELAY_WALL_SAMPLES, seed=17, progress=False)


def _judged(scene, result, model):
    return compare_transients(result.mean, result.stderr, model, dof=result.dof, replicas=result.replica_means)


# one case by default (the wall's cosines at their most peaked; tests/transient/test_nlos.py holds a confocal, a
# tilted single and an exhaustive scan with both legs); all of them under -m slow
FAST = ("nlos-near-wall",)


@pytest.mark.parametrize("name", [pytest.param(name, marks=() if name in FAST else pytest.mark.slow)
                                  for name in CASES])
def test_each_relay_wall_case_agrees_at_the_suite_count(name):
    scene, result = _case(name)
    agreement = _judged(scene, result, forward(scene))
    assert agreement.agrees and agreement.bins >= 50, f"{name}: {agreement.summary()}"


def _without_the_wall_cosine_at_s(scene: RelayWallScene) -> np.ndarray:
    """The model with the read point's cosine cos θ_s^x left out: a deliberately wrong model."""
    rectangle, pairs = scene.geometry()
    wrong = PointPairs(pairs.sources, pairs.sensors, offsets=pairs.offsets, source_normals=pairs.source_normals,
                       scales=pairs.scales)
    matrix = rectangle_matrix(rectangle, wrong, scene.sampling,
                              make_waveform(scene.illumination, scene.sampling.bin_width_opl))
    return (matrix @ scene.reflectance.ravel()).reshape(scene.sensor_count, scene.sampling.count)


@pytest.mark.parametrize("name", ["nlos-near-wall", pytest.param("nlos-tilted", marks=pytest.mark.slow)])
def test_a_model_without_the_wall_cosine_fails_the_suites_test(name):
    scene, result = _case(name)
    assert not _judged(scene, result, _without_the_wall_cosine_at_s(scene)).agrees


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_the_fewest_samples_the_suite_allows_judge_some_bins(name):
    """At the fewest samples ``validate --spp`` accepts for it, each case has bins to judge."""
    scene = CASES[name]
    spp = max(MIN_CHECK_SAMPLES, MINIMUM_SAMPLES.get(name, 0))
    result = render(scene, spp=spp, seed=3, progress=False)
    assert _judged(scene, result, forward(scene)).bins > 0
