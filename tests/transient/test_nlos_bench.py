"""benchmarks/bench_nlos_render.py runs: its quick mode in a named variant, its model file, its EXR fallback."""

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_nlos_render.py"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_nlos_render", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_texture_without_openexr_is_the_same_image(tmp_path, monkeypatch, mitsuba):
    # The GPU machines have no OpenEXR module: the fallback must write the texture OpenEXR writes.
    bench = _bench()
    scene = bench.bench_scene()
    bench.export_for_mitransient(scene, tmp_path / "with")
    monkeypatch.setitem(sys.modules, "OpenEXR", None)          # `import OpenEXR` now raises ImportError
    bench.export_for_mitransient(scene, tmp_path / "without")
    images = [np.array(mitsuba.Bitmap(str(tmp_path / folder / "reflectance.exr")), dtype=np.float64).squeeze()
              for folder in ("with", "without")]
    assert images[0].shape == (32, 32)
    np.testing.assert_array_equal(images[1], images[0])
    assert (tmp_path / "with" / "scene.xml").read_text() == (tmp_path / "without" / "scene.xml").read_text()


def test_model_file_of_another_capture_is_refused(tmp_path):
    bench = _bench()
    scene = bench.bench_scene()
    path = tmp_path / "model.npz"
    np.savez(path, model=np.zeros((scene.sensor_count, scene.sampling.count)), scene=np.array("another"))
    with pytest.raises(SystemExit, match="not the model of this capture"):
        bench.exact_model(scene, path, tmp_path / "out", bias=False)


@pytest.mark.slow
def test_quick_run_in_a_named_variant(tmp_path):
    out = tmp_path / "quick"
    environment = os.environ | {"PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out), "--quick", "--variant", "llvm_ad_mono"],
                          cwd=ROOT, env=environment, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    assert results["variant"] == "llvm_ad_mono" and results["quick"]
    assert [row["samples"] for row in results["ours"]] == [2**12, 2**14]
    assert [row["samples"] for row in results["theirs"]] == [2**8]
    # Both renderers estimate the same capture: errors of a few % of the peak at these counts, not O(1).
    for row in results["ours"] + results["theirs"]:
        assert 0.0 < row["rms_error_of_peak"] < 0.1
    # The saved model serves a second run (no Numba there), and gives the same errors for the same seeds.
    again = tmp_path / "again"
    done = subprocess.run([sys.executable, str(SCRIPT), "--out", str(again), "--quick", "--theirs",
                           "--model", str(out / "model.npz")], cwd=ROOT, env=environment, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    second = json.loads((again / "results.json").read_text())
    assert [r["rms_error_of_peak"] for r in second["ours"]] == [r["rms_error_of_peak"] for r in results["ours"]]
