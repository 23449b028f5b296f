"""Issue 38's probe, tal's render configurations (YAML) and OBJ meshes: refusals in one line naming tal's key,
and legal configurations whose light matches docs/design.md section 7's formula integrated by the midpoint rule
(tests/probe/common.py), with the pose built here from tal's to_world (T Rz Ry Rx S, by SciPy's rotations).

Every refusal: ``forward`` exits 2 with exactly one stderr line naming the key (the warning about tal's default
``integrator_filter_bounces: -1`` included: a refusal is one line, so no warning precedes it), and the ``--out``
folder is not created. OBJ file names resolve against the working directory (tal's rule): each case runs in its
own temporary folder.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml
from probe.common import ERROR, assert_accepted, assert_refused, relay_wall_path_range, relay_wall_totals, run
from scipy.spatial.transform import Rotation

import analytic
from analytic.errors import SceneError

# as from a shell: every warning reaches the command's own handler, which prints it as a line (or drops it when
# the command is refused), instead of pytest's filterwarnings = error raising it inside the command
pytestmark = pytest.mark.filterwarnings("always")

DROP = object()                          # a change that removes the key

WALL = {"name": "relay_wall", "mesh": {"type": "rectangle"}, "displacement_x": 0.0, "displacement_y": 0.0,
        "displacement_z": 0.0, "scale_x": 1, "scale_y": 1, "material": {"id": "white"}}
PLANE = {"name": "plane", "mesh": {"type": "rectangle"}, "scale_x": 0.5, "scale_y": 0.5, "rot_degrees_x": 180.0,
         "displacement_z": 1.0, "material": {"id": "white"}}
BASE = {"name": "probe", "mitsuba_variant": "llvm_ad_mono", "integrator_filter_bounces": 2, "num_bins": 18,
        "bin_width_opl": 0.05, "start_opl": 2.1, "scan_type": "single", "sensor_width": 2, "sensor_height": 2,
        "geometry": [PLANE, WALL], "relay_wall": "relay_wall", "diffuse_imaging": {"pixels": 4}}

SQUARE = "v -{s} -{s} 0\nv {s} -{s} 0\nv {s} {s} 0\nv -{s} {s} 0\nf 1 2 3 4\n"      # a square of half side s
SQUARE_OBJ = SQUARE.format(s=1)                                                      # tal's rectangle, as an OBJ
TRIANGLES_OBJ = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf 1//1 3//1 4//1\n"


def _apply(mapping: dict, changes: dict) -> dict:
    """``mapping`` updated by ``changes`` (DROP removes a key; None is YAML's null, a value like any other)."""
    return {key: value for key, value in {**mapping, **changes}.items() if value is not DROP}


def config(plane=None, wall=None, **top) -> dict:
    """BASE with the hidden geometry's, the wall's and the top-level keys changed (DROP removes a key)."""
    return _apply({**BASE, "geometry": [_apply(PLANE, plane or {}), _apply(WALL, wall or {})]}, top)


def obj_plane(filename="m.obj", **keys) -> dict:
    """Changes making the hidden geometry an OBJ (the rectangle's pose kept)."""
    return {"mesh": {"type": "obj", "filename": filename}, **keys}


def write(folder, name, content) -> None:
    path = folder / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8", newline="")


def refused(tmp_path, monkeypatch, capsys, data, needle, files=None) -> str:
    """``forward`` of ``data`` (a mapping written as YAML, or the file's text/bytes) is refused in one line."""
    monkeypatch.chdir(tmp_path)
    for name, content in (files or {}).items():
        write(tmp_path, name, content)
    write(tmp_path, "tal.yaml", data if isinstance(data, (str, bytes)) else yaml.safe_dump(data))
    needles = needle if isinstance(needle, tuple) else (needle,)
    return assert_refused(capsys, ["forward", "tal.yaml", "--out", tmp_path / "out"], tmp_path / "out", *needles)


HIDDEN = "geometry[plane]"
WALL_KEY = "geometry[relay_wall]"

# (configuration, the text the one error line must hold)
REFUSED = {
    # the keys at the top level
    "unknown key (a typo)": (config(sensor_widht=4), "sensor_widht"),
    "name a number": (config(name=5), "name"),
    "variant spectral": (config(mitsuba_variant="llvm_ad_spectral"), "mitsuba_variant"),
    "variant polarized": (config(mitsuba_variant="scalar_spectral_polarized"), "mitsuba_variant"),
    "variant a number": (config(mitsuba_variant=3), "mitsuba_variant"),
    "filter bounces 3": (config(integrator_filter_bounces=3), "integrator_filter_bounces"),
    "filter bounces a string": (config(integrator_filter_bounces="2"), "integrator_filter_bounces"),
    "filter bounces 2.0": (config(integrator_filter_bounces=2.0), "integrator_filter_bounces"),
    "filter bounces true": (config(integrator_filter_bounces=True), "integrator_filter_bounces"),
    "max depth 3": (config(integrator_max_depth=3), "integrator_max_depth"),
    "max depth nan": (config(integrator_max_depth=math.nan), "integrator_max_depth"),
    "histogram frequency": (config(histogram_mode="frequency"), "histogram_mode"),
    "laser sampling an integer": (config(integrator_nlos_laser_sampling=1), "integrator_nlos_laser_sampling"),
    "auto detect bins a string": (config(auto_detect_bins="no"), "auto_detect_bins"),
    "bounces flag a string": (config(account_first_and_last_bounces="yes"), "account_first_and_last_bounces"),
    # scans and grids
    "scan type unknown": (config(scan_type="raster"), "scan_type"),
    "scan type null": (config(scan_type=None), "scan_type"),
    "sensor width zero": (config(sensor_width=0), "sensor_width"),
    "sensor height negative": (config(sensor_height=-4), "sensor_height"),
    "sensor width fraction": (config(sensor_width=2.5), "sensor_width"),
    "sensor width a string": (config(sensor_width="16"), "sensor_width"),
    "sensor width true": (config(sensor_width=True), "sensor_width"),
    "sensor width nan": (config(sensor_width=math.nan), "sensor_width"),
    "sensor grid 100000 x 100000": (config(sensor_width=100000, sensor_height=100000), "sensor_width"),
    "confocal 100000 x 100000": (config(scan_type="confocal", sensor_width=100000, sensor_height=100000,
                                        laser_width=100000, laser_height=100000), "sensor_width"),
    "exhaustive 1000^4 pairs": (config(scan_type="exhaustive", sensor_width=1000, sensor_height=1000,
                                       laser_width=1000, laser_height=1000), "sensor_width"),
    "exhaustive laser width zero": (config(scan_type="exhaustive", laser_width=0, laser_height=2), "laser_width"),
    "confocal laser grid differs": (config(scan_type="confocal", laser_width=3, laser_height=2), "laser_width"),
    "confocal with tal's 32 x 32 laser default": (config(scan_type="confocal"), "laser_width"),
    # the key named is the one that makes the aperture partial; a value that is no number is refused as such
    "confocal partial aperture": (config(scan_type="confocal", laser_width=2, laser_height=2,
                                         laser_aperture_end_x=0.5), "laser_aperture_end_x"),
    "exhaustive partial aperture": (config(scan_type="exhaustive", laser_width=2, laser_height=2,
                                           laser_aperture_start_y=0.25), "laser_aperture_start_y"),
    "confocal aperture a string": (config(scan_type="confocal", laser_width=2, laser_height=2,
                                          laser_aperture_start_x="abc"), ("laser_aperture_start_x", "a number")),
    "exhaustive aperture a list": (config(scan_type="exhaustive", laser_width=2, laser_height=2,
                                          laser_aperture_end_y=[1]), ("laser_aperture_end_y", "a number")),
    "confocal aperture nan": (config(scan_type="confocal", laser_width=2, laser_height=2,
                                     laser_aperture_end_x=math.nan), ("laser_aperture_end_x", "finite")),
    "lookat beyond the wall": (config(laser_lookat_x=3), "laser_lookat_x"),
    "lookat negative": (config(laser_lookat_y=-1), "laser_lookat_y"),
    "lookat nan": (config(laser_lookat_x=math.nan), "laser_lookat_x"),
    "lookat a string": (config(laser_lookat_y="1"), "laser_lookat_y"),
    # the laser and the sensor
    "emission negative": (config(mitsuba_variant="llvm_ad_rgb", laser_emission="-1, 1, 1"), "laser_emission"),
    "emission zero (0 alone is tal's default)": (config(mitsuba_variant="llvm_ad_rgb", laser_emission="0, 0, 0"),
                                                 "laser_emission"),
    "emission nan": (config(laser_emission=math.nan), "laser_emission"),
    "emission 1e300": (config(laser_emission=1e300), "laser_emission"),
    "emission two values": (config(mitsuba_variant="llvm_ad_rgb", laser_emission="1, 2"), "laser_emission"),
    "emission mode spectrum": (config(laser_emission_mode="spectrum"), "laser_emission_mode"),
    "coloured emission in a mono variant": (config(laser_emission="1, 0.5, 0.2"), "laser_emission"),
    "laser on the wall": (config(laser_z=0.0), "laser_z"),
    "laser behind the wall": (config(laser_z=-0.25), "laser_z"),
    "laser x nan": (config(laser_x=math.nan), "laser_x"),
    "laser y inf": (config(laser_y=math.inf), "laser_y"),
    "sensor z a string": (config(sensor_z="0.25"), "sensor_z"),
    "sensor x 1e300": (config(sensor_x=1e300), "sensor_x"),
    "laser line blocked by the plane": (config(laser_x=0.0, laser_z=2.0), (HIDDEN, "blocks the laser's line")),
    "sensor line blocked by the plane": (config(sensor_x=0.0, sensor_z=2.0), (HIDDEN, "blocks the sensor's line")),
    "hidden edge-on to the wall": (config(plane={"rot_degrees_x": 90.0, "displacement_z": 1.5}), (HIDDEN, "does not face every scanned point")),
    # bins
    "num bins zero": (config(num_bins=0), "num_bins"),
    "num bins negative": (config(num_bins=-5), "num_bins"),
    "num bins fraction": (config(num_bins=2.5), "num_bins"),
    "bin width zero": (config(bin_width_opl=0.0), "bin_width_opl"),
    "bin width negative": (config(bin_width_opl=-0.01), "bin_width_opl"),
    "bin width nan": (config(bin_width_opl=math.nan), "bin_width_opl"),
    "start inf": (config(start_opl=math.inf), "start_opl"),
    "start a string": (config(start_opl="1.9"), "start_opl"),
    # ours
    "pixels zero": (config(diffuse_imaging={"pixels": 0}), "diffuse_imaging.pixels"),
    "pixels a billion": (config(diffuse_imaging={"pixels": 10**9}), "diffuse_imaging.pixels"),
    "pixels a string": (config(diffuse_imaging={"pixels": "4"}), "diffuse_imaging.pixels"),
    "ours not a mapping": (config(diffuse_imaging=4), "diffuse_imaging"),
    "ours unknown key": (config(diffuse_imaging={"colour": 1}), "diffuse_imaging.colour"),
    "tolerance negative": (config(diffuse_imaging={"pixels": 4, "tolerance": -1e-6}), "diffuse_imaging.tolerance"),
    "noise with an unknown key": (config(diffuse_imaging={"noise": {"kind": "gaussian", "sgima": 0.1}}),
                                  "diffuse_imaging.noise"),
    # the geometry list and the relay wall
    "geometry not a list": (config(geometry="plane"), "geometry"),
    "geometry without a hidden shape": (config(geometry=[WALL]), "geometry"),
    "geometry with two hidden shapes": (config(geometry=[PLANE, {**PLANE, "name": "b"}, WALL]), "geometry"),
    "geometry names repeated": (config(geometry=[{**PLANE, "name": "relay_wall"}, WALL]), "geometry"),
    "relay wall names no geometry": (config(relay_wall="wall"), "relay_wall"),
    "wall missing scale_x": (config(wall={"scale_x": DROP}), f"{WALL_KEY}.scale_x"),
    "wall missing displacement_z": (config(wall={"displacement_z": DROP}), f"{WALL_KEY}.displacement_z"),
    "wall rotated": (config(wall={"rot_degrees_z": 10.0}), f"{WALL_KEY}.rot_degrees_z"),
    "wall moved": (config(wall={"displacement_x": 0.5}), f"{WALL_KEY}.displacement_x"),
    "wall an OBJ (not a rectangle)": (config(wall={"mesh": {"type": "obj", "filename": "w.obj"}}),
                                      f"{WALL_KEY}.mesh.type"),
    "wall a disk": (config(wall={"mesh": {"type": "disk"}}), f"{WALL_KEY}.mesh.type"),
    "wall facing -z": (config(wall={"scale_z": -1}), f"{WALL_KEY}.scale_z"),
    "wall scale_z a string": (config(wall={"scale_z": "a"}), (f"{WALL_KEY}.scale_z", "a number")),
    "wall scale_z nan": (config(wall={"scale_z": math.nan}), (f"{WALL_KEY}.scale_z", "finite")),
    "wall displacement nan": (config(wall={"displacement_y": math.nan}), (f"{WALL_KEY}.displacement_y", "finite")),
    "wall displacement a string": (config(wall={"displacement_x": "0"}), (f"{WALL_KEY}.displacement_x",
                                                                            "a number")),
    "wall displacement null": (config(wall={"displacement_z": None}), (f"{WALL_KEY}.displacement_z", "a number")),
    "wall scale negative": (config(wall={"scale_x": -1.0}), f"{WALL_KEY}.scale_x"),
    "wall scale nan": (config(wall={"scale_y": math.nan}), f"{WALL_KEY}.scale_y"),
    "wall scale inf": (config(wall={"scale_x": math.inf}), f"{WALL_KEY}.scale_x"),
    "wall scale a string": (config(wall={"scale_x": "1"}), f"{WALL_KEY}.scale_x"),
    "wall scale 1e300": (config(wall={"scale_x": 1e300, "scale_y": 1e300}), f"{WALL_KEY}.scale_x"),
    "wall scale 1e-300": (config(wall={"scale_y": 1e-300}), f"{WALL_KEY}.scale_y"),
    "wall material copper": (config(wall={"material": {"id": "copper"}}), f"{WALL_KEY}.material.id"),
    # the hidden rectangle
    "hidden a sphere": (config(plane={"mesh": {"type": "sphere"}}), f"{HIDDEN}.mesh.type"),
    "hidden without a mesh": (config(plane={"mesh": DROP}), f"{HIDDEN}.mesh.type"),
    "hidden unknown key": (config(plane={"colour": "red"}), f"{HIDDEN}.colour"),
    "hidden scale negative": (config(plane={"scale_x": -0.5}), f"{HIDDEN}.scale_x"),
    "hidden scale nan": (config(plane={"scale_y": math.nan}), f"{HIDDEN}.scale_y"),
    "hidden scale 1e-300": (config(plane={"scale_x": 1e-300, "scale_y": 1e-300}), HIDDEN),
    "hidden scale 1e300": (config(plane={"scale_x": 1e300}), HIDDEN),
    "hidden rotation nan": (config(plane={"rot_degrees_y": math.nan}), f"{HIDDEN}.rot_degrees_y"),
    "hidden rotation inf": (config(plane={"rot_degrees_z": math.inf}), f"{HIDDEN}.rot_degrees_z"),
    "hidden displacement inf": (config(plane={"displacement_z": math.inf}), f"{HIDDEN}.displacement_z"),
    "hidden displacement a string": (config(plane={"displacement_z": "1"}), f"{HIDDEN}.displacement_z"),
    "hidden facing away (tal's default rectangle)": (config(plane={"rot_degrees_x": DROP}), HIDDEN),
    "hidden behind the wall": (config(plane={"displacement_z": -1.0, "rot_degrees_x": DROP}), HIDDEN),
    "hidden crossing the wall": (config(plane={"rot_degrees_x": 100.0, "displacement_z": 0.3}), HIDDEN),
    "hidden material copper": (config(plane={"material": {"id": "copper"}}), f"{HIDDEN}.material.id"),
    "hidden material missing": (config(plane={"material": DROP}), f"{HIDDEN}.material"),
    "hidden conductor BSDF": (config(plane={"material": {"id": "custom", "text": '<bsdf type="conductor"/>'}}),
                              f"{HIDDEN}.material.text"),
    "hidden reflectance 1.5": (config(plane={"material": {"id": "custom", "text": '<bsdf type="diffuse">'
                                                          '<float name="reflectance" value="1.5"/></bsdf>'}}),
                               f"{HIDDEN}.material.text"),
    "hidden BSDF not XML": (config(plane={"material": {"id": "custom", "text": "<bsdf"}}),
                            f"{HIDDEN}.material.text"),
}


@pytest.mark.parametrize("data, needle", REFUSED.values(), ids=REFUSED.keys())
def test_forward_refuses_in_one_line(tmp_path, monkeypatch, capsys, data, needle):
    refused(tmp_path, monkeypatch, capsys, data, needle)


# tal's default integrator_filter_bounces (-1) is warned about on a legal configuration; on a refused one the
# refusal is the only line (issue 38 cause 6)
AT_TALS_DEFAULT = ("sensor grid 100000 x 100000", "scan type unknown", "hidden facing away (tal's default "
                   "rectangle)", "wall rotated", "num bins zero", "emission nan", "laser on the wall",
                   "confocal partial aperture", "pixels zero", "hidden scale 1e-300")


@pytest.mark.parametrize("name", AT_TALS_DEFAULT)
def test_refusal_at_tals_default_bounces_is_still_one_line(tmp_path, monkeypatch, capsys, name):
    data, needle = REFUSED[name]
    refused(tmp_path, monkeypatch, capsys, _apply(data, {"integrator_filter_bounces": DROP}), needle)


def test_a_huge_sensor_grid_is_refused_before_any_grid_is_built(tmp_path, monkeypatch, capsys):
    """100000 x 100000 read points (10^10) are refused by their count, before any point is computed."""
    import analytic.scenes.relay_wall as relay_wall
    import interop.tal.geometry as geometry

    def guarded(grid, size, _real=relay_wall.grid_points):
        assert grid[0] * grid[1] <= 1 << 20, f"a {grid} grid was built before the refusal"
        return _real(grid, size)

    monkeypatch.setattr(relay_wall, "grid_points", guarded)
    monkeypatch.setattr(geometry, "grid_points", guarded)
    line = refused(tmp_path, monkeypatch, capsys, config(integrator_filter_bounces=DROP, sensor_width=100000,
                                                         sensor_height=100000), "sensor_width")
    assert "10,000,000,000" in line


# ======================================================================== files: YAML and OBJ

MARKED = b"\xef\xbb\xbf"


def _text(data) -> str:
    return yaml.safe_dump(data)


FILE_CASES = {
    "YAML syntax error": ("name: [probe\n", {}, "invalid YAML"),
    "YAML a list": ("- 1\n- 2\n", {}, "mapping"),
    "YAML with a byte-order mark, unknown key": (MARKED + _text(config(sensor_heigth=2)).encode(), {},
                                                 "sensor_heigth"),
    "YAML with CRLF, bad bins": (_text(config(num_bins=0)).replace("\n", "\r\n"), {}, "num_bins"),
    "YAML with BOM and CRLF, facing away": (MARKED + _text(config(plane={"rot_degrees_x": DROP}))
                                            .replace("\n", "\r\n").encode(), {}, HIDDEN),
    "YAML of invalid UTF-8": (b"name: \xff\xfe\n", {}, "tal.yaml"),
    # OBJ meshes: every one names the hidden geometry's filename key
    "OBJ missing": (config(plane=obj_plane("absent.obj")), {}, f"{HIDDEN}.mesh.filename"),
    "OBJ filename missing": (config(plane={"mesh": {"type": "obj"}}), {}, f"{HIDDEN}.mesh.filename"),
    "OBJ filename a folder": (config(plane=obj_plane(".")), {}, f"{HIDDEN}.mesh.filename"),
    "OBJ empty": (config(plane=obj_plane()), {"m.obj": ""}, f"{HIDDEN}.mesh.filename"),
    "OBJ binary garbage": (config(plane=obj_plane()), {"m.obj": bytes(range(256)) * 4}, f"{HIDDEN}.mesh.filename"),
    "OBJ coordinates 1e300": (config(plane=obj_plane()), {"m.obj": SQUARE.format(s="1e300")},
                              f"{HIDDEN}.mesh.filename"),
    "OBJ coordinates 1e-300": (config(plane=obj_plane()), {"m.obj": SQUARE.format(s="1e-300")},
                               f"{HIDDEN}.mesh.filename"),
    "OBJ coordinate nan": (config(plane=obj_plane()), {"m.obj": SQUARE_OBJ.replace("v 1 1 0", "v 1 nan 0")},
                           f"{HIDDEN}.mesh.filename"),
    "OBJ coordinate inf": (config(plane=obj_plane()), {"m.obj": SQUARE_OBJ.replace("v 1 1 0", "v inf 1 0")},
                           f"{HIDDEN}.mesh.filename"),
    "OBJ coordinate 1e400": (config(plane=obj_plane()), {"m.obj": SQUARE_OBJ.replace("v 1 1 0", "v 1 1e400 0")},
                             f"{HIDDEN}.mesh.filename"),
    "OBJ scaled by 1e300 in the YAML": (config(plane=obj_plane(scale_x=1e300, scale_y=1e300)),
                                        {"m.obj": SQUARE_OBJ}, f"{HIDDEN}.mesh.filename"),
    "OBJ scaled by 1e-300 in the YAML": (config(plane=obj_plane(scale_x=1e-300, scale_y=1e-300)),
                                         {"m.obj": SQUARE_OBJ}, f"{HIDDEN}.mesh.filename"),
    "OBJ with CRLF and a nan": (config(plane=obj_plane()),
                                {"m.obj": SQUARE_OBJ.replace("v 1 1 0", "v 1 nan 0").replace("\n", "\r\n")},
                                f"{HIDDEN}.mesh.filename"),
    "OBJ not planar": (config(plane=obj_plane()), {"m.obj": SQUARE_OBJ.replace("v 1 1 0", "v 1 1 0.2")},
                       f"{HIDDEN}.mesh.filename"),
    "OBJ a solid (a cube)": (config(plane=obj_plane()), {"m.obj": "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                                         "v 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\nf 1 4 3 2\n"
                                                         "f 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\n"
                                                         "f 4 1 5 8\n"}, f"{HIDDEN}.mesh.filename"),
    "OBJ a degenerate face (collinear)": (config(plane=obj_plane()), {"m.obj": SQUARE_OBJ + "v 2 0 0\nv 3 0 0\n"
                                                                      "f 5 6 6\n"}, f"{HIDDEN}.mesh.filename"),
    "OBJ all vertices at one point": (config(plane=obj_plane()), {"m.obj": "v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n"},
                                      f"{HIDDEN}.mesh.filename"),
    "OBJ a triangle": (config(plane=obj_plane()), {"m.obj": "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nf 1 2 3\n"},
                       f"{HIDDEN}.mesh.filename"),
    "OBJ a face of two vertices": (config(plane=obj_plane()), {"m.obj": "v 0 0 0\nv 1 0 0\nf 1 2\n"},
                                   f"{HIDDEN}.mesh.filename"),
    "OBJ index out of range": (config(plane=obj_plane()), {"m.obj": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n"},
                               f"{HIDDEN}.mesh.filename"),
    "OBJ normal index out of range": (config(plane=obj_plane()), {"m.obj": SQUARE_OBJ.replace("f 1 2 3 4",
                                                                                          "f 1//5 2//5 3//5 4//5")},
                                      f"{HIDDEN}.mesh.filename"),
    "OBJ faces facing both ways": (config(plane=obj_plane()), {"m.obj": "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                                                               "f 1 2 3\nf 1 4 3\n"}, f"{HIDDEN}.mesh.filename"),
    "OBJ vn against the winding": (config(plane=obj_plane()), {"m.obj": TRIANGLES_OBJ.replace("vn 0 0 1",
                                                                                           "vn 0 0 -1")},
                                   f"{HIDDEN}.mesh.filename"),
    "OBJ overlapping faces": (config(plane=obj_plane()), {"m.obj": SQUARE_OBJ + "f 1 2 3 4\n"},
                              f"{HIDDEN}.mesh.filename"),
    "OBJ corners off the pixel grid": (config(plane=obj_plane()),
                                       {"m.obj": "v 0 0 0\nv 3 0 0\nv 3 1 0\nv 1 1 0\nv 1 3 0\nv 0 3 0\n"
                                                 "f 1 2 3 4 5 6\n"}, f"{HIDDEN}.mesh.filename"),
    "OBJ turned away from the wall": (config(plane=obj_plane(rot_degrees_x=DROP)), {"m.obj": SQUARE_OBJ}, HIDDEN),
}


@pytest.mark.parametrize("data, files, needle", FILE_CASES.values(), ids=FILE_CASES.keys())
def test_files_refused_in_one_line(tmp_path, monkeypatch, capsys, data, files, needle):
    refused(tmp_path, monkeypatch, capsys, data if isinstance(data, (str, bytes)) else data, needle, files)


@pytest.mark.parametrize("name", ["OBJ coordinates 1e300", "OBJ not planar", "wall rotated", "laser on the wall",
                                  "confocal aperture a string", "wall scale_z a string"])
def test_load_scene_raises_a_scene_error_naming_the_key(tmp_path, monkeypatch, name):
    """The Python API refuses a tal configuration as the CLI does: a SceneError, one line, the same key."""
    data, files, needle = (*REFUSED[name][:1], {}, REFUSED[name][1]) if name in REFUSED else FILE_CASES[name]
    monkeypatch.chdir(tmp_path)
    for file, content in files.items():
        write(tmp_path, file, content)
    (tmp_path / "tal.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(SceneError) as raised:
        analytic.load_scene(tmp_path / "tal.yaml")
    for text in needle if isinstance(needle, tuple) else (needle,):
        assert text in str(raised.value)
    assert "\n" not in str(raised.value) and "--" not in str(raised.value)


# ======================================================================== legal configurations

def reference_tables(data: dict) -> dict:
    """The relay-wall tables (tests/probe/common.py's reference) of a tal configuration, from docs/tal.md's
    table written out here: the hidden rectangle [-1, 1]² by T Rz Ry Rx S (SciPy's extrinsic xyz Euler
    angles), read points the cell centres, a single scan lit at lookat / W, I = π Σ_c E_c."""
    hidden = next(g for g in data["geometry"] if g["name"] != data["relay_wall"])
    wall = next(g for g in data["geometry"] if g["name"] == data["relay_wall"])
    scale = [hidden.get(f"scale_{a}") or 1.0 for a in "xyz"]
    angles = [hidden.get(f"rot_degrees_{a}") or 0.0 for a in "xyz"]
    matrix = Rotation.from_euler("xyz", angles, degrees=True).as_matrix() @ np.diag(scale)
    shift = [hidden.get(f"displacement_{a}") or 0.0 for a in "xyz"]
    halves = (float(wall["scale_x"]), float(wall["scale_y"]))
    width, height = data["sensor_width"], data["sensor_height"]
    scan = {"type": data["scan_type"], "grid": [width, height]}
    if data["scan_type"] == "single":
        lookat = [(data.get(f"laser_lookat_{a}") or w / 2) / w for a, w in (("x", width), ("y", height))]
        scan["laser_point"] = [halves[0] * (2 * lookat[0] - 1), halves[1] * (2 * lookat[1] - 1), 0.0]
    elif data["scan_type"] == "exhaustive":
        scan["laser_grid"] = [data["laser_width"], data["laser_height"]]
    emission = data.get("laser_emission", 1.0)
    channels = [float(x) for x in str(emission).split(",")]
    if "rgb" in data["mitsuba_variant"] and len(channels) == 1:
        channels *= 3
    rho_h = 1.0
    material = hidden["material"]
    if material["id"] == "custom":
        rho_h = float(material["text"].split('value="')[1].split('"')[0])
    return {"relay_wall": {"size": [2 * halves[0], 2 * halves[1]], "reflectance": 1.0},
            "hidden": {"center": shift, "u": list(matrix @ [2.0, 0, 0]), "v": list(matrix @ [0, 2.0, 0]),
                       "reflectance": rho_h},
            "laser": {"position": [data.get(f"laser_{a}", d) for a, d in zip("xyz", (-0.5, 0.0, 0.25))],
                      "intensity": math.pi * sum(channels)},
            "scan": scan}


def forward(tmp_path, monkeypatch, capsys, data, files=None, name="out", text=None):
    """``forward`` of a legal configuration with ``--window auto``: (transient, meta, stderr lines)."""
    monkeypatch.chdir(tmp_path)
    for file, content in (files or {}).items():
        write(tmp_path, file, content)
    path = tmp_path / f"{name}.yaml"
    write(tmp_path, path.name, text if text is not None else yaml.safe_dump(data))
    lines = assert_accepted(capsys, ["forward", path.name, "--out", tmp_path / name, "--window", "auto", "--quiet"])
    lines = [line for line in lines if not line.startswith("diffuse-imaging: window:")]     # the window chosen
    return np.load(tmp_path / name / "transient.npy"), json.loads((tmp_path / name / "meta.json").read_text()), lines


LEGAL = {
    "single, centred": config(),
    "single, lit off-centre, rgb": config(sensor_width=3, sensor_height=2, laser_lookat_x=1, laser_lookat_y=1.5,
                                          mitsuba_variant="llvm_ad_rgb"),
    "confocal 3 x 3": config(scan_type="confocal", sensor_width=3, sensor_height=3, laser_width=3, laser_height=3),
    "exhaustive 2 x 1 by 1 x 2": config(scan_type="exhaustive", sensor_width=2, sensor_height=1, laser_width=1,
                                        laser_height=2),
    "rotated and displaced hidden plane": config(plane={"scale_x": 0.4, "scale_y": 0.25, "rot_degrees_x": 170.0,
                                                        "rot_degrees_y": 15.0, "rot_degrees_z": 25.0,
                                                        "displacement_x": 0.3, "displacement_y": -0.2,
                                                        "displacement_z": 0.9}),
    "non-square wall, grey hidden, bright laser": config(
        wall={"scale_x": 1.5, "scale_y": 0.5}, laser_emission=2.5,
        plane={"material": {"id": "custom", "text": '<bsdf type="diffuse"><rgb name="reflectance" value="0.3"/>'
                                                    '</bsdf>'}}),
    "single, partial aperture (not read by tal)": config(laser_aperture_end_x=0.5),
}
FAST = ("single, centred", "rotated and displaced hidden plane")


@pytest.mark.parametrize("data", [pytest.param(v, marks=() if k in FAST else pytest.mark.slow)
                                  for k, v in LEGAL.items()], ids=LEGAL.keys())
def test_forward_light_matches_the_midpoint_integral(tmp_path, monkeypatch, capsys, data):
    transient, meta, lines = forward(tmp_path, monkeypatch, capsys, data)
    assert lines == []
    assert np.all(np.isfinite(transient)) and np.all(transient >= 0) and meta["window_share"] == 1.0
    tables = reference_tables(data)
    expected, bound = relay_wall_totals(tables)
    assert transient.shape[0] == len(expected)
    np.testing.assert_array_less(np.abs(transient.sum(axis=1) - expected), bound + 2e-6 * expected)
    shortest, longest = relay_wall_path_range(tables)
    edges = meta["start_opl"] + meta["bin_width_opl"] * np.arange(transient.shape[1] + 1)
    before = edges[1:][None, :] <= shortest[:, None] - 1e-9
    after = edges[:-1][None, :] >= longest[:, None] + 1e-9
    assert np.all(transient[before | after] == 0.0)


def test_tals_default_bounces_warns_in_one_line_and_changes_nothing(tmp_path, monkeypatch, capsys):
    """Left at tal's -1, a legal configuration renders the same model with one warning line naming the key."""
    plain, _, _ = forward(tmp_path, monkeypatch, capsys, config(), name="two")
    warned, _, lines = forward(tmp_path, monkeypatch, capsys, config(integrator_filter_bounces=DROP), name="dflt")
    assert len(lines) == 1 and "integrator_filter_bounces" in lines[0], lines
    np.testing.assert_array_equal(warned, plain)


OBJ_EQUAL = {       # (the OBJ's text, the rectangle's configuration, the OBJ geometry's own keys)
    "one quad": (SQUARE_OBJ, config(), {}),
    "two triangles with vn": (TRIANGLES_OBJ, config(), {}),
    "BOM and CRLF": ("\ufeff" + SQUARE_OBJ.replace("\n", "\r\n"), config(), {}),
    "CR line ends": (SQUARE_OBJ.replace("\n", "\r"), config(), {}),
    "negative indices": (SQUARE_OBJ.replace("f 1 2 3 4", "f -4 -3 -2 -1"), config(), {}),
    # a vertex no face names is not rendered: it used to overflow the merging of repeated vertices (a warning)
    "a far vertex no face names": ("v 1e308 -1e308 0\n" + SQUARE_OBJ.replace("f 1 2 3 4", "f 2 3 4 5"), config(),
                                   {}),
    "coordinates 1e-300 scaled by 0.5e300": (SQUARE.format(s="1e-300"), config(),
                                             {"scale_x": 0.5e300, "scale_y": 0.5e300}),
    "coordinates 1e300 scaled by 0.5e-300": (SQUARE.format(s="1e300"), config(),
                                             {"scale_x": 0.5e-300, "scale_y": 0.5e-300}),
    "a 0.5 m square unscaled": (SQUARE.format(s=0.5), config(), {"scale_x": DROP, "scale_y": DROP}),
    "turned and moved, confocal": (TRIANGLES_OBJ, config(
        scan_type="confocal", laser_width=2, laser_height=2,
        plane={"scale_x": 0.4, "scale_y": 0.3, "rot_degrees_x": 160.0, "rot_degrees_z": 30.0,
               "displacement_x": -0.2, "displacement_y": 0.1, "displacement_z": 1.1}), {}),
}


@pytest.mark.parametrize("obj, data, keys", [pytest.param(*v, marks=() if k == "a far vertex no face names" else
                                                          pytest.mark.slow) for k, v in OBJ_EQUAL.items()],
                         ids=OBJ_EQUAL.keys())
def test_an_obj_rectangle_equals_the_rectangle_mesh(tmp_path, monkeypatch, capsys, obj, data, keys):
    """tal's rectangle written as an OBJ (one quad, two triangles, a marked CRLF file, coordinates scaled back
    by the YAML) under the same pose gives the rectangle's capture within the model's tolerance (1e-6 relative
    per bin: the OBJ's rectangle is the same to 1e-16 m, and the adaptive quadrature of a bin that a path-length
    extreme crosses follows such a change by up to its tolerance, 7.7e-9 seen here), with no warning."""
    rectangle, _, _ = forward(tmp_path, monkeypatch, capsys, data, name="rect")
    with_obj = _apply(data, {"geometry": [_apply(data["geometry"][0], {**obj_plane(), **keys}), data["geometry"][1]]})
    meshed, _, lines = forward(tmp_path, monkeypatch, capsys, with_obj, files={"m.obj": obj.encode("utf-8")},
                               name="obj")
    assert lines == [] and rectangle.max() > 0
    np.testing.assert_allclose(meshed, rectangle, rtol=1e-6, atol=1e-15 * rectangle.max())


def test_a_yaml_with_bom_and_crlf_is_the_same_scene(tmp_path, monkeypatch, capsys):
    plain, _, _ = forward(tmp_path, monkeypatch, capsys, config(), name="plain")
    text = "\ufeff" + yaml.safe_dump(config()).replace("\n", "\r\n")
    marked, _, _ = forward(tmp_path, monkeypatch, capsys, None, name="marked", text=text)
    np.testing.assert_array_equal(marked, plain)



def _tiny_laser(tmp_path, scene, intensity) -> str:
    """A scene file whose laser is ``intensity`` (tal's irradiance E, or a relay-wall TOML's I)."""
    from probe.common import toml_text

    if scene == "yaml":
        (tmp_path / "s.yaml").write_text(yaml.safe_dump(config(laser_emission=intensity)))
    else:
        (tmp_path / "s.toml").write_text(toml_text({"relay_wall": {"size": [2.0, 2.0]}, "hidden": {"pixels": 4},
                                                    "scan": {"type": "confocal", "grid": [2, 2]},
                                                    "laser": {"intensity": intensity},
                                                    "sampling": {"period": 0.05, "start": 1.9, "count": 22}}))
    return f"s.{scene}"


@pytest.mark.parametrize("scene, intensity", [("yaml", 1e-320), ("toml", 1e-310)])
def test_light_below_float64s_normal_range_is_no_traceback(tmp_path, monkeypatch, capsys, scene, intensity):
    """A laser so faint that the light is subnormal: the figure's power of ten (1e-322) overflowed its scale
    10^322 (validation.plots.axes.power_of_ten) into a traceback. Whether such light is refused (below) or
    written, the command ends as the promises say."""
    monkeypatch.chdir(tmp_path)
    status, lines = run(capsys, ["forward", _tiny_laser(tmp_path, scene, intensity), "--out", tmp_path / "out",
                                 "--quiet"])
    assert status in (0, 2) and not any("Traceback" in line for line in lines), (status, lines)
    if status == 2:
        assert len(lines) == 1 and lines[0].startswith(ERROR) and not (tmp_path / "out").exists(), lines
    else:
        assert np.all(np.isfinite(np.load(tmp_path / "out" / "transient.npy")))
        assert (tmp_path / "out" / "transient.png").stat().st_size > 0


@pytest.mark.parametrize("scene, intensity, key", [("yaml", 1e-320, "laser_emission"),
                                                   ("toml", 1e-320, "laser.intensity")])
def test_light_that_underflows_is_refused(tmp_path, monkeypatch, capsys, scene, intensity, key):
    monkeypatch.chdir(tmp_path)
    refused_line = assert_refused(capsys, ["forward", _tiny_laser(tmp_path, scene, intensity), "--out",
                                           tmp_path / "out"], tmp_path / "out", key)
    assert refused_line
