"""The Mitsuba transient renderer against the exact analytic model.

Agreement is judged per bin by z = (y_mc - y_model) / se_mc (DESIGN.md
section 6, validation.compare): over the bins with enough samples, χ²/dof
must lie inside the two-sided band and max |z| below the Šidák threshold,
the two together at false-alarm rate 1e-3. Every render
uses a fixed seed, so each test is deterministic; the false-alarm rate says
how unlucky a seed would have to be. Deliberately wrong models must fail the
same check, which shows it has the power to catch the errors it is meant for.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

from analytic.scene import Illumination, Sampling, Scene
from analytic.system import forward
from transient import backend
from transient.backend import BackendError, choose_libllvm, find_llvm_libraries, llvm_version_of
from transient.render import STATE_FILE, render, scene_fingerprint, standard_error
from validation.compare import compare_transients

FALSE_ALARM = 1e-3


def model(scene: Scene) -> np.ndarray:
    """The exact analytic model's y for the scene."""
    return forward(scene)


def agreement(mean, stderr, reference):
    """(χ²/dof, max |z|, bins judged, passes) by validation.compare (DESIGN.md section 6)."""
    result = compare_transients(mean, stderr, reference, false_alarm=FALSE_ALARM)
    return result.chi2_per_dof, result.max_abs_z, result.bins, result.agrees


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
    chi2_per_dof, largest, dof, passes = agreement(rendered.mean, rendered.stderr, model(scene))
    assert dof >= 50
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"
    assert rendered.samples == 2**22 and rendered.seed == 11
    assert rendered.mean.dtype == np.float64 and rendered.stderr.dtype == np.float64


@pytest.mark.parametrize("wrong", ["paper attenuation", "half-bin shift", "mirrored image",
                                   "no outgoing cosine"])
def test_wrong_model_fails(scene, rendered, wrong):
    if wrong == "paper attenuation":
        reference = model(scene.replace(attenuation="paper"))
    elif wrong == "half-bin shift":
        sampling = scene.sampling
        shifted = Sampling(bin_width_opl=sampling.bin_width_opl, start_opl=sampling.start_opl + sampling.bin_width_opl / 2,
                           count=sampling.count)
        reference = model(scene.replace(sampling=shifted))
    elif wrong == "mirrored image":
        # Row 0 at the bottom instead of the top.
        reference = model(scene.replace(reflectance=np.flipud(scene.reflectance)))
    else:
        # paper = lambertian x π / cos θ_k; undo the π: only the cosine is missing.
        reference = model(scene.replace(attenuation="paper")) / np.pi
    *_, passes = agreement(rendered.mean, rendered.stderr, reference)
    assert not passes


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
    result = render(shaped, spp=2**21, seed=12, progress=False)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(shaped))
    assert passes, f"{waveform}: chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"
    # A response one bin late must be caught.
    *_, shifted_passes = agreement(result.mean, result.stderr,
                                   np.roll(model(shaped), 1, axis=1))
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
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, reference)
    assert dof >= 950
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"
    # Light lands only where the model has light.
    assert np.all(reference[result.mean > 0] > 0)


# -- general path: several shapes, visibility, interreflection -------------


def _render_dict(mitsuba, entries: dict, samples: int, seed: int):
    """Load a Mitsuba scene dict and return (mean, stderr) of a transient_opl render."""
    loaded = mitsuba.load_dict(entries)
    sums, squares = loaded.integrator().render_transient(loaded, seed=seed, first_sample=0,
                                                        sample_count=samples)
    return sums / samples, standard_error(sums, squares, samples)


def test_general_path_matches_model_on_the_plane(mitsuba, scene, rendered):
    """The general estimator (area sampling over all shapes, shadow rays, next-event
    estimation) on the single-plane scene: same answer as the model, and as
    the single-plane estimator up to noise."""
    from transient.mitsuba_scene import scene_dict

    entries = scene_dict(scene)
    general = {key: value for key, value in entries["integrator"].items()
               if key not in ("plane_to_world", "source_position")}
    entries["integrator"] = dict(general, max_depth=3)   # a plane cannot see itself
    mean, stderr = _render_dict(mitsuba, entries, 2**22, 21)
    chi2_per_dof, largest, dof, passes = agreement(mean, stderr, model(scene))
    assert dof >= 50
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


