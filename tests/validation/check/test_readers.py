"""validation.check.readers: files in every format a user brings, read back to the array written or refused
with a DataError naming the file; our render's own errors found beside its output."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from analytic.errors import DataError
from analytic.files import build_meta, save_exr, write_transient
from analytic.scenes.common import Sampling
from analytic.operator.matrix_free import forward
from check_cases import COUNT, START, WIDTH, noisy_replicas, render_folder, run_check, small_scene
from validation.check import check_transient, read_data, read_stderr
from validation.cli import main

# Synthetic replicas are few (6) and independent from bin to bin: the limits' fallback to independent
# bins, and its warning, are what tests/validation/test_compare.py tests; here they are expected.
pytestmark = pytest.mark.filterwarnings("ignore::validation.judging.compare.CorrelationWarning")


@pytest.fixture
def files(tmp_path, scene, model):
    """Our forward output folder, and stray arrays in the other formats."""
    out = tmp_path / "forward"
    write_transient(out, model, build_meta(scene, kind="model"))
    return out


def test_our_outputs_are_read_back(files, scene, model):
    assert np.array_equal(read_data(files, scene), model)
    assert np.array_equal(read_data(files / "transient.npy", scene), model)
    assert np.allclose(read_data(files / "transient.exr", scene), model.astype(np.float32), rtol=0, atol=0)


def test_wrong_time_axis_is_refused(tmp_path, scene, model):
    out = tmp_path / "late"
    late = scene.replace(sampling=Sampling(bin_width_opl=WIDTH, start_opl=START + WIDTH, count=COUNT))
    write_transient(out, model, build_meta(late, kind="model"))
    with pytest.raises(DataError, match="time axis"):
        read_data(out / "transient.npy", scene)
    save_exr(tmp_path / "wide.exr", model, {"start_opl": START, "bin_width_opl": 2 * WIDTH})
    with pytest.raises(DataError, match="time axis"):
        read_data(tmp_path / "wide.exr", scene)


def test_wrong_shape_nan_and_unknown_formats_are_refused(tmp_path, scene, model):
    np.save(tmp_path / "short.npy", model[:, :-1])
    with pytest.raises(DataError, match=r"short.npy: shape \(2, 23\) does not match"):
        read_data(tmp_path / "short.npy", scene)
    np.save(tmp_path / "transposed.npy", model.T)
    with pytest.raises(DataError, match="transposed"):
        read_data(tmp_path / "transposed.npy", scene)
    bad = model.copy()
    bad[1, 3] = np.nan
    np.save(tmp_path / "nan.npy", bad)
    with pytest.raises(DataError, match="NaN"):
        read_data(tmp_path / "nan.npy", scene)
    (tmp_path / "data.csv").write_text("1,2\n")
    with pytest.raises(DataError, match="unknown format"):
        read_data(tmp_path / "data.csv", scene)
    with pytest.raises(DataError, match="no such file"):
        read_data(tmp_path / "missing.npy", scene)
    np.save(tmp_path / "negative.npy", -np.ones_like(model))
    with pytest.raises(DataError, match="negative"):
        read_stderr(tmp_path / "negative.npy", scene)


def test_mitransient_film_arrays(tmp_path, scene, model):
    """mitransient's developed film: (height, width, bins, channels) per sensor, stacked per sensor."""
    films = model[:, None, None, :, None].astype(np.float32)            # (K, 1, 1, N, 1)
    np.save(tmp_path / "mono.npy", films)
    assert np.array_equal(read_data(tmp_path / "mono.npy", scene), films[:, 0, 0, :, 0])
    np.save(tmp_path / "rgb.npy", np.repeat(films, 3, axis=-1))
    assert np.array_equal(read_data(tmp_path / "rgb.npy", scene), films[:, 0, 0, :, 0])
    coloured = np.repeat(films, 3, axis=-1)
    coloured[..., 0] *= 2
    np.save(tmp_path / "coloured.npy", coloured)
    with pytest.raises(DataError, match="colour channels differ"):
        read_data(tmp_path / "coloured.npy", scene)
    np.save(tmp_path / "one.npy", films[0])                               # one sensor of two
    with pytest.raises(DataError, match="1 film"):
        read_data(tmp_path / "one.npy", scene)
    np.save(tmp_path / "camera.npy", np.zeros((2, 4, 4, COUNT, 1)))
    with pytest.raises(DataError, match="4 x 4 pixels"):
        read_data(tmp_path / "camera.npy", scene)


