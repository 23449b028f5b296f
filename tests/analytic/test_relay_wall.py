"""Captures through a relay wall: the third bounce against an independent quadrature of docs/design.md section 7.

The reference (tests/relay_wall_reference.py) writes the formula out again in
world coordinates (its own frame of the hidden rectangle, its own cosines at
the wall and on the hidden plane) and integrates it with tests/reference.py's
nested QUADPACK, which shares nothing with the model.
"""

import math

import numpy as np
import pytest
from relay_wall_reference import pixel_region, reference_bin

from analytic.errors import SceneError
from analytic.scenes.relay_wall import RelayWallScene, Scan, grid_points
from analytic.scenes.common import Illumination, Sampling
from analytic.operator.system import system_matrix
from analytic.operator.window import pairs_range

TOLERANCE = 1e-6


def _reference_entry(scene, pair, pixel, n):
    """A[(pair, n), pixel]: H(l, s)[n] of one hidden pixel of unit reflectance, by nested QUADPACK."""
    return reference_bin(scene, pair, n, pixel_region(scene, pixel))


def _covering(scene, count=40):
    """The scene with bins covering every pair's light (plus the pulse)."""
    low, high = pairs_range(*scene.geometry())
    period = (high - low) * 1.05 / (count - 2)
    return scene.replace(sampling=Sampling(bin_width_opl=period, start_opl=low - period, count=count))


POSES = {
    "facing": dict(),
    "tilted": dict(u=(0.8 * math.cos(0.5), 0.0, 0.8 * math.sin(0.5)), v=(0.0, -0.8, 0.0), center=(0.1, 0.2, 1.2)),
    "grazing": dict(center=(1.6, 0.0, 0.6), u=(0.0, 0.0, 0.6), v=(0.0, 0.6, 0.0)),
    "near the wall": dict(center=(0.2, -0.1, 0.04), u=(0.1, 0.0, 0.0), v=(0.0, -0.1, 0.0)),
    "far": dict(center=(0.0, 0.0, 40.0), u=(3.0, 0.0, 0.0), v=(0.0, -3.0, 0.0)),
    "tiny": dict(center=(0.3, 0.2, 0.8), u=(1e-3, 0.0, 0.0), v=(0.0, -1e-3, 0.0)),
}


def _scene(pose, scan=Scan(type="single", grid=(3, 2), laser_point=(0.5, -0.5, 0.0)), pixels=4, **changes):
    image = np.arange(pixels * pixels, dtype=float).reshape(pixels, pixels) / (pixels * pixels)   # asymmetric
    scene = RelayWallScene(pixels=pixels, reflectance=image, scan=scan, wall_reflectance=0.8, intensity=3.0,
                           **POSES[pose], **changes)
    return _covering(scene)


def _check_entries(scene, rng, picks=3):
    matrix = system_matrix(scene).tocsr()
    row_max = abs(matrix).max(axis=1).toarray().ravel()
    coo = matrix.tocoo()
    chosen = [int(np.argmax(np.abs(coo.data)))] + list(rng.choice(coo.nnz, size=picks - 1, replace=False))
    count = scene.sampling.count
    for i in chosen:
        row, pixel = int(coo.row[i]), int(coo.col[i])
        pair, n = divmod(row, count)
        reference = _reference_entry(scene, pair, pixel, n)
        assert abs(coo.data[i] - reference) <= TOLERANCE * row_max[row], (pair, pixel, n, coo.data[i], reference)


@pytest.mark.parametrize("pose", list(POSES))
def test_single_scan_entries_match_the_reference(pose, rng):
    _check_entries(_scene(pose), rng)


@pytest.mark.slow      # 13 s; confocal pairs are also held to the model by tests/transient/test_nlos.py
def test_confocal_pairs_with_l_equal_s_match_the_reference(rng):
    _check_entries(_scene("tilted", scan=Scan(type="confocal", grid=(2, 2))), rng)


def test_exhaustive_pairs_with_both_legs_counted_match_the_reference(rng):
    scan = Scan(type="exhaustive", grid=(2, 1), laser_grid=(1, 2), account_first_and_last_bounces=True)
    _check_entries(_scene("facing", scan=scan, illumination=Illumination(waveform="butterworth", order=2)), rng)


def test_pairs_follow_the_documented_order():
    """Grid cell (row j, column i) at ((2i+1)/W - 1, (2j+1)/H - 1) x half sizes, row-major, laser-major."""
    points = grid_points((3, 2), (2.0, 4.0))
    np.testing.assert_allclose(points[1], [0.0, -1.0, 0.0])            # i = 1, j = 0
    np.testing.assert_allclose(points[3], [-2 / 3, 1.0, 0.0])           # i = 0, j = 1
    scene = RelayWallScene(wall_size=(2.0, 4.0), scan=Scan(type="exhaustive", grid=(3, 2), laser_grid=(2, 1)))
    lit, read = scene.pair_points
    assert scene.sensor_count == 12
    np.testing.assert_allclose(lit[7], grid_points((2, 1), (2.0, 4.0))[1])   # laser 1 of the second block
    np.testing.assert_allclose(read[7], points[1])


def test_total_light_is_linear_in_the_laser_and_the_reflectances():
    base = _scene("facing")
    doubled = base.replace(intensity=2 * base.intensity, wall_reflectance=0.5 * base.wall_reflectance)
    y, y2 = (system_matrix(s) @ s.reflectance.ravel() for s in (base, doubled))
    np.testing.assert_allclose(y2, 0.5 * y, rtol=1e-14)


