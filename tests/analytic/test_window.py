"""The time window: path-length range, covering bins, the share of the light a window holds."""

import numpy as np
import pytest

from analytic.scenes.common import Illumination, Sampling, Scene, default_scene
from analytic.operator.system import system_matrix
from analytic.operator.matrix_free import forward
from analytic.operator.window import FULL_SHARE, WindowWarning, covering_sampling, response_range, warn_if_cut, window_share


def test_covering_sampling_keeps_every_path():
    # With an impulse each pixel's row sum over all bins is ∫ a_k over the pixel,
    # whatever the bins; the covering bins must lose none of it.
    from analytic.operator.conditioning import scene_for

    base = Scene(pixels=6, reflectance=0.5, source=(0.5, 0.5, 1.0), sensors=((0.2, 0.3, 1.0),))
    narrow = scene_for(base, extent=3.0, period=0.1, grid=(2, 2))
    wide = narrow.replace(sampling=Sampling(bin_width_opl=0.1, start_opl=0.0, count=120))
    k, n = narrow.sensor_count, narrow.sampling.count
    covered = system_matrix(narrow).toarray().reshape(k, n, -1).sum(axis=1)
    everything = system_matrix(wide).toarray().reshape(k, 120, -1).sum(axis=1)
    assert np.allclose(covered, everything, rtol=1e-9)


def test_response_range_is_the_extreme_path_lengths_of_a_fine_grid():
    scene = Scene(pixels=4, source=(0.3, 1.4, 0.7), sensors=((0.9, 0.2, 0.4), (0.5, 0.5, 2.0)))
    low, high = response_range(scene)
    grid = np.linspace(0.0, 1.0, 801)
    x, y = np.meshgrid(grid, grid)
    lengths = [np.sqrt((x - 0.3) ** 2 + (y - 1.4) ** 2 + 0.7**2)
               + np.sqrt((x - k[0]) ** 2 + (y - k[1]) ** 2 + k[2] ** 2) for k in scene.sensors]
    brute = np.min(lengths), np.max(lengths)
    assert low <= brute[0] and brute[0] - low < 1e-5      # the grid cannot go below the true minimum
    assert high == pytest.approx(brute[1], abs=1e-12)     # the maximum is at a corner, on the grid


@pytest.mark.parametrize("waveform", ["impulse", "square", "butterworth"])
def test_window_share_is_the_held_part_of_an_independent_sum(waveform):
    base = default_scene(pixels=8, illumination=Illumination(waveform=waveform))
    full = base.replace(sampling=covering_sampling(base, 0.1, margin=2))
    assert window_share(full) == 1.0
    y = forward(full)
    # cut the window after its fourth bin: the share is the sum of the bins kept
    cut = full.replace(sampling=Sampling(bin_width_opl=0.1, start_opl=full.sampling.start_opl, count=4))
    assert window_share(cut) == pytest.approx(y[:, :4].sum() / y.sum(), rel=1e-6)


def test_a_cut_window_warns_in_one_line():
    scene = default_scene(pixels=8)
    cut = scene.replace(sampling=Sampling(bin_width_opl=0.1, start_opl=1.9, count=4))
    share = window_share(cut)
    assert share < FULL_SHARE
    with pytest.warns(WindowWarning, match="holds"):
        warn_if_cut(cut, share)
