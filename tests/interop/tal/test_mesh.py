"""OBJ meshes of tal configurations read as planar polygons: the values that must be refused in one line.

Finite-but-huge and tiny coordinates (issue 38) and coordinates that are no finite number are refused
naming the file's key, before any area or normal is formed (an area of a 1e300 m square overflows, one of
a 1e-300 m square underflows); an ordinary square still gives its own corners back.
"""

import warnings

import numpy as np
import pytest

from analytic.errors import SceneError
from interop.tal.mesh import planar_polygon, read_obj

KEY = "geometry[m].mesh.filename"
SQUARE = "v -{s} -{s} 0\nv {s} -{s} 0\nv {s} {s} 0\nv -{s} {s} 0\nf 1 2 3 4\n"


def _polygon(tmp_path, text, scale=1.0):
    path = tmp_path / "m.obj"
    path.write_text(text)
    vertices, faces, normals = read_obj(path, KEY)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(over="ignore"):       # what tal_config does: a transform beyond float64 gives inf
            world = vertices * scale
        return planar_polygon(world, faces, normals, KEY, "m.obj")


def test_a_square_gives_its_corners(tmp_path):
    corner, u, v, _ = _polygon(tmp_path, SQUARE.format(s=0.5))
    assert sorted(np.abs(np.cross(u, v))) == pytest.approx([0, 0, 1.0])
    np.testing.assert_allclose(sorted([corner[0], (corner + u + v)[0]]), [-0.5, 0.5], atol=1e-15)


@pytest.mark.parametrize("text, scale, message", [
    (SQUARE.format(s="1e300"), 1.0, "a vertex at 1e+300 m is beyond"),
    (SQUARE.format(s="1e160"), 1.0, "a vertex at 1e+160 m is beyond"),       # its area, 4e320, overflows
    (SQUARE.format(s="1e13"), 1.0, "is beyond the ±1e+12 m"),
    ("v -1e300 -1 0\nv 1e300 -1 0\nv 1e300 1 0\nv -1e300 1 0\nf 1 2 3 4\n", 1.0, "is beyond"),
    (SQUARE.format(s=1), 1e300, "is beyond"),
    (SQUARE.format(s="1e200"), 1e200, "is beyond"),                          # the transform itself overflows
    (SQUARE.format(s="1e-300"), 1.0, "its extent, 2e-300 m, is below the smallest length supported"),
    (SQUARE.format(s=1), 1e-200, "is below the smallest length supported"),
], ids=["1e300", "1e160", "1e13", "one-side-1e300", "scaled-1e300", "scaled-overflow", "1e-300", "scaled-1e-200"])
def test_huge_and_tiny_meshes_are_refused_naming_the_file(tmp_path, text, scale, message):
    with pytest.raises(SceneError) as caught:
        _polygon(tmp_path, text, scale)
    assert caught.value.key == KEY and message in str(caught.value) and "\n" not in str(caught.value)


@pytest.mark.parametrize("value", ["inf", "-inf", "nan", "1e400"])
def test_a_coordinate_that_is_no_finite_number_is_a_malformed_record(tmp_path, value):
    path = tmp_path / "m.obj"
    path.write_text(SQUARE.format(s=1).replace("v 1 1 0", f"v 1 {value} 0"))
    with pytest.raises(SceneError, match="line 3: not a valid OBJ v record"):
        read_obj(path, KEY)
    path.write_text(SQUARE.format(s=1) + f"vn 0 0 {value}\n")
    with pytest.raises(SceneError, match="line 6: not a valid OBJ vn record"):
        read_obj(path, KEY)


def test_a_byte_order_mark_does_not_hide_the_first_vertex(tmp_path):
    plain = tmp_path / "plain.obj"
    plain.write_text(SQUARE.format(s=0.5))
    marked = tmp_path / "marked.obj"
    marked.write_text("\ufeff" + SQUARE.format(s=0.5), encoding="utf-8")
    for got, expected in zip(read_obj(marked, KEY), read_obj(plain, KEY)):
        np.testing.assert_array_equal(np.asarray(got, dtype=object), np.asarray(expected, dtype=object))
