"""The commands take a tal render configuration (YAML) as SCENE: forward writes tal's capture of it,
a refusal is one line, and check judges a capture that states tal's (unrendered) legs flag."""

import json

import h5py
import numpy as np
import pytest
import yaml

from interop.tal import read_capture
from analytic.scenes.scene_file import load_scene
from interop.tal.config import TalConfigWarning
from scene_files import write_relay_wall_file
from validation.cli import main

CONFIG = {
    "name": "tiny", "integrator_filter_bounces": 2, "num_bins": 60, "bin_width_opl": 0.025, "start_opl": 1.95,
    "scan_type": "single", "sensor_width": 3, "sensor_height": 2, "laser_lookat_x": 1, "laser_lookat_y": 1,
    "account_first_and_last_bounces": True,
    "geometry": [
        {"name": "plane", "mesh": {"type": "rectangle"}, "scale_x": 0.5, "scale_y": 0.5, "rot_degrees_x": 180.0,
         "displacement_z": 1.0, "material": {"id": "white"}},
        {"name": "relay_wall", "mesh": {"type": "rectangle"}, "displacement_x": 0.0, "displacement_y": 0.0,
         "displacement_z": 0.0, "scale_x": 1, "scale_y": 1, "material": {"id": "white"}}],
    "relay_wall": "relay_wall",
    "diffuse_imaging": {"pixels": 4},
}


@pytest.mark.filterwarnings("default::interop.tal.config.TalConfigWarning")   # shown as the CLI shows it
def test_forward_of_a_tal_configuration_and_check_of_its_capture(tmp_path, capsys):
    scene_file = tmp_path / "tiny.yaml"
    scene_file.write_text(yaml.safe_dump(CONFIG))
    out = tmp_path / "out"
    assert main(["forward", str(scene_file), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "diffuse-imaging: warning: account_first_and_last_bounces: true reaches only" in err   # one line
    meta = json.loads((out / "meta.json").read_text())
    assert meta["scan"]["account_first_and_last_bounces"] is False             # what tal renders
    capture = read_capture(out / "transient.h5")
    y = np.load(out / "transient.npy")
    np.testing.assert_array_equal(capture.transient, y)
    assert y.shape == (6, 60) and y.sum() > 0
    # the lit point: lookat (1, 1) of 3 x 2 pixels -> uv (1/3, 1/2) -> (2/3 - 1, 0, 0)
    np.testing.assert_allclose(capture.lasers[0], [-1 / 3, 0.0, 0.0], atol=1e-15)
    # as tal writes it: the YAML's flag, over path lengths without the legs
    tal_like = tmp_path / "tal.hdf5"
    tal_like.write_bytes((out / "transient.h5").read_bytes())
    with h5py.File(tal_like, "r+") as handle:
        handle["t_accounts_first_and_last_bounces"][()] = True
    checked = tmp_path / "checked"
    assert main(["check", str(scene_file), "--data", str(tal_like), "--shape-only", "--out", str(checked)]) == 0
    assert json.loads((checked / "metrics.json").read_text())["relative_l2"] < 1e-12
    # the same capture against the scene as a plain relay-wall scene: the flag differs, one line
    with pytest.warns(TalConfigWarning):
        plain = load_scene(scene_file)
    assert plain.capture_accounts_flag is True
    capsys.readouterr()
    toml = write_relay_wall_file(tmp_path, plain, name="plain.toml")
    assert main(["check", str(toml), "--data", str(tal_like), "--shape-only", "--out", str(tmp_path / "x")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "t_accounts_first_and_last_bounces is true" in lines[0], lines


def test_a_refused_configuration_is_one_line_and_writes_nothing(tmp_path, capsys):
    config = {**CONFIG, "geometry": [{**CONFIG["geometry"][0], "material": {"id": "copper", "alpha": "0.2"}},
                                     CONFIG["geometry"][1]]}
    scene_file = tmp_path / "copper.yml"
    scene_file.write_text(yaml.safe_dump(config))
    out = tmp_path / "out"
    assert main(["forward", str(scene_file), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    # the legs flag's warning is not said first: a refusal is one line
    assert len(err) == 1, err
    assert err[0].startswith("diffuse-imaging: error: geometry[plane].material.id: 'copper' is not Lambertian")
    assert not out.exists()


@pytest.mark.filterwarnings("default::interop.tal.config.TalConfigWarning")   # shown as the CLI shows it
@pytest.mark.parametrize("command", [
    ["forward", "--window", "auto"],                          # refused by its window, after the scene's checks
    ["check", "--data", "missing.npy"],                       # refused by its data
    ["render", "--spp", "64", "--window", "auto"],
    ["export", "--format", "mitsuba", "--spp", "0"],
])
def test_a_tal_configuration_with_tals_default_bounces_is_refused_in_one_line(tmp_path, capsys, command):
    # integrator_filter_bounces left at tal's -1 warns, but not before a refusal of what follows the scene
    config = {key: value for key, value in CONFIG.items() if key != "integrator_filter_bounces"}
    if "auto" in command:       # bins of 1 nm: the window that holds all the light does not fit in memory
        config["bin_width_opl"] = 1e-9
    scene_file = tmp_path / "tiny.yaml"
    scene_file.write_text(yaml.safe_dump(config))
    out = tmp_path / "out"
    args = [command[0], str(scene_file), *[str(tmp_path / a) if a.endswith(".npy") else a for a in command[1:]],
            "--out", str(out)]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("diffuse-imaging: error: "), err
