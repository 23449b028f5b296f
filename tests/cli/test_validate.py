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

