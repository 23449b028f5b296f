"""Checkpoints, resume and refusals of transient.render (the render's state and scene files).

An interrupted render (Ctrl-C, SIGTERM, kill -9) resumes, from its folder
alone, to the numbers of an uninterrupted one; until then its outputs say
they are partial; every bad argument is refused before any work; every
state that cannot be resumed is refused with a one-line RenderStateError
naming the file and the fix.
"""

from __future__ import annotations

import importlib
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from analytic.scenes.common import Sampling, Scene
from transient.render import PARTIAL_FOLDER, REPLICAS_FILE, RenderInterrupted, render, resume
from transient.render_state import SCENE_FILE, STATE_FILE, RenderStateError, read_saved_render, scene_fingerprint


@pytest.fixture(scope="module")
def scene():
    image = np.random.default_rng(7).uniform(0.1, 0.9, (6, 6))
    return Scene(size=1.0, pixels=6, reflectance=image, source=(0.4, 0.6, 0.7),
                 sensors=[(0.2, 0.3, 0.5), (0.9, 0.8, 0.6)],
                 sampling=Sampling(bin_width_opl=0.05, start_opl=1.0, count=30))


SAMPLES, CHUNK = 2**19, 2**16


@pytest.fixture(scope="module")
def straight(scene):
    return render(scene, spp=SAMPLES, seed=17, chunk_size=CHUNK, progress=False)


def _interrupted(scene, folder, *, after: int, seed: int = 17) -> RenderInterrupted:
    """Render into ``folder`` and stop (as Ctrl-C would) once ``after`` samples are done."""
    def stop(done):
        if done >= after:
            raise KeyboardInterrupt

    with pytest.raises(RenderInterrupted) as stopped:
        render(scene, spp=SAMPLES, seed=seed, chunk_size=CHUNK, out_dir=folder, progress=False, on_chunk=stop)
    return stopped.value


def test_first_checkpoint_comes_with_the_first_chunk(scene, tmp_path):
    seen = []

    def look(done):
        if not seen:
            with np.load(tmp_path / STATE_FILE) as state:
                seen.append(int(state["done"]))

    render(scene, spp=SAMPLES, seed=1, chunk_size=CHUNK, out_dir=tmp_path, progress=False, on_chunk=look)
    assert seen == [2**16]                          # the first chunk, checkpointed at once


