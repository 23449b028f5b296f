"""Checkpoints, resume and refusals of transient.render (the render's state file).

An interrupted render (Ctrl-C, SIGTERM, kill -9) resumes to the numbers of
an uninterrupted one; every bad argument is refused before any work; every
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

from analytic.scene import Sampling, Scene
from transient.render import STATE_FILE, RenderStateError, render, scene_fingerprint


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


def _interrupted(scene, folder, *, after: int, seed: int = 17):
    """Render into ``folder`` and stop (as Ctrl-C would) once ``after`` samples are done."""
    def stop(done):
        if done >= after:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render(scene, spp=SAMPLES, seed=seed, chunk_size=CHUNK, out_dir=folder, progress=False, on_chunk=stop)


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
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["kind"] == "render" and meta["seed"] == 17 and meta["replicas"] >= 2
    assert meta["samples"] == meta["replicas"] * SAMPLES // 32
    resumed = render(scene, spp=SAMPLES, seed=17, chunk_size=CHUNK, out_dir=tmp_path, resume=True, progress=False)
    assert resumed.samples == SAMPLES and resumed.dof == 31
    np.testing.assert_allclose(resumed.mean, straight.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(resumed.stderr, straight.stderr, rtol=1e-9, atol=0)
    np.testing.assert_allclose(np.load(tmp_path / "transient.npy"), straight.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.load(tmp_path / "stderr.npy"), straight.stderr, rtol=1e-9, atol=0)
    assert json.loads((tmp_path / "meta.json").read_text())["samples"] == SAMPLES


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
from analytic.scene import Sampling, Scene
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
    module = importlib.import_module("transient.render")

    if reseal:
        identity = json.loads(str(state["identity"]))
        progress = {"done": int(state["done"]), "completed": int(state["completed"]),
                    **{name: np.asarray(state[name], dtype=np.float64) for name in ("partial", "replica_mean",
                                                                                   "deviations")}}
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
    state["replica_mean"] = state["replica_mean"] * 1.001
    _rewrite(saved, state, reseal=False)
    _refused(scene, saved, "corrupted")


@pytest.mark.parametrize("damage, pattern", [
    ("nan", "NaN"), ("negative", "negative"), ("wrong shape", "shape"), ("counts", "replicas complete")])
def test_inconsistent_states_are_refused_even_with_a_valid_checksum(scene, saved, damage, pattern):
    state = _state(saved)
    if damage == "nan":
        state["partial"] = state["partial"] * np.nan
    elif damage == "negative":
        state["deviations"] = -1.0 - state["deviations"]
    elif damage == "wrong shape":
        state["replica_mean"] = np.zeros((3, 30))
    else:
        state["completed"] = np.int64(int(state["completed"]) + 1)
    _rewrite(saved, state, reseal=True)
    assert "inconsistent" in _refused(scene, saved, pattern)


def test_state_of_another_render_is_refused(scene, saved):
    _refused(scene, saved, "seed 17", seed=18)
    _refused(scene.replace(source=(0.3, 0.6, 0.9)), saved, "different scene")
    _refused(scene, saved, "different scene or estimator", estimator={"sampler": "independent"})
    assert "--spp 524288" in _refused(scene, saved, "planned for spp", spp=2 * SAMPLES)
    assert "below" in _refused(scene, saved, "below", spp=2**16)
    state = _state(saved)
    identity = json.loads(str(state["identity"]))
    state["identity"] = np.array(json.dumps(dict(identity, variant="cuda_ad_mono"), sort_keys=True))
    _rewrite(saved, state, reseal=True)
    _refused(scene, saved, "variant")


def test_fingerprint_covers_scene_and_estimator(scene):
    base = scene_fingerprint(scene)
    assert base != scene_fingerprint(scene.replace(source=(0.4, 0.6, 0.70000001)))
    assert base != scene_fingerprint(scene, {"strategy": "area"})
    assert base == scene_fingerprint(scene.replace(attenuation="paper"))       # the renderer ignores it
