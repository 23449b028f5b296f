"""validation.check: any transient judged against the exact model, its scale and offset fitted.

The references are independent of the code under test: synthetic data made
from the model at a known scale and start offset plus noise of known size
(the fit must find them within its standard errors, and a wrong scene must
stay in disagreement after it), our own Monte Carlo renderer (must agree as
given), and files in every format a user brings (read back to the array
written, or refused with a DataError naming the file).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from analytic.errors import DataError
from analytic.io import build_meta, save_exr, write_transient
from analytic.scene import Sampling, Scene
from analytic.system import forward
from transient.render import render
from validation.check import (_agreement, check_transient, diagnose, read_data, read_stderr,
                              write_check_report)
from validation.cli import main

START, WIDTH, COUNT = 1.7, 0.05, 24

# The synthetic replicas below are few (6) and independent from bin to bin: the limits' fallback to
# independent bins, and its warning, are what test_compare.py tests; here they are expected.
pytestmark = pytest.mark.filterwarnings("ignore::validation.compare.CorrelationWarning")


def small_scene(**changes) -> Scene:
    """4 x 4 asymmetric image, two sensors at different heights, 24 bins around the light."""
    image = np.arange(16, dtype=np.float64).reshape(4, 4) / 20.0
    values = dict(name="small", size=1.0, pixels=4, reflectance=image, source=(0.5, 0.5, 1.0),
                  sensors=[(0.8, 0.3, 1.0), (0.25, 0.7, 0.8)],
                  sampling=Sampling(bin_width_opl=WIDTH, start_opl=START, count=COUNT))
    return Scene(**(values | changes))


def shifted(scene: Scene, offset: float) -> np.ndarray:
    """The model with every bin edge moved by +offset: what data short by `offset` read."""
    sampling = Sampling(bin_width_opl=WIDTH, start_opl=START + offset, count=COUNT)
    return forward(scene.replace(sampling=sampling))


def noisy_replicas(truth: np.ndarray, rng, replicas: int = 6) -> np.ndarray:
    """Independent replicas: truth + Gaussian noise of 1 % of each bin plus a floor."""
    sigma = 0.01 * np.abs(truth) + 1e-4 * np.max(truth)
    return truth + sigma * rng.standard_normal((replicas,) + truth.shape)


@pytest.fixture(scope="module")
def scene():
    return small_scene()


@pytest.fixture(scope="module")
def model(scene):
    return forward(scene)


# ---------------------------------------------------------------- the fit against known truths

def test_known_scale_and_offset_are_recovered(scene, model, rng):
    scale, offset = 0.3, 0.012
    data = noisy_replicas(scale * shifted(scene, offset), rng)
    result = check_transient(scene, data, model=model)
    assert not result.agrees and result.agrees_after_fit
    assert result.judged_by == "replicas" and result.replicas == 6 and result.dof == 5
    fit = result.fit
    assert fit.stderr_from == "replicas" and fit.converged
    assert abs(fit.scale - scale) < 3 * fit.scale_stderr
    assert abs(fit.offset_opl - offset) < 3 * fit.offset_stderr
    assert fit.offset_stderr < 0.05 * offset                      # the test has power
    assert fit.scale_stderr < 0.01 * scale
    assert "path lengths short" in result.diagnosis


def test_the_fits_standard_errors_describe_its_spread(scene, model, rng):
    """The jackknife standard errors that the thresholds above use are neither inflated nor too small:
    over 100 independent data sets the fitted values scatter by about the stated error (the sample
    standard deviation of 100 values is itself known to ~7 %; the bounds allow for that many times)."""
    scales, offsets, scale_errors, offset_errors = [], [], [], []
    for _ in range(100):
        fit = check_transient(scene, noisy_replicas(0.3 * shifted(scene, 0.012), rng), model=model).fit
        scales.append(fit.scale), offsets.append(fit.offset_opl)
        scale_errors.append(fit.scale_stderr), offset_errors.append(fit.offset_stderr)
    for values, errors in ((scales, scale_errors), (offsets, offset_errors)):
        ratio = np.std(values, ddof=1) / np.mean(errors)
        assert 0.5 < ratio < 1.5, ratio


def test_data_without_convention_errors_agree_as_given(scene, model, rng):
    result = check_transient(scene, noisy_replicas(model, rng), model=model)
    assert result.agrees and result.agrees_after_fit
    assert abs(result.fit.scale - 1) < 3 * result.fit.scale_stderr
    assert abs(result.fit.offset_opl) < 3 * result.fit.offset_stderr
    assert result.diagnosis.startswith("agrees as given")


def test_whole_bins_of_offset_are_named(scene, model, rng):
    data = noisy_replicas(shifted(scene, 2 * WIDTH), rng)
    result = check_transient(scene, data, model=model)
    assert result.agrees_after_fit
    assert abs(result.fit.offset_opl - 2 * WIDTH) < 3 * result.fit.offset_stderr
    assert "off by +2 bin(s)" in result.diagnosis


def test_a_wrong_scene_stays_in_disagreement_after_the_fit(scene, model, rng):
    """Light from a sensor 5 cm away is no scale or offset of the right model's."""
    moved = small_scene(sensors=[(0.85, 0.3, 1.0), (0.25, 0.7, 0.8)])
    result = check_transient(scene, noisy_replicas(forward(moved), rng), model=model)
    assert not result.agrees and not result.agrees_after_fit
    assert "not a scale or time-offset convention" in result.diagnosis


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


