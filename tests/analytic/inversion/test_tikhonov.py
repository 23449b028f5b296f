"""The two Tikhonov routes (SVD, LSQR) against dense least squares; argument checks; rank deficiency."""

import numpy as np
import pytest

from analytic.inversion import RankDeficiencyWarning, reconstruct
from analytic.scenes.common import Sampling, Scene, sensor_grid
from analytic.operator.system import system_matrix
from dense_reference import dense_solution, synthetic_problem


@pytest.fixture(scope="module")
def small_scene():
    """A well-posed scene: M = 8, a 6 x 6 array of extent 2 m, 2 cm bins."""
    pixels = 8
    x, y = np.meshgrid((np.arange(pixels) + 0.5) / pixels, (np.arange(pixels) + 0.5) / pixels)
    image = 0.4 + 0.2 * np.cos(np.pi * x) * np.sin(np.pi * y) + 0.1 * x
    scene = Scene(pixels=pixels, reflectance=image, source=(0.5, 0.5, 1.0),
                  sensors=sensor_grid((6, 6), 2.0, (0.5, 0.5, 1.0)),
                  sampling=Sampling(bin_width_opl=0.02, start_opl=1.9, count=100), name="small")
    return scene, system_matrix(scene)



@pytest.mark.parametrize("lam", [1e-8, 1e-3, 1.0, 1e3])
def test_svd_solver_equals_dense_stacked_least_squares(rng, lam):
    matrix, y, _ = synthetic_problem(rng, rows=30)  # 30 rows for 36 unknowns: rank-deficient
    result = reconstruct(matrix, y, 6, rule=lam, method="svd")
    # fewer independent measurements than unknowns is the method, stated (not warned about)
    assert result.rank == 30 and not result.warnings
    reference = dense_solution(matrix, y, 6, lam)
    assert np.max(np.abs(result.image.ravel() - reference)) <= 1e-8 * np.max(np.abs(reference))
    assert result.residual_norm == pytest.approx(np.linalg.norm(matrix @ reference - y), rel=1e-8)


def test_both_solvers_agree_on_a_scene_matrix(small_scene, rng):
    scene, matrix = small_scene
    y = matrix @ scene.reflectance.ravel() + 1e-4 * rng.standard_normal(matrix.shape[0])
    lam = 1e-9
    svd = reconstruct(matrix, y, scene.pixels, rule=lam, method="svd")
    lsqr = reconstruct(matrix, y, scene.pixels, rule=lam, method="lsqr")
    reference = dense_solution(matrix.toarray(), y, scene.pixels, lam)
    assert np.max(np.abs(svd.image.ravel() - reference)) < 1e-8 * np.max(np.abs(reference))
    assert np.max(np.abs(lsqr.image.ravel() - reference)) < 1e-6 * np.max(np.abs(reference))


def test_smooth_image_is_recovered_exactly_from_noiseless_well_posed_data(small_scene):
    scene, matrix = small_scene
    y = matrix @ scene.reflectance.ravel()
    result = reconstruct(matrix, y, scene.pixels, rule=1e-16)
    assert result.rank == scene.pixels**2  # 3600 rows, full column rank: no warning
    assert np.max(np.abs(result.image - scene.reflectance)) < 1e-6


def test_rule_arguments_are_validated(rng):
    matrix, y, _ = synthetic_problem(rng)
    with pytest.raises(ValueError, match="truth"):
        reconstruct(matrix, y, 6, rule="oracle")
    with pytest.raises(ValueError, match="sigma"):
        reconstruct(matrix, y, 6, rule="discrepancy")
    with pytest.raises(ValueError, match="rule"):
        reconstruct(matrix, y, 6, rule="best")
    with pytest.raises(ValueError, match="rule"):
        reconstruct(matrix, y, 6, rule=-1.0)
    with pytest.raises(ValueError, match="method"):
        reconstruct(matrix, y, 6, method="cholesky")
    with pytest.raises(ValueError, match="data"):
        reconstruct(matrix, y[:-1], 6)


