"""The agreement test of DESIGN.md section 6 on synthetic data with known truth."""

import numpy as np
import pytest

from validation.compare import assert_transients_agree, compare_transients


def _synthetic(rng, shape=(4, 50)):
    model = rng.uniform(1.0, 2.0, size=shape)
    stderr = rng.uniform(0.01, 0.02, size=shape)
    return model, stderr


def test_pure_noise_fails_at_the_stated_false_alarm_rate(rng):
    model, stderr = _synthetic(rng, (2, 25))
    alpha, trials = 0.05, 4000
    failures = sum(not compare_transients(model + stderr * rng.standard_normal(model.shape), stderr, model,
                                          false_alarm=alpha).agrees for _ in range(trials))
    # the two tests split α; their union is a little under α
    spread = 4 * np.sqrt(trials * alpha * (1 - alpha))
    assert 0.6 * alpha * trials - spread <= failures <= alpha * trials + spread


def test_a_single_biased_bin_is_found(rng):
    model, stderr = _synthetic(rng)
    rendered = model + stderr * rng.standard_normal(model.shape)
    rendered[2, 17] += 8 * stderr[2, 17]
    result = compare_transients(rendered, stderr, model)
    assert not result.agrees and result.worst[0][:2] == (2, 17)
    with pytest.raises(AssertionError, match="sensor 2, bin 17"):
        assert_transients_agree(rendered, stderr, model)


def test_a_small_global_scale_error_is_found_by_chi2(rng):
    model, stderr = _synthetic(rng, (16, 400))
    rendered = model + stderr * rng.standard_normal(model.shape)
    wrong = model * (1 + 0.5 * stderr / model)           # half a standard error everywhere
    result = compare_transients(rendered, stderr, wrong)
    assert not result.agrees and result.max_abs_z < result.z_threshold
    assert result.chi2_per_dof > result.chi2_interval[1]
    assert compare_transients(rendered, stderr, model).agrees


def test_light_in_unsampled_bins_is_a_disagreement(rng):
    model, stderr = _synthetic(rng)
    rendered = model + stderr * rng.standard_normal(model.shape)
    stderr[1, 3] = 0.0
    rendered[1, 3] = 0.0
    result = compare_transients(rendered, stderr, model)
    assert not result.agrees and result.unsampled_light[0][:2] == (1, 3)
