"""The CUDA variant: agreement with the model, and the CPU's sums to 1e-9 (skipped without a card)."""

from __future__ import annotations


import numpy as np
import pytest

from analytic.scenes.common import Illumination
from render_checks import agreement, model
from transient import backend
from transient.render import render


def _cuda_variant() -> str | None:
    """A mono CUDA variant when this machine has a CUDA device, else None."""
    backend.select_variant()
    import drjit as dr
    import mitsuba as mi

    if not dr.has_backend(dr.JitBackend.CUDA):
        return None
    return next((v for v in ("cuda_mono", "cuda_ad_mono") if v in mi.variants()), None)


@pytest.mark.cuda
def test_cuda_variant_agrees_with_model(scene):
    variant = _cuda_variant()
    if variant is None:
        pytest.skip("no CUDA device")
    try:
        result = render(scene, spp=2**24, seed=11, variant=variant, progress=False)
    finally:
        backend.select_variant()
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(scene), result.dof)
    assert result.variant == variant
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


@pytest.mark.cuda
@pytest.mark.parametrize("waveform", ["impulse", "butterworth"])
def test_cuda_sums_equal_cpu_sums(scene, waveform):
    """A fixed seed draws the same samples on both backends: the sums agree to float32 geometry's rounding.

    Each sample's path length and weight are computed in the variant's float32 (only the
    accumulation is float64), and the two backends contract multiply-adds differently: measured
    on an H100, 12 of 1,920 entries moved by up to 1e-4 of themselves (a sample within rounding of
    a bin edge lands on the other side) and the total by 5.7e-7. A different sampler, a lost term
    or a wrong bin would move them by far more.
    """
    variant = _cuda_variant()
    if variant is None:
        pytest.skip("no CUDA device")
    from transient.chunks import ReplicaLayout

    shaped = scene.replace(illumination=Illumination(waveform=waveform))
    layout = ReplicaLayout.for_samples(2**22)
    sums = {}
    try:
        for name in (variant, None):
            backend.select_variant(name)
            from transient.mitsuba_scene import load_scene

            loaded = load_scene(shaped)
            sums[name] = loaded.integrator().render_chunk(loaded, seed=7, layout=layout, first=2**20,
                                                          count=2**21)
    finally:
        backend.select_variant()
    cuda, cpu = np.asarray(sums[variant]), np.asarray(sums[None])
    np.testing.assert_allclose(cuda.sum(axis=-1), cpu.sum(axis=-1), rtol=1e-4)   # every (replica, sensor)
    np.testing.assert_allclose(cuda, cpu, rtol=0, atol=1e-3 * np.abs(cpu).max())


def _relay_wall_case():
    """An off-centre, tilted hidden rectangle, a Butterworth pulse, a single scan: every factor of the third bounce."""
    from analytic.scenes.relay_wall import RelayWallScene, Scan
    from analytic.scenes.common import Sampling
    from analytic.operator.window import pairs_range

    scene = RelayWallScene(pixels=6, reflectance=np.linspace(0.1, 1.0, 36).reshape(6, 6), center=(0.2, 0.1, 1.1),
                           u=(0.7, 0.0, 0.3), v=(0.0, -0.8, 0.0),
                           scan=Scan(type="single", grid=(3, 2), laser_point=(0.3, -0.2, 0.0)),
                           illumination=Illumination(waveform="butterworth", order=2, cutoff=8.0), intensity=5.0)
    low, high = pairs_range(*scene.geometry())
    return scene.replace(sampling=Sampling(bin_width_opl=0.02, start_opl=low - 0.02,
                                           count=int((high - low) / 0.02) + 3))


def relay_wall_sums(variant, seed=7):
    """Our relay-wall renderer's per-replica sums of 2^21 samples on ``variant`` (None: the CPU's)."""
    import mitsuba as mi

    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import relay_wall_scene_dict

    backend.select_variant(variant)
    loaded = mi.load_dict(relay_wall_scene_dict(_relay_wall_case()))
    layout = ReplicaLayout.for_samples(2**22)
    return np.asarray(loaded.integrator().render_chunk_per_unit_intensity(loaded, seed=seed, layout=layout,
                                                                          first=2**20, count=2**21))


@pytest.mark.cuda
def test_cuda_relay_wall_render_agrees_with_model():
    """transient_opl_nlos on the card: the render of a tilted, off-centre capture agrees with the exact model."""
    variant = _cuda_variant()
    if variant is None:
        pytest.skip("no CUDA device")
    scene = _relay_wall_case()
    try:
        result = render(scene, spp=2**22, seed=5, variant=variant, progress=False)
    finally:
        backend.select_variant()
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(scene), result.dof,
                                                   replicas=result.replica_means)
    assert result.variant == variant and dof > 100
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


@pytest.mark.cuda
def test_cuda_relay_wall_sums_equal_cpu_sums():
    """The same samples on both backends: sums agree to float32 geometry's rounding (as for the plane)."""
    variant = _cuda_variant()
    if variant is None:
        pytest.skip("no CUDA device")
    try:
        cuda, cpu = relay_wall_sums(variant), relay_wall_sums(None)
    finally:
        backend.select_variant()
    np.testing.assert_allclose(cuda.sum(axis=-1), cpu.sum(axis=-1), rtol=1e-4)
    np.testing.assert_allclose(cuda, cpu, rtol=0, atol=1e-3 * np.abs(cpu).max())
