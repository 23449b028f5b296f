"""Parameter sweeps on a local Dask cluster (validation.sweep, validation.cli_sweep).

The reference for every sweep result is an independent code path: a plain
sequential :func:`transient.render.render` of the same scene, seed and chunk
size in this process. With Dr.Jit on one thread (as every sweep worker runs)
a chunk's float64 sums are a function of the chunk alone, so the sweep must
match the sequential render bit for bit, whatever worker computed which
chunk, whether a worker died, or whether the sweep was interrupted and
resumed. Everything runs on loopback with fixed seeds.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import sys

import numpy as np
import pytest

from analytic.errors import ResourceError, SceneError
from analytic.scenes.common import default_scene
from analytic.scenes.scene_file import scene_from_dict
from transient.chunks import ChunkPlan, ReplicaAccumulator, ReplicaLayout
from transient.render import render
from transient.render_state import scene_fingerprint
from validation.cli import main
from validation.sweep import ITEM_FILE, STATE_FILE, load_sweep, run_sweep, sweep_client, sweep_from_dict
from validation.sweep.config import default_scene_table

distributed = pytest.importorskip("distributed")

CHUNK = 2**13
SAMPLES = 6 * CHUNK + 100          # 32 replicas of 1540 samples: 7 chunks, the last one short
SEED = 23
PLAN = ChunkPlan(ReplicaLayout.for_samples(SAMPLES), CHUNK)
CHUNKS = len(PLAN)

BASE_SCENE = """
[plane]
size = 1.0
pixels = 8
reflectance = 0.5

[source]
position = [0.3, 0.6, 0.8]

[sensors]
positions = [[0.2, 0.7, 1.0], [0.8, 0.15, 0.5]]

[sampling]
period = 0.1
start = 0.8
count = 20
"""

SWEEP = f"""
scene = "base.toml"
samples = {SAMPLES}
seed = {SEED}
chunk = {CHUNK}
cross_check = {{cross_check}}

