"""Spherical-rectangle sampling against the closed-form solid angle of rectangles.

The solid angle of [x0, x1] x [y0, y1] seen from height h above the origin
is F(x1, y1) - F(x0, y1) - F(x1, y0) + F(x0, y0) with
F(x, y) = atan(x y / (h sqrt(x² + y² + h²))), independent of the sampler's
own angles. Points drawn by the sampler must fall in every cell of a grid
with probability Ω_cell / Ω (a χ² test at a fixed seed), and the sampler's
Ω must be that closed form.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from transient import backend
from transient.spherical_rectangle import density, setup

POINTS = {
    "above the centre": (0.5, 0.5, 1.0),
    "1e-3 above the plane": (0.3, 0.4, 1e-3),
    "1e-3 above a corner": (0.999, 0.001, 1e-3),
    "outside the footprint": (1.5, -0.5, 0.3),
    "grazing": (-3.0, 0.5, 0.05),
    "1e-6 above the plane": (0.5, 0.25, 1e-6),
}


def _solid_angle(point, x0, x1, y0, y1):
    px, py, h = point

    def corner(x, y):
        x, y = x - px, y - py
        return np.arctan(x * y / (h * np.sqrt(x * x + y * y + h * h)))

    return corner(x1, y1) - corner(x0, y1) - corner(x1, y0) + corner(x0, y0)


@pytest.fixture(scope="module")
def mitsuba():
    backend.select_variant()
    import mitsuba

    return mitsuba


@pytest.mark.parametrize("name", POINTS)
def test_solid_angle_is_the_closed_form(name):
    point = POINTS[name]
    rectangle = setup(point, 1.0, 1.0)
    assert rectangle.solid_angle == pytest.approx(_solid_angle(point, 0.0, 1.0, 0.0, 1.0), rel=1e-10)


@pytest.mark.parametrize("name", POINTS)
def test_points_follow_the_solid_angle(mitsuba, rng, name):
    from transient.spherical_rectangle import sample

    point = POINTS[name]
    rectangle = setup(point, 1.0, 1.0)
    count = 2**20
    x, y = sample(rectangle, mitsuba.Float64(rng.random(count)), mitsuba.Float64(rng.random(count)))
    x, y = np.array(x), np.array(y)
    assert np.all((x >= 0) & (x <= 1) & (y >= 0) & (y <= 1))
    # Cells: a regular 12 x 12 grid, refined around the point's foot where the density peaks.
    foot = np.clip(point[:2], 0.0, 1.0)
    edges = []
    for axis in range(2):
        regular = np.linspace(0.0, 1.0, 13)
        near = foot[axis] + np.array([-1, 1])[:, None] * np.geomspace(point[2], 0.05, 6)[None, :]
        edges.append(np.unique(np.clip(np.concatenate([regular, near.ravel()]), 0.0, 1.0)))
    observed, _, _ = np.histogram2d(x, y, bins=edges)
    expected = count * np.array([[_solid_angle(point, a, b, c, d) for c, d in zip(edges[1][:-1], edges[1][1:])]
                                 for a, b in zip(edges[0][:-1], edges[0][1:])]) / rectangle.solid_angle
    kept = expected > 20            # χ² needs expected counts well above a few
    statistic = float(np.sum((observed[kept] - expected[kept]) ** 2 / expected[kept]))
    dof = int(kept.sum()) - 1
    assert observed[~kept].sum() <= 4 * max(expected[~kept].sum(), 1.0)
    assert statistic < stats.chi2.isf(1e-3, dof), f"χ² = {statistic:.1f} over {dof} cells"


def test_density_is_cosine_over_distance_squared_over_solid_angle():
    point = POINTS["outside the footprint"]
    rectangle = setup(point, 1.0, 1.0)
    x, y = np.array([0.0, 0.3, 1.0]), np.array([0.2, 0.9, 1.0])
    distance = np.sqrt((x - point[0]) ** 2 + (y - point[1]) ** 2 + point[2] ** 2)
    np.testing.assert_allclose(density(rectangle, x, y),
                               (point[2] / distance) / distance**2 / rectangle.solid_angle, rtol=1e-14)


def test_point_on_the_plane_is_refused():
    with pytest.raises(ValueError, match="above"):
        setup((0.5, 0.5, 0.0), 1.0, 1.0)
