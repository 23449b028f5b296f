"""The renderer against mitransient, side by side in one run, and its throughput.

The logic is :func:`validation.runs.bench.speed_against_error` (also behind
``diffuse-imaging bench``): on the 1 m plane (1 sensor, 40 bins) and the
built-in default scene (16 sensors, 40 bins, M = 50), ours and
mitransient's RMS relative error and wall time over sample counts and
seeds, efficiency 1 / (error² x time), the time to errors 1e-3, 1e-4 and
1e-5, and samples/s and sensor-samples/s for K = 1, 16, 64 and M = 50, 256
on the variant's device.

Usage::

    python benchmarks/bench_render.py --out out/bench [--variant cuda_ad_mono] [--quick]

Prints the markdown tables; writes bench.md, bench.png and metrics.json in
--out. With ``--deposit`` it instead times the histogram deposit alone in
bare Dr.Jit kernels (float64 geometry of the bench plane, one sensor, 40
bins, or 16 sensors): points in random or coherent (jittered, Morton)
order, each sample's value alone or with its square, scattered with each
``drjit.ReduceMode`` — the measurement behind
:func:`transient.common.reduce_mode`.
"""

from __future__ import annotations

import argparse
import sys

from validation.runs.bench import speed_against_error


def deposit_strategies(variant: str | None, samples: int, repeats: int = 3) -> list[dict]:
    """Samples per second of the bare deposit for each order, moment and ReduceMode (best of repeats)."""
    import time

    from transient.backend import select_variant

    select_variant(variant)
    import drjit as dr
    import mitsuba as mi

    from transient.common import jittered_point

    def kernel(order, squares, mode, sensors, seed):
        lane = dr.arange(mi.UInt32, samples)
        rng = mi.PCG32(samples, dr.opaque(mi.UInt64, seed), mi.UInt64(lane))
        ju, jv = rng.next_float64(), rng.next_float64()
        if order == "coherent":
            u, v = jittered_point(lane, dr.opaque(mi.UInt32, samples), ju, jv)
        else:
            u, v = ju, jv
        source = dr.sqrt(dr.square(u - 0.5) + dr.square(v - 0.5) + 1.0)
        histogram = dr.zeros(mi.Float64, sensors * 40)
        moments = dr.zeros(mi.Float64, sensors * 40) if squares else None
        for k in range(sensors):
            sensor = dr.sqrt(dr.square(u - 0.2 - 0.6 * k / max(sensors - 1, 1)) + dr.square(v - 0.3) + 1.0)
            value = 1.0 / (dr.square(source) * dr.square(sensor))
            n = dr.floor((source + sensor - 1.5) / 0.05)
            inside = (n >= 0) & (n < 40)
            slot = mi.UInt32(dr.clip(n, 0, 39)) + 40 * k
            dr.scatter_reduce(dr.ReduceOp.Add, histogram, value, slot, active=inside, mode=mode)
            if squares:
                dr.scatter_reduce(dr.ReduceOp.Add, moments, value * value, slot, active=inside, mode=mode)
        dr.eval(histogram, moments)
        dr.sync_thread()          # kernels run asynchronously: wait for the sums
        return histogram

    rows = []
    for sensors in (1, 16):
        for order in ("random", "coherent"):
            for squares in (True, False):
                for mode in ("Auto", "Direct", "Local"):
                    chosen = getattr(dr.ReduceMode, mode)
                    kernel(order, squares, chosen, sensors, 0)                    # compile
                    best = float("inf")
                    for repeat in range(repeats):
                        started = time.perf_counter()
                        kernel(order, squares, chosen, sensors, repeat + 1)
                        best = min(best, time.perf_counter() - started)
                    rows.append({"sensors": sensors, "order": order, "squares": squares, "mode": mode,
                                 "samples_per_second": samples / best})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--variant", default=None, help="Mitsuba variant (default: the CPU one)")
    parser.add_argument("--seeds", type=int, default=4, help="renders per sample count (RMS over them)")
    parser.add_argument("--max-power", type=int, default=26, help="our largest sample count, 2^p")
    parser.add_argument("--mitransient-max-power", type=int, default=22,
                        help="mitransient's largest sample count per sensor, 2^p")
    parser.add_argument("--throughput-power", type=int, default=24, help="samples of each throughput render, 2^p")
    parser.add_argument("--quick", action="store_true", help="small counts: a smoke test, not a measurement")
    parser.add_argument("--deposit", action="store_true", help="time the bare deposit strategies instead")
    args = parser.parse_args(argv)
    if args.deposit:
        from analytic.files import save_json

        rows = deposit_strategies(args.variant, 2**22, repeats=7)
        save_json(f"{args.out}/deposit.json", rows)
        print("| K | order | squares | ReduceMode | samples/s |\n|---|---|---|---|---|")
        for row in rows:
            print(f"| {row['sensors']} | {row['order']} | {'yes' if row['squares'] else 'no'} | {row['mode']} | "
                  f"{row['samples_per_second']:.3g} |")
        return 0
    if args.quick:
        args.seeds, args.max_power, args.mitransient_max_power, args.throughput_power = 2, 18, 16, 18
    result = speed_against_error(args.out, powers=range(16, args.max_power + 1, 2), variant=args.variant,
                                 seeds=args.seeds, mitransient_powers=range(16, args.mitransient_max_power + 1, 2),
                                 throughput_samples=2**args.throughput_power)
    print(result["markdown"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