def test_mitransient_frame_folder(tmp_path, model):
    """mitransient.vis.save_frames: 000.exr, 001.exr, ... one 1 x 1 image (channel Y) per bin."""
    one = small_scene(sensors=[(0.8, 0.3, 1.0)])
    y = forward(one)
    folder = tmp_path / "frames"
    for n in range(COUNT):
        save_exr(folder / f"{n:03d}.exr", y[:, n].reshape(1, 1))
    assert np.allclose(read_data(folder, one), y.astype(np.float32), rtol=0, atol=0)
    (folder / f"{COUNT:03d}.exr").write_bytes((folder / "000.exr").read_bytes())
    with pytest.raises(DataError, match="shape"):
        read_data(folder, one)


def test_a_capture_with_sensors_sharing_a_point_is_read_in_order(tmp_path):
    """Two of the scene's sensors at one point: the file's two sensors there are taken in order."""
    scene = small_scene(sensors=[(0.8, 0.3, 1.0), (0.25, 0.7, 0.8), (0.8, 0.3, 1.0)])
    data = forward(scene) * np.array([[1.0], [2.0], [3.0]])         # rows told apart
    write_transient(tmp_path / "out", data, build_meta(scene, kind="model"))
    assert np.array_equal(read_data(tmp_path / "out" / "transient.h5", scene), data)
    fewer = small_scene(sensors=[(0.8, 0.3, 1.0), (0.25, 0.7, 0.8), (0.25, 0.7, 0.8)])
    with pytest.raises(DataError, match="only 1 sensor.s. of sensor_grid_xyz at the point of the scene's sensor 2"):
        read_data(tmp_path / "out" / "transient.h5", fewer)


def test_check_command_takes_our_renders_own_errors(tmp_path, scene_file):
    """`check` on our render's folder or transient.npy judges with its replicas.npy (sign flips, Student's
    t on R - 1 degrees of freedom), or without them with its stderr.npy and the render's dof."""
    from analytic.scenes.scene_file import load_scene

    assert main(["render", str(scene_file), "--spp", str(2**20), "--seed", "5", "--out", str(tmp_path / "r"),
                 "--quiet"]) == 0
    dof = json.loads((tmp_path / "r" / "meta.json").read_text())["dof"]
    for data in (tmp_path / "r", tmp_path / "r" / "transient.npy"):
        out = tmp_path / f"check_{data.name}"
        assert run_check(scene_file, "--data", data, "--out", out) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["agrees"] is True and metrics["judged_by"] == "replicas" and metrics["dof"] == dof
        assert metrics["null"] == "sign-flip"
    # the same numbers passed by hand
    replicas = np.load(tmp_path / "r" / "replicas.npy")
    from_file = load_scene(scene_file)          # its EXR holds the image in float32
    by_hand = check_transient(from_file, replicas)
    assert by_hand.dof == dof and by_hand.chi2_per_dof == pytest.approx(metrics["chi2_per_dof"], rel=1e-12)
    # without replicas.npy: stderr.npy, with the render's degrees of freedom
    (tmp_path / "r" / "replicas.npy").unlink()
    assert run_check(scene_file, "--data", tmp_path / "r", "--out", tmp_path / "by_stderr") == 0
    metrics = json.loads((tmp_path / "by_stderr" / "metrics.json").read_text())
    assert metrics["judged_by"] == "stderr" and metrics["dof"] == dof and metrics["null"] == "independent"
    mean, stderr = np.load(tmp_path / "r" / "transient.npy"), np.load(tmp_path / "r" / "stderr.npy")
    assert check_transient(from_file, mean, stderr=stderr, dof=dof).chi2_per_dof == pytest.approx(
        metrics["chi2_per_dof"], rel=1e-12)
    assert check_transient(from_file, mean, stderr=stderr).dof is None          # without dof: normal z
    # a bare (K, N) .npy elsewhere still needs --stderr
    np.save(tmp_path / "bare.npy", mean)
    assert run_check(scene_file, "--data", tmp_path / "bare.npy", "--out", tmp_path / "bare") == 2