def test_collinear_sensors_warn_and_give_the_mirror_symmetric_answer(rng):
    # Source and sensors on the line y = 0.5: an image and its mirror across
    # that line give the same data, so A is rank-deficient, and the unique
    # regularised answer (the Laplacian is mirror-invariant) is mirror-symmetric.
    pixels = 10
    sensors = [(x, 0.5, 1.0) for x in (0.1, 0.3, 0.7, 0.9)]
    scene = Scene(pixels=pixels, reflectance=rng.random((pixels, pixels)), source=(0.5, 0.5, 1.0),
                  sensors=sensors, sampling=Sampling(bin_width_opl=0.02, start_opl=1.9, count=80))
    matrix = system_matrix(scene)
    # A's entries are accurate to its tolerance, so mirror columns agree only to
    # ~1e-7; average them to give the exact symmetry this test is about
    mirror = np.arange(pixels * pixels).reshape(pixels, pixels)[::-1].ravel()
    matrix = 0.5 * (matrix + matrix[:, mirror])
    y = matrix @ scene.reflectance.ravel() + 1e-3 * rng.standard_normal(matrix.shape[0])
    with pytest.warns(RankDeficiencyWarning, match="repeat one another"):
        svd = reconstruct(matrix, y, pixels, rule="gcv", method="svd")
    assert svd.rank <= pixels * (pixels // 2)  # at most the mirror-symmetric images
    # lsqr sees the numerical rank only from A's singular values, which σ asks for; without σ it does not
    # warn, and it still returns the same answer
    lsqr = reconstruct(matrix, y, pixels, rule=svd.lam, method="lsqr")
    assert lsqr.rank is None and not lsqr.warnings
    with pytest.warns(RankDeficiencyWarning, match="repeat one another"):
        assert reconstruct(matrix, y, pixels, rule=svd.lam, method="lsqr", sigma=1e-3).rank == svd.rank
    for result in (svd, lsqr):
        assert np.all(np.isfinite(result.image))
        assert np.allclose(result.image, np.flipud(result.image),
                           atol=1e-6 * np.abs(result.image).max())
    assert np.allclose(lsqr.image, svd.image, atol=1e-5 * np.abs(svd.image).max())
    few = reconstruct(matrix[:60], y[:60], pixels, rule=1e-6, method="lsqr")
    assert np.all(np.isfinite(few.image))


# σ grows with y while A stays: at the large powers no singular value of A stands above σ (the data fix none
# of the image's numbers at unit scale), which is warned about; the scaling is what is tested here
@pytest.mark.filterwarnings("ignore::analytic.inversion.NoiseLimitWarning")
@pytest.mark.parametrize("power", [-480, -100, 0, 100, 480])
@pytest.mark.parametrize("rule", ["gcv", "lcurve", "discrepancy", "oracle", 1e-6])
def test_data_of_any_representable_magnitude_scale_the_answer_exactly(small_scene, rng, power, rule):
    """y -> 2^p y gives 2^p times the image and the same λ, for every rule: powers of two scale exactly."""
    scene, matrix = small_scene
    noise = 1e-3 * rng.standard_normal(matrix.shape[0])
    y = matrix @ scene.reflectance.ravel() + noise
    factor = 2.0**power
    base = reconstruct(matrix, y, scene.pixels, rule=rule, truth=scene.reflectance, sigma=1e-3)
    scaled = reconstruct(matrix, factor * y, scene.pixels, rule=rule, truth=factor * scene.reflectance,
                         sigma=factor * 1e-3)
    assert np.array_equal(scaled.image, factor * base.image)
    assert scaled.lam == base.lam
    if rule == 1e-6:
        assert np.all(np.isnan(scaled.criterion))                     # a given λ has no criterion
    else:
        assert np.all(np.isfinite(scaled.criterion))


@pytest.mark.parametrize("power", [-520, 520])
def test_data_whose_squares_float64_cannot_hold_are_refused(small_scene, power):
    from analytic.errors import DataError

    scene, matrix = small_scene
    y = matrix @ scene.reflectance.ravel()
    with pytest.raises(DataError, match=r"data: largest \|y\|"):
        reconstruct(matrix, 2.0**power * y, scene.pixels, rule="gcv")
    sign = 1 if power > 0 else -1                      # y and A each within range, y / A not
    with pytest.raises(DataError, match="the image would be of order"):
        reconstruct(2.0**(-450 * sign) * matrix, 2.0**(100 * sign) * y, scene.pixels, rule="gcv")


@pytest.mark.filterwarnings("ignore::analytic.inversion.RankDeficiencyWarning",
                            "ignore::analytic.inversion.RegularizationWarning")
@pytest.mark.parametrize("rule", ["gcv", "lcurve", "oracle", 1.0])
@pytest.mark.parametrize("method", ["svd", "lsqr"])
def test_data_that_see_only_the_mean_give_the_flat_image(rule, method):
    """Every row sums the whole image (each sensor's light in one bin): only the mean is seen, and the
    Laplacian-regularised answer is the constant image with the least-squares sum, for every λ."""
    pixels, weight = 4, 0.25
    matrix = np.full((6, pixels * pixels), weight)
    y = np.array([1.0, 1.1, 0.9, 1.05, 0.95, 1.0])
    result = reconstruct(matrix, y, pixels, rule=rule, method=method, truth=np.full((pixels, pixels), 0.2))
    expected = y.mean() / (weight * pixels * pixels)
    assert np.allclose(result.image, expected, rtol=1e-9, atol=0)


def test_the_memory_limit_holds_for_an_explicit_svd(small_scene, rng):
    """memory_limit: "svd" beyond it is refused naming the need; "auto" falls back to lsqr."""
    from analytic.errors import ResourceError

    scene, matrix = small_scene
    y = matrix @ scene.reflectance.ravel()
    need = 3 * matrix.shape[0] * scene.pixels**2 * 8
    with pytest.raises(ResourceError, match="method svd"):
        reconstruct(matrix, y, scene.pixels, rule=1e-6, method="svd", memory_limit=need - 1)
    assert reconstruct(matrix, y, scene.pixels, rule=1e-6, memory_limit=need - 1).method == "lsqr"
    assert reconstruct(matrix, y, scene.pixels, rule=1e-6, memory_limit=need).method == "svd"
