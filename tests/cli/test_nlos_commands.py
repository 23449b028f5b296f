"""The commands on captures through a relay wall (docs/design.md section 7): forward, render (and its resume),
reconstruct, run, plot and validate; their files, shapes and numbers, the numbers against an independent
QUADPACK reference of the formula, and their one-line refusals."""

import json
import re
import warnings

import numpy as np
import pytest
from relay_wall_reference import brute_force_path_range, reference_bin

from analytic.files import read_transient
from analytic.scenes.scene_file import load_scene
from analytic.operator.matrix_free import forward
from validation.cli import main
from validation.judging.compare import compare_transients

# reconstruct and run show the inversion's warnings (a λ at the end of its grid, rank deficiency) on stderr
pytestmark = pytest.mark.filterwarnings("default::analytic.inversion.RegularizationWarning",
                                        "default::analytic.inversion.RankDeficiencyWarning")

# a small confocal capture: 3 x 3 points lit and read, a 6 x 6 hidden image (a bright stripe, columns 2 and 3,
# on a dark ground), 2 cm bins holding all the light, noise of about 0.5 % of the brightest bin
SCENE = """
name = "wall"
[relay_wall]
size = [2.0, 2.0]
reflectance = 0.9
[hidden]
center = [0.1, -0.1, 0.8]
u = [0.8, 0.0, 0.0]
v = [0.0, -0.8, 0.0]
pixels = 6
reflectance = "stripe.png"
[laser]
position = [-0.5, 0.0, 0.25]
intensity = 2.0
[sensor]
position = [-0.5, 0.0, 0.25]
[scan]
type = "confocal"
grid = [3, 3]
[sampling]
period = 0.02
start = 1.5
count = 120
[noise]
sigma = 2e-5
seed = 4
"""

#: The hidden image's two values, and its stripe's columns.
GROUND, STRIPE, COLUMNS = 0.2, 0.9, (2, 4)


def _write(folder, text, name="wall.toml"):
    from analytic.files import save_png_image

    image = np.full((6, 6), GROUND)
    image[:, COLUMNS[0]:COLUMNS[1]] = STRIPE
    save_png_image(folder / "stripe.png", image)
    path = folder / name
    path.write_text(text)
    return path


