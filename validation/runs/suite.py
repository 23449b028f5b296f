"""Built-in scenes: the hard cases that the model and the renderer must both get right.

Each case isolates one way a forward model can go wrong: a peaked
attenuation (source or sensors 1e-3 L above the plane), a degenerate
ellipse family (source and sensor at one point: circles), grazing light, a
sensor outside the plane's footprint, a plane hundreds of lengths away
binned finer than its response's spread (float precision of path lengths),
bins from L/1000 to longer than the whole response, and a first-arrival bin
that catches only the point-sized start of the isochrones.

The captures through a relay wall (:func:`relay_wall_cases`, docs/design.md
section 7) do the same for the third bounce: a hidden rectangle seen at
grazing angles, tilted, 4 cm from the wall (the wall's cosines peak), 40 m
away (path lengths near 80 m binned at 5 mm), a millimetre wide (its light
in a few bins), a confocal scan (l = s: circles again), and single and
exhaustive scans with the laser's and the sensor's legs counted.
"""

from __future__ import annotations

import numpy as np

from analytic.scenes.reflectance import builtin_reflectance
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import Illumination, Sampling, Scene
from analytic.operator.window import covering_sampling, response_range

__all__ = ["hard_cases", "relay_wall_cases", "validation_suite", "MINIMUM_SAMPLES", "RELAY_WALL_SAMPLES"]

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


#: Samples of each relay-wall case in the suite: every sample serves all its pairs, so 2^20 points on the
#: hidden rectangle are 2^20 x P paths.
RELAY_WALL_SAMPLES = 2**20


def relay_wall_cases(pixels: int = 6) -> dict[str, RelayWallScene]:
    """The hard relay-wall captures (docs/design.md section 7), small enough for tests (M = ``pixels``).

    Each window covers its light (pulse included) at its own period, one empty bin either side.

    Returns
    -------
    dict
        Name -> RelayWallScene.
    """
    image = builtin_reflectance(pixels)
    single = Scan(type="single", grid=(4, 4), laser_point=(0.5, -0.5, 0.0))

    def capture(name, period, scan=single, **pose):
        scene = RelayWallScene(name=name, pixels=pixels, reflectance=image, scan=scan, wall_reflectance=0.8,
                               **pose)
        return scene.replace(sampling=covering_sampling(scene, period, margin=1))

    cases = {}
    cases["nlos-confocal"] = capture("nlos-confocal", 0.02, scan=Scan(type="confocal", grid=(4, 4)))
    cases["nlos-grazing"] = capture("nlos-grazing", 0.02, center=(1.6, 0.0, 0.6), u=(0.0, 0.0, 0.6),
                                    v=(0.0, 0.6, 0.0))
    cases["nlos-tilted"] = capture("nlos-tilted", 0.02, center=(0.1, 0.2, 1.2), u=(0.8 * np.cos(0.5), 0.0,
                                                                                  0.8 * np.sin(0.5)),
                                   v=(0.0, -0.8, 0.0))
    cases["nlos-near-wall"] = capture("nlos-near-wall", 0.01, center=(0.2, -0.1, 0.04), u=(0.1, 0.0, 0.0),
                                      v=(0.0, -0.1, 0.0))
    cases["nlos-far"] = capture("nlos-far", 0.005, center=(0.0, 0.0, 40.0), u=(3.0, 0.0, 0.0),
                                v=(0.0, -3.0, 0.0))
    cases["nlos-tiny"] = capture("nlos-tiny", 2e-4, center=(0.3, 0.2, 0.8), u=(1e-3, 0.0, 0.0),
                                 v=(0.0, -1e-3, 0.0))
    legs = Scan(type="single", grid=(4, 4), laser_point=(-0.25, 0.25, 0.0), account_first_and_last_bounces=True)
    cases["nlos-single-legs"] = capture("nlos-single-legs", 0.02, scan=legs,
                                        laser_position=(-0.8, 0.3, 0.4), sensor_position=(0.6, -0.7, 0.3),
                                        illumination=Illumination(waveform="butterworth"))
    exhaustive = Scan(type="exhaustive", grid=(3, 3), laser_grid=(2, 2), account_first_and_last_bounces=True)
    cases["nlos-exhaustive-legs"] = capture("nlos-exhaustive-legs", 0.02, scan=exhaustive,
                                            center=(0.1, 0.0, 0.7), u=(0.6, 0.0, 0.0), v=(0.0, -0.6, 0.0),
                                            illumination=Illumination(waveform="square"))
    return cases


def validation_suite() -> list[tuple[Scene, int]]:
    """The built-in scenes of ``diffuse-imaging validate`` with their sample counts.

    The default scene under each illumination, every hard case, a large M,
    and the relay-wall captures (:func:`relay_wall_cases`); the corner
    (outside the one-bounce model) is run separately by
    :func:`validation.runs.corner.check_corner`. Sample counts keep the whole run
    within a few minutes on 2 cores.
    """
    from analytic.scenes.common import default_scene

    suite = []
    for waveform in ("impulse", "square", "butterworth"):
        # the scene's noise is added only for its reconstructions: the render is judged noiseless
        scene = default_scene(illumination=Illumination(waveform=waveform))
        suite.append((scene.replace(name=f"default-{waveform}"), 2**22))
    for name, scene in hard_cases(pixels=10).items():
        suite.append((scene, 2**22))
    large = default_scene(pixels=128)
    suite.append((large.replace(name="large-M128"), 2**22))
    for scene in relay_wall_cases().values():
        suite.append((scene, RELAY_WALL_SAMPLES))
    return suite
