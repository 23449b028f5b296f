"""The check command's lines to the user: stated conventions, scenes too small to fit, locked data."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import numpy as np
import pytest

from validation.cli import main

SCENE = """
[plane]
size = 1.0
pixels = 4
reflectance = 0.4
[source]
position = [0.5, 0.5, 1.0]
[sensors]
positions = [[0.8, 0.3, 1.0], [0.25, 0.7, 0.8]]
[sampling]
period = {period}
start = {start}
count = {count}
"""


def write_scene(folder, *, period=0.05, start=1.7, count=24):
    path = folder / "scene.toml"
    path.write_text(SCENE.format(period=period, start=start, count=count))
    return path


def model_of(path):
    from analytic.scenes.scene_file import load_scene
    from analytic.operator.matrix_free import forward

    return forward(load_scene(path))


def save_replicas(folder, truth, rng, count=16):
    """``count`` files of truth + 1 % Gaussian noise (each an independent replica)."""
    paths = []
    for r in range(count):
        paths.append(folder / f"replica_{r}.npy")
        np.save(paths[-1], truth + 0.01 * np.abs(truth) * rng.standard_normal(truth.shape))
    return paths


def error_line(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


@pytest.mark.parametrize("options, words", [
    (["--expect", "irradiancemeter", "--radius", "0.8"],
     "--radius: must lie in (0, 0.8) m, below the lowest sensor's height"),
    (["--expect", "irradiancemeter", "--expect-scale", "0.25"],
     "--expect: give a named convention or --expect-scale/--expect-offset, not both"),
    (["--radius", "0.001"], "--radius: applies to --expect irradiancemeter only"),
    (["--expect-offset", "nan"], "--expect-offset: must be finite"),
    (["--expect-scale", "0"], "--expect-scale: must be finite and > 0"),
])
def test_stated_conventions_refused_in_one_line(tmp_path, rng, capsys, options, words):
    scene = write_scene(tmp_path)
    paths = save_replicas(tmp_path, model_of(scene), rng)
    argv = ["check", str(scene), "--data", *map(str, paths), *options, "--out", str(tmp_path / "out"), "--quiet"]
    try:
        status = main(argv)
    except SystemExit as exit:          # argparse's own refusals of a flag's value
        status = exit.code
    assert status == 2
    line = error_line(capsys)
    assert "error: " in line and words in line, line
    assert not (tmp_path / "out").exists()


def test_check_states_what_the_data_can_detect(tmp_path, rng, capsys):
    """The summary, report.md and metrics.json carry `detectable` of the verdict that matters, and the
    stated scale is tested: data 1 % off a stated scale exit 1."""
    scene = write_scene(tmp_path, period=0.0125, count=96)
    truth = model_of(scene)
    paths = save_replicas(tmp_path, 0.25 * truth, rng)
    assert main(["check", str(scene), "--data", *map(str, paths), "--expect-scale", "0.25", "--out",
                 str(tmp_path / "quarter")]) == 0
    printed = capsys.readouterr().out
    metrics = json.loads((tmp_path / "quarter" / "metrics.json").read_text())
    detectable = metrics["detectable"]
    assert 0 < detectable["scale"] < 0.01 and detectable == metrics["expected"]["detectable"]
    assert "Detectable (flagged half the time): a scale error of" in printed
    assert "detectable (flagged half the time)" in (tmp_path / "quarter" / "report.md").read_text()
    assert main(["check", str(scene), "--data", *map(str, paths), "--expect-scale", "0.2525", "--out",
                 str(tmp_path / "off"), "--quiet"]) == 1
    stated = json.loads((tmp_path / "off" / "metrics.json").read_text())["as_expected_detail"]["directed"]
    assert abs(stated["scale_t"]) > stated["limit"]


def test_a_one_bin_scene_is_judged_and_says_why_nothing_was_fitted(tmp_path, rng, capsys):
    """One bin per sensor (two bins): the verdict as given, exit 0, and the reason the fit is skipped;
    formerly 'render more samples to judge them', which cannot help."""
    scene = write_scene(tmp_path, period=1.5, start=1.5, count=1)
    paths = save_replicas(tmp_path, model_of(scene), rng)
    assert main(["check", str(scene), "--data", *map(str, paths), "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "no scale or time offset fitted: the scene's 2 bin(s) cannot fit them" in printed
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["agrees"] is True and metrics["fit"] is None and metrics["agrees_after_fit"] is None


def test_zero_standard_errors_are_named(tmp_path, capsys):
    scene = write_scene(tmp_path)
    np.save(tmp_path / "y.npy", model_of(scene))
    np.save(tmp_path / "zero.npy", np.zeros_like(model_of(scene)))
    assert main(["check", str(scene), "--data", str(tmp_path / "y.npy"), "--stderr", str(tmp_path / "zero.npy"),
                 "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "stderr: the standard errors are all zero" in error_line(capsys)


def test_check_does_not_read_a_folder_another_command_is_writing(tmp_path, rng, capsys):
    """While a command holds the data's folder for writing, check waits for it and then refuses in one
    line naming that process, instead of reading files that are being replaced."""
    scene = write_scene(tmp_path)
    data = tmp_path / "data"
    data.mkdir()
    paths = save_replicas(data, model_of(scene), rng)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom analytic.files import output_folder\n"
                               "with output_folder(sys.argv[1]):\n    print('held', flush=True)\n"
                               "    time.sleep(120)\n", str(data)],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        assert main(["check", str(scene), "--data", *map(str, paths), "--out", str(tmp_path / "out"),
                     "--quiet"]) == 2
        line = error_line(capsys)
        assert f"(process {holder.pid}) is writing" in line, line
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()
    assert main(["check", str(scene), "--data", *map(str, paths), "--out", str(tmp_path / "out"),
                 "--quiet"]) in (0, 1)


# Renders an exported mitransient scene in a fresh process (its own Mitsuba variant): K films per seed.
_MITRANSIENT = r"""
import sys
import numpy as np, mitsuba as mi
mi.set_variant("llvm_ad_mono")
import mitransient
xml, spp, seeds, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
scene = mi.load_file(xml, spp=spp)
for seed in range(seeds):
    films = [np.array(mi.render(scene, sensor=k, seed=seed)[1]) for k in range(len(scene.sensors()))]
    np.save(f"{out}/render_{seed}.npy", np.stack(films))
