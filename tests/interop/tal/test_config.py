"""tal render configurations (YAML) read as the scene tal renders: every key's meaning, and the refusals.

The expected poses are built here independently of interop.tal.config: the
transform by SciPy's extrinsic x-y-z Euler rotation (Rz Ry Rx), the grid
and lookat points from tal's formulas written out.
"""

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from analytic.errors import SceneError
from analytic.scenes.scene_file import load_scene
from interop.tal.config import TalConfigWarning, TalScene, load_tal_config, tal_config_scene

EXAMPLES = Path(__file__).resolve().parents[3] / "examples" / "tal"

WALL = {"name": "relay_wall", "mesh": {"type": "rectangle"}, "displacement_x": 0.0, "displacement_y": 0.0,
        "displacement_z": 0.0, "scale_x": 1, "scale_y": 1, "material": {"id": "white"}}


def config(hidden=None, **keys):
    """A small tal configuration: a 1 m square facing the wall 1 m away, a 4 x 4 single scan."""
    hidden = hidden or {"name": "plane", "mesh": {"type": "rectangle"}, "scale_x": 0.5, "scale_y": 0.5,
                        "rot_degrees_x": 180.0, "displacement_z": 1.0, "material": {"id": "white"}}
    base = {"name": "t", "integrator_filter_bounces": 2, "num_bins": 100, "bin_width_opl": 0.02,
            "start_opl": 1.9, "sensor_width": 4, "sensor_height": 4, "geometry": [hidden, WALL],
            "relay_wall": "relay_wall"}
    return {**base, **keys}


