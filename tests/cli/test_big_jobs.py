"""A long model says what it will cost before it starts (unless --quiet), and Ctrl-C ends it at once.

The scene, 2^16 confocal pairs over 16 x 16 pixels, is estimated at minutes on any machine this runs on;
SIGINT after its assembly has started must end it with exit status 130 long before that.
"""

import re
import select
import signal
import subprocess
import sys
import time

import pytest

_SCENE = """\
name = "big"
[relay_wall]
size = [2.0, 2.0]
[hidden]
pixels = 16
reflectance = 0.5
[scan]
type = "confocal"
grid = [256, 256]
[sampling]
period = 0.05
start = 1.9
count = 64
"""

#: Seconds a job may take to end after SIGINT: a few blocks of about a second each, and the exit.
_STOP_SECONDS = 15


@pytest.mark.parametrize("quiet", [False, True], ids=["announced", "quiet"])
def test_a_long_model_is_announced_and_ends_at_ctrl_c(tmp_path, quiet):
    scene = tmp_path / "big.toml"
    scene.write_text(_SCENE)
    child = subprocess.Popen([sys.executable, "-m", "validation.cli", "forward", str(scene), "--out",
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
        match = re.fullmatch(r"diffuse-imaging: forward: about ([\d.]+) (s|min|h) and ([\d.]+) GiB \(estimate\)\n",
                             announced)
        assert match, announced
        seconds = float(match[1]) * {"s": 1, "min": 60, "h": 3600}[match[2]]
        assert seconds > 3 * _STOP_SECONDS          # it would still be running: the signal ended it
        assert 0.1 < float(match[3]) < 2
