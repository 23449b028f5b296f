"""The general multi-bounce estimator (transient_opl_path): the plane, float32 binning, area emitters, the corner."""

from __future__ import annotations


import numpy as np
from scipy import stats

from analytic.scenes.common import Sampling, Scene
from render_checks import FALSE_ALARM, agreement, model, render_dict
from validation.judging.compare import combined_dof


CORNER_SOURCE = np.array([0.6, 0.4, 0.7])
CORNER_SENSORS = np.array([[0.5, 0.6, 0.8], [0.3, 0.2, 0.4]])
CORNER_ALBEDO = 0.5
CORNER_SAMPLING = Sampling(bin_width_opl=0.1, start_opl=0.6, count=30)


def test_general_path_matches_model_on_the_plane(mitsuba, scene, path_dict):
    """The general estimator (area sampling over all shapes, shadow rays, next-event
    estimation) on the single-plane scene: same answer as the model."""
    from transient.mitsuba_scene import scene_dict

    result = render_dict(mitsuba, path_dict(scene_dict(scene), max_depth=3), 2**22, 21)   # a plane cannot see itself
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(scene), result.dof)
    assert dof >= 50
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


def test_general_path_bins_float32_lengths_right_at_100_times_their_error(mitsuba, path_dict):
    """Bins 100 times the stated float32 path-length error, over a window inside the response."""
    from transient.mitsuba_scene import scene_dict
    from transient.path import path_length_error

    source, sensor = np.array([0.5, 0.5, 1.0]), np.array([0.8, 0.3, 1.0])
    error = path_length_error(2.5, 1.0, 1)
    window = Sampling(bin_width_opl=100 * error, start_opl=2.2, count=120)
    scene = Scene(size=1.0, pixels=1, reflectance=0.5, source=source, sensors=[sensor], sampling=window)
    result = render_dict(mitsuba, path_dict(scene_dict(scene)), 2**24, 25)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, model(scene), result.dof)
    assert error < 2e-6 and dof >= 100
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


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
    result = render_dict(mitsuba, entries, 2**20, 24)

    def integrand(y, x):
        squared = (x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2
        return sensor[2] / squared**1.5

    exact, _ = integrate.dblquad(integrand, -1.0, 1.0, -1.0, 1.0, epsabs=0, epsrel=1e-10)
    t = (result.mean[0, 0] - exact) / result.stderr[0, 0]
    assert result.stderr[0, 0] < 1e-2 * exact
    assert abs(t) < stats.t.isf(FALSE_ALARM / 2, result.dof)


def test_corner_one_bounce_matches_two_plane_models(mitsuba):
    result = render_dict(mitsuba, _corner(1), 2**22, 22)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, _corner_one_bounce_model(),
                                                   result.dof)
    assert dof >= 20
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"


def test_corner_two_bounces_match_independent_estimate(mitsuba, rng):
    # 2^20 samples each (2^22 before: ~8 s): still 44 bins judged, and without the second bounce
    # χ²/dof is ~190 (limit ~1.5), so the missing interreflection fails by far
    result = render_dict(mitsuba, _corner(2), 2**20, 23)
    one = _corner_one_bounce_model()
    two, two_stderr = _corner_two_bounce_reference(2**20, rng)
    combined = np.sqrt(result.stderr**2 + two_stderr**2)
    dof = combined_dof(result.stderr, result.dof, two_stderr, np.inf)
    chi2_per_dof, largest, bins, passes = agreement(result.mean, combined, one + two, dof)
    assert bins >= 40
    assert passes, f"chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {bins} bins"
    # Interreflection is visible: leaving it out fails the same check.
    assert two.sum() > 0.05 * one.sum()
    *_, without_passes = agreement(result.mean, combined, one, dof)
    assert not without_passes
