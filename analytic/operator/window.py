"""The time window: which path lengths the plane sends to the sensors, and how much light a window holds.

Path length d(x) = |x − p_s| + |x − p_k| is convex on the plane, so its
range over the plane is exact: the maximum at a corner, the minimum at the
first-arrival point or on an edge (:func:`analytic.kernels.isochrone.rectangle_range`).
The same holds for any scene's geometry (:meth:`analytic.scenes.common.Scene.geometry`): a relay-wall
capture's hidden rectangle with the lit and read wall points as the foci, each
pair's counted laser and sensor legs added (docs/design.md section 7).
A window [t0, t0 + N T) holds all the light when it covers
[min d, max d + pulse duration]; otherwise the share it holds is the ratio of
two one-bin models, since the box prefilter is additive over adjacent bins:
the bin that is the whole window over the bin that covers every path.

Two warnings (:class:`WindowWarning`, one line each) say when a window
changes what its numbers mean: it cuts the light (:func:`warn_if_cut`), or,
holding it all, more than half of its bins receive none
(:func:`warn_if_mostly_empty`);
each names the window that covers the light at the same period
(:func:`covering_sampling`, what ``--window auto`` takes).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..geometry import PointPairs, Rectangle, pair_table
from ..kernels.formulas import LAMBERTIAN
from ..kernels.isochrone import table_ranges
from ..scenes.common import Sampling, Scene, SceneError

__all__ = ["response_range", "pairs_range", "covering_sampling", "auto_sampling", "window_share", "empty_bins",
           "warn_if_cut", "warn_if_mostly_empty", "WindowWarning", "FULL_SHARE", "impulse_totals"]

#: The share of the light a window must hold not to be warned about.
FULL_SHARE = 0.999


class WindowWarning(UserWarning):
    """The time window cuts the response (some light falls outside its bins), or most of its bins hold none."""


def response_range(scene: Scene) -> tuple[float, float]:
    """(first, last) path length from the source over the plane to any sensor, metres (exact).

    For a relay-wall capture (:class:`analytic.scenes.relay_wall.RelayWallScene`): from a lit point over the
    hidden rectangle to a read point, plus |o_l - l| + |s - o_s| when the scan counts those legs.
    """
    return pairs_range(*scene.geometry())


def pairs_range(rectangle: Rectangle, pairs: PointPairs) -> tuple[float, float]:
    """(first, last) path length over the rectangle of any pair, its added length included, metres (exact)."""
    table = pair_table(rectangle, pairs)
    if table.size == 0:
        return math.inf, -math.inf
    ranges = table_ranges(table, np.array([[0.0, rectangle.width, 0.0, rectangle.height]]), LAMBERTIAN)[:, 0]
    return float(np.min(ranges[:, 0] + table["offset"])), float(np.max(ranges[:, 1] + table["offset"]))


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

    Raises
    ------
    SceneError
        When no window of this period can be made to cover the light (a
        pulse so long that its bins would not be numbers, or beyond what
        :class:`~analytic.scenes.common.Sampling` accepts).
    """
    from ..waveforms import make_waveform

    low, high = response_range(scene)
    waveform = make_waveform(scene.illumination, bin_width_opl)
    earliest, longest = float(low) + waveform.lead, float(high) + waveform.duration
    first, last = earliest / bin_width_opl, longest / bin_width_opl
    if not (math.isfinite(first) and math.isfinite(last)):
        raise SceneError("sampling.period", f"light from {earliest:.6g} to {longest:.6g} m takes more than "
                                            f"1e308 bins of {bin_width_opl:g} m; no window covers it")
    start = (math.floor(first) - margin) * bin_width_opl
    count = int(math.floor((longest - start) / bin_width_opl)) + 1 + margin
    return Sampling(bin_width_opl=bin_width_opl, start_opl=start, count=count)


def auto_sampling(scene: Scene) -> Sampling:
    """The scene's window replaced by the bins that cover its light at the scene's own period.

    :func:`covering_sampling` at ``scene.sampling.bin_width_opl``, no
    margin: the first bin holds the first arrival (the pulse's lead
    included), the last the longest path plus the pulse, on the grid
    t0 = j T (``--window auto``).
    """
    return covering_sampling(scene, scene.sampling.bin_width_opl)


def _light_span(scene: Scene) -> tuple[float, float]:
    """(earliest, latest) path length at which light reaches any sensor, the pulse included, metres."""
    from ..waveforms import make_waveform

    low, high = response_range(scene)
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    return low + waveform.lead, high + waveform.duration


def empty_bins(scene: Scene) -> int:
    """How many bins of the scene's window no light reaches: those wholly before the first arrival or
    after the longest path plus the pulse (exact; the reflectance is not looked at).

    Bin n covers [t0 + n T, t0 + (n + 1) T) and receives light when it
    overlaps the open span (earliest, latest) of :func:`_light_span`.
    """
    earliest, latest = _light_span(scene)
    edges = scene.sampling.edges
    lit = (edges[:-1] < latest) & (edges[1:] > earliest)
    return int(scene.sampling.count - np.count_nonzero(lit))


