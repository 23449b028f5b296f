"""validation.check.conventions: the diagnosis names known conventions; the irradiancemeter's stated
convention (1/4 of the fluence, paths short by 2r/3) against independent quadratures and renders."""

from __future__ import annotations

import json

import numpy as np
import pytest

from check_cases import WIDTH, noisy_replicas, run_check, shifted
from validation.check import check_transient, diagnose

# Synthetic replicas are few (6) and independent from bin to bin: the limits' fallback to independent
# bins, and its warning, are what tests/validation/test_compare.py tests; here they are expected.
pytestmark = pytest.mark.filterwarnings("ignore::validation.judging.compare.CorrelationWarning")


def test_diagnosis_of_an_irradiancemeter():
    from validation.check import Fit

    fit = Fit(0.2501, 0.0004, 1.55e-4, 0.1e-4, 3, True, "replicas")
    text = diagnose(fit, agrees=False, agrees_after_fit=True, bin_width_opl=0.05)
    assert text == ("agrees after scale 0.2501 ± 0.0004 and offset +1.55e-4 ± 0.10e-4 m: a sensor that "
                    "reads 1/4 of the fluence and path lengths short (an irradiancemeter? --expect "
                    "irradiancemeter states that convention).")


def test_whole_bins_of_offset_are_named(scene, model, rng):
    data = noisy_replicas(shifted(scene, 2 * WIDTH), rng)
    result = check_transient(scene, data, model=model)
    assert result.agrees_after_fit
    assert abs(result.fit.offset_opl - 2 * WIDTH) < 3 * result.fit.offset_stderr
    assert "off by +2 bin(s)" in result.diagnosis


def sphere_mean_irradiance(centre_distance: float, radius: float, intensity, points: int = 64) -> float:
    """Irradiance from a point emitter at the origin averaged over a sphere's surface, by quadrature.

    The sphere's centre lies at distance d on the direction at 60° from the +z axis; ``intensity(ω)``
    is the emitter's intensity toward the unit direction ω. Gauss–Legendre in μ (the cosine about the
    axis toward the emitter, over the lit cap μ > r/d) and uniform in the azimuth.
    """
    axis = np.array([np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3)])
    centre = centre_distance * axis
    helper = np.cross(axis, [0.0, 1.0, 0.0])
    u, v = helper / np.linalg.norm(helper), np.array([0.0, 1.0, 0.0])
    nodes, weights = np.polynomial.legendre.leggauss(points)
    low = radius / centre_distance
    mu = low + (1 - low) * (nodes + 1) / 2
    phi = np.linspace(0.0, 2 * np.pi, 2 * points, endpoint=False)
    mu, phi = np.meshgrid(mu, phi, indexing="ij")
    sine = np.sqrt(1 - mu**2)
    normal = (-mu[..., None] * axis + sine[..., None] * (np.cos(phi)[..., None] * u + np.sin(phi)[..., None] * v))
    point = centre + radius * normal
    distance = np.linalg.norm(point, axis=-1)
    towards = -point / distance[..., None]                      # from the sphere's point to the emitter
    irradiance = intensity(-towards) * np.maximum(np.sum(normal * towards, axis=-1), 0.0) / distance**2
    area_weight = (1 - low) / 2 * weights[:, None] * (2 * np.pi / phi.shape[1])     # dA / r² = dμ dφ
    return float(np.sum(irradiance * area_weight) / (4 * np.pi))


def test_an_irradiancemeter_reads_a_quarter_of_a_lambertian_plane_exactly():
    """A sphere of any radius above a Lambertian element intercepts exactly 1/4 of the fluence rate at
    its centre (its projected solid angle is π (r/d)² cos θ), unlike a sphere near an isotropic point,
    which reads 1 / (2 (1 + sqrt(1 - (r/d)²))) of it: the scale `--expect irradiancemeter` states."""
    distance = 1.0
    cosine = np.cos(np.pi / 3)                                   # the centre's angle from the normal
    for radius in (0.05, 0.3, 0.49):
        lambertian = sphere_mean_irradiance(distance, radius, lambda w: w[..., 2])
        assert lambertian == pytest.approx(cosine / distance**2 / 4, rel=1e-9)
        isotropic = sphere_mean_irradiance(distance, radius, lambda w: np.ones(w.shape[:-1]))
        ratio = 1 / (2 * (1 + np.sqrt(1 - (radius / distance) ** 2)))
        assert isotropic == pytest.approx(ratio / distance**2, rel=1e-9)
        assert abs(isotropic * distance**2 - 0.25) > 1e-4                 # the correction is real there


