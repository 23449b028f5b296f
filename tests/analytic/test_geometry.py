"""The rectangle-and-pairs geometry: the plane is one instance, and the model does not care where it sits."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from analytic.errors import SceneError
from analytic.geometry import PointPairs, Rectangle, pair_table, plane_geometry
from analytic.scenes.common import Sampling, default_scene
from analytic.operator.system import rectangle_matrix, system_matrix
from analytic.waveforms import make_waveform
from validation.runs.suite import hard_cases


def _moved(scene, matrix, shift):
    """The scene's rectangle and pairs carried rigidly by a rotation matrix and a shift (metres)."""
    rectangle, pairs = plane_geometry(scene)

    def move(points):
        return np.asarray(points) @ matrix.T + shift

    moved = Rectangle(move(rectangle.corner), rectangle.u @ matrix.T, rectangle.v @ matrix.T, rectangle.pixels)
    return moved, PointPairs(move(pairs.sources), move(pairs.sensors), scales=pairs.scales,
                             attenuation=pairs.attenuation)


HARD = ["low", "grazing", "outside", "first_arrival", "colocated"]


@pytest.mark.parametrize("name", HARD)
@pytest.mark.parametrize("waveform", ["impulse", "butterworth"])
def test_a_plane_moved_exactly_gives_the_same_matrix(name, waveform):
    """Quarter turns about the origin carry every coordinate exactly: A is the same to its last bits."""
    scene = hard_cases(pixels=6, waveform=waveform)[name]
    reference = system_matrix(scene).toarray()
    for rotation in (Rotation.from_euler("xyz", [90, 180, -90], degrees=True), Rotation.from_euler("z", 90,
                                                                                                   degrees=True)):
        quarter_turns = np.round(rotation.as_matrix())        # entries exactly 0 and ±1
        rectangle, pairs = _moved(scene, quarter_turns, np.zeros(3))
        moved = rectangle_matrix(rectangle, pairs, scene.sampling,
                                 make_waveform(scene.illumination, scene.sampling.bin_width_opl)).toarray()
        np.testing.assert_allclose(moved, reference, rtol=1e-15, atol=0)


@pytest.mark.parametrize("name", HARD)
@pytest.mark.parametrize("waveform", ["impulse", "butterworth"])
def test_a_plane_moved_anywhere_gives_the_same_matrix(name, waveform, rng):
    """Turned and shifted anywhere, every entry of A stays within the tolerance of itself.

    The moved coordinates differ by their rounding (1e-16 of a few metres), so the two matrices are
    models of slightly different inputs, each within the tolerance of its own exact value; entries that
    the rounding moves across a bin edge (slivers, under 1e-12 of their row) or that sit just after the
    first arrival (whose value changes fastest with the geometry) stay within that too. A sliver is
    bounded by the largest entry, as a row the exact geometry leaves empty may hold one.
    """
    scene = hard_cases(pixels=6, waveform=waveform)[name]
    reference = system_matrix(scene).toarray()
    rectangle, pairs = _moved(scene, Rotation.from_rotvec(rng.normal(size=3)).as_matrix(), rng.uniform(-3, 3, 3))
    moved = rectangle_matrix(rectangle, pairs, scene.sampling,
                             make_waveform(scene.illumination, scene.sampling.bin_width_opl)).toarray()
    largest = np.abs(reference).max()
    assert np.all(np.abs(moved - reference) <= 2 * scene.tolerance * np.abs(reference) + 1e-12 * largest)


def test_an_added_path_length_of_whole_bins_shifts_the_rows():
    """A pair whose paths carry 3 bins' more length reads the plain pair's bins 3 later."""
    scene = default_scene(pixels=8)
    rectangle, pairs = plane_geometry(scene)
    period = scene.sampling.bin_width_opl
    longer = PointPairs(pairs.sources, pairs.sensors, offsets=np.full(len(pairs), 3 * period),
                        scales=pairs.scales)
    sampling = Sampling(bin_width_opl=period, start_opl=scene.sampling.start_opl, count=scene.sampling.count + 3)
    waveform = make_waveform(scene.illumination, period)
    plain = rectangle_matrix(rectangle, pairs, sampling, waveform).toarray().reshape(len(pairs), sampling.count, -1)
    shifted = rectangle_matrix(rectangle, longer, sampling, waveform).toarray().reshape(len(pairs),
                                                                                         sampling.count, -1)
    scale = np.abs(plain).max()
    np.testing.assert_allclose(shifted[:, 3:], plain[:, :-3], rtol=0, atol=1e-12 * scale)
    assert np.all(shifted[:, :3] == 0)


def test_points_behind_the_lit_face_or_ends_facing_away_are_refused():
    scene = default_scene(pixels=4)
    rectangle, pairs = plane_geometry(scene)
    below = PointPairs(pairs.sources * np.array([1, 1, -1]), pairs.sensors)
    with pytest.raises(SceneError, match="not in front"):
        pair_table(rectangle, below)
    # a wall point whose normal points away from part of the rectangle cannot light it
    facing = PointPairs([[0.5, 0.5, 1.0]], [[0.5, 0.5, 1.0]], source_normals=[[1.0, 0.0, 0.0]])
    with pytest.raises(SceneError, match="behind"):
        pair_table(rectangle, facing)


def test_edges_must_be_orthogonal():
    with pytest.raises(ValueError, match="orthogonal"):
        Rectangle(np.zeros(3), [1.0, 0.0, 0.0], [0.5, 1.0, 0.0], 4)
