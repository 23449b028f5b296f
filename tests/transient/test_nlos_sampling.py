"""The relay-wall plugin's points: Owen-scrambled Sobol sets and the texture's density, against independent checks."""

import numpy as np
import pytest


@pytest.fixture(scope="module")
def sampling(mitsuba):
    import transient.nlos_sampling as sampling

    return sampling


def _points(sampling, mitsuba, count, seed_u, seed_v, jitter=0.0):
    index = mitsuba.UInt32(np.arange(count))
    u, v = sampling.owen_sobol_point(index, mitsuba.UInt32(seed_u), mitsuba.UInt32(seed_v),
                                     mitsuba.Float64(np.full(count, jitter)), mitsuba.Float64(np.full(count, jitter)))
    return np.array(u), np.array(v)


def test_reverse_bits_against_python(sampling, mitsuba):
    values = np.random.default_rng(1).integers(0, 2**32, 1000, dtype=np.uint64)
    expected = [int(f"{int(v):032b}"[::-1], 2) for v in values]
    assert np.array_equal(np.array(sampling.reverse_bits(mitsuba.UInt32(values.astype(np.uint32)))), expected)


def test_unscrambled_points_are_scipys_sobol_set(sampling, mitsuba):
    """The first 2^10 points (van der Corput, Sobol's second dimension) are SciPy's Sobol points as a set
    (SciPy visits them in Gray-code order)."""
    from scipy.stats import qmc

    index = mitsuba.UInt32(np.arange(2**10))
    ours = np.stack([np.array(sampling.reverse_bits(index)), np.array(sampling.sobol_second(index))], axis=1)
    theirs = np.rint(qmc.Sobol(2, scramble=False, bits=32).random_base2(10) * 2**32).astype(np.int64)
    assert {tuple(p) for p in ours.astype(np.int64)} == {tuple(p) for p in theirs}


@pytest.mark.parametrize("seeds", [(0, 0), (123456789, 987654321), (2**32 - 1, 7)])
def test_scrambled_sets_are_nets(sampling, mitsuba, seeds):
    """Every 2^m prefix is a (0, m, 2)-net: each of the 2^m boxes 2^-k x 2^-(m-k) holds exactly one point."""
    for m in (4, 7, 10):
        u, v = _points(sampling, mitsuba, 2**m, *seeds, jitter=0.5)
        for k in range(m + 1):
            boxes = np.floor(u * 2**k).astype(np.int64) * 2 ** (m - k) + np.floor(v * 2 ** (m - k)).astype(np.int64)
            assert np.array_equal(np.sort(boxes), np.arange(2**m)), (m, k)


def test_each_point_is_uniform_over_scrambles(sampling, mitsuba):
    """Point 5 over 40000 scrambles (seeds from a fixed stream): χ² over a 16 x 16 grid within 5 σ of its dof.
    Without the seed's addition (a fixed scramble) every draw is the same point and the test fails."""
    rng = np.random.default_rng(8)
    draws = 40000
    seeds = rng.integers(0, 2**32, (2, draws), dtype=np.uint64).astype(np.uint32)
    index = mitsuba.UInt32(np.full(draws, 5, dtype=np.uint32))
    jitter = mitsuba.Float64(rng.random(draws)), mitsuba.Float64(rng.random(draws))
    u, v = (np.array(c) for c in sampling.owen_sobol_point(index, mitsuba.UInt32(seeds[0]), mitsuba.UInt32(seeds[1]),
                                                           *jitter))
    assert 0.0 <= u.min() and u.max() < 1.0 and 0.0 <= v.min() and v.max() < 1.0
    counts = np.histogram2d(u, v, bins=16, range=[[0, 1], [0, 1]])[0]
    expected = draws / 256
    chi2 = float(np.sum((counts - expected) ** 2 / expected))
    assert abs(chi2 - 255) < 5 * np.sqrt(2 * 255), chi2


def _texture():
    texture = np.random.default_rng(3).uniform(0.0, 1.0, (6, 5))
    texture[1, 2] = 0.0                  # a black texel keeps the floor's share
    return texture


def test_texture_density_follows_the_texture(sampling, mitsuba):
    """A fine grid of unit-square points lands on each texel in proportion to ρ + 1 % of the mean ρ, the
    density returned is that share over the texel's area, and each point lies inside its texel."""
    texture, area = _texture(), 0.6
    density = sampling.PixelDensity(texture, area)
    side = 600
    grid = (np.arange(side) + 0.5) / side
    u, v = (c.ravel() for c in np.meshgrid(grid, grid))
    su, sv, p = (np.array(c) for c in density.sample(mitsuba.Float64(u), mitsuba.Float64(v)))
    weights = texture + sampling.FLOOR * texture.mean()
    share = weights / weights.sum()
    rows, columns = np.floor(sv * 6).astype(int), np.floor(su * 5).astype(int)
    counts = np.zeros((6, 5))
    np.add.at(counts, (rows, columns), 1.0)
    assert np.allclose(counts / side**2, share, atol=2.0 / side)       # the grid's discretisation
    assert np.allclose(p, share[rows, columns] * 30 / area, rtol=1e-12)


def test_texture_density_estimates_an_integral_without_bias(sampling, mitsuba):
    """E[f / p] over the density's points is ∫ f, f = e^{2u} (1 + v²) on the unit square (closed form), within
    4 standard errors; a density that forgets its floor (the black texel's points weighted as if it had none)
    is off by far more."""
    texture = _texture()
    density = sampling.PixelDensity(texture, 1.0)
    rng = np.random.default_rng(4)
    count = 400000
    su, sv, p = (np.array(c) for c in density.sample(mitsuba.Float64(rng.random(count)),
                                                     mitsuba.Float64(rng.random(count))))
    values = np.exp(2 * su) * (1 + sv**2) / p
    exact = (np.exp(2) - 1) / 2 * (4 / 3)
    error = values.std(ddof=1) / np.sqrt(count)
    assert abs(values.mean() - exact) < 4 * error
    # the density without the floor's share (renormalised): the black texel's points now weigh nothing
    share = texture / texture.sum()
    rows, columns = np.minimum((sv * 6).astype(int), 5), np.minimum((su * 5).astype(int), 4)
    wrong = np.where(share[rows, columns] > 0, np.exp(2 * su) * (1 + sv**2) / np.maximum(share[rows, columns] * 30,
                                                                                        1e-300), 0.0)
    assert abs(wrong.mean() - exact) > 10 * error
