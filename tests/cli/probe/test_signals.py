"""Issue 22's second probe (its harness and promises: tests/probe/cli_probe.py): signals at random times and two
commands on one folder, in child processes.
"""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import time
from pathlib import Path

import numpy as np

from probe.cli_probe import GOOD, LOCK_FILE, PROGRAM, Probe, TEMPORARY_PREFIX, case_table, case_test, tree


CASES, case = case_table()


def _spawn(probe: Probe, *argv, env=None):
    argv = [str(a) for a in argv]
    probe.commands.append("diffuse-imaging " + " ".join(shlex.quote(a) for a in argv) + " &")
    return subprocess.Popen([*PROGRAM, *argv], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            cwd=probe.tmp, env={**os.environ, **(env or {})})


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(TEMPORARY_PREFIX) or p.name == LOCK_FILE) \
        if folder.is_dir() else []


LONG_SPP = 2**29


def _signal_then_resume(probe: Probe, signum: int, seed: int, after_checkpoint: bool = False):
    """Render, deliver ``signum`` at a random time, resume; the result must be the uninterrupted render's.

    The time is drawn after the folder's lock appears (or its first checkpoint, ``after_checkpoint``).
    Before the first checkpoint nothing can be resumed: then the interrupted render says so, and
    ``--resume`` is refused in one line.
    """
    delay = np.random.default_rng(seed).uniform(0.0, 2.5)
    scene = probe.scene()
    child = _spawn(probe, "render", scene, "--spp", LONG_SPP, "--seed", "9", "--out", probe.out, "--quiet")
    _wait_for_lock(probe.out, child)
    deadline = time.monotonic() + 60
    while after_checkpoint and not (probe.out / "render_state.npz").exists() and child.poll() is None \
            and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(delay)
    child.send_signal(signum)
    try:
        _, err = child.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        child.kill()
        _, err = child.communicate()
        probe.problem(f"the render did not end within 60 s of signal {signum}")
    lines = [line for line in err.decode("utf-8", "replace").splitlines() if line.strip()]
    saved = (probe.out / "render_state.npz").exists()
    probe.observed.append(f"signal {signal.Signals(signum).name} {delay:.2f} s after the "
                          f"{'checkpoint' if after_checkpoint else 'lock'}: exit {child.returncode}, "
                          f"stderr {lines[:2]}, state saved: {saved}")
    probe.check(not any("Traceback" in line for line in lines), f"traceback: {lines[-3:]}")
    if child.returncode != 0:
        expected_status = {signal.SIGINT: 130, signal.SIGTERM: 130, signal.SIGKILL: -9}[signum]
        probe.check(child.returncode == expected_status, f"exit {child.returncode}, expected {expected_status}")
        if signum != signal.SIGKILL:
            said = "--resume" if saved else "nothing was saved"
            probe.check(len(lines) == 1 and said in lines[0], f"stderr {lines}, expected one line with {said!r}")
        probe.sub("render", "--resume", probe.out, "--quiet", timeout=120)
        if not saved:
            probe.refused("nothing to resume")
            return
        probe.answered()
    probe.check(not _leftovers(probe.out), f"left in --out: {_leftovers(probe.out)}")
    resumed = probe.y()
    straight = probe.tmp / "straight"
    probe.sub("render", scene, "--spp", LONG_SPP, "--seed", "9", "--out", straight, "--quiet", timeout=120,
              outside_changes=True)
    if probe.answered() and resumed is not None:
        # README: "continues from the last checkpoint to the same numbers": to float64 rounding (the
        # replica sums are regrouped at the checkpoint), not necessarily bit for bit
        whole = np.load(straight / "transient.npy")
        probe.observed.append(f"bit for bit: {np.array_equal(resumed, whole)}")
        probe.close(resumed, whole, rtol=1e-14, what="resumed y")
        # the standard error is a difference of nearly equal sums: compare it on the scale of y
        probe.close(np.load(probe.out / "stderr.npy"), np.load(straight / "stderr.npy"),
                    atol=1e-13 * np.abs(whole).max(), what="resumed stderr")


for _signum, _seed in ((signal.SIGINT, 1), (signal.SIGTERM, 2), (signal.SIGKILL, 3)):
    @case("signals", f"{signal.Signals(_signum).name} at a random time during render, then --resume",
          "exit 130 (SIGINT, SIGTERM; one line naming --resume) or killed; --resume gives the uninterrupted "
          "render bit for bit; no temporaries, no lock", slow=True)
    def _(probe, signum=_signum, seed=_seed):
        _signal_then_resume(probe, signum, seed, after_checkpoint=signum == signal.SIGKILL)


def _wait_for_lock(folder: Path, child, seconds: float = 60) -> bool:
    deadline = time.monotonic() + seconds
    while not (folder / LOCK_FILE).exists():
        if child.poll() is not None or time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


_BUSY = GOOD.toml().replace("positions = [[0.2, 0.7, 1.0]]", "grid = [8, 8]\ncenter = [0.5, 0.5, 1.0]") \
    .replace("pixels = 8", "pixels = 32").replace("count = 12", "count = 60").replace("period = 0.1", "period = 0.02")


