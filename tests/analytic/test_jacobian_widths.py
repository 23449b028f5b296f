"""The exact route's pulse widths (``illumination.fwhm``, ``.tail``, ``.width``, ``.cutoff``) of a plane scene.

Reference: Richardson central differences of the model at tolerance 1e-10 (``route="differences"``, the
model's own quadrature, sharing nothing with the route's cell integrals: it never evaluates s or s'),
with the differences' own error bound (``errors=True``, docs/derivatives.md "Error estimates"): every
entry of the exact column within that bound plus the scene's tolerance times the column's largest entry.
The hard cases: an isochrone born inside a bin, a pulse wider than the window, a sensor near the plane.
"""

import warnings

import numpy as np
import pytest

from analytic.operator.derivatives import exact_keys, jacobian
from analytic.operator.parameters import parameters
from analytic.operator.system import QuadratureWarning
from analytic.scenes.common import Illumination, Sampling, default_scene

# each waveform's widths, a pulse narrower than a bin and one wider than the window of the scenes below
_NARROW = {"gaussian": dict(fwhm=0.06), "sech2": dict(fwhm=0.05), "square": dict(width=0.05),
           "emg": dict(fwhm=0.04, tail=0.05), "butterworth": dict(cutoff=8.0)}
_WIDE = {"gaussian": dict(fwhm=2.0), "sech2": dict(fwhm=1.5), "square": dict(width=0.7),
         "emg": dict(fwhm=0.8, tail=1.0), "butterworth": dict(cutoff=0.5)}
# the differences' first step, a fraction of the width (the square's y has a kink where the pulse's end
# crosses a bin edge: a small step keeps fewer of them in a stencil)
_STEP = 1e-4


def _image(pixels, seed=1):
    return np.random.default_rng(seed).uniform(0.2, 1.0, (pixels, pixels))


def _against_differences(scene, widths):
    keys = [f"illumination.{name}" for name in widths]
    assert all(exact_keys(scene, parameters(scene, keys)))
    exact = jacobian(scene, keys)
    with warnings.catch_warnings():
        # the model at 1e-10 may stop a few pieces short of it: the bound's model term leaves room
        warnings.simplefilter("ignore", QuadratureWarning)
        reference, bound = jacobian(scene, keys, route="differences", step=_STEP, errors=True)
    scale = np.abs(exact).max(axis=1)
    gap = np.abs(exact - reference).max(axis=1)
    assert np.all(scale > 0.0)
    # the reference must be sharp enough to fail a wrong column
    assert np.all(bound < 1e-4 * scale), bound / scale
    assert np.all(gap <= bound + scene.tolerance * scale), (gap / scale, bound / scale)


def _scene(pulse, widths, sensors, sampling):
    return default_scene(pixels=8, reflectance=_image(8), sensors=sensors, noise=None, sampling=sampling,
                         illumination=Illumination(waveform=pulse, **widths))


@pytest.mark.parametrize("pulse", sorted(_NARROW))
def test_an_isochrone_born_inside_a_bin(pulse):
    # sensor 0's first arrival (1.814 m) falls inside bin 0, 0.09 of a bin below its upper edge
    scene = _scene(pulse, _NARROW[pulse], [[0.3, 0.6, 0.8], [0.9, 0.2, 0.5]],
                   Sampling(bin_width_opl=0.07, start_opl=1.75, count=14))
    _against_differences(scene, _NARROW[pulse])


@pytest.mark.parametrize("pulse", sorted(_WIDE))
def test_a_pulse_wider_than_the_window(pulse):
    """Every cell reaches every bin; [S - u s] is a difference of two nearly equal values."""
    scene = _scene(pulse, _WIDE[pulse], [[0.3, 0.6, 0.8]], Sampling(bin_width_opl=0.05, start_opl=2.0, count=12))
    _against_differences(scene, _WIDE[pulse])


@pytest.mark.parametrize("pulse", ["square", "emg"])
def test_a_sensor_near_the_plane(pulse):
    scene = _scene(pulse, _NARROW[pulse], [[0.37, 0.61, 0.04]], Sampling(bin_width_opl=0.09, start_opl=1.0, count=14))
    _against_differences(scene, _NARROW[pulse])


# (the Gaussian's is the nearest the bound: 8e-8 of its column, 6e-7 with the pulse's integrals left unjudged)
@pytest.mark.parametrize("pulse", ["gaussian", "emg"])
def test_the_scenes_tolerance_bounds_each_width_column_entry(pulse):
    """At the default 1e-6, every entry within 1e-6 of its column's largest of the route at 1e-8."""
    scene = _scene(pulse, _NARROW[pulse], [[0.2, 0.3, 0.6], [0.7, 0.9, 0.2]],
                   Sampling(bin_width_opl=0.05, start_opl=1.5, count=20))
    keys = [f"illumination.{name}" for name in _NARROW[pulse]]
    loose, tight = jacobian(scene, keys), jacobian(scene.replace(tolerance=1e-8), keys)
    gap, scale = np.abs(loose - tight).max(axis=1), np.abs(tight).max(axis=1)
    assert np.all(gap < scene.tolerance * scale), gap / scale


def test_only_the_widths_the_route_gives_are_reported_exact():
    """A Butterworth's stated duration is a truncation its cutoff does not scale: both keep the differences."""
    sampling = Sampling(bin_width_opl=0.07, start_opl=1.75, count=14)
    stated = _scene("butterworth", dict(cutoff=8.0, duration=0.3), [[0.3, 0.6, 0.8]], sampling)
    keys = ["illumination.cutoff", "illumination.duration", "source.position.x"]
    assert exact_keys(stated, parameters(stated, keys)) == [False, False, True]
    scaled = _scene("butterworth", dict(cutoff=8.0), [[0.3, 0.6, 0.8]], sampling)
    assert exact_keys(scaled, parameters(scaled, keys[:1])) == [True]


# a relay wall's pass carries the same two integrals (analytic/operator/relay_wall_sensitivity.py), by the
# general route (the end legs counted) and by pixel offsets (a square parallel to the wall, a 4 x 4 scan)
_RELAY = {"general": dict(scan='type = "confocal"\ngrid = [2, 2]\naccount_first_and_last_bounces = true', start=3.01),
          "offsets": dict(scan='type = "confocal"\ngrid = [4, 4]', start=1.51,
                          hidden="center = [0.1, -0.05, 0.8]\nu = [1.5, 0.0, 0.0]\nv = [0.0, -1.5, 0.0]")}


@pytest.mark.parametrize("route, pulse, widths", [
    ("general", "gaussian", dict(fwhm=0.08)),
    pytest.param("general", "emg", dict(fwhm=0.05, tail=0.08), marks=pytest.mark.slow),
    pytest.param("offsets", "gaussian", dict(fwhm=0.08), marks=pytest.mark.slow),
    pytest.param("offsets", "emg", dict(fwhm=0.05, tail=0.08), marks=pytest.mark.slow)])
def test_a_relay_walls_widths(tmp_path, route, pulse, widths):
    from relay_capture import capture

    light = f'waveform = "{pulse}"\n' + "\n".join(f"{key} = {value}" for key, value in widths.items())
    _against_differences(capture(tmp_path, light=light, **_RELAY[route]), widths)
