"""validation.check.verdict: data consistent with the model agree as given, by their standard error, replicas
or shape; too little to fit is judged without a fit; what cannot be judged is refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from analytic.errors import DataError
from analytic.operator.matrix_free import forward
from check_cases import noisy_replicas, one_bin_scene
from transient.render import render
from validation.check import check_transient
from validation.check.verdict import _agreement

# Synthetic replicas are few (6) and independent from bin to bin: the limits' fallback to independent
# bins, and its warning, are what tests/validation/test_compare.py tests; here they are expected.
pytestmark = pytest.mark.filterwarnings("ignore::validation.judging.compare.CorrelationWarning")


def test_data_without_convention_errors_agree_as_given(scene, model, rng):
    result = check_transient(scene, noisy_replicas(model, rng), model=model)
    assert result.agrees and result.agrees_after_fit
    assert abs(result.fit.scale - 1) < 3 * result.fit.scale_stderr
    assert abs(result.fit.offset_opl) < 3 * result.fit.offset_stderr
    assert result.diagnosis.startswith("agrees as given")


def test_one_transient_with_its_standard_error(scene, model, rng):
    sigma = 0.01 * model + 1e-4 * model.max()
    data = 0.5 * model + 0.5 * sigma * rng.standard_normal(model.shape)
    result = check_transient(scene, data, stderr=0.5 * sigma, model=model)
    assert result.judged_by == "stderr" and result.dof is None and result.fit.stderr_from == "bins"
    assert not result.agrees and result.agrees_after_fit
    assert abs(result.fit.scale - 0.5) < 3 * result.fit.scale_stderr
    assert "y scaled by" in result.diagnosis


def test_shape_only_judgement_says_so(scene, model):
    result = check_transient(scene, 0.25 * model, shape_only=True, model=model)
    assert result.judged_by == "shape" and result.chi2_per_dof is None
    assert not result.agrees and result.agrees_after_fit
    assert result.relative_l2 == pytest.approx(0.75) and result.relative_l2_after_fit < 1e-6
    assert result.diagnosis.startswith("judged by shape only")
    assert "1/4 of the fluence" in result.diagnosis


def test_student_t_scores_keep_their_tail_probability(scene, model):
    """z from R replicas maps to the normal z with the same tail: Φ⁻¹ of F_t, by scipy directly."""
    stderr = np.full(model.shape, 1e-4)
    t_scores = np.linspace(-6, 6, model.size).reshape(model.shape)
    data = model + t_scores * stderr
    agreement = _agreement(data, stderr, model, 3, 1e-3)
    judged = np.isfinite(agreement.z)
    expected = np.sign(t_scores) * stats.norm.isf(stats.t.sf(np.abs(t_scores), 3))
    assert judged.sum() > 10
    assert np.allclose(agreement.z[judged], expected[judged], rtol=1e-9, atol=1e-12)
    gaussian = _agreement(data, stderr, model, None, 1e-3)
    assert np.allclose(gaussian.z[judged], t_scores[judged])


def test_our_render_passes_with_no_fit_needed(scene, model):
    replicas = np.array([render(scene, spp=2**19, seed=seed, progress=False).mean for seed in range(6)])
    result = check_transient(scene, replicas, model=model)
    assert result.agrees and result.agrees_after_fit, result.summary()
    assert abs(result.fit.scale - 1) < 3 * result.fit.scale_stderr
    assert abs(result.fit.offset_opl) < 3 * result.fit.offset_stderr
    single = render(scene, spp=2**20, seed=11, progress=False)
    result = check_transient(scene, single.mean, stderr=single.stderr, model=model)
    assert result.agrees, result.summary()


def test_a_single_transient_without_errors_is_refused(scene, model):
    with pytest.raises(DataError, match="without errors"):
        check_transient(scene, model, model=model)
    with pytest.raises(DataError, match="replicas carry their own error"):
        check_transient(scene, np.stack([model] * 3), stderr=np.ones_like(model), model=model)
    with pytest.raises(DataError, match="at least 3"):
        check_transient(scene, np.stack([model, model]), model=model)
    with pytest.raises(DataError, match="shape"):
        check_transient(scene, model[:, :-1], shape_only=True, model=model)
    with pytest.raises(DataError, match="NaN"):
        check_transient(scene, np.full_like(model, np.nan), shape_only=True, model=model)


def test_a_one_bin_scene_is_judged_as_given_without_a_fit(rng):
    scene = one_bin_scene()
    model = forward(scene)
    result = check_transient(scene, noisy_replicas(model, rng), model=model)
    assert result.agrees and result.fit is None and result.agrees_after_fit is None
    assert result.diagnosis == ("agrees as given; no scale or time offset fitted: the scene's 1 bin(s) cannot "
                                "fit them (two parameters need at least 3 bins).")
    metrics = result.as_dict()
    assert metrics["fit"] is None and metrics["agrees_after_fit"] is None and "cannot fit" in metrics["fit_skipped"]
    wrong = check_transient(scene, noisy_replicas(1.1 * model, rng), model=model)
    assert not wrong.agrees and wrong.diagnosis.startswith("disagrees as given; no scale")
    shape = check_transient(scene, model, shape_only=True, model=model)
    assert shape.agrees and shape.fit is None and "cannot fit" in shape.diagnosis


def test_too_few_precise_bins_are_judged_without_a_fit(scene, model, rng):
    """Two bins precise enough to judge: judged as given, and the sentence says why nothing was fitted."""
    sigma = np.where(model > 0, model, 1.0)        # 100 % errors: nothing judged ...
    sigma[0, 10:12] = 1e-3 * model[0, 10:12]       # ... but two bins
    result = check_transient(scene, model + 0.1 * sigma * rng.standard_normal(model.shape), stderr=sigma,
                             model=model)
    assert result.as_given.bins == 2 and result.fit is None
    assert "only 2 bin(s) have a standard error under 0.1 of their value" in result.diagnosis


def test_zero_errors_are_named_for_what_they_are(scene, model):
    with pytest.raises(DataError, match="standard errors are all zero"):
        check_transient(scene, model, stderr=np.zeros_like(model), model=model)
    with pytest.raises(DataError, match="replicas are equal in every bin"):
        check_transient(scene, np.stack([model] * 4), model=model)
    with pytest.raises(DataError, match="too noisy to judge; render more samples"):
        check_transient(scene, model, stderr=np.abs(model) + 1.0, model=model)


def test_a_standard_error_too_small_to_square_is_refused(scene, model):
    """stderr 1e-300 next to y ~ 1e-3: z ~ 1e297 squares to infinity, and the fit's SVD failed with a
    LinAlgError traceback; now one DataError."""
    with pytest.raises(DataError, match="standard error under 1e-100 of the largest"):
        check_transient(scene, model, stderr=np.full_like(model, 1e-300 * model.max()), model=model)


def test_data_closer_to_the_model_than_their_errors_allow_are_named_so(scene, model):
    """The model itself given with a standard error: χ²/dof = 0 is refused (below the accept interval), and
    the diagnosis says why, not 'a different model, scene or a bug?'."""
    result = check_transient(scene, model, stderr=0.01 * model + 1e-4 * model.max(), model=model)
    assert not result.agrees and result.chi2_per_dof == 0.0
    assert "below its accept interval" in result.diagnosis and "bug" not in result.diagnosis
