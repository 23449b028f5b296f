"""A against an independent high-precision reference, on every hard geometry.

The reference (tests/reference.py) shares no code with the model: roots of
d = const by bracketing along each line, SciPy's adaptive QUADPACK for the
nested integrals, κ_n from the waveform's closed form only.
"""

import numpy as np
import pytest
from reference import box_kernel, pixel_entry

from analytic.scene import default_scene
from analytic.system import _pixel_box, system_matrix
from analytic.waveforms import make_waveform
from validation.suite import hard_cases

TOLERANCE = 1e-6


def _picks(matrix, scene, rng):
    """(row, pixel) pairs: each sensor's first-arrival row maximum, the global
    peak row's maximum, and random non-zero entries."""
    count = scene.sampling.count
    row_max = matrix.max(axis=1).toarray().ravel()
    picks = set()
    for k in range(scene.sensor_count):
        lit = np.nonzero(row_max[k * count:(k + 1) * count] > 0)[0]
        if len(lit):
            row = k * count + lit[0]
            picks.add((row, int(matrix[[row], :].toarray().argmax())))
    peak = int(np.argmax(row_max))
    picks.add((peak, int(matrix[[peak], :].toarray().argmax())))
    coo = matrix.tocoo()
    for i in rng.choice(coo.nnz, size=min(2, coo.nnz), replace=False):
        picks.add((int(coo.row[i]), int(coo.col[i])))
    return sorted(picks), row_max


def _reference(scene, waveform, row, pixel):
    k, n = divmod(row, scene.sampling.count)
    edges = scene.sampling.edges
    if waveform.name == "impulse":
        kernel = box_kernel(edges[n], edges[n + 1])
        breakpoints = [edges[n], edges[n + 1]]
    else:
        def kernel(tau):
            return float(waveform.cumulative(edges[n + 1] - tau) - waveform.cumulative(edges[n] - tau))
        breakpoints = [edges[n], edges[n + 1], edges[n] - waveform.duration,
                       edges[n + 1] - waveform.duration]
    box = _pixel_box(scene.size, scene.pixels, pixel)
    return pixel_entry(box, scene.source, scene.sensors[k], kernel, breakpoints, scene.attenuation)


# The reference needs minutes for a pulse spread over many of the far plane's fine bins.
CASES = [pytest.param(name, waveform, marks=[pytest.mark.slow] if name == "far" and waveform != "impulse"
                      else [])
         for waveform in ("impulse", "square", "butterworth") for name in hard_cases(pixels=4)]


@pytest.mark.parametrize("name, waveform", CASES)
def test_entries_match_reference_on_hard_geometry(name, waveform, rng):
    scene = hard_cases(pixels=10, waveform=waveform)[name]
    matrix = system_matrix(scene)
    wave = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    picks, row_max = _picks(matrix, scene, rng)
    if name == "far":
        picks = picks[:2]
    for row, pixel in picks:
        reference = _reference(scene, wave, row, pixel)
        error = abs(matrix[row, pixel] - reference) / row_max[row]
        assert error <= TOLERANCE, (name, waveform, row, pixel, matrix[row, pixel], reference)


@pytest.mark.parametrize("waveform", ["impulse", "butterworth"])
def test_default_scene_entries_match_reference(waveform, rng):
    scene = default_scene().replace(illumination=default_scene().illumination.__class__(waveform=waveform))
    matrix = system_matrix(scene)
    wave = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    picks, row_max = _picks(matrix, scene, rng)
    for row, pixel in picks[:6]:
        reference = _reference(scene, wave, row, pixel)
        assert abs(matrix[row, pixel] - reference) <= TOLERANCE * row_max[row]


def test_samples_match_reference_sum_over_pixels(rng):
    """y = A f on a small low-source scene: each sensor's largest sample against
    the reference summed over every pixel it sees."""
    scene = hard_cases(pixels=4)["low"]
    image = rng.uniform(0.1, 1.0, size=(4, 4))
    scene = scene.replace(reflectance=image)
    matrix = system_matrix(scene)
    y = (matrix @ image.ravel()).reshape(scene.sensor_count, -1)
    wave = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    for k in range(scene.sensor_count):
        n = int(np.argmax(y[k]))
        row = k * scene.sampling.count + n
        pixels = np.nonzero(matrix[[row], :].toarray().ravel())[0]
        reference = sum(image.ravel()[p] * _reference(scene, wave, row, p) for p in pixels)
        assert abs(y[k, n] - reference) <= TOLERANCE * y[k].max()


def test_tolerance_setting_converges():
    """Self-convergence of the model's one discretisation setting: each looser
    tolerance is met against a much tighter assembly, and the error shrinks."""
    scene = hard_cases(pixels=8, waveform="butterworth")["outside"]
    finest = system_matrix(scene, tolerance=1e-7)
    row_max = finest.max(axis=1).toarray().ravel()
    row_max[row_max == 0] = 1.0
    errors = []
    for tolerance in (1e-2, 1e-3, 1e-4, 1e-5):
        matrix = system_matrix(scene, tolerance=tolerance)
        difference = abs(matrix - finest).max(axis=1).toarray().ravel() / row_max
        errors.append(difference.max())
        assert difference.max() <= tolerance
    assert errors[-1] < errors[0]
