"""The Mitsuba transient renderer against the exact analytic model.

Agreement is judged per bin (DESIGN.md section 6, validation.compare): the
render's standard error comes from its 32 independent replicas, so each
z is Student's t with 31 degrees of freedom mapped to a normal score; over
the bins with enough samples, χ²/dof must lie inside the two-sided band
and max |z| below the Šidák threshold, the two together at false-alarm
rate 1e-3. Every render uses a fixed seed, so each test is deterministic;
the false-alarm rate says how unlucky a seed would have to be.
Deliberately wrong models must fail the same check, which shows it has the
power to catch the errors it is meant for.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

from analytic.scene import Illumination, Sampling, Scene
from analytic.system import forward
from transient import backend
from transient.backend import BackendError, choose_libllvm, find_llvm_libraries, llvm_version_of
from transient.render import render, render_loaded
from validation.compare import combined_dof, compare_transients
from validation.suite import hard_cases, validation_suite

FALSE_ALARM = 1e-3


def model(scene: Scene) -> np.ndarray:
    """The exact analytic model's y for the scene."""
    return forward(scene)


def agreement(mean, stderr, reference, dof):
    """(χ²/dof, max |z|, bins judged, passes) by validation.compare (DESIGN.md section 6)."""
    result = compare_transients(mean, stderr, reference, dof=dof, false_alarm=FALSE_ALARM)
    return result.chi2_per_dof, result.max_abs_z, result.bins, result.agrees


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


# -- unbiasedness ----------------------------------------------------------


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
        # Path lengths over a fine grid of the pixel (DESIGN.md section 1 orientation),
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
        # Scene loading launches its own small kernels (4096 lanes); the chunks are the others.
        launches = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT and k["size"] not in (1, 4096)]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert len(launches) >= 8 and len({k["hash"] for k in launches}) == 1


# -- general path: several shapes, visibility, interreflection -------------


def _render_dict(mitsuba, entries: dict, samples: int, seed: int):
    """Load a Mitsuba scene dict and render it (mean, stderr, dof from the replicas)."""
    return render_loaded(mitsuba.load_dict(entries), spp=samples, seed=seed)


def _general(entries: dict, **changes) -> dict:
    """The same scene for transient_opl_path (the single-plane keys dropped)."""
    general = {key: value for key, value in entries["integrator"].items()
               if key not in ("plane_to_world", "source_position")}
    return dict(entries, integrator=dict(general, type="transient_opl_path", **changes))


def test_general_path_matches_model_on_the_plane(mitsuba, scene):
    """The general estimator (area sampling over all shapes, shadow rays, next-event
    estimation) on the single-plane scene: same answer as the model."""
    from transient.mitsuba_scene import scene_dict

    result = _render_dict(mitsuba, _general(scene_dict(scene), max_depth=3), 2**22, 21)   # a plane cannot see itself
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(scene), result.dof)
    assert dof >= 50
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


def test_general_path_bins_float32_lengths_right_at_100_times_their_error(mitsuba):
    """Bins 100 times the stated float32 path-length error, over a window inside the response."""
    from transient.mitsuba_scene import scene_dict
    from transient.path import path_length_error

    source, sensor = np.array([0.5, 0.5, 1.0]), np.array([0.8, 0.3, 1.0])
    error = path_length_error(2.5, 1.0, 1)
    window = Sampling(bin_width_opl=100 * error, start_opl=2.2, count=120)
    scene = Scene(size=1.0, pixels=1, reflectance=0.5, source=source, sensors=[sensor], sampling=window)
    result = _render_dict(mitsuba, _general(scene_dict(scene)), 2**24, 25)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(scene), result.dof)
    assert error < 2e-6 and dof >= 100
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


CORNER_SOURCE = np.array([0.6, 0.4, 0.7])
CORNER_SENSORS = np.array([[0.5, 0.6, 0.8], [0.3, 0.2, 0.4]])
CORNER_ALBEDO = 0.5
CORNER_SAMPLING = Sampling(bin_width_opl=0.1, start_opl=0.6, count=30)


def _corner(max_depth: int) -> dict:
    """Floor [0,1]² x {0} (normal +z) and wall {0} x [0,1]² (normal +x), albedo 0.5."""
    from transient.mitsuba_scene import corner_scene_dict

    return corner_scene_dict(CORNER_SOURCE, CORNER_SENSORS, CORNER_ALBEDO, CORNER_SAMPLING, max_depth)


