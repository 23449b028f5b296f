"""The main job, ``run``, on the built-in scene: the render agrees, and the image comes back from noisy data."""

import json
import re
import warnings

import numpy as np
import pytest

from validation.cli import main

SCHEMA = {"kind", "samples", "seed", "scene", "plane_size", "pixels", "source", "intensity",
          "sensor_positions", "attenuation", "illumination", "illumination_parameters", "tolerance",
          "window_share", "noise", "start_opl", "bin_width_opl", "bins", "sensors", "units"}


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    # 16 sensors x 12 bins fix 124 of the 2500 pixels, the letter's own set-up: stated in the report, not a
    # warning (warnings are errors here), since the Laplacian prior filling the rest is the method
    out = tmp_path_factory.mktemp("run") / "default"
    assert main(["run", "--out", str(out), "--spp", str(2**20), "--quiet"]) == 0
    return out


def test_run_states_what_the_data_fix_on_the_letters_scene(run_folder):
    """The built-in scene's A has rank 124 (192 rows for 50² pixels); at σ = 0.1 the data fix the singular
    values of A above it, counted here by NumPy on the assembled A; the report's sentence says both."""
    from analytic.scenes.common import default_scene
    from analytic.operator.system import system_matrix

    values = np.linalg.svd(system_matrix(default_scene()).toarray(), compute_uv=False)
    information = json.loads((run_folder / "metrics.json").read_text())["reconstruction"]["information"]
    assert information["rank"] == np.sum(values > values[0] * 2500 * np.finfo(float).eps) == 124
    assert information["effective_rank"] == np.sum(values > 0.1)
    assert information["sigma"] == 0.1 and information["unknowns"] == 2500
    report = (run_folder / "report.md").read_text()
    assert (f"The data fix about {information['effective_rank']} of the image's 2500 numbers at σ = 0.1 "
            f"(singular values of A/σ above 1; A's rank, what noiseless data would fix, is 124)") in report


def test_run_reconstructs_from_noisy_data_better_than_a_flat_image(run_folder):
    metrics = json.loads((run_folder / "metrics.json").read_text())
    recon = metrics["reconstruction"]
    # the built-in scene knows its σ: the data-driven rule is the discrepancy principle
    assert recon["rule"] == "discrepancy" and recon["noise"]["sigma"] == 0.1
    for data in ("model", "render"):
        assert set(recon[data]) >= {"psnr", "ssim", "lambda"}
        assert recon[data]["psnr"] >= recon["flat_psnr"] + 3.0, (data, recon[data], recon["flat_psnr"])
        assert recon[data]["psnr"] <= recon["oracle"]["psnr"] + 0.5      # the oracle is a bound
    assert metrics["agreement"]["agrees"] and metrics["window_share"] == 1.0


def test_run_reports_the_model_estimates_exact_error_beside_the_bound(run_folder):
    """The letter's scene: the Tikhonov estimate's rms error predicted exactly at its λ, while no unbiased
    estimate of any pixel exists (192 samples for 2500 pixels: the Cramér-Rao bound is inf everywhere)."""
    recon = json.loads((run_folder / "metrics.json").read_text())["reconstruction"]
    error = recon["error"]
    assert error["lambda"] == recon["model"]["lambda"] and error["crb_unbounded_pixels"] == 2500
    # PSNR over a data range of 1 is -20 log10(rms error): one draw's error against its expectation
    assert abs(-20 * np.log10(error["rmse_expected"]) - recon["model"]["psnr"]) < 0.5


def test_run_states_what_its_render_can_detect(run_folder):
    """metrics.json and report.md carry `detectable`, the directed tests' power (docs/design.md section 6)."""
    metrics = json.loads((run_folder / "metrics.json").read_text())
    detectable = metrics["detectable"]
    assert 0 < detectable["scale"] < 0.01 and 0 < detectable["shift_opl"] < 0.1        # bins of 0.1 m
    assert metrics["agreement"]["detectable"] == detectable and metrics["agreement"]["directed"]["agrees"]
    assert "detectable (flagged half the time)" in (run_folder / "report.md").read_text()


def test_run_report_links_only_files_that_exist(run_folder):
    report = (run_folder / "report.md").read_text()
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert links and all((run_folder / link).is_file() for link in links)
    assert "discrepancy rule" in report                    # which data and which rule, in words


