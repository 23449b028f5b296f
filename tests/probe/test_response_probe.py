"""Issue 38's probe, instrument responses and the detector: refusals in one line, and legal responses checked
against computations made here.

- The light of a waveform s summed over every bin is the area of s times the impulse's (the window holding
  all of it): the area from s's own definition (docs/design.md section 8): Gaussian σ √(2π), EMG 1 / the
  peak of SciPy's exponnorm density, sampled the trapezoid of its samples over their largest.
- Bin by bin, y under a Gaussian or an EMG is the numerical convolution of a fine impulse transient with the
  bin kernel κ_n(τ) = ∫_bin s(t - τ) dt, written from SciPy's normal and exponnorm CDFs.
- Expected counts (section 8) recomputed from transient.npy with exclusive sums in math.fsum: C λ_n without
  dead time; C e^{-Λ_n} (1 - e^{-λ_n}) with it, whose total never exceeds C.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from probe.common import assert_accepted, assert_forward_refuses, assert_refused, merged, toml_text
from scipy import optimize, special, stats

PLANE = {"plane": {"size": 1.0, "pixels": 4}, "source": {"position": [0.5, 0.5, 1.0]},
         "sensors": {"positions": [[0.2, 0.7, 1.0], [0.9, 0.1, 0.6]]},
         "sampling": {"period": 0.1, "start": 1.5, "count": 20}}
NOT_A_NUMBER = float("nan")

REFUSED = {
    "waveform unknown": ({"illumination": {"waveform": "lorentz"}}, "illumination.waveform"),
    "gaussian fwhm zero": ({"illumination": {"waveform": "gaussian", "fwhm": 0.0}}, "illumination.fwhm"),
    "gaussian fwhm negative": ({"illumination": {"waveform": "gaussian", "fwhm": -0.01}}, "illumination.fwhm"),
    "gaussian fwhm nan": ({"illumination": {"waveform": "gaussian", "fwhm": NOT_A_NUMBER}}, "illumination.fwhm"),
    "gaussian fwhm inf": ({"illumination": {"waveform": "gaussian", "fwhm": math.inf}}, "illumination.fwhm"),
    "gaussian fwhm string": ({"illumination": {"waveform": "gaussian", "fwhm": "0.1"}}, "illumination.fwhm"),
    "gaussian fwhm 1e300": ({"illumination": {"waveform": "gaussian", "fwhm": 1e300}}, "illumination.fwhm"),
    "gaussian with a tail": ({"illumination": {"waveform": "gaussian", "fwhm": 0.1, "tail": 0.1}},
                             "illumination.tail"),
    "emg tail zero": ({"illumination": {"waveform": "emg", "fwhm": 0.1, "tail": 0.0}}, "illumination.tail"),
    "emg tail negative": ({"illumination": {"waveform": "emg", "fwhm": 0.1, "tail": -1.0}}, "illumination.tail"),
    "emg tail boolean": ({"illumination": {"waveform": "emg", "fwhm": 0.1, "tail": True}}, "illumination.tail"),
    "emg tail far below fwhm": ({"illumination": {"waveform": "emg", "fwhm": 1.0, "tail": 1e-7}}, "tail"),
    "impulse with a fwhm": ({"illumination": {"waveform": "impulse", "fwhm": 0.1}}, "illumination.fwhm"),
    "sampled one sample": ({"illumination": {"waveform": "sampled", "samples": [1.0], "sample_width": 0.01}},
                           "illumination.samples"),
    "sampled no samples": ({"illumination": {"waveform": "sampled", "samples": [], "sample_width": 0.01}},
                           "illumination.samples"),
    "sampled all zero": ({"illumination": {"waveform": "sampled", "samples": [0.0, 0.0, 0.0],
                                           "sample_width": 0.01}}, "illumination.samples"),
    "sampled negative sample": ({"illumination": {"waveform": "sampled", "samples": [0.0, -1.0, 2.0],
                                                  "sample_width": 0.01}}, "illumination.samples"),
    "sampled nan sample": ({"illumination": {"waveform": "sampled", "samples": [0.0, NOT_A_NUMBER, 1.0],
                                             "sample_width": 0.01}}, "illumination.samples"),
    "sampled boolean sample": ({"illumination": {"waveform": "sampled", "samples": [0.0, True, 0.0],
                                                 "sample_width": 0.01}}, "illumination.samples[1]"),
    "sampled string sample": ({"illumination": {"waveform": "sampled", "samples": [0.0, "1e0", 0.0],
                                                "sample_width": 0.01}}, "illumination.samples[1]"),
    "sampled nested list": ({"illumination": {"waveform": "sampled", "samples": [[0.0, 1.0], [1.0, 0.0]],
                                              "sample_width": 0.01}}, "illumination.samples"),
    "sampled without width": ({"illumination": {"waveform": "sampled", "samples": [0.0, 1.0, 0.0]}},
                              "illumination.sample_width"),
    "sampled with both widths": ({"illumination": {"waveform": "sampled", "samples": [0.0, 1.0, 0.0],
                                                   "sample_width": 0.01, "sample_width_ps": 10.0}},
                                 "illumination.sample_width"),
    "sampled width zero": ({"illumination": {"waveform": "sampled", "samples": [0.0, 1.0, 0.0],
                                             "sample_width": 0.0}}, "illumination.sample_width"),
    "sampled width in ps negative": ({"illumination": {"waveform": "sampled", "samples": [0.0, 1.0, 0.0],
                                                       "sample_width_ps": -3.0}}, "illumination.sample_width_ps"),
    "sampled start nan": ({"illumination": {"waveform": "sampled", "samples": [0.0, 1.0, 0.0],
                                            "sample_width": 0.01, "start": NOT_A_NUMBER}}, "illumination.start"),
    "sampled neither samples nor file": ({"illumination": {"waveform": "sampled", "sample_width": 0.01}},
                                         "illumination.file"),
    "sampled missing file": ({"illumination": {"waveform": "sampled", "file": "irf.npy", "sample_width": 0.01}},
                             "illumination.file"),
    "sampled file of another suffix": ({"illumination": {"waveform": "sampled", "file": "irf.txt",
                                                         "sample_width": 0.01}}, "illumination.file"),
}

# files written beside the scene for the file cases: name -> bytes
FILES = {
    "two columns": ("irf.csv", b"0,1\n1,2\n0,1\n"),
    "a word": ("irf.csv", b"0\n1\nhigh\n0\n"),
    "only comments": ("irf.csv", b"# a header\n\n# nothing else\n"),
    "UTF-16": ("irf.csv", "0\n1\n0\n".encode("utf-16")),
    "2-D npy": ("irf.npy", None),
    "complex npy": ("irf.npy", None),
    "string npy": ("irf.npy", None),
    "truncated npy": ("irf.npy", b"\x93NUMPY\x01\x00"),
}


def _write_file(folder, case):
    name, content = FILES[case]
    if content is None:
        value = {"2-D npy": np.ones((3, 2)), "complex npy": np.array([0, 1 + 1j, 0]),
                 "string npy": np.array(["0", "1", "0"])}[case]
        np.save(folder / name, value)
    else:
        (folder / name).write_bytes(content)
    return name


@pytest.mark.parametrize("changes, needle", REFUSED.values(), ids=REFUSED.keys())
def test_a_bad_response_is_refused_in_one_line(tmp_path, capsys, changes, needle):
    assert_forward_refuses(tmp_path, capsys, merged(PLANE, changes), needle)


@pytest.mark.parametrize("case", FILES.keys())
def test_a_bad_response_file_is_refused_in_one_line(tmp_path, capsys, case):
    name = _write_file(tmp_path, case)
    scene = tmp_path / "scene.toml"
    scene.write_text(toml_text(merged(PLANE, {"illumination": {"waveform": "sampled", "file": name,
                                                               "sample_width": 0.01}})))
    out = tmp_path / "out"
    assert_refused(capsys, ["forward", scene, "--out", out], out, "illumination.file")


# ======================================================================== legal responses: areas

def _sigma(fwhm):
    return fwhm / (2 * math.sqrt(2 * math.log(2)))


def _emg_peak(fwhm, tail):
    """The largest value of the exponnorm density (σ from fwhm, rate 1/tail), found here by SciPy."""
    sigma = _sigma(fwhm)
    density = stats.exponnorm(tail / sigma, scale=sigma)
    found = optimize.minimize_scalar(lambda t: -density.logpdf(t), bounds=(-5 * sigma, 5 * sigma + 5 * tail),
                                     method="bounded", options={"xatol": 1e-12 * (sigma + tail)})
    return float(density.pdf(found.x))


def _area(illumination):
    if illumination["waveform"] == "gaussian":
        return _sigma(illumination["fwhm"]) * math.sqrt(2 * math.pi)
    if illumination["waveform"] == "emg":
        return 1.0 / _emg_peak(illumination["fwhm"], illumination["tail"])
    samples = np.asarray(illumination["samples"], float)
    width = illumination.get("sample_width", illumination.get("sample_width_ps", 0) * 299792458e-12)
    return width * (samples.sum() - 0.5 * (samples[0] + samples[-1])) / samples.max()


AREAS = {
    "gaussian 3 cm": {"waveform": "gaussian", "fwhm": 0.03},
    "gaussian wider than the bins": {"waveform": "gaussian", "fwhm": 0.35},
    "gaussian a micron": {"waveform": "gaussian", "fwhm": 1e-6},
    "emg short tail": {"waveform": "emg", "fwhm": 0.05, "tail": 0.01},
    "emg long tail": {"waveform": "emg", "fwhm": 0.02, "tail": 0.3},
    "emg tail just above the bound": {"waveform": "emg", "fwhm": 0.1, "tail": 1.0000000000000002e-05},
    "sampled triangle": {"waveform": "sampled", "samples": [0.0, 1.0, 0.0], "sample_width": 0.02},
    "sampled ragged, offset start": {"waveform": "sampled", "samples": [0.2, 3.0, 1.0, 0.5, 0.0, 0.7],
                                     "sample_width": 0.013, "start": -0.02},
    "sampled in picoseconds": {"waveform": "sampled", "samples": [0.0, 2.0, 5.0, 1.0], "sample_width_ps": 40.0},
    "sampled whole numbers": {"waveform": "sampled", "samples": [0, 4, 9, 2], "sample_width": 0.01},
}


@pytest.fixture(scope="module")
def impulse_light(tmp_path_factory):
    """Σ_n y_n per sensor of the impulse (window auto: all the light), the reference each waveform scales."""
    folder = tmp_path_factory.mktemp("impulse")
    from validation.cli import main

    (folder / "scene.toml").write_text(toml_text(PLANE))
    assert main(["forward", str(folder / "scene.toml"), "--out", str(folder / "out"), "--window", "auto",
                 "--quiet"]) == 0
    return np.load(folder / "out" / "transient.npy").sum(axis=1)


@pytest.mark.parametrize("illumination", AREAS.values(), ids=AREAS.keys())
def test_the_light_of_a_response_is_its_area_times_the_impulse(tmp_path, capsys, impulse_light, illumination):
    scene = tmp_path / "scene.toml"
    scene.write_text(toml_text(merged(PLANE, {"illumination": illumination})))
    out = tmp_path / "out"
    assert_accepted(capsys, ["forward", scene, "--out", out, "--window", "auto", "--quiet"])
    transient = np.load(out / "transient.npy")
    assert np.all(np.isfinite(transient)) and json.loads((out / "meta.json").read_text())["window_share"] == 1.0
    np.testing.assert_allclose(transient.sum(axis=1), _area(illumination) * impulse_light, rtol=1e-5)


def test_a_response_csv_with_a_byte_order_mark_reads_as_without(tmp_path, capsys):
    outs = []
    for name, text in (("plain.csv", b"0\n2\n5\n1\n"), ("bom.csv", b"\xef\xbb\xbf0\r\n2\r\n5\r\n1\r\n")):
        (tmp_path / name).write_bytes(text)
        scene = tmp_path / f"{name}.toml"
        scene.write_text(toml_text(merged(PLANE, {"illumination": {"waveform": "sampled", "file": name,
                                                                   "sample_width": 0.02}})))
        assert_accepted(capsys, ["forward", scene, "--out", tmp_path / name[:-4], "--quiet"])
        outs.append(np.load(tmp_path / name[:-4] / "transient.npy"))
    assert outs[0].max() > 0
    np.testing.assert_array_equal(outs[0], outs[1])


# ======================================================================== legal responses: bin by bin

CONVOLVED = {
    "gaussian": {"waveform": "gaussian", "fwhm": 0.25},
    "emg": {"waveform": "emg", "fwhm": 0.1, "tail": 0.15},
}


def _bin_kernel(illumination, lower, upper, delays):
    """κ(τ) = ∫_lower^upper s(t - τ) dt for unit-peak s, from SciPy's CDFs."""
    sigma = _sigma(illumination["fwhm"])
    if illumination["waveform"] == "gaussian":
        return sigma * math.sqrt(2 * math.pi) * (special.ndtr((upper - delays) / sigma)
                                                 - special.ndtr((lower - delays) / sigma))
    density = stats.exponnorm(illumination["tail"] / sigma, scale=sigma)
    peak = _emg_peak(illumination["fwhm"], illumination["tail"])
    return (density.cdf(upper - delays) - density.cdf(lower - delays)) / peak


