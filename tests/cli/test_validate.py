"""The validate command on a scene file."""

import json
import subprocess
import sys


def test_validate_command_on_a_scene_file(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text("[plane]\npixels = 8\n[source]\nposition = [0.5, 0.5, 0.6]\n"
                     "[sensors]\npositions = [[0.3, 0.4, 0.5]]\n[sampling]\nperiod = 0.05\nstart = 1.0\n"
                     "count = 30\n")
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "validation.cli", "validate", str(scene), "--out", str(out),
                           "--spp", str(2**20), "--fast", "--quiet"], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["all_agree"] and "scene" in metrics["scenes"]
    assert (out / "report.md").read_text().count("agree") >= 1
    assert (out / "scene" / "z_map.png").exists()
    # every verdict states its power: 2^20 samples see well under 1 % of scale
    detectable = metrics["scenes"]["scene"]["detectable"]
    assert 0 < detectable["scale"] < 0.01 and 0 < detectable["shift_opl"] < 0.05
    assert "| detectable |" in (out / "report.md").read_text()



def test_scene_names_never_lead_outside_out_and_never_overwrite_each_other(tmp_path, capsys):
    from validation.cli import main

    text = ("[plane]\npixels = 6\n[source]\nposition = [0.5, 0.5, 0.6]\n[sensors]\npositions = [[0.3, 0.4, 0.5]]\n"
            "[sampling]\nperiod = 0.05\nstart = 1.0\ncount = 30\n")
    scenes = []
    for index, name in enumerate(["../escaped", "../escaped", "metrics.json"]):
        path = tmp_path / f"scene{index}.toml"
        path.write_text(f"name = {name!r}\n" + text.replace("0.3, 0.4", f"0.{3 + index}, 0.4"))
        scenes.append(str(path))
    out = tmp_path / "runs" / "out"
    assert main(["validate", *scenes, "--out", str(out), "--spp", "4096", "--fast", "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    written = {path for path in tmp_path.rglob("*") if path.is_file() and path.suffix != ".toml"}
    assert written and all(out in path.parents for path in written)          # nothing outside out
    metrics = json.loads((out / "metrics.json").read_text())
    assert sorted(entry["name"] for entry in metrics["scenes"].values()) == ["../escaped", "../escaped",
                                                                             "metrics.json"]
    assert len({entry["agreement"]["chi2"] for entry in metrics["scenes"].values()}) == 3   # three scenes' own
    for folder in metrics["scenes"]:
        assert (out / folder / "transients.png").is_file() and (out / folder / "z_map.png").is_file()