def test_run_puts_its_figures_beside_its_report(run_folder):
    # one scene: no folder named after it (its name would otherwise decide where files go)
    assert {path.name for path in run_folder.iterdir()} == {
        "report.md", "metrics.json", "model", "render", "transients.png", "z_map.png", "convergence.png",
        "reconstructions.png"}
    report = (run_folder / "report.md").read_text()
    # the chosen λ of both reconstructions is in the report, beside what each column means
    recon = json.loads((run_folder / "metrics.json").read_text())["reconstruction"]
    for data in ("model", "render"):
        assert f"{recon[data]['lambda']:.3g}" in report
    assert "- **eq. (1): error / shape error**:" in report


def test_the_metadata_schema_is_the_same_for_every_command(run_folder, tmp_path):
    assert main(["forward", "--out", str(tmp_path / "forward"), "--quiet"]) == 0
    assert main(["render", "--spp", "4096", "--out", str(tmp_path / "render"), "--quiet"]) == 0
    metas = {"forward": tmp_path / "forward", "render": tmp_path / "render",
             "run model": run_folder / "model", "run render": run_folder / "render"}
    keys = {}
    for name, folder in metas.items():
        meta = json.loads((folder / "meta.json").read_text())
        assert SCHEMA <= set(meta), (name, SCHEMA - set(meta))
        assert meta["illumination"] == "impulse" and meta["intensity"] == 1e4 and meta["bins"] == 12
        keys[name] = set(meta) & SCHEMA
    assert len({frozenset(k) for k in keys.values()}) == 1
    assert json.loads((tmp_path / "render" / "meta.json").read_text())["kind"] == "render"


def test_intensity_scales_the_render_exactly(tmp_path):
    from analytic.scenes.common import default_scene
    from transient.render import render

    scene = default_scene(pixels=8)
    unit = render(scene.replace(intensity=1.0), spp=2**14, seed=5, progress=False)
    bright = render(scene, spp=2**14, seed=5, progress=False)
    np.testing.assert_allclose(bright.mean, scene.intensity * unit.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(bright.stderr, scene.intensity * unit.stderr, rtol=1e-9, atol=0)


# -- warnings that change what a number means: on stderr in one line, and in the report ----------------

ONE_SENSOR = """
[plane]
size = 1
pixels = 8
reflectance = 0.5
[source]
position = [0.5, 0.5, 1]
[sensors]
positions = [[0.2, 0.7, 1]]
[sampling]
period = 0.1
start = 1.9
count = 12
"""
NOISY = "\n[noise]\nsigma = 1.0\n"          # far above every singular value of A (at most about 0.01)


@pytest.fixture
def one_sensor_data(tmp_path):
    """One sensor's 12 bins for 64 pixels, and the model's transient of them (noiseless)."""
    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(ONE_SENSOR)
    assert main(["forward", str(scene_path), "--out", str(tmp_path / "f"), "--quiet"]) == 0
    return scene_path, tmp_path / "f"


def _warning_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("diffuse-imaging: warning: ")]


@pytest.mark.filterwarnings("default::analytic.inversion.RankDeficiencyWarning",
                            "default::analytic.inversion.RegularizationWarning")
def test_reconstruct_shows_its_warnings_on_stderr_and_in_its_report(tmp_path, one_sensor_data, capsys):
    scene_path, data = one_sensor_data
    scene_path.write_text(ONE_SENSOR + NOISY)
    # at σ = 1 the data fix none of the 64 pixels, and a grid far above every useful λ puts the optimum at its end
    assert main(["reconstruct", str(scene_path), "--data", str(data), "--out", str(tmp_path / "r"), "--lambda",
                 "gcv", "--lambda-range", "1e6", "1e8", "--lambda-count", "5", "--quiet"]) == 0
    shown = _warning_lines(capsys.readouterr().err)
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert metrics["rank"] is not None and metrics["rank"] <= 12 < metrics["unknowns"] == 64
    assert metrics["effective_rank"] == 0
    assert any("at σ = 1 the data fix about 0 of the image's 64 numbers" in line for line in shown), shown
    assert any("optimum is at the" in line and "of the grid" in line for line in shown), shown
    report = (tmp_path / "r" / "report.md").read_text()
    for line in shown:
        assert f"- warning: {line.removeprefix('diffuse-imaging: warning: ')}" in report
    # the report gives λ, and says in words what each of its numbers means
    assert f"| λ | {metrics['lambda']:.4g} |" in report and "- **λ**: the weight of the penalty" in report
    for name in ("rule", "PSNR (dB)", "SSIM", "‖A f − y‖", "‖D f‖", "rank of A", "fixed at the noise",
                 "degrees of freedom", "m"):
        assert f"- **{name}**: " in report, name


@pytest.mark.filterwarnings("default::analytic.operator.window.WindowWarning",
                            "default::analytic.inversion.RankDeficiencyWarning",
                            "default::analytic.inversion.RegularizationWarning")