def _window_text(sampling: Sampling) -> str:
    # + 0.0: a start of -0.0 reads as 0
    end = sampling.start_opl + sampling.count * sampling.bin_width_opl
    return f"[{sampling.start_opl + 0.0:g}, {end + 0.0:g}) m"


def _covering_text(scene: Scene) -> str:
    """"start = 2, count = 10 covers the light at the same period (what --window auto takes)"."""
    try:
        covering = auto_sampling(scene)
    except SceneError as error:
        return f"no window of this period covers it ({error.problem})"
    return (f"[sampling] start = {covering.start_opl:.12g}, count = {covering.count} covers the light at the "
            f"same period (what --window auto takes)")


def window_share(scene: Scene) -> float:
    """Share of the light reaching the sensors that the scene's window holds.

    1.0 exactly when the window covers every path and the pulse's tail;
    otherwise Σ_k y_k(window) / Σ_k y_k(all), both from one-bin models of
    the scene's own reflectance and attenuation: the window as one bin
    (the box prefilter is additive over adjacent bins), and all the light
    as the pulse's energy ∫ s dt times the impulse's one bin that holds
    every path (so a pulse of any length needs no bin longer than the paths).
    """
    from ..scenes.common import Illumination
    from .matrix_free import forward
    from ..waveforms import make_waveform

    sampling = scene.sampling
    low, high = response_range(scene)
    waveform = make_waveform(scene.illumination, sampling.bin_width_opl)
    end = sampling.start_opl + sampling.count * sampling.bin_width_opl
    if sampling.start_opl <= low + waveform.lead and end >= high + waveform.duration:
        return 1.0
    if end <= low + waveform.lead:
        return 0.0
    window = Sampling(bin_width_opl=sampling.count * sampling.bin_width_opl, start_opl=sampling.start_opl,
                      count=1)
    # the one-bin window's pulse must be the scene's, whose defaults follow the scene's period
    pinned = Illumination(waveform=scene.illumination.waveform, **waveform.parameters)
    total = waveform.energy * float(np.sum(impulse_totals(scene)))
    held = float(np.sum(forward(scene.replace(sampling=window, illumination=pinned))))
    return held / total if total > 0 else 0.0


def impulse_totals(scene: Scene) -> np.ndarray:
    """Per sensor (or pair), all the light of an impulse over every path: ``(K,)``, W/sr x m⁻¹ of y's unit.

    The one-bin impulse model whose bin holds every path length (:func:`response_range`, widened by
    a millionth); a bin of the scene's y, of any pulse of unit peak, is at most this times
    min(T, ∫|s| dt) (the bin's kernel is ∫_bin s, |s| <= 1), or this for the impulse.
    """
    from ..scenes.common import Illumination
    from .matrix_free import forward

    low, high = response_range(scene)
    margin = 1e-6 * max(high - low, abs(high))
    paths = Sampling(bin_width_opl=(high - low) + 2 * margin, start_opl=low - margin, count=1)
    return np.asarray(forward(scene.replace(sampling=paths, illumination=Illumination())), dtype=np.float64)[:, 0]


def warn_if_cut(scene: Scene, share: float) -> None:
    """One-line :class:`WindowWarning` when the window holds less than :data:`FULL_SHARE`."""
    if share < FULL_SHARE:
        low, high = response_range(scene)
        warnings.warn(f"the window {_window_text(scene.sampling)} holds {100 * share:.2f} % of the light (paths "
                      f"span [{low:.4g}, {high:.4g}] m plus the pulse); widen it: {_covering_text(scene)}",
                      WindowWarning, stacklevel=2)


def warn_if_mostly_empty(scene: Scene, share: float) -> int:
    """One-line :class:`WindowWarning` when more than half of the window's bins receive no light.

    Such bins hold nothing but what noise adds: they dilute every per-bin
    average (a χ²/dof, a residual norm) and cost time. A window that cuts
    the light (``share`` below :data:`FULL_SHARE`) is :func:`warn_if_cut`'s
    to warn about, with the same covering window: one line per problem.
    Returns the number of empty bins (:func:`empty_bins`).

    Parameters
    ----------
    scene : Scene
    share : float
        The share of the light the window holds (:func:`window_share`).
    """
    empty = empty_bins(scene)
    if share >= FULL_SHARE and 2 * empty > scene.sampling.count:
        low, high = response_range(scene)
        warnings.warn(f"the window {_window_text(scene.sampling)} is mostly empty: {empty} of its "
                      f"{scene.sampling.count} bins receive no light (paths span [{low:.4g}, {high:.4g}] m plus "
                      f"the pulse); {_covering_text(scene)}", WindowWarning, stacklevel=2)
    return empty
