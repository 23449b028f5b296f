"""The shipped examples: every scene file loads and models, each shows what its header says, and the
tutorial runs.

The README lists the example files (``examples/...``) and its tour runs them
(``tests/test_docs.py``); here each scene is held to its own claim: the
paper's set-up is the built-in scene, the pulses and noise are the ones
named, every window holds all the light, the images are what
``examples/make_image.py`` writes.
"""

from __future__ import annotations

import functools
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import analytic
from analytic.operator.window import FULL_SHARE, window_share

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
SCENES = sorted(EXAMPLES.glob("*.toml"))
#: Every scene a user may give a command: our TOML files and tal's YAML configurations.
EVERY_SCENE = SCENES + sorted((EXAMPLES / "tal").glob("*.yaml"))


def test_the_examples_cover_each_feature():
    names = {path.stem for path in SCENES}
    assert {"paper", "square", "butterworth", "image", "counts", "far", "nlos"} <= names


@functools.lru_cache(maxsize=None)
def modelled(path: Path):
    """(scene, y) of an example, modelled once per test session."""
    scene = analytic.load_scene(path)
    return scene, analytic.forward(scene)


@pytest.mark.parametrize("path", SCENES, ids=lambda path: path.name)
def test_each_example_loads_and_models_a_finite_nonzero_transient(path):
    scene, y = modelled(path)
    assert y.shape == (scene.sensor_count, scene.sampling.count)
    assert np.all(np.isfinite(y))
    if scene.illumination.waveform != "butterworth":   # the Butterworth pulse undershoots, so y may too
        assert np.all(y >= 0)
    assert np.all(y.sum(axis=1) > 0)                   # every sensor sees light in the window


@pytest.mark.parametrize("path", EVERY_SCENE, ids=lambda path: path.name)
def test_each_examples_window_holds_all_its_light(path, monkeypatch):
    monkeypatch.chdir(ROOT)                 # tal's OBJ file names are relative to the working folder, as tal's
    scene = analytic.load_scene(path)
    assert window_share(scene) >= FULL_SHARE
    first, last = analytic.response_range(scene)
    edges = scene.sampling.edges
    assert edges[0] < first and edges[-1] > last       # the first and the longest paths inside


@pytest.mark.slow          # tal's confocal example: about a minute of assembly
@pytest.mark.parametrize("path", EVERY_SCENE, ids=lambda path: path.name)
def test_forward_on_each_example_prints_nothing_but_its_summary(path, tmp_path):
    """What a new user runs first: no warning (a window that cuts the light, tal's notes) on any shipped example."""
    done = subprocess.run([sys.executable, "-m", "validation.cli", "forward", str(path), "--out", str(tmp_path / "f")],
                          capture_output=True, text=True, cwd=ROOT, timeout=900)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert done.stdout.startswith("forward: ") and len(done.stdout.splitlines()) == 1, done.stdout


def test_paper_is_the_built_in_scene_as_a_file():
    """Same geometry, pulse, window, intensity and noise; the pattern to its 16-bit PNG's rounding."""
    paper, built_in = analytic.load_scene(EXAMPLES / "paper.toml"), analytic.default_scene()
    assert paper.pixels == built_in.pixels and paper.size == built_in.size
    np.testing.assert_array_equal(paper.source, built_in.source)
    np.testing.assert_array_equal(paper.sensors, built_in.sensors)
    assert paper.intensity == built_in.intensity
    assert paper.sampling == built_in.sampling and paper.illumination == built_in.illumination
    assert paper.noise == built_in.noise and paper.attenuation == built_in.attenuation
    assert np.abs(paper.reflectance - built_in.reflectance).max() <= 0.5 / 65535 + 1e-12


