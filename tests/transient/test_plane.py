"""The single-plane estimator (transient_opl) against the exact model: unbiased, and powerful enough to
fail deliberately wrong models. Every render uses a fixed seed."""

from __future__ import annotations


import numpy as np
import pytest

from analytic.scenes.common import Illumination, Sampling, Scene
from analytic.operator.system import system_matrix
from analytic.operator.matrix_free import forward
from render_checks import agreement, model, render_dict
from transient.render import render, render_loaded
from validation.runs.suite import hard_cases, validation_suite


def test_render_agrees_with_model(scene, rendered):
    chi2_per_dof, largest, dof, passes = agreement(rendered.mean, rendered.stderr, model(scene), rendered.dof)
    assert dof >= 50
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"
    assert rendered.samples == 2**22 and rendered.seed == 11
    assert rendered.replicas == 32 and rendered.dof == 31
    assert rendered.mean.dtype == np.float64 and rendered.stderr.dtype == np.float64


@pytest.mark.parametrize("wrong", ["paper attenuation", "half-bin shift", "mirrored image",
                                   "no outgoing cosine"])
def test_wrong_model_fails(scene, rendered, wrong):
    if wrong == "paper attenuation":
        reference = model(scene.replace(attenuation="paper"))
    elif wrong == "half-bin shift":
        sampling = scene.sampling
        shifted = Sampling(bin_width_opl=sampling.bin_width_opl,
                           start_opl=sampling.start_opl + sampling.bin_width_opl / 2, count=sampling.count)
        reference = model(scene.replace(sampling=shifted))
    elif wrong == "mirrored image":
        # Row 0 at the bottom instead of the top.
        reference = model(scene.replace(reflectance=np.flipud(scene.reflectance)))
    else:
        # paper = lambertian x π / cos θ_k; undo the π: only the cosine is missing.
        reference = model(scene.replace(attenuation="paper")) / np.pi
    *_, passes = agreement(rendered.mean, rendered.stderr, reference, rendered.dof)
    assert not passes


def test_paper_attenuation_renders_the_papers_model(scene):
    """attenuation = "paper" renders eq. (1): it agrees with the paper's model and not with physical transport."""
    paper = scene.replace(attenuation="paper")
    result = render(paper, spp=2**20, seed=19, progress=False)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(paper), result.dof)
    assert dof >= 50
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"
    *_, lambertian_passes = agreement(result.mean, result.stderr, model(scene), result.dof)
    assert not lambertian_passes


def test_y_scales_with_the_intensity_exactly(scene):
    """y(I) / I is one array for every legal I (same seed), and each y(I) agrees with the model's.

    A float32 intensity flushes I = 1e-300 to zero (y = 0, stderr = 0) and
    rounds I = 1e30 by 1.5e-8 relative.
    """
    results = {intensity: render(scene.replace(intensity=intensity), spp=2**16, seed=23, progress=False)
               for intensity in (1e-300, 1e-30, 1.0, 1e30)}
    unit = results[1.0]
    assert np.all(unit.stderr[unit.mean > 0] > 0)
    for intensity, result in results.items():
        np.testing.assert_allclose(result.mean / intensity, unit.mean, rtol=1e-15, atol=0)
        np.testing.assert_allclose(result.stderr / intensity, unit.stderr, rtol=1e-15, atol=0)
        np.testing.assert_allclose(result.replica_means / intensity, unit.replica_means, rtol=1e-15, atol=0)
        chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr,
                                                       model(scene.replace(intensity=intensity)), result.dof)
        assert passes, f"I = {intensity:g}: chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


