"""The reconstruct command: its files, metrics and figures, and its one-line refusals; it reads its
data while no command writes them, and keeps what float32 cannot hold in its float64 file."""

import json
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

from analytic.files import read_transient, save_npy
from analytic.measurement.noise import add_noise
from analytic.scenes.scene_file import load_scene
from analytic.operator.matrix_free import forward
from validation.cli import main

# reconstruct shows the inversion's warnings (a λ at the end of its grid, rank deficiency) on stderr
pytestmark = pytest.mark.filterwarnings("default::analytic.inversion.RegularizationWarning",
                                        "default::analytic.inversion.RankDeficiencyWarning")

SCENE = """
[plane]
pixels = 8
[source]
position = [0.5, 0.5, 1.0]
[sensors]
grid = [4, 4]
extent = 2.0
center = [0.5, 0.5, 1.0]
[sampling]
period = 0.05
start = 1.9
count = 40
[noise]
sigma = 0.001
seed = 3
"""


@pytest.fixture
def noisy_data(tmp_path):
    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(SCENE)
    scene = load_scene(scene_path)
    save_npy(tmp_path / "y.npy", add_noise(forward(scene), scene.noise))
    return scene_path, tmp_path / "y.npy"


def test_reconstruct_command_writes_its_files(tmp_path, noisy_data):
    scene_path, data = noisy_data
    assert main(["reconstruct", str(scene_path), "--data", str(data), "--out", str(tmp_path / "r"),
                 "--quiet"]) == 0
    names = {p.name for p in (tmp_path / "r").iterdir()}
    assert {"reconstruction.png", "reconstruction.exr", "reconstruction.npy", "metrics.json",
            "criterion.png", "comparison.png", "error.png", "report.md"} == names
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    # the scene knows σ, so the data-driven default is the discrepancy principle
    assert metrics["rule"] == "discrepancy" and metrics["data_range"] == 1.0
    assert metrics["psnr"] > 20  # a uniform 0.5 plane at σ = 1e-3
    image = read_transient(tmp_path / "r" / "reconstruction.exr")
    assert np.allclose(image, np.load(tmp_path / "r" / "reconstruction.npy"), atol=1e-6)
    report = (tmp_path / "r" / "report.md").read_text()
    assert "comparison.png" in report and "criterion.png" in report
    assert main(["reconstruct", str(scene_path), "--data", str(data), "--out", str(tmp_path / "tv"),
                 "--lambda", "oracle", "--regularizer", "tv", "--quiet"]) == 0
    tv = json.loads((tmp_path / "tv" / "metrics.json").read_text())
    assert tv["method"] == "pdhg" and tv["psnr"] > 20


def test_lambda_grid_options_set_the_searched_grid(tmp_path, noisy_data):
    scene_path, data = noisy_data
    assert main(["reconstruct", str(scene_path), "--data", str(data), "--out", str(tmp_path / "g"),
                 "--lambda", "gcv", "--lambda-range", "1e-6", "1e-2", "--lambda-count", "9",
                 "--quiet"]) == 0
    metrics = json.loads((tmp_path / "g" / "metrics.json").read_text())
    assert np.allclose(metrics["lambdas"], np.geomspace(1e-6, 1e-2, 9))


@pytest.mark.parametrize("extra, words", [
    (["--lambda", "best"], "--lambda"),
    (["--lambda", "gcv", "--regularizer", "tv"], "--lambda gcv"),
    (["--lambda", "-1"], "--lambda"),
    (["--lambda-range", "1", "0.1"], "--lambda-range"),
    (["--lambda-count", "5"], "--lambda-count"),
    (["--regularizer", "tv", "--lambda", "oracle", "--method", "svd"], "--method"),
])
def test_bad_options_end_in_one_line_and_no_files(tmp_path, noisy_data, capsys, extra, words):
    scene_path, data = noisy_data
    with pytest.raises(SystemExit) if extra[1] in ("best", "-1") else _returns(2) as outcome:
        outcome.value = main(["reconstruct", str(scene_path), "--data", str(data), "--out",
                              str(tmp_path / "s"), *extra])
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and words in error[0], error
    assert not (tmp_path / "s").exists()


