"""What mitransient's NLOS integrator renders: the closed form (model read from the moved origin, less the strip)
held to a brute-force emulation of mitransient's estimator, written from its code (mitransient 1.3.1
``transient_nlos_path``: hidden-geometry sampling, ``spawn_ray``, laser sampling).

The ray offset is magnified (2 mm instead of Mitsuba's ~1.6e-4 m) so that its effects stand far above the
emulation's own noise; the relations are linear in it.
"""

from __future__ import annotations

import numpy as np
import pytest

from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import Sampling
from analytic.operator.matrix_free import forward
from interop.mitransient import emulated_estimates, moved_read_points, offset_model, spawn_offset_difference
from interop.mitransient import nlos as mitransient_nlos

EPSILON = 2e-3


def scene_of(**changes) -> RelayWallScene:
    image = np.arange(16, dtype=np.float64).reshape(4, 4) / 20.0 + 0.1
    values = dict(pixels=4, reflectance=image, center=(0.1, 0.05, 0.6), u=(0.5, 0.0, 0.1), v=(0.0, -0.4, 0.0),
                  scan=Scan(type="single", grid=(2, 2), laser_point=(0.3, -0.2, 0.0)),
                  sampling=Sampling(bin_width_opl=0.02, start_opl=1.0, count=60))
    return RelayWallScene(**(values | changes))


def moments(difference: np.ndarray, scene) -> np.ndarray:
    """Per pair: the time sum and the first moment (bin centres) of a binned difference, ``(P, 2)``."""
    centres = scene.sampling.edges[:-1] + 0.5 * scene.sampling.bin_width_opl
    return np.column_stack([difference.sum(axis=1), difference @ centres])


def test_moved_read_points_follow_mitsubas_offset_p():
    scene = scene_of()
    moved = moved_read_points(scene, ray_epsilon=1.0, world_offset=(10.0, 0.0, 0.0))
    _, read = scene.pair_points
    assert np.array_equal(moved[:, :2], read[:, :2])
    assert np.allclose(moved[:, 2], 1.0 + np.abs(read[:, 0] + 10.0))       # (1 + max_i |s_i|) along +z


def test_the_emulated_estimator_without_offsets_is_the_model():
    scene = scene_of()
    exact, _ = emulated_estimates(scene, samples=2**16, seed=1)
    model = forward(scene)
    assert np.allclose(exact.sum(axis=1), model.sum(axis=1), rtol=2e-5)      # stratified: far below 1e-4
    # without an offset the ray meets x itself (to rounding): nothing is added
    assert np.max(np.abs(spawn_offset_difference(scene, samples=2**12, ray_epsilon=0.0))) < 1e-12 * model.max()


def test_the_closed_form_is_mitransients_estimator():
    scene = scene_of()
    model = forward(scene)
    closed = moments(offset_model(scene, ray_epsilon=EPSILON) - model, scene)
    runs = np.stack([moments(spawn_offset_difference(scene, samples=2**16, seed=seed, ray_epsilon=EPSILON), scene)
                     for seed in range(5)])
    mean, error = runs.mean(axis=0), runs.std(axis=0, ddof=1) / np.sqrt(len(runs))
    assert np.all(np.abs(closed - mean) < 5 * error + 1e-9 * np.abs(model).sum()), (closed, mean, error)
    assert np.all(np.abs(closed[:, 1]) > 20 * error[:, 1])                  # the effect is resolved
    # power: without the strip its sampling misses, the time sums are off by far more than the noise
    rectangle, pairs = scene.geometry()
    strip = mitransient_nlos._unsampled_strip(scene, pairs, moved_read_points(scene, ray_epsilon=EPSILON),
                                              mitransient_nlos.EDGE_POINTS)
    without = closed[:, 0] + strip.sum(axis=1)
    assert np.any(np.abs(without - mean[:, 0]) > 10 * error[:, 0])


def test_only_the_impulse_is_stated():
    from analytic.scenes.common import Illumination

    scene = scene_of(illumination=Illumination(waveform="square"))
    with pytest.raises(ValueError, match="impulse"):
        offset_model(scene)
