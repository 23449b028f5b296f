"""The console itself: a command never ends in a traceback because of its own output, and library
warnings reach stderr as one line only when they may have changed a number."""

import io
import os
import subprocess
import sys
import warnings

import pytest

from analytic.operator.window import WindowWarning
from scene_files import GOOD, write_scene
from validation.cli.program import OWN_PACKAGES, _OneLineWarnings

# a window that holds the light and little else: no window warning on stderr
FITTED = GOOD.replace("start = 0.0\ncount = 40", "start = 1.9\ncount = 10")

FILES = {"transient.npy", "transient.exr", "transient.h5", "meta.json", "transient.png"}


def _forward(tmp_path, out, **options):
    """``diffuse-imaging forward`` in a new process; its summary line names ``out``."""
    scene = write_scene(tmp_path, FITTED)
    environment = {**os.environ, **options.pop("env", {})}
    return subprocess.run([sys.executable, "-m", "validation.cli", "forward", str(scene), "--out", str(out)],
                          env=environment, timeout=300, **options)


def test_characters_the_terminal_cannot_show_are_escaped(tmp_path):
    out = tmp_path / "χ-out"            # the summary line names it: not ASCII
    done = _forward(tmp_path, out, env={"PYTHONIOENCODING": "ascii"}, capture_output=True)
    assert done.returncode == 0, done.stderr
    assert b"Traceback" not in done.stderr and done.stderr == b""
    assert b"\\u03c7-out" in done.stdout                           # χ as an escape
    assert {path.name for path in out.iterdir()} == FILES


def test_a_full_stdout_ends_with_one_line_and_status_2(tmp_path):
    out = tmp_path / "out"
    with open("/dev/full", "w") as full:
        done = _forward(tmp_path, out, stdout=full, stderr=subprocess.PIPE)
    lines = done.stderr.decode().strip().splitlines()
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1 and lines[0].startswith("diffuse-imaging: error: cannot write to standard output")
    assert {path.name for path in out.iterdir()} == FILES            # the files were written before


def test_a_reader_that_stops_reading_costs_no_traceback(tmp_path):
    out = tmp_path / "out"
    scene = write_scene(tmp_path, FITTED)
    with subprocess.Popen([sys.executable, "-m", "validation.cli", "forward", str(scene), "--out", str(out)],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE) as process:
        process.stdout.close()          # as `| head -0` would: the summary line meets a closed pipe
        stderr = process.stderr.read()
        status = process.wait(timeout=300)
    assert status == 0, stderr                                      # the command did its work
    assert stderr == b""
    assert {path.name for path in out.iterdir()} == FILES


def _shown(category, message, filename="/somewhere/module.py"):
    stream = io.StringIO()
    show = _OneLineWarnings()
    show(category(message), category, filename, 12, file=stream)
    show(category(message), category, filename, 12, file=stream)    # the same line again: shown once
    return stream.getvalue().splitlines()


def test_our_warnings_are_one_line_each():
    assert WindowWarning.__module__.split(".")[0] in OWN_PACKAGES
    assert _shown(WindowWarning, "the window holds 31 %\nof the light") == [
        "diffuse-imaging: warning: the window holds 31 % of the light"]


def test_a_library_warning_that_may_change_a_number_is_one_line_saying_where():
    assert _shown(RuntimeWarning, "overflow encountered in exp", "/x/analytic/waveforms.py") == [
        "diffuse-imaging: warning: overflow encountered in exp (RuntimeWarning at waveforms.py:12)"]


@pytest.mark.parametrize("category, message", [
    (UserWarning, "Glyph 26085 (\\N{CJK UNIFIED IDEOGRAPH-65E5}) missing from font(s) DejaVu Sans."),
    (DeprecationWarning, "this will change"),
    (FutureWarning, "a default will change"),
])
def test_a_library_notice_that_changes_no_number_is_not_shown(category, message):
    assert _shown(category, message) == []


def test_main_installs_the_policy(tmp_path, capsys):
    from validation.cli import main

    with warnings.catch_warnings():
        assert main(["forward", str(write_scene(tmp_path, FITTED)), "--out", str(tmp_path / "out"),
                     "--quiet"]) == 0
        assert isinstance(warnings.showwarning, _OneLineWarnings)
    assert capsys.readouterr().err == ""


def test_held_warnings_are_printed_once_released_and_forgotten_when_dropped():
    stream = io.StringIO()
    show = _OneLineWarnings(hold=True)
    show(WindowWarning("first"), WindowWarning, "/x/analytic/window.py", 1, file=stream)
    assert stream.getvalue() == ""                                  # held while the inputs are checked
    show.drop()                                                     # refused: the error line alone
    show(WindowWarning("second"), WindowWarning, "/x/analytic/window.py", 1, file=stream)
    show.release()
    show(WindowWarning("third"), WindowWarning, "/x/analytic/window.py", 1, file=stream)
    assert stream.getvalue().splitlines() == ["diffuse-imaging: warning: second", "diffuse-imaging: warning: third"]