def test_diagnosis_of_an_irradiancemeter():
    from validation.check import Fit

    fit = Fit(0.2501, 0.0004, 1.55e-4, 0.1e-4, 3, True, "replicas")
    text = diagnose(fit, agrees=False, agrees_after_fit=True, bin_width_opl=0.05)
    assert text == ("agrees after scale 0.2501 ± 0.0004 and offset +1.55e-4 ± 0.10e-4 m: a sensor that "
                    "reads 1/4 of the fluence and path lengths short (an irradiancemeter? --expect "
                    "irradiancemeter states that convention).")


# ---------------------------------------------------------------- our own renderer

def test_our_render_passes_with_no_fit_needed(scene, model):
    replicas = np.array([render(scene, spp=2**19, seed=seed, progress=False).mean for seed in range(6)])
    result = check_transient(scene, replicas, model=model)
    assert result.agrees and result.agrees_after_fit, result.summary()
    assert abs(result.fit.scale - 1) < 3 * result.fit.scale_stderr
    assert abs(result.fit.offset_opl) < 3 * result.fit.offset_stderr
    single = render(scene, spp=2**20, seed=11, progress=False)
    result = check_transient(scene, single.mean, stderr=single.stderr, model=model)
    assert result.agrees, result.summary()


def test_check_command_takes_our_renders_own_errors(tmp_path, scene_file):
    """`check` on our render's folder or transient.npy judges with its replicas.npy (sign flips, Student's
    t on R - 1 degrees of freedom), or without them with its stderr.npy and the render's dof."""
    from analytic.scene_file import load_scene

    assert main(["render", str(scene_file), "--spp", str(2**20), "--seed", "5", "--out", str(tmp_path / "r"),
                 "--quiet"]) == 0
    dof = json.loads((tmp_path / "r" / "meta.json").read_text())["dof"]
    for data in (tmp_path / "r", tmp_path / "r" / "transient.npy"):
        out = tmp_path / f"check_{data.name}"
        assert run_check(scene_file, "--data", data, "--out", out) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["agrees"] is True and metrics["judged_by"] == "replicas" and metrics["dof"] == dof
        assert metrics["null"] == "sign-flip"
    # the same numbers passed by hand
    replicas = np.load(tmp_path / "r" / "replicas.npy")
    from_file = load_scene(scene_file)          # its EXR holds the image in float32
    by_hand = check_transient(from_file, replicas)
    assert by_hand.dof == dof and by_hand.chi2_per_dof == pytest.approx(metrics["chi2_per_dof"], rel=1e-12)
    # without replicas.npy: stderr.npy, with the render's degrees of freedom
    (tmp_path / "r" / "replicas.npy").unlink()
    assert run_check(scene_file, "--data", tmp_path / "r", "--out", tmp_path / "by_stderr") == 0
    metrics = json.loads((tmp_path / "by_stderr" / "metrics.json").read_text())
    assert metrics["judged_by"] == "stderr" and metrics["dof"] == dof and metrics["null"] == "independent"
    mean, stderr = np.load(tmp_path / "r" / "transient.npy"), np.load(tmp_path / "r" / "stderr.npy")
    assert check_transient(from_file, mean, stderr=stderr, dof=dof).chi2_per_dof == pytest.approx(
        metrics["chi2_per_dof"], rel=1e-12)
    assert check_transient(from_file, mean, stderr=stderr).dof is None          # without dof: normal z
    # a bare (K, N) .npy elsewhere still needs --stderr
    np.save(tmp_path / "bare.npy", mean)
    assert run_check(scene_file, "--data", tmp_path / "bare.npy", "--out", tmp_path / "bare") == 2


