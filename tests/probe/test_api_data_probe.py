"""Issue 38's probe, the Python API and data from other tools: what a user's own tests call, and captures and
films given to ``check --data``, ``plot``, ``export`` and ``render --resume``.

A Python call gets what the command line gets: a subclass of ``analytic.errors.UserError`` (never a bare
ValueError, TypeError, AttributeError or IndexError) whose message carries no command-line wording; a path is
taken wherever a scene or data object is. Legal data (our own capture as tal's HDF5, as mitransient's film
array) is judged as agreeing with the model that made it.
"""

from __future__ import annotations

import numpy as np
import pytest
from probe.common import ERROR, assert_accepted, assert_refused, run, toml_text

import analytic
import validation
from analytic.errors import UserError

WALL = {"relay_wall": {"size": [2.0, 2.0]}, "hidden": {"pixels": 4}, "scan": {"type": "confocal", "grid": [2, 2]},
        "sampling": {"period": 0.1, "start": 1.9, "count": 18}}
PAIRS, BINS = 4, 18


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """A relay-wall scene file and its forward output folder (our capture)."""
    folder = tmp_path_factory.mktemp("wall")
    (folder / "wall.toml").write_text(toml_text(WALL))
    from validation.cli import main

    assert main(["forward", str(folder / "wall.toml"), "--out", str(folder / "out"), "--quiet"]) == 0
    return folder / "wall.toml", folder / "out"


def _raises_user_error(call) -> str:
    with pytest.raises(Exception) as raised:
        call()
    assert isinstance(raised.value, UserError), f"{type(raised.value).__name__}: {raised.value}"
    message = str(raised.value)
    assert "--" not in message and "\n" not in message, message
    return message


# ======================================================================== the Python API refuses like the CLI

def _model(capture):
    return np.load(capture[1] / "transient.npy")


BAD_CALLS = {
    "data of the wrong shape": lambda s, m: validation.check_transient(s, m[:, :-1], stderr=np.ones_like(m[:, :-1])),
    "data of one dimension": lambda s, m: validation.check_transient(s, m.ravel(), stderr=np.ones(m.size)),
    "data with a NaN": lambda s, m: validation.check_transient(s, np.where(m == m.max(), np.nan, m),
                                                              stderr=np.ones_like(m)),
    "complex data": lambda s, m: validation.check_transient(s, m + 1j, stderr=np.ones_like(m)),
    "data of strings": lambda s, m: validation.check_transient(s, m.astype(str), stderr=np.ones_like(m)),
    "negative stderr": lambda s, m: validation.check_transient(s, m, stderr=-np.ones_like(m)),
    "stderr of another shape": lambda s, m: validation.check_transient(s, m, stderr=np.ones((3, 3))),
    "false alarm zero": lambda s, m: validation.check_transient(s, m, stderr=np.ones_like(m), false_alarm=0),
    "false alarm one": lambda s, m: validation.check_transient(s, m, stderr=np.ones_like(m), false_alarm=1.0),
    "false alarm two": lambda s, m: validation.check_transient(s, m, stderr=np.ones_like(m), false_alarm=2),
    "false alarm nan": lambda s, m: validation.check_transient(s, m, stderr=np.ones_like(m), false_alarm=np.nan),
    "false alarm a string": lambda s, m: validation.check_transient(s, m, stderr=np.ones_like(m),
                                                                    false_alarm="0.01"),
    "expect a typo": lambda s, m: validation.check_transient(s, m, stderr=np.ones_like(m), expect="irradiance"),
    "a missing data path": lambda s, m: validation.check_transient(s, "no/such/file.npy"),
    "a missing scene path": lambda s, m: validation.check_transient("no/such/scene.toml", m, stderr=np.ones_like(m)),
    "a scene of another type": lambda s, m: validation.check_transient(42, m, stderr=np.ones_like(m)),
    "assert_agrees: wrong shape": lambda s, m: validation.assert_agrees(s, m[:-1], stderr=np.ones_like(m[:-1])),
    "assert_agrees: false alarm zero": lambda s, m: validation.assert_agrees(s, m, stderr=np.ones_like(m),
                                                                             false_alarm=0),
    "assert_agrees: a missing data path": lambda s, m: validation.assert_agrees(s, "missing.npy"),
    "assert_agrees: all-zero stderr": lambda s, m: validation.assert_agrees(s, m, stderr=np.zeros_like(m)),
    "load_scene: a missing path": lambda s, m: analytic.load_scene("no/such/scene.toml"),
    "load_scene: a folder": lambda s, m: analytic.load_scene(s.parent),
    "load_scene: a number": lambda s, m: analytic.load_scene(3),
    "load_scene: an empty path": lambda s, m: analytic.load_scene(""),
    "system_matrix: tolerance zero": lambda s, m: analytic.system_matrix(analytic.load_scene(s), tolerance=0.0),
    "system_matrix: tolerance negative": lambda s, m: analytic.system_matrix(analytic.load_scene(s), tolerance=-1e-6),
    "system_matrix: tolerance a string": lambda s, m: analytic.system_matrix(analytic.load_scene(s), tolerance="x"),
    "system_matrix: one byte of memory": lambda s, m: analytic.system_matrix(analytic.load_scene(s), memory_limit=1),
    "forward: a matrix of another shape": lambda s, m: analytic.forward(analytic.load_scene(s), np.eye(3)),
}