CORNER_SOURCE = np.array([0.6, 0.4, 0.7])
CORNER_SENSORS = np.array([[0.5, 0.6, 0.8], [0.3, 0.2, 0.4]])
CORNER_ALBEDO = 0.5
CORNER_SAMPLING = Sampling(bin_width_opl=0.1, start_opl=0.6, count=30)


def _corner(mitsuba, max_depth: int) -> dict:
    """Floor [0,1]² x {0} (normal +z) and wall {0} x [0,1]² (normal +x), albedo 0.5."""
    film = {"type": "hdrfilm", "width": 1, "height": 1, "pixel_format": "luminance"}
    # Local x -> world y, local y -> world z, local z (the normal) -> world x.
    wall = np.array([[0, 0, 0.5, 0], [0.5, 0, 0, 0.5], [0, 0.5, 0, 0.5], [0, 0, 0, 1.0]])
    entries = {
        "type": "scene",
        "integrator": {"type": "transient_opl", "bins": CORNER_SAMPLING.count,
                       "start_opl": CORNER_SAMPLING.start_opl, "bin_width_opl": CORNER_SAMPLING.bin_width_opl,
                       "max_depth": max_depth},
        "floor": {"type": "rectangle",
                  "to_world": mitsuba.ScalarTransform4f().translate([0.5, 0.5, 0]).scale([0.5, 0.5, 1]),
                  "bsdf": {"type": "diffuse", "reflectance": CORNER_ALBEDO}},
        "wall": {"type": "rectangle", "to_world": mitsuba.ScalarTransform4f(wall),
                 "bsdf": {"type": "diffuse", "reflectance": CORNER_ALBEDO}},
        "source": {"type": "point", "position": CORNER_SOURCE.tolist(), "intensity": 1.0},
    }
    for k, position in enumerate(CORNER_SENSORS):
        entries[f"sensor_{k}"] = {"type": "omni_point", "position": position.tolist(), "film": film}
    return entries


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
    Returns (mean, standard error), both (K, N).
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
               "integrator": {"type": "transient_opl", "bins": 1, "start_opl": 0.0, "bin_width_opl": 10.0},
               "lamp": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 0.0},
                        "emitter": {"type": "area", "radiance": 1.0}},
               "sensor": {"type": "omni_point", "position": list(sensor), "film": film}}
    mean, stderr = _render_dict(mitsuba, entries, 2**20, 24)

    def integrand(y, x):
        squared = (x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2
        return sensor[2] / squared**1.5

    exact, _ = integrate.dblquad(integrand, -1.0, 1.0, -1.0, 1.0, epsabs=0, epsrel=1e-10)
    z = (mean[0, 0] - exact) / stderr[0, 0]
    assert stderr[0, 0] < 1e-2 * exact
    assert abs(z) < stats.norm.isf(FALSE_ALARM / 2)


def test_corner_one_bounce_matches_two_plane_models(mitsuba):
    mean, stderr = _render_dict(mitsuba, _corner(mitsuba, 1), 2**22, 22)
    chi2_per_dof, largest, dof, passes = agreement(mean, stderr, _corner_one_bounce_model())
    assert dof >= 20
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


def test_corner_two_bounces_match_independent_estimate(mitsuba, rng):
    mean, stderr = _render_dict(mitsuba, _corner(mitsuba, 2), 2**22, 23)
    one = _corner_one_bounce_model()
    two, two_stderr = _corner_two_bounce_reference(2**22, rng)
    combined = np.sqrt(stderr**2 + two_stderr**2)
    chi2_per_dof, largest, dof, passes = agreement(mean, combined, one + two)
    assert dof >= 40
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"
    # Interreflection is visible: leaving it out fails the same check.
    assert two.sum() > 0.05 * one.sum()
    *_, without_passes = agreement(mean, combined, one)
    assert not without_passes


# -- accumulation, chunking, checkpoints -----------------------------------


def test_float64_accumulation_of_2_26_samples_in_one_bin():
    """2^26 contributions into one bin in one kernel: a float32 sum would stall.

    A float32 accumulator stops growing once the sum reaches 2^24 times the
    typical contribution, so its mean would be low by far more than the
    standard error (about 1e-4 of the mean here).
    """
    scene = Scene(size=1.0, pixels=2, reflectance=0.5, source=(0.5, 0.5, 1.0),
                  sensors=[(0.4, 0.6, 1.0)], sampling=Sampling(bin_width_opl=10.0, start_opl=0.0, count=1))
    samples = 2**26
    result = render(scene, spp=samples, seed=14, chunk_size=samples, progress=False)
    reference = model(scene)
    z = (result.mean[0, 0] - reference[0, 0]) / result.stderr[0, 0]
    assert result.stderr[0, 0] < 1e-3 * reference[0, 0]
    assert abs(z) < stats.norm.isf(FALSE_ALARM / 2)


def test_standard_error_formula():
    rng = np.random.default_rng(0)
    values = rng.exponential(size=(3, 1000))
    se = standard_error(values.sum(axis=1), (values**2).sum(axis=1), 1000)
    np.testing.assert_allclose(se, values.std(axis=1, ddof=1) / np.sqrt(1000), rtol=1e-12)


def test_chunking_does_not_change_the_result(scene):
    samples = 3 * 2**16 + 17
    whole = render(scene, spp=samples, seed=15, chunk_size=samples, progress=False)
    for chunk in (2**16, 12345):
        split = render(scene, spp=samples, seed=15, chunk_size=chunk, progress=False)
        # Float64 atomics add in any order: equal to rounding, not bit for bit.
        np.testing.assert_allclose(split.mean, whole.mean, rtol=1e-12, atol=0)
        np.testing.assert_allclose(split.stderr, whole.stderr, rtol=1e-9, atol=0)
    other_seed = render(scene, spp=samples, seed=16, chunk_size=samples, progress=False)
    assert not np.allclose(other_seed.mean, whole.mean, rtol=1e-6, atol=0)


def test_interrupt_then_resume_matches_uninterrupted(scene, tmp_path):
    samples, chunk = 5 * 2**15, 2**15

    def stop_after_two_chunks(done):
        if done >= 2 * chunk:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render(scene, spp=samples, seed=17, chunk_size=chunk, out_dir=tmp_path, progress=False,
               on_chunk=stop_after_two_chunks)
    with np.load(tmp_path / STATE_FILE) as state:
        assert int(state["samples"]) == 2 * chunk
        assert str(state["fingerprint"]) == scene_fingerprint(scene)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["samples"] == 2 * chunk and meta["kind"] == "render"
    assert meta["attenuation"] == "lambertian" and meta["seed"] == 17
    partial = np.load(tmp_path / "transient.npy")
    assert partial.shape == (scene.sensor_count, scene.sampling.count)

    with pytest.raises(ValueError, match="seed"):
        render(scene, spp=samples, seed=18, chunk_size=chunk, out_dir=tmp_path, resume=True,
               progress=False)
    with pytest.raises(ValueError, match="different scene"):
        render(scene.replace(source=(0.3, 0.6, 0.9)), spp=samples, seed=17, chunk_size=chunk,
               out_dir=tmp_path, resume=True, progress=False)

    resumed = render(scene, spp=samples, seed=17, chunk_size=chunk, out_dir=tmp_path, resume=True,
                     progress=False)
    straight = render(scene, spp=samples, seed=17, chunk_size=chunk, progress=False)
    assert resumed.samples == samples
    np.testing.assert_allclose(resumed.mean, straight.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.load(tmp_path / "transient.npy"), straight.mean, rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.load(tmp_path / "stderr.npy"), straight.stderr, rtol=1e-9, atol=0)
    assert json.loads((tmp_path / "meta.json").read_text())["samples"] == samples


def test_render_rejects_bad_arguments(scene, tmp_path):
    with pytest.raises(ValueError, match="spp"):
        render(scene, spp=1, progress=False)
    with pytest.raises(ValueError, match="seed"):
        render(scene, spp=100, seed=-1, progress=False)
    with pytest.raises(ValueError, match="resume"):
        render(scene, spp=100, resume=True, out_dir=tmp_path, progress=False)


def test_sigterm_keeps_finished_chunks(scene, tmp_path):
    chunk = 2**15

    def terminate_after_one_chunk(done):
        os.kill(os.getpid(), signal.SIGTERM)

    previous = signal.getsignal(signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt):
        render(scene, spp=4 * chunk, seed=19, chunk_size=chunk, out_dir=tmp_path, progress=False,
               on_chunk=terminate_after_one_chunk)
    assert signal.getsignal(signal.SIGTERM) is previous
    with np.load(tmp_path / STATE_FILE) as state:
        assert int(state["samples"]) == chunk
    resumed = render(scene, spp=4 * chunk, seed=19, chunk_size=chunk, out_dir=tmp_path, resume=True,
                     progress=True)
    straight = render(scene, spp=4 * chunk, seed=19, chunk_size=2 * chunk, progress=False)
    np.testing.assert_allclose(resumed.mean, straight.mean, rtol=1e-12, atol=0)


# -- plugins ---------------------------------------------------------------


@pytest.fixture(scope="module")
def mitsuba():
    backend.select_variant()
    import mitsuba

    return mitsuba


@pytest.mark.parametrize("waveform", ["impulse", "square", "butterworth"])
def test_drjit_cumulative_matches_numpy(mitsuba, waveform):
    from analytic.waveforms import make_waveform
    from transient.integrator import cumulative

    for period in (0.001, 0.1, 10.0):
        shape = make_waveform(Illumination(waveform=waveform), period)
        span = max(shape.duration, period)
        # a geometric grid reaches the u -> 0 end, where S ~ u³ for the Butterworth pulse
        u = np.concatenate([-np.geomspace(1e-9, 1, 200) * span, np.geomspace(1e-9, 2, 2000) * span])
        values = np.array(cumulative(shape, mitsuba.Float64(u)))
        np.testing.assert_allclose(values, shape.cumulative(u), rtol=1e-12, atol=0)


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


def test_integrator_refuses_scenes_it_cannot_render(mitsuba, scene):
    from transient.mitsuba_scene import scene_dict

    parts = scene_dict(scene)
    extra = dict(parts, wall={"type": "rectangle"})
    loaded = mitsuba.load_dict(extra)
    with pytest.raises(ValueError, match="exactly one 'rectangle'"):
        loaded.integrator().render_transient(loaded, seed=0, first_sample=0, sample_count=16)
    moved = dict(parts, integrator=dict(parts["integrator"], source_position=[0.3, 0.6, 0.81]))
    loaded = mitsuba.load_dict(moved)
    with pytest.raises(ValueError, match="source_position"):
        loaded.integrator().render_transient(loaded, seed=0, first_sample=0, sample_count=16)
    with pytest.raises(RuntimeError, match="waveform"):
        mitsuba.load_dict(dict(parts, integrator=dict(parts["integrator"], waveform="sine")))
    with pytest.raises(RuntimeError, match="max_depth"):
        mitsuba.load_dict(dict(parts, integrator=dict(parts["integrator"], max_depth=2)))
    general = {key: value for key, value in parts["integrator"].items()
               if key not in ("plane_to_world", "source_position")}
    mirror = dict(parts, integrator=general, plane=dict(parts["plane"], bsdf={"type": "conductor"}))
    loaded = mitsuba.load_dict(mirror)
    with pytest.raises(ValueError, match="diffuse"):
        loaded.integrator().render_transient(loaded, seed=0, first_sample=0, sample_count=16)


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


def _cuda_available() -> bool:
    backend.select_variant()
    import drjit as dr
    import mitsuba as mi

    return any(v.startswith("cuda_") and v.endswith("mono") for v in mi.variants()) and \
        dr.has_backend(dr.JitBackend.CUDA)


@pytest.mark.cuda
def test_cuda_variant_agrees_with_model(scene):
    if not _cuda_available():
        pytest.skip("no CUDA device")
    import mitsuba as mi

    variant = "cuda_mono" if "cuda_mono" in mi.variants() else "cuda_ad_mono"
    try:
        result = render(scene, spp=2**22, seed=11, variant=variant, progress=False)
    finally:
        backend.select_variant()
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(scene))
    assert result.variant == variant
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


def test_sample_streams_beyond_2_32_are_new_for_every_seed(mitsuba, scene):
    """Sample 2^32 + i of one seed must not replay sample i of any seed (the
    old key folding made seed s past 2^32 equal seed s ^ 0x9E3779B9 from 0)."""
    from transient.mitsuba_scene import load_scene

    loaded = load_scene(scene)
    integrator = loaded.integrator()
    count = 2**12
    late, _ = integrator.render_transient(loaded, seed=5, first_sample=2**32, sample_count=count)
    for seed in (5, 5 ^ 0x9E3779B9):
        early, _ = integrator.render_transient(loaded, seed=seed, first_sample=0, sample_count=count)
        assert not np.allclose(late, early, rtol=1e-6)   # other streams: other noise
    again, _ = integrator.render_transient(loaded, seed=5, first_sample=2**32, sample_count=count)
    # with several Dr.Jit threads, atomic adds land in any order: equal to rounding
    np.testing.assert_allclose(late, again, rtol=1e-12)
