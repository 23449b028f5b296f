"""Cramér-Rao bounds (analytic.inversion.bounds) against independent computations.

- Gaussian, full rank: σ sqrt(diag((AᵀA)⁻¹)) with A from tests/reference.py's adaptive quadrature (no code of
  the model), and the spread of least-squares estimates over noise draws (an efficient unbiased estimator);
- rank deficient: inf exactly where the image has a component in the null space of an SVD of our own;
- Poisson: the closed form F = p Aᵀ diag(1/y) A; a first-photon (dead time) detector: the multinomial's Fisher
  information from finite differences of its cell probabilities, and the spread of maximum-likelihood estimates;
- nuisances: the Schur complement, from the inverse of the full Fisher matrix.
"""

import math
import warnings

import numpy as np
import pytest
import scipy.optimize
from reference import bin_kernel, pixel_box, pixel_entry

from analytic.errors import SceneError
from analytic.inversion.bounds import crb, information_bounds
from analytic.measurement.detector import Detector, detection_probabilities, draw_counts
from analytic.operator.system import QuadratureWarning, system_matrix
from analytic.operator.matrix_free import forward
from analytic.scenes.common import Illumination, Noise, Sampling, default_scene

SIGMA = 0.05


def _scene(pixels, sensors, *, count=8, start=2.0, period=0.1, noise=None, **changes):
    return default_scene(pixels=pixels, reflectance=np.full((pixels, pixels), 0.5), sensors=sensors,
                         intensity=10.0, illumination=Illumination(waveform="impulse"),
                         sampling=Sampling(bin_width_opl=period, start_opl=start, count=count),
                         noise=Noise(kind="gaussian", sigma=SIGMA) if noise is None else noise, **changes)


SPREAD = ((0.1, 0.2, 0.9), (0.85, 0.3, 1.1), (0.4, 0.95, 0.8))


@pytest.mark.slow           # the adaptive reference: ~30 s
def test_gaussian_bound_against_quadrature():
    scene = _scene(2, SPREAD)
    reference = np.zeros((len(SPREAD) * scene.sampling.count, 4))
    for row in range(reference.shape[0]):
        k, n = divmod(row, scene.sampling.count)
        kernel, breakpoints = bin_kernel(scene.illumination, scene.sampling.start_opl,
                                         scene.sampling.bin_width_opl, n)
        for pixel in range(4):
            reference[row, pixel] = scene.intensity * pixel_entry(
                pixel_box(scene.size, scene.pixels, pixel), scene.source, scene.sensors[k], kernel, breakpoints,
                epsrel=1e-7)
    expected = SIGMA * np.sqrt(np.diag(np.linalg.inv(reference.T @ reference)))
    bounds = crb(scene)
    assert np.linalg.matrix_rank(reference) == 4
    np.testing.assert_allclose(bounds.image.ravel(), expected, rtol=1e-4)
    assert bounds.unbounded_pixels == 0 and bounds.numerical_rank == 4


def test_gaussian_bound_is_the_spread_of_least_squares(rng):
    scene = _scene(3, SPREAD + ((0.5, 0.1, 1.2),), count=10, start=1.9)
    matrix = system_matrix(scene).toarray()
    bounds = crb(scene, matrix=matrix)
    truth = scene.reflectance.ravel()
    draws = 4000
    data = matrix @ truth + SIGMA * rng.standard_normal((draws, matrix.shape[0]))
    estimates = np.linalg.lstsq(matrix, data.T, rcond=None)[0].T
    spread = estimates.std(axis=0, ddof=1)
    # the sample standard deviation's relative standard error is 1/sqrt(2 (n - 1))
    assert np.all(np.abs(spread / bounds.image.ravel() - 1) < 5 / math.sqrt(2 * (draws - 1)))
    assert np.all(np.abs(estimates.mean(axis=0) - truth) < 5 * spread / math.sqrt(draws))   # unbiased


def test_rank_deficient_bound_is_inf_exactly_on_the_null_space():
    # source and sensors on the line x = L/2: an image and its mirror in x give the same data
    scene = _scene(3, ((0.5, 0.1, 0.9), (0.5, 0.8, 1.1), (0.5, 0.4, 0.7)), count=10, start=1.6)
    matrix = system_matrix(scene).toarray()
    bounds = crb(scene, matrix=matrix)
    _, values, vt = np.linalg.svd(matrix / SIGMA)
    rank = int(np.sum(values > values[0] * max(matrix.shape) * np.finfo(float).eps))
    null = vt[rank:]
    in_null = np.sum(null**2, axis=0) > 1e-8
    assert 0 < rank < 9 and bounds.numerical_rank == rank
    np.testing.assert_array_equal(~np.isfinite(bounds.image.ravel()), in_null)
    assert not in_null.reshape(3, 3)[:, 1].any() and in_null.reshape(3, 3)[:, 0].all()   # the mirror's axis
    pseudo = SIGMA * np.sqrt(np.diag(np.linalg.pinv(matrix.T @ matrix, rcond=1e-12)))
    np.testing.assert_allclose(bounds.image.ravel()[~in_null], pseudo[~in_null], rtol=1e-6)


def test_effective_rank_counts_whitened_singular_values_above_one():
    scene = _scene(3, SPREAD, count=10, start=1.9, noise=Noise(kind="gaussian", sigma=2.0))
    matrix = system_matrix(scene).toarray()
    bounds = crb(scene, matrix=matrix)
    values = np.linalg.svd(matrix / 2.0, compute_uv=False)
    np.testing.assert_allclose(bounds.singular_values[:values.size], values, rtol=1e-10)
    assert bounds.effective_rank == int(np.sum(values > 1.0)) < bounds.numerical_rank


