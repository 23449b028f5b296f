"""The forward command: the contract's files, and one-line refusals with no files."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from analytic.files import read_transient
from scene_files import GOOD, write_scene
from validation.cli import main


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "validation.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


@pytest.mark.parametrize("change", [
    ("size = 1.0", "size = 1.0\ncolour = 3"),
    ("position = [0.5, 0.5, 1.0]", "position = [0.5, 0.5, -0.1]"),
    ("count = 40", "count = 0"),
])
def test_bad_scene_exits_2_with_one_line_and_no_files(tmp_path, change):
    path = write_scene(tmp_path, GOOD.replace(*change))
    out = tmp_path / "out"
    result = _cli("forward", path, "--out", out)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert not out.exists()


def test_missing_scene_file_exits_2(tmp_path, capsys):
    assert main(["forward", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "out")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.mark.filterwarnings("default::analytic.operator.window.WindowWarning")     # GOOD's window is mostly empty
def test_forward_writes_the_contract_files(tmp_path, capsys):
    text = GOOD + "\n[noise]\nsigma = 0.1\nseed = 3\n"
    path = write_scene(tmp_path, text)
    out = tmp_path / "out"
    # in-process: the files are the point here (test_bad_scene_exits_2... and tests/cli/test_console.py
    # run the process itself)
    assert main(["forward", str(path), "--out", str(out), "--quiet"]) == 0, capsys.readouterr().err
    names = {p.name for p in out.iterdir()}
    assert names == {"transient.exr", "transient.npy", "transient.h5", "meta.json", "transient_noisy.npy",
                     "transient.png"}
    y = np.load(out / "transient.npy")
    assert y.shape == (1, 40) and y.dtype == np.float64 and y.max() > 0
    np.testing.assert_allclose(read_transient(out / "transient.exr"), y, rtol=1e-6, atol=1e-12)
    assert np.array_equal(read_transient(out / "transient.h5"), y)
    meta = json.loads((out / "meta.json").read_text())
    assert meta["start_opl"] == 0.0 and meta["bin_width_opl"] == 0.1 and meta["attenuation"] == "lambertian"
    assert meta["kind"] == "model" and meta["illumination"] == "impulse" and meta["window_share"] == 1.0
    assert meta["noise"] == {"kind": "gaussian", "sigma": 0.1, "photons": None, "seed": 3}
    import OpenEXR
    with OpenEXR.File(str(out / "transient.exr")) as handle:
        header = dict(handle.header())   # the header is a view that closes with the file
    assert float(np.ravel(header["start_opl"])[0]) == 0.0 and float(np.ravel(header["bin_width_opl"])[0]) == 0.1
    assert header["illumination"] == "impulse"
    noisy = np.load(out / "transient_noisy.npy")
    # σ = 0.1 noise: the residual's standard deviation within 4 standard errors of σ
    residual = noisy - y
    assert abs(residual.std() - 0.1) < 4 * 0.1 / math.sqrt(2 * residual.size)


@pytest.mark.filterwarnings("default::analytic.operator.window.WindowWarning")
def test_a_window_that_cuts_the_response_warns_in_one_line(tmp_path, capsys):
    path = write_scene(tmp_path, GOOD.replace("start = 0.0\ncount = 40", "start = 1.9\ncount = 3"))
    assert main(["forward", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert len(warning) == 1 and "% of the light" in warning[0]
    assert json.loads((tmp_path / "out" / "meta.json").read_text())["window_share"] < 0.999


@pytest.mark.filterwarnings("default::analytic.operator.window.WindowWarning")
def test_a_mostly_empty_window_warns_in_one_line_with_the_covering_window(tmp_path, capsys):
    # GOOD's window is [0, 4) m; its light spans about [2.0, 2.7] m: 33 of its 40 bins receive none
    path = write_scene(tmp_path, GOOD)
    assert main(["forward", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert len(warning) == 1 and "is mostly empty: 33 of its 40 bins receive no light" in warning[0], warning
    assert "[sampling] start = 2, count = 7 covers the light" in warning[0]
    # and so it is: the light lies in bins 20 to 26
    y = np.load(tmp_path / "out" / "transient.npy")
    lit = np.flatnonzero(y[0] > 0)
    assert (lit[0], lit[-1]) == (20, 26)


@pytest.mark.filterwarnings("default::analytic.operator.window.WindowWarning")
def test_window_auto_takes_the_bins_that_hold_all_the_light(tmp_path, capsys):
    path = write_scene(tmp_path, GOOD)
    # the same period with the auto window: every bin that receives light, and no other
    assert main(["forward", str(path), "--window", "auto", "--out", str(tmp_path / "auto"), "--quiet"]) == 0
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("diffuse-imaging: window: start 2 m, count 7 "), lines
    meta = json.loads((tmp_path / "auto" / "meta.json").read_text())
    assert (meta["start_opl"], meta["bins"], meta["bin_width_opl"], meta["window_share"]) == (2.0, 7, 0.1, 1.0)
    assert main(["forward", str(path), "--out", str(tmp_path / "scene"), "--quiet"]) == 0
    assert "mostly empty" in capsys.readouterr().err
    whole, auto = np.load(tmp_path / "scene" / "transient.npy"), np.load(tmp_path / "auto" / "transient.npy")
    # the box prefilter: the same bins, the same numbers (bin edges j T on both grids)
    np.testing.assert_allclose(auto, whole[:, 20:27], rtol=1e-12, atol=0)
    assert np.all(auto > 0)


FITTED = GOOD.replace("start = 0.0\ncount = 40", "start = 1.9\ncount = 10")


def test_intensity_scales_the_model_exactly(tmp_path):
    bright = FITTED.replace("position = [0.5, 0.5, 1.0]", "position = [0.5, 0.5, 1.0]\nintensity = 37.5")
    for name, text in (("unit", FITTED), ("bright", bright)):
        assert main(["forward", str(write_scene(tmp_path, text, f"{name}.toml")), "--out",
                     str(tmp_path / name), "--quiet"]) == 0
    unit, scaled = np.load(tmp_path / "unit" / "transient.npy"), np.load(tmp_path / "bright" / "transient.npy")
    np.testing.assert_allclose(scaled, 37.5 * unit, rtol=1e-15, atol=0)


def test_a_scene_name_is_drawn_as_it_is(tmp_path):
    # "$...$" would be matplotlib's mathtext (this one an error), 日本 is not in its font (a warning)
    path = write_scene(tmp_path, "name = 'a$\\frac$b 日本'\n" + FITTED)      # a TOML literal string
    assert main(["forward", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert (tmp_path / "out" / "transient.png").stat().st_size > 0


# issue 38: instrument responses whose exact model takes hours are refused up front, in one line, with the
# estimate (time, memory) and what to change, before any file is written
RESPONSES = {
    "dense-samples": ('waveform = "sampled"\nfile = "irf.npy"\nsample_width = 1e-6', "scene"),
    "wide-gaussian": ('waveform = "gaussian"\nfwhm = 1000', "auto"),
    "long-emg": ('waveform = "emg"\nfwhm = 10\ntail = 100', "auto"),
    "sharp-emg-long-tail": ('waveform = "emg"\nfwhm = 0.001\ntail = 10', "auto"),
}


def _response_scene(folder, illumination):
    np.save(folder / "irf.npy", np.hanning(100_000))
    text = (GOOD.replace('waveform = "impulse"', illumination).replace("period = 0.1", "period = 0.01")
            .replace("start = 0.0", "start = 2.0").replace("count = 40", "count = 120"))
    return write_scene(folder, text)


@pytest.mark.parametrize("name", sorted(RESPONSES))
def test_a_response_the_model_cannot_cover_in_reasonable_time_is_refused_in_one_line(tmp_path, capsys, name):
    illumination, window = RESPONSES[name]
    path = _response_scene(tmp_path, illumination)
    commands = [["forward", "--window", window]]
    if window == "auto":
        commands.append(["render", "--spp", "64", "--window", "auto"])
    else:
        data = tmp_path / "y.npy"
        np.save(data, np.zeros((1, 120)))
        commands += [["run", "--spp", "4096"], ["validate", "--spp", "4096"], ["check", "--data", str(data)],
                     ["reconstruct", "--data", str(data)]]
    for command in commands:
        out = tmp_path / command[0]
        assert main([command[0], str(path), *command[1:], "--out", str(out)]) == 2, command
        error = capsys.readouterr().err.strip().splitlines()
        assert len(error) == 1 and "the exact model would take about" in error[0], (command, error)
        assert ("sampling.period of at least" in error[0] or "more coarsely" in error[0]) and not out.exists()
