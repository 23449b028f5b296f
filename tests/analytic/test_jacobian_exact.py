"""The exact route of analytic.jacobian (interior + bin-edge terms) against two independent references.

1. Richardson central differences of the model assembled at tolerance 1e-10
   (``route="differences"``, a quadrature that shares nothing with the
   exact route's cell integrals), on the hard cases: an isochrone born
   inside a bin, a sensor near the plane, a grazing source (paper
   attenuation), tiny pixels and bins. With the step 2e-5 of the scene's
   extent the differences themselves are good to ~2e-6 of a column's
   largest entry (their truncation, and the model's 1e-10 over the step):
   the bound asserted is 1e-5.
2. A point-like plane (side s << its distances), where y_n ≈ I s² a(c) P_n
   with P_n the share of the plane whose path lengths fall in bin n, d ≈
   L + g·u linear over the plane: the density of g·u over the square is a
   trapezoid (two uniforms added), so ∂y_n/∂θ ≈ I s² [∂a/∂θ P_n + a ∂L/∂θ
   (p(t_n - L) - p(t_{n+1} - L))], differentiated by hand (relative error
   O(s / distance)).
"""

import numpy as np
import pytest

from analytic.operator.derivatives import jacobian
from analytic.operator.matrix_free import forward
from analytic.operator.sensitivity import position_derivatives
from analytic.scenes.common import Sampling, default_scene
from point_plane import centre_and_spread, expected_columns, trapezoid

_POSITIONS = ["source.position.x", "source.position.y", "source.position.z", "sensors.positions.{k}.x",
              "sensors.positions.{k}.y", "sensors.positions.{k}.z", "sampling.start"]
_STEP = 2e-5


def _image(pixels, seed=1):
    return np.random.default_rng(seed).uniform(0.2, 1.0, (pixels, pixels))


def _column_errors(computed, reference):
    """max_n |computed - reference| / max_n |reference| per (sensor, key), over columns that are not all zero."""
    scale = np.abs(reference).max(axis=1)
    gap = np.abs(computed - reference).max(axis=1)
    assert np.all(gap[scale == 0.0] == 0.0)
    return np.where(scale > 0.0, gap / np.where(scale > 0.0, scale, 1.0), 0.0)


def _against_differences(scene, sensor=0, bound=1e-5):
    keys = [key.format(k=sensor) for key in _POSITIONS]
    exact = jacobian(scene, keys)
    reference = jacobian(scene, keys, route="differences", step=_STEP)
    errors = _column_errors(exact, reference)
    assert errors.max() < bound, errors


def test_an_isochrone_born_inside_a_bin():
    # sensor 0's first arrival (1.814 m) falls inside bin 0, 0.09 of a bin below its upper edge: its row's
    # source and time-zero columns see the isochrone born there (sensor 1's, 1.581 m, is before the window)
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.3, 0.6, 0.8], [0.9, 0.2, 0.5]],
                          sampling=Sampling(bin_width_opl=0.07, start_opl=1.75, count=14), noise=None)
    _against_differences(scene, sensor=1)


def test_a_sensor_near_the_plane():
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.37, 0.61, 0.04]],
                          sampling=Sampling(bin_width_opl=0.09, start_opl=1.0, count=14), noise=None)
    _against_differences(scene)


def test_a_grazing_source_with_the_papers_attenuation():
    scene = default_scene(pixels=8, reflectance=_image(8), source=(2.5, 0.4, 0.08), sensors=[[0.5, 0.5, 0.7]],
                          attenuation="paper",
                          sampling=Sampling(bin_width_opl=0.08, start_opl=2.3, count=14), noise=None)
    _against_differences(scene)


def test_tiny_pixels_and_bins():
    scene = default_scene(size=0.1, pixels=40, reflectance=_image(40), source=(0.05, 0.04, 0.3),
                          sensors=[[0.02, 0.07, 0.25]],
                          sampling=Sampling(bin_width_opl=0.004, start_opl=0.548, count=16), noise=None)
    _against_differences(scene)


