"""Finite-difference derivatives of y against derivatives of the integral taken by hand."""

import numpy as np
import pytest

from analytic.operator.derivatives import derivative
from analytic.scenes.common import Sampling, default_scene


def _scene():
    """A small plane whose one-bin window holds all the light: Σ_n y = I ∫ ρ a dx."""
    return default_scene(pixels=6, sensors=[[0.2, 0.7, 0.9], [0.8, 0.4, 1.2]],
                         sampling=Sampling(bin_width_opl=4.0, start_opl=0.5, count=1), noise=None)


def _total_derivative(scene, wrt):
    """∂/∂θ of I Σ_pixels ρ_p ∫_p a, a = h_s h_k / (π d_s³ d_k³), by a 24 x 24 Gauss rule per pixel.

    Written out independently: ∂a/∂h_s = h_k (d_s² - 3 h_s²) / (π d_s⁵ d_k³) and
    ∂a/∂x_k = 3 h_s h_k (x - x_k) / (π d_s³ d_k⁵) (the sensor moving along x).
    """
    nodes, weights = np.polynomial.legendre.leggauss(24)
    delta = scene.size / scene.pixels
    source = np.asarray(scene.source)
    totals = []
    for sensor in np.asarray(scene.sensors):
        total = 0.0
        for r in range(scene.pixels):
            for c in range(scene.pixels):
                x = (c + 0.5 + 0.5 * nodes) * delta
                y = scene.size - (r + 0.5 + 0.5 * nodes) * delta
                xx, yy = np.meshgrid(x, y, indexing="ij")
                ds = np.sqrt((xx - source[0]) ** 2 + (yy - source[1]) ** 2 + source[2] ** 2)
                dk = np.sqrt((xx - sensor[0]) ** 2 + (yy - sensor[1]) ** 2 + sensor[2] ** 2)
                if wrt == "source height":
                    f = sensor[2] * (ds**2 - 3 * source[2] ** 2) / (np.pi * ds**5 * dk**3)
                else:
                    f = 3 * source[2] * sensor[2] * (xx - sensor[0]) / (np.pi * ds**3 * dk**5)
                total += scene.reflectance[r, c] * np.sum(np.outer(weights, weights) * f) * (delta / 2) ** 2
        totals.append(scene.intensity * total)
    return np.array(totals)


def test_source_height_derivative_matches_the_integral_differentiated_by_hand():
    scene = _scene()
    computed = derivative(scene, "source.position[2]")[:, 0]
    np.testing.assert_allclose(computed, _total_derivative(scene, "source height"), rtol=1e-7)


def test_sensor_derivative_moves_only_its_own_row():
    scene = _scene()
    computed = derivative(scene, "sensors.positions[0][0]")[:, 0]
    assert computed[1] == 0.0
    np.testing.assert_allclose(computed[0], _total_derivative(scene, "sensor x")[0], rtol=1e-7)


def test_moving_the_plane_is_moving_the_points_the_other_way():
    """Lowering the plane by dz raises every point by dz: ∂/∂(plane z) = -(∂/∂h_s + Σ_k ∂/∂h_k)."""
    scene = _scene()
    plane = derivative(scene, "plane.translation[2]")
    points = derivative(scene, "source.position[2]") + sum(
        derivative(scene, f"sensors.positions[{k}][2]") for k in range(scene.sensor_count))
    np.testing.assert_allclose(plane, -points, rtol=1e-7)


def test_unknown_parameters_are_refused():
    with pytest.raises(ValueError, match="parameter"):
        derivative(_scene(), "source.colour")