def test_check_command_refuses_bad_input_in_one_line(tmp_path, scene_file, model, capsys):
    np.save(tmp_path / "y.npy", model)
    np.save(tmp_path / "short.npy", model[:, 1:])
    for argv, words in (((tmp_path / "y.npy",), "without errors"),
                        ((tmp_path / "y.npy", tmp_path / "y.npy", "--stderr", tmp_path / "y.npy"),
                         "--stderr: give it with one --data"),
                        ((tmp_path / "short.npy", "--shape-only"), "short.npy")):
        assert run_check(scene_file, "--data", *argv, "--out", tmp_path / "out") == 2
        error = capsys.readouterr().err.strip().splitlines()
        assert len(error) == 1 and words in error[0], error
    assert not (tmp_path / "out").exists()                   # nothing written before the refusal


def test_check_takes_the_replicas_beside_our_render(tmp_path, scene_file, scene, model, rng):
    folder = render_folder(tmp_path / "r", scene, noisy_replicas(model, rng, replicas=16))
    for data in (folder, folder / "transient.npy"):
        out = tmp_path / f"check_{data.name}"
        assert run_check(scene_file, "--data", data, "--out", out) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["judged_by"] == "replicas" and metrics["replicas"] == 16 and metrics["dof"] == 15
        assert metrics["null"] == "sign-flip"
    (folder / "replicas.npy").unlink()
    assert run_check(scene_file, "--data", folder, "--out", tmp_path / "by_stderr") == 0
    metrics = json.loads((tmp_path / "by_stderr" / "metrics.json").read_text())
    assert metrics["judged_by"] == "stderr" and metrics["dof"] == 15 and metrics["null"] == "independent"
    np.save(folder / "replicas.npy", noisy_replicas(model, rng, replicas=16))       # another render's
    assert run_check(scene_file, "--data", folder, "--out", tmp_path / "mixed") == 2
    assert not (tmp_path / "mixed").exists()


@pytest.mark.parametrize("text, refused", [
    ('{"start_opl": "abc", "bin_width_opl": 0.1}', True),      # ours in form, not in content: one line
    ('{"start_opl": NaN, "bin_width_opl": 0.1}', True),        # NaN compares false: would pass unchecked
    ('{"start_opl": 1' + 400 * '0' + ', "bin_width_opl": 0.1}', True),   # an int beyond float64
    ('{"start_opl": 1' + 5000 * '0' + ', "bin_width_opl": 0.1}', False),  # beyond Python's digit limit: not JSON
    ('[1, 2]', False),                                         # not ours: nothing to compare
    ('{"start_opl": 1.0}', False),
])
def test_a_meta_json_of_other_types_is_one_line_or_ignored(tmp_path, scene, model, text, refused):
    out = tmp_path / "forward"
    write_transient(out, model, build_meta(scene, kind="model"))
    (out / "meta.json").write_text(text)
    if refused:
        with pytest.raises(DataError, match="meta.json: start_opl .* are not two finite numbers"):
            read_data(out / "transient.npy", scene)
    else:
        assert np.array_equal(read_data(out / "transient.npy", scene), model)


def test_a_named_pipe_is_refused_not_waited_on(tmp_path, scene):
    os.mkfifo(tmp_path / "pipe.npy")
    with pytest.raises(DataError, match="not a file or folder"):
        read_data(tmp_path / "pipe.npy", scene)


def test_a_plane_capture_whose_times_count_the_legs_is_refused(tmp_path, scene, model):
    """t_accounts_first_and_last_bounces true adds |sensor point - sensor_xyz| to each sensor's path lengths
    (sensor_xyz is the sensors' centroid in ours): read as it stands it would be silently late by that."""
    import h5py

    write_transient(tmp_path / "out", model, build_meta(scene, kind="model"))
    path = tmp_path / "out" / "transient.h5"
    with h5py.File(path, "r+") as handle:
        del handle["t_accounts_first_and_last_bounces"]
        handle["t_accounts_first_and_last_bounces"] = True
    with pytest.raises(DataError, match="t_accounts_first_and_last_bounces is true"):
        read_data(path, scene)


def test_a_meta_json_with_a_byte_order_mark_is_read_as_utf8(tmp_path, scene, model):
    """A meta.json an editor saved with a UTF-8 byte-order mark still states the time axis: it was skipped
    as "not ours" (json refuses the mark), so a wrong axis went unchecked."""
    out = tmp_path / "late"
    late = scene.replace(sampling=Sampling(bin_width_opl=WIDTH, start_opl=START + WIDTH, count=COUNT))
    write_transient(out, model, build_meta(late, kind="model"))
    (out / "meta.json").write_bytes(b"\xef\xbb\xbf" + (out / "meta.json").read_bytes())
    with pytest.raises(DataError, match="time axis"):
        read_data(out / "transient.npy", scene)