# ---------------------------------------------------------------- what is refused

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


@pytest.fixture
def files(tmp_path, scene, model):
    """Our forward output folder, and stray arrays in the other formats."""
    out = tmp_path / "forward"
    write_transient(out, model, build_meta(scene, kind="model"))
    return out


def test_our_outputs_are_read_back(files, scene, model):
    assert np.array_equal(read_data(files, scene), model)
    assert np.array_equal(read_data(files / "transient.npy", scene), model)
    assert np.allclose(read_data(files / "transient.exr", scene), model.astype(np.float32), rtol=0, atol=0)


def test_wrong_time_axis_is_refused(tmp_path, scene, model):
    out = tmp_path / "late"
    late = scene.replace(sampling=Sampling(bin_width_opl=WIDTH, start_opl=START + WIDTH, count=COUNT))
    write_transient(out, model, build_meta(late, kind="model"))
    with pytest.raises(DataError, match="time axis"):
        read_data(out / "transient.npy", scene)
    save_exr(tmp_path / "wide.exr", model, {"start_opl": START, "bin_width_opl": 2 * WIDTH})
    with pytest.raises(DataError, match="time axis"):
        read_data(tmp_path / "wide.exr", scene)


def test_wrong_shape_nan_and_unknown_formats_are_refused(tmp_path, scene, model):
    np.save(tmp_path / "short.npy", model[:, :-1])
    with pytest.raises(DataError, match=r"short.npy: shape \(2, 23\) does not match"):
        read_data(tmp_path / "short.npy", scene)
    np.save(tmp_path / "transposed.npy", model.T)
    with pytest.raises(DataError, match="transposed"):
        read_data(tmp_path / "transposed.npy", scene)
    bad = model.copy()
    bad[1, 3] = np.nan
    np.save(tmp_path / "nan.npy", bad)
    with pytest.raises(DataError, match="NaN"):
        read_data(tmp_path / "nan.npy", scene)
    (tmp_path / "data.csv").write_text("1,2\n")
    with pytest.raises(DataError, match="unknown format"):
        read_data(tmp_path / "data.csv", scene)
    with pytest.raises(DataError, match="no such file"):
        read_data(tmp_path / "missing.npy", scene)
    np.save(tmp_path / "negative.npy", -np.ones_like(model))
    with pytest.raises(DataError, match="negative"):
        read_stderr(tmp_path / "negative.npy", scene)


