"""A non-rectangular planar polygon in a tal configuration: its bounding rectangle with the polygon's
indicator image as the reflectance, exact when its sides lie on the pixel grid; refused otherwise.

The expected values are built here without interop.tal.mesh: the L's pose by SciPy's extrinsic x-y-z
rotation (tal's T Rz Ry Rx S), its indicator by mapping each pixel centre back into the OBJ's own
coordinates, and, independently of any indicator, as the sum of the two rectangles the L is made of,
each its own RelayWallScene.
"""

import warnings

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

import analytic
from analytic.scenes.relay_wall import RelayWallScene
from analytic.scenes.scene_file import load_scene
from interop.tal.config import TalConfigWarning
from validation.cli import main

# an L in the OBJ's plane z = 0, lit side +z (counter-clockwise), as four triangles from (0, 0)
L_OBJ = ("v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\n"
         "f 1 2 3\nf 1 3 4\nf 1 4 5\nf 1 5 6\n")
SCALE, ANGLES, SHIFT = 0.25, (180.0, 0.0, 30.0), (0.15, -0.1, 1.0)
CONFIG = {
    "name": "ell", "integrator_filter_bounces": 2, "num_bins": 90, "bin_width_opl": 0.02, "start_opl": 2.3,
    "scan_type": "single", "sensor_width": 4, "sensor_height": 4, "laser_lookat_x": 1, "laser_lookat_y": 3,
    "geometry": [
        {"name": "ell", "mesh": {"type": "obj", "filename": "ell.obj"}, "scale_x": SCALE, "scale_y": SCALE,
         "scale_z": SCALE, "rot_degrees_x": ANGLES[0], "rot_degrees_z": ANGLES[2],
         "displacement_x": SHIFT[0], "displacement_y": SHIFT[1], "displacement_z": SHIFT[2],
         "material": {"id": "white"}},
        {"name": "relay_wall", "mesh": {"type": "rectangle"}, "displacement_x": 0.0, "displacement_y": 0.0,
         "displacement_z": 0.0, "scale_x": 1, "scale_y": 1, "material": {"id": "white"}}],
    "relay_wall": "relay_wall", "diffuse_imaging": {"pixels": 4},
}
ROTATION = Rotation.from_euler("xyz", ANGLES, degrees=True)


def to_world(local):
    return ROTATION.apply(SCALE * np.asarray(local, dtype=float)) + SHIFT


def inside_ell(local):
    x, y = local[..., 0], local[..., 1]
    return ((0 < x) & (x < 2) & (0 < y) & (y < 1)) | ((0 < x) & (x < 1) & (0 < y) & (y < 2))


def write(tmp_path, obj_text, **ours):
    (tmp_path / "ell.obj").write_text(obj_text)
    config = {**CONFIG, "diffuse_imaging": {**CONFIG["diffuse_imaging"], **ours}}
    (tmp_path / "ell.yaml").write_text(yaml.safe_dump(config))
    return tmp_path / "ell.yaml"


def rectangle_scene(scene, corner_local, u_local, v_local):
    """A uniform white rectangle of the L's plane (OBJ coordinates), with the L scene's wall, scan and bins."""
    corner = to_world(corner_local)
    u = to_world(np.add(corner_local, u_local)) - corner
    v = to_world(np.add(corner_local, v_local)) - corner
    return RelayWallScene(wall_size=scene.wall_size, wall_reflectance=scene.wall_reflectance,
                          center=corner + 0.5 * (u + v), u=u, v=v, pixels=2, reflectance=1.0,
                          laser_position=scene.laser_position, sensor_position=scene.sensor_position,
                          intensity=scene.intensity, scan=scene.scan, sampling=scene.sampling,
                          tolerance=scene.tolerance)


def test_an_L_is_its_bounding_rectangle_times_its_indicator(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)                          # tal resolves the OBJ against the working directory
    scene_file = write(tmp_path, L_OBJ)
    out = tmp_path / "out"
    assert main(["forward", str(scene_file), "--out", str(out), "--quiet"]) == 0
    y = np.load(out / "transient.npy")
    with warnings.catch_warnings():
        warnings.simplefilter("error", TalConfigWarning)
        scene = load_scene(scene_file)
    # the bounding rectangle is the L's [0, 2]² box, posed as tal poses it
    box = np.array([to_world(c) for c in ([0, 0, 0], [2, 0, 0], [0, 2, 0], [2, 2, 0])])
    np.testing.assert_allclose(np.sort(scene.rectangle().corners(), axis=0), np.sort(box, axis=0), atol=1e-12)
    # pixel centres, mapped back into the OBJ's coordinates: inside the L or not
    m = scene.pixels
    rows, cols = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    corner = scene.center - 0.5 * (scene.u + scene.v)
    centres = (corner + ((cols + 0.5) / m)[..., None] * scene.u + ((m - rows - 0.5) / m)[..., None] * scene.v)
    local = ROTATION.inv().apply((centres - SHIFT).reshape(-1, 3)).reshape(m, m, 3) / SCALE
    indicator = inside_ell(local).astype(float)
    assert indicator.sum() == 12                         # three of the four 2 x 2 quarters
    expected = analytic.forward(scene.replace(reflectance=indicator))
    np.testing.assert_allclose(y, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    # independently of any indicator: the L is the rectangles [0, 2] x [0, 1] and [0, 1] x [1, 2]
    lower = rectangle_scene(scene, [0, 0, 0], [2, 0, 0], [0, 1, 0])
    upper = rectangle_scene(scene, [0, 1, 0], [1, 0, 0], [0, 1, 0])
    both = analytic.forward(lower) + analytic.forward(upper)
    assert np.abs(y).max() > 0 and np.abs(both).max() > 0
    np.testing.assert_allclose(y, both, rtol=0, atol=1e-5 * np.abs(both).max())
    # and deliberately wrong images (the whole box; the L turned over) are far from it
    for wrong in (np.ones((m, m)), indicator[::-1], indicator.T):
        error = np.abs(analytic.forward(scene.replace(reflectance=wrong)) - both).max() / np.abs(both).max()
        assert error > 0.01, error


@pytest.mark.parametrize("obj, ours, words", [
    ("v 0 0 0\nv 2 0 0\nv 0 2 0\nf 1 2 3\n", {}, "runs at 45 degrees to its longest side"),
    (L_OBJ, {"pixels": 3}, "do not lie on the 3 x 3 pixel grid of its bounding rectangle "
                           "(0.5 x 0.5 m), so its indicator image would not be exact; choose "
                           "diffuse_imaging.pixels so that they do (e.g. 2, 4, 6), or use a rectangle"),
    ("v 0 0 0\nv 2 0 0\nv 2 0.9 0\nv 1 0.9 0\nv 1 2 0\nv 0 2 0\nf 1 2 3\nf 1 3 4\nf 1 4 5\nf 1 5 6\n", {},
     "do not lie on the 4 x 4 pixel grid"),
])
def test_a_polygon_off_the_grid_is_refused_in_one_line_before_any_file(tmp_path, monkeypatch, capsys, obj, ours,
                                                                       words):
    monkeypatch.chdir(tmp_path)
    scene_file = write(tmp_path, obj, **ours)
    out = tmp_path / "out"
    assert main(["forward", str(scene_file), "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("diffuse-imaging: error: geometry[ell].mesh.filename: ell.obj: "), lines[0]
    assert words in lines[0], lines[0]
    assert not out.exists()
