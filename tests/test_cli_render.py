"""The `render` command end to end: files of DESIGN.md section 5, resume, the LLVM trap."""

import glob
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from analytic.scene import default_scene
from analytic.system import forward
from validation.compare import compare_transients

SCENE = """
[plane]
pixels = 10
[source]
position = [0.4, 0.6, 0.7]
[sensors]
positions = [[0.2, 0.3, 0.5], [0.9, 0.8, 0.6]]
[sampling]
period = 0.05
start = 1.0
count = 30
"""


def _cli(*args, env=None):
    return subprocess.run([sys.executable, "-m", "validation.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=300, env=env)


def test_render_command_writes_files_that_agree_with_forward(tmp_path):
    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(SCENE)
    result = _cli("render", scene_path, "--spp", 2**20, "--seed", 3, "--out", tmp_path / "r", "--quiet")
    assert result.returncode == 0, result.stderr
    names = {p.name for p in (tmp_path / "r").iterdir()}
    assert {"transient.exr", "transient.npy", "stderr.npy", "meta.json"} <= names
    meta = json.loads((tmp_path / "r" / "meta.json").read_text())
    assert meta["samples"] == 2**20 and meta["seed"] == 3 and meta["attenuation"] == "lambertian"
    result = _cli("forward", scene_path, "--out", tmp_path / "f", "--quiet")
    assert result.returncode == 0, result.stderr
    agreement = compare_transients(np.load(tmp_path / "r" / "transient.npy"),
                                   np.load(tmp_path / "r" / "stderr.npy"),
                                   np.load(tmp_path / "f" / "transient.npy"))
    assert agreement.agrees, agreement.summary()


def test_resume_continues_to_the_same_numbers(tmp_path):
    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(SCENE)
    whole = _cli("render", scene_path, "--spp", 2**19, "--seed", 9, "--out", tmp_path / "whole", "--quiet")
    half = _cli("render", scene_path, "--spp", 2**18, "--seed", 9, "--out", tmp_path / "part", "--quiet")
    assert whole.returncode == 0 and half.returncode == 0
    resumed = _cli("render", scene_path, "--spp", 2**19, "--seed", 9, "--resume", tmp_path / "part", "--quiet")
    assert resumed.returncode == 0, resumed.stderr
    np.testing.assert_allclose(np.load(tmp_path / "part" / "transient.npy"),
                               np.load(tmp_path / "whole" / "transient.npy"), rtol=1e-12, atol=0)
    assert json.loads((tmp_path / "part" / "meta.json").read_text())["samples"] == 2**19


@pytest.mark.skipif(not glob.glob("/usr/lib/*/libLLVM-15.so*"), reason="no LLVM 15 here to refuse")
def test_llvm_15_is_refused_in_one_line_before_any_kernel(tmp_path):
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=sorted(glob.glob("/usr/lib/*/libLLVM-15.so*"))[0])
    result = _cli("render", "--spp", 1000, "--out", tmp_path / "r", env=env)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1 and "libllvm19" in result.stderr
    assert not (tmp_path / "r").exists()


def test_default_scene_render_agrees_with_model():
    from transient.render import render
    scene = default_scene(noise=None)
    result = render(scene, spp=2**21, seed=2, progress=False)
    agreement = compare_transients(result.mean, result.stderr, forward(scene))
    assert agreement.agrees, agreement.summary()
