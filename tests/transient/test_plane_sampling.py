"""The plane integrator's sampling techniques: where their points fall and the density they state, against the
solid-angle density h / d³ integrated by brute force; the blocks of a replica; the choice of area sampling."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

WIDTH, HEIGHT = 1.2, 0.8          # not a square: a swapped side changes every cell
SOURCE, SENSOR = (0.3, 0.5, 0.6), (1.0, 0.1, 0.25)
CELLS = 8


@pytest.fixture(scope="module")
def sampling(mitsuba):
    from transient import plane_sampling

    return plane_sampling


def _cell_probabilities(point):
    """``(CELLS, CELLS)`` probability of each cell (x index, y index) for points drawn by ``point``'s solid angle.

    The density h / d³ integrated over each cell by the midpoint rule on 40 x 40 points and normalised by
    its sum: h / d³ varies on the scale of the heights (>= 0.25 m), so the rule's relative error is
    ~ (cell side / 40 / 0.25)² / 24 ~ 1e-5 per cell.
    """
    points = 40 * CELLS
    x = (np.arange(points) + 0.5) * WIDTH / points
    y = (np.arange(points) + 0.5) * HEIGHT / points
    px, py, h = point
    squared = (x[:, None] - px) ** 2 + (y[None, :] - py) ** 2 + h * h
    cells = (h / squared**1.5).reshape(CELLS, 40, CELLS, 40).sum(axis=(1, 3))
    return cells / cells.sum()


def _plan(sampling):
    """Two solid-angle techniques and an area one: every branch of the warp at once."""
    from transient import spherical_rectangle

    return [sampling.Technique(sampling.SOLID_ANGLE, SOURCE, 0.5, spherical_rectangle.setup(SOURCE, WIDTH, HEIGHT)),
            sampling.Technique(sampling.AREA, (0.6, 0.4, 5.0), 0.2, None),
            sampling.Technique(sampling.SOLID_ANGLE, SENSOR, 0.3, spherical_rectangle.setup(SENSOR, WIDTH, HEIGHT))]


def _expected(plan, sampling):
    area = np.full((CELLS, CELLS), 1.0 / CELLS**2)
    return sum(t.share * (area if t.kind == sampling.AREA else _cell_probabilities(t.point)) for t in plan)


def test_warped_points_fall_in_each_cell_with_the_closed_form_probability(sampling, mitsuba, rng):
    plan = _plan(sampling)
    count = 400_000
    technique = np.repeat(np.arange(len(plan)), [int(t.share * count) for t in plan])
    u, v = rng.random(len(technique)), rng.random(len(technique))
    x, y = sampling.warp(plan, mitsuba.UInt32(technique), mitsuba.Float64(u), mitsuba.Float64(v), WIDTH, HEIGHT)
    x, y = np.array(x), np.array(y)
    assert np.all((x >= 0) & (x <= WIDTH) & (y >= 0) & (y <= HEIGHT))
    observed, _, _ = np.histogram2d(x, y, bins=CELLS, range=[[0, WIDTH], [0, HEIGHT]])
    expected = _expected(plan, sampling) * len(technique)
    chi2 = float(np.sum((observed - expected) ** 2 / expected))
    assert stats.chi2.sf(chi2, CELLS**2 - 1) > 1e-3


def test_the_mixture_density_integrates_to_each_cells_probability(sampling, mitsuba):
    plan = _plan(sampling)
    # the same midpoint rule as the cells' probabilities: what differs is the density's normalisation (Ω)
    # and its form; the rule's own error, ~1e-5, is below the tolerance
    points = 40 * CELLS
    x = (np.arange(points) + 0.5) * WIDTH / points
    y = (np.arange(points) + 0.5) * HEIGHT / points
    grid_x, grid_y = np.meshgrid(x, y, indexing="ij")
    shares = [mitsuba.Float64(t.share) for t in plan]
    density = np.array(sampling.mixture_density(plan, shares, mitsuba.Float64(grid_x.ravel()),
                                                 mitsuba.Float64(grid_y.ravel()), WIDTH, HEIGHT))
    cells = density.reshape(CELLS, 40, CELLS, 40).sum(axis=(1, 3)) * (WIDTH / points) * (HEIGHT / points)
    assert np.allclose(cells, _expected(plan, sampling), rtol=1e-4, atol=0)


@pytest.mark.parametrize("shares, size", [([0.5, 0.25, 0.25], 1000), ([0.98, 0.01, 0.01], 3), ([1.0], 7),
                                          ([0.5, 0.5 / 3, 0.5 / 3, 0.5 / 3], 2**20 + 1)])
def test_replica_blocks_cover_the_replica_in_order_and_follow_the_shares(sampling, shares, size):
    bounds = sampling.block_bounds(shares, size)
    assert bounds[0] == 0 and bounds[-1] == size and len(bounds) == len(shares) + 1
    sizes = np.diff(bounds)
    assert np.all(sizes >= 1)
    if size >= 100 * len(shares):
        assert np.all(np.abs(sizes - np.asarray(shares) * size) <= 1)


# ratios 1.03, 17.6, 3.19, 1.13, and 2.96 / 3.03 on either side of the limit 3
@pytest.mark.parametrize("point", [(0.6, 0.4, 5.0), (0.6, 0.4, 0.3), (3.0, -2.0, 1.0), (30.0, 0.4, 1.0),
                                   (0.6, 0.4, 0.7), (0.6, 0.4, 0.69)])
def test_area_sampling_where_the_solid_angle_density_varies_less_than_the_stated_ratio(sampling, point):
    # h / d³ over a dense grid of the rectangle, edges included: its largest over its smallest
    x, y = np.meshgrid(np.linspace(0, WIDTH, 601), np.linspace(0, HEIGHT, 401), indexing="ij")
    squared = (x - point[0]) ** 2 + (y - point[1]) ** 2 + point[2] ** 2
    ratio = float(np.max(squared) / np.min(squared)) ** 1.5
    expected = sampling.AREA if ratio < sampling.AREA_SAMPLING_RATIO else sampling.SOLID_ANGLE
    assert sampling.sampling_kind(point, WIDTH, HEIGHT) == expected