def test_mitransient_film_arrays(tmp_path, scene, model):
    """mitransient's developed film: (height, width, bins, channels) per sensor, stacked per sensor."""
    films = model[:, None, None, :, None].astype(np.float32)            # (K, 1, 1, N, 1)
    np.save(tmp_path / "mono.npy", films)
    assert np.array_equal(read_data(tmp_path / "mono.npy", scene), films[:, 0, 0, :, 0])
    np.save(tmp_path / "rgb.npy", np.repeat(films, 3, axis=-1))
    assert np.array_equal(read_data(tmp_path / "rgb.npy", scene), films[:, 0, 0, :, 0])
    coloured = np.repeat(films, 3, axis=-1)
    coloured[..., 0] *= 2
    np.save(tmp_path / "coloured.npy", coloured)
    with pytest.raises(DataError, match="colour channels differ"):
        read_data(tmp_path / "coloured.npy", scene)
    np.save(tmp_path / "one.npy", films[0])                               # one sensor of two
    with pytest.raises(DataError, match="1 film"):
        read_data(tmp_path / "one.npy", scene)
    np.save(tmp_path / "camera.npy", np.zeros((2, 4, 4, COUNT, 1)))
    with pytest.raises(DataError, match="4 x 4 pixels"):
        read_data(tmp_path / "camera.npy", scene)


def test_mitransient_frame_folder(tmp_path, model):
    """mitransient.vis.save_frames: 000.exr, 001.exr, ... one 1 x 1 image (channel Y) per bin."""
    one = small_scene(sensors=[(0.8, 0.3, 1.0)])
    y = forward(one)
    folder = tmp_path / "frames"
    for n in range(COUNT):
        save_exr(folder / f"{n:03d}.exr", y[:, n].reshape(1, 1))
    assert np.allclose(read_data(folder, one), y.astype(np.float32), rtol=0, atol=0)
    (folder / f"{COUNT:03d}.exr").write_bytes((folder / "000.exr").read_bytes())
    with pytest.raises(DataError, match="shape"):
        read_data(folder, one)


# ---------------------------------------------------------------- the command

def run_check(*argv) -> int:
    return main(["check", *map(str, argv), "--quiet"])


@pytest.fixture
def scene_file(tmp_path):
    image = np.arange(16, dtype=np.float64).reshape(4, 4) / 20.0
    save_exr(tmp_path / "image.exr", image)
    path = tmp_path / "small.toml"
    path.write_text(f"""
[plane]
size = 1.0
pixels = 4
reflectance = "image.exr"
[source]
position = [0.5, 0.5, 1.0]
[sensors]
positions = [[0.8, 0.3, 1.0], [0.25, 0.7, 0.8]]
[sampling]
period = {WIDTH}
start = {START}
count = {COUNT}
""")
    return path


def test_check_command_exit_status_and_report(tmp_path, scene_file, scene, model, rng):
    paths = []
    for r, replica in enumerate(noisy_replicas(model, rng)):
        paths.append(tmp_path / f"replica_{r}.npy")
        np.save(paths[-1], replica)
    assert run_check(scene_file, "--data", *paths, "--out", tmp_path / "good") == 0
    metrics = json.loads((tmp_path / "good" / "metrics.json").read_text())
    assert metrics["agrees"] is True and metrics["agrees_after_fit"] is True
    assert set(metrics["fit"]) >= {"scale", "scale_stderr", "offset_opl", "offset_stderr"}
    assert {"chi2_per_dof", "max_abs_z"} <= set(metrics)
    report = (tmp_path / "good" / "report.md").read_text()
    assert "(check_transients.png)" in report and "(check_z.png)" in report
    assert (tmp_path / "good" / "check_transients.png").is_file() and (tmp_path / "good" / "check_z.png").is_file()

    sigma = 0.0025 * model + 1e-6
    np.save(tmp_path / "quarter.npy", 0.25 * model + sigma * rng.standard_normal(model.shape))
    np.save(tmp_path / "sigma.npy", sigma)
    assert run_check(scene_file, "--data", tmp_path / "quarter.npy", "--stderr", tmp_path / "sigma.npy",
                     "--out", tmp_path / "quarter") == 1
    assert json.loads((tmp_path / "quarter" / "metrics.json").read_text())["agrees_after_fit"] is True

    assert run_check(scene_file, "--data", tmp_path / "quarter.npy", "--shape-only",
                     "--out", tmp_path / "shape") == 1
    assert "shape only" in (tmp_path / "shape" / "report.md").read_text()
    assert not (tmp_path / "shape" / "check_z.png").exists()


