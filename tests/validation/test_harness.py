"""The cross-check harness: passes the right model, fails deliberately wrong ones, reports every figure."""

import re

import numpy as np
import pytest

from analytic.operator.matrix_free import forward
from transient.render import render
from validation.judging.compare import compare_transients
from analytic.operator.response import binned_contour_model
from validation.runs.harness import check_scene, data_driven_rule, imaging_problem
from validation.runs.suite import hard_cases, validation_suite

SPP = dict((scene.name, spp) for scene, spp in validation_suite())["outside"]   # the suite's count


@pytest.fixture(scope="module")
def outside():
    """A suite scene (sensor outside the plane's footprint) rendered at the suite's sample count."""
    scene = hard_cases(pixels=10)["outside"]
    return scene, render(scene, spp=SPP, seed=0, progress=False)



def test_right_model_passes(outside):
    scene, result = outside
    assert compare_transients(result.mean, result.stderr, forward(scene)).agrees
    assert compare_transients(result.mean, result.stderr, forward(scene), replicas=result.replica_means).agrees



def test_contour_form_with_coarea_factor_is_the_model(outside):
    """Binning g_k(t) (contour form with 1/|∇d|) reproduces A f: the harness's wrong-model
    builder is right when the factor is in."""
    scene, _ = outside
    model = forward(scene)
    # fixed composite Gauss-Legendre across the kinks of g (pixel corners): ~1e-3
    np.testing.assert_allclose(binned_contour_model(scene), model, atol=2e-3 * model.max())



@pytest.mark.parametrize("wrong", ["no coarea factor", "half-bin shift", "missing cos θ_k"])
def test_wrong_models_fail(outside, wrong):
    scene, result = outside
    model = forward(scene)
    if wrong == "no coarea factor":
        reference = binned_contour_model(scene, coarea=False)
        reference *= np.linalg.norm(model) / np.linalg.norm(reference)   # shape only: same total
    elif wrong == "half-bin shift":
        sampling = scene.sampling
        reference = forward(scene.replace(sampling=sampling.__class__(
            bin_width_opl=sampling.bin_width_opl, start_opl=sampling.start_opl + sampling.bin_width_opl / 2, count=sampling.count)))
    else:
        reference = forward(scene.replace(attenuation="paper")) / np.pi
        reference *= np.linalg.norm(model) / np.linalg.norm(reference)  # shape only
    assert not compare_transients(result.mean, result.stderr, reference).agrees
    # the replicas' own limits keep the power to see it
    assert not compare_transients(result.mean, result.stderr, reference, replicas=result.replica_means).agrees



def test_check_scene_reports_every_figure():
    scene = hard_cases(pixels=6)["colocated"]
    # a second sensor beside the colocated one: one sensor's transient cannot be reconstructed (skipped, below)
    assert check_scene(scene, spp=2**12, seed=1, convergence=False).metrics["reconstruction"] == {
        "skipped": imaging_problem(scene)}
    scene = scene.replace(sensors=np.vstack([scene.sensors, [[0.3, 0.6, 0.5]]]))
    check = check_scene(scene, spp=2**20, seed=1)
    assert check.agreement.agrees
    # judged with the render's replicas: limits that hold whatever the correlation between bins
    assert check.agreement.null == "sign-flip" and check.metrics["agreement"]["null"] == "sign-flip"
    metrics = check.metrics
    assert metrics["window_share"] == pytest.approx(1.0)
    assert metrics["model_convergence"][-1]["over_stderr"] < 1e-2    # model ≪ noise
    # stratified replicas: between N^-1/2 (no stratification gain) and N^-1 (smooth integrand)
    assert -1.05 < metrics["render_slope"] < -0.45
    costs = metrics["simplifications"]
    assert costs["paper_attenuation"] > 0.5 and costs["no_coarea_factor"] > 0.01
    recon = metrics["reconstruction"]
    assert recon["rule"] == "gcv" and recon["noise"] is None      # the scene is noiseless: GCV
    for key in ("model", "render"):
        assert set(recon[key]) == {"psnr", "ssim", "lambda", "degrees_of_freedom", "warnings"}
        assert np.isfinite(recon[key]["psnr"])
    assert np.isfinite(recon["oracle"]["psnr"]) and np.isfinite(recon["flat_psnr"])


def test_data_driven_rule_uses_sigma_when_the_scene_knows_it():
    from analytic.errors import SceneError
    from analytic.scenes.common import Noise, default_scene

    assert data_driven_rule(default_scene()) == ("discrepancy", 0.1)
    assert data_driven_rule(default_scene(noise=None)) == ("gcv", None)
    assert data_driven_rule(default_scene(noise=Noise(kind="poisson"))) == ("gcv", None)
    assert data_driven_rule(default_scene(), "lcurve") == ("lcurve", None)
    with pytest.raises(SceneError, match="noise.sigma"):
        data_driven_rule(default_scene(noise=None), "discrepancy")


def test_a_render_more_precise_than_the_scenes_tolerance_is_judged_against_a_tighter_model():
    """A 1 mm hidden square renders to ~1e-12 of its value: judged against the 1e-6 model it failed (χ²/dof 240)."""
    from analytic.scenes.relay_wall import RelayWallScene, Scan
    from analytic.scenes.common import Sampling

    scene = RelayWallScene(name="tiny", pixels=1, reflectance=0.5, center=(0.0, 0.0, 1.0), u=(0.001, 0.0, 0.0),
                           v=(0.0, -0.001, 0.0), scan=Scan(type="single", grid=(2, 2)),
                           sampling=Sampling(bin_width_opl=0.01, start_opl=2.22, count=1))
    check = check_scene(scene, spp=2**14, seed=3, convergence=False, reconstruction=False)
    assert np.max(check.stderr / check.render) < 1e-8        # the case: far under the scene's tolerance
    assert check.agreement.agrees, check.summary()
    assert check.metrics["model_tolerance"] < scene.tolerance
    assert "tighter than the scene's" in check.summary()


def test_check_scene_takes_a_scene_file_and_states_what_it_can_detect(tmp_path):
    """A path is a scene here too; the verdict tests the render's scale and offset and states its power."""
    import scene_files
    from check_cases import small_scene

    check = check_scene(scene_files.write_scene_file(tmp_path, small_scene()), spp=2**16, convergence=False,
                        reconstruction=False)
    assert check.agreement.agrees and check.agreement.directed.agrees
    assert 0 < check.metrics["detectable"]["scale"] < 0.01 and check.metrics["detectable"]["shift_opl"] > 0


@pytest.mark.parametrize("call, words", [
    (lambda: check_scene(hard_cases(pixels=4)["outside"], spp=-3), "spp: must be in [2, 2^48]"),
    (lambda: check_scene(hard_cases(pixels=4)["outside"], spp="many"), "spp: must be an integer"),
    (lambda: check_scene(hard_cases(pixels=4)["outside"], spp=2**12, seed=-1), "seed: must be an integer"),
    (lambda: check_scene(42, spp=2**12), "scene: expected a Scene"),
    (lambda: __import__("validation").check_corner(mitransient_samples="x"), "mitransient_samples: must be"),
])
def test_a_bad_argument_is_the_librarys_one_line_error(call, words):
    from analytic.errors import OptionError

    with pytest.raises(OptionError, match=re.escape(words)):
        call()