def test_the_irradiancemeters_paths_are_short_by_two_thirds_of_its_radius():
    """Irradiance-weighted mean shortfall of the path to the sphere's surface against its centre: 2r/3,
    to first order in r/d (the offset `--expect irradiancemeter` states, with Mitsuba's ray epsilon)."""
    distance, radius = 1.0, 1e-3
    nodes, weights = np.polynomial.legendre.leggauss(64)
    low = radius / distance
    mu = low + (1 - low) * (nodes + 1) / 2           # the lit cap, μ the cosine about the axis to the emitter
    # the emitter's intensity is the same toward the whole cap to first order: the weight is the irradiance
    point_distance = np.sqrt(distance**2 + radius**2 - 2 * distance * radius * mu)
    weight = weights * (distance * mu - radius) / point_distance**3
    shortfall = np.sum(weight * (distance - point_distance)) / np.sum(weight)
    assert shortfall == pytest.approx(2 * radius / 3, rel=2 * radius / distance)


def irradiancemeter_data(scene, rng, radius: float, scale: float = 0.25) -> np.ndarray:
    """16 replicas of what spheres of ``radius`` read, from the formula: scale x the model with start_opl
    moved by 2r/3 + Mitsuba's float32 RayEpsilon (1500 x 2^-24 m)."""
    return noisy_replicas(scale * shifted(scene, 2 * radius / 3 + 1500 * 2.0**-24), rng, replicas=16)


def test_check_expect_irradiancemeter_judges_the_stated_convention(tmp_path, scene_file, scene, rng):
    """The command with each option where it must agree (so each option is read); the verdicts that must
    not agree from check_transient in this process (the same judge, without ~1.5 s of figures each)."""
    from validation.check import Convention, check_transient, irradiancemeter

    radius = 0.015
    offset = 2 * radius / 3 + 1500 * 2.0**-24
    data = irradiancemeter_data(scene, rng, radius)
    paths = []
    for r, replica in enumerate(data):
        paths.append(tmp_path / f"meter_{r}.npy")
        np.save(paths[-1], replica)
    assert run_check(scene_file, "--data", *paths, "--expect", "irradiancemeter", "--radius", radius,
                     "--out", tmp_path / "meter") == 0
    metrics = json.loads((tmp_path / "meter" / "metrics.json").read_text())
    assert metrics["agrees"] is False and metrics["expected"]["agrees"] is True
    assert metrics["expected"]["scale"] == 0.25
    assert metrics["expected"]["offset_opl"] == pytest.approx(offset, rel=1e-15)
    assert "with the stated convention" in (tmp_path / "meter" / "report.md").read_text()
    assert run_check(scene_file, "--data", *paths, "--expect-scale", 0.25, "--expect-offset", offset,
                     "--out", tmp_path / "numbers") == 0
    # as given, a sphere of another radius, or data of another scale, is not the stated convention
    data = np.stack(data)
    assert check_transient(scene, data, expect=irradiancemeter(scene, radius)).verdict      # as the command
    assert not check_transient(scene, data).verdict
    assert not check_transient(scene, data, expect=irradiancemeter(scene, radius / 3)).verdict
    assert not check_transient(scene, data, expect=Convention(scale=0.26, offset_opl=offset, name="x")).verdict


def test_the_irradiancemeter_convention_refuses_a_sphere_that_reaches_the_plane(scene):
    from validation.check import irradiancemeter

    with pytest.raises(ValueError, match=r"radius: must lie in \(0, 0.8\) m"):
        irradiancemeter(scene, 0.8)
    meter = irradiancemeter(scene, 1e-3)
    assert (meter.scale, meter.offset_opl) == (0.25, 2e-3 / 3 + 1500 * 2.0**-24)