def test_check_command_refuses_bad_input_in_one_line(tmp_path, scene_file, model, capsys):
    np.save(tmp_path / "y.npy", model)
    np.save(tmp_path / "short.npy", model[:, 1:])
    for argv, words in (((tmp_path / "y.npy",), "without errors"),
                        ((tmp_path / "y.npy", tmp_path / "y.npy", "--stderr", tmp_path / "y.npy"),
                         "--stderr: give it with one --data"),
                        ((tmp_path / "short.npy", "--shape-only"), "short.npy")):
        assert run_check(scene_file, "--data", *argv, "--out", tmp_path / "out") == 2
        error = capsys.readouterr().err.strip().splitlines()
        assert len(error) == 1 and words in error[0], error
    assert not (tmp_path / "out").exists()                   # nothing written before the refusal


def test_report_of_a_render_check(tmp_path, scene, model):
    """write_check_report on its own: metrics.json written atomically with the section 5 keys."""
    single = render(scene, spp=2**18, seed=3, progress=False)
    result = check_transient(scene, single.mean, stderr=single.stderr, model=model)
    metrics = write_check_report(tmp_path, result, scene_name="small", data_paths=["render"])
    assert json.loads((tmp_path / "metrics.json").read_text()) == json.loads(json.dumps(metrics))


# ---------------------------------------------------------------- too little to fit, nothing to judge

def one_bin_scene() -> Scene:
    """One sensor and one bin holding the whole response: nothing to fit a scale and an offset to."""
    return small_scene(sensors=[(0.8, 0.3, 1.0)], sampling=Sampling(bin_width_opl=1.5, start_opl=1.5, count=1))


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


def test_the_report_of_a_result_without_a_fit(tmp_path, rng):
    scene = one_bin_scene()
    model = forward(scene)
    result = check_transient(scene, noisy_replicas(model, rng), model=model)
    metrics = write_check_report(tmp_path, result, scene_name="one bin")
    assert metrics["fit"] is None
    assert "cannot fit them" in (tmp_path / "report.md").read_text()


# ---------------------------------------------------------------- tal captures with shared points

def test_a_capture_with_sensors_sharing_a_point_is_read_in_order(tmp_path):
    """Two of the scene's sensors at one point: the file's two sensors there are taken in order."""
    scene = small_scene(sensors=[(0.8, 0.3, 1.0), (0.25, 0.7, 0.8), (0.8, 0.3, 1.0)])
    data = forward(scene) * np.array([[1.0], [2.0], [3.0]])         # rows told apart
    write_transient(tmp_path / "out", data, build_meta(scene, kind="model"))
    assert np.array_equal(read_data(tmp_path / "out" / "transient.h5", scene), data)
    fewer = small_scene(sensors=[(0.8, 0.3, 1.0), (0.25, 0.7, 0.8), (0.25, 0.7, 0.8)])
    with pytest.raises(DataError, match="only 1 sensor.s. of sensor_grid_xyz at the point of the scene's sensor 2"):
        read_data(tmp_path / "out" / "transient.h5", fewer)


# ---------------------------------------------------------------- our render's replicas beside its output

def render_folder(folder, scene, replicas: np.ndarray):
    """A render's output as `render` writes it: the replicas' mean, their standard error, replicas.npy."""
    count = replicas.shape[0]
    meta = build_meta(scene, kind="render", samples=count, seed=0, replicas=count, dof=count - 1)
    write_transient(folder, replicas.mean(axis=0), meta,
                    stderr=replicas.std(axis=0, ddof=1) / np.sqrt(count))
    np.save(folder / "replicas.npy", replicas)
    return folder


