"""The forked figure process: the same PNG as drawing in the command, a fallback when it dies, no orphan."""

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from analytic.scene_file import load_scene
from scene_files import GOOD, write_scene
from validation.plots import model_figure, png_bytes

ROOT = Path(__file__).resolve().parents[2]


def _python(code: str, **kwargs):
    """Run code in a fresh interpreter (where matplotlib and Numba are not loaded yet, so start() forks)."""
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120, **kwargs)


def test_forward_writes_the_figure_drawing_it_here_would(tmp_path):
    path = write_scene(tmp_path, GOOD + "\n[noise]\nsigma = 0.01\nseed = 3\n")
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "validation.cli", "forward", str(path), "--out", str(out),
                           "--quiet"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    scene = load_scene(path)
    expected = png_bytes(model_figure(scene.sampling, np.load(out / "transient.npy"),
                                      np.load(out / "transient_noisy.npy"),
                                      title=f"{scene.name}: impulse illumination, lambertian attenuation"))
    assert (out / "transient.png").read_bytes() == expected


def test_the_figure_process_forks_in_a_fresh_interpreter_and_draws_the_same_png():
    done = _python("""
        import numpy as np
        from analytic.scene import Sampling
        from validation import figure_process
        from validation.plots import model_figure, png_bytes
        process = figure_process.start()
        assert process.forked
        sampling = Sampling(bin_width_opl=0.1, start_opl=1.0, count=20)
        y = np.exp(-np.arange(20.0))[None, :] * np.arange(1.0, 4.0)[:, None]
        process.submit(model_figure, sampling, y, title="t")
        png = process.result()
        assert png == png_bytes(model_figure(sampling, y, title="t"))
        print("ok")
    """)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def test_a_dead_figure_process_leaves_the_figure_to_the_command():
    done = _python("""
        import os, signal
        import numpy as np
        from analytic.scene import Sampling
        from validation import figure_process
        from validation.plots import model_figure, png_bytes
        process = figure_process.start()
        assert process.forked
        os.kill(process._pid, signal.SIGKILL)
        os.waitpid(process._pid, 0)
        process._pid = -1
        sampling = Sampling(bin_width_opl=0.1, start_opl=1.0, count=20)
        y = np.exp(-np.arange(20.0))[None, :]
        process.submit(model_figure, sampling, y, title="t")
        assert process.result() == png_bytes(model_figure(sampling, y, title="t"))
        print("ok")
    """)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def test_a_stuck_figure_process_is_killed_and_the_command_draws_the_figure():
    done = _python("""
        import os, signal, time
        import numpy as np
        from analytic.scene import Sampling
        from validation import figure_process
        from validation.plots import model_figure, png_bytes
        figure_process.PATIENCE = 1.0
        process = figure_process.start()
        pid = process._pid
        os.kill(pid, signal.SIGSTOP)
        sampling = Sampling(bin_width_opl=0.1, start_opl=1.0, count=200)
        y = np.exp(-np.arange(200.0))[None, :] * np.ones((64, 1))    # 100 kB: more than a pipe holds
        started = time.monotonic()
        process.submit(model_figure, sampling, y, title="t")
        png = process.result()
        assert time.monotonic() - started < 30
        assert png == png_bytes(model_figure(sampling, y, title="t"))
        try:
            os.kill(pid, 0)
            raise SystemExit("the stuck process is still there")
        except ProcessLookupError:
            print("ok")
    """)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def test_a_failing_figure_fails_in_the_command_with_its_own_error():
    done = _python("""
        import numpy as np
        from analytic.scene import Sampling
        from validation import figure_process
        from validation.plots import model_figure
        process = figure_process.start()
        process.submit(model_figure, Sampling(bin_width_opl=0.1, start_opl=1.0, count=20), np.ones((2, 5, 7)))
        process.result()
    """)
    assert done.returncode == 1 and "Traceback" in done.stderr


def test_the_figure_process_ends_with_a_killed_command():
    code = textwrap.dedent("""
        import os, signal
        from validation import figure_process
        process = figure_process.start()
        print(process._pid, flush=True)
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    # not subprocess.run: it would wait for the pipes, which the figure process holds while it lives
    with subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                          cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT))) as command:
        pid = int(command.stdout.readline())
        assert command.wait(timeout=120) == -9
        command.stdout.close()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:    # gone, or a zombie (exited; a container's init may not reap orphans)
            if Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                return
        except (FileNotFoundError, ProcessLookupError):
            return
        time.sleep(0.1)
    pytest.fail(f"the figure process {pid} outlived its killed command")


def test_no_process_is_forked_where_matplotlib_is_loaded():
    import matplotlib  # noqa: F401
    from validation import figure_process

    with figure_process.start() as process:
        assert not process.forked
