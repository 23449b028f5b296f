"""Chunked renders: float64 accumulation, chunk invariance, sample streams."""

from __future__ import annotations


import numpy as np
from scipy import stats

from analytic.scenes.common import Sampling, Scene
from render_checks import FALSE_ALARM, model
from transient.render import render


def test_float64_accumulation_of_2_26_samples_in_one_bin():
    """2^26 contributions into one bin: a float32 sum would stall.

    A float32 accumulator stops growing once the sum reaches 2^24 times the
    typical contribution, so its mean would be low by far more than the
    standard error.
    """
    scene = Scene(size=1.0, pixels=2, reflectance=0.5, source=(0.5, 0.5, 1.0),
                  sensors=[(0.4, 0.6, 1.0)], sampling=Sampling(bin_width_opl=10.0, start_opl=0.0, count=1))
    result = render(scene, spp=2**26, seed=14, chunk_size=2**26, progress=False)
    reference = model(scene)
    t = (result.mean[0, 0] - reference[0, 0]) / result.stderr[0, 0]
    assert result.stderr[0, 0] < 1e-6 * reference[0, 0]
    assert abs(t) < stats.t.isf(FALSE_ALARM / 2, result.dof)


def test_chunking_does_not_change_the_result(scene):
    samples = 3 * 2**16 + 17
    whole = render(scene, spp=samples, seed=15, chunk_size=2**31, progress=False)
    for chunk in (2**16, 12345):
        split = render(scene, spp=samples, seed=15, chunk_size=chunk, progress=False)
        # Float64 additions in another order: equal to rounding, not bit for bit.
        np.testing.assert_allclose(split.mean, whole.mean, rtol=1e-12, atol=0)
        np.testing.assert_allclose(split.stderr, whole.stderr, rtol=1e-9, atol=0)
    other_seed = render(scene, spp=samples, seed=16, progress=False)
    assert not np.allclose(other_seed.mean, whole.mean, rtol=1e-6, atol=0)


def test_sample_streams_beyond_2_32_are_new_for_every_seed(mitsuba, scene):
    """Sample 2^32 + i of one seed must not replay sample i of any seed."""
    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import load_scene

    loaded = load_scene(scene, sampler="independent")
    integrator = loaded.integrator()
    layout = ReplicaLayout(4, 2**31)
    count = 2**12

    def sums(seed, first):
        return integrator.render_chunk(loaded, seed=seed, layout=layout, first=first, count=count).sum(axis=0)

    late = sums(5, 2**32)
    for seed in (5, 5 ^ 0x9E3779B9):
        assert not np.allclose(late, sums(seed, 0), rtol=1e-6)   # other streams: other noise
    np.testing.assert_allclose(sums(5, 2**32), late, rtol=1e-12)