[grid]
"sampling.period" = [0.05, 0.1]
"illumination.waveform" = ["impulse", "butterworth"]
"""


def write_sweep(folder, *, cross_check=False, text=None):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "base.toml").write_text(BASE_SCENE)
    path = folder / "sweep.toml"
    path.write_text(text if text is not None else SWEEP.replace("{cross_check}",
                                                                 "true" if cross_check else "false"))
    return path


@pytest.fixture(scope="module")
def client():
    with sweep_client(workers=2) as client:
        yield client


@pytest.fixture(scope="module")
def sweep_file(tmp_path_factory):
    return write_sweep(tmp_path_factory.mktemp("sweep"))


class _Estimate:
    def __init__(self, accumulator):
        self.mean, self.stderr, self.dof = accumulator.mean(), accumulator.stderr(), accumulator.dof


@pytest.fixture(scope="module")
def reference(sweep_file):
    """Every item rendered here, chunk after chunk of the sweep's plan (Dr.Jit on one thread, as
    in a worker): name -> estimate. The sweep must give these numbers exactly."""
    from transient.backend import select_variant
    from transient.mitsuba_scene import load_scene

    select_variant()
    import drjit as dr

    threads = dr.thread_count()
    dr.set_thread_count(1)
    try:
        estimates = {}
        for item in load_sweep(sweep_file).items:
            loaded = load_scene(item.scene)
            accumulator = ReplicaAccumulator(PLAN.layout, (item.scene.sensor_count, item.scene.sampling.count))
            for chunk in PLAN:
                accumulator.add(chunk, loaded.integrator().render_chunk(
                    loaded, seed=SEED, layout=PLAN.layout, first=chunk.first, count=chunk.count))
            estimates[item.name] = _Estimate(accumulator)
        return estimates
    finally:
        dr.set_thread_count(threads)


def assert_matches_reference(out_dir, reference):
    for name, expected in reference.items():
        assert (out_dir / name / ITEM_FILE).is_file(), name
        np.testing.assert_array_equal(np.load(out_dir / name / "transient.npy"), expected.mean)
        np.testing.assert_array_equal(np.load(out_dir / name / "stderr.npy"), expected.stderr)


# -- the sweep file ---------------------------------------------------------

def test_grid_builds_validated_scenes(sweep_file):
    sweep = load_sweep(sweep_file)
    assert len(sweep.items) == 4 and sweep.samples == SAMPLES and sweep.seed == SEED
    periods = [item.scene.sampling.bin_width_opl for item in sweep.items]
    waveforms = [item.scene.illumination.waveform for item in sweep.items]
    assert periods == [0.05, 0.05, 0.1, 0.1]
    assert waveforms == ["impulse", "butterworth", "impulse", "butterworth"]
    # Everything not in the grid comes from the base scene.
    assert all(item.scene.pixels == 8 and item.scene.sensor_count == 2 for item in sweep.items)
    names = [item.name for item in sweep.items]
    assert len(set(names)) == 4
    assert all(name == "".join(c for c in name if c.isalnum() or c in "._+-") for name in names)
    assert len({scene_fingerprint(item.scene) for item in sweep.items}) == 4


def test_default_base_is_the_builtin_scene(tmp_path):
    assert scene_fingerprint(scene_from_dict(default_scene_table())) == scene_fingerprint(default_scene())
    sweep = sweep_from_dict({"scene": "default", "samples": 100,
                             "grid": {"plane.pixels": [20], "sensors.extent": [0.5, 2.0]}}, tmp_path)
    assert scene_fingerprint(sweep.items[0].scene) == scene_fingerprint(
        default_scene(pixels=20, sensors=sweep.items[0].scene.sensors))
    spans = [np.ptp(item.scene.sensors[:, 0]) for item in sweep.items]
    np.testing.assert_allclose(spans, [0.5, 2.0], rtol=1e-12)


def test_reflectance_folder_gives_one_item_per_image(tmp_path, rng):
    from PIL import Image

    images = tmp_path / "images"
    images.mkdir()
    expected = {}
    for name in ("b", "a"):
        pixels = rng.integers(0, 256, (8, 8), dtype=np.uint8)
        Image.fromarray(pixels).save(images / f"{name}.png")
        expected[name] = pixels / 255.0
    (tmp_path / "base.toml").write_text(BASE_SCENE)
    sweep = sweep_from_dict({"scene": "base.toml", "samples": 100,
                             "grid": {"plane.reflectance": {"folder": "images"}}}, tmp_path)
    assert [item.name for item in sweep.items] == ["000_plane.reflectance-a", "001_plane.reflectance-b"]
    for item, name in zip(sweep.items, ("a", "b")):
        np.testing.assert_array_equal(item.scene.reflectance, expected[name])


@pytest.mark.parametrize("text, key", [
    ('scene = "base.toml"\nsamples = 100\nsede = 1\n', "sede"),
    ('scene = "base.toml"\nsamples = 100\n[grid]\n"sampling.peroid" = [0.1]\n', "grid.sampling.peroid"),
    ('scene = "base.toml"\nsamples = 100\n[grid]\n"sampling.period" = [0.1, -0.1]\n', "grid.sampling.period"),
    ('scene = "base.toml"\nsamples = 100\n[grid]\n"sampling.period" = 0.1\n', "grid.sampling.period"),
    ('scene = "base.toml"\nsamples = 100\n[grid]\n"illumination.waveform" = ["lorentzian"]\n',
     "grid.illumination.waveform"),
    ('scene = "base.toml"\nsamples = 100\n[grid]\n"illumination.waveform" = ["gaussian"]\n',
     "illumination.fwhm"),                          # a waveform's own key, missing from the base scene
    ('scene = "base.toml"\nsamples = 100\n[grid]\nperiod = [0.1]\n', "grid.period"),
    ('scene = "base.toml"\nsamples = 1\n', "samples"),
    ('scene = "base.toml"\nsamples = 100\nchunk = 0\n', "chunk"),
    ('scene = "missing.toml"\nsamples = 100\n', "scene"),
    ('samples = 100\n', "scene"),
    ('scene = "base.toml"\nsamples = 100\ncross_check = true\n', "samples"),       # too few to judge bins
    ('scene = "base.toml"\nsamples = 100\n[grid]\n"sampling.count" = [' + ", ".join(map(str, range(1, 401)))
     + ']\n"sampling.start" = [' + ", ".join(f"{0.001 * i:.3f}" for i in range(300)) + ']\n', "grid"),
])
def test_bad_sweep_files_name_the_key(tmp_path, capsys, text, key):
    path = write_sweep(tmp_path, text=text)
    with pytest.raises(SceneError) as caught:
        load_sweep(path)
    assert caught.value.key == key
    # Through the command, before any cluster starts or any file is written.
    assert main(["sweep", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and key in error[0]
    assert not (tmp_path / "out").exists()


def _may_have_cuda() -> bool:
    """A CUDA driver is installed (asked without importing Dr.Jit, which must pick its LLVM first)."""
    import ctypes.util

    return ctypes.util.find_library("cuda") is not None or os.path.exists("/proc/driver/nvidia/version")


@pytest.mark.skipif(_may_have_cuda(), reason="this machine may have a CUDA device: the variant is legal here")
def test_a_cuda_variant_without_a_gpu_is_refused_before_any_cluster_or_file(tmp_path):
    import subprocess
    import sys

    path = write_sweep(tmp_path, text='scene = "base.toml"\nsamples = 4096\nvariant = "cuda_ad_mono"\n')
    out = tmp_path / "out"
    # in a process of its own: asking for a CUDA variant imports Dr.Jit without choosing its LLVM
    done = subprocess.run([sys.executable, "-m", "validation.cli", "sweep", str(path), "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("diffuse-imaging: error: variant cuda_ad_mono") and "CUDA" in line
    assert not out.exists()


def test_without_dask_a_sweep_is_refused_in_one_line_naming_the_extra(tmp_path, capsys, monkeypatch):
    """The lean install (no ``sweep`` extra): the command and the Python call say which extra to install."""
    path = write_sweep(tmp_path)
    monkeypatch.setitem(sys.modules, "distributed", None)       # as if not installed: find_spec gives None
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--out", str(out)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("diffuse-imaging: error: sweep: runs on Dask") and "diffuse-imaging[sweep]" in line
    assert not out.exists()
    with pytest.raises(ResourceError, match=r"diffuse-imaging\[sweep\]"):
        run_sweep(load_sweep(path), tmp_path / "python")
    assert not (tmp_path / "python").exists()


def test_the_sweep_renders_what_render_renders():
    """The sweep's chunks differ from render()'s (which starts small for an early checkpoint):
    the same samples, summed in another order, to float64 rounding."""
    scene = scene_from_dict({"plane": {"pixels": 4}, "sensors": {"positions": [[0.2, 0.7, 1.0]]},
                             "sampling": {"period": 0.1, "start": 1.5, "count": 20}})
    from transient.backend import select_variant
    from transient.mitsuba_scene import load_scene

    select_variant()
    loaded = load_scene(scene)
    accumulator = ReplicaAccumulator(PLAN.layout, (1, 20))
    for chunk in PLAN:
        accumulator.add(chunk, loaded.integrator().render_chunk(loaded, seed=SEED, layout=PLAN.layout,
                                                                first=chunk.first, count=chunk.count))
    direct = render(scene, spp=SAMPLES, seed=SEED, progress=False)
    np.testing.assert_allclose(accumulator.mean(), direct.mean, rtol=1e-12, atol=0)


# -- on the cluster ---------------------------------------------------------

def test_sweep_equals_sequential_renders(client, sweep_file, reference, tmp_path):
    sweep = load_sweep(sweep_file)
    sweep = sweep_from_dict({"scene": "base.toml", "samples": SAMPLES, "seed": SEED, "chunk": CHUNK,
                             "cross_check": True, "grid": sweep.grid}, sweep_file.parent)
    result = run_sweep(sweep, tmp_path, client=client, progress=False)
    assert_matches_reference(tmp_path, reference)
    assert sorted(result.computed_chunks) == sorted((item.name, c) for item in sweep.items for c in range(CHUNKS))
    # The cross-check ran on every item, and the model files sit beside the render.
    assert result.all_agree is True
    index = json.loads((tmp_path / "index.json").read_text())
    assert [row["name"] for row in index["items"]] == list(reference)
    for row in index["items"]:
        assert row["status"] == "done" and row["samples"] == PLAN.layout.samples and row["agrees"] is True
        assert row["replicas"] == 32 and row["dof"] == 31 and 0.5 < row["window_share"] < 1.01
        assert row["render_seconds"] > 0 and row["chi2_per_dof"] > 0
        folder = tmp_path / row["path"]
        meta = json.loads((folder / "meta.json").read_text())
        assert meta["samples"] == PLAN.layout.samples and meta["seed"] == SEED and meta["kind"] == "render"
        assert meta["sweep_parameters"] == row["parameters"] and meta["dof"] == 31
        assert (folder / "transient.exr").is_file() and (folder / "model" / "transient.npy").is_file()
        assert json.loads((folder / "agreement.json").read_text())["agrees"] is True
    with open(tmp_path / "index.csv", newline="") as stream:
        table = list(csv.DictReader(stream))
    assert [row["name"] for row in table] == list(reference)
    assert [float(row["sampling.period"]) for row in table] == [0.05, 0.05, 0.1, 0.1]


def test_interrupted_sweep_resumes_without_recomputing(client, sweep_file, reference, tmp_path):
    sweep = load_sweep(sweep_file)
    seen = []

    def stop_after_ten_chunks(name, chunk):
        seen.append((name, chunk))
        if len(seen) == 10:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(sweep, tmp_path, client=client, progress=False, on_chunk=stop_after_ten_chunks)
    checkpointed = {}
    finished = []
    for item in sweep.items:
        if (tmp_path / item.name / ITEM_FILE).is_file():
            finished.append(item.name)
        elif (tmp_path / item.name / STATE_FILE).is_file():
            with np.load(tmp_path / item.name / STATE_FILE) as state:
                checkpointed[item.name] = set(state["done"].tolist())
    # Items go first to last: ten chunks finish the first item (seven) and start another.
    assert finished and checkpointed and sum(map(len, checkpointed.values())) + CHUNKS * len(finished) == 10
    finished_times = {name: os.stat(tmp_path / name / "transient.npy").st_mtime_ns for name in finished}
    index = json.loads((tmp_path / "index.json").read_text())
    assert {row["name"] for row in index["items"] if row["status"] == "done"} == set(finished)

    result = run_sweep(sweep, tmp_path, client=client, progress=False)
    assert set(result.skipped_items) == set(finished)
    expected = {(item.name, c) for item in sweep.items if item.name not in finished for c in range(CHUNKS)
                if c not in checkpointed.get(item.name, ())}
    assert sorted(result.computed_chunks) == sorted(expected)
    assert {name: os.stat(tmp_path / name / "transient.npy").st_mtime_ns for name in finished} == finished_times
    assert_matches_reference(tmp_path, reference)
    # A third run has nothing left to do.
    again = run_sweep(sweep, tmp_path, client=client, progress=False)
    assert again.computed_chunks == () and len(again.skipped_items) == 4
    # Another seed into the same folder is refused, not mixed in.
    other = sweep_from_dict({"scene": "base.toml", "samples": SAMPLES, "seed": SEED + 1, "chunk": CHUNK,
                             "grid": sweep.grid}, sweep_file.parent)
    with pytest.raises(ResourceError, match="another"):
        run_sweep(other, tmp_path, client=client, progress=False)


def test_killed_worker_chunk_is_redone(client, sweep_file, reference, tmp_path):
    sweep = load_sweep(sweep_file)
    killed = {}

    def kill_a_busy_worker(name, chunk):
        if killed:
            return
        pids = client.run(os.getpid)
        busy = {address: keys for address, keys in client.processing().items() if keys}
        if busy:
            address, keys = next(iter(busy.items()))
            killed.update(address=address, tasks=len(keys))
            os.kill(pids[address], signal.SIGKILL)

    result = run_sweep(sweep, tmp_path, client=client, progress=False, on_chunk=kill_a_busy_worker)
    assert killed and killed["tasks"] >= 1
    # The lost chunks were redone elsewhere: every chunk arrived exactly once, and the result is exact.
    assert sorted(result.computed_chunks) == sorted((item.name, c) for item in sweep.items for c in range(CHUNKS))
    assert_matches_reference(tmp_path, reference)
    client.wait_for_workers(2, timeout=60)


def test_cli_on_a_running_scheduler(client, sweep_file, reference, tmp_path, capsys):
    argv = ["sweep", str(sweep_file), "--out", str(tmp_path), "--scheduler", client.scheduler.address]
    assert main(argv + ["--quiet"]) == 0
    assert_matches_reference(tmp_path, reference)
    assert main(argv) == 0
    assert "4 already done" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["sweep", str(sweep_file), "--out", str(tmp_path), "--scheduler", "x", "--workers", "2"])
