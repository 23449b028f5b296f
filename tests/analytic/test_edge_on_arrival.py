"""A bin edge on a pair's first arrival: the impulse response jumps there and y has no derivative in
anything that moves the edge or the arrival (the exact route returns a one-sided value), so the exact
route warns (EdgeOnArrivalWarning) instead of returning it silently; an edge off the arrival is silent.

The first arrival is computed here from the positions (the shortest path over the surface, by the
mirror image of one end), not taken from the code under test.
"""

import warnings

import numpy as np
import pytest

from analytic.operator.derivatives import jacobian
from analytic.operator.sensitivity import EdgeOnArrivalWarning
from analytic.scenes.common import Sampling, default_scene
from relay_capture import capture

_WIDTH = 0.05


def _plane(start):
    return default_scene(pixels=4, sensors=[[0.3, 0.6, 0.8]], source=[0.5, 0.5, 1.0], noise=None,
                         sampling=Sampling(bin_width_opl=_WIDTH, start_opl=start, count=12))


def _relay(tmp_path, start):
    # the relay-wall tests' capture (bins of 0.05 m): the rectangle 0.8 m from the wall, parallel to it
    return capture(tmp_path, 'type = "confocal"\ngrid = [3, 3]', start=float(start))


def _plane_arrival():
    # the source's mirror image below z = 0 to the sensor
    return float(np.linalg.norm(np.array([0.5, 0.5, -1.0]) - np.array([0.3, 0.6, 0.8])))


def _relay_arrival(scene):
    # confocal: l = s, the shortest path straight to the rectangle's plane (z = 0.8) and back, for a
    # point whose foot is on the rectangle ([-0.2, 0.4] x [-0.35, 0.25])
    lit, _ = scene.pair_points
    under = (lit[:, 0] > -0.2) & (lit[:, 0] < 0.4) & (lit[:, 1] > -0.35) & (lit[:, 1] < 0.25)
    assert under.any()
    return 2.0 * (0.8 - lit[under][0, 2])


def _silent(scene, keys):
    with warnings.catch_warnings():
        warnings.simplefilter("error", EdgeOnArrivalWarning)
        return jacobian(scene, keys)


def test_the_plane_warns_of_an_edge_on_the_first_arrival():
    start = _plane_arrival() - 3 * _WIDTH
    with pytest.warns(EdgeOnArrivalWarning, match="bin edge 3 of sensor 0 .* no derivative") as caught:
        columns = jacobian(_plane(start), ["sampling.start", "sensors.positions.0.z"])
    assert len(caught) == 1 and "\n" not in str(caught[0].message)
    assert np.all(np.isfinite(columns))
    _silent(_plane(start + 0.3 * _WIDTH), ["sampling.start", "sensors.positions.0.z"])


def test_the_relay_wall_warns_of_an_edge_on_the_first_arrival(tmp_path):
    scene = _relay(tmp_path, 0.0)
    start = _relay_arrival(scene) - 3 * _WIDTH
    with pytest.warns(EdgeOnArrivalWarning, match="bin edge 3 of pair .* no derivative") as caught:
        columns = jacobian(_relay(tmp_path, start), ["sampling.start", "hidden.center.z"])
    assert len(caught) == 1 and "\n" not in str(caught[0].message)
    assert np.all(np.isfinite(columns))
    _silent(_relay(tmp_path, start + 0.3 * _WIDTH), ["sampling.start", "hidden.center.z"])
