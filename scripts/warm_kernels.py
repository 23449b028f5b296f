"""Compile (or load) the model's kernels that the commands and the tests use: every route, both waveform kinds.

A command compiles only what its scene needs, once (``analytic.kernels.cache``); the tests need every
route. ``scripts/setup.sh`` runs this beside the renderer's warm-up so that the two use both cores and no
test pays a compile. ``--waveform impulse`` or ``--waveform square`` compiles one kind's kernels (the set-up runs the two in
processes of their own, side by side). With ``--renderer`` it renders the built-in scene instead (Dr.Jit's kernels, cached in
``~/.drjit``) and imports matplotlib (which builds its font cache on its first import). The values
computed are discarded.
"""

from __future__ import annotations

import contextlib
import sys
import warnings

import numpy as np


def model(waveforms: tuple[str, ...] = ("impulse", "square")) -> None:
    from analytic.operator.derivatives import jacobian
    from analytic.operator.response import impulse_response
    from analytic.scenes.common import Illumination, Sampling, Scene
    from analytic.operator.system import METHODS, pair_entries, system_matrix
    from analytic.operator.window import window_share

    # a sensor near the plane (the cut route by its foot), bins finer than the pixels (strips), a far sensor
    scene = Scene(pixels=6, reflectance=1.0, source=(0.3, 0.6, 0.4), sensors=[(0.7, 0.2, 0.5), (0.5, 0.5, 0.02)],
                  sampling=Sampling(bin_width_opl=0.03, start_opl=0.4, count=90), noise=None)
    for waveform in waveforms:                   # impulse: a step function's first pass; square: the moments'
        shaped = scene.replace(illumination=Illumination(waveform=waveform))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            system_matrix(shaped)
            window_share(shaped)
            for method in METHODS:               # the tests hold each route to the adaptive one
                for taylor in (True, False):
                    with contextlib.suppress(ValueError):     # a route that does not apply is compiled anyway
                        pair_entries(shaped, 1, 14, method=method, taylor=taylor)
            relay_wall(waveform)
    if "impulse" in waveforms:
        impulse_response(scene, 0, [1.2, 1.3])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            jacobian(scene, ["source.position.z", "sensors.positions.1.x", "sampling.start"])   # the exact route
            # the exact route of every other waveform (one set of kernels): here rather than with the square's
            # forward kernels, whose process is the set-up's longer one (~20 s of compile moved, measured)
            jacobian(scene.replace(illumination=Illumination(waveform="square")), ["source.position.z", "sampling.start"])


def relay_wall(waveform: str) -> None:
    """A confocal capture of a hidden square parallel to the wall: the offset route's kernels (y without A;
    for the impulse, the exact derivatives by pixel offsets too)."""
    from analytic.operator.derivatives import jacobian
    from analytic.operator.matrix_free import forward
    from analytic.scenes.common import Illumination, Sampling
    from analytic.scenes.relay_wall import Scan, default_relay_wall_scene

    scene = default_relay_wall_scene(pixels=8, scan=Scan(type="confocal", grid=(8, 8)),
                                     sampling=Sampling(bin_width_opl=0.05, start_opl=1.9, count=60),
                                     illumination=Illumination(waveform=waveform))
    forward(scene)
    if waveform == "impulse":
        jacobian(scene, ["hidden.center.z", "hidden.u.x"])


def renderer() -> None:
    from analytic.scenes.common import default_scene
    from transient.render import render

    render(default_scene(noise=None), spp=4096, seed=0, progress=False)
    import matplotlib.pyplot  # noqa: F401 (matplotlib builds its font cache on its first import)


if __name__ == "__main__":
    np.seterr(all="ignore")
    if sys.argv[1:] == ["--renderer"]:
        renderer()
    elif sys.argv[1:2] == ["--waveform"]:       # one kind per process: setup.sh compiles the two side by side
        model(tuple(sys.argv[2:]))
    else:
        model()
