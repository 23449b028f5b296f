"""The renderer with the measured-response waveforms: Dr.Jit's S(u) is the model's, and renders agree with the model.

S(u) and the kernels in NumPy, Numba and Dr.Jit agree to 1e-12 (of the
area; each kernel to its own size); a render of each new waveform agrees
with the exact model by the replicas' test (render_checks.agreement),
and a model with another pulse width, or one bin late, fails it.
"""

from __future__ import annotations

import numpy as np
import pytest
from render_checks import agreement, model

from analytic.scenes.common import Illumination
from analytic.waveforms import make_waveform
from analytic.waveforms.pieces import kernel_array
from compiled_kernels import compiled_cumulative, compiled_kernels
from deposited_kernels import deposited_kernels, traced_cumulative
from transient.render import render

RNG_SAMPLES = np.random.default_rng(4).uniform(0.0, 1.0, 24) * np.hanning(24)      # > 8 pieces: the gather path
ILLUMINATIONS = {
    "gaussian": Illumination(waveform="gaussian", fwhm=0.08),
    "emg": Illumination(waveform="emg", fwhm=0.05, tail=0.03),
    "sech2": Illumination(waveform="sech2", fwhm=0.06),
    "sampled": Illumination(waveform="sampled", samples=RNG_SAMPLES, sample_width=0.01, start=-0.04),
    "sampled, 3 samples": Illumination(waveform="sampled", samples=[0.0, 1.0, 0.4], sample_width_ps=100.0),
}


@pytest.mark.parametrize("name", list(ILLUMINATIONS))
def test_cumulative_and_kernels_agree_in_numpy_numba_and_drjit(mitsuba, rng, name):
    waveform = make_waveform(ILLUMINATIONS[name], 0.05)
    terms = waveform.terms
    span = waveform.duration - waveform.lead
    u = np.concatenate([rng.uniform(waveform.lead - 0.2 * span, waveform.duration + 0.2 * span, 3000),
                        np.asarray(terms.starts), [0.0, -0.0, 1e-300]])
    expected = waveform.cumulative(u)
    compiled = compiled_cumulative(terms, u)
    traced = traced_cumulative(mitsuba, terms, u)
    area = waveform.energy
    assert np.max(np.abs(compiled - expected)) <= 1e-14 * area
    assert np.max(np.abs(traced - expected)) <= 1e-14 * area
    floor = 1e-15 * area        # kernels beyond the pulse are rounding on every side
    for width in rng.uniform(0.0, 0.1 * span, 4):           # the deposit's bins are of one width
        upper = u + width
        kernels = kernel_array(terms, u, upper)
        compiled = compiled_kernels(terms, u, upper)
        traced = deposited_kernels(mitsuba, terms, u, width)
        assert np.all(np.abs(compiled - kernels) <= 1e-12 * np.abs(kernels) + floor)
        assert np.all(np.abs(traced - kernels) <= 1e-12 * np.abs(kernels) + floor)


# the EMG's render (~25 s) under -m slow; its Dr.Jit deposit is held to the model's kernels by default above
@pytest.mark.parametrize("name", ["gaussian", pytest.param("emg", marks=pytest.mark.slow), "sech2", "sampled"])
def test_renders_agree_with_the_model(scene, name):
    shaped = scene.replace(illumination=ILLUMINATIONS[name])
    result = render(shaped, spp=2**20, seed=12, progress=False)
    expected = model(shaped)
    chi2_per_dof, largest, dof, passes = agreement(result.mean, result.stderr, expected, result.dof,
                                                   replicas=result.replica_means)
    assert dof >= 50
    assert passes, f"{name}: chi2/dof {chi2_per_dof:.3f}, max|z| {largest:.2f} over {dof} bins"
    *_, late = agreement(result.mean, result.stderr, np.roll(expected, 1, axis=1), result.dof,
                         replicas=result.replica_means)
    assert not late
    if name != "sampled":
        wider = scene.replace(illumination=Illumination(waveform=name, fwhm=1.5 * ILLUMINATIONS[name].fwhm,
                                                        tail=ILLUMINATIONS[name].tail))
        *_, wide = agreement(result.mean, result.stderr, model(wider), result.dof, replicas=result.replica_means)
        assert not wide
