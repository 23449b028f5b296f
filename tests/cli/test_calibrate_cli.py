"""diffuse-imaging calibrate: its files, the time axis a capture states as time zero's start, refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from analytic.operator.parameters import with_values
from analytic.operator.matrix_free import forward
from analytic.scenes.scene_file import load_scene
from validation.cli import main

SCENE = """
name = "small"
[plane]
size = 1.0
pixels = 1
reflectance = 0.5
[illumination]
waveform = "square"
width = 0.05
[sensors]
positions = [[0.2, 0.7, 1.0], [0.8, 0.3, 0.9], [0.5, 0.2, 1.1]]
[sampling]
period = 0.05
start = {start}
count = 24
"""


def capture(folder, *, scene_start=1.80, stated_start=1.85, true_start=1.835, height=1.002, seed=0):
    """A scene file (time zero ``scene_start``) and a capture of it whose meta.json states ``stated_start``
    while its light is that of ``true_start``, with sensor 0 at ``height`` (1 m in the scene file); (scene, data,
    stderr) paths."""
    scene_path = folder / "scene.toml"
    scene_path.write_text(SCENE.format(start=scene_start))
    truth = with_values(load_scene(scene_path), {"sampling.start": true_start, "sensors.positions.0.z": height})
    y = forward(truth)
    sigma = np.full(y.shape, 0.01 * y.max())
    data = folder / "capture"
    data.mkdir()
    np.save(data / "transient.npy", y + sigma * np.random.default_rng(seed).standard_normal(y.shape))
    (data / "meta.json").write_text(json.dumps({"start_opl": stated_start, "bin_width_opl": 0.05}))
    np.save(folder / "stderr.npy", sigma)
    return scene_path, data / "transient.npy", folder / "stderr.npy"


def test_calibrate_starts_time_zero_at_the_stated_axis_and_writes_the_fitted_scene(tmp_path, capsys):
    scene, data, stderr = capture(tmp_path)
    out = tmp_path / "out"
    status = main(["calibrate", str(scene), "--data", str(data), "--stderr", str(stderr), "--free",
                   "sampling.start", "sensors.positions.0.z", "--out", str(out)])
    printed = capsys.readouterr().out
    assert status == 0, printed
    content = json.loads((out / "calibration.json").read_text())
    start = content["parameters"]["sampling.start"]
    assert start["start"] == 1.85                      # the capture's stated axis, not the scene file's 1.80
    assert abs(start["value"] - 1.835) < 4.5 * start["stderr"]
    assert content["converged"] and content["agrees"] and set(content["scale"]) == {"value", "stderr"}
    assert content["covariance"]["names"] == ["sampling.start", "sensors.positions.0.z", "scale"]
    fitted = load_scene(out / "scene.toml")
    assert fitted.sampling.start_opl == start["value"]
    assert fitted.sensors[0, 2] == content["parameters"]["sensors.positions.0.z"]["value"]
    assert np.array_equal(fitted.sensors[1:], load_scene(scene).sensors[1:])
    report = (out / "report.md").read_text()
    assert "calibration_residuals.png" in report and (out / "calibration_residuals.png").stat().st_size > 0
    assert "sampling.start: 1.85 -> " in printed


def test_a_capture_off_the_scenes_axis_is_refused_unless_time_zero_is_free(tmp_path, capsys):
    scene, data, stderr = capture(tmp_path)
    out = tmp_path / "out"
    status = main(["calibrate", str(scene), "--data", str(data), "--stderr", str(stderr), "--free",
                   "sensors.positions.0.z", "--out", str(out)])
    lines = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "time axis" in lines[0], lines
    assert not out.exists()


@pytest.mark.parametrize("free, words", [
    (["sensors.positions.7.z"], "the scene has 3 sensors"),
    (["source.position.w"], "is no parameter"),
    (["sampling.start", "sampling.start"], "give it once"),
])
def test_a_bad_key_is_one_line_before_any_file(tmp_path, capsys, free, words):
    scene, data, stderr = capture(tmp_path)
    out = tmp_path / "out"
    status = main(["calibrate", str(scene), "--data", str(data), "--stderr", str(stderr), "--free", *free,
                   "--out", str(out)])
    lines = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and lines[0].startswith("diffuse-imaging: error: --free: "), lines
    assert words in lines[0]
    assert not out.exists()


def test_a_fit_that_cannot_explain_the_data_exits_1_with_its_files(tmp_path, capsys):
    """Sensor 0 is 3 cm high in the capture, but only time zero is free: the fit converges and the data
    still disagree with it (exit 1), its files written all the same."""
    scene, data, stderr = capture(tmp_path, scene_start=1.85, stated_start=1.85, true_start=1.85, height=1.03)
    out = tmp_path / "out"
    status = main(["calibrate", str(scene), "--data", str(data), "--stderr", str(stderr), "--free",
                   "sampling.start", "--fixed-scale", "--out", str(out)])
    printed = capsys.readouterr().out
    content = json.loads((out / "calibration.json").read_text())
    assert status == 1 and "DISAGREE" in printed, printed
    assert content["converged"] and not content["agrees"] and content["scale"] == {"value": 1.0, "stderr": 0.0}
    assert (out / "scene.toml").is_file() and (out / "report.md").is_file()


def test_a_transient_without_errors_is_refused_in_calibrates_words(tmp_path, capsys):
    scene, data, _ = capture(tmp_path)
    status = main(["calibrate", str(scene), "--data", str(tmp_path / "stderr.npy"), "--free", "sampling.start",
                   "--out", str(tmp_path / "out")])
    lines = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "--stderr FILE" in lines[0] and "--counts" in lines[0], lines
    assert "shape" not in lines[0]
