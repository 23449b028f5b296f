"""The time window: which path lengths the plane sends to the sensors, and how much light a window holds.

Path length d(x) = |x − p_s| + |x − p_k| is convex on the plane, so its
range over the plane is exact: the maximum at a corner, the minimum at the
first-arrival point or on an edge (:func:`analytic.isochrone.rectangle_range`).
A window [t0, t0 + N T) holds all the light when it covers
[min d, max d + pulse duration]; otherwise the share it holds is the ratio of
two one-bin models, since the box prefilter is additive over adjacent bins:
the bin that is the whole window over the bin that covers every path.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from .geometry import PointPairs, Rectangle, pair_table, plane_geometry
from .isochrone import LAMBERTIAN, PixelBox, pair_frame, rectangle_range
from .scene import Sampling, Scene

__all__ = ["response_range", "pairs_range", "covering_sampling", "window_share", "warn_if_cut", "WindowWarning", "FULL_SHARE"]

#: The share of the light a window must hold not to be warned about.
FULL_SHARE = 0.999


class WindowWarning(UserWarning):
    """The time window cuts the response: some of the light falls outside its bins."""


def response_range(scene: Scene) -> tuple[float, float]:
    """(first, last) path length from the source over the plane to any sensor, metres (exact)."""
    rectangle, pairs = plane_geometry(scene)
    return pairs_range(rectangle, pairs)


def pairs_range(rectangle: Rectangle, pairs: PointPairs) -> tuple[float, float]:
    """(first, last) path length over the rectangle of any pair, its added length included, metres (exact)."""
    whole = PixelBox(0.0, rectangle.width, 0.0, rectangle.height)
    low, high = math.inf, -math.inf
    for pair in pair_table(rectangle, pairs):
        first, last = rectangle_range(pair_frame(pair, LAMBERTIAN), whole)
        low, high = min(low, float(first) + pair["offset"]), max(high, float(last) + pair["offset"])
    return low, high


def covering_sampling(scene: Scene, bin_width_opl: float, *, margin: int = 0) -> Sampling:
    """Bins of width T holding every path length and the pulse's tail, on the grid t0 = j T.

    Parameters
    ----------
    scene : Scene
        Geometry and illumination.
    bin_width_opl : float
        T, metres of path length.
    margin : int
        Empty bins added before the first arrival and after the last light.
    """
    from .waveforms import make_waveform

    low, high = response_range(scene)
    waveform = make_waveform(scene.illumination, bin_width_opl)
    longest = high + waveform.duration
    start = (math.floor((low + waveform.lead) / bin_width_opl) - margin) * bin_width_opl
    count = int(math.floor((longest - start) / bin_width_opl)) + 1 + margin
    return Sampling(bin_width_opl=bin_width_opl, start_opl=start, count=count)


def window_share(scene: Scene) -> float:
    """Share of the light reaching the sensors that the scene's window holds.

    1.0 exactly when the window covers every path and the pulse's tail;
    otherwise Σ_k y_k(window) / Σ_k y_k(all), both from one-bin models of
    the scene's own reflectance and attenuation: the window as one bin
    (the box prefilter is additive over adjacent bins), and all the light
    as the pulse's energy ∫ s dt times the impulse's one bin that holds
    every path (so a pulse of any length needs no bin longer than the paths).
    """
    from .scene import Illumination
    from .system import forward
    from .waveforms import make_waveform

    sampling = scene.sampling
    low, high = response_range(scene)
    waveform = make_waveform(scene.illumination, sampling.bin_width_opl)
    end = sampling.start_opl + sampling.count * sampling.bin_width_opl
    if sampling.start_opl <= low + waveform.lead and end >= high + waveform.duration:
        return 1.0
    if end <= low + waveform.lead:
        return 0.0
    margin = 1e-6 * max(high - low, abs(high))
    paths = Sampling(bin_width_opl=(high - low) + 2 * margin, start_opl=low - margin, count=1)
    window = Sampling(bin_width_opl=sampling.count * sampling.bin_width_opl, start_opl=sampling.start_opl,
                      count=1)
    # the one-bin window's pulse must be the scene's, whose defaults follow the scene's period
    pinned = Illumination(waveform=scene.illumination.waveform, **waveform.parameters)
    total = waveform.energy * float(np.sum(forward(scene.replace(sampling=paths,
                                                                 illumination=Illumination()))))
    held = float(np.sum(forward(scene.replace(sampling=window, illumination=pinned))))
    return held / total if total > 0 else 0.0


def warn_if_cut(scene: Scene, share: float) -> None:
    """One-line :class:`WindowWarning` when the window holds less than :data:`FULL_SHARE`."""
    if share < FULL_SHARE:
        low, high = response_range(scene)
        warnings.warn(f"the window [{scene.sampling.start_opl:g}, "
                      f"{scene.sampling.start_opl + scene.sampling.count * scene.sampling.bin_width_opl:g}) m "
                      f"holds {100 * share:.2f} % of the light (paths span [{low:.4g}, {high:.4g}] m plus "
                      f"the pulse); widen [sampling] start/count", WindowWarning, stacklevel=2)