def test_nlos_is_a_confocal_capture_of_the_built_in_pattern():
    """A relay-wall capture, confocal 8 x 8, whose hidden image is the built-in pattern (to its 16-bit PNG's
    rounding), with the noise its header states: sigma 0.3 % of the brightest bin."""
    scene, y = modelled(EXAMPLES / "nlos.toml")
    assert isinstance(scene, analytic.RelayWallScene)
    assert scene.scan.type == "confocal" and scene.scan.grid == (8, 8) and scene.sensor_count == 64
    pattern = analytic.builtin_reflectance(scene.pixels)
    assert np.abs(scene.reflectance - pattern).max() <= 0.5 / 65535 + 1e-12
    assert 0.002 <= scene.noise.sigma / y.max() <= 0.004, scene.noise.sigma / y.max()


def test_the_pulses_and_the_noise_are_the_ones_named():
    load = lambda name: analytic.load_scene(EXAMPLES / f"{name}.toml")    # noqa: E731
    assert load("square").illumination.waveform == "square"
    assert load("butterworth").illumination.waveform == "butterworth"
    assert load("counts").noise.kind == "poisson" and load("far").noise.kind == "poisson"
    assert load("paper").illumination.waveform == "impulse"


def expected_photons(scene, cells: int = 400) -> np.ndarray:
    """Expected photons per sensor over a window holding all the light: photons · I ∫ f a_k dx, impulse.

    A midpoint sum of design.md section 2's Lambertian attenuation over
    ``cells`` x ``cells`` cells that tile each pixel exactly (nothing from
    the model): the impulse's unit area makes each sensor's total the
    integral itself.
    """
    side = scene.size / cells
    centres = (np.arange(cells) + 0.5) * side
    x, y = np.meshgrid(centres, centres)                # y up, x to the right
    rows = ((scene.size - y) / (scene.size / scene.pixels)).astype(int)
    columns = (x / (scene.size / scene.pixels)).astype(int)
    reflectance = scene.reflectance[rows, columns]
    points = np.stack([x, y, np.zeros_like(x)], axis=-1)
    to_source = np.linalg.norm(points - scene.source, axis=-1)
    totals = []
    for sensor in scene.sensors:
        to_sensor = np.linalg.norm(points - sensor, axis=-1)
        attenuation = (scene.source[2] / to_source) * (sensor[2] / to_sensor) / (np.pi * to_source**2 * to_sensor**2)
        totals.append(scene.intensity * np.sum(reflectance * attenuation) * side**2)
    return scene.noise.photons * np.array(totals)


def test_the_photon_counts_the_headers_state():
    """counts.toml: 530 to 860 expected photons per sensor; far.toml: about 100 (an independent integral)."""
    for name, low, high in (("counts", 530, 860), ("far", 95, 105)):
        scene = analytic.load_scene(EXAMPLES / f"{name}.toml")
        assert scene.illumination.waveform == "impulse"
        photons = expected_photons(scene)
        assert low <= photons.min() and photons.max() <= high, (name, photons.min(), photons.max())


def test_the_images_are_what_make_image_writes(tmp_path):
    subprocess.run([sys.executable, str(EXAMPLES / "make_image.py"), str(tmp_path)], check=True,
                   capture_output=True)
    for name, pixels in (("pattern.png", 50), ("hidden.png", 16), ("shapes.png", 32)):
        shipped = analytic.read_reflectance(EXAMPLES / name, pixels)
        made = analytic.read_reflectance(tmp_path / name, pixels)
        np.testing.assert_array_equal(shipped, made)


def test_every_example_the_readme_names_exists():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    named = set(re.findall(r"examples/[\w.-]+\.\w+", readme))
    assert named, "the README names no example"
    missing = sorted(name for name in named if not (ROOT / name).exists())
    assert not missing, missing


@pytest.mark.slow
def test_the_tutorial_runs_from_scene_to_reconstruction(tmp_path):
    done = subprocess.run([sys.executable, str(EXAMPLES / "tutorial.py"), str(tmp_path / "out")], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "agrees" in done.stdout and "PSNR" in done.stdout
    assert (tmp_path / "out" / "model" / "transient.npy").exists()
