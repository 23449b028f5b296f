"""The exact Jacobian's cost on a relay wall: every geometric key against ``forward`` by both routes.

    python benchmarks/bench_jacobian_relay_wall.py [--repeats 3]

examples/nlos.toml with its time zero moved to 1.993 m (its own 1.99 m puts a bin edge on first
arrivals, where y has no derivative: analytic.EdgeOnArrivalWarning), 17 keys: ``sampling.start``,
``laser.position.*``, ``sensor.position.*``, ``hidden.center.*``, ``hidden.rotation.*`` and the edge
vectors' components the scene accepts. Times are the best of ``--repeats``, kernels warm; ``forward`` by
the offset route (what the model takes) and by the general route (``offsets.MIN_SAVING = 0``).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import analytic
from analytic.operator import offsets
from analytic.operator.parameters import with_values

KEYS = (["sampling.start"] + [f"{stem}.{axis}" for stem in ("laser.position", "sensor.position", "hidden.center",
                                                            "hidden.rotation") for axis in "xyz"]
        + ["hidden.u.x", "hidden.u.z", "hidden.v.y", "hidden.v.z"])


def _best(call, repeats):
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        call()
        times.append(time.perf_counter() - started)
    return min(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    scene = with_values(analytic.load_scene("examples/nlos.toml"), {"sampling.start": 1.993})
    analytic.forward(scene)
    analytic.jacobian(scene, KEYS)
    print(f"machine: {platform.node()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f} at the start")
    forward = _best(lambda: analytic.forward(scene), args.repeats)
    exact = _best(lambda: analytic.jacobian(scene, KEYS), args.repeats)
    saving = offsets.MIN_SAVING
    offsets.MIN_SAVING = 0.0
    try:
        general = _best(lambda: analytic.forward(scene), args.repeats)
    finally:
        offsets.MIN_SAVING = saving
    print(f"examples/nlos.toml ({scene.sensor_count} pairs, M = {scene.pixels}, {scene.sampling.count} bins), "
          f"{len(KEYS)} keys: forward {forward:.3f} s (offset route), {general:.3f} s (general route); jacobian "
          f"{exact:.3f} s = {exact / forward:.1f} and {exact / general:.1f} forwards; load "
          f"{os.getloadavg()[0]:.2f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
