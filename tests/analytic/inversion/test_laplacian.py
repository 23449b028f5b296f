"""The Neumann Laplacian against its stencil written out pixel by pixel."""

import numpy as np

from analytic.inversion import dct2, idct2, laplacian_eigenvalues, neumann_laplacian
from dense_reference import stencil_laplacian


def test_neumann_laplacian_is_the_reflecting_stencil_and_the_dct_diagonalises_it(rng):
    pixels = 7
    stencil = stencil_laplacian(pixels)
    assert np.array_equal(neumann_laplacian(pixels).toarray(), stencil)
    assert np.allclose(stencil @ np.ones(pixels**2), 0.0)  # constants are its null space
    assert np.linalg.matrix_rank(stencil) == pixels**2 - 1
    image = rng.random((pixels, pixels))
    spectral = idct2(-laplacian_eigenvalues(pixels) * dct2(image))
    assert np.allclose(spectral.ravel(), stencil @ image.ravel(), atol=1e-13)
    assert np.allclose(np.sort(laplacian_eigenvalues(pixels).ravel()),
                       np.sort(-np.linalg.eigvalsh(stencil)), atol=1e-12)
