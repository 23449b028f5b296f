"""A smooth pulse's truncated tails are no breakpoints for the exact derivatives' quadrature.

analytic.waveforms.pieces.without_tail_kinks clears the kinks where a pulse is only cut off (s and its
slope below 1e-12 of the peak on both sides); the columns must not move beyond the scene's tolerance,
and a real breakpoint (a square's edges, a Butterworth's start) must stay one.
"""

import numpy as np
import pytest

import analytic.operator.relay_wall_offsets as offsets_route
import analytic.operator.waveform_sensitivity as waveform_route
from analytic.operator.derivatives import jacobian
from analytic.scenes.common import Illumination, Sampling, default_scene
from analytic.waveforms import make_waveform
from analytic.waveforms.pieces import derivative_array, without_tail_kinks
from relay_capture import capture


@pytest.mark.parametrize("illumination", [Illumination(waveform="gaussian", fwhm=0.02),
                                          Illumination(waveform="sech2", fwhm=0.03)])
def test_a_smooth_pulses_truncation_points_are_no_kinks(illumination):
    terms = make_waveform(illumination, 0.01).terms
    cleared = without_tail_kinks(terms)
    ends = [np.argmin(np.abs(terms.starts - terms.lead)), np.argmin(np.abs(terms.starts - terms.duration))]
    assert terms.kinks[ends].all() and not cleared.kinks.any()
    # s really is negligible there: the jump the quadrature no longer cuts at
    assert np.all(derivative_array(terms, terms.starts[ends] + [1e-9, -1e-9]) < 1e-12)


@pytest.mark.parametrize("illumination", [Illumination(waveform="square", width=0.05),
                                          Illumination(waveform="butterworth", cutoff=50.0)])
def test_a_real_breakpoint_stays_one(illumination):
    terms = make_waveform(illumination, 0.01).terms
    assert terms.kinks.any()
    assert np.array_equal(without_tail_kinks(terms).kinks, terms.kinks)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["plane", "relay wall"])
def test_the_columns_do_not_move_beyond_the_tolerance(tmp_path, monkeypatch, kind):
    if kind == "plane":
        scene = default_scene(pixels=6, noise=None, sensors=[[0.3, 0.6, 0.5]],
                              sampling=Sampling(bin_width_opl=0.03, start_opl=1.4, count=30),
                              illumination=Illumination(waveform="gaussian", fwhm=0.05))
        keys = ["sampling.start", "source.position.x", "sensors.positions.0.z", "illumination.fwhm"]
    else:
        scene = capture(tmp_path, scan='type = "confocal"\ngrid = [2, 2]', start=1.51,
                        light='waveform = "gaussian"\nfwhm = 0.05')
        keys = ["sampling.start", "hidden.center.z", "hidden.rotation.x", "hidden.u.x", "illumination.fwhm"]
    cleared = jacobian(scene, keys)
    for module in (offsets_route, waveform_route):
        monkeypatch.setattr(module, "without_tail_kinks", lambda terms: terms)
    kept = jacobian(scene, keys)
    scale = np.abs(kept).max(axis=1, keepdims=True)
    assert np.all(np.abs(cleared - kept) <= 1e-6 * scale)
