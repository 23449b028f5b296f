"""The interop commands on the command line: export's refusal of what mitransient cannot render, and check's
warnings about the scene's window."""

import numpy as np
import pytest

from analytic.scenes.scene_file import load_scene
from analytic.operator.matrix_free import forward
from scene_files import GOOD, write_scene
from interop.mitransient.export import MITRANSIENT_IMPULSE_ONLY
from validation.cli import main

REFUSAL = ('diffuse-imaging: error: illumination.waveform: mitransient renders the impulse response only; export '
           'the scene with waveform = "impulse" and convolve, or use our render')

FITTED = GOOD.replace("start = 0.0\ncount = 40", "start = 1.9\ncount = 10")


@pytest.mark.parametrize("waveform", ['"square"', '"butterworth"', '"square"\nwidth = 0.05'])
def test_export_for_mitransient_refuses_a_pulse_in_one_stable_line(tmp_path, capsys, waveform):
    path = write_scene(tmp_path, FITTED.replace('waveform = "impulse"', f"waveform = {waveform}"))
    assert main(["export", str(path), "--format", "mitransient", "--out", str(tmp_path / "x"), "--quiet"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [REFUSAL]
    assert MITRANSIENT_IMPULSE_ONLY in REFUSAL
    assert not (tmp_path / "x").exists()
    # our own plugins render the pulse
    assert main(["export", str(path), "--format", "mitsuba", "--out", str(tmp_path / "ours"), "--quiet"]) == 0


@pytest.mark.filterwarnings("default::analytic.operator.window.WindowWarning")
def test_check_warns_when_the_window_is_mostly_empty(tmp_path, capsys, rng):
    # GOOD's window is [0, 4) m and its light spans about [2.0, 2.7] m: the model plus its stated noise agrees
    path = write_scene(tmp_path, GOOD)
    y = forward(load_scene(path))
    stderr = 0.01 * y
    np.save(tmp_path / "y.npy", y + stderr * rng.standard_normal(y.shape))
    np.save(tmp_path / "se.npy", stderr)
    assert main(["check", str(path), "--data", str(tmp_path / "y.npy"), "--stderr", str(tmp_path / "se.npy"),
                 "--out", str(tmp_path / "c"), "--quiet"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if line.startswith("diffuse-imaging: warn")]
    assert [line for line in warnings if "window" in line] == [
        "diffuse-imaging: warning: the window [0, 4) m is mostly empty: 33 of its 40 bins receive no light (paths "
        "span [2.032, 2.684] m plus the pulse); [sampling] start = 2, count = 7 covers the light at the same period "
        "(what --window auto takes)"]


def test_export_into_the_scenes_folder_never_replaces_its_image(tmp_path, capsys):
    """--out in the scene's own folder, whose image is reflectance.exr: refused, the user's image untouched."""
    from analytic.files import save_exr

    image = np.linspace(0.1, 0.9, 64).reshape(8, 8)
    save_exr(tmp_path / "reflectance.exr", image)
    before = (tmp_path / "reflectance.exr").read_bytes()
    path = write_scene(tmp_path, FITTED.replace("reflectance = 0.5", 'reflectance = "reflectance.exr"'))
    assert main(["export", str(path), "--format", "mitsuba", "--out", str(tmp_path), "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "would replace the scene's own reflectance.exr" in lines[0], lines
    assert (tmp_path / "reflectance.exr").read_bytes() == before
    assert not (tmp_path / "scene.xml").exists()
    # another folder is fine
    assert main(["export", str(path), "--format", "mitsuba", "--out", str(tmp_path / "x"), "--quiet"]) == 0
