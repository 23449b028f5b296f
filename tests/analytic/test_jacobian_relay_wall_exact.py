"""A relay wall's geometric keys on the exact route, against differences of the model.

In the hidden rectangle's frame a pair (l, s) is the plane's problem with the wall's cosines at both
ends (analytic/operator/relay_wall_sensitivity.py): ``sampling.start``, ``hidden.center.*``,
``hidden.rotation.*`` (the wall's normal turning in the frame too), ``scan.laser_point.*`` and, with the end legs counted, the laser's and sensor's positions. The
reference is Richardson differences of the model assembled at tolerance 1e-10 with a fine step (a
route that shares no code with the cell integrals' edge terms), held to its own error bound
(``errors=True``: the Richardson pair's disagreement and the second differences' change, which a
kink of y in the stencil raises) plus the exact route's tolerance. Dropping the bin-edge term (what
Monte Carlo differentiation does) must fail it.

``hidden.u.*`` and ``hidden.v.*`` (the edge vectors: the pixel grid stretched and turned) are held to
the same reference on every component the scene accepts; the others (which break u ⟂ v) are refused.
"""

import numpy as np
import pytest

import analytic.operator.relay_wall_sensitivity as relay
from analytic.operator.derivatives import exact_keys, jacobian
from analytic.errors import SceneError
from analytic.operator.parameters import parameters
from relay_capture import capture as _capture

_STEP = 2e-5
_TOLERANCE = 1e-6


_COUNTED = "\naccount_first_and_last_bounces = true"
_CASES = {
    "confocal, counted legs": (dict(scan='type = "confocal"\ngrid = [2, 2]' + _COUNTED, start=3.0),
                               ["sampling.start", "laser.position.x", "laser.position.z", "sensor.position.y",
                                "hidden.center.x", "hidden.center.z", "hidden.rotation.y"]),
    "exhaustive, tilted rectangle": (dict(scan='type = "exhaustive"\ngrid = [2, 1]',
                                          hidden="center = [0.1, -0.05, 0.8]\nu = [0.6, 0.0, 0.25]\n"
                                                 "v = [0.0, -0.6, 0.0]"),
                                     ["sampling.start", "hidden.center.x", "hidden.center.y", "hidden.center.z",
                                      "hidden.rotation.x", "hidden.rotation.y", "hidden.rotation.z"]),
    "single, counted legs": (dict(scan='type = "single"\nlaser_point = [0.2, 0.1, 0.0]\ngrid = [2, 2]' + _COUNTED,
                                  start=3.0),
                             ["scan.laser_point.x", "scan.laser_point.y", "laser.position.y", "sensor.position.x",
                              "hidden.center.y", "hidden.rotation.x"]),
    "rectangle near the wall": (dict(scan='type = "confocal"\ngrid = [2, 2]', start=0.0,
                                     hidden="center = [0.1, -0.05, 0.1]\nu = [0.6, 0.0, 0.0]\nv = [0.0, -0.6, 0.0]",
                                     points="[laser]\nposition = [-0.4, 0.2, 0.05]\n[sensor]\n"
                                            "position = [0.3, -0.1, 0.05]"),
                                ["sampling.start", "hidden.center.x", "hidden.center.z"]),
    "confocal, counted legs, Gaussian pulse": (dict(scan='type = "confocal"\ngrid = [2, 2]' + _COUNTED, start=3.0,
                                                    light='waveform = "gaussian"\nfwhm = 0.05'),
                                               ["sampling.start", "laser.position.x", "sensor.position.z",
                                                "hidden.center.z", "hidden.rotation.y"]),
    "single, tilted rectangle, square pulse": (dict(scan='type = "single"\nlaser_point = [0.2, 0.1, 0.0]\n'
                                                         'grid = [2, 2]',
                                                    hidden="center = [0.1, -0.05, 0.8]\nu = [0.6, 0.0, 0.25]\n"
                                                           "v = [0.0, -0.6, 0.0]",
                                                    light='waveform = "square"\nwidth = 0.08'),
                                               ["sampling.start", "scan.laser_point.x", "hidden.center.x",
                                                "hidden.rotation.z"]),
}


def _gap(exact, reference, bound):
    """Each (row, key) column's largest |exact - reference| over its bound: the reference's own error
    plus the exact route's tolerance of the column's largest entry."""
    scale = np.abs(reference).max(axis=1)
    return np.abs(exact - reference).max(axis=1) / (bound + _TOLERANCE * scale)


@pytest.mark.parametrize("case", [pytest.param(case, marks=pytest.mark.slow) if "Gaussian" in case else case
                                  for case in _CASES])
