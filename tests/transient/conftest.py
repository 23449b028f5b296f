"""Fixtures of the renderer's tests: Mitsuba's variant, a non-symmetric scene and its render."""

import numpy as np
import pytest

from analytic.scenes.common import Sampling, Scene
from render_checks import general_path_dict
from transient import backend
from transient.render import render

# transient_opl's own keys beyond render_checks.general_path_dict's: Mitsuba refuses keys a plugin never reads.
_PLANE_ONLY_KEYS = ("source_intensity", "attenuation")


@pytest.fixture(scope="module")
def mitsuba():
    backend.select_variant()
    import mitsuba

    return mitsuba


@pytest.fixture(scope="module")
def image():
    # Non-symmetric: a mirrored or transposed lookup changes the transient.
    rng = np.random.default_rng(20240611)
    values = rng.uniform(0.05, 0.95, (12, 12))
    values[:4, 8:] = 1.0          # bright top-right corner
    return values


@pytest.fixture(scope="module")
def scene(image):
    return Scene(size=1.0, pixels=12, reflectance=image, source=(0.3, 0.6, 0.8),
                 sensors=[(0.2, 0.7, 1.0), (0.8, 0.15, 0.5), (0.6, 0.9, 0.3)],
                 sampling=Sampling(bin_width_opl=0.05, start_opl=0.8, count=40))


@pytest.fixture(scope="module")
def rendered(scene):
    return render(scene, spp=2**22, seed=11, progress=False)


@pytest.fixture(scope="module")
def path_dict():
    """``general_path_dict`` for a ``scene_dict``: the same scene for transient_opl_path."""
    def convert(entries: dict, **changes) -> dict:
        integrator = {key: value for key, value in entries["integrator"].items() if key not in _PLANE_ONLY_KEYS}
        return general_path_dict(dict(entries, integrator=integrator), **changes)
    return convert
