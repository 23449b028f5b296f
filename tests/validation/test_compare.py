"""The agreement test of DESIGN.md section 6 on synthetic data with known truth."""

import numpy as np
import pytest
from scipy import stats

from validation.compare import assert_transients_agree, combined_dof, compare_transients, normal_scores


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


# -- Student t: errors from R replicas -----------------------------------------------


def _replica_trial(rng, model, spread, replicas):
    """Mean of R normal replica means around the model, and its standard error from their spread."""
    means = model + spread * rng.standard_normal((replicas,) + model.shape)
    return means.mean(axis=0), means.std(axis=0, ddof=1) / np.sqrt(replicas)


@pytest.mark.parametrize("replicas", [4, 32])
def test_replica_errors_keep_the_stated_false_alarm_rate(rng, replicas):
    """Over many trials, each test fails at its stated rate α/2 when told the degrees of freedom."""
    model = rng.uniform(1.0, 2.0, (2, 25))
    spread = rng.uniform(0.01, 0.05, model.shape)
    alpha, trials = 0.05, 3000
    chi2_fails = max_fails = 0
    pooled = []
    for _ in range(trials):
        mean, stderr = _replica_trial(rng, model, spread, replicas)
        result = compare_transients(mean, stderr, model, dof=replicas - 1, false_alarm=alpha,
                                    max_relative_stderr=1.0)
        chi2_fails += not (result.chi2_interval[0] <= result.chi2_per_dof <= result.chi2_interval[1])
        max_fails += result.max_abs_z > result.z_threshold
        pooled.append(result.z.ravel())
    spread_count = 4 * np.sqrt(trials * alpha / 2)
    assert abs(chi2_fails - trials * alpha / 2) < spread_count, chi2_fails
    assert abs(max_fails - trials * alpha / 2) < spread_count, max_fails
    # the normal scores are standard normal
    assert stats.kstest(np.concatenate(pooled), "norm").pvalue > 1e-3


def test_ignoring_the_degrees_of_freedom_raises_false_alarms(rng):
    """The same replica errors judged as if normal fail far more often than stated: dof matters."""
    model = rng.uniform(1.0, 2.0, (2, 25))
    spread = np.full(model.shape, 0.02)
    alpha, trials = 0.05, 1000
    fails = sum(not compare_transients(*_replica_trial(rng, model, spread, 4), model, false_alarm=alpha,
                                       max_relative_stderr=1.0).agrees for _ in range(trials))
    assert fails > 4 * alpha * trials


def test_replica_errors_still_find_a_biased_bin(rng):
    model = rng.uniform(1.0, 2.0, (4, 50))
    mean, stderr = _replica_trial(rng, model, 0.01 * model, 32)
    mean[1, 7] += 12 * stderr[1, 7]
    result = compare_transients(mean, stderr, model, dof=31)
    assert not result.agrees and result.worst[0][:2] == (1, 7)
    assert result.dof == 31 and "31 degrees of freedom" in result.summary()


def test_normal_scores_match_the_t_tail_far_out():
    t = np.array([-40.0, -3.0, 0.0, 2.5, 1e3])
    z = normal_scores(t, 5)
    np.testing.assert_allclose(stats.norm.sf(np.abs(z)), stats.t.sf(np.abs(t), 5), rtol=1e-9)
    assert np.all(np.sign(z) == np.sign(t)) and np.isfinite(z).all()
    np.testing.assert_array_equal(normal_scores(t, np.inf), t)


def test_combined_degrees_of_freedom():
    # equal errors and dof: twice the dof; one normal side dominates
    assert combined_dof(1.0, 10, 1.0, 10) == pytest.approx(20.0)
    assert combined_dof(1.0, 10, 0.0, 10) == pytest.approx(10.0)
    assert combined_dof(1e-3, 3, 1.0, np.inf) > 1e6


def test_real_renders_keep_the_stated_false_alarm_rate():
    """Many seeds of a cheap scene against the exact model: failures at about the stated rate."""
    from analytic.scene import Sampling, Scene
    from analytic.system import forward
    from transient.render import render

    scene = Scene(size=1.0, pixels=4, reflectance=np.random.default_rng(5).uniform(0.2, 0.9, (4, 4)),
                  source=(0.4, 0.5, 0.6), sensors=[(0.7, 0.2, 0.5)],
                  sampling=Sampling(bin_width_opl=0.06, start_opl=1.0, count=20))
    model = forward(scene)
    alpha, trials = 0.1, 200
    fails, pooled = 0, []
    for seed in range(trials):
        result = render(scene, spp=2**14, seed=seed, progress=False)
        agreement = compare_transients(result.mean, result.stderr, model, dof=result.dof, false_alarm=alpha)
        fails += not agreement.agrees
        pooled.append(agreement.z[np.isfinite(agreement.z)])
    pooled = np.concatenate(pooled)
    assert fails <= alpha * trials + 3 * np.sqrt(trials * alpha), fails
    assert abs(np.mean(np.abs(pooled) > 2) - 2 * stats.norm.sf(2)) < 0.01
    assert stats.kstest(pooled, "norm").pvalue > 1e-3
