"""Photon counts on the command line: forward/render/run write them beside y, check --counts judges them.

The expected histogram is held to Coates' formula written here; the captures that must fail are drawn here
with NumPy's own generator from a model that differs from the scene's claim (a wider pulse, no dead time).
"""

import json

import numpy as np
import pytest

import analytic
from analytic.measurement.detector import draw_counts
from analytic.files import read_transient
from analytic.scenes.scene_file import load_scene
from scene_files import GOOD, write_scene
from validation.cli import main

CYCLES = 100_000
# photons: about half a photon per cycle over the window, so that pile-up shapes the dead-time histogram
DETECTOR = f"""
[detector]
photons = 35.0
background = 1e-4
cycles = {CYCLES}
dead_time = "cycle"
seed = 3
"""
GAUSSIAN = (GOOD.replace('waveform = "impulse"', 'waveform = "gaussian"\nfwhm = 0.15')
            .replace("start = 0.0", "start = 1.4").replace("count = 40", "count = 19"))


def _coates(y, photons=35.0, background=1e-4, cycles=CYCLES):
    """C e^{-Λ_n} (1 - e^{-λ_n}), written out here (docs/design.md section 8)."""
    lam = photons * np.maximum(y, 0.0) + background
    before = np.concatenate([np.zeros((lam.shape[0], 1)), np.cumsum(lam, axis=1)[:, :-1]], axis=1)
    return cycles * np.exp(-before) * (1.0 - np.exp(-lam))


def _multinomial(expected, rng):
    p = expected / CYCLES
    return np.array([rng.multinomial(CYCLES, np.append(row, 1.0 - row.sum()))[:-1] for row in p])


@pytest.fixture(scope="module")
def spad(tmp_path_factory):
    """A Gaussian-pulse scene with a dead-time detector, and forward's folder of it."""
    folder = tmp_path_factory.mktemp("counts")
    path = write_scene(folder, GAUSSIAN + DETECTOR)
    assert main(["forward", str(path), "--out", str(folder / "forward"), "--quiet"]) == 0
    return path, folder / "forward"


def test_forward_writes_the_expected_counts_and_a_draw_beside_y(spad):
    _, out = spad
    y = np.load(out / "transient.npy")
    expected = np.load(out / "counts_expected.npy")
    counts = np.load(out / "counts.npy")
    np.testing.assert_allclose(expected, _coates(y), rtol=1e-12, atol=0)
    assert counts.dtype == np.int64 and counts.shape == y.shape and counts.sum() <= CYCLES
    # the draw is the expected histogram's: its total within 5 binomial standard errors
    total = expected.sum()
    assert abs(counts.sum() - total) < 5 * np.sqrt(total * (1 - total / CYCLES))
    meta = json.loads((out / "meta.json").read_text())
    assert meta["detector"] == {"photons": 35.0, "background": 1e-4, "cycles": CYCLES, "dead_time": "cycle",
                                "seed": 3}
    assert (out / "counts.png").is_file()
    np.testing.assert_array_equal(read_transient(out / "counts.h5"), counts)      # tal's layout, as transient.h5


def test_check_counts_passes_the_draw_and_fails_a_wider_pulse_or_no_dead_time(spad, tmp_path, capsys):
    path, out = spad
    assert main(["check", str(path), "--data", str(out / "counts.npy"), "--counts", "--out", str(tmp_path / "good"),
                 "--quiet"]) == 0
    metrics = json.loads((tmp_path / "good" / "metrics.json").read_text())
    assert metrics["agrees"] and metrics["counts"]["statistic"] == "multinomial"
    assert metrics["counts"]["false_alarm"] == 0.01 and metrics["fit"] is None
    assert (tmp_path / "good" / "check_counts.png").is_file()

    rng = np.random.default_rng(11)
    scene = load_scene(path)
    wide = analytic.forward(scene.replace(illumination=analytic.Illumination(waveform="gaussian", fwhm=0.25)))
    np.save(tmp_path / "wide.npy", _multinomial(_coates(wide), rng))
    # every photon counted (no dead time), from the scene's own y
    y = np.load(out / "transient.npy")
    np.save(tmp_path / "free.npy", rng.poisson(CYCLES * (35.0 * y + 1e-4)))
    capsys.readouterr()
    for name in ("wide", "free"):
        assert main(["check", str(path), "--data", str(tmp_path / f"{name}.npy"), "--counts",
                     "--out", str(tmp_path / name)]) == 1, name
        assert "DISAGREES: multinomial deviance" in capsys.readouterr().out
        assert json.loads((tmp_path / name / "metrics.json").read_text())["counts"]["p_value"] < 0.01


