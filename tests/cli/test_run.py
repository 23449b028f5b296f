"""The main job, ``run``, on the built-in scene: the render agrees, and the image comes back from noisy data."""

import json
import re

import numpy as np
import pytest

from validation.cli import main

SCHEMA = {"kind", "samples", "seed", "scene", "plane_size", "pixels", "source", "intensity",
          "sensor_positions", "attenuation", "illumination", "illumination_parameters", "tolerance",
          "window_share", "noise", "start_opl", "bin_width_opl", "bins", "sensors", "units"}


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "default"
    assert main(["run", "--out", str(out), "--spp", str(2**20), "--quiet"]) == 0
    return out


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
    from analytic.scene import default_scene
    from transient.render import render

    scene = default_scene(pixels=8)
    unit = render(scene.replace(intensity=1.0), spp=2**14, seed=5, progress=False)
    bright = render(scene, spp=2**14, seed=5, progress=False)
    np.testing.assert_allclose(bright.mean, scene.intensity * unit.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(bright.stderr, scene.intensity * unit.stderr, rtol=1e-9, atol=0)
