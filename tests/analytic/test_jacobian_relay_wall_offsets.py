"""A relay wall's exact derivatives by pixel offsets, against differences of the model and the general route.

Where the pairs are translates of a few by whole pixels (a rectangle parallel to the wall, a scan grid
commensurate with its pixels), the exact route integrates each distinct (pair, pixel) offset once over a
virtual rectangle (analytic/operator/relay_wall_offsets.py) and correlates the runs with the image. The
reference is Richardson differences of the model assembled at tolerance 1e-10 (held to their own error
bound, as tests/analytic/test_jacobian_relay_wall_exact.py holds the general route); the general route
(every pair over every pixel) must give the same columns to the scene's tolerance.
"""

import numpy as np
import pytest

import analytic.operator.relay_wall_offsets as offsets_route
import analytic.operator.relay_wall_sensitivity as relay
from analytic.operator import offsets
from analytic.operator.derivatives import exact_keys, jacobian
from analytic.operator.parameters import parameters
from relay_capture import capture as _capture

_STEP = 2e-5
_TOLERANCE = 1e-6
_KEYS = (["sampling.start", "laser.position.x", "laser.position.z", "sensor.position.y"]
         + [f"hidden.{stem}.{axis}" for stem in ("center", "rotation") for axis in "xyz"]
         + ["hidden.u.x", "hidden.u.z", "hidden.v.y", "hidden.v.z"])
# a 1.5 m square of 3 x 3 pixels 0.5 m wide parallel to the 2 m wall: a 4 x 4 confocal grid (pitch 0.5 m, one
# group) and a 2 x 2 exhaustive one (pitch 1 m: one group per laser-to-read offset)
_HIDDEN = "center = [0.1, -0.05, 0.8]\nu = [1.5, 0.0, 0.0]\nv = [0.0, -1.5, 0.0]"
_CASES = {"confocal": dict(scan='type = "confocal"\ngrid = [4, 4]', start=1.51),
          "exhaustive": dict(scan='type = "exhaustive"\ngrid = [2, 2]', start=1.7),
          "confocal, Gaussian pulse": dict(scan='type = "confocal"\ngrid = [4, 4]', start=1.51,
                                           light='waveform = "gaussian"\nfwhm = 0.08'),
          "exhaustive, square pulse": dict(scan='type = "exhaustive"\ngrid = [2, 2]', start=1.7,
                                           light='waveform = "square"\nwidth = 0.08')}


@pytest.fixture
def taken(monkeypatch):
    """The offset route forced wherever it applies, and a record of whether it was taken."""
    record = []

    def spy(*arguments, **options):
        parts = offsets_route.offset_parts(*arguments, **options)
        record.append(parts is not None)
        return parts

    monkeypatch.setattr(offsets, "MIN_SAVING", 1e9)
    monkeypatch.setattr(relay, "offset_parts", spy)
    return record


def _gap(exact, reference, bound):
    scale = np.abs(reference).max(axis=1)
    return np.abs(exact - reference).max(axis=1) / (bound + _TOLERANCE * scale)


def _slow_pulses(cases):
    return [pytest.param(case, marks=pytest.mark.slow) if "pulse" in case else case for case in cases]


@pytest.mark.slow
# (the square pulse's reference leaves quadrature pieces unrefined at 1e-10 here: held to the general route only)
@pytest.mark.parametrize("case", [case for case in _CASES if "square" not in case])
def test_the_offset_route_against_differences_of_the_model(tmp_path, taken, case):
    scene = _capture(tmp_path, hidden=_HIDDEN, **_CASES[case])
    assert all(exact_keys(scene, parameters(scene, _KEYS)))
    exact = jacobian(scene, _KEYS)
    assert taken == [True]
    reference, bound = jacobian(scene, _KEYS, route="differences", step=_STEP, errors=True)
    moving = [i for i, key in enumerate(_KEYS) if not key.startswith("sensor.")]      # the legs not counted
    assert np.all(np.abs(reference).max(axis=(0, 1))[moving] > 0.0)
    assert _gap(exact, reference, bound).max() < 1.0


@pytest.mark.parametrize("case", _slow_pulses(_CASES))
def test_the_offset_route_gives_the_general_routes_columns(tmp_path, taken, monkeypatch, case):
    scene = _capture(tmp_path, hidden=_HIDDEN, **_CASES[case])
    by_offsets = jacobian(scene, _KEYS)
    monkeypatch.setattr(relay, "offset_parts", lambda *arguments, **options: None)
    general = jacobian(scene, _KEYS)
    scale = np.abs(general).max(axis=1, keepdims=True)
    assert np.all(np.abs(by_offsets - general) <= _TOLERANCE * scale)


def test_moments_left_about_the_virtual_centre_fail(tmp_path, taken, monkeypatch):
    # each member's stretch moment is the virtual one moved to the real centre: without the move, the
    # edge vectors' columns are off
    scene = _capture(tmp_path, hidden=_HIDDEN, **_CASES["confocal"])
    keys = ["hidden.u.x", "hidden.v.y"]
    reference, bound = jacobian(scene, keys, route="differences", step=_STEP, errors=True)
    monkeypatch.setattr(offsets_route, "_about_the_centre", lambda moments, *arguments: moments)
    assert _gap(jacobian(scene, keys), reference, bound).min() > 1.0