@case("signals", "SIGKILL at a random time during forward, then forward again",
      "exit 0; no temporaries or lock left; y equal to an undisturbed forward", slow=True)
def _(probe):
    scene = probe.file("scene.toml", _BUSY)
    child = _spawn(probe, "forward", scene, "--out", probe.out, "--quiet")
    if _wait_for_lock(probe.out, child):
        time.sleep(np.random.default_rng(4).uniform(0.0, 1.0))
    child.kill()
    child.communicate()
    probe.observed.append(f"killed: exit {child.returncode}; left {sorted(tree(probe.out))}")
    probe.sub("forward", scene, "--out", probe.out, "--quiet", timeout=300)
    probe.answered()
    probe.check(not _leftovers(probe.out), f"left in --out: {_leftovers(probe.out)}")
    first = probe.y()
    probe.out = probe.tmp / "calm"
    probe.sub("forward", scene, "--out", probe.out, "--quiet", timeout=300)
    if probe.answered() and first is not None:
        probe.check(np.array_equal(first, probe.y()), "y differs from an undisturbed forward")


@case("signals", "SIGINT at a random time during forward", "exit 130, one line; the --out it created removed",
      slow=True)
def _(probe):
    child = _spawn(probe, "forward", probe.file("scene.toml", _BUSY), "--out", probe.out, "--quiet")
    if _wait_for_lock(probe.out, child):
        time.sleep(np.random.default_rng(5).uniform(0.0, 0.5))
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=120)
    lines = [line for line in err.decode("utf-8", "replace").splitlines() if line.strip()]
    probe.observed.append(f"exit {child.returncode}, stderr {lines[:3]}, out {sorted(tree(probe.out))}")
    if child.returncode == 0:
        probe.observed.append("finished before the signal; not judged")
        return
    probe.check(child.returncode == 130 and len(lines) == 1 and "interrupted" in lines[0],
                f"exit {child.returncode}, {lines[:3]}")
    probe.check(not os.path.lexists(probe.out), f"--out left: {sorted(tree(probe.out))}")


@case("concurrency", "two renders on one folder at once",
      "the first exit 0; the second exit 2 in one line naming the other's process id", slow=True)
def _(probe):
    scene = probe.scene()
    first = _spawn(probe, "render", scene, "--spp", LONG_SPP, "--out", probe.out, "--quiet")
    deadline = time.monotonic() + 30
    while not (probe.out / LOCK_FILE).exists() and time.monotonic() < deadline and first.poll() is None:
        time.sleep(0.02)
    time.sleep(0.2)
    probe.sub("render", scene, "--spp", "4096", "--out", probe.out, "--quiet", outside_changes=True)
    if first.poll() is None:
        probe.refused(str(first.pid), out_as_it_was=False)     # the first one is writing it
    else:
        probe.observed.append("the first render ended before the second started; not judged")
    _, err = first.communicate(timeout=120)
    probe.check(first.returncode == 0 and not err.strip(), f"the first: exit {first.returncode}, {err[-300:]}")
    probe.check(not _leftovers(probe.out), f"left in --out: {_leftovers(probe.out)}")


@case("concurrency", "check reading a folder a render is writing",
      "exit 2 in one line naming the writer, or it waits and judges the finished render", slow=True)
def _(probe):
    scene = probe.scene()
    render_out = probe.tmp / "render"
    writer = _spawn(probe, "render", scene, "--spp", LONG_SPP, "--out", render_out, "--quiet")
    deadline = time.monotonic() + 30
    while not (render_out / LOCK_FILE).exists() and time.monotonic() < deadline and writer.poll() is None:
        time.sleep(0.02)
    probe.sub("check", scene, "--data", render_out, "--out", probe.out, "--quiet", outside_changes=True)
    if probe.status == 2:
        probe.refused("writing")
    else:
        probe.check(probe.status in (0, 1) and not probe.lines, f"exit {probe.status}, {probe.lines}")
    writer.communicate(timeout=120)
    probe.check(writer.returncode == 0, f"the render: exit {writer.returncode}")


@case("concurrency", "six forwards on one folder at once",
      "each exit 0, or exit 2 in one line naming another process; the files the reference's; nothing left", slow=True)
def _(probe):
    scene = probe.scene()
    children = [_spawn(probe, "forward", scene, "--out", probe.out, "--quiet") for _ in range(6)]
    results = [(child.communicate(timeout=120)[1].decode(), child.returncode)[::-1] for child in children]
    probe.observed.append(f"exits {[status for status, _ in results]}")
    for status, err in results:
        lines = [line for line in err.splitlines() if line.strip()]
        if status == 0:
            probe.check(not lines, f"stderr {lines}")
        else:
            probe.check(status == 2 and len(lines) == 1 and "another diffuse-imaging command" in lines[0],
                        f"exit {status}, {lines}")
    probe.check(any(status == 0 for status, _ in results), "none succeeded")
    probe.matches_reference(GOOD)
    probe.check(not _leftovers(probe.out), f"left in --out: {_leftovers(probe.out)}")


test_case = case_test(CASES)
