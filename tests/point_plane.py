"""A point-like plane's exact derivatives by hand (tests/analytic/test_jacobian_*.py).

For a plane of side s small against its distances, d ≈ L + g·u over it
(L the path length through its centre, g the gradient of d there), so

    ∂y_n/∂θ ≈ I s² [∂a/∂θ K_n + a ∂L/∂θ K'_n],   ∂y_n/∂t_0 ≈ -I s² a K'_n,

with K_n = ∫ p(v) κ_n(L + v) dv and K'_n = ∫ p(v) κ_n'(L + v) dv, p the
density of g·u over the plane (a trapezoid: two uniforms added), and the
relative error O(s / distance).
"""

import numpy as np

from analytic.attenuation import attenuation


def trapezoid(tau, alpha, beta):
    """Density and distribution of g_x u + g_y v, u, v uniform on [-s/2, s/2] (alpha = |g_x| s/2, beta = |g_y| s/2)."""
    corners = [(1.0, alpha + beta), (-1.0, alpha - beta), (-1.0, beta - alpha), (1.0, -alpha - beta)]
    area = sum(sign * np.maximum(tau + shift, 0.0) ** 2 / 2.0 for sign, shift in corners)
    slope = sum(sign * np.maximum(tau + shift, 0.0) for sign, shift in corners)
    return slope / (4.0 * alpha * beta), area / (4.0 * alpha * beta)


def centre_and_spread(scene):
    """(centre, L, alpha, beta) of a one-sensor point-like plane scene (:func:`trapezoid`'s alpha and beta)."""
    side = float(scene.size)
    source, sensor = np.asarray(scene.source, dtype=np.float64), np.asarray(scene.sensors[0], dtype=np.float64)
    centre = np.array([0.5 * side, 0.5 * side, 0.0])
    length = np.linalg.norm(centre - source) + np.linalg.norm(centre - sensor)
    gradient = ((centre - source) / np.linalg.norm(centre - source)
                + (centre - sensor) / np.linalg.norm(centre - sensor))[:2]
    alpha, beta = np.abs(gradient) * side / 2.0
    return centre, length, alpha, beta


def expected_columns(scene, kernel, slope):
    """(N, 7): ∂y/∂source.position.{x,y,z}, ∂y/∂sensors.positions.0.{x,y,z}, ∂y/∂sampling.start by hand,
    from K_n (``kernel``) and K'_n (``slope``)."""
    mode, side = scene.attenuation, float(scene.size)
    source, sensor = np.asarray(scene.source, dtype=np.float64), np.asarray(scene.sensors[0], dtype=np.float64)
    centre = centre_and_spread(scene)[0]

    def a(p_source, p_sensor):
        return attenuation(centre[None, :2], p_source, p_sensor, mode)[0]

    expected = np.zeros((scene.sampling.count, 7))
    h = 1e-6
    for j in range(3):
        step = np.eye(3)[j] * h
        partial_source = (a(source + step, sensor) - a(source - step, sensor)) / (2 * h)
        partial_sensor = (a(source, sensor + step) - a(source, sensor - step)) / (2 * h)
        along_source = (source - centre)[j] / np.linalg.norm(source - centre)     # ∂L/∂p_s
        along_sensor = (sensor - centre)[j] / np.linalg.norm(sensor - centre)
        expected[:, j] = partial_source * kernel + a(source, sensor) * along_source * slope
        expected[:, 3 + j] = partial_sensor * kernel + a(source, sensor) * along_sensor * slope
    expected[:, 6] = -a(source, sensor) * slope                                   # every edge moving by +dt
    return expected * scene.intensity * side * side