def test_bad_data_and_a_missing_noise_level_end_in_one_line(tmp_path, noisy_data, capsys):
    scene_path, data = noisy_data
    assert main(["reconstruct", str(scene_path), "--data", str(tmp_path / "missing.npy"),
                 "--out", str(tmp_path / "s")]) == 2
    save_npy(tmp_path / "nan.npy", np.full((16, 40), np.nan))
    assert main(["reconstruct", str(scene_path), "--data", str(tmp_path / "nan.npy"),
                 "--out", str(tmp_path / "s")]) == 2
    scene_path.write_text(SCENE.split("[noise]")[0])
    assert main(["reconstruct", str(scene_path), "--data", str(data), "--out", str(tmp_path / "s"),
                 "--lambda", "discrepancy"]) == 2
    errors = capsys.readouterr().err.strip().splitlines()
    assert len(errors) == 3 and "missing.npy" in errors[0] and "NaN" in errors[1]
    assert "noise.sigma" in errors[2]
    assert not (tmp_path / "s").exists()


def test_data_another_command_is_writing_are_not_read(tmp_path, noisy_data, capsys, monkeypatch):
    """`reconstruct --data p/model/transient.npy` while `run --out p` writes p: one line naming run."""
    scene_path, data = noisy_data
    inside = tmp_path / "p" / "model" / "transient.npy"
    inside.parent.mkdir(parents=True)
    save_npy(inside, np.load(data))
    monkeypatch.setattr("analytic.files.locks.LOCK_WAIT_SECONDS", 0.2)
    writer = subprocess.Popen([sys.executable, "-c", textwrap.dedent("""
        import sys
        from analytic.files import output_folder
        with output_folder(sys.argv[1]):
            print("ready", flush=True)
            sys.stdin.readline()
        """), str(tmp_path / "p")], cwd=Path(__file__).resolve().parents[2], text=True,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    command = ["reconstruct", str(scene_path), "--data", str(inside), "--out", str(tmp_path / "r"), "--quiet"]
    try:
        assert writer.stdout.readline().strip() == "ready"
        assert main(command) == 2
    finally:
        writer.communicate("done\n", timeout=60)
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and f"process {writer.pid}" in error[0] and "--data" in error[0], error
    assert not (tmp_path / "r").exists()
    assert main(command) == 0                                   # once it is done


def test_a_reconstruction_float32_cannot_hold_stays_exact_in_its_npy(tmp_path, capsys):
    """A legal plane of reflectance 1e-39: float32 would write it as subnormal noise."""
    scene_path = tmp_path / "faint.toml"
    scene_path.write_text(SCENE.replace("pixels = 8", "pixels = 8\nreflectance = 1e-39").split("[noise]")[0])
    save_npy(tmp_path / "y.npy", forward(load_scene(scene_path)))
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "reconstruction.exr").write_bytes(b"an earlier run's")
    with warnings.catch_warnings():
        warnings.simplefilter("always")                # as a user sees them: the CLI prints one line each
        assert main(["reconstruct", str(scene_path), "--data", str(tmp_path / "y.npy"), "--out",
                     str(tmp_path / "r"), "--quiet"]) == 0
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "reconstruction.exr: not written" in lines[0] and "float32" in lines[0], lines
    assert not (tmp_path / "r" / "reconstruction.exr").exists()
    image = np.load(tmp_path / "r" / "reconstruction.npy")
    assert np.allclose(image, 1e-39, rtol=1e-3, atol=0)          # noiseless data give the plane back
    assert json.loads((tmp_path / "r" / "metrics.json").read_text())["exr"].startswith("not written")


class _returns:
    """Context that records a return value and checks it on exit (the twin of pytest.raises)."""

    def __init__(self, expected):
        self.expected = expected
        self.value = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        assert exc[0] is None and self.value == self.expected, self.value
        return False