def test_check_takes_the_replicas_beside_our_render(tmp_path, scene_file, scene, model, rng):
    folder = render_folder(tmp_path / "r", scene, noisy_replicas(model, rng, replicas=16))
    for data in (folder, folder / "transient.npy"):
        out = tmp_path / f"check_{data.name}"
        assert run_check(scene_file, "--data", data, "--out", out) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["judged_by"] == "replicas" and metrics["replicas"] == 16 and metrics["dof"] == 15
        assert metrics["null"] == "sign-flip"
    (folder / "replicas.npy").unlink()
    assert run_check(scene_file, "--data", folder, "--out", tmp_path / "by_stderr") == 0
    metrics = json.loads((tmp_path / "by_stderr" / "metrics.json").read_text())
    assert metrics["judged_by"] == "stderr" and metrics["dof"] == 15 and metrics["null"] == "independent"
    np.save(folder / "replicas.npy", noisy_replicas(model, rng, replicas=16))       # another render's
    assert run_check(scene_file, "--data", folder, "--out", tmp_path / "mixed") == 2
    assert not (tmp_path / "mixed").exists()


# ---------------------------------------------------------------- a stated convention: the irradiancemeter

def sphere_mean_irradiance(centre_distance: float, radius: float, intensity, points: int = 64) -> float:
    """Irradiance from a point emitter at the origin averaged over a sphere's surface, by quadrature.

    The sphere's centre lies at distance d on the direction at 60° from the +z axis; ``intensity(ω)``
    is the emitter's intensity toward the unit direction ω. Gauss–Legendre in μ (the cosine about the
    axis toward the emitter, over the lit cap μ > r/d) and uniform in the azimuth.
    """
    axis = np.array([np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3)])
    centre = centre_distance * axis
    helper = np.cross(axis, [0.0, 1.0, 0.0])
    u, v = helper / np.linalg.norm(helper), np.array([0.0, 1.0, 0.0])
    nodes, weights = np.polynomial.legendre.leggauss(points)
    low = radius / centre_distance
    mu = low + (1 - low) * (nodes + 1) / 2
    phi = np.linspace(0.0, 2 * np.pi, 2 * points, endpoint=False)
    mu, phi = np.meshgrid(mu, phi, indexing="ij")
    sine = np.sqrt(1 - mu**2)
    normal = (-mu[..., None] * axis + sine[..., None] * (np.cos(phi)[..., None] * u + np.sin(phi)[..., None] * v))
    point = centre + radius * normal
    distance = np.linalg.norm(point, axis=-1)
    towards = -point / distance[..., None]                      # from the sphere's point to the emitter
    irradiance = intensity(-towards) * np.maximum(np.sum(normal * towards, axis=-1), 0.0) / distance**2
    area_weight = (1 - low) / 2 * weights[:, None] * (2 * np.pi / phi.shape[1])     # dA / r² = dμ dφ
    return float(np.sum(irradiance * area_weight) / (4 * np.pi))


def test_an_irradiancemeter_reads_a_quarter_of_a_lambertian_plane_exactly():
    """A sphere of any radius above a Lambertian element intercepts exactly 1/4 of the fluence rate at
    its centre (its projected solid angle is π (r/d)² cos θ), unlike a sphere near an isotropic point,
    which reads 1 / (2 (1 + sqrt(1 - (r/d)²))) of it: the scale `--expect irradiancemeter` states."""
    distance = 1.0
    cosine = np.cos(np.pi / 3)                                   # the centre's angle from the normal
    for radius in (0.05, 0.3, 0.49):
        lambertian = sphere_mean_irradiance(distance, radius, lambda w: w[..., 2])
        assert lambertian == pytest.approx(cosine / distance**2 / 4, rel=1e-9)
        isotropic = sphere_mean_irradiance(distance, radius, lambda w: np.ones(w.shape[:-1]))
        ratio = 1 / (2 * (1 + np.sqrt(1 - (radius / distance) ** 2)))
        assert isotropic == pytest.approx(ratio / distance**2, rel=1e-9)
        assert abs(isotropic * distance**2 - 0.25) > 1e-4                 # the correction is real there