def test_run_window_auto_states_and_records_the_covering_window(tmp_path, capsys):
    # in-process (not a subprocess): each run saves ~5 s of imports; the lines are the CLI's own stderr
    from analytic.scenes.scene_file import load_scene
    from analytic.operator.window import covering_sampling

    scene_path = tmp_path / "wide.toml"
    scene_path.write_text(ONE_SENSOR.replace("start = 1.9\ncount = 12", "start = 0\ncount = 40"))
    covering = covering_sampling(load_scene(scene_path), 0.1)
    assert (covering.start_opl, covering.count) == (2.0, 7)        # the light spans [2.03, 2.68] m
    assert main(["run", str(scene_path), "--window", "auto", "--spp", "8192", "--out", str(tmp_path / "run"),
                 "--quiet"]) == 0
    stderr = capsys.readouterr().err
    assert "diffuse-imaging: window: start 2 m, count 7 " in stderr
    assert "mostly empty" not in stderr
    for part in ("model", "render"):
        meta = json.loads((tmp_path / "run" / part / "meta.json").read_text())
        assert (meta["start_opl"], meta["bins"]) == (2.0, 7), part
    assert main(["run", str(scene_path), "--spp", "8192", "--out", str(tmp_path / "scene"), "--quiet"]) == 0
    stderr = capsys.readouterr().err
    assert len([line for line in _warning_lines(stderr) if "is mostly empty" in line]) == 1, stderr


def test_run_shows_each_reconstruction_warning_naming_its_data():
    """What run's reconstructions warned about (kept by the harness as category and message) is shown again,
    each in its own class, so the one-line policy shows it on stderr."""
    from analytic.inversion import NoiseLimitWarning, RankDeficiencyWarning, RegularizationWarning
    from validation.cli.checks import show_reconstruction_warnings

    reconstructions = {
        "warnings": [{"category": "NoiseLimitWarning", "message": "at σ = 1 the data fix about 0"}],
        "model": {"warnings": [{"category": "RankDeficiencyWarning", "message": "A has rank 7 for 64 unknowns"}]},
        "render": {"warnings": [{"category": "RegularizationWarning", "message": "the gcv optimum is at the "
                                                                                "largest λ of the grid"}]},
        "oracle": {"warnings": [{"category": "RegularizationWarning", "message": "not shown: a bound"}]},
    }
    with pytest.warns(Warning) as caught:
        show_reconstruction_warnings(reconstructions)
    assert [(w.category, str(w.message)) for w in caught] == [
        (NoiseLimitWarning, "reconstruction from the scene: at σ = 1 the data fix about 0"),
        (RankDeficiencyWarning, "reconstruction from the model's data: A has rank 7 for 64 unknowns"),
        (RegularizationWarning, "reconstruction from the render's data: the gcv optimum is at the largest λ of "
                                "the grid")]
    show_reconstruction_warnings({"model": {"psnr": 20.0}})          # none kept: nothing shown


@pytest.mark.filterwarnings("default::analytic.inversion.RankDeficiencyWarning",
                            "default::analytic.inversion.RegularizationWarning")
def test_run_shows_the_reconstructions_warnings_on_stderr_and_in_its_report(tmp_path, capsys):
    """Two sensors' 24 bins at σ = 1, far above every singular value of A: the data fix none of the 64
    pixels. Said once (it concerns A and σ, the same for the model's and the render's data), in one line,
    and in the report. In-process (the CLI's own warning policy writes the lines)."""
    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(ONE_SENSOR.replace("[[0.2, 0.7, 1]]", "[[0.2, 0.7, 1], [0.8, 0.3, 1]]") + NOISY)
    assert main(["run", str(scene_path), "--spp", "8192", "--out", str(tmp_path / "run")]) == 0
    captured = capsys.readouterr()
    shown = _warning_lines(captured.err)
    lines = [line for line in shown if "the data fix about" in line]
    assert lines == [line for line in shown if line.startswith("diffuse-imaging: warning: reconstruction from the "
                                                               "scene: at σ = 1 the data fix about 0 of the image's "
                                                               "64 numbers")] and len(lines) == 1, shown
    assert "the data fix about 0 of the image's 64 numbers at σ = 1" in captured.out
    report = (tmp_path / "run" / "report.md").read_text()
    assert "Warning: at σ = 1 the data fix about 0 of the image's 64 numbers" in report
    recon = json.loads((tmp_path / "run" / "metrics.json").read_text())["reconstruction"]
    assert recon["information"]["effective_rank"] == 0 and len(recon["warnings"]) == 1
