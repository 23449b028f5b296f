"""An independent reference for the illumination waveforms' cumulative S(u).

Shares nothing with ``analytic``: the Butterworth pulse is built here from
its definition (poles on a circle of radius ω_c in the left half-plane) as a
chain of first-order sections in state-space form, x' = A x + B u,
h(t) = C e^{At} B, and evaluated with mpmath at 50 significant digits:

    ∫_0^v h(t) dt = C A⁻¹ (e^{Av} − I) B

(A is invertible: no pole at 0). The unit-peak scale is the maximum of h on
[0, duration]: a grid march of e^{A Δt} finds its neighbourhood, and the
root of h'(t) = C A e^{At} B is polished by a bracketing solver. The code
under test uses partial fractions (residues) instead.
"""

from __future__ import annotations

import functools
import math

import mpmath
import numpy as np

__all__ = ["reference_cumulative", "ButterworthReference"]

_DIGITS = 40


class ButterworthReference:
    """The truncated, unit-peak Butterworth pulse of docs/design.md section 2, in mpmath.

    Parameters
    ----------
    order : int
        Filter order n.
    cutoff : float
        -3 dB cutoff, cycles per metre of path length (ω_c = 2π cutoff).
    duration : float
        Truncation: s(t) = 0 for t > duration, metres.
    """

    def __init__(self, order: int, cutoff: float, duration: float):
        with mpmath.workdps(_DIGITS):
            self.order = int(order)
            self.omega = 2 * mpmath.pi * mpmath.mpf(cutoff)
            self.duration = mpmath.mpf(duration)
            n = self.order
            poles = [self.omega * mpmath.exp(1j * mpmath.pi * (2 * k + n - 1) / (2 * n))
                     for k in range(1, n + 1)]
            self.slowest = min(-mpmath.re(p) for p in poles)        # smallest decay rate, 1/m
            self.a = mpmath.matrix(n, n)
            for i, pole in enumerate(poles):
                self.a[i, i] = pole
                if i > 0:
                    self.a[i, i - 1] = 1
            self.b = mpmath.matrix(n, 1)
            self.b[0] = 1
            self.c = mpmath.matrix(1, n)
            self.c[n - 1] = self.omega ** n
            # beyond this time e^{At} is below 1e-60 of its start: the pulse is over
            self.settled = mpmath.mpf(140) / self.slowest
            self.peak_time, self.peak = self._peak()

    def _response(self, state):
        return mpmath.re((self.c * state)[0])

    def _peak(self):
        end = min(self.duration, self.settled)
        steps = 800
        dt = end / steps
        step = mpmath.expm(self.a * dt)
        state = self.b.copy()
        best, best_index = self._response(state), 0
        for i in range(1, steps + 1):
            state = step * state
            value = self._response(state)
            if value > best:
                best, best_index = value, i
        if best_index == steps:     # rising up to the truncation: the peak is h(duration)
            return end, best
        if best_index == 0:         # order 1: falling from t = 0
            return mpmath.mpf(0), best

        # h' > 0 before the peak and < 0 after it: Newton on h' (h'' from A² e^{At}),
        # kept inside the shrinking bracket, falling back to bisection. Stopped at 1e-25 of the time: h'
        # at 40 digits cancels to noise near 1e-27 of it at order 20, below which the bracket only
        # bisected on that noise (14 more matrix exponentials, 10 s); float64 resolves 1e-16.
        low, high = (best_index - 1) * dt, (best_index + 1) * dt
        time = best_index * dt
        for _ in range(60):
            state = mpmath.expm(self.a * time) * self.b
            first = mpmath.re((self.c * self.a * state)[0])
            second = mpmath.re((self.c * self.a * self.a * state)[0])
            if first > 0:
                low = time
            else:
                high = time
            step = time - first / second if second < 0 else (low + high) / 2
            step = step if low < step < high else (low + high) / 2
            if abs(step - time) <= mpmath.mpf(10) ** (-25) * high:
                time = step
                break
            time = step
        return time, self._response(mpmath.expm(self.a * time) * self.b)

    def cumulative(self, u: float) -> float:
        """S(u) = ∫_0^min(u, duration) h / peak, metres (0 for u <= 0)."""
        with mpmath.workdps(_DIGITS):
            v = min(mpmath.mpf(u), self.duration, self.settled)
            if v <= 0:
                return 0.0
            identity = mpmath.eye(self.order)
            integral = self.c * mpmath.lu_solve(self.a, (mpmath.expm(self.a * v) - identity) * self.b)
            return float(mpmath.re(integral[0]) / self.peak)

    def kernel(self, lower: float, upper: float) -> float:
        """∫_lower^upper s(t) dt in mpmath (no difference of two rounded S), metres."""
        with mpmath.workdps(_DIGITS):
            end = min(self.duration, self.settled)
            a = min(max(mpmath.mpf(lower), 0), end)
            b = min(max(mpmath.mpf(upper), 0), end)
            if not b > a:
                return 0.0
            change = mpmath.expm(self.a * b) - mpmath.expm(self.a * a)
            integral = self.c * mpmath.lu_solve(self.a, change * self.b)
            return float(mpmath.re(integral[0]) / self.peak)

    def intensity(self, t: float) -> float:
        """s(t) = h(t) / peak on [0, duration], 0 elsewhere."""
        with mpmath.workdps(_DIGITS):
            t = mpmath.mpf(t)
            if t < 0 or t > self.duration:
                return 0.0
            return float(self._response(mpmath.expm(self.a * min(t, self.settled)) * self.b) / self.peak)


@functools.lru_cache(maxsize=64)
def _butterworth(order: int, cutoff: float, duration: float) -> ButterworthReference:
    return ButterworthReference(order, cutoff, duration)


def reference_cumulative(waveform: str, u, *, period: float, width: float | None = None,
                         cutoff: float | None = None, duration: float | None = None,
                         order: int | None = None) -> np.ndarray:
    """S(u) of a scene's illumination from its definition (docs/design.md sections 2 and 5).

    Parameters
    ----------
    waveform : {"impulse", "square", "butterworth"}
    u : array_like
        Time after the pulse starts, metres of path length.
    period : float
        Sampling period T, metres: sets the documented defaults (square width
        T/5; Butterworth cutoff 1/(2T), duration 3/cutoff, order 3).
    width, cutoff, duration, order
        The scene's ``[illumination]`` values, None for the default.

    Returns
    -------
    numpy.ndarray
        float64, the shape of ``u``.
    """
    u = np.asarray(u, dtype=np.float64)
    if waveform == "impulse":
        return (u > 0).astype(np.float64)
    if waveform == "square":
        width = period / 5.0 if width is None else width
        return np.clip(u, 0.0, width)
    if waveform != "butterworth":
        raise ValueError(f"unknown waveform {waveform!r}")
    cutoff = 0.5 / period if cutoff is None else cutoff
    duration = 3.0 / cutoff if duration is None else duration
    order = 3 if order is None else order
    pulse = _butterworth(int(order), float(cutoff), float(duration))
    return np.vectorize(pulse.cumulative, otypes=[np.float64])(u)


def _self_check() -> None:
    # order 1: h = ω e^{-ωt}, peak ω at 0, S(u) = (1 - e^{-ωu}) / ω
    pulse = ButterworthReference(1, 1.0, 10.0)
    omega = 2 * math.pi
    for u in (0.01, 0.3, 2.0):
        assert math.isclose(pulse.cumulative(u), -math.expm1(-omega * u) / omega, rel_tol=1e-13)


if __name__ == "__main__":
    _self_check()
    print("ok")
