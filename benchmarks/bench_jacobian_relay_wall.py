"""The exact Jacobian's cost on a relay wall: every geometric key against ``forward``, by each route.

    python benchmarks/bench_jacobian_relay_wall.py [--repeats 5] [--gaussian FWHM]

examples/nlos.toml with its time zero moved to 1.993 m (its own 1.99 m puts a bin edge on first
arrivals, where y has no derivative: analytic.EdgeOnArrivalWarning), 17 keys: ``sampling.start``,
``laser.position.*``, ``sensor.position.*``, ``hidden.center.*``, ``hidden.rotation.*`` and the edge
vectors' components the scene accepts. Three captures, each against its own ``forward``: the scene as it
is (both by pixel offsets), the same with every route but the general one closed
(``offsets.MIN_SAVING = 0``: every pair over every pixel), and with the end legs counted
(``account_first_and_last_bounces``, tal's convention: the pairs' added paths differ, so the general
route is the only one). Times are the best of ``--repeats``, kernels warm, wall and CPU. ``--gaussian FWHM``
replaces the impulse by a Gaussian pulse of that FWHM (metres; the waveform route) and adds
``illumination.fwhm`` to the keys.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time

import analytic
from analytic.scenes.common import Illumination
from analytic.operator import offsets
from analytic.operator.parameters import with_values

KEYS = (["sampling.start"] + [f"{stem}.{axis}" for stem in ("laser.position", "sensor.position", "hidden.center",
                                                            "hidden.rotation") for axis in "xyz"]
        + ["hidden.u.x", "hidden.u.z", "hidden.v.y", "hidden.v.z"])


def _best(call, repeats):
    """(wall, CPU) seconds, the best of ``repeats`` calls."""
    times = []
    for _ in range(repeats):
        started, cpu = time.perf_counter(), time.process_time()
        call()
        times.append((time.perf_counter() - started, time.process_time() - cpu))
    return min(times)


def _case(name, scene, repeats, general=False):
    saving = offsets.MIN_SAVING
    offsets.MIN_SAVING = 0.0 if general else saving
    try:
        analytic.forward(scene)
        analytic.jacobian(scene, KEYS)
        forward = _best(lambda: analytic.forward(scene), repeats)
        exact = _best(lambda: analytic.jacobian(scene, KEYS), repeats)
    finally:
        offsets.MIN_SAVING = saving
    print(f"| {name} | {forward[0]:.3f} ({forward[1]:.3f}) | {exact[0]:.3f} ({exact[1]:.3f}) | "
          f"{exact[0] / forward[0]:.1f} ({exact[1] / forward[1]:.1f}) |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--gaussian", type=float, default=None, metavar="FWHM")
    args = parser.parse_args(argv)
    scene = with_values(analytic.load_scene("examples/nlos.toml"), {"sampling.start": 1.993})
    if args.gaussian is not None:
        scene = scene.replace(illumination=Illumination(waveform="gaussian", fwhm=args.gaussian))
        KEYS.append("illumination.fwhm")
    print(f"machine: {platform.node()}, {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"load {os.getloadavg()[0]:.2f} at the start")
    pulse = "impulse" if args.gaussian is None else f"Gaussian of FWHM {args.gaussian:g} m"
    print(f"examples/nlos.toml, start 1.993 m, {pulse} ({scene.sensor_count} pairs, M = {scene.pixels}, "
          f"{scene.sampling.count} bins), {len(KEYS)} keys; seconds, wall (CPU)\n")
    print("| capture | forward | jacobian | forwards |\n|---|---|---|---|")
    _case("as it is (pixel offsets)", scene, args.repeats)
    _case("general route forced", scene, args.repeats, general=True)
    counted = scene.replace(scan=dataclasses.replace(scene.scan, account_first_and_last_bounces=True))
    _case("end legs counted (general route)", counted, args.repeats)
    print(f"\nload {os.getloadavg()[0]:.2f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
