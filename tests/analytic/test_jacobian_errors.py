"""jacobian(..., errors=True): each (row, key) column's stated error bound holds against an independent reference.

The reference is the exact route at tolerance 1e-10 (interior and bin-edge
cell integrals, a method that shares nothing with the differences; itself
held to fine-step differences and a closed form in test_jacobian_exact.py).
Two kinds of y(θ) for the differences: with kinks (the impulse over a few
pixels: a bin edge's isochrone passing a pixel corner bends y_n(θ), and the
default step straddles such bends) and smooth (one uniform pixel much larger
than every isochrone of the window, the first arrival below the first edge:
y_n(θ) analytic around θ), each at two steps. The pair's disagreement
|D(h/2) - D(h)| / 3 alone (plus the model's part) is 0.2 of the error with
the kinks: the bound's second-difference term is what holds there.
"""

import numpy as np
import pytest

from analytic.operator.derivatives import jacobian
from analytic.scenes.common import Sampling, default_scene

_KEYS = ["source.position.x", "source.position.z", "sensors.positions.0.x", "sensors.positions.0.y",
         "sensors.positions.0.z", "sampling.start"]


def _kinked():
    image = np.random.default_rng(1).uniform(0.2, 1.0, (8, 8))
    return default_scene(pixels=8, reflectance=image, sensors=[[0.3, 0.6, 0.8], [0.9, 0.2, 0.5]],
                         sampling=Sampling(bin_width_opl=0.07, start_opl=1.75, count=14), noise=None)


def _smooth():
    # the first arrival (1.83 m) below the first edge, the last edge's ellipse (2.55 m) well inside the 4 m plane
    return default_scene(size=4.0, pixels=1, reflectance=np.ones((1, 1)), source=(2.0, 2.0, 1.0),
                         sensors=[[2.3, 1.9, 0.8]], sampling=Sampling(bin_width_opl=0.1, start_opl=1.95, count=6),
                         noise=None)


@pytest.mark.parametrize("step", [None, 1e-2])
@pytest.mark.parametrize("make", [_kinked, _smooth], ids=["kinks", "smooth"])
def test_the_differences_bound_holds_against_the_exact_route(make, step):
    scene = make()
    values, bounds = jacobian(scene, _KEYS, route="differences", step=step, errors=True)
    np.testing.assert_array_equal(values, jacobian(scene, _KEYS, route="differences", step=step))
    reference = jacobian(scene.replace(tolerance=1e-10), _KEYS)
    gap = np.abs(values - reference).max(axis=1)
    assert bounds.shape == gap.shape == (scene.sensor_count, len(_KEYS))
    assert np.all(gap <= bounds), gap / bounds
    # informative at the default step: below each live column's largest entry
    largest = np.abs(reference).max(axis=1)
    if step is None:
        assert np.all(bounds[largest > 0] < largest[largest > 0])


@pytest.mark.parametrize("make", [_kinked, _smooth], ids=["kinks", "smooth"])
def test_the_exact_routes_bound_is_the_scenes_tolerance_of_each_column(make):
    scene = make()
    values, bounds = jacobian(scene, _KEYS + ["source.intensity"], errors=True)
    np.testing.assert_array_equal(bounds, scene.tolerance * np.abs(values).max(axis=1))
    reference = jacobian(scene.replace(tolerance=1e-10), _KEYS + ["source.intensity"])
    assert np.all(np.abs(values - reference).max(axis=1) <= bounds)
