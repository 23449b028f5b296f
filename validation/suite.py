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
from analytic.window import response_range

__all__ = ["hard_cases", "validation_suite", "MINIMUM_SAMPLES"]

#: Suite scenes whose light is spread over so many bins (800 and 1,020) that
#: below this many samples no bin's standard error is under 0.1 of its value,
#: so nothing can be judged (at 2^14 samples "fine" judges 4 of 648 lit bins and
#: "far" none; at 2^16, 273 and 264). Every other suite scene is judged at 4,096.
MINIMUM_SAMPLES = {"fine": 2**16, "far": 2**16}


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

    def scene(name, source, sensors, period, start, count, m=pixels):
        return Scene(name=name, size=1.0, pixels=m, reflectance=builtin_reflectance(m),
                     source=source, sensors=sensors, illumination=illumination,
                     sampling=Sampling(bin_width_opl=period, start_opl=start, count=count))

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
    far = scene("far", (0.5, 0.5, 400.0), [(0.6, 0.45, 400.0)], 1.0, 0.0, 1, m=6)
    low, high = response_range(far)
    period = (high - low) / 1000.0
    cases["far"] = far.replace(sampling=Sampling(bin_width_opl=period, start_opl=low - 5 * period,
                                                 count=1020))
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
        # the scene's noise is added only for its reconstructions: the render is judged noiseless
        scene = default_scene(illumination=Illumination(waveform=waveform))
        suite.append((scene.replace(name=f"default-{waveform}"), 2**22))
    for name, scene in hard_cases(pixels=10).items():
        suite.append((scene, 2**22))
    large = default_scene(pixels=128)
    suite.append((large.replace(name="large-M128"), 2**22))
    return suite