@pytest.mark.parametrize("arguments, message", [
    (["--fit", "scale"], "--fit/--false-alarm: apply to --counts only"),
    (["--counts", "--fit", "scale,width"], "--fit: width is not one of"),
    (["--counts", "--fit", "offset,offset_opl"], "--fit: each name once"),
    (["--counts", "--fit", "tail"], "--fit tail: the scene's pulse ('gaussian') has no tail"),
    (["--counts", "--expect-scale", "2"], "--expect-scale: does not apply to --counts"),
    (["--counts", "--false-alarm", "0.7"], "--false-alarm: must be in [0.0001, 0.5]"),
    (["--counts", "--false-alarm", "1e-9"], "--false-alarm: must be in [0.0001, 0.5]"),
])
def test_check_counts_refuses_bad_options_in_one_line(spad, tmp_path, capsys, arguments, message):
    path, out = spad
    try:
        status = main(["check", str(path), "--data", str(out / "counts.npy"), *arguments,
                       "--out", str(tmp_path / "out")])
    except SystemExit as exit:      # argparse's own refusals
        status = exit.code
    assert status == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and message in error[0], error
    assert not (tmp_path / "out").exists()


def test_check_counts_refuses_bad_data_and_scenes_without_a_detector(spad, tmp_path, capsys):
    path, out = spad
    cases = {"no detector": (write_scene(tmp_path, GAUSSIAN, name="plain.toml"), out / "counts.npy",
                             "has no [detector] table"),
             "shape": (path, tmp_path / "short.npy", "the scene's rows x bins are (1, 19)"),
             "fraction": (path, tmp_path / "fraction.npy", "every count must be a finite whole number"),
             "too many": (path, tmp_path / "many.npy", "more counts than the 100000 cycles")}
    np.save(tmp_path / "short.npy", np.zeros((1, 18), dtype=np.int64))
    np.save(tmp_path / "fraction.npy", np.full((1, 19), 0.5))
    np.save(tmp_path / "many.npy", np.full((1, 19), 6000))
    for name, (scene, data, message) in cases.items():
        assert main(["check", str(scene), "--data", str(data), "--counts", "--out", str(tmp_path / name)]) == 2
        error = capsys.readouterr().err.strip().splitlines()
        assert len(error) == 1 and message in error[0], (name, error)
        assert not (tmp_path / name).exists()


@pytest.mark.parametrize("change, key", [('dead_time = "cycle"', "detector.dead_time"),
                                         ("photons = 35.0", "detector.photons"),
                                         (f"cycles = {CYCLES}", "detector.cycles")])
