"""Issue 38's probe, relay-wall scenes (TOML): refusals in one line naming the key, and legal captures whose
light matches docs/design.md section 7's formula integrated here by the midpoint rule (tests/probe/common.py).

Each refusal case states the key the one line must name; each legal case states its geometry, and the light
of every pair summed over time must equal the midpoint integral (impulse, ``--window auto``: the window holds
all of it) within the midpoint rule's own error bound plus the model's 1e-6 tolerance, with no light in the
bins before the shortest path or after the longest.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from probe.common import (assert_accepted, assert_forward_refuses, merged, relay_wall_path_range,
                          relay_wall_totals, toml_text)

import analytic
from analytic.errors import SceneError

BASE = {"relay_wall": {"size": [2.0, 2.0]}, "hidden": {"pixels": 4}, "scan": {"type": "confocal", "grid": [2, 2]},
        "sampling": {"start": 1.5, "count": 30}}

# (changes to BASE, the text the one error line must hold)
REFUSED = {
    "wall size zero": ({"relay_wall": {"size": [0.0, 2.0]}}, "relay_wall.size"),
    "wall size negative": ({"relay_wall": {"size": [2.0, -1.0]}}, "relay_wall.size"),
    "wall size one number": ({"relay_wall": {"size": [2.0]}}, "relay_wall.size"),
    "wall size three numbers": ({"relay_wall": {"size": [2.0, 2.0, 2.0]}}, "relay_wall.size"),
    "wall size inf": ({"relay_wall": {"size": [math.inf, 2.0]}}, "relay_wall.size"),
    "wall size nan": ({"relay_wall": {"size": [2.0, math.nan]}}, "relay_wall.size"),
    "wall size string": ({"relay_wall": {"size": "2"}}, "relay_wall.size"),
    "wall size boolean": ({"relay_wall": {"size": [True, 2.0]}}, "relay_wall.size"),
    "wall size 1e300": ({"relay_wall": {"size": [1e300, 1e300]}}, "relay_wall.size"),
    "wall size subnormal": ({"relay_wall": {"size": [5e-324, 2.0]}}, "relay_wall.size"),
    "wall reflectance negative": ({"relay_wall": {"reflectance": -0.1}}, "relay_wall.reflectance"),
    "wall reflectance above one": ({"relay_wall": {"reflectance": 1.5}}, "relay_wall.reflectance"),
    "wall reflectance nan": ({"relay_wall": {"reflectance": math.nan}}, "relay_wall.reflectance"),
    "wall reflectance string": ({"relay_wall": {"reflectance": "1"}}, "relay_wall.reflectance"),
    "wall unknown key": ({"relay_wall": {"colour": 1.0}}, "colour"),
    "hidden behind the wall": ({"hidden": {"center": [0.0, 0.0, -1.0]}}, "hidden.center"),
    "hidden through the wall": ({"hidden": {"center": [0.0, 0.0, 0.0]}}, "hidden.center"),
    "hidden tilted through the wall": ({"hidden": {"center": [0.0, 0.0, 0.3], "v": [0.0, -0.8, -0.8]}},
                                       "hidden.center"),
    "hidden center two numbers": ({"hidden": {"center": [0.0, 1.0]}}, "hidden.center"),
    "hidden center nan": ({"hidden": {"center": [0.0, math.nan, 1.0]}}, "hidden.center"),
    "hidden u zero": ({"hidden": {"u": [0.0, 0.0, 0.0]}}, "hidden.u"),
    "hidden v underflows": ({"hidden": {"v": [0.0, -1e-300, 0.0]}}, "hidden.v"),
    "hidden v subnormal": ({"hidden": {"v": [0.0, -5e-324, 0.0]}}, "hidden.v"),
    "hidden u below a nanometre": ({"hidden": {"u": [1e-10, 0.0, 0.0]}}, "hidden.u"),
    "hidden u not orthogonal to v": ({"hidden": {"v": [0.1, -1.0, 0.0]}}, "hidden.v"),
    "hidden facing away": ({"hidden": {"v": [0.0, 1.0, 0.0]}}, "hidden.u"),
    "hidden edge-on to the wall": ({"hidden": {"center": [0.0, 0.0, 0.5], "u": [0.0, 0.5, 0.0],
                                               "v": [0.0, 0.0, 0.5]}}, "hidden.u"),
    "hidden pixels zero": ({"hidden": {"pixels": 0}}, "hidden.pixels"),
    "hidden pixels negative": ({"hidden": {"pixels": -3}}, "hidden.pixels"),
    "hidden pixels fraction": ({"hidden": {"pixels": 2.5}}, "hidden.pixels"),
    "hidden pixels string": ({"hidden": {"pixels": "4"}}, "hidden.pixels"),
    "hidden pixels boolean": ({"hidden": {"pixels": True}}, "hidden.pixels"),
    "hidden pixels a billion": ({"hidden": {"pixels": 10**9}}, "hidden.pixels"),
    "hidden reflectance negative": ({"hidden": {"reflectance": -0.5}}, "hidden.reflectance"),
    "hidden reflectance nan": ({"hidden": {"reflectance": math.nan}}, "hidden.reflectance"),
    "hidden reflectance missing image": ({"hidden": {"reflectance": "missing.png"}}, "hidden.reflectance"),
    "laser on the wall": ({"laser": {"position": [0.0, 0.0, 0.0]}}, "laser.position"),
    "laser behind the wall": ({"laser": {"position": [-0.5, 0.0, -0.25]}}, "laser.position"),
    "laser two numbers": ({"laser": {"position": [-0.5, 0.25]}}, "laser.position"),
    "laser position string": ({"laser": {"position": "origin"}}, "laser.position"),
    "laser beyond float64's reach": ({"laser": {"position": [0.0, 0.0, 1e200]}}, "laser.position"),
    "laser intensity zero": ({"laser": {"intensity": 0.0}}, "laser.intensity"),
    "laser intensity negative": ({"laser": {"intensity": -1.0}}, "laser.intensity"),
    "laser intensity inf": ({"laser": {"intensity": math.inf}}, "laser.intensity"),
    "laser intensity 1e300": ({"laser": {"intensity": 1e300}}, "laser.intensity"),
    "sensor on the wall": ({"sensor": {"position": [0.3, 0.0, 0.0]}}, "sensor.position"),
    "scan type unknown": ({"scan": {"type": "raster"}}, "scan.type"),
    "scan grid zero": ({"scan": {"grid": [0, 4]}}, "scan.grid"),
    "scan grid one number": ({"scan": {"grid": [4]}}, "scan.grid"),
    "scan grid fraction": ({"scan": {"grid": [2.5, 2]}}, "scan.grid"),
    "scan grid past 2^20 pairs": ({"scan": {"grid": [2048, 1024]}}, "scan.grid"),
    "exhaustive past 2^20 pairs": ({"scan": {"type": "exhaustive", "grid": [64, 64], "laser_grid": [64, 64]}},
                                   "scan.grid"),
    "laser point outside the wall": ({"scan": {"type": "single", "laser_point": [1.5, 0.0, 0.0]}},
                                     "scan.laser_point"),
    "laser point off the wall's plane": ({"scan": {"type": "single", "laser_point": [0.0, 0.0, 0.1]}},
                                         "scan.laser_point"),
    "laser point with a confocal scan": ({"scan": {"laser_point": [0.0, 0.0, 0.0]}}, "scan.laser_point"),
    "laser grid with a confocal scan": ({"scan": {"laser_grid": [2, 2]}}, "scan.laser_grid"),
    "exhaustive laser grid zero": ({"scan": {"type": "exhaustive", "laser_grid": [0, 2]}}, "scan.laser_grid"),
    "bounces flag a string": ({"scan": {"account_first_and_last_bounces": "yes"}},
                              "scan.account_first_and_last_bounces"),
    "sampling period zero": ({"sampling": {"period": 0.0}}, "sampling.period"),
    "sampling count zero": ({"sampling": {"count": 0}}, "sampling.count"),
    "sampling start nan": ({"sampling": {"start": math.nan}}, "sampling.start"),
    "a plane table beside the wall": ({"plane": {"size": 1.0}}, "plane"),
    "a sensors table beside the wall": ({"sensors": {"positions": [[0.0, 0.0, 1.0]]}}, "sensors"),
    # issue 38 cause 2's class: a laser's or a sensor's line through the hidden rectangle, other poses
    "single: laser line blocked off-centre": ({"laser": {"position": [0.3, 0.2, 1.5]},
                                               "scan": {"type": "single", "laser_point": [0.3, 0.2, 0.0]}},
                                              "blocks the laser's line"),
    "exhaustive: laser line blocked": ({"laser": {"position": [0.45, 0.45, 1.5]},
                                        "scan": {"type": "exhaustive", "laser_grid": [2, 2]}},
                                       "blocks the laser's line"),
    "confocal: sensor line blocked": ({"sensor": {"position": [0.1, -0.2, 3.0]}}, "blocks the sensor's line"),
    "tilted rectangle blocks the laser": ({"hidden": {"center": [0.0, 0.0, 0.5], "u": [1.0, 0.0, 0.0],
                                                      "v": [0.0, -1.0, -0.5]},
                                           "laser": {"position": [0.0, 0.0, 2.0]}}, "blocks the laser's line"),
    "rectangle nearly on the wall blocks the laser": ({"hidden": {"center": [0.0, 0.0, 1e-6]}},
                                                      "blocks the laser's line"),
}


@pytest.mark.parametrize("changes, needle", REFUSED.values(), ids=REFUSED.keys())
def test_forward_refuses_in_one_line(tmp_path, capsys, changes, needle):
    assert_forward_refuses(tmp_path, capsys, merged(BASE, changes), needle)


@pytest.mark.parametrize("changes, needle", [REFUSED[k] for k in ("hidden facing away", "laser on the wall",
                                                                  "confocal: sensor line blocked",
                                                                  "hidden v underflows")],
                         ids=["facing away", "laser on wall", "sensor blocked", "v underflows"])
def test_load_scene_raises_a_scene_error_with_the_same_cause(tmp_path, changes, needle):
    """The Python API (analytic.load_scene with a path) refuses as the CLI does, with a SceneError."""
    scene = tmp_path / "wall.toml"
    scene.write_text(toml_text(merged(BASE, changes)))
    with pytest.raises(SceneError) as raised:
        analytic.load_scene(scene)
    assert needle in str(raised.value) and "--" not in str(raised.value)


# (changes to an impulse scene, window chosen by --window auto)
LEGAL = {
    "default confocal 2x2": {},
    "single, lit point off-centre": {"scan": {"type": "single", "grid": [3, 2], "laser_point": [0.3, -0.2, 0.0]}},
    "single, lit point at the wall's corner": {"scan": {"type": "single", "laser_point": [1.0, 1.0, 0.0]}},
    "exhaustive 2x1 by 1x2": {"scan": {"type": "exhaustive", "grid": [2, 1], "laser_grid": [1, 2]}},
    "tilted hidden rectangle": {"hidden": {"center": [0.1, 0.2, 1.2], "u": [0.8, 0.0, 0.2], "v": [0.0, -0.9, 0.0]}},
    "non-square wall, grey wall and hidden, bright laser": {"relay_wall": {"size": [3.0, 1.5], "reflectance": 0.7},
                                                            "hidden": {"reflectance": 0.3},
                                                            "laser": {"intensity": 2.5}},
    "first and last bounces counted": {"scan": {"account_first_and_last_bounces": True}},
    "far, large hidden square": {"hidden": {"center": [0.0, 0.0, 5.0], "u": [2.0, 0.0, 0.0],
                                            "v": [0.0, -2.0, 0.0]}, "sampling": {"period": 0.2}},
    "centimetre square near the wall": {"hidden": {"center": [0.2, 0.1, 0.3], "u": [0.01, 0.0, 0.0],
                                                   "v": [0.0, -0.01, 0.0]}, "sampling": {"period": 0.01}},
    "off-axis hidden square": {"hidden": {"center": [0.8, -0.6, 0.7], "u": [0.5, 0.0, 0.0], "v": [0.0, -0.5, 0.0]}},
    "laser and sensor apart": {"laser": {"position": [0.5, 0.5, 0.5]}, "sensor": {"position": [-0.3, 0.1, 0.4]},
                               "hidden": {"center": [0.0, 0.0, 1.5]}},
}


FAST = ("default confocal 2x2", "tilted hidden rectangle", "first and last bounces counted")


@pytest.mark.parametrize("changes", [pytest.param(v, marks=() if k in FAST else pytest.mark.slow) for k, v in
                                     LEGAL.items()], ids=LEGAL.keys())
def test_forward_light_matches_the_midpoint_integral(tmp_path, capsys, changes):
    tables = merged(BASE, changes)
    tables["sampling"].pop("count")
    tables["sampling"].pop("start")
    scene = tmp_path / "wall.toml"
    scene.write_text(toml_text(tables))
    out = tmp_path / "out"
    assert_accepted(capsys, ["forward", scene, "--out", out, "--window", "auto", "--quiet"])
    transient = np.load(out / "transient.npy")
    meta = json.loads((out / "meta.json").read_text())
    assert np.all(np.isfinite(transient)) and np.all(transient >= 0)
    assert meta["window_share"] == 1.0
    expected, bound = relay_wall_totals(tables)
    assert transient.shape[0] == len(expected)
    np.testing.assert_array_less(np.abs(transient.sum(axis=1) - expected), bound + 2e-6 * expected)
    # no light before the shortest path or after the longest (plus the legs when they are counted)
    shortest, longest = relay_wall_path_range(tables)
    if tables["scan"].get("account_first_and_last_bounces"):
        from probe.common import wall_pairs

        lit, read = wall_pairs(tables["scan"], tables["relay_wall"]["size"])
        laser = np.asarray(tables.get("laser", {}).get("position", (-0.5, 0.0, 0.25)))
        sensor = np.asarray(tables.get("sensor", {}).get("position", (-0.5, 0.0, 0.25)))
        legs = np.linalg.norm(lit - laser, axis=1) + np.linalg.norm(read - sensor, axis=1)
        shortest, longest = shortest + legs, longest + legs
    edges = meta["start_opl"] + meta["bin_width_opl"] * np.arange(transient.shape[1] + 1)
    before = edges[1:][None, :] <= shortest[:, None] - 1e-9
    after = edges[:-1][None, :] >= longest[:, None] + 1e-9
    assert np.all(transient[before | after] == 0.0)


def test_python_forward_of_a_path_and_of_the_scene_object_agree_with_the_cli(tmp_path, capsys):
    """analytic.forward(load_scene(path)) is what `forward` writes, for a path and for the loaded object."""
    tables = merged(BASE, LEGAL["tilted hidden rectangle"])
    scene_path = tmp_path / "wall.toml"
    scene_path.write_text(toml_text(tables))
    out = tmp_path / "out"
    assert_accepted(capsys, ["forward", scene_path, "--out", out, "--quiet"])
    from_cli = np.load(out / "transient.npy")
    scene = analytic.load_scene(str(scene_path))
    np.testing.assert_allclose(analytic.forward(scene), from_cli, rtol=1e-12, atol=0)
    matrix = analytic.system_matrix(scene)
    image = np.asarray(scene.reflectance, float).ravel()
    np.testing.assert_allclose((matrix @ image).reshape(from_cli.shape), from_cli, rtol=1e-9,
                               atol=1e-12 * from_cli.max())
