"""validation.check.inputs: a Python call takes what ``check`` takes (scene and data by path or in memory,
mitransient's films in every shape they come in, lists of replicas) and gets the same verdict; what ``check``
refuses it refuses with the library's own exceptions, in Python's words."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from analytic.errors import DataError, OptionError, SceneError, UserError
from analytic.scenes.scene_file import load_scene
from check_cases import noisy_replicas, render_folder, run_check
import validation
from validation.check import check_transient

pytestmark = pytest.mark.filterwarnings("ignore::validation.judging.compare.CorrelationWarning")


@pytest.fixture
def replicas(model, rng):
    return noisy_replicas(model, rng, replicas=16)


def _same(result, reference):
    """The same verdicts, statistics and fit: the same arrays judged the same way (to the rounding of a mean
    of three equal colour channels, and of the scene file's float32 image, which the fit's models see)."""
    assert (result.verdict, result.agrees, result.judged_by, result.replicas) == (
        reference.verdict, reference.agrees, reference.judged_by, reference.replicas)
    close = {"rel": 1e-6, "abs": 1e-9}
    assert result.chi2_per_dof == pytest.approx(reference.chi2_per_dof, **close)
    assert result.max_abs_z == pytest.approx(reference.max_abs_z, **close)
    fit, expected = result.fit.as_dict(), reference.fit.as_dict()
    assert fit.keys() == expected.keys()
    for key, value in expected.items():       # pytest >= 9.2's approx takes numbers only
        if isinstance(value, float):
            assert fit[key] == pytest.approx(value, **close), key
        else:
            assert fit[key] == value, key
    assert result.detectable == pytest.approx(reference.detectable, **close)


def test_mitransient_films_in_every_shape_are_the_replicas_they_hold(scene, model, replicas):
    """np.array(film) of each sensor (1, 1, N, C), stacked (K, 1, 1, N, C), replicas of them, RGB: one verdict."""
    reference = check_transient(scene, replicas, model=model)
    films = replicas[:, :, None, None, :, None]                       # (R, K, 1, 1, N, 1)
    _same(check_transient(scene, films, model=model), reference)
    _same(check_transient(scene, list(films), model=model), reference)
    _same(check_transient(scene, [list(replica) for replica in films], model=model), reference)
    _same(check_transient(scene, np.repeat(films, 3, axis=-1), model=model), reference)      # three equal channels
    sigma = 0.01 * model + 1e-4 * model.max()
    _same(check_transient(scene, list(films[0]), stderr=sigma, model=model),
          check_transient(scene, replicas[0], stderr=sigma, model=model))


def test_paths_are_taken_wherever_a_scene_or_data_are(tmp_path, scene_file, model, replicas):
    scene = load_scene(scene_file)
    reference = check_transient(scene, replicas)
    files = []
    for r, replica in enumerate(replicas):
        files.append(tmp_path / f"replica_{r:02d}.npy")
        np.save(files[-1], replica[:, None, None, :, None])           # mitransient's films, one file per render
    _same(check_transient(str(scene_file), files), reference)
    _same(check_transient(scene_file, [str(f) for f in files]), reference)
    sigma = 0.01 * model + 1e-4 * model.max()
    np.save(tmp_path / "one.npy", replicas[0])
    np.save(tmp_path / "se.npy", sigma)
    _same(check_transient(scene_file, tmp_path / "one.npy", stderr=tmp_path / "se.npy"),
          check_transient(scene, replicas[0], stderr=sigma))
    folder = render_folder(tmp_path / "render", scene, replicas)     # our render: its replicas come with it
    _same(check_transient(scene_file, folder), reference)
    assert np.array_equal(validation.read_data(folder, str(scene_file)), replicas.mean(axis=0))


def test_a_python_call_gets_the_verdict_of_the_command(tmp_path, scene, scene_file, model, rng):
    """The same files, check and check_transient: one function under both (metrics.json's numbers)."""
    replicas = noisy_replicas(1.003 * model, rng, replicas=16)
    files = []
    for r, replica in enumerate(replicas):
        files.append(tmp_path / f"r{r:02d}.npy")
        np.save(files[-1], replica)
    status = run_check(scene_file, "--data", *files, "--out", tmp_path / "out")
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    result = check_transient(scene_file, files)
    assert status == (0 if result.verdict else 1)
    assert metrics["chi2_per_dof"] == result.chi2_per_dof and metrics["detectable"] == result.detectable
    assert metrics["fit"]["scale"] == result.fit.scale


@pytest.mark.parametrize("call, error, words", [
    (lambda s, m, r: check_transient(s, r[0]), DataError, "stderr=<array or file>"),
    (lambda s, m, r: check_transient(s, r.astype(complex)), DataError, "complex numbers"),
    (lambda s, m, r: check_transient(s, r[:, :, :-1]), DataError, "does not match the scene's 2 sensors x 24"),
    (lambda s, m, r: check_transient(s, r[:2]), DataError, "two replicas"),
    (lambda s, m, r: check_transient(s, r, stderr=m), DataError, "give neither stderr nor shape_only=True"),
    (lambda s, m, r: check_transient(s, r, false_alarm=0), OptionError, "false_alarm: must be in"),
    (lambda s, m, r: check_transient(s, r, false_alarm=2), OptionError, "false_alarm: must be in"),
    (lambda s, m, r: check_transient(s, r, expect="irradiance"), OptionError, "is no convention"),
    (lambda s, m, r: check_transient(s, r, expect="transient_nlos_path"), OptionError, "relay-wall scene"),
    (lambda s, m, r: check_transient(s, r, expect="irradiancemeter", radius=5.0), OptionError, "radius: must"),
    (lambda s, m, r: check_transient(s, r, radius=0.001), OptionError, "applies to expect irradiancemeter only"),
    (lambda s, m, r: check_transient(s, r[0], stderr=m, dof=0), OptionError, "dof:"),
    (lambda s, m, r: check_transient(3, r), OptionError, "scene: expected a Scene"),
    (lambda s, m, r: check_transient("missing.toml", r), SceneError, "missing.toml"),
    (lambda s, m, r: check_transient(s, "missing.npy"), DataError, "missing.npy: no such file"),
    (lambda s, m, r: check_transient(s, []), DataError, "empty list"),
    (lambda s, m, r: check_transient(s, r[0, :, None, None, :, None][0]), DataError, "one sensor's film"),
    (lambda s, m, r: check_transient(s, r, shape_tolerance=-1), OptionError, "shape_tolerance"),
    (lambda s, m, r: validation.assert_agrees(s, r, expect=3), OptionError, "is no convention"),
    (lambda s, m, r: validation.read_data(m, s), DataError, "expected a file or folder's path"),
    (lambda s, m, r: validation.Convention(scale=-1, offset_opl=0, name="x"), OptionError, "scale"),
])
def test_what_check_refuses_a_python_call_refuses_in_its_own_words(scene, model, replicas, call, error, words):
    with pytest.raises(error, match=re.escape(words)) as raised:
        call(scene, model, replicas)
    assert isinstance(raised.value, UserError) and "\n" not in str(raised.value)
    assert "--" not in str(raised.value), str(raised.value)          # no command-line wording


def test_the_command_keeps_its_own_words(tmp_path, scene_file, model, capsys):
    np.save(tmp_path / "one.npy", model)
    assert run_check(scene_file, "--data", tmp_path / "one.npy", "--out", tmp_path / "out") == 2
    assert "--stderr FILE" in capsys.readouterr().err
