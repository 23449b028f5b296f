"""The offset route (analytic.operator.offsets) and y = A f without A (analytic.operator.matrix_free).

A capture whose pairs are translates of a few by whole pixels has each distinct offset's entries
computed once: its entries are held to the independent reference of tests/relay_wall_reference.py
(nested QUADPACK in world coordinates) and to the general route's, entry for entry. y = A f made a
block of pairs at a time equals A f.
"""

import math

import numpy as np
import pytest
from relay_wall_reference import pixel_region, reference_bin

from analytic.operator import offsets
from analytic.operator.matrix_free import forward, forward_route
from analytic.operator.system import _problem, system_matrix
from analytic.operator.window import pairs_range
from analytic.scenes.common import Sampling
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.waveforms import make_waveform

TOLERANCE = 1e-6


def _scene(pixels=4, grid=(16, 16), count=40, **changes):
    image = np.arange(pixels * pixels, dtype=float).reshape(pixels, pixels) / (pixels * pixels)   # asymmetric
    scene = RelayWallScene(pixels=pixels, reflectance=image, scan=Scan(type="confocal", grid=grid),
                           wall_reflectance=0.8, intensity=3.0, **changes)
    low, high = pairs_range(*scene.geometry())
    period = (high - low) * 1.05 / (count - 2)
    return scene.replace(sampling=Sampling(bin_width_opl=period, start_opl=low - period, count=count))


def _plan(scene):
    rectangle, pairs = scene.geometry()
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    return offsets.offset_plan(_problem(rectangle, pairs, scene.sampling, waveform))


#: (scene, groups): a 2 m wall's 8 x 8 scan over a 1 m square of 8 x 8 pixels, one pixel per scan pitch;
#: its 16 x 16 scan over 4 x 4 pixels, half a pixel per pitch, whose points fall on 2 x 2 sub-pixel places;
#: a 0.75 m x 0.5 m rectangle off the wall's centre scanned 16 x 8 (1 and 3 pixels per pitch), the laser
#: and the sensor apart.
CASES = {
    "whole pixels": (dict(pixels=8, grid=(8, 8)), 1),
    "half pixels": (dict(pixels=4, grid=(16, 16)), 4),
    "off centre": (dict(pixels=6, grid=(16, 8), center=(0.3125, -0.125, 0.7), u=(0.75, 0.0, 0.0),
                        v=(0.0, -0.5, 0.0), laser_position=(0.4, 0.3, 0.5), sensor_position=(-0.6, 0.1, 0.3)), 1),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_parallel_rectangle_on_a_commensurate_grid_matches_the_reference_by_offsets(case, rng):
    changes, groups = CASES[case]
    scene = _scene(**changes)
    plan = _plan(scene)
    assert plan is not None
    assert len(plan.virtual.pairs) == groups
    matrix = system_matrix(scene).tocsr()
    row_max = abs(matrix).max(axis=1).toarray().ravel()
    coo = matrix.tocoo()
    chosen = [int(np.argmax(np.abs(coo.data)))] + list(rng.choice(coo.nnz, size=3, replace=False))
    for i in chosen:
        row, pixel = int(coo.row[i]), int(coo.col[i])
        pair, n = divmod(row, scene.sampling.count)
        reference = reference_bin(scene, pair, n, pixel_region(scene, pixel))
        assert abs(coo.data[i] - reference) <= TOLERANCE * row_max[row], (pair, pixel, n, coo.data[i], reference)


@pytest.mark.parametrize("case", list(CASES))
def test_the_offset_route_equals_the_general_route_entry_for_entry(case, monkeypatch):
    scene = _scene(**CASES[case][0])
    by_offsets = system_matrix(scene).tocsr()
    y, statistics = forward(scene, statistics=(found := {})), found
    monkeypatch.setattr(offsets, "MIN_SAVING", 0.0)       # no capture saves enough: the general route
    assert _plan(scene) is None
    general = system_matrix(scene).tocsr()
    assert statistics == {"route": "offsets", "nonzeros": general.nnz}
    assert by_offsets.nnz == general.nnz and np.array_equal(by_offsets.indices, general.indices)
    row_max = abs(general).max(axis=1).toarray().ravel()
    rows = np.repeat(np.arange(general.shape[0]), np.diff(general.indptr))
    assert np.all(np.abs(by_offsets.data - general.data) <= 1e-10 * row_max[rows])     # rounding: 1e-4 of 1e-6
    expected = (general @ scene.reflectance.ravel()).reshape(y.shape)
    assert np.max(np.abs(y - expected)) <= 1e-12 * np.max(np.abs(expected))


NOT_TRANSLATES = {
    "tilted": dict(u=(0.8 * math.cos(0.5), 0.0, 0.8 * math.sin(0.5)), v=(0.0, -0.8, 0.0), center=(0.1, 0.2, 1.2)),
    "turned about the wall's normal": dict(u=(math.cos(0.3), math.sin(0.3), 0.0), v=(math.sin(0.3), -math.cos(0.3), 0.0)),
    "a pitch of 0.3 pixels": dict(pixels=8, grid=(13, 13)),
}


@pytest.mark.parametrize("case", list(NOT_TRANSLATES))
def test_pairs_that_are_not_translates_keep_the_general_route(case):
    assert _plan(_scene(**NOT_TRANSLATES[case])) is None


def test_a_single_scan_or_counted_legs_keep_the_general_route():
    assert _plan(_scene(pixels=8, grid=(8, 8)).replace(scan=Scan(type="single", grid=(8, 8)))) is None
    legs = Scan(type="confocal", grid=(8, 8), account_first_and_last_bounces=True)
    assert _plan(_scene(pixels=8, grid=(8, 8)).replace(scan=legs)) is None


def test_y_made_a_block_of_pairs_at_a_time_equals_a_f():
    scene = _scene(grid=(6, 6), **NOT_TRANSLATES["tilted"])
    matrix = system_matrix(scene)
    expected = (matrix @ scene.reflectance.ravel()).reshape(scene.sensor_count, -1)
    route, cost = forward_route(scene)
    assert route == "matrix"
    limit = int(cost.memory / 1.2)            # A would not fit: blocks of about a fifth of the pairs
    assert forward_route(scene, memory_limit=limit)[0] == "blocks"
    y = forward(scene, memory_limit=limit, statistics=(statistics := {}))
    assert statistics["route"] == "blocks" and 1 <= statistics["block_pairs"] < scene.sensor_count
    assert statistics["nonzeros"] == matrix.nnz
    assert np.max(np.abs(y - expected)) <= 1e-13 * np.max(np.abs(expected))
