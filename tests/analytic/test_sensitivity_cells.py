"""One cell's coarea integral H(t) against the t-derivative of its area integral F(t) (analytic.kernels.sensitivity).

H_a(t) = ∫_cell a δ(d - t) dx is dF_a/dt with F_a(t) = ∫_{cell, d < t} a dx;
F is smooth in t and its Richardson central differences are good to ~1e-12,
an independent reference for H. The hard cells are those at the
isochrone's x-extreme (the square-root branch point of its roots, where
H's integrand is as large as 1/sqrt): the extreme inside the cell, just
beyond its edge, and a cell 100 times smaller than the ellipse (each 200
steps of the differences clear of an edge: F is smooth there; the
differences agree with themselves at half the step to 6e-10, and an x-map
whose extreme is off by √ε misses 7e-8 to 2e-7).
"""

import numpy as np
import pytest

from analytic.kernels.sensitivity import AMPLITUDES, isochrone_ellipse, pair_sums
from analytic.operator.sensitivity import pair_geometry

_T = 2.1


def _sums(geometry, cell, t, rtol=1e-10):
    F, H = np.zeros((1, AMPLITUDES)), np.zeros((1, AMPLITUDES))
    assert pair_sums(geometry, np.array([cell]), np.array([t]), rtol, F, H) == 0
    return F[0], H[0]


def _extreme(geometry, t):
    cx, _, a, b = isochrone_ellipse(geometry, t)
    return cx + np.hypot(a * geometry.ex, b * geometry.ey)


@pytest.mark.parametrize("attenuation", ["lambertian", "paper"])
@pytest.mark.parametrize("placement", ["inside", "beyond", "small"])
def test_the_edge_integral_is_the_area_integrals_derivative_at_an_extreme(attenuation, placement):
    geometry = pair_geometry([0.5, 0.5, 1.0], [2 / 3, 2 / 3, 1.0], attenuation)
    right = _extreme(geometry, _T)
    width = 3e-3 if placement == "small" else 0.03
    edge = right + {"inside": 0.4, "beyond": -0.2, "small": 0.3}[placement] * width
    cell = [edge - width, edge, 0.5, 0.67, 1.0]       # the ellipse's roots cross it near the extreme
    step = 1e-3 * width
    central = [(_sums(geometry, cell, _T + h)[0][0] - _sums(geometry, cell, _T - h)[0][0]) / (2 * h)
               for h in (step, step / 2)]
    reference = (4 * central[1] - central[0]) / 3
    edge_integral = _sums(geometry, cell, _T)[1][0]
    assert edge_integral > 0
    assert abs(edge_integral - reference) <= 1e-8 * abs(reference)