def scene_of(data, tmp_path=None, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("error", TalConfigWarning)
        return tal_config_scene(data, cwd=tmp_path, **kwargs)


def refusal(data, key, tmp_path=None):
    with pytest.raises(SceneError) as caught:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", TalConfigWarning)
            tal_config_scene(data, cwd=tmp_path)
    assert caught.value.key == key, str(caught.value)
    assert "\n" not in str(caught.value)
    return str(caught.value)


def test_example_is_what_tal_renders():
    scene = load_scene(EXAMPLES / "plane-single.yaml")           # dispatch by extension
    assert isinstance(scene, TalScene) and scene.name == "plane-single"
    np.testing.assert_allclose(scene.center, [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(scene.u, [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(scene.v, [0, -1, 0], atol=1e-15)
    np.testing.assert_allclose(scene.rectangle().normal, [0, 0, -1], atol=1e-15)   # toward the wall
    assert scene.wall_size == (2.0, 2.0) and scene.wall_reflectance == 1.0 and scene.reflectance.max() == 1.0
    assert scene.intensity == pytest.approx(3 * math.pi)         # π E per channel, three channels summed
    assert (scene.scan.type, scene.scan.grid) == ("single", (16, 16))
    np.testing.assert_array_equal(scene.scan.laser_point, [0, 0, 0])
    assert (scene.sampling.count, scene.sampling.bin_width_opl, scene.sampling.start_opl) == (520, 0.003, 1.95)
    np.testing.assert_array_equal(scene.laser_position, [-0.5, 0, 0.25])     # tal's defaults
    np.testing.assert_array_equal(scene.sensor_position, [-0.5, 0, 0.25])


@pytest.mark.parametrize("angles", [(0.0, 0.0, 0.0), (200.0, 10.0, -30.0), (170.0, -25.0, 60.0)])
def test_transform_is_T_Rz_Ry_Rx_S(angles):
    scale = (0.3, 0.2, 2.0)
    shift = (0.1, -0.2, 1.5)
    hidden = {"name": "p", "mesh": {"type": "rectangle"}, "material": {"id": "white"},
              **{f"scale_{a}": s for a, s in zip("xyz", scale)},
              **{f"rot_degrees_{a}": t for a, t in zip("xyz", angles)},
              **{f"displacement_{a}": d for a, d in zip("xyz", shift)}}
    matrix = Rotation.from_euler("xyz", angles, degrees=True).as_matrix() @ np.diag(scale)
    normal = Rotation.from_euler("xyz", angles, degrees=True).apply([0, 0, 1])
    data = config(hidden)
    if normal[2] >= 0:                        # faces away: tal renders it black, refused
        refusal(data, "geometry[p]")
        return
    scene = scene_of(data)
    np.testing.assert_allclose(scene.center, shift, atol=1e-14)
    np.testing.assert_allclose(scene.u, matrix @ [2, 0, 0], atol=1e-14)
    np.testing.assert_allclose(scene.v, matrix @ [0, 2, 0], atol=1e-14)
    np.testing.assert_allclose(scene.rectangle().normal, normal, atol=1e-14)


def test_zero_scale_counts_as_one_and_lookat_zero_as_unset():
    hidden = {"name": "p", "mesh": {"type": "rectangle"}, "scale_x": 0, "scale_y": 0.5, "rot_degrees_x": 180,
              "displacement_z": 1.0, "material": {"id": "white"}}
    scene = scene_of(config(hidden, laser_lookat_x=0, laser_lookat_y=3))
    assert np.linalg.norm(scene.u) == pytest.approx(2.0)          # tal's `scale_x or 1.0`
    # lookat 0 is unset (the wall's centre, x = 0); y = 3 of 4 pixels: uv 0.75 -> y = 2 0.75 - 1
    np.testing.assert_allclose(scene.scan.laser_point, [0.0, 0.5, 0.0])


def test_scans_and_grids():
    scene = scene_of(config(scan_type="exhaustive", laser_width=2, laser_height=3))
    assert scene.scan.laser_grid == (2, 3) and scene.sensor_count == 4 * 4 * 2 * 3
    np.testing.assert_allclose(scene.laser_points[:, :2], [[x, y] for y in (-2 / 3, 0, 2 / 3) for x in (-0.5, 0.5)])
    confocal = scene_of(config(scan_type="confocal", laser_width=4, laser_height=4))
    assert confocal.scan.type == "confocal"
    assert "tal refuses" in refusal(config(scan_type="confocal"), "laser_width")   # default laser grid 32 x 32
    wide = {**WALL, "scale_x": 1.5, "scale_y": 0.5}
    scene = scene_of(config(geometry=[config()["geometry"][0], wide]))
    assert scene.wall_size == (3.0, 1.0)
    np.testing.assert_allclose(scene.read_points[0], [-1.125, -0.375, 0.0])         # tal's get_grid_xyz


def test_obj_rectangle_two_triangles_and_refusals(tmp_path):
    quad = "v 1 -1 0\nv -1 -1 0\nv 1 1 0\nv -1 1 0\nvn 0 0 -1\nf 1//1 2//1 4//1 3//1\n"
    (tmp_path / "quad.obj").write_text(quad)
    (tmp_path / "tri.obj").write_text("v 1 -1 0\nv -1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 4\nf 1 4 3\n")
    hidden = {"name": "w", "mesh": {"type": "obj", "filename": "quad.obj"}, "displacement_z": 1.0,
              "scale_x": 0.5, "scale_y": 0.25, "material": {"id": "white"}}
    scene = scene_of(config(hidden), tmp_path)
    np.testing.assert_allclose(scene.center, [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(scene.u, [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(scene.v, [0, -0.5, 0], atol=1e-15)
    split = scene_of(config({**hidden, "mesh": {"type": "obj", "filename": "tri.obj"}}), tmp_path)
    for name in ("center", "u", "v"):
        np.testing.assert_allclose(getattr(split, name), getattr(scene, name), atol=1e-15)
    refused = {
        # a Z-like polygon: slanted sides, no exact indicator image
        "ell.obj": "v 0 0 0\nv -1 0 0\nv -1 -1 0\nv 0 -2 0\nv 0 -1 0\nv -2 -2 0\nf 1 2 5\nf 2 3 5\nf 3 6 4\nf 3 4 5\n",
        "bent.obj": "v 1 -1 0\nv -1 -1 0\nv 1 1 0\nv -1 1 0.3\nf 1 2 4\nf 1 4 3\n",          # not coplanar
        "gap.obj": "v 1 -1 0\nv -1 -1 0\nv 1 1 0\nv -1 1 0\nv 0 0 0\nf 1 2 5\nf 2 4 5\nf 4 3 5\n",  # a hole
        "tee.obj": "v 1 -1 0\nv -1 -1 0\nv 1 1 0\nv -1 1 0\nv 0 -1 0\nf 1 5 3\nf 5 2 4\nf 5 4 3\nf 1 2 4\n",
        "flip.obj": "v 1 -1 0\nv -1 -1 0\nv 1 1 0\nv -1 1 0\nvn 0 0 1\nf 1//1 2//1 4//1 3//1\n",  # vn vs winding
    }
    for name, text in refused.items():
        (tmp_path / name).write_text(text)
        message = refusal(config({**hidden, "mesh": {"type": "obj", "filename": name}}), "geometry[w].mesh.filename",
                          tmp_path)
        assert name in message
    assert "working directory" in refusal(config({**hidden, "mesh": {"type": "obj", "filename": "none.obj"}}),
                                          "geometry[w].mesh.filename", tmp_path)


def test_notched_rectangle_is_its_box_with_the_notch_left_out(tmp_path):
    # [0, 4] x [0, 2] less the notch [1, 2] x [1, 2], as three convex faces whose shared sides are split
    # differently (the outline keeps collinear pieces)
    vertices = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nv 2 0 0\nv 2 1 0\nv 4 0 0\nv 4 2 0\nv 2 2 0\n"
    (tmp_path / "notch.obj").write_text(vertices + "f 1 2 3 4 5\nf 2 6 7 3\nf 6 8 9 10 7\n")
    # the same as one non-convex face: its fan from (0, 0) has a triangle turned over, refused
    (tmp_path / "fan.obj").write_text(vertices + "f 1 8 9 10 7 3 4 5\n")
    hidden = {"name": "n", "mesh": {"type": "obj", "filename": "notch.obj"}, "rot_degrees_x": 180.0,
              "scale_x": 0.25, "scale_y": 0.25, "displacement_x": -0.5, "displacement_y": 0.25,
              "displacement_z": 1.0, "material": {"id": "white"}}
    scene = scene_of(config(hidden, diffuse_imaging={"pixels": 4}), tmp_path)
    # x -> x, y -> -y: the box [-0.5, 0.5] x [-0.25, 0.25], u along +x, v along -y (its rows run top to bottom
    # in -y, so row 0 is at y = -0.25 where the notch, local y in [1, 2], lies)
    np.testing.assert_allclose(scene.center, [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(scene.u, [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(scene.v, [0, -0.5, 0], atol=1e-15)
    expected = np.ones((4, 4))
    expected[:2, 1] = 0.0                      # local x in [1, 2]: column 1 of 4; local y in [1, 2]: rows 0-1
    np.testing.assert_array_equal(scene.reflectance, expected)
    message = refusal(config(hidden, diffuse_imaging={"pixels": 6}), "geometry[n].mesh.filename", tmp_path)
    assert "e.g. 4, 8, 12" in message
    # the faces as fans of triangles, each with its own copies of its vertices (as Blender's exporter writes
    # them): the diagonals inside cancel only when equal positions count as one vertex
    rows = [line.split()[1:] for line in vertices.splitlines()]
    triangles = [(face[0], face[i], face[i + 1]) for face in ([1, 2, 3, 4, 5], [2, 6, 7, 3], [7, 6, 8, 9, 10])
                 for i in range(1, len(face) - 1)]
    split = "".join(f"v {' '.join(rows[i - 1])}\n" for triangle in triangles for i in triangle)
    split += "".join(f"f {3 * k + 1} {3 * k + 2} {3 * k + 3}\n" for k in range(len(triangles)))
    (tmp_path / "split.obj").write_text(split)
    again = scene_of(config({**hidden, "mesh": {"type": "obj", "filename": "split.obj"}},
                            diffuse_imaging={"pixels": 4}), tmp_path)
    np.testing.assert_array_equal(again.reflectance, expected)
    assert "do not all face one side" in refusal(config({**hidden, "mesh": {"type": "obj", "filename": "fan.obj"}}),
                                                 "geometry[n].mesh.filename", tmp_path)


def test_example_obj_matches_rectangle_example():
    obj = scene_of(yaml.safe_load((EXAMPLES / "plane-confocal.yaml").read_text()),
                   EXAMPLES.parents[1])
    np.testing.assert_allclose(obj.center, [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(obj.u, [2, 0, 0], atol=1e-15)
    np.testing.assert_allclose(obj.v, [0, -2, 0], atol=1e-15)
    assert obj.intensity == pytest.approx(math.pi)                  # mono: one channel
    assert obj.noise.sigma == 1e-4 and obj.pixels == 32


def test_channels_are_summed():
    hidden = {**config()["geometry"][0],
              "material": {"id": "custom", "text": '<bsdf type="diffuse"><rgb name="reflectance" '
                                                   'value="0.2, 0.4, 0.6"/></bsdf>'}}
    scene = scene_of(config(hidden, laser_emission="1, 2, 3"))
    # I rho_w^2 rho_h = sum_c pi E_c rho_w,c^2 rho_h,c
    assert scene.intensity * scene.wall_reflectance**2 * scene.reflectance[0, 0] == pytest.approx(
        math.pi * (0.2 + 0.8 + 1.8))
    grey_wall = {**WALL, "material": {"id": "custom", "text": '<bsdf type="diffuse"><float name="reflectance" '
                                                              'value="0.5"/></bsdf>'}}
    scene = scene_of(config(geometry=[config()["geometry"][0], grey_wall]))
    assert (scene.wall_reflectance, scene.reflectance[0, 0], scene.intensity) == (0.5, 1.0, pytest.approx(3 * math.pi))
    coloured_wall = {**WALL, "material": {"id": "custom", "text": '<bsdf type="diffuse"><rgb name="reflectance" '
                                                                  'value="1, 0.5, 0"/></bsdf>'}}
    scene = scene_of(config(geometry=[config()["geometry"][0], coloured_wall]))
    assert scene.intensity * scene.wall_reflectance**2 * scene.reflectance[0, 0] == pytest.approx(math.pi * 1.25)
    assert "mono" in refusal(config(hidden, mitsuba_variant="llvm_ad_mono"), "geometry[plane].material.text")


def test_stated_flag_kept_and_warned():
    with pytest.warns(TalConfigWarning, match="account_first_and_last_bounces: true reaches only"):
        scene = tal_config_scene(config(account_first_and_last_bounces=True))
    assert scene.scan.account_first_and_last_bounces is False     # what tal renders
    assert scene.capture_accounts_flag is True                    # what its HDF5 says
    assert scene.replace(name="other").capture_accounts_flag is True
    with pytest.warns(TalConfigWarning, match="integrator_filter_bounces: -1"):
        tal_config_scene(config(integrator_filter_bounces=-1))


@pytest.mark.parametrize("change, key", [
    ({"mitsuba_variant": "llvm_ad_spectral"}, "mitsuba_variant"),
    ({"integrator_filter_bounces": 3}, "integrator_filter_bounces"),
    ({"integrator_max_depth": 3}, "integrator_max_depth"),
    ({"histogram_mode": "frequency"}, "histogram_mode"),
    ({"scan_type": "confocal", "laser_width": 4, "laser_height": 4, "laser_aperture_end_x": 0.5},
     "laser_aperture_end_x"),                    # the key that makes it partial
    ({"laser_lookat_x": 9}, "laser_lookat_x"),
    ({"laser_emission_mode": "spectrum"}, "laser_emission_mode"),
    ({"sensor_widht": 4}, "sensor_widht"),
    ({"num_bins": 0}, "num_bins"),
    ({"laser_z": -1.0}, "laser_z"),
    ({"diffuse_imaging": {"pixels": 4, "noise": {"sigma": 1e-3, "seeds": 1}}}, "diffuse_imaging.noise"),
    ({"diffuse_imaging": {"pixels": 4, "detector": {"photons": 1}}}, "diffuse_imaging.detector"),
    ({"diffuse_imaging": [4]}, "diffuse_imaging"),
])
def test_refusals_name_tal_keys(change, key):
    refusal(config(**change), key)


def test_a_laser_aperture_is_ignored_by_a_single_scan_and_refused_partial_by_the_others():
    """tal 0.20's render.py reads laser_aperture_* only for confocal and exhaustive scans (the lit points'
    grid); a single scan lights laser_lookat_x/y whatever the aperture: the same scene, as docs/tal.md says."""
    aperture = {"laser_aperture_start_x": 0.25, "laser_aperture_end_x": 0.5, "laser_aperture_end_y": 0.75}
    plain, partial = scene_of(config()), scene_of(config(**aperture))
    assert (partial.scan.type, partial.scan.grid) == (plain.scan.type, plain.scan.grid) == ("single", (4, 4))
    np.testing.assert_array_equal(partial.laser_points, plain.laser_points)
    for kind in ("confocal", "exhaustive"):
        assert "partial laser aperture" in refusal(config(scan_type=kind, laser_width=4, laser_height=4, **aperture),
                                                   "laser_aperture_start_x")


def test_refused_geometry_and_materials():
    hidden = config()["geometry"][0]
    refusal(config({**hidden, "material": {"id": "copper", "alpha": "0.1"}}), "geometry[plane].material.id")
    refusal(config({**hidden, "mesh": {"type": "sphere"}}), "geometry[plane].mesh.type")
    refusal(config({**hidden, "rot_degrees_x": 0.0}), "geometry[plane]")                     # faces away
    refusal(config({**hidden, "displacement_z": -1.0}), "geometry[plane]")                   # behind the wall
    refusal(config({**hidden, "displacement_z": 0.2, "displacement_x": -0.5, "scale_x": 0.2}),
            "geometry[plane]")                                                               # blocks the laser
    refusal(config({**hidden, "material": {"id": "custom", "text": '<bsdf type="plastic"/>'}}),
            "geometry[plane].material.text")
    refusal(config({**hidden, "material": {"id": "custom", "text": '<bsdf type="diffuse"><texture '
                                                                   'type="bitmap" name="reflectance"/></bsdf>'}}),
            "geometry[plane].material.text")
    refusal(config(geometry=[hidden, hidden, WALL]), "geometry")
    refusal(config(geometry=[hidden, {**WALL, "rot_degrees_x": 0.0}]), "geometry[relay_wall].rot_degrees_x")
    without = {k: v for k, v in WALL.items() if k != "displacement_y"}
    refusal(config(geometry=[hidden, without]), "geometry[relay_wall].displacement_y")
    default = {k: v for k, v in config().items() if k != "geometry"}
    assert "./Z.obj" in refusal(default, "geometry[Z].mesh.filename")      # tal's default hidden geometry


def test_yaml_file_errors(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(SceneError, match="invalid YAML at line"):
        load_tal_config(bad)
    listed = tmp_path / "list.yml"
    listed.write_text("- 1\n- 2\n")
    with pytest.raises(SceneError, match="mapping of keys"):
        load_scene(listed)


@pytest.mark.parametrize("keys", [
    dict(sensor_width=100_000, sensor_height=100_000),                 # 74.5 GiB of grid before the pair check
    dict(sensor_width=10**30, sensor_height=2),
    dict(scan_type="confocal", sensor_width=100_000, sensor_height=100_000, laser_width=100_000,
         laser_height=100_000),
    dict(scan_type="exhaustive", laser_width=100_000, laser_height=100_000),
])
def test_huge_scan_grids_are_refused_before_any_point_is_built(keys):
    assert "(laser point, read point) pairs; at most 1,048,576" in refusal(config(**keys), "sensor_width")


def test_huge_and_tiny_hidden_geometry_is_refused_naming_it(tmp_path):
    square = "v -{s} -{s} 0\nv {s} -{s} 0\nv {s} {s} 0\nv -{s} {s} 0\nf 1 2 3 4\n"
    obj = {"name": "m", "mesh": {"type": "obj", "filename": "m.obj"}, "rot_degrees_x": 180.0,
           "displacement_z": 1.0, "material": {"id": "white"}}
    for size, scale, message in (("1e300", 1, "beyond the ±1e+12 m"), ("1e160", 1, "beyond the ±1e+12 m"),
                                 ("1", 1e300, "beyond the ±1e+12 m"), ("1", 1e-300, "smallest length")):
        (tmp_path / "m.obj").write_text(square.format(s=size))
        assert message in refusal(config({**obj, "scale_x": scale, "scale_y": scale}), "geometry[m].mesh.filename",
                                  tmp_path)
    hidden = config()["geometry"][0]
    for scales, message in (({"scale_x": 1e-300}, "its sides are 2e-300 m and 1.0 m; the smallest length"),
                            ({"scale_x": 1e-170, "scale_y": 1e-170}, "its sides are 2e-170 m and 2e-170 m"),
                            ({"scale_x": 1e200, "scale_y": 1e200, "rot_degrees_x": 0.0}, "beyond the ±1e+12 m")):
        assert message in refusal(config({**hidden, **scales}), "geometry[plane]")


@pytest.mark.parametrize("emission", [1e308, "1e300, 1e300, 1e300", "1, 1e308, 1"])
def test_an_irradiance_beyond_float64s_sums_is_refused_naming_it(emission):
    assert "an irradiance beyond 1e+30" in refusal(config(laser_emission=emission), "laser_emission")


@pytest.mark.parametrize("refused, key", [({"num_bins": 0}, "num_bins"), ({"laser_z": -1.0}, "laser_z"),
                                          ({"sensor_width": 10**6, "sensor_height": 10**6}, "sensor_width")])
def test_a_refused_configuration_warns_of_nothing_first(refused, key):
    # tal's default integrator_filter_bounces (-1), the legs flag and a later key each warn, but only once
    # the whole configuration is accepted: a refusal is its one line
    noisy = {k: v for k, v in config(account_first_and_last_bounces=True, simultaneous_scan=False).items()
             if k != "integrator_filter_bounces"}
    with warnings.catch_warnings():
        warnings.simplefilter("error", TalConfigWarning)
        with pytest.raises(SceneError) as caught:
            tal_config_scene({**noisy, **refused})
    assert caught.value.key == key
    with pytest.warns(TalConfigWarning) as said:
        tal_config_scene(noisy)
    assert len(said) == 3 and all(str(w.message).split(":")[0] in ("integrator_filter_bounces",
                                                                   "account_first_and_last_bounces",
                                                                   "simultaneous_scan") for w in said)


def test_a_whole_number_past_pythons_digit_limit_is_one_line(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_text("sensor_width: 1" + "0" * 5000 + "\n")
    with pytest.raises(SceneError, match="whole number of more than 4300 digits"):
        load_tal_config(path)