def _one_error_line(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("diffuse-imaging: error: "), lines
    return lines[0]


@pytest.fixture(scope="module")
def modelled(tmp_path_factory):
    """forward's folder of the capture, and the scene file."""
    folder = tmp_path_factory.mktemp("nlos")
    path = _write(folder, SCENE)
    assert main(["forward", str(path), "--out", str(folder / "model"), "--quiet"]) == 0
    return path, folder / "model"


def test_forward_writes_pairs_by_bins_and_the_relay_wall_metadata(modelled):
    path, out = modelled
    assert {p.name for p in out.iterdir()} == {"transient.npy", "transient.exr", "transient.h5", "meta.json",
                                               "transient.png", "transient_noisy.npy"}
    np.testing.assert_array_equal(read_transient(out / "transient.h5"), np.load(out / "transient.npy"))
    y = np.load(out / "transient.npy")
    assert y.shape == (9, 120) and y.dtype == np.float64
    np.testing.assert_allclose(read_transient(out / "transient.exr"), y, rtol=2**-23, atol=0)   # height P
    meta = json.loads((out / "meta.json").read_text())
    assert meta["geometry"] == "relay_wall" and meta["sensors"] == 9 and meta["bins"] == 120
    assert meta["pixels"] == 6 and meta["intensity"] == 2.0 and meta["window_share"] == 1.0
    assert meta["plane_size"] is None and meta["source"] is None and meta["sensor_positions"] is None
    assert meta["relay_wall"] == {"size": [2.0, 2.0], "reflectance": 0.9}
    assert meta["hidden"]["center"] == [0.1, -0.1, 0.8] and meta["hidden"]["reflectance"] is None
    assert abs(meta["hidden"]["reflectance_mean"] - (2 * GROUND + STRIPE) / 3) < 1e-4     # a 16-bit PNG
    assert meta["laser"] == {"position": [-0.5, 0.0, 0.25], "intensity": 2.0}
    assert meta["scan"] == {"type": "confocal", "grid": [3, 3], "laser_point": None, "laser_grid": None,
                            "account_first_and_last_bounces": False, "pairs": 9}
    assert "radiance leaving the read point" in meta["units"]
    assert (out / "transient.png").read_bytes()[:4] == b"\x89PNG"


def test_forward_numbers_match_the_independent_quadrature(modelled):
    """y[p, n] = ρ_ground H over the whole hidden rectangle + (ρ_stripe - ρ_ground) H over the stripe, each by
    QUADPACK: the brightest bin, and the bin holding the 90th percentile of the last pair's light."""
    path, out = modelled
    scene = load_scene(path)
    ground, stripe = scene.reflectance[0, 0], scene.reflectance[0, COLUMNS[0]]     # as the PNG holds them
    width, height = np.linalg.norm(scene.u), np.linalg.norm(scene.v)
    band = (COLUMNS[0] / 6 * width, COLUMNS[1] / 6 * width, 0.0, height)
    y = np.load(out / "transient.npy")
    picks = [np.unravel_index(np.argmax(y), y.shape)]
    for pair, share in ((len(y) - 1, 0.9),):
        picks.append((pair, int(np.searchsorted(np.cumsum(y[pair]) / y[pair].sum(), share))))
    for pair, n in picks:
        pair, n = int(pair), int(n)
        reference = ground * reference_bin(scene, pair, n) + (stripe - ground) * reference_bin(scene, pair, n, band)
        assert abs(y[pair, n] - reference) <= 1e-6 * y[pair].max(), (pair, n, y[pair, n], reference)


def test_window_auto_takes_the_bins_that_hold_every_path_legs_included(tmp_path, capsys):
    text = SCENE.replace('type = "confocal"', 'type = "single"\nlaser_point = [0.4, 0.3, 0.0]\n'
                                               'account_first_and_last_bounces = true')
    path = _write(tmp_path, text)
    assert main(["forward", str(path), "--window", "auto", "--out", str(tmp_path / "f"), "--quiet"]) == 0
    assert capsys.readouterr().err.startswith("diffuse-imaging: window: start ")
    meta = json.loads((tmp_path / "f" / "meta.json").read_text())
    low, high = brute_force_path_range(load_scene(path))     # legs added: 2.6 to 4.0 m, far from the scene's
    start, width, count = meta["start_opl"], meta["bin_width_opl"], meta["bins"]
    assert width == 0.02 and meta["window_share"] == 1.0
    # the first bin holds the first arrival and the last the longest path, on the grid t0 = j T
    assert start <= low < start + width and start + (count - 1) * width <= high < start + count * width
    assert abs(start / width - round(start / width)) < 1e-9


def test_render_agrees_with_forward_and_resumes_to_the_same_numbers(tmp_path, modelled):
    from transient.render import RenderInterrupted, render

    path, model = modelled
    scene = load_scene(path)
    assert main(["render", str(path), "--spp", str(2**17), "--seed", "2", "--out", str(tmp_path / "whole"),
                 "--quiet"]) == 0
    whole = tmp_path / "whole"
    assert {"transient.npy", "transient.exr", "transient.h5", "stderr.npy", "replicas.npy", "meta.json",
            "transient.png", "render_state.npz", "render_scene.npz"} == {p.name for p in whole.iterdir()}
    meta = json.loads((whole / "meta.json").read_text())
    assert meta["geometry"] == "relay_wall" and meta["samples"] == 2**17 and meta["complete"] is True
    replicas = np.load(whole / "replicas.npy")
    assert replicas.shape == (32, 9, 120)
    agreement = compare_transients(np.load(whole / "transient.npy"), np.load(whole / "stderr.npy"),
                                   np.load(model / "transient.npy"), dof=meta["dof"], replicas=replicas)
    assert agreement.agrees and agreement.bins > 100, agreement.summary()

    def stop(done):
        raise KeyboardInterrupt

    with pytest.raises(RenderInterrupted):      # Ctrl-C after the first chunk: its state is saved
        render(scene, spp=2**17, seed=2, out_dir=tmp_path / "part", progress=False, on_chunk=stop)
    assert not (tmp_path / "part" / "transient.npy").exists()
    assert main(["render", "--resume", str(tmp_path / "part"), "--quiet"]) == 0
    for name in ("transient.npy", "stderr.npy"):
        np.testing.assert_allclose(np.load(tmp_path / "part" / name), np.load(whole / name), rtol=1e-12, atol=0)


def test_resume_names_the_relay_wall_key_that_differs(tmp_path, capsys):
    from transient.render import RenderInterrupted, render

    path = _write(tmp_path, SCENE)

    def stop(done):
        raise KeyboardInterrupt

    with pytest.raises(RenderInterrupted):
        render(load_scene(path), spp=2**17, seed=1, out_dir=tmp_path / "part", progress=False, on_chunk=stop)
    moved = _write(tmp_path, SCENE.replace("center = [0.1, -0.1, 0.8]", "center = [0.1, -0.1, 0.9]"), "moved.toml")
    assert main(["render", str(moved), "--resume", str(tmp_path / "part"), "--quiet"]) == 2
    line = _one_error_line(capsys)
    assert "[hidden] center [0.1, -0.1, 0.9] (the state's: [0.1, -0.1, 0.8])" in line, line


def test_reconstruct_recovers_the_hidden_image_better_than_a_flat_one(tmp_path, modelled):
    from analytic.inversion import flat_image_psnr

    path, model = modelled
    assert main(["reconstruct", str(path), "--data", str(model / "transient_noisy.npy"), "--out", str(tmp_path / "r"),
                 "--quiet"]) == 0
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert metrics["rule"] == "discrepancy" and metrics["measurements"] == 9 * 120
    assert metrics["psnr"] >= flat_image_psnr(load_scene(path).reflectance) + 3.0, metrics["psnr"]
    assert np.load(tmp_path / "r" / "reconstruction.npy").shape == (6, 6)
    assert "9 pairs (confocal scan) x 120 bins" in (tmp_path / "r" / "report.md").read_text()


@pytest.fixture(scope="module")
def ran(tmp_path_factory):
    folder = tmp_path_factory.mktemp("nlos-run")
    path = _write(folder, SCENE)
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        assert main(["run", str(path), "--spp", str(2**16), "--out", str(folder / "run"), "--quiet"]) == 0
    return folder / "run"


def test_run_does_the_whole_job_on_a_relay_wall_capture(ran):
    assert {"report.md", "metrics.json", "model", "render", "transients.png", "z_map.png", "wall.png",
            "convergence.png", "reconstructions.png"} == {p.name for p in ran.iterdir()}
    metrics = json.loads((ran / "metrics.json").read_text())
    assert metrics["agreement"]["agrees"] and metrics["window_share"] == 1.0
    recon = metrics["reconstruction"]
    assert recon["rule"] == "discrepancy" and recon["noise"]["sigma"] == 2e-5
    for data in ("model", "render"):
        assert recon[data]["psnr"] <= recon["oracle"]["psnr"] + 0.5 and np.isfinite(recon[data]["lambda"])
    assert json.loads((ran / "render" / "meta.json").read_text())["replicas"] == 32      # its error's source
    for folder in ("model", "render"):
        meta = json.loads((ran / folder / "meta.json").read_text())
        assert meta["geometry"] == "relay_wall" and np.load(ran / folder / "transient.npy").shape == (9, 120)
    report = (ran / "report.md").read_text()
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert "wall.png" in links and all((ran / link).is_file() for link in links)


def test_plot_draws_a_capture_per_pair_from_its_folder_and_with_its_scene(tmp_path, modelled, ran, capsys):
    path, model = modelled
    assert main(["plot", str(ran / "render"), "--out", str(tmp_path / "p")]) == 0       # with its standard error
    assert "9 pairs x 120 bins" in capsys.readouterr().out
    assert [p.name for p in (tmp_path / "p").iterdir()] == ["transient.png"]
    bare = tmp_path / "bare.npy"
    np.save(bare, np.load(model / "transient.npy"))
    assert main(["plot", str(bare), "--scene", str(path), "--out", str(tmp_path / "q"), "--quiet"]) == 0
    assert (tmp_path / "q" / "transient.png").is_file()


@pytest.mark.slow      # 10 s; run (above) holds the same check and report of a relay-wall capture
def test_validate_judges_a_relay_wall_file(tmp_path):
    path = _write(tmp_path, SCENE)
    assert main(["validate", str(path), "--spp", str(2**16), "--fast", "--out", str(tmp_path / "v"), "--quiet"]) == 0
    metrics = json.loads((tmp_path / "v" / "metrics.json").read_text())
    assert metrics["all_agree"] and metrics["scenes"]["wall"]["agreement"]["agrees"]
    assert (tmp_path / "v" / "wall" / "wall.png").is_file() and (tmp_path / "v" / "wall" / "z_map.png").is_file()


def test_reconstruct_and_plot_read_the_captures_tal_layout(modelled, tmp_path):
    """transient.h5 (tal's NLOS layout) reads back as the capture's (P, N) data, in reconstruct and plot alike."""
    path, out = modelled
    from_h5, from_npy = tmp_path / "h5", tmp_path / "npy"
    for data, folder in ((out / "transient.h5", from_h5), (out / "transient.npy", from_npy)):
        assert main(["reconstruct", str(path), "--data", str(data), "--lambda", "0.5", "--out", str(folder),
                     "--quiet"]) == 0
    np.testing.assert_array_equal(np.load(from_h5 / "reconstruction.npy"), np.load(from_npy / "reconstruction.npy"))
    assert main(["plot", str(out / "transient.h5"), "--scene", str(path), "--out", str(tmp_path / "p"),
                 "--quiet"]) == 0
    assert (tmp_path / "p" / "transient.png").is_file()


def test_a_sweep_of_a_relay_wall_capture_is_refused_in_one_line(tmp_path, capsys):
    path = _write(tmp_path, SCENE)
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'scene = "{path.name}"\nsamples = 4096\n[grid]\n"hidden.pixels" = [4, 6]\n')
    out = tmp_path / "out"
    assert main(["sweep", str(sweep), "--out", str(out)]) == 2
    assert "relay_wall" in _one_error_line(capsys)
    assert not out.exists()


def test_forward_of_the_capture_matches_the_library(modelled):
    path, out = modelled
    np.testing.assert_array_equal(np.load(out / "transient.npy"), forward(load_scene(path)))