def test_the_irradiancemeters_paths_are_short_by_two_thirds_of_its_radius():
    """Irradiance-weighted mean shortfall of the path to the sphere's surface against its centre: 2r/3,
    to first order in r/d (the offset `--expect irradiancemeter` states, with Mitsuba's ray epsilon)."""
    distance, radius = 1.0, 1e-3
    nodes, weights = np.polynomial.legendre.leggauss(64)
    low = radius / distance
    mu = low + (1 - low) * (nodes + 1) / 2           # the lit cap, μ the cosine about the axis to the emitter
    # the emitter's intensity is the same toward the whole cap to first order: the weight is the irradiance
    point_distance = np.sqrt(distance**2 + radius**2 - 2 * distance * radius * mu)
    weight = weights * (distance * mu - radius) / point_distance**3
    shortfall = np.sum(weight * (distance - point_distance)) / np.sum(weight)
    assert shortfall == pytest.approx(2 * radius / 3, rel=2 * radius / distance)


def irradiancemeter_data(scene, rng, radius: float, scale: float = 0.25) -> np.ndarray:
    """16 replicas of what spheres of ``radius`` read, from the formula: scale x the model with start_opl
    moved by 2r/3 + Mitsuba's float32 RayEpsilon (1500 x 2^-24 m)."""
    return noisy_replicas(scale * shifted(scene, 2 * radius / 3 + 1500 * 2.0**-24), rng, replicas=16)


def test_check_expect_irradiancemeter_judges_the_stated_convention(tmp_path, scene_file, scene, rng):
    radius = 0.015
    paths = []
    for r, replica in enumerate(irradiancemeter_data(scene, rng, radius)):
        paths.append(tmp_path / f"meter_{r}.npy")
        np.save(paths[-1], replica)
    assert run_check(scene_file, "--data", *paths, "--out", tmp_path / "plain") == 1
    assert run_check(scene_file, "--data", *paths, "--expect", "irradiancemeter", "--radius", radius,
                     "--out", tmp_path / "meter") == 0
    metrics = json.loads((tmp_path / "meter" / "metrics.json").read_text())
    assert metrics["agrees"] is False and metrics["expected"]["agrees"] is True
    assert metrics["expected"]["scale"] == 0.25
    assert metrics["expected"]["offset_opl"] == pytest.approx(2 * radius / 3 + 1500 * 2.0**-24, rel=1e-15)
    assert "with the stated convention" in (tmp_path / "meter" / "report.md").read_text()
    # a sphere of another radius, or data of another scale, is not the stated convention
    assert run_check(scene_file, "--data", *paths, "--expect", "irradiancemeter", "--radius", radius / 3,
                     "--out", tmp_path / "smaller") == 1
    offset = 2 * radius / 3 + 1500 * 2.0**-24
    assert run_check(scene_file, "--data", *paths, "--expect-scale", 0.25, "--expect-offset", offset,
                     "--out", tmp_path / "numbers") == 0
    assert run_check(scene_file, "--data", *paths, "--expect-scale", 0.26, "--expect-offset", offset,
                     "--out", tmp_path / "wrong_scale") == 1


def test_the_irradiancemeter_convention_refuses_a_sphere_that_reaches_the_plane(scene):
    from validation.check import irradiancemeter

    with pytest.raises(ValueError, match=r"radius: must lie in \(0, 0.8\) m"):
        irradiancemeter(scene, 0.8)
    meter = irradiancemeter(scene, 1e-3)
    assert (meter.scale, meter.offset_opl) == (0.25, 2e-3 / 3 + 1500 * 2.0**-24)