def test_interrupt_then_resume_matches_uninterrupted(scene, straight, tmp_path):
    _interrupted(scene, tmp_path, after=3 * CHUNK)
    with np.load(tmp_path / STATE_FILE) as state:
        assert int(state["done"]) >= 3 * CHUNK
    # The estimate so far is labelled partial, and no complete-looking file exists yet.
    assert not (tmp_path / "transient.npy").exists() and not (tmp_path / "meta.json").exists()
    meta = json.loads((tmp_path / PARTIAL_FOLDER / "meta.json").read_text())
    assert meta["complete"] is False and meta["kind"] == "render" and meta["seed"] == 17 and meta["replicas"] >= 2
    assert meta["samples"] == meta["replicas"] * SAMPLES // 32
    partial = np.load(tmp_path / PARTIAL_FOLDER / REPLICAS_FILE)
    assert partial.shape == (meta["replicas"], 2, 30)
    resumed = render(scene, spp=SAMPLES, seed=17, chunk_size=CHUNK, out_dir=tmp_path, resume=True, progress=False)
    assert resumed.samples == SAMPLES and resumed.dof == 31
    assert resumed.drawn == SAMPLES - 3 * CHUNK                 # this run's samples only
    np.testing.assert_allclose(resumed.mean, straight.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(resumed.stderr, straight.stderr, rtol=1e-9, atol=0)
    np.testing.assert_allclose(np.load(tmp_path / "transient.npy"), straight.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.load(tmp_path / "stderr.npy"), straight.stderr, rtol=1e-9, atol=0)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["samples"] == SAMPLES and meta["complete"] is True
    assert not (tmp_path / PARTIAL_FOLDER).exists()


def test_outputs_hold_the_replica_means(scene, straight, tmp_path):
    """replicas.npy: the R replica estimates whose mean is transient.npy and whose spread is stderr.npy."""
    result = render(scene, spp=SAMPLES, seed=17, chunk_size=CHUNK, out_dir=tmp_path, progress=False)
    replicas = np.load(tmp_path / REPLICAS_FILE)
    assert replicas.shape == (32, 2, 30) and replicas.dtype == np.float64
    np.testing.assert_allclose(replicas, result.replica_means, rtol=0, atol=0)
    np.testing.assert_allclose(replicas.mean(axis=0), np.load(tmp_path / "transient.npy"), rtol=1e-13, atol=0)
    np.testing.assert_allclose(replicas.std(axis=0, ddof=1) / np.sqrt(32), np.load(tmp_path / "stderr.npy"),
                               rtol=1e-10, atol=0)
    # Independent replicas: their spread is the estimate's, not a copy of one replica.
    assert np.all(np.ptp(replicas, axis=0)[straight.mean > 0] > 0)


def test_resume_from_the_folder_alone(scene, straight, tmp_path):
    """The folder holds the scene, seed, samples and variant: nothing else is needed to finish."""
    stopped = _interrupted(scene, tmp_path, after=2 * CHUNK)
    assert (stopped.done, stopped.planned, stopped.folder) == (2 * CHUNK, SAMPLES, tmp_path)
    saved = read_saved_render(tmp_path)
    assert (saved.spp, saved.seed, saved.done) == (SAMPLES, 17, 2 * CHUNK)
    assert scene_fingerprint(saved.scene) == scene_fingerprint(scene)
    resumed = resume(tmp_path, chunk_size=CHUNK, progress=False)
    np.testing.assert_allclose(resumed.mean, straight.mean, rtol=1e-12, atol=0)


def test_resume_names_every_argument_that_differs(scene, saved):
    message = _resume_refused(saved, spp=1000, seed=3)
    assert "--spp 1000 differs from the state's 524288" in message
    assert "--seed 3 differs from the state's 17" in message
    assert "different" not in message                                  # not blamed on the scene
    message = _resume_refused(saved, scene=scene.replace(source=(0.4, 0.6, 0.71)))
    assert "scene given differs" in message
    # Fields a render does not read may differ: they only go to meta.json.
    resume(saved, scene=scene.replace(tolerance=1e-4, name="renamed"), chunk_size=CHUNK, progress=False)
    assert json.loads((saved / "meta.json").read_text())["scene"] == "renamed"


def test_a_damaged_scene_file_is_refused_in_one_line_and_the_scene_given_again_resumes(scene, straight, saved):
    (saved / SCENE_FILE).write_bytes(b"not an archive")
    message = _resume_refused(saved)
    assert SCENE_FILE in message and "SCENE --resume" in message
    resumed = resume(saved, scene=scene, chunk_size=CHUNK, progress=False)      # as the message says
    np.testing.assert_allclose(resumed.mean, straight.mean, rtol=1e-12, atol=0)
    assert scene_fingerprint(read_saved_render(saved).scene) == scene_fingerprint(scene)   # repaired
    (saved / SCENE_FILE).unlink()
    assert "no " + SCENE_FILE in _resume_refused(saved)


def test_sigterm_keeps_finished_chunks(scene, straight, tmp_path):
    def terminate(done):
        os.kill(os.getpid(), signal.SIGTERM)

    previous = signal.getsignal(signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt):
        render(scene, spp=SAMPLES, seed=17, chunk_size=CHUNK, out_dir=tmp_path, progress=False,
               on_chunk=terminate)
    assert signal.getsignal(signal.SIGTERM) is previous
    with np.load(tmp_path / STATE_FILE) as state:
        assert int(state["done"]) == 2**16
    resumed = render(scene, spp=SAMPLES, seed=17, chunk_size=CHUNK, out_dir=tmp_path, resume=True, progress=True)
    np.testing.assert_allclose(resumed.mean, straight.mean, rtol=1e-12, atol=0)


_KILLED = r"""
import sys
import numpy as np
from analytic.scenes.common import Sampling, Scene
from transient.render import render
image = np.random.default_rng(7).uniform(0.1, 0.9, (6, 6))
scene = Scene(size=1.0, pixels=6, reflectance=image, source=(0.4, 0.6, 0.7),
              sensors=[(0.2, 0.3, 0.5), (0.9, 0.8, 0.6)],
              sampling=Sampling(bin_width_opl=0.05, start_opl=1.0, count=30))
render(scene, spp=int(sys.argv[2]), seed=17, chunk_size=2**16, out_dir=sys.argv[1], progress=False)
"""


def test_kill_9_after_the_first_checkpoint_then_resume(scene, tmp_path):
    """kill -9 loses at most the work since the last checkpoint; --resume continues to the same numbers."""
    samples = 2**24
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    child = subprocess.Popen([sys.executable, "-c", _KILLED, str(tmp_path), str(samples)], env=environment,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not (tmp_path / STATE_FILE).exists():
            assert child.poll() is None, child.stderr.read().decode()
            assert time.monotonic() < deadline, "no checkpoint within 2 minutes"
            time.sleep(0.02)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait(timeout=60)
        child.stderr.close()
    assert child.returncode == -signal.SIGKILL
    with np.load(tmp_path / STATE_FILE) as state:
        done = int(state["done"])
    assert 0 < done < samples
    assert not list(tmp_path.glob(f".{STATE_FILE}*"))      # no torn state under the final name
    resumed = render(scene, spp=samples, seed=17, chunk_size=2**16, out_dir=tmp_path, resume=True, progress=False)
    straight = render(scene, spp=samples, seed=17, progress=False)
    np.testing.assert_allclose(resumed.mean, straight.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(resumed.stderr, straight.stderr, rtol=1e-9, atol=0)


# -- refusals ----------------------------------------------------------------------


@pytest.mark.parametrize("changes, message", [
    ({"spp": 1}, "spp"), ({"spp": 2**70}, "2\\^48"), ({"spp": 1.5}, "spp"), ({"spp": True}, "spp"),
    ({"seed": -1}, "seed"), ({"seed": 2**32}, "seed"), ({"seed": 2**64}, "seed"), ({"seed": 0.5}, "seed"),
    ({"chunk_size": 0}, "chunk_size"), ({"replicas": 1}, "replicas"), ({"resume": True}, "out_dir"),
])
def test_bad_arguments_are_refused_before_any_work(scene, tmp_path, changes, message):
    arguments = {"spp": 1000, "seed": 0, "progress": False} | changes
    with pytest.raises(ValueError, match=message) as error:
        render(scene, **arguments)
    assert "\n" not in str(error.value)
    assert not list(tmp_path.iterdir())


def _state(tmp_path):
    with np.load(tmp_path / STATE_FILE) as saved:
        return {name: saved[name] for name in saved.files}


def _rewrite(tmp_path, state, *, reseal: bool):
    """Write a state back, with a checksum recomputed for its (altered) contents when ``reseal``."""
    module = importlib.import_module("transient.render_state")

    if reseal:
        identity = json.loads(str(state["identity"]))
        progress = {"done": int(state["done"]), "completed": int(state["completed"]),
                    **{name: np.asarray(state[name], dtype=np.float64) for name in ("partial", "replica_means")}}
        state = dict(state, checksum=np.array(module._checksum(identity, progress)))
    with open(tmp_path / STATE_FILE, "wb") as stream:
        np.savez(stream, **state)


def _refused(scene, folder, pattern, **changes):
    arguments = {"spp": SAMPLES, "seed": 17, "chunk_size": CHUNK, "out_dir": folder, "resume": True,
                 "progress": False} | changes
    with pytest.raises(RenderStateError, match=pattern) as error:
        render(scene, **arguments)
    message = str(error.value)
    assert "\n" not in message and message.startswith("resume: ")
    return message


def _resume_refused(folder, **given):
    with pytest.raises(RenderStateError) as error:
        resume(folder, chunk_size=CHUNK, progress=False, **given)
    message = str(error.value)
    assert "\n" not in message and message.startswith("resume: ")
    return message


@pytest.fixture
def saved(scene, tmp_path):
    """A folder holding the state of a render stopped after 3 chunks."""
    _interrupted(scene, tmp_path, after=3 * CHUNK)
    return tmp_path


def test_resume_without_a_state_is_refused(scene, tmp_path):
    assert "does not exist" in _refused(scene, tmp_path / "missing", "folder")
    assert "nothing to resume" in _refused(scene, tmp_path, STATE_FILE)


@pytest.mark.parametrize("damage", ["empty", "truncated", "random bytes", "not a zip of arrays"])
def test_unreadable_states_are_refused(scene, saved, damage):
    path = saved / STATE_FILE
    content = path.read_bytes()
    path.write_bytes({"empty": b"", "truncated": content[: len(content) // 2],
                      "random bytes": np.random.default_rng(1).bytes(4096),
                      "not a zip of arrays": b"sums = [1, 2, 3]\n"}[damage])
    message = _refused(scene, saved, "not a readable render state")
    assert str(path) in message and "delete it" in message


def test_tampered_state_is_refused_by_its_checksum(scene, saved):
    state = _state(saved)
    state["replica_means"] = state["replica_means"] * 1.001
    _rewrite(saved, state, reseal=False)
    _refused(scene, saved, "corrupted")


@pytest.mark.parametrize("damage, pattern", [
    ("nan", "NaN"), ("infinite", "infinite"), ("wrong shape", "shape"), ("counts", "replicas complete")])
def test_inconsistent_states_are_refused_even_with_a_valid_checksum(scene, saved, damage, pattern):
    state = _state(saved)
    if damage == "nan":
        state["partial"] = state["partial"] * np.nan
    elif damage == "infinite":
        state["replica_means"] = state["replica_means"] + np.inf
    elif damage == "wrong shape":
        state["replica_means"] = np.zeros((3, 30))
    else:
        state["completed"] = np.int64(int(state["completed"]) + 1)
    _rewrite(saved, state, reseal=True)
    assert "inconsistent" in _refused(scene, saved, pattern)


def test_state_of_another_render_is_refused(scene, saved):
    _refused(scene, saved, "--seed 18 differs from the state's 17", seed=18)
    _refused(scene.replace(source=(0.3, 0.6, 0.9)), saved, "scene given differs")
    _refused(scene.replace(attenuation="paper"), saved, "scene given differs")
    _refused(scene, saved, "estimator options", estimator={"sampler": "independent"})
    _refused(scene, saved, "--spp 1048576 differs from the state's 524288", spp=2 * SAMPLES)
    _refused(scene, saved, "--spp 65536 differs from the state's 524288", spp=2**16)
    state = _state(saved)
    identity = json.loads(str(state["identity"]))
    state["identity"] = np.array(json.dumps(dict(identity, variant="cuda_ad_mono"), sort_keys=True))
    _rewrite(saved, state, reseal=True)
    _refused(scene, saved, "--variant llvm_.*differs from the state's cuda_ad_mono")


def test_a_state_of_the_previous_format_is_refused(scene, saved):
    state = _state(saved)
    identity = json.loads(str(state["identity"]))
    state["identity"] = np.array(json.dumps(dict(identity, format="diffuse-imaging render state 2 "
                                                                 "(stratified replicas)"), sort_keys=True))
    _rewrite(saved, state, reseal=True)
    _refused(scene, saved, "another version")


def test_fingerprint_covers_scene_and_estimator(scene):
    base = scene_fingerprint(scene)
    assert base != scene_fingerprint(scene.replace(source=(0.4, 0.6, 0.70000001)))
    assert base != scene_fingerprint(scene, {"strategy": "area"})
    assert base != scene_fingerprint(scene.replace(attenuation="paper"))       # the renderer renders it
    assert base != scene_fingerprint(scene.replace(intensity=2.0))
    assert base == scene_fingerprint(scene.replace(tolerance=1e-4, name="other"))   # the model's alone


def test_a_relay_wall_fingerprint_covers_what_the_renderer_reads():
    """A capture through a relay wall: every key of its wall, hidden rectangle, laser, sensor, scan and image
    changes the fingerprint; its name, tolerance and noise do not."""
    from analytic.scenes.relay_wall import RelayWallScene, Scan
    from analytic.scenes.common import Noise

    image = np.random.default_rng(3).uniform(0.1, 0.9, (4, 4))
    scene = RelayWallScene(pixels=4, reflectance=image, scan=Scan(type="single", grid=(2, 2)))
    base = scene_fingerprint(scene)
    other = image.copy()
    other[1, 2] += 1e-9
    for changes in (dict(wall_size=(2.0, 2.5)), dict(wall_reflectance=0.5), dict(center=(0.0, 0.0, 1.0000001)),
                    dict(laser_position=(-0.5, 0.0, 0.3)), dict(sensor_position=(-0.4, 0.0, 0.25)),
                    dict(intensity=2.0), dict(reflectance=other), dict(scan=Scan(type="confocal", grid=(2, 2))),
                    dict(scan=Scan(type="single", grid=(2, 2), account_first_and_last_bounces=True)),
                    dict(scan=Scan(type="single", grid=(2, 2), laser_point=(0.1, 0.0, 0.0))),
                    dict(sampling=Sampling(bin_width_opl=0.02, start_opl=1.0, count=40))):
        assert scene_fingerprint(scene.replace(**changes)) != base, changes
    assert scene_fingerprint(scene.replace(name="x", tolerance=1e-4, noise=Noise(sigma=1e-3))) == base


def test_a_relay_wall_render_folder_holds_its_scene(tmp_path):
    """The saved scene of a capture reads back to the same fingerprint, its image bit for bit."""
    from analytic.scenes.relay_wall import RelayWallScene, Scan
    from transient.render_state import save_scene, _load_saved_scene

    image = np.random.default_rng(5).uniform(0.1, 0.9, (4, 4))
    scene = RelayWallScene(pixels=4, reflectance=image, scan=Scan(type="exhaustive", grid=(2, 1), laser_grid=(1, 2),
                                                                  account_first_and_last_bounces=True))
    save_scene(tmp_path, scene)
    back = _load_saved_scene(tmp_path)
    assert isinstance(back, RelayWallScene) and scene_fingerprint(back) == scene_fingerprint(scene)
    np.testing.assert_array_equal(back.reflectance, image)
