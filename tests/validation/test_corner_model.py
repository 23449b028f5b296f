"""The corner's one-bounce model: two rectangles of one scene, against the construction it replaced and against
an independent quadrature of the one-bounce integral on the wall."""

from __future__ import annotations

import math

import numpy as np
import pytest

from analytic.errors import SceneError
from analytic.scenes.common import Illumination, Sampling, Scene
from analytic.operator.system import rectangle_matrix
from analytic.operator.matrix_free import forward
from analytic.waveforms import make_waveform
from validation.runs.corner import Corner, corner_model, corner_pairs, corner_rectangles, default_corner

# A sensor near the wall and one near the floor: the attenuation peaks sharply under both.
NEAR_CORNER = Corner(name="near", source=(0.35, 0.8, 0.25), sensors=((0.12, 0.3, 0.6), (0.7, 0.55, 0.15)),
                     albedo=0.8, sampling=Sampling(bin_width_opl=0.04, start_opl=0.3, count=70))


def _rotated_planes_model(corner: Corner) -> np.ndarray:
    """The construction the corner had: the wall rotated onto z = 0, two plane scenes added."""
    source = np.asarray(corner.source, dtype=np.float64)
    sensors = np.asarray(corner.sensors, dtype=np.float64)
    rotate = [1, 2, 0]                     # (x, y, z) -> (y, z, x): the wall x = 0 onto z = 0
    return sum(forward(Scene(size=1.0, pixels=1, reflectance=corner.albedo, source=s, sensors=k,
                             sampling=corner.sampling))
               for s, k in ((source, sensors), (source[rotate], sensors[:, rotate])))


@pytest.mark.parametrize("corner", [default_corner(), NEAR_CORNER], ids=["default", "near"])
def test_two_rectangles_of_one_scene_equal_the_rotated_planes_added(corner):
    old = _rotated_planes_model(corner)
    new = corner_model(corner)
    assert np.max(old) > 0
    assert np.max(np.abs(new - old)) <= 1e-12 * np.max(np.abs(old))


def test_each_rectangle_faces_into_the_corner():
    floor, wall = corner_rectangles()
    assert np.array_equal(floor.normal, [0.0, 0.0, 1.0])
    assert np.array_equal(wall.normal, [1.0, 0.0, 0.0])
    assert np.allclose(wall.corners(), [[0, 0, 0], [0, 1, 0], [0, 0, 1], [0, 1, 1]])


def test_a_point_behind_the_wall_is_refused():
    outside = Corner(name="outside", source=(-0.2, 0.5, 0.5), sensors=((0.5, 0.5, 0.5),), albedo=0.5,
                     sampling=Sampling(bin_width_opl=0.05, start_opl=0.5, count=20))
    with pytest.raises(SceneError):
        corner_pairs(outside)


def _path_and_weight(y, z, source, sensor, albedo, area):
    """d = d_s + d_k and ρ I a area at wall points (0, y, z): a = cos θ_s cos θ_k / (π d_s² d_k²), I = 1."""
    source_squared = source[0] ** 2 + (y - source[1]) ** 2 + (z - source[2]) ** 2
    sensor_squared = sensor[0] ** 2 + (y - sensor[1]) ** 2 + (z - sensor[2]) ** 2
    source_distance, sensor_distance = np.sqrt(source_squared), np.sqrt(sensor_squared)
    # the wall's normal is +x: cos θ = x / d at both ends
    cosines = (source[0] / source_distance) * (sensor[0] / sensor_distance)
    return source_distance + sensor_distance, albedo * cosines / (math.pi * source_squared * sensor_squared) * area


def _binned_midpoint(source, sensor, albedo, sampling, cells=512, levels=3):
    """The impulse's y[n] on the wall by the midpoint rule, cells that a bin edge may cut refined 4 x 4.

    Returns the values and a bound on the binning error per bin: d varies by at most √2 h over a cell of
    side h (|∇d| <= 2 on the wall), so a cell whose d-range holds no bin edge lies in one bin; each cell
    still cut after the last level may put all of its weight in the wrong one of its two bins.
    """
    start, width, count = sampling.start_opl, sampling.bin_width_opl, sampling.count
    side = 1.0 / cells
    centres = (np.arange(cells) + 0.5) * side
    y, z = (grid.ravel() for grid in np.meshgrid(centres, centres, indexing="ij"))
    values, bound = np.zeros(count), np.zeros(count)
    for level in range(levels + 1):
        path, weight = _path_and_weight(y, z, source, sensor, albedo, side * side)
        reach = math.sqrt(2.0) * side
        assert 2 * reach < width
        low = np.floor((path - reach - start) / width).astype(np.int64)
        high = np.floor((path + reach - start) / width).astype(np.int64)
        cut = low != high
        last = level == levels
        kept = np.ones_like(cut) if last else ~cut
        bins = np.floor((path[kept] - start) / width).astype(np.int64)
        inside = (bins >= 0) & (bins < count)
        values += np.bincount(bins[inside], weight[kept][inside], minlength=count)
        if last:
            for ends in (low[cut], high[cut]):
                inside = (ends >= 0) & (ends < count)
                bound += np.bincount(ends[inside], weight[cut][inside], minlength=count)
            break
        offsets = (np.arange(4) - 1.5) * side / 4
        child_y, child_z = np.meshgrid(offsets, offsets, indexing="ij")
        y = (y[cut][:, None] + child_y.ravel()[None, :]).ravel()
        z = (z[cut][:, None] + child_z.ravel()[None, :]).ravel()
        side /= 4
    return values, bound


def test_the_wall_alone_is_the_one_bounce_integral_by_the_midpoint_rule():
    corner = default_corner()
    _, wall = corner_rectangles()
    pairs = corner_pairs(corner)
    waveform = make_waveform(Illumination(), corner.sampling.bin_width_opl)
    model = (rectangle_matrix(wall, pairs, corner.sampling, waveform) @ np.full(1, corner.albedo)).reshape(
        len(pairs), corner.sampling.count)
    source = np.asarray(corner.source, dtype=np.float64)
    nearest = min(source[0], min(sensor[0] for sensor in corner.sensors))
    # The midpoint rule's own error on a cell of side h is h²/24 |∇²w| h²; with w ∝ x_s x_k / (d_s³ d_k³),
    # |∇²w| / w <= 84 / d² at distance d >= nearest from the wall, on the coarsest cells (h = 1/512).
    smooth = (1.0 / 512) ** 2 / 24 * 84 / nearest**2
    for k, sensor in enumerate(corner.sensors):
        values, bound = _binned_midpoint(source, np.asarray(sensor, dtype=np.float64), corner.albedo,
                                         corner.sampling)
        assert np.count_nonzero(values) > 10
        tolerance = bound + 2 * smooth * values + 1e-9 * values.max()
        assert np.all(np.abs(model[k] - values) <= tolerance), np.max(np.abs(model[k] - values) / tolerance)
        # the reference is sharp enough to see a model off by 1 % wherever there is light
        lit = values > 0.01 * values.max()
        assert np.all(tolerance[lit] < 0.01 * values[lit])
