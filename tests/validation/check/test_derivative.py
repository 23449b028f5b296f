"""check --derivative: data claiming to be ∂y/∂θ judged against the exact column (docs/design.md section 9).

A noisy exact derivative passes; one 3 % off fails, with noise chosen from the column itself so that the
directed scale test of section 6 sees 3 % at many standard errors (its power is then near 1).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from analytic.errors import OptionError
from analytic.operator.derivatives import jacobian
from analytic.scenes.scene_file import scene_from_dict
from validation.check import check_derivative
from validation.cli import main

KEY = "sensors.positions.0.z"
REPLICAS = 16
FALSE_ALARM = 1e-3
#: How many standard errors of the fitted scale a 3 % error is made to be (power ~ 1 at α/4, z ~ 3.5).
SEPARATION = 12.0


def small_scene():
    return scene_from_dict({
        "plane": {"size": 1.0, "pixels": 1, "reflectance": 0.5},
        "illumination": {"waveform": "square", "width": 0.05},
        "sensors": {"positions": [[0.2, 0.7, 1.0], [0.8, 0.3, 0.9]]},
        "sampling": {"period": 0.05, "start": 1.85, "count": 24}})


def replicas_of(column, seed, scale=1.0):
    """``REPLICAS`` noisy copies of scale x column, with σ per replica such that the mean's error on a global
    scale (σ_mean / sqrt(Σ column²)) is 0.03 / SEPARATION; and that σ."""
    sigma_of_scale = 0.03 / SEPARATION
    sigma = sigma_of_scale * np.sqrt(np.sum(column**2)) * np.sqrt(REPLICAS)
    rng = np.random.default_rng(seed)
    return scale * column + sigma * rng.standard_normal((REPLICAS, *column.shape)), sigma


@pytest.fixture(scope="module")
def exact():
    scene = small_scene()
    return scene, jacobian(scene, [KEY])[..., 0]


def test_a_noisy_exact_derivative_agrees(exact):
    scene, column = exact
    data, _ = replicas_of(column, seed=5)
    result = check_derivative(scene, data, KEY, false_alarm=FALSE_ALARM)
    assert result.agrees and result.verdict, result.summary()
    assert np.array_equal(result.model, column)
    # its fitted scale is 1 within the error the noise was made to give it
    assert abs(result.fit.scale - 1.0) < 4.5 * 0.03 / SEPARATION


def test_a_derivative_three_percent_off_is_flagged(exact):
    scene, column = exact
    data, _ = replicas_of(column, seed=6, scale=1.03)
    result = check_derivative(scene, data, KEY, false_alarm=FALSE_ALARM)
    assert not result.agrees, result.summary()
    # the stated power: a 3 % scale error is well beyond what these data flag half the time
    assert result.detectable["scale"] < 0.03 / 2
    # the threshold the directed scale test uses (α/4 two-sided) is far below the 3 % made to be 12 errors
    assert stats.norm.isf(FALSE_ALARM / 8) < SEPARATION / 2
    assert result.fit.scale == pytest.approx(1.03, abs=4.5 * 0.03 / SEPARATION)


def test_a_bad_key_is_refused_before_the_data_are_read(exact):
    scene, _ = exact
    with pytest.raises(OptionError, match="is no parameter"):
        check_derivative(scene, "no-such-file.npy", "sensors.positions.0.w")


def test_the_command_judges_the_derivative_and_refuses_a_bad_key(exact, tmp_path, capsys):
    from tests.scene_files import write_scene_file

    scene, column = exact
    path = write_scene_file(tmp_path, scene)
    files = []
    data, _ = replicas_of(column, seed=7)
    for r, replica in enumerate(data):
        files.append(str(tmp_path / f"derivative_{r}.npy"))
        np.save(files[-1], replica)
    out = tmp_path / "out"
    status = main(["check", str(path), "--data", *files, "--derivative", KEY, "--out", str(out)])
    printed = capsys.readouterr().out
    assert status == 0 and f"judged as dy/d{KEY}" in printed, printed
    bad = main(["check", str(path), "--data", *files, "--derivative", "sensors.positions.5.z", "--out",
                str(tmp_path / "bad")])
    lines = capsys.readouterr().err.strip().splitlines()
    assert bad == 2 and len(lines) == 1 and lines[0].startswith("diffuse-imaging: error: --derivative:"), lines
    assert not (tmp_path / "bad").exists()