def test_the_geometric_keys_against_differences_of_the_model(tmp_path, case):
    changes, keys = _CASES[case]
    _hold_to_differences(_capture(tmp_path, **changes), keys)


def _hold_to_differences(scene, keys):
    assert all(exact_keys(scene, parameters(scene, keys)))
    exact = jacobian(scene, keys)
    reference, bound = jacobian(scene, keys, route="differences", step=_STEP, errors=True)
    assert np.all(np.abs(reference).max(axis=1) > 0.0)
    assert _gap(exact, reference, bound).max() < 1.0


def test_dropping_the_edge_term_fails(tmp_path, monkeypatch):
    changes, keys = _CASES["confocal, counted legs"]
    scene = _capture(tmp_path, **changes)
    keys = ["hidden.center.x", "hidden.center.z"]
    reference, bound = jacobian(scene, keys, route="differences", step=_STEP, errors=True)
    columns = relay.edge_columns

    def interior_only(sums, scale):
        sums = sums.copy()
        sums[:, 1, :, 7:] = 0.0           # H of a ∂d/∂p: the bin edges' term
        return columns(sums, scale)

    monkeypatch.setattr(relay, "edge_columns", interior_only)
    assert _gap(jacobian(scene, keys), reference, bound).min() > 1.0


def test_dropping_the_wall_normals_turn_fails(tmp_path, monkeypatch):
    # a rotation of the rectangle turns the wall's normal in its frame: the cosines' share is needed
    changes, _ = _CASES["exhaustive, tilted rectangle"]
    scene = _capture(tmp_path, **changes)
    keys = ["hidden.rotation.x", "hidden.rotation.y"]
    reference, bound = jacobian(scene, keys, route="differences", step=_STEP, errors=True)
    monkeypatch.setattr(relay, "_normal_turn", lambda *arguments: 0.0)
    assert _gap(jacobian(scene, keys), reference, bound).min() > 1.0


@pytest.mark.parametrize("light", ['waveform = "impulse"', 'waveform = "square"\nwidth = 0.08'])
def test_pairs_in_blocks_give_the_same_columns(tmp_path, monkeypatch, light):
    # big scans are integrated a block of pairs at a time: one pair per block must change nothing
    scene = _capture(tmp_path, scan='type = "exhaustive"\ngrid = [2, 1]' + _COUNTED, start=3.0, light=light)
    keys = ["sampling.start", "laser.position.x", "hidden.center.z"]
    whole = jacobian(scene, keys)
    monkeypatch.setattr(relay, "_BLOCK_DOUBLES", 1)
    assert np.array_equal(jacobian(scene, keys), whole)


_EDGE_CASES = {
    "confocal, counted legs": ["hidden.u.x", "hidden.u.z", "hidden.v.y", "hidden.v.z"],
    "exhaustive, tilted rectangle": ["hidden.u.x", "hidden.u.z", "hidden.v.y"],
}


@pytest.mark.parametrize("case", list(_EDGE_CASES))
def test_the_edge_vectors_against_differences_of_the_model(tmp_path, case):
    _hold_to_differences(_capture(tmp_path, **_CASES[case][0]), _EDGE_CASES[case])


def test_dropping_the_stretch_fails(tmp_path, monkeypatch):
    # the stretch's integrand is the points' derivatives weighted by the frame coordinate: dropping the
    # moments (the area element's change alone) must fail
    scene = _capture(tmp_path, **_CASES["exhaustive, tilted rectangle"][0])
    keys = ["hidden.u.x", "hidden.v.y"]
    reference, bound = jacobian(scene, keys, route="differences", step=_STEP, errors=True)
    columns = relay.relay_edge_columns
    monkeypatch.setattr(relay, "relay_edge_columns", lambda sums: (*columns(sums)[:5], 0.0 * columns(sums)[5]))
    assert _gap(jacobian(scene, keys), reference, bound).min() > 1.0


@pytest.mark.parametrize("key, other", [("hidden.u.y", "hidden.v.y"), ("hidden.v.z", "hidden.u.z")])
def test_an_edge_component_that_breaks_orthogonality_is_refused(tmp_path, key, other):
    # refused as a parameter of the scene, before any integral, on both routes, with the same line
    scene = _capture(tmp_path, **_CASES["exhaustive, tilted rectangle"][0])
    messages = []
    for refuse in (lambda: parameters(scene, [key]), lambda: jacobian(scene, [key]),
                   lambda: jacobian(scene, [key], route="differences")):
        with pytest.raises(SceneError) as refusal:
            refuse()
        messages.append(str(refusal.value))
    assert len(set(messages)) == 1
    assert "\n" not in messages[0] and messages[0].startswith(key) and other in messages[0]
