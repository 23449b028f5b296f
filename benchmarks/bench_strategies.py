"""The renderer's sampling strategies on the suite's hardest case: weight tails and efficiency.

    python benchmarks/bench_strategies.py [--samples-power 20] [--seeds 4]

The ``low`` case of :func:`validation.runs.suite.hard_cases`: the source and
two sensors 1 mm above a 1 m plane. For each strategy of ``transient_opl``
(``mis``: the source's solid angle with multiple importance sampling of the
peaked sensors, the default; ``source``: the source's solid angle alone;
``area``: uniform points), prints

- the largest replica weight over the mean: replicas of 4 independent
  samples in one bin that holds all the light, so any sample weighing more
  than 4 x the mean shows (a heavy tail reaches thousands);
- the RMS relative L2 error over ``--seeds`` renders of 2^p samples
  against the exact model (tolerance 1e-10), the mean wall time, and the
  efficiency 1 / (error² x seconds).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from analytic.scenes.common import Sampling
from analytic.operator.system import system_matrix
from analytic.operator.matrix_free import forward
from transient.backend import select_variant
from validation.runs.suite import hard_cases


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples-power", type=int, default=20, help="samples per render, 2^p (default 20)")
    parser.add_argument("--seeds", type=int, default=4, help="renders per strategy (default 4)")
    args = parser.parse_args(argv)
    select_variant()
    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import load_scene
    from transient.render import render_loaded

    scene = hard_cases(pixels=10)["low"]
    one_bin = scene.replace(sampling=Sampling(bin_width_opl=100.0, start_opl=0.0, count=1))
    layout = ReplicaLayout(2**16, 4)
    reference = forward(scene, system_matrix(scene, tolerance=1e-10))
    print("| strategy | largest replica weight / mean | RMS error | seconds | efficiency |")
    print("|---|---|---|---|---|")
    for strategy in ("mis", "source", "area"):
        loaded = load_scene(one_bin, sampler="independent", strategy=strategy)
        sums = loaded.integrator().render_chunk(loaded, seed=3, layout=layout, first=0, count=layout.samples)
        means = sums[:, :, 0] / layout.size
        peak = float((means.max(axis=0) / means.mean(axis=0)).max())
        full = load_scene(scene, strategy=strategy)
        render_loaded(full, spp=2**16, seed=99)                      # compile
        errors, seconds = [], []
        for seed in range(args.seeds):
            started = time.perf_counter()
            result = render_loaded(full, spp=2**args.samples_power, seed=seed)
            seconds.append(time.perf_counter() - started)
            errors.append(np.linalg.norm(result.mean - reference) / np.linalg.norm(reference))
        rms, wall = float(np.sqrt(np.mean(np.square(errors)))), float(np.mean(seconds))
        print(f"| {strategy} | {peak:.3g} | {rms:.3g} | {wall:.3f} | {1 / (rms**2 * wall):.3g} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