def test_the_same_integrals_give_the_models_samples():
    scene = default_scene(pixels=12, reflectance=_image(12), sensors=[[0.3, 0.6, 0.8], [0.9, 0.2, 0.5]],
                          sampling=Sampling(bin_width_opl=0.07, start_opl=1.75, count=14), noise=None)
    y = position_derivatives(scene)[0]
    reference = forward(scene.replace(tolerance=1e-10))
    assert np.abs(y - reference).max() < 1e-6 * np.abs(reference).max()


@pytest.mark.parametrize("height", [0.3, 2e-3])
def test_the_scenes_tolerance_bounds_each_column_entry(height):
    """At the default 1e-6, every entry within 1e-6 of its column's largest of the route at 1e-10.

    A sensor 2 mm above the plane: its ∂a/∂h (a peak of height 1/h) must not loosen the other columns'
    accuracy (the time zero's drifted to 7e-6 when the cells were judged on the amplitudes' sum).
    """
    scene = default_scene(pixels=16, reflectance=_image(16), sensors=[[0.2, 0.3, 0.6], [0.7, 0.9, height]],
                          sampling=Sampling(bin_width_opl=0.05, start_opl=1.5, count=30), noise=None)
    keys = [key.format(k=1) for key in _POSITIONS]
    loose = jacobian(scene, keys)
    tight = jacobian(scene.replace(tolerance=1e-10), keys)
    assert _column_errors(loose, tight).max() < scene.tolerance


def test_a_sensors_keys_move_only_its_row_and_the_plane_moving_or_growing_is_the_points_moving_back():
    """The plane's motions and its size come from the points' columns (and, for the size, the edges')."""
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.3, 0.6, 0.8], [0.9, 0.2, 0.5]],
                          sampling=Sampling(bin_width_opl=0.07, start_opl=1.75, count=14), noise=None)
    keys = ["plane.translation.y", "plane.rotation.z", "plane.rotation.x", "plane.size"]
    columns = jacobian(scene, ["sensors.positions.1.y", *keys])
    assert np.all(columns[0, :, 0] == 0.0) and np.any(columns[1, :, 0] != 0.0)
    reference = jacobian(scene, keys, route="differences", step=_STEP)
    assert _column_errors(columns[..., 1:], reference).max() < 1e-5


@pytest.mark.parametrize("mode", ["lambertian", "paper"])
def test_the_plane_growing_on_a_sensor_near_it(mode):
    scene = default_scene(pixels=8, reflectance=_image(8), sensors=[[0.37, 0.61, 0.04]], attenuation=mode,
                          sampling=Sampling(bin_width_opl=0.09, start_opl=1.0, count=14), noise=None)
    computed = jacobian(scene, ["plane.size"])
    reference = jacobian(scene, ["plane.size"], route="differences", step=_STEP)
    assert _column_errors(computed, reference).max() < 1e-5


# -- a point-like plane, by hand ------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["lambertian", "paper"])
def test_a_point_like_plane_against_its_closed_form(mode):
    side = 2e-4
    source, sensor = np.array([0.3, -0.2, 0.7]), np.array([-0.4, 0.5, 0.9])
    centre = np.array([0.5 * side, 0.5 * side, 0.0])
    length = np.linalg.norm(centre - source) + np.linalg.norm(centre - sensor)
    # bins a third of the plane's spread of path lengths, straddling it
    scene = default_scene(size=side, pixels=1, reflectance=np.ones((1, 1)), source=tuple(source),
                          sensors=[tuple(sensor)], attenuation=mode, noise=None,
                          sampling=Sampling(bin_width_opl=side / 3.0, start_opl=length - 1.3 * side, count=8))
    computed = jacobian(scene, [key.format(k=0) for key in _POSITIONS])[0]
    _, length, alpha, beta = centre_and_spread(scene)
    # the impulse: K_n the share of the plane in bin n, K'_n = p(t_n - L) - p(t_{n+1} - L)
    density, distribution = trapezoid(scene.sampling.edges - length, alpha, beta)
    expected = expected_columns(scene, np.diff(distribution), density[:-1] - density[1:])
    errors = np.abs(computed - expected).max(axis=0) / np.abs(expected).max(axis=0)
    assert errors.max() < 2e-3, errors