@pytest.mark.parametrize("call", BAD_CALLS.values(), ids=BAD_CALLS.keys())
def test_a_bad_python_call_raises_a_user_error_in_the_libraries_words(capture, call):
    _raises_user_error(lambda: call(capture[0], _model(capture)))


@pytest.mark.parametrize("as_path", [False, True], ids=["objects", "paths"])
def test_consistent_data_agree_given_by_object_or_by_path(tmp_path, capture, as_path):
    scene_path, out = capture
    model = _model(capture)
    stderr = np.full_like(model, 1e-3 * model.max())
    # data drawn about the model at that spread (seeded): consistent, so agreeing at α = 0.001
    noisy = model + stderr * np.random.default_rng(38).standard_normal(model.shape)
    np.save(tmp_path / "data.npy", noisy)
    scene = str(scene_path) if as_path else analytic.load_scene(scene_path)
    data = str(tmp_path / "data.npy") if as_path else noisy
    result = validation.check_transient(scene, data, stderr=stderr)
    assert result.agrees and np.isfinite(result.chi2_per_dof)
    validation.assert_agrees(scene, data, stderr=stderr)
    # a 1 % scale error at this spread is flagged, not passed
    with pytest.raises(AssertionError):
        validation.assert_agrees(scene, 1.01 * noisy, stderr=stderr)


def test_forward_takes_a_scene_path_or_says_why_not(capture):
    try:
        by_path = analytic.forward(str(capture[0]))
    except UserError:
        return
    np.testing.assert_array_equal(by_path, _model(capture))


# ======================================================================== data from other tools

def _film(model, shape):
    """Our capture as mitransient's developed film (H, W, T, C): rows along y, columns along x."""
    return model.reshape(shape[0], shape[1], BINS, 1) * np.ones(shape[-1])


FILMS_REFUSED = {
    "film of three rows": lambda m: np.ones((3, 2, BINS, 1)),
    "film of two channels": lambda m: _film(m, (2, 2, 2)),
    "film of other bins": lambda m: np.ones((2, 2, BINS + 1, 1)),
    "film with a NaN": lambda m: np.where(_film(m, (2, 2, 1)) == m.max(), np.nan, _film(m, (2, 2, 1))),
    "complex film": lambda m: _film(m, (2, 2, 1)) + 0j,
    "film of one dimension": lambda m: m.ravel(),
    "empty array": lambda m: np.zeros((0, BINS)),
}


