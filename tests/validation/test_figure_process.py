"""forward's figure process: the PNG that drawing in the command gives, drawn by a forked process, and a
fallback whenever that process dies, fails or hangs."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from analytic.scene_file import load_scene
from scene_files import GOOD, write_scene
from validation.plots import model_figure, png_bytes

ROOT = Path(__file__).resolve().parents[2]

# A fresh interpreter, where matplotlib and Numba are not loaded, so that start() forks. check() prints
# "forked" when the PNG came from the forked process (matplotlib still not loaded here) and "here" when
# the command drew it itself (the fallback loads matplotlib), after checking it is the figure asked for.
PRELUDE = """
import os, signal, sys, time
import numpy as np
from analytic.scene import Sampling
from validation import figure_process
from validation.plots import model_figure

def check(png, sampling, y):
    drawn_here = "matplotlib" in sys.modules
    from validation.plots import png_bytes
    assert png == png_bytes(model_figure(sampling, y, title="t")), "not the figure asked for"
    print("here" if drawn_here else "forked")

sampling = Sampling(bin_width_opl=0.1, start_opl=1.0, count=20)
y = np.exp(-np.arange(20.0))[None, :] * np.arange(1.0, 4.0)[:, None]
"""


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", PRELUDE + textwrap.dedent(code)], capture_output=True,
                          text=True, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=240)


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


def test_the_forked_process_draws_the_figure():
    done = _python("""
        process = figure_process.start()
        assert process.forked
        process.submit(model_figure, sampling, y, title="t")
        check(process.result(), sampling, y)
    """)
    assert done.returncode == 0 and done.stdout.split() == ["forked"], done.stderr


def test_a_dead_process_leaves_the_figure_to_the_command():
    done = _python("""
        process = figure_process.start()
        assert process.forked
        os.kill(process._pid, signal.SIGKILL)
        os.waitpid(process._pid, 0)
        process.submit(model_figure, sampling, y, title="t")
        check(process.result(), sampling, y)
    """)
    assert done.returncode == 0 and done.stdout.split() == ["here"], done.stderr


@pytest.mark.parametrize("stop", ["before submit", "after submit"])
def test_a_stuck_process_is_killed_and_the_command_draws_the_figure(stop):
    """Stopped before it takes a request larger than a pipe holds (submit times out), or after a small
    one while still loading matplotlib (result times out)."""
    done = _python(f"""
        figure_process.PATIENCE_SECONDS = 1.0
        process = figure_process.start()
        assert process.forked
        pid = process._pid
        bins = 200 if {stop!r} == "before submit" else 20
        wide = Sampling(bin_width_opl=0.1, start_opl=1.0, count=bins)
        data = np.exp(-np.arange(float(bins)))[None, :] * np.ones((64 if bins == 200 else 3, 1))
        started = time.monotonic()
        if {stop!r} == "before submit":
            os.kill(pid, signal.SIGSTOP)
        process.submit(model_figure, wide, data, title="t")
        if {stop!r} == "after submit":
            os.kill(pid, signal.SIGSTOP)
        png = process.result()
        assert time.monotonic() - started < 30
        try:
            os.waitpid(pid, 0)
            raise SystemExit("the stuck process was not reaped")
        except ChildProcessError:
            pass
        check(png, wide, data)
    """)
    assert done.returncode == 0 and done.stdout.split() == ["here"], done.stderr


def test_a_failing_figure_fails_in_the_command_with_its_own_error():
    done = _python("""
        process = figure_process.start()
        assert process.forked
        process.submit(model_figure, sampling, np.ones((2, 5, 7)))
        process.result()
    """)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines()[-1].startswith("TypeError: Invalid shape (2, 5, 7)"), done.stderr


def test_a_process_never_asked_exits_and_is_reaped():
    done = _python("""
        process = figure_process.start()
        assert process.forked
        pid = process._pid
        started = time.monotonic()
        process.close()
        try:
            os.waitpid(pid, 0)
            raise SystemExit("not reaped")
        except ChildProcessError:
            pass
        print("closed", time.monotonic() - started < figure_process.GRACE_SECONDS)
    """)
    assert done.returncode == 0 and done.stdout.split() == ["closed", "True"], done.stderr


def test_the_process_ends_with_a_killed_command():
    code = PRELUDE + textwrap.dedent("""
        process = figure_process.start()
        assert process.forked
        print(process._pid, flush=True)
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    # not subprocess.run: it would wait for the pipes, which the forked process holds while it lives
    with subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                          cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT))) as command:
        pid = int(command.stdout.readline())
        assert command.wait(timeout=120) == -9
        command.stdout.close()
    assert pid > 0
    import time
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:    # gone, or a zombie (exited; a container's init may not reap orphans)
            if Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                return
        except (FileNotFoundError, ProcessLookupError):
            return
        time.sleep(0.1)
    raise AssertionError(f"the figure process {pid} outlived its killed command")


def test_no_fork_where_it_cannot_gain_or_is_not_asked_for():
    import matplotlib  # noqa: F401  (loaded here: nothing to overlap)
    from validation import figure_process

    with figure_process.start() as process:
        assert not process.forked
    done = _python("""
        import numba
        print(figure_process.start(enabled=False).forked, figure_process.start().forked)
    """)
    assert done.stdout.split() == ["False", "False"], done.stderr