@pytest.mark.slow
@pytest.mark.parametrize("illumination", CONVOLVED.values(), ids=CONVOLVED.keys())
def test_each_bin_is_the_numerical_convolution_of_a_fine_impulse_transient(tmp_path, capsys, illumination):
    fine = merged(PLANE, {"sampling": {"period": 0.0005, "start": 1.6, "count": 2200}})   # [1.6, 2.7) m
    (tmp_path / "fine.toml").write_text(toml_text(fine))
    assert_accepted(capsys, ["forward", tmp_path / "fine.toml", "--out", tmp_path / "fine", "--quiet"])
    impulse = np.load(tmp_path / "fine" / "transient.npy")
    coarse = merged(PLANE, {"illumination": illumination, "sampling": {"period": 0.1, "start": 1.3, "count": 30}})
    (tmp_path / "coarse.toml").write_text(toml_text(coarse))
    assert_accepted(capsys, ["forward", tmp_path / "coarse.toml", "--out", tmp_path / "coarse", "--quiet"])
    transient = np.load(tmp_path / "coarse" / "transient.npy")
    delays = 1.6 + 0.0005 * (np.arange(2200) + 0.5)            # each fine bin's light at its centre
    lower = 1.3 + 0.1 * np.arange(30)
    kernels = np.array([_bin_kernel(illumination, a, a + 0.1, delays) for a in lower])      # (bins, fine)
    reference = impulse @ kernels.T
    assert np.abs(impulse[:, [0, -1]]).max() == 0.0          # the fine window holds every path
    # the midpoint rule in τ over 0.5 mm bins: relative error ~ (h/σ)²/24 < 1e-4 of the peak
    np.testing.assert_allclose(transient, reference, rtol=0, atol=2e-4 * reference.max())


