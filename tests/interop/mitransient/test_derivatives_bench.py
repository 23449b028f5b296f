"""benchmarks/mitransient_derivatives.py: its files are replicas that check's readers read, and what it finds.

mitransient runs in a subprocess (the script), so that its plugins never
load into this process. References: a derivative along a uniform scale of
the reflectance is the render itself (y is linear in it), so mitransient's
forward-mode derivative on the differential seed of a replica must equal
the central difference of its primal renders on that seed (the same paths)
to float32 rounding; the files must read back through
:func:`validation.check.read_data` as the films they hold; the closed-form
expectation of a detached estimator must equal Mitsuba's own per-path
derivatives integrated over the plane.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from analytic.scenes.scene_file import load_scene
from validation.check import read_data

ROOT = Path(__file__).resolve().parents[3]
SCRIPT = ROOT / "benchmarks" / "mitransient_derivatives.py"

needs_mitransient = pytest.mark.skipif(importlib.util.find_spec("mitransient") is None,
                                       reason="mitransient is not installed (pip install -e .[bench])")

REPLICAS = 3


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("mitransient-derivatives")
    environment = os.environ | {"PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-W", "ignore", str(SCRIPT), "--out", str(out), "--spp", str(2**14),
                           "--replicas", str(REPLICAS), "--keys", "plane.reflectance", "source.position.z",
                           "sensors.positions.0.z", "plane.translation.z"], cwd=ROOT, env=environment, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "| `plane.reflectance` |" in done.stdout
    return out


@pytest.mark.slow
@needs_mitransient
def test_files_are_films_that_check_reads(run):
    scene = load_scene(run / "scene.toml")
    for method in ("ad", "fd"):
        for r in range(REPLICAS):
            path = run / "plane.reflectance" / f"{method}_{r:02d}.npy"
            film = np.load(path)
            assert film.shape == (scene.sensor_count, 1, 1, scene.sampling.count, 1)
            np.testing.assert_array_equal(read_data(path, scene), film[:, 0, 0, :, 0])


@pytest.mark.slow
@needs_mitransient
def test_forward_derivative_along_a_reflectance_scale_is_the_render(run):
    scene = load_scene(run / "scene.toml")
    for r in range(REPLICAS):
        derivative, difference = (read_data(run / "plane.reflectance" / f"{method}_{r:02d}.npy", scene)
                                  for method in ("ad", "fd"))
        assert np.max(difference) > 0
        # float32 renders at 1 ± 0.002: the difference quotient carries ~1e-4 of rounding
        assert np.max(np.abs(derivative - difference)) < 1e-3 * np.max(np.abs(difference))


@pytest.mark.slow
@needs_mitransient
def test_what_the_api_gives_for_positions_is_recorded(run):
    rows = json.loads((run / "results.json").read_text())["rows"]
    assert "not attached to the AD graph" in rows["source.position.z"]["ad"]["failed"]
    # the sensor's rays are detached: forward mode returns 0 where the exact column is not
    assert rows["sensors.positions.0.z"]["ad"]["verdict"] == "zero"
    assert rows["sensors.positions.0.z"]["ad"]["largest_relative"] == 0.0
    exact = np.load(run / "sensors.positions.0.z" / "exact.npy")
    assert np.max(np.abs(exact)) > 0


@pytest.mark.slow
@needs_mitransient
def test_detached_expectation_is_mitsubas_per_path_derivative_and_the_ad_keeps_only_it(run):
    row = json.loads((run / "results.json").read_text())["rows"]["plane.translation.z"]
    # two quadratures of one integral (3000² and 600² points): 3e-3 apart at most in a lit bin
    assert row["detached"]["paths_largest_difference"] < 1e-2
    # the detached estimator misses the silhouette term: about 0.62 of the exact sum over bins
    assert 0.5 < row["detached"]["ratio_to_exact"] < 0.75
    # and mitransient's forward mode (2^14 samples x 3 here: a few per cent of error) follows it
    assert 0.9 < row["detached"]["ad_ratio"] < 1.1
