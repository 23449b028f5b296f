"""Extreme but legal inputs give the right numbers; impossible ones are refused before any work.

Resource limits are checked before anything of A's size is allocated (the
column and row pointers first, then the exactly counted non-zeros), and the
message names the setting, what it needs and the limit.
"""


import numpy as np
import pytest

from analytic.errors import ResourceError, SceneError
from analytic.scenes.common import Illumination, Sampling, Scene
from analytic.operator.system import MIN_TOLERANCE, count_entries, system_matrix
from analytic.operator.matrix_free import forward


def _scene(**changes):
    base = dict(pixels=6, reflectance=0.5, source=(0.4, 0.6, 0.8), sensors=[(0.7, 0.3, 0.6)],
                sampling=Sampling(bin_width_opl=0.1, start_opl=0.5, count=30))
    base.update(changes)
    return Scene(**base)


def test_too_many_pixels_for_the_column_index_is_refused_before_counting():
    scene = _scene(pixels=2000)
    with pytest.raises(ResourceError, match=r"^plane\.pixels.*GiB.*limit"):
        system_matrix(scene, memory_limit=10 * 2**20)


def test_too_many_bins_for_the_row_index_is_refused():
    scene = _scene(sampling=Sampling(bin_width_opl=0.1, start_opl=0.5, count=10**7))
    with pytest.raises(ResourceError, match=r"sampling\.count.*GiB.*limit"):
        system_matrix(scene, memory_limit=2**26)


def test_too_many_entries_is_refused_after_the_exact_count():
    scene = _scene(sampling=Sampling(bin_width_opl=1e-5, start_opl=0.5, count=200000))
    with pytest.raises(ResourceError, match=r"sampling.*entries.*GiB.*limit"):
        system_matrix(scene, memory_limit=4 * 2**20)


def test_count_is_exact_and_memory_follows_it():
    scene = _scene(illumination=Illumination(waveform="butterworth"))
    per_column = count_entries(scene)
    matrix = system_matrix(scene)
    assert per_column.sum() >= matrix.nnz >= 0.9 * per_column.sum()   # only exact zeros are dropped
    assert matrix.data.nbytes + matrix.indices.nbytes <= 12 * per_column.sum()


@pytest.mark.parametrize("tolerance", [1e-300, 0.0, -1e-6, 0.5, MIN_TOLERANCE / 10, float("nan")])
def test_tolerance_outside_the_supported_range_is_refused_before_any_quadrature(tolerance):
    with pytest.raises(SceneError, match="model.tolerance"):
        system_matrix(_scene(), tolerance=tolerance)


def test_square_pulse_wider_than_the_window_equals_any_other_wider_than_it():
    """Inside a 3 m window a 1e100 m and a 100 m square pulse are the same step."""
    narrow = system_matrix(_scene(illumination=Illumination(waveform="square", width=100.0)))
    wide = system_matrix(_scene(illumination=Illumination(waveform="square", width=1e100)))
    assert narrow.nnz > 0
    assert abs(narrow - wide).max() <= 1e-12 * abs(narrow).max()


def test_window_long_before_any_light_is_all_zero():
    """t0 = -1e11 m: a legal window that ends long before the first arrival."""
    y = forward(_scene(sampling=Sampling(bin_width_opl=0.1, start_opl=-1e11, count=30)))
    assert np.all(y == 0.0)


def test_huge_period_puts_all_light_in_one_bin():
    """T = 1e10 m (40 bins end at 4e11 m, inside the ±1e12 m bound): the first bin holds it all."""
    scene = _scene(sampling=Sampling(bin_width_opl=1e10, start_opl=0.0, count=40))
    y = forward(scene)
    reference = forward(_scene(sampling=Sampling(bin_width_opl=10.0, start_opl=0.0, count=1)))
    assert np.all(np.isfinite(y))
    assert y[0, 0] == pytest.approx(reference[0, 0], rel=1e-6)
    assert np.all(y[0, 1:] == 0.0)


@pytest.mark.parametrize("sampling", [dict(bin_width_opl=1e307, start_opl=0.0, count=40),
                                      dict(bin_width_opl=0.1, start_opl=-1e308, count=30)])
def test_windows_beyond_the_lengths_float64_resolves_are_refused(sampling):
    with pytest.raises(SceneError, match="sampling"):
        Sampling(**sampling)