"""


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("mitransient") is None, reason="mitransient is not installed")
def test_mitransient_renders_hold_the_irradiancemeter_convention(tmp_path):
    """Another renderer, from the exported scene: `--expect irradiancemeter` (scale 1/4, start moved by
    2r/3 + RayEpsilon) holds, and the fit finds those numbers within its errors."""
    import os

    from transient.backend import choose_libllvm, find_llvm_libraries

    scene = write_scene(tmp_path)
    assert main(["export", str(scene), "--format", "mitransient", "--out", str(tmp_path / "xml"), "--quiet"]) == 0
    environment = os.environ | {"DRJIT_LIBLLVM_PATH": choose_libllvm(os.environ.get("DRJIT_LIBLLVM_PATH"),
                                                                     find_llvm_libraries())}
    done = subprocess.run([sys.executable, "-c", _MITRANSIENT, str(tmp_path / "xml" / "scene.xml"), str(2**22),
                           "16", str(tmp_path)], capture_output=True, text=True, timeout=1200, env=environment)
    assert done.returncode == 0, done.stderr[-3000:]
    renders = [str(tmp_path / f"render_{seed}.npy") for seed in range(16)]
    assert main(["check", str(scene), "--data", *renders, "--out", str(tmp_path / "plain"), "--quiet"]) == 1
    assert main(["check", str(scene), "--data", *renders, "--expect", "irradiancemeter",
                 "--out", str(tmp_path / "meter"), "--quiet"]) == 0
    fit = json.loads((tmp_path / "meter" / "metrics.json").read_text())["fit"]
    radius = 1e-3                                              # the export's default
    assert abs(fit["scale"] - 0.25) < 3 * fit["scale_stderr"]
    assert abs(fit["offset_opl"] - (2 * radius / 3 + 1500 * 2.0**-24)) < 3 * fit["offset_stderr"]
