"""A applied by FFT over pixel offsets (analytic.operator.offset_operator) against the sparse A of the same capture.

The sparse A is assembled independently of the FFT (analytic.operator.system, held to the QUADPACK reference
in tests/analytic/test_offsets.py); the operator's products, adjoint, pattern and scale must equal it to
rounding, and a reconstruction through it must equal the one through A.
"""

import numpy as np
import pytest

from analytic.inversion import reconstruct
from analytic.operator.offset_operator import OffsetOperator, capture_operator
from analytic.operator.system import system_matrix
from analytic.operator.window import pairs_range
from analytic.scenes.common import Sampling
from analytic.scenes.relay_wall import RelayWallScene, Scan

#: one group (a pixel per scan pitch), four (half a pixel per pitch: 2 x 2 sub-pixel places), and an
#: off-centre, non-square rectangle with the laser and the sensor apart (1 and 3 pixels per pitch)
CASES = {
    "whole pixels": dict(pixels=8, grid=(8, 8)),
    "half pixels": dict(pixels=4, grid=(16, 16)),
    "off centre": dict(pixels=6, grid=(16, 8), center=(0.3125, -0.125, 0.7), u=(0.75, 0.0, 0.0),
                       v=(0.0, -0.5, 0.0), laser_position=(0.4, 0.3, 0.5), sensor_position=(-0.6, 0.1, 0.3)),
}


def _scene(pixels, grid, count=40, type="confocal", **changes):
    image = np.arange(pixels * pixels, dtype=float).reshape(pixels, pixels) / (pixels * pixels)   # asymmetric
    scene = RelayWallScene(pixels=pixels, reflectance=image, scan=Scan(type=type, grid=grid),
                           wall_reflectance=0.8, intensity=3.0, **changes)
    low, high = pairs_range(*scene.geometry())
    period = (high - low) * 1.05 / (count - 2)
    return scene.replace(sampling=Sampling(bin_width_opl=period, start_opl=low - period, count=count))


@pytest.mark.parametrize("case", list(CASES))
def test_the_fft_products_equal_the_sparse_a_of_the_same_capture(case, rng):
    scene = _scene(**CASES[case])
    matrix = system_matrix(scene).tocsr()
    operator = capture_operator(scene)
    assert isinstance(operator, OffsetOperator) and operator.shape == matrix.shape
    for _ in range(3):
        f, r = rng.standard_normal(matrix.shape[1]), rng.standard_normal(matrix.shape[0])
        y = matrix @ f
        x = matrix.T @ r
        assert np.max(np.abs(operator @ f - y)) <= 1e-13 * np.max(np.abs(y))
        assert np.max(np.abs(operator.T @ r - x)) <= 1e-13 * np.max(np.abs(x))
    assert operator.nnz == matrix.nnz
    assert np.array_equal(operator.toarray(), matrix.toarray())
    assert operator.largest_entry == pytest.approx(np.max(np.abs(matrix.data)), rel=1e-15)
    rows, columns = operator.row_and_column_seen()
    assert np.array_equal(rows, np.diff(matrix.indptr) > 0)
    assert np.array_equal(columns, np.bincount(matrix.indices, minlength=matrix.shape[1]) > 0)
    half = operator.scaled(2.0)
    f = rng.standard_normal(matrix.shape[1])
    assert np.max(np.abs(half @ f - matrix @ f / 2)) <= 1e-13 * np.max(np.abs(matrix @ f))


def test_a_capture_the_offsets_cannot_serve_gives_no_operator():
    # one laser point: no two pairs are translates of each other
    scene = _scene(pixels=4, grid=(4, 4), type="single")
    assert capture_operator(scene) is None


def _noisy(case, rng):
    """(scene, sparse A, operator, y with noise of σ, σ = 1e-3 of the brightest sample)."""
    scene = _scene(**CASES[case])
    matrix = system_matrix(scene)
    clean = matrix @ scene.reflectance.ravel()
    sigma = 1e-3 * np.max(clean)
    return scene, matrix, capture_operator(scene), clean + sigma * rng.standard_normal(clean.size), sigma


def test_reconstructing_through_the_operator_equals_reconstructing_through_a(rng):
    scene, matrix, operator, y, sigma = _noisy("off centre", rng)
    by_a = reconstruct(matrix, y, scene.pixels, rule=1e-3 * np.max(matrix.data) ** 2, method="lsqr")
    by_operator = reconstruct(operator, y, scene.pixels, rule=by_a.lam, method="lsqr")
    assert np.max(np.abs(by_operator.image - by_a.image)) <= 1e-8 * np.max(np.abs(by_a.image))
    svd = reconstruct(operator, y, scene.pixels, rule="discrepancy", sigma=sigma, method="svd")
    reference = reconstruct(matrix, y, scene.pixels, rule="discrepancy", sigma=sigma, method="svd")
    assert svd.lam == pytest.approx(reference.lam, rel=1e-8)
    assert svd.rank == reference.rank and svd.effective_rank == reference.effective_rank


def test_solves_through_the_operator_stopped_by_the_noise_stay_within_their_margin(rng):
    # with σ known the operator's solves run preconditioned (analytic.inversion.iterative): each must still leave
    # a stacked residual within κ σ² √(2m) of the exact (svd) one, and the discrepancy search must land on m σ²
    from analytic.inversion.iterative import CROSSING_FRACTION, NOISE_FRACTION

    scene, matrix, operator, y, sigma = _noisy("whole pixels", rng)
    margin = NOISE_FRACTION * sigma**2 * np.sqrt(2 * y.size)
    for lam in (1e-2, 1e-4, 1e-6):
        lam = lam * np.max(matrix.data) ** 2
        exact = reconstruct(matrix, y, scene.pixels, rule=lam, method="svd")
        stopped = reconstruct(operator, y, scene.pixels, rule=lam, method="lsqr", sigma=sigma)
        floor = exact.residual_norm**2 + lam * exact.seminorm**2
        assert -1e-9 * floor <= stopped.residual_norm**2 + lam * stopped.seminorm**2 - floor <= margin
    searched = reconstruct(operator, y, scene.pixels, rule="discrepancy", sigma=sigma, method="lsqr")
    assert not searched.warnings
    assert abs(searched.residual_norm**2 - y.size * sigma**2) <= CROSSING_FRACTION * sigma**2 * np.sqrt(2 * y.size)