def test_the_emitter_holds_a_float32_stand_in_of_the_float64_intensity(mitsuba, scene):
    """Below float32's normal range the emitter holds the smallest normal float32; the plugin's float64
    source_intensity is what is rendered, and an emitter that disagrees with it is refused."""
    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import scene_dict
    from transient.intensity import emitter_intensity

    assert emitter_intensity(1e-300) == float(np.finfo(np.float32).tiny)
    assert emitter_intensity(1e30) == float(np.float32(1e30))
    layout = ReplicaLayout(2, 2**10)

    def sums(entries):
        loaded = mitsuba.load_dict(entries)
        return loaded.integrator().render_chunk(loaded, seed=4, layout=layout, first=0, count=layout.samples)

    unit = sums(scene_dict(scene))
    tiny = sums(scene_dict(scene.replace(intensity=1e-300)))
    np.testing.assert_allclose(tiny / 1e-300, unit, rtol=1e-15, atol=0)
    parts = scene_dict(scene)
    with pytest.raises(ValueError, match="source_intensity"):
        sums(dict(parts, source=dict(parts["source"], intensity=2.0)))


@pytest.mark.parametrize("estimator", [{"strategy": "source"}, {"strategy": "area"},
                                       {"strategy": "mis", "sampler": "independent"}])
def test_every_strategy_and_sampler_agrees_with_model(scene, estimator):
    result = render(scene, spp=2**20, seed=31, progress=False, estimator=estimator)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(scene), result.dof)
    assert passes, f"{estimator}: chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


def test_stratification_beats_independent_points(scene):
    """Same samples, same estimator: jittered cells give a far smaller error than independent points."""
    stratified = render(scene, spp=2**20, seed=32, progress=False)
    independent = render(scene, spp=2**20, seed=32, progress=False, estimator={"sampler": "independent"})
    assert np.linalg.norm(stratified.stderr) < 0.25 * np.linalg.norm(independent.stderr)


def test_single_pixel_lights_only_its_path_lengths():
    pixels, row, col = 8, 1, 6
    image = np.zeros((pixels, pixels))
    image[row, col] = 1.0
    source, sensor = np.array([0.5, 0.5, 0.4]), np.array([0.1, 0.1, 0.3])
    sampling = Sampling(bin_width_opl=0.02, start_opl=0.5, count=80)
    scene = Scene(size=1.0, pixels=pixels, reflectance=image, source=source, sensors=[sensor],
                  sampling=sampling)
    result = render(scene, spp=2**20, seed=5, progress=False)

    def bins_of(r, c):
        # Path lengths over a fine grid of the pixel (docs/design.md section 1 orientation),
        # widened by the grid's own resolution: d is 2-Lipschitz in x.
        delta = 1.0 / pixels
        step = delta / 400
        x = (c + (np.arange(401) / 400)) * delta
        y = 1.0 - (r + (np.arange(401) / 400)) * delta
        gx, gy = np.meshgrid(x, y)
        points = np.stack([gx, gy, np.zeros_like(gx)], axis=-1)
        length = (np.linalg.norm(points - source, axis=-1) + np.linalg.norm(points - sensor, axis=-1))
        lowest, highest = length.min() - 2 * step, length.max() + 2 * step
        return (int(np.floor((lowest - sampling.start_opl) / sampling.bin_width_opl)),
                int(np.floor((highest - sampling.start_opl) / sampling.bin_width_opl)))

    lit = np.flatnonzero(result.mean[0] > 0)
    first, last = bins_of(row, col)
    assert lit.size > 0 and lit.min() >= first and lit.max() <= last
    # The bins strictly inside the pixel's range are certainly hit.
    assert set(range(first + 1, last)) <= set(lit.tolist())
    # The mirrored pixel would light other bins: the check can tell them apart.
    mirrored = bins_of(pixels - 1 - row, col)
    assert mirrored[0] > last or mirrored[1] < first


@pytest.mark.parametrize("waveform", ["square", "butterworth"])
def test_illuminations_agree_with_model(scene, waveform):
    shaped = scene.replace(illumination=Illumination(waveform=waveform))
    result = render(shaped, spp=2**20, seed=12, progress=False)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(shaped), result.dof)
    assert passes, f"{waveform}: chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"
    # A response one bin late must be caught.
    *_, shifted_passes = agreement(result.mean, result.stderr, np.roll(model(shaped), 1, axis=1), result.dof)
    assert not shifted_passes


