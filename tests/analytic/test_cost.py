"""The model's cost before it is paid: counts against independent ones, and the refusal of illuminations
whose exact model would take hours (issue 38: a 100,000-sample response, pulses of 400 to 7,000 m on 1 cm bins).

The entries are held to :func:`analytic.operator.system.count_entries` (the assembly's own exact count, another
code path) on scenes small enough that every (pixel, pair) is sampled; the breakpoints to a double loop.
"""

import numpy as np
import pytest

from analytic.operator.cost import _breakpoints, impractical_illumination, model_cost, refuse_impractical_illumination
from analytic.errors import SceneError
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import Illumination, Sampling, Scene
from analytic.operator.system import count_entries
from analytic.operator.window import auto_sampling, response_range


def _brute_breakpoints(kinks, start, width, first, bins, low, high):
    edges = [start + width * n for n in range(first, first + bins + 1)]
    return sum(1 for t in edges for b in kinks if low < t - b < high)


@pytest.mark.parametrize("kinks, bins", [(7, 3), (3, 40), (200, 12), (1, 1)])
def test_breakpoints_are_the_edges_minus_kinks_in_range(rng, kinks, bins):
    for _ in range(20):
        b = np.sort(rng.uniform(-0.5, 0.5, kinks))
        start, width, first = rng.uniform(1.0, 2.0), rng.uniform(0.01, 0.2), int(rng.integers(0, 5))
        low = start + width * first + rng.uniform(-0.3, 0.3)
        high = low + rng.uniform(0.0, 0.6)
        assert _breakpoints(b, start, width, first, bins, low, high) == \
            _brute_breakpoints(b, start, width, first, bins, low, high)


ILLUMINATIONS = {
    "impulse": Illumination(),
    "gaussian": Illumination(waveform="gaussian", fwhm=0.3),
    "emg": Illumination(waveform="emg", fwhm=0.01, tail=0.2),
    "sampled": Illumination(waveform="sampled", samples=list(np.hanning(50)), sample_width=2e-3),
}


@pytest.mark.parametrize("name", sorted(ILLUMINATIONS))
def test_entries_are_the_assemblys_own_count_when_every_pixel_is_sampled(name):
    scene = Scene(pixels=6, sensors=[[0.2, 0.7, 1.0], [0.9, 0.1, 0.6]], illumination=ILLUMINATIONS[name],
                  sampling=Sampling(bin_width_opl=0.05, start_opl=1.5, count=60))
    cost = model_cost(scene)
    assert cost.entries == np.sum(count_entries(scene))
    assert cost.memory >= 12 * cost.entries and cost.seconds > 0
    assert impractical_illumination(scene, cost) is None


def test_a_relay_wall_capture_counts_its_pairs():
    scene = RelayWallScene(pixels=5, scan=Scan(type="confocal", grid=(2, 2)),
                           illumination=Illumination(waveform="gaussian", fwhm=0.05),
                           sampling=Sampling(bin_width_opl=0.02, start_opl=1.8, count=100))
    assert model_cost(scene).entries == np.sum(count_entries(scene))


def _plane(illumination, *, period=0.01, start=2.0, count=120):
    return Scene(pixels=8, sensors=[[0.2, 0.7, 1.0]], illumination=illumination,
                 sampling=Sampling(bin_width_opl=period, start_opl=start, count=count))


def _auto(scene):
    return scene.replace(sampling=auto_sampling(scene))


@pytest.mark.parametrize("make, cause", [
    # issue 38's four, and variants of each class
    (lambda: _plane(Illumination(waveform="sampled", samples=list(np.hanning(100_000)), sample_width=1e-6)),
     "cut each pixel's range of path lengths"),
    (lambda: _plane(Illumination(waveform="sampled", samples=list(np.hanning(60_000)), sample_width=2e-6),
                    period=0.005, count=240), "cut each pixel's range of path lengths"),
    (lambda: _auto(_plane(Illumination(waveform="gaussian", fwhm=1000.0))), "the pulse spans"),
    (lambda: _auto(_plane(Illumination(waveform="gaussian", fwhm=300.0), period=0.02)), "the pulse spans"),
    (lambda: _auto(_plane(Illumination(waveform="emg", fwhm=10.0, tail=100.0))), "the pulse spans"),
    (lambda: _auto(_plane(Illumination(waveform="emg", fwhm=0.001, tail=10.0))), "the pulse spans"),
    (lambda: _auto(_plane(Illumination(waveform="emg", fwhm=0.01, tail=30.0), period=0.02)), "the pulse spans"),
])
def test_an_illumination_that_makes_the_model_take_hours_is_refused_with_its_estimate(make, cause):
    scene = make()
    with pytest.raises(SceneError) as caught:
        refuse_impractical_illumination(scene)
    message = str(caught.value)
    assert caught.value.key.startswith("illumination.") and cause in message and "\n" not in message
    assert "the exact model would take about" in message and "GiB" in message
    assert "sampling.period of at least" in message or "more coarsely" in message


def test_a_response_beyond_the_windows_reach_names_the_span_that_reaches_it():
    # 100,000 samples over 10 m from -3 m on a window of 0.12 m: only the response between t_0 - max d and
    # t_N - min d can reach one of its bins; with small pixels, listing every sample at every bin is what
    # the model pays for
    illumination = Illumination(waveform="sampled", samples=list(np.hanning(100_000)), sample_width=1e-4,
                                start=-3.0)
    sampling = Sampling(bin_width_opl=1e-3, start_opl=2.0, count=120)
    scene = Scene(pixels=8, sensors=[[0.2, 0.7, 1.0]], illumination=illumination, sampling=sampling)
    lowest, highest = response_range(scene)          # exact, over the whole plane
    assert model_cost(scene).reach == pytest.approx((2.0 - highest, 2.12 - lowest), rel=1e-12)
    problem = impractical_illumination(scene.replace(pixels=64, reflectance=0.5))
    assert problem is not None and "keep only the samples in that span" in problem


def test_the_python_api_refuses_what_the_commands_refuse(monkeypatch):
    """analytic.forward (system_matrix) refuses an impractical illumination up front, in the commands' words."""
    import analytic
    import analytic.operator.cost as cost

    monkeypatch.setattr(cost, "available_memory", lambda: 16 * 2**30)   # the words name it: one value for both

    scene = _plane(Illumination(waveform="sampled", samples=list(np.hanning(100_000)), sample_width=1e-6))
    with pytest.raises(SceneError) as expected:
        refuse_impractical_illumination(scene)
    with pytest.raises(SceneError) as caught:
        analytic.forward(scene)
    assert str(caught.value) == str(expected.value)
