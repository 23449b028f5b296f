"""The scene dataclasses: the built-in scene, and limits refused before anything is allocated."""

import numpy as np
import pytest

from analytic.measurement.detector import Detector
from analytic.errors import ResourceError, SceneError
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import (MAX_SENSORS, MIN_TOLERANCE, Noise, Sampling, Scene, check_tolerance, default_scene,
                            sensor_grid)
from analytic.operator.window import response_range, window_share


def test_default_scene_is_the_papers_set_up_at_a_sensible_flux():
    scene = default_scene()
    assert scene.pixels == 50 and scene.sensor_count == 16 and scene.noise.sigma == 0.1
    assert np.allclose(scene.sensors[:, :2].mean(axis=0), scene.source[:2])
    image = scene.reflectance
    assert image.min() < 0.1 and image.max() > 0.85       # hard edges ...
    assert len(np.unique(np.round(image, 3))) > 50        # ... beside smooth regions
    # the window holds all the light, with at most half of its bins empty
    assert window_share(scene) == 1.0
    low, high = response_range(scene)
    edges = scene.sampling.edges
    lit = np.sum((edges[1:] > low) & (edges[:-1] < high))
    assert lit >= scene.sampling.count / 2


def test_sensor_grid_has_its_extent_centre_and_x_fastest_order():
    sensors = sensor_grid((3, 2), 2.0, (1.0, 2.0, 0.5))
    assert sensors.shape == (6, 3)
    assert np.allclose(sensors[:3, 0], [0.0, 1.0, 2.0]) and np.allclose(sensors[:3, 1], 1.0)
    assert np.allclose(sensors[3:, 1], 3.0) and np.all(sensors[:, 2] == 0.5)


def test_sizes_beyond_memory_are_refused_before_allocating():
    with pytest.raises(ResourceError, match="plane.pixels"):
        Scene(pixels=10**6)
    with pytest.raises(ResourceError, match="sampling.count"):
        Scene(sampling=Sampling(bin_width_opl=1.0, start_opl=0.0, count=10**11))
    with pytest.raises(SceneError, match="at most"):
        Scene(sensors=[(0.5, 0.5, 1.0)] * (MAX_SENSORS + 1))


def test_bins_float64_cannot_tell_apart_are_refused():
    with pytest.raises(SceneError, match="told apart"):
        Sampling(bin_width_opl=1e-9, start_opl=1e4, count=10)
    Sampling(bin_width_opl=1e-6, start_opl=1e3, count=10)     # 1e-9 relative: fine


def test_seeds_are_32_bit():
    with pytest.raises(SceneError, match="noise.seed"):
        Noise(seed=2**70)
    with pytest.raises(SceneError, match="noise.seed"):
        Noise(seed=-1)
    assert Noise(seed=2**32 - 1).seed == 2**32 - 1


def _refusal(make):
    with pytest.raises(SceneError) as caught:
        make()
    return str(caught.value)


@pytest.mark.parametrize("make, value", [
    (lambda: Sampling(bin_width_opl=1e11, start_opl=1e-4, count=10), 1e-4 + 1e12),     # "ends at 1e+12" hid why
    (lambda: Sampling(bin_width_opl=1e-9, start_opl=1000.0000000000001, count=1), 1000.0000000000001 + 1e-9),
    (lambda: check_tolerance(MIN_TOLERANCE * (1 - 2**-52)), MIN_TOLERANCE * (1 - 2**-52)),
    (lambda: Noise(sigma=1e150 * (1 + 2**-52)), 1e150 * (1 + 2**-52)),
    (lambda: Scene(intensity=1e30 * (1 + 2**-52)), 1e30 * (1 + 2**-52)),
    (lambda: Detector(photons=1.0, cycles=2.0**53 + 2), 2.0**53 + 2),
    (lambda: RelayWallScene(scan=Scan(laser_point=(1 + 2**-52, 0.0, 0.0))), 1 + 2**-52),
    (lambda: RelayWallScene(intensity=1e30 * (1 + 2**-52)), 1e30 * (1 + 2**-52)),
])
def test_a_value_just_past_its_bound_is_shown_with_every_digit(make, value):
    # the value as Python's repr writes it (the shortest text that reads back as the same float64; whole)
    assert repr(value).removesuffix(".0") in _refusal(make)


def test_pixel_size_is_du_dv_in_metres_for_every_kind():
    """One type for every scene kind: the image's pixel sides (du, dv) along its columns and rows, metres."""
    from analytic.scenes.relay_wall import default_relay_wall_scene

    assert default_scene(size=2.0, pixels=8).pixel_size == (0.25, 0.25)
    wall = default_relay_wall_scene(u=(1.5, 0.0, 0.0), v=(0.0, -0.5, 0.0), pixels=10)
    assert wall.pixel_size == pytest.approx((0.15, 0.05), rel=1e-15)