@pytest.mark.parametrize("make", FILMS_REFUSED.values(), ids=FILMS_REFUSED.keys())
def test_check_refuses_a_bad_film_in_one_line(tmp_path, capsys, capture, make):
    np.save(tmp_path / "film.npy", make(_model(capture)))
    out = tmp_path / "out"
    assert_refused(capsys, ["check", capture[0], "--data", tmp_path / "film.npy", "--out", out], out)


@pytest.mark.parametrize("form", ["film, mono", "film, three equal channels", "tal HDF5", "our folder"])
def test_check_judges_a_legal_capture_of_the_same_scene_as_agreeing(tmp_path, capsys, capture, form):
    model = _model(capture)
    if form == "tal HDF5":
        data = capture[1] / "transient.h5"
    elif form == "our folder":
        data = capture[1]
    else:
        data = tmp_path / "film.npy"
        np.save(data, _film(model, (2, 2, 1 if form == "film, mono" else 3)))
    assert_accepted(capsys, ["check", capture[0], "--data", data, "--shape-only", "--out", tmp_path / "out",
                             "--quiet"])
    import json

    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["agrees"] is True


# ======================================================================== plot, export, resume

@pytest.mark.parametrize("target", ["folder", "transient.npy", "transient.h5"])
def test_plot_draws_our_capture(tmp_path, capsys, capture, target):
    path = capture[1] if target == "folder" else capture[1] / target
    assert_accepted(capsys, ["plot", path, "--out", tmp_path / "out", "--quiet"])
    assert (tmp_path / "out" / "transient.png").stat().st_size > 0


PLOT_REFUSED = {
    "a missing file": "missing.npy",
    "a text file": "notes.txt",
    "an empty npy": "empty.npy",
}


@pytest.mark.parametrize("name", PLOT_REFUSED.values(), ids=PLOT_REFUSED.keys())
def test_plot_refuses_what_it_cannot_read_in_one_line(tmp_path, capsys, name):
    (tmp_path / "notes.txt").write_text("not a transient\n")
    np.save(tmp_path / "empty.npy", np.zeros((0, 0)))
    out = tmp_path / "out"
    assert_refused(capsys, ["plot", tmp_path / name, "--out", out], out)


@pytest.mark.parametrize("form", ["mitsuba", "mitransient"])
def test_export_writes_the_relay_wall_scene(tmp_path, capsys, capture, form):
    assert_accepted(capsys, ["export", capture[0], "--format", form, "--out", tmp_path / "out"])
    written = list((tmp_path / "out").glob("*.xml"))
    assert written and all("<scene" in path.read_text() for path in written)


EXPORT_REFUSED = {
    "unknown format": ["--format", "blender"],
    "no format": [],
}


@pytest.mark.parametrize("flags", EXPORT_REFUSED.values(), ids=EXPORT_REFUSED.keys())
def test_export_refuses_a_bad_flag_in_one_line(tmp_path, capsys, capture, flags):
    out = tmp_path / "out"
    status, lines = run(capsys, ["export", capture[0], *flags, "--out", out])
    assert status == 2 and len(lines) == 1 and "diffuse-imaging export: error:" in lines[0], lines
    assert not out.exists()


RESUME_REFUSED = {
    "a folder that is no render": "empty",
    "a missing folder": "missing",
    "a forward's folder": "forward",
}


@pytest.mark.parametrize("kind", RESUME_REFUSED.values(), ids=RESUME_REFUSED.keys())
def test_resume_refuses_what_is_no_interrupted_render_in_one_line(tmp_path, capsys, capture, kind):
    folder = {"empty": tmp_path / "empty", "missing": tmp_path / "missing", "forward": capture[1]}[kind]
    (tmp_path / "empty").mkdir()
    before = sorted(p.name for p in folder.iterdir()) if folder.exists() else None
    status, lines = run(capsys, ["render", "--resume", folder])
    assert status == 2 and len(lines) == 1 and lines[0].startswith(ERROR), lines
    assert (sorted(p.name for p in folder.iterdir()) if folder.exists() else None) == before
