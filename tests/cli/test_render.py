"""The `render` command end to end: files of docs/design.md section 5, resume, the LLVM trap."""

import glob
import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from analytic.scenes.common import default_scene
from analytic.operator.matrix_free import forward
from validation.judging.compare import compare_transients

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


def _in_process(capsys, *args):
    """`_cli` without a new interpreter (~4 s of imports each), for tests not about the process itself."""
    from validation.cli import main

    capsys.readouterr()
    status = main([*map(str, args)])
    captured = capsys.readouterr()
    return subprocess.CompletedProcess(args, status, captured.out, captured.err)


def test_render_command_writes_files_that_agree_with_forward(tmp_path, capsys):
    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(SCENE)
    result = _in_process(capsys, "render", scene_path, "--spp", 2**20, "--seed", 3, "--out", tmp_path / "r",
                         "--quiet")
    assert result.returncode == 0, result.stderr
    names = {p.name for p in (tmp_path / "r").iterdir()}
    # the figure too, as forward draws it
    assert {"transient.exr", "transient.npy", "stderr.npy", "replicas.npy", "meta.json", "transient.png"} <= names
    assert (tmp_path / "r" / "transient.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "partial" not in names
    meta = json.loads((tmp_path / "r" / "meta.json").read_text())
    assert meta["samples"] == 2**20 and meta["seed"] == 3 and meta["attenuation"] == "lambertian"
    assert meta["replicas"] == 32 and meta["dof"] == 31 and meta["complete"] is True
    replicas = np.load(tmp_path / "r" / "replicas.npy")
    assert replicas.shape == (32, 2, 30)
    np.testing.assert_allclose(replicas.mean(axis=0), np.load(tmp_path / "r" / "transient.npy"), rtol=1e-13)
    result = _in_process(capsys, "forward", scene_path, "--out", tmp_path / "f", "--quiet")
    assert result.returncode == 0, result.stderr
    agreement = compare_transients(np.load(tmp_path / "r" / "transient.npy"),
                                   np.load(tmp_path / "r" / "stderr.npy"),
                                   np.load(tmp_path / "f" / "transient.npy"), dof=meta["dof"])
    assert agreement.agrees, agreement.summary()


def test_terminated_render_saves_its_own_state_and_says_how_to_resume(tmp_path):
    """SIGTERM after the first checkpoint: exit 130, one line with the exact resume command (the folder as
    given), no complete-looking output, and a state equal to the one the same render stopped after as many
    samples keeps. 2^40 samples cannot finish before the signal (hours at any speed this code reaches), so
    the interruption is always what is tested."""
    from analytic.scenes.scene_file import load_scene
    from transient.render import RenderInterrupted, render

    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(SCENE)
    samples = 2**40
    child = subprocess.Popen([sys.executable, "-m", "validation.cli", "render", str(scene_path), "--spp",
                              str(samples), "--seed", "9", "--out", "./part/", "--quiet"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    deadline = time.monotonic() + 120
    while not (tmp_path / "part" / "render_state.npz").exists() and child.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    child.send_signal(signal.SIGTERM)
    _, errors = child.communicate(timeout=120)
    assert child.returncode == 130, errors
    assert errors.strip().splitlines() == ["diffuse-imaging: interrupted; resume with: diffuse-imaging render "
                                           "--resume ./part/"], errors
    assert not (tmp_path / "part" / "transient.npy").exists()
    assert not (tmp_path / "part" / "transient.png").exists()
    with np.load(tmp_path / "part" / "render_state.npz") as state:
        saved = {name: state[name] for name in ("done", "partial", "replica_means")}
    assert 0 < saved["done"] < samples

    def stop(done):
        if done >= saved["done"]:
            raise KeyboardInterrupt

    with pytest.raises(RenderInterrupted):
        render(load_scene(scene_path), spp=samples, seed=9, out_dir=tmp_path / "same", progress=False, on_chunk=stop)
    with np.load(tmp_path / "same" / "render_state.npz") as state:
        assert int(state["done"]) == saved["done"]
        for name in ("partial", "replica_means"):
            np.testing.assert_allclose(saved[name], state[name], rtol=1e-12, atol=0, err_msg=name)


def test_resume_alone_finishes_a_render_to_the_same_numbers(tmp_path, capsys):
    """`--resume DIR` alone finishes an interrupted render to the numbers of the same render done at once, and
    its samples/s counts only the samples it drew."""
    scene_path, folder = _interrupted_render(tmp_path)
    with np.load(folder / "render_state.npz") as state:
        done_before = int(state["done"])
    samples = 2**22
    whole = _in_process(capsys, "render", scene_path, "--spp", samples, "--seed", 4, "--out", tmp_path / "whole",
                        "--quiet")
    assert whole.returncode == 0, whole.stderr
    resumed = _in_process(capsys, "render", "--resume", folder)
    assert resumed.returncode == 0, resumed.stderr
    np.testing.assert_allclose(np.load(folder / "transient.npy"), np.load(tmp_path / "whole" / "transient.npy"),
                               rtol=1e-12, atol=0)
    assert json.loads((folder / "meta.json").read_text())["samples"] == samples
    summary = re.search(r"([\d,]+) samples \(([\d,]+) in this run\) in ([\d.]+) s \(([\d,]+) samples/s",
                        resumed.stdout)
    assert summary, resumed.stdout
    total, drawn, seconds, rate = (float(group.replace(",", "")) for group in summary.groups())
    assert total == samples and 0 < drawn == samples - done_before
    # seconds are shown to 0.1 s
    assert drawn / (seconds + 0.05) <= rate <= drawn / max(seconds - 0.05, 1e-9)


def _interrupted_render(tmp_path):
    """A render folder holding a state after its first chunks (seed 4, 2^22 samples)."""
    from analytic.scenes.scene_file import load_scene
    from transient.render import RenderInterrupted, render

    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(SCENE)

    def stop(done):
        raise KeyboardInterrupt

    with pytest.raises(RenderInterrupted):
        render(load_scene(scene_path), spp=2**22, seed=4, out_dir=tmp_path / "part", progress=False, on_chunk=stop)
    return scene_path, tmp_path / "part"


def test_resume_refuses_arguments_that_differ_each_named_in_one_line(tmp_path):
    scene_path, folder = _interrupted_render(tmp_path)
    result = _cli("render", "--resume", folder, "--spp", 1000, "--seed", 5)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "--spp 1000 differs from the state's 4194304" in lines[0]
    assert "--seed 5 differs from the state's 4" in lines[0] and "scene" not in lines[0].split("(in")[0]
    other = tmp_path / "other.toml"
    other.write_text(SCENE.replace("[0.4, 0.6, 0.7]", "[0.4, 0.6, 0.8]"))
    result = _cli("render", other, "--resume", folder)
    assert result.returncode == 2 and "scene given differs" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    # what differs is named: the key and both values
    assert "[source] position [0.4, 0.6, 0.8] (the state's: [0.4, 0.6, 0.7])" in result.stderr


def test_resume_with_too_few_samples_names_the_samples_not_a_scene(tmp_path):
    """--spp below the replica count used to end in a traceback (32 replicas need 32 samples)."""
    _, folder = _interrupted_render(tmp_path)
    result = _cli("render", "--resume", folder, "--spp", 10)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "--spp 10 differs from the state's 4194304" in lines[0]
    assert "scene" not in lines[0].split("(in")[0]


def test_a_new_render_into_a_finished_folder_leaves_no_complete_looking_files_until_done(tmp_path):
    """An earlier render's results beside a new, unfinished render's state would look like its own."""
    from analytic.scenes.scene_file import load_scene
    from transient.render import RenderInterrupted, render

    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(SCENE)
    assert _cli("render", scene_path, "--spp", 4096, "--out", tmp_path / "r", "--quiet").returncode == 0
    assert (tmp_path / "r" / "transient.npy").exists() and (tmp_path / "r" / "transient.png").exists()

    def stop(done):
        raise KeyboardInterrupt

    with pytest.raises(RenderInterrupted):
        render(load_scene(scene_path), spp=2**17, seed=7, out_dir=tmp_path / "r", progress=False, on_chunk=stop)
    names = {path.name for path in (tmp_path / "r").iterdir()}
    assert names == {"render_state.npz", "render_scene.npz", "partial"}, names
    assert json.loads((tmp_path / "r" / "partial" / "meta.json").read_text())["complete"] is False


def test_window_auto_renders_the_covering_bins_and_a_resume_keeps_them(tmp_path, capsys):
    from analytic.scenes.scene_file import load_scene
    from analytic.operator.window import covering_sampling

    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(SCENE.replace("start = 1.0\ncount = 30", "start = 0.0\ncount = 80"))
    covering = covering_sampling(load_scene(scene_path), 0.05)
    result = _in_process(capsys, "render", scene_path, "--window", "auto", "--spp", 4096, "--out", tmp_path / "r",
                         "--quiet")
    assert result.returncode == 0, result.stderr
    assert result.stderr.strip().splitlines() == [
        line for line in result.stderr.strip().splitlines() if line.startswith("diffuse-imaging: window: ")]
    assert f"start {covering.start_opl:.12g} m, count {covering.count} " in result.stderr
    meta = json.loads((tmp_path / "r" / "meta.json").read_text())
    assert (meta["start_opl"], meta["bins"], meta["window_share"]) == (covering.start_opl, covering.count, 1.0)
    assert np.load(tmp_path / "r" / "transient.npy").shape == (2, covering.count)
    # the scene file alone is another window: given again for a resume, the difference is named
    refused = _in_process(capsys, "render", scene_path, "--resume", tmp_path / "r")
    assert refused.returncode == 2 and "[sampling] count 80" in refused.stderr
    assert _in_process(capsys, "render", scene_path, "--window", "auto", "--resume", tmp_path / "r").returncode == 0


def test_new_render_needs_spp_and_help_offers_only_accepted_variants(tmp_path):
    result = _cli("render", "--out", tmp_path / "r")
    assert result.returncode == 2 and "--spp" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "r").exists()
    from transient.backend import select_variant, usable_variants

    select_variant()
    import mitsuba

    offered = re.findall(r"\b(?:llvm|cuda)_\w+", _cli("render", "--help").stdout)
    assert offered and set(offered) <= set(usable_variants(mitsuba.variants()))
    refused = _cli("render", "--spp", 1000, "--variant", "llvm_rgb", "--out", tmp_path / "r")
    assert refused.returncode == 2 and "mono" in refused.stderr


def test_render_on_a_missing_cuda_device_is_one_backend_error(tmp_path):
    import drjit as dr

    from transient.backend import select_variant

    select_variant()
    if dr.has_backend(dr.JitBackend.CUDA):
        pytest.skip("a CUDA device is present")
    result = _cli("render", "--spp", 1000, "--variant", "cuda_ad_mono", "--out", tmp_path / "r")
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "CUDA" in result.stderr
    assert not (tmp_path / "r").exists()


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
    agreement = compare_transients(result.mean, result.stderr, forward(scene), dof=result.dof)
    assert agreement.agrees, agreement.summary()