def _corner_one_bounce_model() -> np.ndarray:
    """Model of the floor plus model of the wall, the wall seen in its own frame.

    Inside the corner nothing occludes a single bounce, so the one-bounce
    transient is the sum of the two planes' exact models; (x, y, z) -> (y, z, x)
    is a rotation taking the wall onto the plane z = 0.
    """
    def planar(source, sensors):
        return model(Scene(size=1.0, pixels=1, reflectance=CORNER_ALBEDO, source=source,
                           sensors=sensors, sampling=CORNER_SAMPLING))

    rotate = [1, 2, 0]
    return planar(CORNER_SOURCE, CORNER_SENSORS) + planar(CORNER_SOURCE[rotate], CORNER_SENSORS[:, rotate])


def _corner_two_bounce_reference(samples: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Independent NumPy estimate of the paths source -> x2 -> x1 -> sensor between floor and wall.

    x1 uniform on one plane, a cosine-weighted direction from it intersected
    analytically with the other plane; per-sample weight
    cos θ_k / d_k² · ρ · ρ/π · cos θ_s / d_s² (the BSDF's cos/pdf cancels).
    Returns (mean, standard error from the samples' second moments), both (K, N).
    """
    sampling, mean, variance = CORNER_SAMPLING, 0.0, 0.0
    for first in ("floor", "wall"):
        u, v = rng.random(samples), rng.random(samples)
        radius, angle = np.sqrt(rng.random(samples)), 2 * np.pi * rng.random(samples)
        a, b = radius * np.cos(angle), radius * np.sin(angle)
        c = np.sqrt(np.maximum(0.0, 1.0 - radius**2))
        if first == "floor":
            x1, normal1, normal2 = np.stack([u, v, 0 * u], 1), np.array([0, 0, 1.0]), np.array([1.0, 0, 0])
            direction, axis = np.stack([a, b, c], 1), 0
        else:
            x1, normal1, normal2 = np.stack([0 * u, u, v], 1), np.array([1.0, 0, 0]), np.array([0, 0, 1.0])
            direction, axis = np.stack([c, a, b], 1), 2
        towards = direction[:, axis] < 0
        t = np.where(towards, -x1[:, axis] / np.where(towards, direction[:, axis], -1.0), 0.0)
        x2 = x1 + t[:, None] * direction
        x2[:, axis] = 0.0                     # on the other plane exactly, not ±1e-17
        hit = towards & np.all((x2 >= 0.0) & (x2 <= 1.0), axis=1)
        to_source = CORNER_SOURCE - x2
        source_distance = np.linalg.norm(to_source, axis=1)
        cos_source = np.clip(to_source @ normal2 / source_distance, 0.0, None)
        sums = np.zeros((len(CORNER_SENSORS), sampling.count))
        squares = np.zeros_like(sums)
        for k, position in enumerate(CORNER_SENSORS):
            to_sensor = position - x1
            sensor_distance = np.linalg.norm(to_sensor, axis=1)
            cos_sensor = np.clip(to_sensor @ normal1 / sensor_distance, 0.0, None)
            value = (cos_sensor / sensor_distance**2 * CORNER_ALBEDO * CORNER_ALBEDO / np.pi
                     * cos_source / source_distance**2)
            n = np.floor((sensor_distance + t + source_distance - sampling.start_opl) / sampling.bin_width_opl)
            keep = hit & (n >= 0) & (n < sampling.count)
            np.add.at(sums[k], n[keep].astype(int), value[keep])
            np.add.at(squares[k], n[keep].astype(int), value[keep] ** 2)
        # Each plane's x1 is its own estimator (area 1, pdf 1): means and variances add.
        mean = mean + sums / samples
        variance = variance + np.maximum(squares / samples - (sums / samples) ** 2, 0.0) / (samples - 1)
    return mean, np.sqrt(variance)


def test_general_path_sees_an_area_emitter(mitsuba):
    """Zero bounces: an omni sensor above a glowing 2 m x 2 m square (radiance 1).

    φ = ∫ L cos θ_e / d² dA over the square, by adaptive quadrature; one bin
    holds every path length.
    """
    from scipy import integrate

    sensor = (0.2, 0.1, 0.5)
    film = {"type": "hdrfilm", "width": 1, "height": 1, "pixel_format": "luminance"}
    entries = {"type": "scene",
               "integrator": {"type": "transient_opl_path", "bins": 1, "start_opl": 0.0, "bin_width_opl": 10.0},
               "lamp": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 0.0},
                        "emitter": {"type": "area", "radiance": 1.0}},
               "sensor": {"type": "omni_point", "position": list(sensor), "film": film}}
    result = _render_dict(mitsuba, entries, 2**20, 24)

    def integrand(y, x):
        squared = (x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2
        return sensor[2] / squared**1.5

    exact, _ = integrate.dblquad(integrand, -1.0, 1.0, -1.0, 1.0, epsabs=0, epsrel=1e-10)
    t = (result.mean[0, 0] - exact) / result.stderr[0, 0]
    assert result.stderr[0, 0] < 1e-2 * exact
    assert abs(t) < stats.t.isf(FALSE_ALARM / 2, result.dof)


def test_corner_one_bounce_matches_two_plane_models(mitsuba):
    result = _render_dict(mitsuba, _corner(1), 2**22, 22)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, _corner_one_bounce_model(),
                                                   result.dof)
    assert dof >= 20
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


def test_corner_two_bounces_match_independent_estimate(mitsuba, rng):
    result = _render_dict(mitsuba, _corner(2), 2**22, 23)
    one = _corner_one_bounce_model()
    two, two_stderr = _corner_two_bounce_reference(2**22, rng)
    combined = np.sqrt(result.stderr**2 + two_stderr**2)
    dof = combined_dof(result.stderr, result.dof, two_stderr, np.inf)
    chi2_per_dof, largest, bins, passes = agreement(result.mean, combined, one + two, dof)
    assert bins >= 40
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {bins} bins"
    # Interreflection is visible: leaving it out fails the same check.
    assert two.sum() > 0.05 * one.sum()
    *_, without_passes = agreement(result.mean, combined, one, dof)
    assert not without_passes


# -- accumulation, chunking ------------------------------------------------


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


# -- plugins ---------------------------------------------------------------


def test_plugins_refuse_what_they_cannot_render(mitsuba, scene):
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
                            ({"source_position": [0.3, 0.6, -0.8]}, "above")):
        with pytest.raises(RuntimeError, match=message):
            mitsuba.load_dict(dict(parts, integrator=dict(parts["integrator"], **change)))
    without = {key: value for key, value in parts["integrator"].items() if key != "plane_to_world"}
    with pytest.raises(RuntimeError, match="plane_to_world"):
        mitsuba.load_dict(dict(parts, integrator=without))
    mirror = dict(_general(parts), plane=dict(parts["plane"], bsdf={"type": "conductor"}))
    with pytest.raises(ValueError, match="diffuse"):
        chunk(mirror)
    with pytest.raises(ValueError, match="seed"):
        render_loaded(mitsuba.load_dict(parts), spp=100, seed=2**32)


def test_sensor_below_the_plane_sees_nothing(mitsuba, scene):
    """The rectangle's diffuse BSDF is one-sided: a sensor under it receives no light."""
    from transient.mitsuba_scene import scene_dict

    parts = scene_dict(scene)
    parts["sensor_000001"]["position"] = [0.5, 0.5, -0.5]
    result = _render_dict(mitsuba, parts, 2**16, 1)
    assert np.all(result.mean[1] == 0.0) and np.any(result.mean[0] > 0)


def test_backend_error_without_a_cuda_device():
    import drjit as dr

    backend.select_variant()
    if dr.has_backend(dr.JitBackend.CUDA):
        pytest.skip("a CUDA device is present")
    with pytest.raises(BackendError) as error:
        backend.select_variant("cuda_ad_mono")
    assert "\n" not in str(error.value) and "CUDA" in str(error.value)
    assert backend.select_variant() in ("llvm_mono", "llvm_ad_mono")



def test_omni_point_sensor(mitsuba):
    import drjit as dr

    film = {"type": "hdrfilm", "width": 1, "height": 1, "pixel_format": "luminance"}
    sensor = mitsuba.load_dict({"type": "omni_point", "position": [0.2, 0.7, 400.3], "film": film})
    # Double precision survives: float32 would give 400.29998779296875.
    assert sensor.position.tolist() == [0.2, 0.7, 400.3]
    moved = mitsuba.load_dict({"type": "omni_point", "film": film,
                               "to_world": mitsuba.ScalarTransform4d().translate([0.1, 0.2, 0.3])})
    np.testing.assert_array_equal(moved.position, [0.1, 0.2, 0.3])
    with pytest.raises(RuntimeError, match="not both"):
        mitsuba.load_dict({"type": "omni_point", "position": [0, 0, 1], "film": film,
                           "to_world": mitsuba.ScalarTransform4d()})
    it = dr.zeros(mitsuba.Interaction3f)
    it.p = mitsuba.Point3f(0.2, 0.7, 398.3)
    record, weight = sensor.sample_direction(it, mitsuba.Point2f(0.5, 0.5))
    assert float(record.dist[0]) == pytest.approx(2.0, rel=1e-6)
    assert float(weight[0][0]) == pytest.approx(0.25, rel=1e-6)       # 1/d², no 1/4 factor
    ray, ray_weight = sensor.sample_ray(0.0, 0.5, mitsuba.Point2f(0.3, 0.8), mitsuba.Point2f(0.5, 0.5))
    assert float(ray_weight[0][0]) == pytest.approx(4 * np.pi)        # ∫ dω over the sphere
    assert abs(float(dr.norm(ray.d)[0]) - 1.0) < 1e-6


# -- backend ---------------------------------------------------------------


@pytest.mark.parametrize("name, version", [
    ("libLLVM-19.so", 19), ("libLLVM.so.19.1", 19), ("libLLVM-15.so.1", 15),
    ("libLLVM-14.0.6.so.1", 14), ("libLLVM.so.18", 18), ("libLLVMCore.so", None),
])
def test_llvm_version_of_names(name, version):
    assert llvm_version_of(f"/nonexistent/{name}") == version


def test_llvm_version_inside_versioned_folder():
    assert llvm_version_of("/nonexistent/llvm-17/lib/libLLVM.so") == 17


def test_choose_libllvm():
    old = [(14, "/lib/libLLVM-14.so.1"), (15, "/lib/libLLVM-15.so.1")]
    new = old + [(19, "/lib/libLLVM.so.19.1"), (17, "/usr/lib/llvm-17/lib/libLLVM-17.so")]
    assert choose_libllvm(None, new) == "/lib/libLLVM.so.19.1"
    assert choose_libllvm("", new) == "/lib/libLLVM.so.19.1"
    with pytest.raises(BackendError) as error:
        choose_libllvm(None, old)
    message = str(error.value)
    assert "\n" not in message
    assert "LLVM 15 at /lib/libLLVM-15.so.1" in message and "apt-get install -y libllvm19" in message
    with pytest.raises(BackendError, match="LLVM 15"):
        choose_libllvm("/lib/libLLVM-15.so.1", new)
    with pytest.raises(BackendError, match="no libLLVM"):
        choose_libllvm(None, [])
    # A user's library of unreadable version is kept (and checked after loading).
    assert choose_libllvm("/opt/custom/libLLVM.so", old) == "/opt/custom/libLLVM.so"


def test_find_llvm_libraries(tmp_path):
    for name in ("libLLVM-15.so.1", "libLLVM.so.19.1", "libLLVMCore.a", "libLLVMX86CodeGen.so"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "libLLVM-19.so").symlink_to("libLLVM.so.19.1")
    (tmp_path / "libLLVM-15.so").symlink_to("libLLVM-15.so.1")
    found = find_llvm_libraries([str(tmp_path / "libLLVM*.so*")])
    assert [version for version, _ in found] == [15, 19]
    assert choose_libllvm(None, found).endswith(("libLLVM-19.so", "libLLVM.so.19.1"))


def _fresh_python(code: str, environment: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], env=environment, capture_output=True,
                          text=True, timeout=120)


def test_fresh_process_without_environment_gets_llvm_16_or_newer():
    if not any(version >= backend.MIN_LLVM for version, _ in find_llvm_libraries()):
        pytest.skip("no libLLVM >= 16 on this machine")
    environment = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    code = ("import os\n"
            "from transient.backend import select_variant\n"
            "variant = select_variant()\n"
            "import drjit as dr, mitsuba as mi\n"
            "value = dr.maximum(mi.Float([1.0, 3.0]), 2.0)\n"   # aborts the process on LLVM 15
            "print(variant, dr.detail.llvm_version()[0], os.environ['DRJIT_LIBLLVM_PATH'], list(value))\n")
    done = _fresh_python(code, environment)
    assert done.returncode == 0, done.stderr
    variant, version, path, *_ = done.stdout.split()
    assert variant in ("llvm_mono", "llvm_ad_mono")
    assert int(version) >= backend.MIN_LLVM and llvm_version_of(path) >= backend.MIN_LLVM


def test_fresh_process_refuses_llvm_15():
    environment = dict(os.environ, DRJIT_LIBLLVM_PATH="/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1")
    code = ("import sys\n"
            "from transient.backend import select_variant, BackendError\n"
            "try:\n    select_variant()\n"
            "except BackendError as error:\n    print(error); sys.exit(3)\n"
            "print('drjit' in sys.modules)\n")
    done = _fresh_python(code, environment)
    assert done.returncode == 3, done.stdout + done.stderr
    assert "LLVM 15" in done.stdout and "apt-get install -y libllvm19" in done.stdout
    assert done.stdout.count("\n") == 1


# -- CUDA ------------------------------------------------------------------


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
    """A fixed seed draws the same samples on both backends: the sums agree to float64 rounding."""
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
    np.testing.assert_allclose(sums[variant], sums[None], rtol=1e-9, atol=1e-9 * np.abs(sums[None]).max())
