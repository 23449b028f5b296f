"""The plot command: any transient we read drawn into --out/transient.png, on the time axis its file states
(or the scene's), and one-line refusals that write nothing."""

import json

import h5py
import numpy as np
import pytest

from interop.tal import capture as capture_module
from analytic.scenes.scene_file import load_scene
from analytic.operator.matrix_free import forward
from scene_files import write_scene
from validation.cli import main
from validation.cli.plot import read_for_plot

SCENE = """
[plane]
size = 1
pixels = 8
reflectance = 0.5
[source]
position = [0.5, 0.5, 1]
[sensors]
positions = [[0.2, 0.7, 1], [0.9, 0.1, 0.8]]
[sampling]
period = 0.1
start = 1.8
count = 12
"""

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _error_line(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("diffuse-imaging: error: "), lines
    return lines[0]


def _drew_only_the_figure(out) -> None:
    assert [path.name for path in out.iterdir()] == ["transient.png"]
    assert (out / "transient.png").read_bytes()[:8] == PNG_SIGNATURE


def test_plot_draws_our_model_folder_on_its_own_time_axis(tmp_path):
    scene_path = write_scene(tmp_path, SCENE)
    assert main(["forward", str(scene_path), "--out", str(tmp_path / "f"), "--quiet"]) == 0
    before = {path.name for path in tmp_path.iterdir()}
    assert main(["plot", str(tmp_path / "f"), "--out", str(tmp_path / "p"), "--quiet"]) == 0
    _drew_only_the_figure(tmp_path / "p")
    assert {path.name for path in tmp_path.iterdir()} == before | {"p"}          # nothing outside --out
    drawn = read_for_plot(tmp_path / "f")
    scene = load_scene(scene_path)
    assert drawn.sampling == scene.sampling and drawn.label == "model" and drawn.stderr is None
    np.testing.assert_array_equal(drawn.transient, forward(scene))
    # each of our files states the same time axis (meta.json beside it; tal's t_start and delta_t)
    for name in ("transient.npy", "transient.exr", "transient.h5"):
        assert read_for_plot(tmp_path / "f" / name).sampling == scene.sampling, name


def test_plot_of_a_render_draws_its_standard_error_and_a_partial_one_says_so(tmp_path, capsys):
    from transient.render import RenderInterrupted, render

    scene = load_scene(write_scene(tmp_path, SCENE))

    def stop(done):
        raise KeyboardInterrupt

    # 2^17 samples are 32 replicas of 4096: the first chunk (2^16) completes 16 of them
    with pytest.raises(RenderInterrupted):
        render(scene, spp=2**17, seed=1, out_dir=tmp_path / "r", progress=False, on_chunk=stop)
    assert main(["plot", str(tmp_path / "r"), "--out", str(tmp_path / "p"), "--quiet"]) == 2
    assert "partial estimate is in" in _error_line(capsys)
    assert not (tmp_path / "p").exists()
    partial = read_for_plot(tmp_path / "r" / "partial")
    assert partial.label == "render" and "PARTIAL" in partial.title and "16 replicas" in partial.title
    np.testing.assert_array_equal(partial.stderr, np.load(tmp_path / "r" / "partial" / "stderr.npy"))
    assert main(["plot", str(tmp_path / "r" / "partial"), "--out", str(tmp_path / "p"), "--quiet"]) == 0
    _drew_only_the_figure(tmp_path / "p")


def _enum(handle, key, names, value):
    dataset = handle.create_dataset(key, (1,), dtype=h5py.enum_dtype(dict(names), basetype="i"))
    dataset[0] = names[value]


def _tal_capture(path, H, grid, *, start, width):
    """A capture as tal writes one: H in T_Sx_Sy, the grid in X_Y_3, its own scene_info (YAML text)."""
    with h5py.File(path, "w") as handle:
        handle["H"] = H
        _enum(handle, "H_format", capture_module.H_FORMATS, "T_Sx_Sy")
        handle["sensor_grid_xyz"] = grid
        _enum(handle, "sensor_grid_format", capture_module.GRID_FORMATS, "X_Y_3")
        handle["laser_xyz"] = np.array([-0.5, 0.0, 0.25])
        handle["delta_t"], handle["t_start"] = width, start
        handle["t_accounts_first_and_last_bounces"] = False
        handle["scene_info"] = "written_by: tal"


def test_plot_draws_a_tal_capture_as_a_map_of_the_wall_and_traces(tmp_path):
    # one hidden point in front of a 6 x 5 grid on the wall: each grid point lights the bin of 2 |x - point|
    axis_x, axis_y = np.linspace(-1, 1, 6), np.linspace(-1, 1, 5)
    grid = np.stack(np.meshgrid(axis_x, axis_y, np.zeros(1), indexing="ij"), axis=-1)[:, :, 0, :]
    distance = np.linalg.norm(grid - np.array([0.3, -0.4, 1.0]), axis=-1)
    start, width, bins = 1.5, 0.01, 300
    H = np.zeros((bins, 6, 5))
    index = np.floor((2 * distance - start) / width).astype(int)
    for i in range(6):
        for j in range(5):
            H[index[i, j], i, j] = distance[i, j] ** -4
    _tal_capture(tmp_path / "scan.h5", H, grid, start=start, width=width)
    assert main(["plot", str(tmp_path / "scan.h5"), "--out", str(tmp_path / "p"), "--quiet"]) == 0
    _drew_only_the_figure(tmp_path / "p")
    drawn = read_for_plot(tmp_path / "scan.h5")
    assert drawn.sampling.start_opl == start and drawn.sampling.bin_width_opl == width
    assert drawn.sampling.count == bins and drawn.positions.shape == (30, 3)
    # point k of the flattened grid (x fastest, as a relay-wall scan's pairs) holds its own bin, at its own place
    k = 3 * 6 + 2
    np.testing.assert_array_equal(drawn.positions[k], grid[2, 3])
    assert np.argmax(drawn.transient[k]) == index[2, 3]


def test_plot_of_a_mitransient_film_needs_the_scene(tmp_path, capsys):
    scene_path = write_scene(tmp_path, SCENE)
    scene = load_scene(scene_path)
    y = forward(scene)
    np.save(tmp_path / "films.npy", y[:, None, None, :, None])          # (K, 1, 1, N, 1), as mitransient's
    assert main(["plot", str(tmp_path / "films.npy"), "--out", str(tmp_path / "p"), "--quiet"]) == 2
    line = _error_line(capsys)
    assert "mitransient film" in line and "--scene" in line and not (tmp_path / "p").exists()
    assert main(["plot", str(tmp_path / "films.npy"), "--scene", str(scene_path), "--out", str(tmp_path / "p"),
                 "--quiet"]) == 0
    _drew_only_the_figure(tmp_path / "p")
    drawn = read_for_plot(tmp_path / "films.npy", scene)
    np.testing.assert_array_equal(drawn.transient, y)
    assert drawn.sampling == scene.sampling


@pytest.mark.parametrize("case, words", [
    ("missing", "no such file"),
    ("bare", "no time axis"),
    ("nan", "NaN or infinite"),
    ("other time axis", "differs from the scene's"),
    ("text", "unknown format"),
])
def test_plot_refuses_what_it_cannot_draw_in_one_line_and_writes_nothing(tmp_path, capsys, case, words):
    scene_path = write_scene(tmp_path, SCENE)
    scene = load_scene(scene_path)
    arguments = []
    if case == "missing":
        path = tmp_path / "nowhere.npy"
    elif case == "bare":
        path = tmp_path / "y.npy"
        np.save(path, forward(scene))
    elif case == "nan":
        assert main(["forward", str(scene_path), "--out", str(tmp_path / "f"), "--quiet"]) == 0
        path = tmp_path / "f" / "transient.npy"
        y = np.load(path)
        y[0, 3] = np.nan
        np.save(path, y)
    elif case == "other time axis":
        assert main(["forward", str(scene_path), "--out", str(tmp_path / "f"), "--quiet"]) == 0
        path = tmp_path / "f"
        shifted = write_scene(tmp_path, SCENE.replace("start = 1.8", "start = 1.7"), "shifted.toml")
        arguments = ["--scene", str(shifted)]
    else:
        path = tmp_path / "notes.txt"
        path.write_text("not a transient")
    assert main(["plot", str(path), *arguments, "--out", str(tmp_path / "p"), "--quiet"]) == 2
    assert words in _error_line(capsys)
    assert not (tmp_path / "p").exists()


def test_plot_checks_the_shape_against_its_meta(tmp_path, capsys):
    scene_path = write_scene(tmp_path, SCENE)
    assert main(["forward", str(scene_path), "--out", str(tmp_path / "f"), "--quiet"]) == 0
    np.save(tmp_path / "f" / "transient.npy", np.ones((2, 11)))
    assert main(["plot", str(tmp_path / "f"), "--out", str(tmp_path / "p"), "--quiet"]) == 2
    assert "its meta.json says 2 sensors x 12 bins" in _error_line(capsys)
    meta = json.loads((tmp_path / "f" / "meta.json").read_text())
    assert meta["bins"] == 12 and not (tmp_path / "p").exists()
