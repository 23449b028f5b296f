"""How many numbers of the image the data fix: the counts every reconstruction reports, against references
built independently of the code (known singular values, the dense influence matrix), and when it warns."""

import numpy as np
import pytest

from analytic.inversion import NoiseLimitWarning, RankDeficiencyWarning, reconstruct
from dense_reference import stencil_laplacian


def known_spectrum(rng, singular_values, *, rows, pixels=6):
    """A dense (rows, M²) A with the given singular values, and data of a smooth image."""
    n = pixels * pixels
    k = len(singular_values)
    u, _ = np.linalg.qr(rng.standard_normal((rows, k)))
    v, _ = np.linalg.qr(rng.standard_normal((n, k)))
    matrix = u @ np.diag(singular_values) @ v.T
    x, y = np.meshgrid(np.linspace(0, 1, pixels), np.linspace(0, 1, pixels))
    return matrix, matrix @ (0.5 + 0.3 * np.sin(2 * x) * np.cos(3 * y)).ravel()


@pytest.mark.parametrize("power", [-300, 0, 300])
@pytest.mark.parametrize("method", ["svd", "lsqr", "tv"])
def test_the_effective_rank_counts_the_singular_values_above_sigma(rng, method, power):
    """36 unknowns, 60 rows, singular values 10^(2 - k/7): those above σ = 10^-1.5 number 25 (k < 24.5); the
    count is the same for any scale of A and y together (σ in the units of y, the image unchanged)."""
    values = 10.0 ** (2 - np.arange(36) / 7)
    sigma = 10.0**-1.5
    expected = int(np.sum(values > sigma))
    assert expected == 25
    matrix, y = known_spectrum(rng, values, rows=60)
    factor = 2.0**power
    # λ scales as A y (TV) or A² (Laplacian): factor² keeps the same problem
    options = ({"regularizer": "tv", "rule": 10.0 * factor**2} if method == "tv"
               else {"method": method, "rule": 1e-3 * factor**2})
    result = reconstruct(factor * matrix, factor * y, 6, sigma=factor * sigma, **options)
    assert result.effective_rank == expected
    assert result.rank == 36 and result.sigma == factor * sigma
    assert not result.warnings                       # 25 of 36 stand above the noise: nothing to act on
    assert reconstruct(matrix, y, 6, rule=1e-3).effective_rank is None      # no σ, no count


def test_the_degrees_of_freedom_are_the_trace_of_the_dense_influence_matrix(rng):
    values = 10.0 ** (1 - np.arange(30) / 10)
    matrix, y = known_spectrum(rng, values, rows=30)
    stencil = stencil_laplacian(6)
    for lam in (1e-4, 1e-1, 10.0):
        influence = matrix @ np.linalg.solve(matrix.T @ matrix + lam * stencil.T @ stencil, matrix.T)
        result = reconstruct(matrix, y, 6, rule=lam, method="svd")
        assert result.degrees_of_freedom == pytest.approx(np.trace(influence), rel=1e-8)
        assert 1.0 <= result.degrees_of_freedom <= 30.0
    assert reconstruct(matrix, y, 6, rule=1e-3, method="lsqr").degrees_of_freedom is None


@pytest.mark.parametrize("method", ["svd", "lsqr", "tv"])
def test_noise_that_hides_most_of_what_a_measures_is_warned_about(rng, method):
    """Full rank (36 of 36): at a σ where 14 singular values stand above it the data fix 14, under half, and
    the warning says so; at one where 19 do, they fix more than half and nothing is warned."""
    values = 10.0 ** (2 - np.arange(36) / 7)
    matrix, y = known_spectrum(rng, values, rows=60)
    options = {"regularizer": "tv", "rule": 10.0} if method == "tv" else {"method": method, "rule": 1e-3}
    with pytest.warns(NoiseLimitWarning, match=r"fix about 14 of the image's 36 numbers .* half of the 36"):
        hidden = reconstruct(matrix, y, 6, sigma=10.0 ** (2 - 13.5 / 7), **options)
    assert hidden.effective_rank == 14 and any("fix about 14" in text for text in hidden.warnings)
    assert reconstruct(matrix, y, 6, sigma=10.0 ** (2 - 18.5 / 7), **options).effective_rank == 19


def test_fewer_measurements_than_unknowns_is_stated_not_warned_about(rng):
    """The letter's set-up: fewer rows than pixels, each row independent (20 for 36). The data fix 20 numbers
    (stated in the result); at a noise that keeps 15 of them, still no warning: the prior fills the rest by
    design. At a noise that keeps 8 (under half of 20) the noise is warned about."""
    values = 10.0 ** (1 - np.arange(20) / 5)
    matrix, y = known_spectrum(rng, values, rows=20)
    quiet = reconstruct(matrix, y, 6, rule="gcv", sigma=10.0 ** (1 - 14.5 / 5))
    assert (quiet.rank, quiet.effective_rank, quiet.warnings) == (20, 15, ())
    with pytest.warns(NoiseLimitWarning, match="fix about 8 of the image's 36 numbers"):
        reconstruct(matrix, y, 6, rule="gcv", sigma=10.0 ** (1 - 7.5 / 5))


@pytest.mark.parametrize("method", ["svd", "lsqr"])
def test_pixels_no_measurement_sees_are_warned_about_by_every_route(rng, method):
    matrix, y = known_spectrum(rng, 10.0 ** (-np.arange(36) / 10), rows=60)
    matrix[:, 7] = 0.0                       # pixel (1, 1) is in no row
    with pytest.warns(RankDeficiencyWarning, match="1 of 36 pixels are seen by no measurement"):
        reconstruct(matrix, y, 6, rule=1e-6, method=method)


def test_a_bad_sigma_is_refused_for_every_rule(rng):
    matrix, y = known_spectrum(rng, np.ones(36), rows=40)
    for sigma in (0.0, -1.0, np.nan, np.inf):
        for rule in ("gcv", 1.0):
            with pytest.raises(ValueError, match="sigma"):
                reconstruct(matrix, y, 6, rule=rule, sigma=sigma)
