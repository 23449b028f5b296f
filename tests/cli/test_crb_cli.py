"""The crb command: its files (the same numbers as analytic.crb), its stderr line, and one-line refusals."""

import json

import numpy as np
import pytest

from analytic.inversion.bounds import crb
from analytic.measurement.detector import Detector
from analytic.scenes.scene_file import load_scene
from validation.cli import main

SCENE = """name = "small"
[plane]
size = 1.0
pixels = 4
reflectance = 0.5
[source]
position = [0.5, 0.5, 1.0]
intensity = 1e3
[sensors]
grid = [3, 3]
extent = 1.0
center = [0.5, 0.5, 1.0]
[sampling]
period = 0.1
start = 1.9
count = 12
"""


def _scene(tmp_path, extra="[noise]\nsigma = 0.1\n"):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE + extra)
    return path


def test_crb_writes_the_bounds_of_the_python_api(tmp_path, capsys):
    path = _scene(tmp_path)
    out = tmp_path / "out"
    assert main(["crb", str(path), "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    expected = crb(load_scene(path))
    np.testing.assert_array_equal(np.load(out / "crb.npy"), expected.image)
    record = json.loads((out / "crb.json").read_text())
    assert record["effective_rank"] == expected.effective_rank
    assert record["singular_values_above_one"] == expected.above_one.tolist()
    assert {p.name for p in out.iterdir()} >= {"crb.npy", "crb.json", "crb.png", "spectrum.png"}
    assert len(err) == 1 and f"fix {expected.effective_rank} of the image's 16 components" in err[0]


def test_counts_with_dead_time_are_bounded(tmp_path):
    path = _scene(tmp_path, "[detector]\nphotons = 0.5\nbackground = 1e-4\ncycles = 1e5\ndead_time = \"cycle\"\n")
    out = tmp_path / "out"
    assert main(["crb", str(path), "--out", str(out), "--quiet"]) == 0
    record = json.loads((out / "crb.json").read_text())
    assert "dead time cycle" in record["measurement"]
    # pile-up loses information: the dead-time bound is above the same detector's without it
    none = crb(load_scene(path).replace(detector=Detector(photons=0.5, background=1e-4, cycles=1e5)))
    assert np.all(np.load(out / "crb.npy") >= none.image)


@pytest.mark.parametrize("extra, args, word", [
    ("", [], "noise"),                                           # exact data have no bound
    ("[noise]\nsigma = 0.1\n", ["--free", "source.bogus"], "--free: 'source.bogus'"),
    ("[noise]\nsigma = 0.1\n", ["--measurement", "detector"], "detector"),
])
def test_bad_input_exits_2_with_one_line_and_no_files(tmp_path, capsys, extra, args, word):
    out = tmp_path / "out"
    assert main(["crb", str(_scene(tmp_path, extra)), "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("diffuse-imaging: error:") and word in err[0]
    assert not out.exists()