def test_far_plane_bins_exactly():
    """Source and sensor 400 m away; bins 1/1000 of the 2 mm spread of path lengths.

    In float32 the positions alone (ulp 3e-5 m at 400 m) would move path
    lengths by tens of bins.
    """
    source, sensor = np.array([0.5, 0.5, 400.3]), np.array([0.2, 0.7, 399.9])
    grid = np.linspace(0.0, 1.0, 801)
    gx, gy = np.meshgrid(grid, grid)
    points = np.stack([gx, gy, np.zeros_like(gx)], axis=-1)
    length = np.linalg.norm(points - source, axis=-1) + np.linalg.norm(points - sensor, axis=-1)
    spread = length.max() - length.min()
    period = spread / 1000
    image = np.random.default_rng(3).uniform(0.2, 1.0, (4, 4))
    scene = Scene(size=1.0, pixels=4, reflectance=image, source=source, sensors=[sensor],
                  sampling=Sampling(bin_width_opl=period, start_opl=length.min() - 20 * period, count=1040))
    result = render(scene, spp=2**24, seed=13, progress=False)
    reference = model(scene)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, reference, result.dof)
    assert dof >= 950
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"
    # Light lands only where the model has light.
    assert np.all(reference[result.mean > 0] > 0)


def test_a_near_deterministic_render_carries_no_float32_constant():
    """A 1e-9 m plane seen from 1 m: every sample has nearly the same value, so the render's standard
    error is ~1e-13 of y and any float32 factor (Mitsuba's ρ/π is float32: float32(1/π) π − 1 = −4.0e-8)
    would stand out by 1e5 standard errors. The sensor off to the side also takes the technique planner
    past a rectangle too small for its solid angle to be resolved."""
    scene = Scene(size=1e-9, pixels=2, reflectance=0.5, source=(0.5, 0.5, 1.0),
                  sensors=[(0.25, 0.75, 1.0), (0.5, 0.5, 0.5)],
                  sampling=Sampling(bin_width_opl=0.1, start_opl=0.0, count=40))
    result = render(scene, spp=2**16, seed=3, progress=False)
    reference = forward(scene, system_matrix(scene, tolerance=1e-10))
    lit = reference > 0
    assert np.all(result.stderr[lit] < 1e-11 * reference[lit])       # the test can see a 4e-8 bias
    assert np.all(np.abs(result.mean - reference)[lit] < 5 * result.stderr[lit] + 1e-13 * reference[lit])
    assert np.all(result.mean[~lit] == 0)


def test_a_pulse_longer_than_the_window_renders_as_fast_and_as_right():
    """A square of width 1e300 m touches ~1e301 bins but the window's 40: the deposit visits those only
    (it looped over every bin the pulse touches: a hang), and inside the window the render equals that of
    a square of width 100 m (the same light there) to rounding."""
    scene = Scene(size=1.0, pixels=4, reflectance=0.5, source=(0.5, 0.5, 1.0), sensors=[(0.2, 0.7, 1.0)],
                  sampling=Sampling(bin_width_opl=0.1, start_opl=0.0, count=40))
    results = {}
    for width in (100.0, 1e300):
        wide = scene.replace(illumination=Illumination(waveform="square", width=width))
        results[width] = render(wide, spp=2**18, seed=5, progress=False)
    np.testing.assert_allclose(results[1e300].mean, results[100.0].mean, rtol=1e-12, atol=0)
    chi2_per_dof, largest, dof, passes = agreement(results[1e300].mean, results[1e300].stderr,
                                                   model(scene.replace(illumination=Illumination(
                                                       waveform="square", width=1e300))), results[1e300].dof)
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


@pytest.mark.parametrize("name", [scene.name for scene, _ in validation_suite()
                                  if scene.name in hard_cases()])
def test_hard_cases_agree_at_the_suite_counts(name):
    scene, spp = next((s, n) for s, n in validation_suite() if s.name == name)
    result = render(scene, spp=spp, seed=41, progress=False)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(scene), result.dof)
    assert passes, f"{name}: chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


