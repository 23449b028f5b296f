"""What a capture can tell: Cramér-Rao bounds on the image and on free parameters (docs/design.md section 9).

For data y(f, θ) = A f (+ the geometry's θ) under the scene's noise or
detector, the Fisher information is F = Jᵀ diag(w) J with J = [A, ∂y/∂θ]
and w the samples' own information (:mod:`analytic.measurement.fisher`).
Any unbiased estimate of a component uᵀ(f, θ) has variance at least
uᵀ F⁻¹ u; with free parameters the image's block of F⁻¹ is the inverse of
the Schur complement F_ff − F_fθ F_θθ⁻¹ F_θf, so the image's bound includes
what not knowing θ costs.

F is never formed (that would square its condition number): the whitened
J̃ = diag(√w) J is factored by a thin SVD, J̃ = U S Vᵀ, and the bound of
coordinate i is ‖(V S⁻¹)[i]‖ over the singular values above the numerical
threshold s_1 max(rows, columns) ε (numpy's ``matrix_rank`` rule). A
coordinate with a component in the numerical null space (the squared norm
of its projection on it above :data:`NULL_TOLERANCE`) cannot be estimated
without bias at all: its bound is inf (every pixel is so when the image
has more pixels than the data have independent samples, as in the letter's
50 x 50 image from 16 x 12 samples: there the prior, not the data, sets
most of the image).

Samples with infinite information (σ = 0, or a photon-counting bin that
expects no photons) fix their rows' combinations exactly: the bound is the
limit of finite information, computed in the null space of those rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse

from ..errors import ResourceError
from ..measurement.fisher import describe_measurement, measurement_of, sample_weights

__all__ = ["Bounds", "crb", "information_bounds", "NULL_TOLERANCE", "DEFAULT_MEMORY_LIMIT"]

#: A coordinate whose unit vector has a squared component above this in the numerical null space is unbounded.
NULL_TOLERANCE = np.sqrt(np.finfo(float).eps)
#: Bytes the dense whitened Jacobian and its SVD may use.
DEFAULT_MEMORY_LIMIT = 2 * 2**30


@dataclass(frozen=True)
class Bounds:
    """The Cramér-Rao bounds of a scene (:func:`crb`).

    Attributes
    ----------
    image : numpy.ndarray
        ``(M, M)`` each pixel's bound on the standard deviation of an unbiased estimate, units of
        reflectance; inf where the data cannot fix the pixel.
    parameters : dict
        ``{key: {"value": θ, "bound": standard deviation}}`` of each free parameter, in its units
        (inf when not identifiable).
    singular_values : numpy.ndarray
        Of the whitened A (√w A over the samples of finite information), descending.
    effective_rank : int
        Singular values of the whitened A above 1, plus the components fixed exactly (``exact_rank``).
    numerical_rank : int
        Components of (image, parameters) the data fix at all (above the numerical threshold).
    exact_rank : int
        Components fixed exactly by samples of infinite information (0 for noise of finite σ).
    unknowns : int
        M².
    measurement : str
        The noise or detector model in words.
    free : tuple of str
        The free parameters' keys.
    """

    image: np.ndarray
    parameters: dict
    singular_values: np.ndarray
    effective_rank: int
    numerical_rank: int
    exact_rank: int
    unknowns: int
    measurement: str
    free: tuple = field(default=())

    @property
    def unbounded_pixels(self) -> int:
        """Pixels the data cannot fix (bound inf)."""
        return int(np.count_nonzero(~np.isfinite(self.image)))

    @property
    def above_one(self) -> np.ndarray:
        """The whitened A's singular values above 1: the image components that stand above the noise."""
        return self.singular_values[self.singular_values > 1.0]

    def summary(self) -> str:
        """One line: what the data fix, and the bound's median over the pixels they fix."""
        finite = self.image[np.isfinite(self.image)]
        median = f"median bound {np.median(finite):.4g} over the {finite.size} fixed pixels" if finite.size \
            else "no pixel is fixed"
        return (f"the data fix {self.effective_rank} of the image's {self.unknowns} components above the noise "
                f"(singular values of the whitened A above 1; {self.numerical_rank} at all); "
                f"{self.unbounded_pixels} pixels unbounded (inf); {median}")

    def as_dict(self) -> dict:
        """crb.json's content (inf becomes null on writing: ``identifiable`` says it)."""
        return {
            "measurement": self.measurement, "unknowns": self.unknowns, "pixels": int(self.image.shape[0]),
            "effective_rank": self.effective_rank, "numerical_rank": self.numerical_rank,
            "exact_rank": self.exact_rank, "unbounded_pixels": self.unbounded_pixels,
            "median_bound": (float(np.median(self.image[np.isfinite(self.image)]))
                             if self.unbounded_pixels < self.image.size else None),
            "singular_values_above_one": self.above_one.tolist(),
            "singular_values": self.singular_values.tolist(),
            "parameters": {key: {**entry, "identifiable": bool(np.isfinite(entry["bound"]))}
                           for key, entry in self.parameters.items()},
            "free": list(self.free),
            "bound": "standard deviation of an unbiased estimate (Cramér-Rao), per pixel in crb.npy; "
                     "inf (null here) where the data cannot fix it",
        }


def _threshold(values: np.ndarray, shape) -> float:
    return float(values[0]) * max(shape) * np.finfo(float).eps if values.size else 0.0