def test_a_bad_detector_is_refused_before_any_file(tmp_path, capsys, change, key):
    bad = {"dead_time": 'dead_time = "sometimes"', "photons": "photons = -1", "cycles": "cycles = 2.5"}
    text = (GAUSSIAN + DETECTOR).replace(change, bad[key.split(".")[1]])
    path = write_scene(tmp_path, text)
    assert main(["forward", str(path), "--out", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and key in error[0] and "Traceback" not in error[0], error
    assert not (tmp_path / "out").exists()


def test_a_folder_rewritten_without_a_detector_loses_its_counts(spad, tmp_path):
    path, _ = spad
    out = tmp_path / "out"
    assert main(["forward", str(path), "--out", str(out), "--quiet"]) == 0
    assert (out / "counts.npy").is_file()
    assert main(["forward", str(write_scene(tmp_path, GAUSSIAN, name="plain.toml")), "--out", str(out),
                 "--quiet"]) == 0
    assert not any((out / name).exists() for name in ("counts.npy", "counts_expected.npy", "counts.h5", "counts.png"))
    assert json.loads((out / "meta.json").read_text())["detector"] is None


@pytest.mark.slow
def test_check_counts_fit_finds_the_width_a_capture_was_drawn_with(spad, tmp_path, capsys):
    path, _ = spad
    scene = load_scene(path)
    wide = analytic.forward(scene.replace(illumination=analytic.Illumination(waveform="gaussian", fwhm=0.25)))
    np.save(tmp_path / "wide.npy", _multinomial(_coates(0.8 * wide), np.random.default_rng(5)))
    assert main(["check", str(path), "--data", str(tmp_path / "wide.npy"), "--counts", "--fit",
                 "scale,offset,fwhm", "--out", str(tmp_path / "fit")]) == 1
    metrics = json.loads((tmp_path / "fit" / "metrics.json").read_text())
    found, stderr = metrics["fit"]["parameters"], metrics["fit"]["stderr"]
    assert not metrics["agrees"] and metrics["agrees_after_fit"]
    assert abs(found["fwhm"] - 0.25) < 4 * stderr["fwhm"] and abs(found["fwhm"] - 0.15) > 5 * stderr["fwhm"]
    assert abs(found["scale"] - 0.8) < 4 * stderr["scale"] and abs(found["offset_opl"]) < 4 * stderr["offset_opl"]
    assert "fit: scale" in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::analytic.inversion.RankDeficiencyWarning")   # one sensor cannot image
@pytest.mark.filterwarnings("ignore::analytic.inversion.RegularizationWarning")
def test_render_and_run_write_counts_of_their_y(spad, tmp_path):
    path, _ = spad
    assert main(["render", str(path), "--spp", "65536", "--out", str(tmp_path / "render"), "--quiet"]) == 0
    mean = np.load(tmp_path / "render" / "transient.npy")
    np.testing.assert_allclose(np.load(tmp_path / "render" / "counts_expected.npy"), _coates(mean), rtol=1e-12)
    # a render's draw is from its own stream (the seed and 1), independent of forward's from the same seed
    detector = load_scene(path).detector
    np.testing.assert_array_equal(np.load(tmp_path / "render" / "counts.npy"),
                                  draw_counts(mean, detector, rng=np.random.default_rng([3, 1])))
    assert json.loads((tmp_path / "render" / "meta.json").read_text())["detector"]["cycles"] == CYCLES
    assert main(["run", str(path), "--spp", "65536", "--out", str(tmp_path / "run"), "--quiet"]) in (0, 1)
    for stream, part in enumerate(("model", "render")):
        y = np.load(tmp_path / "run" / part / "transient.npy")
        expected = _coates(y)
        np.testing.assert_allclose(np.load(tmp_path / "run" / part / "counts_expected.npy"), expected, rtol=1e-12)
        # the model's draw from the detector's seed, the render's from its own stream (independent draws)
        detector = load_scene(path).detector
        drawn = np.load(tmp_path / "run" / part / "counts.npy")
        own = draw_counts(y, detector, rng=np.random.default_rng(3 if stream == 0 else [3, 1]))
        np.testing.assert_array_equal(drawn, own)
        if stream:
            assert not np.array_equal(drawn, draw_counts(y, detector, rng=np.random.default_rng(3)))


def test_a_render_near_the_poisson_limit_is_judged_by_the_model_not_the_bound(tmp_path):
    """The cheap bound (all of a sensor's light in one bin) would refuse it; the exact y does not."""
    from analytic.operator.window import impulse_totals

    covered = GOOD.replace("start = 0.0", "start = 2.0").replace("count = 40", "count = 7")    # the light's bins
    plain = load_scene(write_scene(tmp_path, covered, name="plain.toml"))
    cycles = 1000.0
    photons = 3e14 / (cycles * float(np.max(analytic.forward(plain))))     # the largest expected count: 3e14
    assert 2.0 * cycles * photons * float(np.max(impulse_totals(plain))) > 1e15   # the bound alone would refuse
    text = covered + f"\n[detector]\nphotons = {photons!r}\ncycles = {cycles!r}\ndead_time = \"none\"\n"
    path = write_scene(tmp_path, text)
    assert main(["render", str(path), "--spp", "65536", "--out", str(tmp_path / "render"), "--quiet"]) == 0
    assert np.load(tmp_path / "render" / "counts.npy").max() > 1e14
    # ... and beyond it, refused before any file, naming the exact largest count
    path = write_scene(tmp_path, text.replace(f"photons = {photons!r}", f"photons = {2 * photons!r}"),
                       name="over.toml")
    assert main(["render", str(path), "--spp", "65536", "--out", str(tmp_path / "over")]) == 2
    assert not (tmp_path / "over").exists()


def test_a_render_whose_counts_could_pass_a_poissons_limit_is_refused_before_any_file(tmp_path, capsys):
    text = (GAUSSIAN + DETECTOR).replace('dead_time = "cycle"', 'dead_time = "none"').replace("photons = 35.0",
                                                                                                "photons = 1e30")
    path = write_scene(tmp_path, text)
    assert main(["render", str(path), "--spp", "65536", "--out", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "detector.photons" in error[0] and "Traceback" not in error[0], error
    assert not (tmp_path / "out").exists()


def test_a_relay_wall_capture_gets_counts_in_tal_nlos_layout(tmp_path):
    from analytic.measurement.detector import Detector
    from analytic.scenes.relay_wall import RelayWallScene, Scan
    from analytic.scenes.common import Sampling
    from scene_files import write_relay_wall_file

    scene = RelayWallScene(name="nlos", pixels=4, center=(0.1, 0.05, 0.9), u=(0.8, 0.0, 0.0), v=(0.0, -0.7, 0.0),
                           scan=Scan(type="single", grid=(3, 2), laser_point=(0.4, -0.3, 0.0)),
                           sampling=Sampling(bin_width_opl=0.04, start_opl=1.84, count=30),
                           detector=Detector(photons=2e3, background=1e-3, cycles=1e4, dead_time="none", seed=1))
    path = write_relay_wall_file(tmp_path, scene)
    assert main(["forward", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    out = tmp_path / "out"
    y = np.load(out / "transient.npy")
    np.testing.assert_allclose(np.load(out / "counts_expected.npy"), 1e4 * (2e3 * np.maximum(y, 0) + 1e-3),
                               rtol=1e-12)
    counts = np.load(out / "counts.npy")
    assert counts.shape == (6, 30) and counts.sum() > 0
    np.testing.assert_array_equal(read_transient(out / "counts.h5"), counts)    # tal's NLOS layout, our pair order
    assert json.loads((out / "meta.json").read_text())["detector"]["dead_time"] == "none"


@pytest.mark.parametrize("photons", ["1e300", "1e200", "1e20"])
def test_extreme_pile_up_counts_at_most_the_cycles(tmp_path, photons):
    # issue 38: photons = 1e300 with a background of 1 per bin wrote twice the cycles
    # the impulse: 2 bins of background alone before the first arrival (2.03 m), then light
    text = (GOOD + DETECTOR).replace("photons = 35.0", f"photons = {photons}").replace(
        "background = 1e-4", "background = 1").replace("start = 0.0", "start = 1.8").replace("count = 40", "count = 10")
    path = write_scene(tmp_path, text)
    assert main(["forward", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    y = np.load(tmp_path / "out" / "transient.npy")
    expected = np.load(tmp_path / "out" / "counts_expected.npy")
    assert np.all(expected.sum(axis=1) <= CYCLES)
    np.testing.assert_allclose(expected, _coates(y, photons=float(photons), background=1.0), rtol=1e-12, atol=0)
    # the first bin lit past saturation takes every cycle still armed there: e^{-n} of them, n bins of background
    rows = np.arange(len(y))
    first = np.argmax(float(photons) * y > 50, axis=1)
    saturated = float(photons) * y[rows, first] > 50
    assert expected[rows, first][saturated] == pytest.approx(
        CYCLES * np.exp(-first[saturated] - float(photons) * np.sum(np.where(
            np.arange(y.shape[1]) < first[:, None], y, 0.0), axis=1)[saturated]), rel=1e-12)


@pytest.mark.parametrize("command", [["forward"], ["render", "--spp", "65536"]])
def test_counts_beyond_float64_are_refused_in_one_line_before_the_windows_warning(tmp_path, capsys, command):
    text = (GAUSSIAN + DETECTOR).replace('dead_time = "cycle"', 'dead_time = "none"').replace(
        "photons = 35.0", "photons = 1e306").replace("count = 19", "count = 60")     # a mostly empty window
    path = write_scene(tmp_path, text)
    assert main([command[0], str(path), *command[1:], "--out", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "detector.photons" in error[0], error
    assert not (tmp_path / "out").exists()