# ======================================================================== the detector

DETECTOR_REFUSED = {
    "photons zero": ({"photons": 0.0}, "detector.photons"),
    "photons negative": ({"photons": -1.0}, "detector.photons"),
    "photons nan": ({"photons": NOT_A_NUMBER}, "detector.photons"),
    "photons string": ({"photons": "1"}, "detector.photons"),
    "photons missing": ({"photons": None, "cycles": 10.0}, "detector.photons"),
    "background negative": ({"background": -1e-4}, "detector.background"),
    "background inf": ({"background": math.inf}, "detector.background"),
    "cycles zero": ({"cycles": 0.0}, "detector.cycles"),
    "cycles fraction": ({"cycles": 1.5}, "detector.cycles"),
    "cycles past 2^53": ({"cycles": 2.0**53 + 2}, "detector.cycles"),
    "cycles boolean": ({"cycles": True}, "detector.cycles"),
    "dead time unknown": ({"dead_time": "paralysable"}, "detector.dead_time"),
    "dead time a number": ({"dead_time": 1}, "detector.dead_time"),
    "seed negative": ({"seed": -1}, "detector.seed"),
    "seed 2^32": ({"seed": 2**32}, "detector.seed"),
    "unknown key": ({"efficiency": 0.5}, "efficiency"),
    "counts past float64, no dead time": ({"photons": 1e300, "cycles": 1e10}, "detector.photons"),
    "background counts past float64": ({"background": 1e300, "cycles": 1e10}, "detector.background"),
    "a Poisson draw past 1e15": ({"photons": 1e250, "cycles": 1e3}, "detector.photons"),
}