def information_bounds(jacobian, weights) -> dict:
    """Cramér-Rao bounds of every coordinate of θ from J = ∂y/∂θ and the samples' information w.

    Parameters
    ----------
    jacobian : array_like or scipy.sparse array
        ``(rows, P)``.
    weights : array_like
        ``(rows,)`` information of each sample about its own y (>= 0, inf allowed).

    Returns
    -------
    dict
        ``bounds`` (P,) standard deviations (inf for a coordinate with a null-space component),
        ``singular_values`` of the whitened finite rows (after removing exactly fixed components),
        ``rank`` (numerical, including ``exact_rank``), ``exact_rank``.
    """
    dense = jacobian.toarray() if scipy.sparse.issparse(jacobian) else np.asarray(jacobian, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64).ravel()
    seen = np.any(dense != 0, axis=1)
    hard = seen & np.isinf(weights)
    soft = seen & np.isfinite(weights) & (weights > 0)
    columns = dense.shape[1]
    basis = None                     # orthonormal basis of what the exact rows leave free
    exact_rank = 0
    if np.any(hard):
        _, values, vt = np.linalg.svd(dense[hard], full_matrices=True)
        exact_rank = int(np.sum(values > _threshold(values, dense[hard].shape)))
        basis = vt[exact_rank:].T
    whitened = np.sqrt(weights[soft])[:, None] * dense[soft]
    reduced = whitened if basis is None else whitened @ basis
    shape = reduced.shape                                 # the threshold's max(rows, columns)
    if reduced.shape[0] > reduced.shape[1]:
        # a tall J̃ has the singular values and right vectors of its R factor: no (rows x P) U to form
        reduced = np.linalg.qr(reduced, mode="r")
    if reduced.size:
        _, values, vt = np.linalg.svd(reduced, full_matrices=False)
    else:
        values, vt = np.zeros(0), np.zeros((0, reduced.shape[1]))
    rank = int(np.sum(values > _threshold(values, shape))) if values.size and values[0] > 0 else 0
    right = vt[:rank].T                                   # (free dimensions, rank)
    scaled = right / values[:rank]
    if basis is not None:
        right, scaled = basis @ right, basis @ scaled
    variance = np.sum(scaled**2, axis=1)
    # the unit vector's squared component outside what the data fix (exactly or with noise)
    inside = (np.ones(columns) if basis is None else np.sum(basis**2, axis=1))
    outside = inside - np.sum(right**2, axis=1)
    bounds = np.where(outside > NULL_TOLERANCE, np.inf, np.sqrt(variance))
    return {"bounds": bounds, "singular_values": values, "rank": rank + exact_rank, "exact_rank": exact_rank}


def crb(scene, free=(), *, matrix=None, measurement: str = "auto",
        memory_limit: int = DEFAULT_MEMORY_LIMIT) -> Bounds:
    """Cramér-Rao bounds of the image (and of free parameters) under the scene's noise or detector.

    Parameters
    ----------
    scene : Scene, RelayWallScene, str or Path
        The scene (its reflectance is the true image the bound is taken at: a Poisson or counting
        bound depends on it).
    free : sequence of str
        Parameter keys of docs/design.md section 9 estimated with the image (nuisances).
    matrix : scipy.sparse array, optional
        The scene's A, when the caller has it.
    measurement : {"auto", "noise", "detector"}
        Which table the data carry (``auto``: the ``[detector]``'s counts when the scene has one).
    memory_limit : int
        Bytes the dense whitened Jacobian and its SVD may use.

    Returns
    -------
    Bounds

    Raises
    ------
    SceneError
        No ``[noise]`` or ``[detector]`` (exact data have no bound), or a bad parameter key (OptionError).
    ResourceError
        The dense SVD needs more than ``memory_limit``.
    """
    from ..operator.derivatives import jacobian
    from ..operator.parameters import parameters, value_of
    from ..operator.system import system_matrix
    from ..operator.matrix_free import forward
    from ..scenes.scene_file import scene_of

    scene = scene_of(scene)
    model = measurement_of(scene, measurement)
    free = (free,) if isinstance(free, str) else tuple(free)
    items = parameters(scene, list(free)) if free else []
    unknowns = scene.pixels**2
    rows = scene.sensor_count * scene.sampling.count
    needed = 3 * rows * (unknowns + len(items)) * 8
    if needed > memory_limit:
        raise ResourceError(f"the bound's dense SVD of a {rows} x {unknowns + len(items)} Jacobian needs "
                            f"{needed / 2**30:.2f} GiB, over {memory_limit / 2**30:.2f} GiB; use fewer pixels or bins")
    matrix = system_matrix(scene) if matrix is None else matrix
    y = forward(scene, matrix)
    weights = sample_weights(y, model).ravel()
    dense = matrix.toarray() if scipy.sparse.issparse(matrix) else np.asarray(matrix, dtype=np.float64)
    if items:
        columns = jacobian(scene, [item.key for item in items]).reshape(rows, len(items))
        dense = np.hstack([dense, columns])
    full = information_bounds(dense, weights)
    image_only = full if not items else information_bounds(dense[:, :unknowns], weights)
    parameters_out = {item.key: {"value": float(value_of(scene, item)), "bound": float(bound)}
                      for item, bound in zip(items, full["bounds"][unknowns:])}
    values = image_only["singular_values"]
    return Bounds(image=full["bounds"][:unknowns].reshape(scene.pixels, scene.pixels),
                  parameters=parameters_out, singular_values=values,
                  effective_rank=int(np.sum(values > 1.0)) + image_only["exact_rank"],
                  numerical_rank=full["rank"], exact_rank=full["exact_rank"], unknowns=unknowns,
                  measurement=describe_measurement(model), free=tuple(item.key for item in items))
