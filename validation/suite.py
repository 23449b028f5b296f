"""Built-in scenes: the hard cases that the model and the renderer must both get right.

Each case isolates one way a forward model can go wrong: a peaked
attenuation (source or sensors 1e-3 L above the plane), a degenerate
ellipse family (source and sensor at one point: circles), grazing light, a
sensor outside the plane's footprint, a plane hundreds of lengths away
binned finer than its response's spread (float precision of path lengths),
bins from L/1000 to longer than the whole response, and a first-arrival bin
that catches only the point-sized start of the isochrones.
"""

from __future__ import annotations

import numpy as np

from analytic.reflectance import builtin_reflectance
from analytic.scene import Illumination, Sampling, Scene

__all__ = ["hard_cases", "response_range", "validation_suite"]


def response_range(source, sensor, size: float) -> tuple[float, float]:
    """(first, last) path length over the plane [0, L]², metres (by a dense grid; for set-up only)."""
    axis = np.linspace(0.0, size, 401)
    x, y = np.meshgrid(axis, axis)
    source = np.asarray(source, float)
    sensor = np.asarray(sensor, float)
    d = (np.sqrt((x - source[0]) ** 2 + (y - source[1]) ** 2 + source[2] ** 2)
         + np.sqrt((x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2))
    ratio = source[2] / (source[2] + sensor[2])
    foot = source[:2] + (sensor[:2] - source[:2]) * ratio
    first = d.min()
    if 0 <= foot[0] <= size and 0 <= foot[1] <= size:
        first = float(np.hypot(np.hypot(*(sensor[:2] - source[:2])), source[2] + sensor[2]))
    return float(first), float(d.max())


def hard_cases(pixels: int = 10, waveform: str = "impulse") -> dict[str, Scene]:
    """The hard geometries, small enough for tests (M = ``pixels``).

    Parameters
    ----------
    pixels : int
        Image side M of every case (the far and fine-bin cases use fewer).
    waveform : {"impulse", "square", "butterworth"}
        Illumination of every case.

    Returns
    -------
    dict
        Name -> Scene.
    """
    illumination = Illumination(waveform=waveform)
    image = builtin_reflectance(pixels)

    def scene(name, source, sensors, period, start, count, size=1.0, m=pixels, reflectance=None):
        return Scene(name=name, size=size, pixels=m,
                     reflectance=image if reflectance is None and m == pixels else
                     (builtin_reflectance(m) if reflectance is None else reflectance),
                     source=source, sensors=sensors, illumination=illumination,
                     sampling=Sampling(period=period, start=start, count=count))

    cases = {}
    cases["low"] = scene("low", (0.3, 0.4, 1e-3), [(0.7, 0.6, 1e-3), (0.31, 0.41, 1e-3)],
                         0.05, 0.0, 60)
    cases["colocated"] = scene("colocated", (0.5, 0.5, 0.5), [(0.5, 0.5, 0.5)], 0.02, 0.9, 60)
    cases["grazing"] = scene("grazing", (-20.0, 0.5, 0.05), [(0.5, 0.5, 1.0)], 0.05, 20.0, 60)
    cases["outside"] = scene("outside", (0.5, 0.5, 1.0), [(1.5, -0.5, 0.3)], 0.05, 1.0, 80)
    cases["fine"] = scene("fine", (0.5, 0.5, 1.0), [(0.2, 0.7, 1.0)], 0.001, 1.9, 800, m=5)
    cases["coarse"] = scene("coarse", (0.5, 0.5, 1.0), [(0.2, 0.7, 1.0)], 10.0, 0.0, 2)
    # the first bin ends 1e-7 m after the first arrival: its isochrones are points
    first = float(np.hypot(np.hypot(0.2, 0.1), 1.8))
    cases["first_arrival"] = scene("first_arrival", (0.5, 0.5, 1.0), [(0.7, 0.6, 0.8)],
                                   0.05, first - 0.05 + 1e-7, 30)
    far_source, far_sensor = (0.5, 0.5, 400.0), (0.6, 0.45, 400.0)
    low, high = response_range(far_source, far_sensor, 1.0)
    period = (high - low) / 1000.0
    cases["far"] = scene("far", far_source, [far_sensor], period, low - 5 * period, 1020, m=6)
    return cases


def validation_suite() -> list[tuple[Scene, int]]:
    """The built-in scenes of ``diffuse-imaging validate`` with their sample counts.

    The default scene under each illumination, every hard case, and a large
    M; the corner (outside the one-bounce model) is run separately by
    :func:`validation.corner.check_corner`. Sample counts keep the whole run
    within a few minutes on 2 cores.
    """
    from analytic.scene import default_scene

    suite = []
    for waveform in ("impulse", "square", "butterworth"):
        scene = default_scene(noise=None, illumination=Illumination(waveform=waveform))
        suite.append((scene.replace(name=f"default-{waveform}"), 2**22))
    for name, scene in hard_cases(pixels=10).items():
        suite.append((scene, 2**22))
    large = default_scene(pixels=128, noise=None)
    suite.append((large.replace(name="large-M128"), 2**22))
    return suite