@pytest.mark.parametrize("changes, needle", DETECTOR_REFUSED.values(), ids=DETECTOR_REFUSED.keys())
def test_a_bad_detector_is_refused_in_one_line(tmp_path, capsys, changes, needle):
    detector = {"photons": 1.0, "background": 1e-4, "cycles": 1000.0, "dead_time": "none", **changes}
    scene = tmp_path / "scene.toml"
    scene.write_text(toml_text(merged(PLANE, {"detector": detector})))
    out = tmp_path / "out"
    assert_refused(capsys, ["forward", scene, "--out", out], out, needle)


def _expected_counts(y, photons, background, cycles, dead_time):
    """Section 8's expected counts, bin by bin in Python floats with exclusive sums."""
    rows = []
    for row in y:
        lam = [photons * max(v, 0.0) + background for v in row]
        if dead_time == "none":
            rows.append([cycles * v for v in lam])
            continue
        rows.append([cycles * math.exp(-math.fsum(lam[:n])) * -math.expm1(-lam[n]) for n in range(len(lam))])
    return np.array(rows)


DETECTORS = {
    "dim, no dead time": (1e3, 1e-4, 1e6, "none"),
    "dim, cycle": (1e3, 1e-4, 1e6, "cycle"),
    "no background, cycle": (50.0, 0.0, 1e5, "cycle"),
    "subnormal background, cycle": (50.0, 5e-324, 1e5, "cycle"),
    "pile-up, cycle": (1e8, 1e-3, 1e5, "cycle"),
    "extreme pile-up, cycle": (1e300, 1.0, 1e5, "cycle"),
    "extreme pile-up, no background": (1e250, 0.0, 7.0, "cycle"),
    "background dwarfs the signal, cycle": (1e-6, 50.0, 1e4, "cycle"),
    "one cycle": (1e4, 1e-2, 1.0, "cycle"),
    "2^53 cycles": (1.0, 1e-9, 2.0**53, "cycle"),
    "2^53 cycles, no dead time": (1.0, 1e-9, 2.0**53, "none"),
    "bright, no dead time": (1e9, 1.0, 1e3, "none"),
}


@pytest.mark.parametrize("photons, background, cycles, dead_time", DETECTORS.values(), ids=DETECTORS.keys())
def test_expected_counts_follow_the_detector_model(tmp_path, capsys, photons, background, cycles, dead_time):
    detector = {"photons": photons, "background": background, "cycles": cycles, "dead_time": dead_time}
    scene = tmp_path / "scene.toml"
    scene.write_text(toml_text(merged(PLANE, {"detector": detector})))
    out = tmp_path / "out"
    assert_accepted(capsys, ["forward", scene, "--out", out, "--quiet"])
    y = np.load(out / "transient.npy")
    expected = np.load(out / "counts_expected.npy")
    counts = np.load(out / "counts.npy")
    assert np.all(np.isfinite(expected)) and np.all(expected >= 0)
    np.testing.assert_allclose(expected, _expected_counts(y, photons, background, cycles, dead_time),
                               rtol=1e-12, atol=1e-300)
    assert counts.dtype.kind == "i" and np.all(counts >= 0)
    if dead_time == "cycle":
        # at most one detection per cycle: in expectation and in the draw, per sensor
        assert np.all(expected.sum(axis=1) <= cycles * (1 + 1e-12))
        assert np.all(counts.sum(axis=1) <= cycles)
