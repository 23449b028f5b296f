"""Issue 22's second probe (its harness and promises: tests/probe/cli_probe.py): numbers at their limits: laws (y
proportional to I, y(s L) = y(L) / s², reciprocity) and the reference.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from probe.cli_reference import reference, reference_total
from probe.cli_probe import GOOD, case_table, case_test, forward


CASES, case = case_table()


@case("numbers", "intensity law: I = 1e-300, 1e-30, 3.5, 1e30 against I = 1",
      "exit 0 each; y / I equal to 1e-14 across I, and to the reference at I = 1")
def _(probe):
    base = forward(probe, probe.scene(GOOD, "one.toml")).answered() and probe.matches_reference(GOOD)
    for intensity in (1e-300, 1e-30, 3.5, 1e30):
        geometry = dataclasses.replace(GOOD, intensity=intensity)
        forward(probe, probe.scene(geometry, f"i{intensity:g}.toml"))
        # at 1e-300 the EXR is not written, with a one-line warning (README "Files")
        if probe.answered(warnings=True) and base is not None:
            probe.close(probe.y() / intensity, base, rtol=1e-14, what=f"y / I at I = {intensity:g}")


for _factor in (1e-8, 1e-6, 1e6, 1e9):
    @case("numbers", f"similarity: every length x {_factor:g}", "exit 0; y s² equal to y at s = 1 (rtol 1e-5)")
    def _(probe, factor=_factor):
        geometry = GOOD.scaled(factor)
        if forward(probe, probe.scene(geometry)).answered():
            expected, bound = reference(GOOD)
            probe.close(probe.y() * factor**2, expected, atol=bound, what="y s²")


@case("numbers", "reciprocity: source and sensor swapped (lambertian)", "exit 0; y equal to the unswapped (1e-6)")
def _(probe):
    swapped = dataclasses.replace(GOOD, source=GOOD.sensors[0], sensors=(GOOD.source,))
    forward(probe, probe.scene(GOOD, "a.toml"))
    first = probe.y() if probe.answered() else None
    forward(probe, probe.scene(swapped, "b.toml"))
    if probe.answered() and first is not None:
        probe.close(probe.y(), first, rtol=1e-6, atol=1e-9 * np.abs(first).max(), what="swapped y")


@case("numbers", "paper attenuation (eq. 1), two sensors", "exit 0; y equal to the midpoint reference of eq. 1")
def _(probe):
    geometry = dataclasses.replace(GOOD, attenuation="paper", sensors=((0.2, 0.7, 1.0), (0.9, 0.1, 0.4)),
                                   count=20, start=1.2)
    if forward(probe, probe.scene(geometry)).answered():
        probe.matches_reference(geometry)


@case("numbers", "one bin of 1e12 m from -5e11 m", "exit 0; y = the whole response I ∫ f a (1e-5)")
def _(probe):
    geometry = dataclasses.replace(GOOD, start=-5e11, period=1e12, count=1)
    if forward(probe, probe.scene(geometry)).answered():
        probe.close(probe.y()[:, 0], reference_total(geometry), rtol=1e-5, what="the one bin")


@case("numbers", "window far after the light (start 1e9)", "exit 0 with a one-line window warning; y = 0")
def _(probe):
    geometry = dataclasses.replace(GOOD, start=1e9)
    if forward(probe, probe.scene(geometry)).answered(warnings=True):
        probe.check(len(probe.lines) == 1 and "window" in probe.lines[0], f"warning {probe.lines}")
        y = probe.y()
        probe.check(y is not None and np.all(y == 0), "y is not 0 outside the light")


@case("numbers", "sensor at the source", "exit 0 (7 of 12 bins empty: a one-line warning); y equal to the reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, sensors=(GOOD.source,), start=1.9)
    if forward(probe, probe.scene(geometry)).answered(warnings=True):
        probe.matches_reference(geometry)


@case("numbers", "sensor 1e-6 m above the plane", "exit 0; total -> 2 ρ I cos θ_s / d_s² (the point's limit, 1e-4)")
def _(probe):
    geometry = dataclasses.replace(GOOD, sensors=((0.3, 0.6, 1e-6),), start=0.0, period=10.0, count=1)
    if forward(probe, probe.scene(geometry)).answered():
        d2 = 0.2**2 + 0.1**2 + 1.0
        limit = 2 * 0.5 * (1 / math.sqrt(d2)) / d2
        probe.close(probe.y()[0, 0], limit, rtol=1e-4, what="total under a low sensor")


@case("numbers", "source 1e-6 m above the plane, paper attenuation",
      "exit 0; total -> 2π ρ I / d_k² (eq. 1's limit, 1e-4)")
def _(probe):
    geometry = dataclasses.replace(GOOD, source=(0.4, 0.3, 1e-6), attenuation="paper", start=0.0, period=10.0,
                                   count=1)
    if forward(probe, probe.scene(geometry)).answered():
        d2 = 0.2**2 + 0.4**2 + 1.0
        probe.close(probe.y()[0, 0], 2 * math.pi * 0.5 / d2, rtol=1e-4, what="total under a low source")


@case("numbers", "grid [2, 2], extent 0.5", "exit 0; rows = the reference at centre ± W/2 (as a set)")
def _(probe):
    text = GOOD.toml().replace("positions = [[0.2, 0.7, 1.0]]", "grid = [2, 2]\nextent = 0.5\ncenter = [0.5, 0.5, 1.0]")
    if forward(probe, probe.file("scene.toml", text)).answered():
        points = tuple((x, y, 1.0) for x in (0.25, 0.75) for y in (0.25, 0.75))
        geometry = dataclasses.replace(GOOD, sensors=points)
        expected, bound = reference(geometry)
        y = probe.y()
        if y is not None and probe.check(y.shape == expected.shape, f"shape {y.shape}"):
            order = np.lexsort(expected.T[::-1])
            got = np.lexsort(y.T[::-1])
            probe.close(y[got], expected[order], atol=bound[order], what="grid rows")


@case("numbers", "grid [1, 1]", "exit 0; the one sensor at the centre")
def _(probe):
    text = GOOD.toml().replace("positions = [[0.2, 0.7, 1.0]]", "grid = [1, 1]\ncenter = [0.2, 0.7, 1.0]")
    if forward(probe, probe.file("scene.toml", text)).answered():
        probe.matches_reference(GOOD)


@case("numbers", "grid [32, 32]: 1024 sensors (the most)", "exit 0; y of shape (1024, 12), finite, ≥ 0", slow=True)
def _(probe):
    text = GOOD.toml().replace("positions = [[0.2, 0.7, 1.0]]", "grid = [32, 32]\ncenter = [0.5, 0.5, 1.0]")
    if forward(probe, probe.file("scene.toml", text)).answered():
        y = probe.y()
        probe.check(y is not None and y.shape == (1024, 12) and np.all(y >= 0), "y shape or sign")


@case("numbers", "two identical sensors", "exit 0; two equal rows, each the reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, sensors=GOOD.sensors * 2)
    if forward(probe, probe.scene(geometry)).answered():
        y = probe.matches_reference(geometry)
        probe.check(y is not None and np.array_equal(y[0], y[1]), "the rows differ")


@case("numbers", "pixels = 1", "exit 0; y equal to the reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, pixels=1)
    if forward(probe, probe.scene(geometry)).answered():
        probe.matches_reference(geometry)


@case("numbers", "square pulse of width 0.037", "exit 0; y equal to the reference (box of I over [d, d + w])")
def _(probe):
    geometry = dataclasses.replace(GOOD, waveform="square", width=0.037)
    if forward(probe, probe.scene(geometry)).answered():
        probe.matches_reference(geometry)


@case("numbers", "square pulse of width 1e-9", "exit 0; total = I w ∫ f a (1e-5)")
def _(probe):
    geometry = dataclasses.replace(GOOD, waveform="square", width=1e-9)
    if forward(probe, probe.scene(geometry)).answered():
        probe.close(probe.y().sum(), 1e-9 * reference_total(geometry)[0], rtol=1e-5, what="total")


@case("numbers", "butterworth order 1, cutoff 5, long duration",
      "exit 0; total = I/(2π fc) ∫ f a: s = exp(-2π fc t)")
def _(probe):
    text = GOOD.toml().replace('"impulse"', '"butterworth"\norder = 1\ncutoff = 5.0\nduration = 50.0') \
        .replace("count = 12", "count = 60")
    if forward(probe, probe.file("scene.toml", text)).answered(warnings=True):
        area = 1.0 / (2 * math.pi * 5.0)
        probe.close(probe.y().sum(), area * reference_total(GOOD)[0], rtol=1e-5, what="total")


@case("numbers", "butterworth order 20 (the most)", "exit 0; total = I ∫ s ∫ f a, ∫ s from the analogue filter")
def _(probe):
    from scipy import signal as scipy_signal

    cutoff, duration = 5.0, 4.0
    text = GOOD.toml().replace('"impulse"', f'"butterworth"\norder = 20\ncutoff = {cutoff}\nduration = {duration}') \
        .replace("count = 12", "count = 60")
    if forward(probe, probe.file("scene.toml", text)).answered(warnings=True):
        # the analogue filter's impulse response h: its peak on a fine grid, its integral to the
        # truncation from the step response
        b, a = scipy_signal.butter(20, 2 * math.pi * cutoff, analog=True)
        _, response = scipy_signal.impulse((b, a), T=np.linspace(0.0, duration, 20_001))
        _, step = scipy_signal.step((b, a), T=np.array([0.0, duration]))
        area = step[-1] / response.max()
        probe.close(probe.y().sum(), area * reference_total(GOOD)[0], rtol=1e-3, what="total")


@case("numbers", "poisson noise, photons = 1e25", "exit 0 with noisy y = y (to 1e-9), or a one-line refusal")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra='[noise]\nkind = "poisson"\nphotons = 1e25\n'))) \
            .refused_or_answered("noise.photons"):
        y, noisy = probe.y(), probe.y("transient_noisy.npy")
        probe.close(noisy, y, rtol=1e-9, what="noisy y")


@case("numbers", "poisson noise, photons = 1e-300", "exit 0, noisy y finite and ≥ 0, or a one-line refusal")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra='[noise]\nkind = "poisson"\nphotons = 1e-300\n'))) \
            .refused_or_answered("noise.photons"):
        noisy = probe.y("transient_noisy.npy")
        probe.check(noisy is not None and np.all(noisy >= 0), "noisy y negative")


@case("numbers", "gaussian sigma = 1e300", "exit 0, noisy y finite, or a one-line refusal")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra="[noise]\nsigma = 1e300\n"))).refused_or_answered("noise.sigma"):
        probe.y("transient_noisy.npy")


@case("numbers", "noise seed 2^32 - 1", "exit 0 with transient_noisy.npy")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra="[noise]\nseed = 4294967295\n"))).answered():
        probe.y("transient_noisy.npy")


@case("numbers", "pixels = 100000 (an image of 80 GB)", "exit 2, one line naming memory")
def _(probe):
    forward(probe, probe.scene(dataclasses.replace(GOOD, pixels=100000))).refused("memory")


@case("numbers", "tolerance 1e-10 (the finest)", "exit 0; y equal to the reference")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra="tolerance = 1e-10\n"))).answered():
        probe.matches_reference(GOOD)


test_case = case_test(CASES)