def test_low_source_and_sensors_have_bounded_weights(mitsuba):
    """Source and sensors 1e-3 above the plane: no sample weighs much more than the mean.

    Replicas of 4 independent samples (2 by the source's solid angle, 1 by
    each sensor's) bound every sample's weight by 4 x its replica's mean.
    With multiple importance sampling the largest replica mean stays within
    a few times the mean; by area (or by the source alone) a sample near a
    sensor's foot weighs thousands of times the mean: the heavy tail.
    """
    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import load_scene

    scene = hard_cases(pixels=10)["low"].replace(sampling=Sampling(bin_width_opl=100.0, start_opl=0.0, count=1))
    layout = ReplicaLayout(2**16, 4)

    def peak_over_mean(**estimator):
        loaded = load_scene(scene, sampler="independent", **estimator)
        means = loaded.integrator().render_chunk(loaded, seed=3, layout=layout, first=0,
                                                 count=layout.samples)[:, :, 0] / layout.size
        return means.max(axis=0) / means.mean(axis=0)

    assert np.all(peak_over_mean() < 10)
    assert np.all(peak_over_mean(strategy="area") > 1e3)
    assert np.any(peak_over_mean(strategy="source") > 1e3)


def test_one_compiled_kernel_serves_every_chunk_seed_and_sample_count(mitsuba, scene):
    """Seeds, offsets, replica sizes and technique blocks reach the kernel as opaque values."""
    import drjit as dr

    render(scene, spp=2**17, seed=1, progress=False)                   # compiles
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        render(scene, spp=3 * 2**17 + 5, seed=2, progress=False, chunk_size=2**16)
        render(scene, spp=2**18, seed=3, progress=False)
        render(scene.replace(intensity=1e-300), spp=2**18, seed=3, progress=False)     # I is not in the kernel
        # Scene loading launches its own small kernels (4096 lanes); the chunks are the others.
        launches = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT and k["size"] not in (1, 4096)]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert len(launches) >= 8 and len({k["hash"] for k in launches}) == 1


def test_plugins_refuse_what_they_cannot_render(mitsuba, scene, path_dict):
    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import scene_dict

    layout = ReplicaLayout(2, 16)

    def chunk(entries):
        loaded = mitsuba.load_dict(entries)
        return loaded.integrator().render_chunk(loaded, seed=0, layout=layout, first=0, count=16)

    parts = scene_dict(scene)
    with pytest.raises(ValueError, match="exactly one 'rectangle'"):
        chunk(dict(parts, wall={"type": "rectangle"}))
    with pytest.raises(ValueError, match="source_position"):
        chunk(dict(parts, integrator=dict(parts["integrator"], source_position=[0.3, 0.6, 0.81])))
    for change, message in (({"waveform": "sine"}, "waveform"), ({"max_depth": 2}, "max_depth"),
                            ({"strategy": "best"}, "strategy"), ({"sampler": "sobol"}, "sampler"),
                            ({"source_position": [0.3, 0.6, -0.8]}, "above"),
                            ({"attenuation": "cosine"}, "attenuation"),
                            ({"source_intensity": -1.0}, "source_intensity"),
                            ({"source_intensity": float("inf")}, "source_intensity")):
        with pytest.raises(RuntimeError, match=message):
            mitsuba.load_dict(dict(parts, integrator=dict(parts["integrator"], **change)))
    without = {key: value for key, value in parts["integrator"].items() if key != "plane_to_world"}
    with pytest.raises(RuntimeError, match="plane_to_world"):
        mitsuba.load_dict(dict(parts, integrator=without))
    mirror = dict(path_dict(parts), plane=dict(parts["plane"], bsdf={"type": "conductor"}))
    with pytest.raises(ValueError, match="diffuse"):
        chunk(mirror)
    with pytest.raises(ValueError, match="seed"):
        render_loaded(mitsuba.load_dict(parts), spp=100, seed=2**32)


def test_sensor_below_the_plane_sees_nothing(mitsuba, scene):
    """The rectangle's diffuse BSDF is one-sided: a sensor under it receives no light."""
    from transient.mitsuba_scene import scene_dict

    parts = scene_dict(scene)
    parts["sensor_000001"]["position"] = [0.5, 0.5, -0.5]
    result = render_dict(mitsuba, parts, 2**16, 1)
    assert np.all(result.mean[1] == 0.0) and np.any(result.mean[0] > 0)
