"""Our relay-wall renderer against the exact third-bounce model (each sample serves every pair)."""

import numpy as np
import pytest
from render_checks import agreement

from analytic.relay_wall import RelayWallScene, Scan, default_relay_wall_scene
from analytic.scene import Illumination, Sampling
from analytic.system import system_matrix
from analytic.window import pairs_range


def _covering(scene, period=0.02):
    low, high = pairs_range(*scene.geometry())
    return scene.replace(sampling=Sampling(bin_width_opl=period, start_opl=low - period,
                                           count=int((high - low) / period) + 3))


def _render(scene, spp, seed):
    from transient.backend import select_variant

    select_variant()
    import mitsuba as mi

    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import relay_wall_scene_dict

    loaded = mi.load_dict(relay_wall_scene_dict(scene))
    layout = ReplicaLayout.for_samples(spp)
    sums = loaded.integrator().render_chunk_per_unit_intensity(loaded, seed=seed, layout=layout, first=0,
                                                               count=layout.samples)
    return sums / layout.size * scene.intensity


CASES = {
    "confocal": default_relay_wall_scene(pixels=8, scan=Scan(type="confocal", grid=(3, 3))),
    "single, tilted, Butterworth": RelayWallScene(
        pixels=6, reflectance=np.linspace(0, 1, 36).reshape(6, 6), center=(0.2, 0.1, 1.1),
        u=(0.7, 0.0, 0.3), v=(0.0, -0.8, 0.0), scan=Scan(type="single", grid=(3, 2), laser_point=(0.3, -0.2, 0.0)),
        illumination=Illumination(waveform="butterworth", order=2, cutoff=8.0), intensity=5.0),
    "exhaustive, legs counted, near the wall": RelayWallScene(
        pixels=4, center=(0.1, 0.0, 0.15), u=(0.3, 0.0, 0.0), v=(0.0, -0.3, 0.0),
        scan=Scan(type="exhaustive", grid=(2, 2), laser_grid=(2, 1), account_first_and_last_bounces=True)),
}


@pytest.mark.parametrize("name", list(CASES))
def test_render_agrees_with_the_model(name):
    scene = _covering(CASES[name])
    model = (system_matrix(scene) @ scene.reflectance.ravel()).reshape(scene.sensor_count, -1)
    replicas = _render(scene, 2**18, seed=3)
    chi2, max_z, bins, passes = agreement(replicas.mean(axis=0), replicas.std(axis=0, ddof=1) / np.sqrt(len(replicas)),
                                          model, dof=len(replicas) - 1, replicas=replicas)
    assert passes and bins > 50, (chi2, max_z, bins)


def test_a_wrong_model_fails():
    """A model without the wall's cosine at s must be told apart (the check has power)."""
    scene = _covering(CASES["confocal"])
    replicas = _render(scene, 2**18, seed=4)
    rectangle, pairs = scene.geometry()
    from analytic.geometry import PointPairs
    from analytic.system import rectangle_matrix
    from analytic.waveforms import make_waveform

    wrong_pairs = PointPairs(pairs.sources, pairs.sensors, source_normals=pairs.source_normals,
                             scales=pairs.scales)
    wrong = (rectangle_matrix(rectangle, wrong_pairs, scene.sampling, make_waveform(scene.illumination, 0.02))
             @ scene.reflectance.ravel()).reshape(scene.sensor_count, -1)
    *_, passes = agreement(replicas.mean(axis=0), replicas.std(axis=0, ddof=1) / np.sqrt(len(replicas)), wrong,
                           dof=len(replicas) - 1, replicas=replicas)
    assert not passes