ONE_SENSOR = """
[plane]
pixels = 4
[source]
position = [0.3, 0.4, 1.0]
[sensors]
positions = [[0.8, 0.65, 0.7]]
[sampling]
period = 0.01
start = 1.75
count = 70
[noise]
sigma = {sigma!r}
seed = 3
"""


def test_reconstruct_reports_what_the_data_fix_at_their_noise(tmp_path, capsys):
    """One sensor, 70 bins, 16 pixels: A has full rank, yet at a σ above most of its singular values the data
    fix few of the image's numbers. The report, metrics and summary line say how many (the singular values
    above σ, counted here by NumPy on the assembled A), and a warning says so when they are at most half."""
    from analytic.operator.system import system_matrix

    scene_path = tmp_path / "one.toml"
    scene_path.write_text(ONE_SENSOR.format(sigma=1e-9))
    values = np.linalg.svd(system_matrix(load_scene(scene_path)).toarray(), compute_uv=False)
    assert np.sum(values > values[0] * 1e-12) == 16                  # full rank: noiseless data fix all
    for kept, warned in ((5, True), (12, False)):
        sigma = float(np.sqrt(values[kept - 1] * values[kept]))      # between the kept-th and the next
        scene_path.write_text(ONE_SENSOR.format(sigma=sigma))
        scene = load_scene(scene_path)
        save_npy(tmp_path / "y.npy", add_noise(forward(scene), scene.noise))
        out = tmp_path / f"r{kept}"
        assert main(["reconstruct", str(scene_path), "--data", str(tmp_path / "y.npy"), "--out", str(out),
                     "--lambda", "gcv", "--lambda-range", "1e-12", "1e-2"]) == 0
        captured = capsys.readouterr()
        metrics = json.loads((out / "metrics.json").read_text())
        assert (metrics["rank"], metrics["effective_rank"], metrics["sigma"]) == (16, kept, sigma)
        assert 1.0 <= metrics["degrees_of_freedom"] <= 16.0
        fixed = f"the data fix about {kept} of the image's 16 numbers at σ = {sigma:g}"
        assert fixed in captured.out
        report = (out / "report.md").read_text()
        assert "| rank of A | 16 of 16 |" in report
        assert f"| fixed at the noise | {kept} of 16 (σ = {sigma:g}) |" in report
        shown = [line for line in captured.err.splitlines() if "the data fix about" in line]
        assert len(shown) == warned, captured.err
        if warned:
            assert shown[0].startswith(f"diffuse-imaging: warning: at σ = {sigma:g} the data fix about {kept} ")
            assert f"- warning: {shown[0].removeprefix('diffuse-imaging: warning: ')}" in report


def test_reconstruct_reports_its_exact_bias_and_variance_beside_the_bound(tmp_path, noisy_data, capsys):
    from analytic.inversion.bounds import crb
    from analytic.inversion.tikhonov_error import tikhonov_error

    scene_path, data = noisy_data
    assert main(["reconstruct", str(scene_path), "--data", str(data), "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    recorded = json.loads((tmp_path / "r" / "metrics.json").read_text())
    error, scene = recorded["tikhonov_error"], load_scene(scene_path)
    expected = tikhonov_error(_matrix(scene), scene.reflectance, recorded["lambda"], variance=scene.noise.sigma**2)
    assert error["bias_rms"] == pytest.approx(np.sqrt(np.mean(expected.bias**2)), rel=1e-9)
    assert error["stddev_median"] == pytest.approx(np.median(expected.stddev), rel=1e-9)
    assert error["crb_median"] == pytest.approx(np.median(crb(scene).image), rel=1e-9)
    assert f"standard deviation median {error['stddev_median']:.3g} per pixel" in out
    assert "error.png" in (tmp_path / "r" / "report.md").read_text()


def _matrix(scene):
    from analytic.operator.system import system_matrix
    return system_matrix(scene)
