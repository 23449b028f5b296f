"""Issue 22's second probe (its harness and promises: tests/probe/cli_probe.py): the environment, in child processes:
HOME, locale, TMPDIR, stdout, a full or read-only disk.
"""

from __future__ import annotations

import contextlib
import dataclasses
import subprocess

import numpy as np
import pytest

from probe.cli_reference import write_exr
from probe.cli_probe import ERROR, GOOD, case_table, case_test, noisy_data


CASES, case = case_table()

# an 8 x 8 reflectance that float32 holds exactly
_single = np.random.default_rng(11).uniform(0, 1, (8, 8)).astype(np.float32)


@case("environment", "HOME unset: forward and render", "exit 0 each, stderr empty", slow=True)
def _(probe):
    scene = probe.scene()
    probe.sub("forward", scene, "--out", probe.tmp / "f", "--quiet", unset=("HOME",), outside_changes=True).answered()
    probe.sub("render", scene, "--spp", "4096", "--out", probe.tmp / "r", "--quiet", unset=("HOME",),
              outside_changes=True).answered()


@case("environment", "HOME a file (no ~/.config possible)", "exit 0, stderr empty (no library notice)")
def _(probe):
    probe.sub("forward", probe.scene(), "--out", probe.out, "--quiet", env={"HOME": str(probe.file("home", ""))})
    probe.answered()


@case("environment", "LC_ALL=C, a scene named 'scène ✓'", "exit 0, stderr empty, the summary escaped", slow=True)
def _(probe):
    scene = probe.scene(GOOD.toml().replace("[plane]", 'name = "scène ✓"\n[plane]'))
    probe.sub("forward", scene, "--out", probe.out, env={"LC_ALL": "C", "LANG": "C"})
    probe.answered()


@case("environment", "PYTHONIOENCODING=ascii, --out with accents", "exit 0, stderr empty", slow=True)
def _(probe):
    probe.out = probe.tmp / "sortie é"
    probe.sub("forward", probe.scene(), "--out", probe.out, env={"PYTHONIOENCODING": "ascii"}).answered()


@case("environment", "TMPDIR a missing folder, an EXR image", "exit 0, stderr empty, y equal to the reference")
def _(probe):
    write_exr(probe.tmp / "image.exr", {"Y": _single})
    geometry = dataclasses.replace(GOOD, reflectance=_single.astype(np.float64))
    probe.sub("forward", probe.scene(geometry.toml(image="image.exr")), "--out", probe.out, "--quiet",
              env={"TMPDIR": str(probe.tmp / "missing")})
    if probe.answered():
        probe.matches_reference(geometry)


@case("environment", "MPLCONFIGDIR unwritable (under /proc)", "exit 0, stderr empty (no matplotlib notice)")
def _(probe):
    probe.sub("forward", probe.scene(), "--out", probe.out, "--quiet",
              env={"MPLCONFIGDIR": "/proc/diffuse-imaging-mpl"}).answered()


@case("environment", "the working folder deleted, absolute paths", "exit 0", slow=True)
def _(probe):
    gone = probe.tmp / "gone"
    gone.mkdir()
    scene = probe.scene()
    probe.sub("forward", scene, "--out", probe.out, "--quiet", cwd=gone,
              prefix=["sh", "-c", 'rmdir "$0" && exec "$@"', str(gone)], outside_changes=True)
    probe.answered()


@case("environment", "the working folder deleted, a relative --out", "exit 2, one line")
def _(probe):
    gone = probe.tmp / "gone"
    gone.mkdir()
    scene = probe.scene()
    probe.out = gone / "out"
    probe.sub("forward", scene, "--out", "out", "--quiet", cwd=gone,
              prefix=["sh", "-c", 'rmdir "$0" && exec "$@"', str(gone)], outside_changes=True)
    probe.refused()


@case("environment", "stdout closed (>&-)", "exit 0 and the files, or exit 2 in one line")
def _(probe):
    probe.sub("forward", probe.scene(), "--out", probe.out, prefix=["sh", "-c", 'exec "$@" >&-', "sh"])
    if probe.status == 0:
        probe.answered()
        probe.matches_reference(GOOD)
    else:
        probe.check(probe.status == 2 and len(probe.lines) == 1, f"exit {probe.status}, {probe.lines}")


# slow: tests/cli/test_console.py's test_a_full_stdout_ends_with_one_line_and_status_2 keeps the property
@case("environment", "check with stdout on /dev/full", "exit 2, one line; its files written", slow=True)
def _(probe):
    data, stderr = noisy_data()
    with open("/dev/full", "wb") as full:
        probe.sub("check", probe.scene(), "--data", probe.npy("y.npy", data), "--stderr", probe.npy("se.npy", stderr),
                  "--out", probe.out, stdout=full)
    probe.check(probe.status == 2 and len(probe.lines) == 1 and probe.lines[0].startswith(ERROR),
                f"exit {probe.status}, {probe.lines}")
    probe.check((probe.out / "metrics.json").is_file(), "no metrics.json")


@case("environment", "a refusal with stderr closed", "exit 2, no hang")
def _(probe):
    probe.sub("forward", probe.file("scene.toml", "[plane]\nsize = -1\n"), "--out", probe.out,
              prefix=["sh", "-c", 'exec "$@" 2>&-', "sh"])
    probe.check(probe.status == 2, f"exit {probe.status}")
    probe.check(not probe.out.exists(), "--out created")


@contextlib.contextmanager
def _tmpfs(mount, options: str):
    """A tmpfs mounted at ``mount`` with ``options`` for the block, unmounted after (the case skipped where
    mounting is not allowed)."""
    mount.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(mount)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


@case("environment", "a full disk (a 64 kB tmpfs)", "exit 2, one line naming the disk; --out as it was")
def _(probe):
    with _tmpfs(probe.tmp / "small", "size=64k") as mount:
        (mount / "filler").write_bytes(b"\0" * 40_000)
        probe.out = mount / "out"
        probe.sub("forward", probe.scene(), "--out", probe.out, "--quiet", outside_changes=True)
        probe.refused("space")


@case("environment", "a read-only mount as --out, and as the working folder",
      "exit 2, one line naming read-only; nothing written; an absolute --out elsewhere works", slow=True)
def _(probe):
    with _tmpfs(probe.tmp / "ro", "size=1m,ro") as mount:
        probe.out = mount / "out"
        scene = probe.scene()
        probe.sub("forward", scene, "--out", probe.out, "--quiet").refused("read-only")
        # the same folder as the working folder: a relative --out is refused, an absolute one works
        probe.sub("forward", scene, "--out", "out", "--quiet", cwd=mount).refused("read-only")
        probe.out = probe.tmp / "elsewhere"
        probe.sub("forward", scene, "--out", probe.out, "--quiet", cwd=mount)
        if probe.answered():
            probe.matches_reference(GOOD)


@case("environment", "NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1", "exit 0; y equal to the reference", slow=True)
def _(probe):
    probe.sub("forward", probe.scene(), "--out", probe.out, "--quiet",
              env={"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
    if probe.answered():
        probe.matches_reference(GOOD)


test_case = case_test(CASES)