@pytest.mark.parametrize("changes, key", [
    (dict(center=(0.0, 0.0, 0.3), u=(0.0, 0.0, 1.0), v=(0.0, 1.0, 0.0)), "hidden.center"),   # crosses the wall
    (dict(u=(1.0, 0.0, 0.0), v=(0.0, 1.0, 0.0)), "hidden.u"),                                # faces away
    (dict(v=(0.5, -1.0, 0.0)), "hidden.v"),                                                  # not orthogonal
    (dict(center=(0.0, 0.0, -1.0)), "hidden.center"),                                        # behind the wall
    (dict(laser_position=(0.0, 0.0, 0.0)), "laser.position"),
    (dict(scan=Scan(type="single", laser_point=(2.0, 0.0, 0.0))), "scan.laser_point"),
])
def test_impossible_captures_are_refused_in_one_line(changes, key):
    with pytest.raises(SceneError) as caught:
        RelayWallScene(**changes)
    assert caught.value.key == key and "\n" not in str(caught.value)


def test_scan_options_of_another_type_are_refused():
    with pytest.raises(SceneError, match="scan.laser_grid"):
        Scan(type="single", laser_grid=(2, 2))
    with pytest.raises(SceneError, match="scan.laser_point"):
        Scan(type="confocal", laser_point=(0.0, 0.0, 0.0))


def _crosses(start, end, rectangle):
    """Does the segment start -> end meet the rectangle? Solved as corner + a u + b v = start + t (end - start)."""
    matrix = np.column_stack([rectangle.u, rectangle.v, start - end])
    if abs(np.linalg.det(matrix)) < 1e-12:
        return False
    a, b, t = np.linalg.solve(matrix, start - rectangle.corner)
    return 0 < t < 1 and 0 <= a <= 1 and 0 <= b <= 1


def test_blocked_lines_agree_with_a_linear_solve(rng):
    scene = RelayWallScene(center=(0.1, -0.2, 1.0), u=(0.9, 0.0, 0.3), v=(0.0, -0.7, 0.0))
    rectangle = scene.rectangle()
    for _ in range(200):
        start = rng.uniform([-1.5, -1.5, 0.05], [1.5, 1.5, 2.5])
        ends = np.column_stack([rng.uniform(-1, 1, (8, 2)), np.zeros(8)])
        expected = [_crosses(start, end, rectangle) for end in ends]
        assert scene.blocked(start, ends).tolist() == expected


BLOCKING = [   # (changes, whose line): the default 1 m square at z = 1 between the wall and the laser or sensor
    (dict(laser_position=(0.0, 0.0, 2.0)), "laser"),
    (dict(sensor_position=(0.1, 0.1, 1.5)), "sensor"),
    (dict(laser_position=(0.0, 0.0, 2.0), scan=Scan(type="confocal", grid=(4, 4))), "laser"),
    (dict(sensor_position=(0.0, 0.0, 2.0), scan=Scan(type="confocal", grid=(4, 4))), "sensor"),
    # partly blocked: only the lit points near the wall's corner (-1, -1) hide behind a small square
    (dict(center=(-0.7, -0.7, 0.3), u=(0.2, 0.0, 0.0), v=(0.0, -0.2, 0.0), laser_position=(-1.4, -1.4, 0.9),
          scan=Scan(type="exhaustive", grid=(2, 2), laser_grid=(4, 4))), "laser"),
    (dict(center=(-0.7, -0.7, 0.3), u=(0.2, 0.0, 0.0), v=(0.0, -0.2, 0.0), sensor_position=(-1.4, -1.4, 0.9),
          scan=Scan(type="exhaustive", grid=(4, 4), laser_grid=(2, 2))), "sensor"),
]


@pytest.mark.parametrize("changes, who", BLOCKING)
def test_a_line_the_hidden_rectangle_blocks_is_refused_in_one_line(changes, who):
    # the model counts only the third bounce through clear lines: a blocked pair has no light in any renderer
    with pytest.raises(SceneError) as caught:
        RelayWallScene(**changes)
    assert caught.value.key == "hidden.center" and f"blocks the {who}'s line" in str(caught.value)
    assert "\n" not in str(caught.value)
    moved = dict(changes, **{f"{who}_position": (-1.9, 1.9, 0.2)})      # beside it, the same scan is accepted
    RelayWallScene(**moved)


@pytest.mark.parametrize("changes, key, shown", [
    (dict(u=(1e-300, 0.0, 0.0)), "hidden.u", "1e-300 m"),                 # not "must be non-zero": |u| underflowed
    (dict(v=(0.0, -1e-170, 0.0)), "hidden.v", "1e-170 m"),
    (dict(u=(3e-10, 4e-10, 0.0), v=(-4e-10, 3e-10, 0.0)), "hidden.u", "5e-10 m"),
    (dict(u=(0.0, 0.0, 0.0)), "hidden.u", "0 (the edge vector must be non-zero)"),
])
def test_a_side_below_the_smallest_length_is_refused_with_its_length(changes, key, shown):
    with pytest.raises(SceneError) as caught:
        RelayWallScene(**changes)
    assert caught.value.key == key and shown in str(caught.value) and "smallest length supported" in str(caught.value)
