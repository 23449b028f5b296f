"""A relay wall's laser and sensor positions on the exact route, against differences of the model.

Unless the end legs are counted, the laser's position enters y only through each pair's laser-leg
factor and the sensor's not at all (analytic/operator/relay_wall_legs.py). y is then smooth in both, so
Richardson differences of the model assembled at tolerance 1e-10 (a route that shares nothing with the
factor's derivative) are good to ~1e-7 of a column's largest entry; the bound asserted is 1e-6.
"""

import numpy as np
import pytest

from analytic.operator.derivatives import exact_keys, jacobian
from analytic.operator.parameters import parameters
from relay_capture import capture

_KEYS = ["laser.position.x", "laser.position.y", "laser.position.z", "sensor.position.x", "sensor.position.z"]


@pytest.mark.parametrize("scan", ['type = "confocal"\ngrid = [2, 2]',
                                  pytest.param('type = "exhaustive"\ngrid = [2, 2]', marks=pytest.mark.slow),
                                  pytest.param('type = "single"\nlaser_point = [0.2, 0.1, 0.0]\ngrid = [3, 3]',
                                               marks=pytest.mark.slow)])
def test_the_laser_and_sensor_positions_against_differences_of_the_model(tmp_path, scan):
    scene = capture(tmp_path, scan, pixels=4)
    assert all(exact_keys(scene, parameters(scene, _KEYS)))
    exact = jacobian(scene, _KEYS)
    reference = jacobian(scene, _KEYS, route="differences", step=1e-4)
    scale = np.abs(reference).max(axis=1)
    assert np.all(scale[:, :3] > 0.0) and np.all(reference[..., 3:] == 0.0)
    assert np.all(exact[..., 3:] == 0.0)
    gap = np.abs(exact - reference).max(axis=1)[:, :3] / scale[:, :3]
    assert gap.max() < 1e-6, gap.max()

