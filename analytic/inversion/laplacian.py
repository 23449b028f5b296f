"""The 5-point discrete Laplacian on the M x M pixel grid, reflecting boundaries.

Boundary handling: Neumann ("reflecting", half-sample symmetric). A ghost
pixel outside the image copies its mirror image inside it, f[-1] = f[0] and
f[M] = f[M-1], so a boundary pixel's stencil loses the term across the
boundary. In one dimension the second difference is then

    L1 = [[-1,  1,          ],
          [ 1, -2,  1,      ],
          [      ...        ],
          [          1, -1  ]]

and the 2-D operator is D = L1 ⊗ I + I ⊗ L1 (unit pixel spacing: the 1/Δ²
factor is absorbed into λ). D is symmetric, its null space is exactly the
constant images, and the orthonormal 2-D DCT-II diagonalises it:

    D = C diag(-μ) Cᵀ,   μ_ij = (2 - 2 cos(π i / M)) + (2 - 2 cos(π j / M)),

with C the orthonormal inverse DCT-II (``scipy.fft.idctn(..., norm="ortho")``)
and Cᵀ the forward one (``scipy.fft.dctn(..., norm="ortho")``).
"""

from __future__ import annotations

import numpy as np
import scipy.fft
import scipy.sparse

__all__ = ["neumann_laplacian", "laplacian_eigenvalues", "dct2", "idct2"]


def _second_difference(pixels: int) -> scipy.sparse.csr_array:
    if pixels == 1:
        return scipy.sparse.csr_array((1, 1), dtype=np.float64)
    main = np.full(pixels, -2.0)
    main[0] = main[-1] = -1.0  # the mirrored ghost pixel cancels one neighbour term
    off = np.ones(pixels - 1)
    return scipy.sparse.diags_array([off, main, off], offsets=[-1, 0, 1], format="csr")


def neumann_laplacian(pixels: int) -> scipy.sparse.csr_array:
    """The 5-point Laplacian D with reflecting boundaries, as a sparse matrix.

    Parameters
    ----------
    pixels : int
        Image side M.

    Returns
    -------
    scipy.sparse.csr_array
        ``(M², M²)`` float64, acting on ``image.ravel()`` (column r M + c);
        unit pixel spacing, so its entries are dimensionless.

    Notes
    -----
    (D f)[r, c] = f[r-1, c] + f[r+1, c] + f[r, c-1] + f[r, c+1] - 4 f[r, c],
    with every neighbour outside the image replaced by f[r, c] itself
    (Neumann boundary). D · 1 = 0.
    """
    if int(pixels) != pixels or pixels < 1:
        raise ValueError(f"pixels: expected a positive whole number, got {pixels!r}")
    pixels = int(pixels)
    second = _second_difference(pixels)
    identity = scipy.sparse.eye_array(pixels, format="csr")
    return (scipy.sparse.kron(second, identity) + scipy.sparse.kron(identity, second)).tocsr()


def laplacian_eigenvalues(pixels: int) -> np.ndarray:
    """Eigenvalues μ_ij of -D, arranged like the DCT coefficients.

    Parameters
    ----------
    pixels : int
        Image side M.

    Returns
    -------
    numpy.ndarray
        ``(M, M)`` float64, μ[i, j] = (2 - 2 cos(π i / M)) + (2 - 2 cos(π j / M));
        μ[0, 0] = 0 (the constant image), every other entry > 0.
    """
    if int(pixels) != pixels or pixels < 1:
        raise ValueError(f"pixels: expected a positive whole number, got {pixels!r}")
    one = 2.0 - 2.0 * np.cos(np.pi * np.arange(int(pixels)) / pixels)
    return one[:, None] + one[None, :]


def dct2(image: np.ndarray) -> np.ndarray:
    """Orthonormal 2-D DCT-II over the last two axes (Cᵀ f)."""
    return scipy.fft.dctn(image, type=2, norm="ortho", axes=(-2, -1))


def idct2(coefficients: np.ndarray) -> np.ndarray:
    """Orthonormal inverse 2-D DCT-II over the last two axes (C c)."""
    return scipy.fft.idctn(coefficients, type=2, norm="ortho", axes=(-2, -1))