def test_poisson_bound_is_the_closed_form():
    photons = 30.0
    scene = _scene(2, SPREAD, count=10, start=1.9, noise=Noise(kind="poisson", photons=photons))
    matrix = system_matrix(scene).toarray()
    y = matrix @ scene.reflectance.ravel()
    live = y > 0
    fisher = photons * (matrix[live].T / y[live]) @ matrix[live]
    np.testing.assert_allclose(crb(scene, matrix=matrix).image.ravel(), np.sqrt(np.diag(np.linalg.inv(fisher))),
                               rtol=1e-8)


def test_a_bin_expecting_no_photons_fixes_its_combination_exactly():
    # infinite information on rows with y = 0 is the limit of a vanishing background
    matrix = np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 2.0]])
    weights = np.array([np.inf, 4.0, 1.0])
    limit = information_bounds(matrix, np.array([1e12, 4.0, 1.0]))["bounds"]
    exact = information_bounds(matrix, weights)
    np.testing.assert_allclose(exact["bounds"], limit, rtol=1e-5, atol=1e-6)
    assert exact["bounds"][0] == 0.0 and exact["exact_rank"] == 1


def _dead_time_scene(pixels, detector):
    return _scene(pixels, SPREAD[:2], count=10, start=1.9, detector=detector)


def test_dead_time_information_is_the_multinomials():
    detector = Detector(photons=1.0, background=1e-3, cycles=1e4, dead_time="cycle")
    scene = _dead_time_scene(2, detector)
    matrix = system_matrix(scene).toarray()
    f = scene.reflectance.ravel()
    rows, count = matrix.shape[0] // scene.sampling.count, scene.sampling.count
    assert detector.photons * (matrix @ f).reshape(rows, count).sum(axis=1).max() > 0.5   # pile-up matters

    def cells(image):      # per sensor: the N bins and "no detection", per cycle
        p, none = detection_probabilities(detector.photons * np.maximum((matrix @ image).reshape(rows, count), 0)
                                          + detector.background)
        return np.concatenate([p, none[:, None]], axis=1).ravel()

    step = 1e-6
    derivative = np.stack([(cells(f + step * e) - cells(f - step * e)) / (2 * step) for e in np.eye(f.size)], 1)
    fisher = detector.cycles * (derivative.T / cells(f)) @ derivative
    np.testing.assert_allclose(crb(scene, matrix=matrix).image.ravel(), np.sqrt(np.diag(np.linalg.inv(fisher))),
                               rtol=1e-5)


def test_dead_time_bound_is_the_spread_of_maximum_likelihood(rng):
    detector = Detector(photons=1.0, background=1e-3, cycles=2e3, dead_time="cycle")
    scene = _dead_time_scene(1, detector)
    column = system_matrix(scene).toarray()[:, 0]
    bound = crb(scene).image[0, 0]
    truth = float(scene.reflectance[0, 0])
    shape = (column.size // scene.sampling.count, scene.sampling.count)

    def negative_log_likelihood(value, counts):
        p, none = detection_probabilities(detector.photons * np.maximum(column * value, 0).reshape(shape)
                                          + detector.background)
        return -(np.sum(counts * np.log(p)) + np.sum((detector.cycles - counts.sum(axis=1)) * np.log(none)))

    draws = 1500
    estimates = np.array([scipy.optimize.minimize_scalar(
        negative_log_likelihood, bounds=(0.05, 1.5), args=(draw_counts((column * truth).reshape(shape), detector, rng=rng),),
        method="bounded", options={"xatol": 1e-9}).x for _ in range(draws)])
    spread = estimates.std(ddof=1)
    assert abs(spread / bound - 1) < 5 / math.sqrt(2 * (draws - 1))
    poisson = crb(scene.replace(detector=Detector(photons=1.0, background=1e-3, cycles=2e3))).image[0, 0]
    assert abs(spread / poisson - 1) > 5 / math.sqrt(2 * (draws - 1))    # pile-up's loss is seen


def test_free_parameters_enter_through_the_schur_complement():
    scene = _scene(2, SPREAD, count=10, start=1.9)
    matrix = system_matrix(scene).toarray()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadratureWarning)       # the differences' tight model
        bounds = crb(scene, ["source.position.z", "sensors.positions.1.x"], matrix=matrix)
        step = 1e-5
        columns = []
        for key, value in (("source.position.z", 1.0), ("sensors.positions.1.x", 0.85)):
            from analytic.operator.parameters import with_values
            up = forward(with_values(scene, {key: value + step}).replace(tolerance=1e-10))
            down = forward(with_values(scene, {key: value - step}).replace(tolerance=1e-10))
            columns.append(((up - down) / (2 * step)).ravel())
    full = np.hstack([matrix, np.stack(columns, 1)])
    covariance = SIGMA**2 * np.linalg.inv(full.T @ full)
    np.testing.assert_allclose(bounds.image.ravel(), np.sqrt(np.diag(covariance)[:4]), rtol=1e-4)
    np.testing.assert_allclose([bounds.parameters[k]["bound"] for k in ("source.position.z", "sensors.positions.1.x")],
                               np.sqrt(np.diag(covariance)[4:]), rtol=1e-4)
    assert np.all(bounds.image.ravel() > crb(scene, matrix=matrix).image.ravel())


def test_a_scale_free_with_the_image_is_not_identifiable():
    # y(s f) = s A f: the image's scale and the reflectance scale are one number
    scene = _scene(2, SPREAD, count=10, start=1.9)
    bounds = crb(scene, ["plane.reflectance"])
    assert math.isinf(bounds.parameters["plane.reflectance"]["bound"]) and bounds.unbounded_pixels == 4


def test_no_noise_is_refused():
    with pytest.raises(SceneError, match=r"noise"):
        crb(_scene(2, SPREAD).replace(noise=None))
