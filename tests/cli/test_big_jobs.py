"""A long model says what it will cost before it starts (unless --quiet), and Ctrl-C ends it at once.

The scene, 2^14 confocal pairs over 32 x 32 pixels with the laser's and the sensor's legs counted (each
pair's added path differs: no two pairs are translates, so the general route, analytic.operator.offsets),
is estimated at minutes on any machine this runs on; SIGINT after its assembly has started must end it
with exit status 130 long before that. With half a GiB of memory said to be available, its A (about 0.4
GiB) would not fit in the model's quarter of a GiB: y = A f is made a block of pairs at a time
(analytic.operator.matrix_free), said so in the estimate's line, and Ctrl-C ends it the same way.
"""

import re
import select
import signal
import subprocess
import sys
import time

import pytest

from scene_files import tilted_relay_wall

_SCENE = """\
name = "big"
[relay_wall]
size = [2.0, 2.0]
[hidden]
pixels = 32
reflectance = 0.5
[scan]
type = "confocal"
grid = [128, 128]
account_first_and_last_bounces = true
[sampling]
period = 0.05
start = 2.0
count = 140
"""

#: Seconds a job may take to end after SIGINT: a few blocks of about a second each, and the exit.
_STOP_SECONDS = 15


#: The command line with half a GiB of memory said to be available (half of it the model's limit).
_SMALL_MEMORY = ("import sys, analytic.resources as resources; resources.available_memory = lambda: 2**29; "
                 "from validation.cli.program import main; sys.exit(main(sys.argv[1:]))")
#: What the estimate's line says between "forward" and its figures, by route.
_ROUTE_TEXT = {"matrix": "", "blocks": r" \(A would not fit in memory: y = A f a block of pairs at a time\)"}


@pytest.mark.parametrize("quiet, route", [(False, "matrix"), (True, "matrix"), (False, "blocks")],
                         ids=["announced", "quiet", "without A"])
def test_a_long_model_is_announced_and_ends_at_ctrl_c(tmp_path, quiet, route):
    scene = tmp_path / "big.toml"
    scene.write_text(_SCENE)
    start = ["-c", _SMALL_MEMORY] if route == "blocks" else ["-m", "validation.cli"]
    child = subprocess.Popen([sys.executable, *start, "forward", str(scene), "--out",
                              str(tmp_path / "out"), *(["--quiet"] if quiet else [])],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             # Ctrl-C as a terminal delivers it: a pytest-xdist worker ignores SIGINT, and a
                             # child started with SIGINT ignored (as from `nohup` or `&`) rightly keeps ignoring it
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        if quiet:
            time.sleep(6)       # started, loaded and assembling (nothing to wait for on a quiet stderr)
            announced = ""
        else:
            ready, _, _ = select.select([child.stderr], [], [], 60)     # its first line, before any work
            announced = child.stderr.readline() if ready else "(nothing on stderr within a minute)"
            time.sleep(2)       # its assembly under way
        child.send_signal(signal.SIGINT)
        _, errors = child.communicate(timeout=_STOP_SECONDS)
    finally:
        child.kill()
        child.wait()
    assert child.returncode == 130, announced + errors
    assert errors.strip().splitlines() == ["diffuse-imaging: interrupted"]
    assert not (tmp_path / "out").exists()
    if not quiet:
        match = re.fullmatch(rf"diffuse-imaging: forward{_ROUTE_TEXT[route]}: about ([\d.]+) (s|min|h) and "
                             r"([\d.]+) GiB \(estimate\)\n", announced)
        assert match, announced
        seconds = float(match[1]) * {"s": 1, "min": 60, "h": 3600}[match[2]]
        assert seconds > 3 * _STOP_SECONDS          # it would still be running: the signal ended it
        # A, or y and one block of A's rows within a quarter of the model's limit
        assert 0.1 < float(match[3]) < 2 if route == "matrix" else 0.01 < float(match[3]) < 0.25


@pytest.mark.slow
def test_ctrl_c_of_a_tilted_square_ends_with_one_line_every_time(tmp_path):
    # a tilted square (the general route): Ctrl-C in the first second after the estimate's line, while its kernels
    # load and its window's ranges are found, crashed it now and then (exit -11, nothing said): the kernels'
    # loads now hold SIGINT (analytic.kernels.cache), and no Frame is boxed for Python (isochrone.table_ranges)
    scene = tmp_path / "tilted.toml"
    scene.write_text(tilted_relay_wall(16, 256))
    for delay in (0.1, 0.25, 0.4, 0.55, 0.7, 0.85, 1.0, 1.5):    # seconds after the estimate's line
        child = subprocess.Popen([sys.executable, "-m", "validation.cli", "forward", str(scene), "--out",
                                  str(tmp_path / "out")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        try:
            ready, _, _ = select.select([child.stderr], [], [], 60)
            announced = child.stderr.readline() if ready else "(nothing on stderr within a minute)"
            time.sleep(delay)
            child.send_signal(signal.SIGINT)
            _, errors = child.communicate(timeout=_STOP_SECONDS)
        finally:
            child.kill()
            child.wait()
        assert announced.startswith("diffuse-imaging: forward: about"), announced
        assert child.returncode == 130, f"{delay} s: {child.returncode}\n{errors[-3000:]}"
        assert errors.strip().splitlines() == ["diffuse-imaging: interrupted"], f"{delay} s"
        assert not (tmp_path / "out").exists()
