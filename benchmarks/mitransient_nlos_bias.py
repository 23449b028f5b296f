"""Why mitransient's NLOS renders disagree with the exact model, and by how much.

    python benchmarks/mitransient_nlos_bias.py --out out/mitransient_nlos [--spp 1048576] [--renders 16]
                                               [--shifts 0 10] [--emulated 1048576]

For a 4 x 4 single scan of the default relay-wall capture (a 1 m hidden
square 1 m in front of a 2 m wall, the built-in pattern, bins of 1 cm),
exported with ``diffuse-imaging export --format mitransient`` and moved by
each ``--shifts`` value along x (metres: the same capture, far from the
origin), this script

1. renders ``--renders`` independent films with mitransient
   (``llvm_ad_mono``, ``--spp`` samples per read point, a subprocess per
   configuration) and judges them with ``check``'s machinery: the verdict
   as given, the fitted scale and offset (jackknife errors from the
   replicas), and the same fit pair by pair;
2. judges them against mitransient's estimator stated in closed form with
   no fitted parameter (:func:`interop.mitransient.offset_model`: the model
   read from o = s + (1 + max|s_i|) RayEpsilon n, where Mitsuba's
   ``spawn_ray`` starts the ray that hidden-geometry sampling aims from s,
   less the strip of the hidden rectangle its sampling misses), and
   predicts the scale and offset a fit against the model finds, overall and
   pair by pair, from that statement and the data's errors;
3. holds the closed form to a float64 emulation of mitransient's code
   (:func:`interop.mitransient.spawn_offset_difference`).

Writes results.json in --out and prints the table that docs/interop.md
quotes. mitransient takes about 11 minutes per shift at the defaults on 2
busy cores; its films are kept in --out and read back by a second run with
the same settings.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from analytic.files import save_json
from analytic.scenes.relay_wall import Scan, default_relay_wall_scene
from validation.runs.bench import cpu_model

# Renders an exported mitransient NLOS scene in a fresh process: one (H, W, T, C) film per seed.
_RENDER = r"""
import sys, time
import numpy as np, mitsuba as mi
mi.set_variant("llvm_ad_mono")
import mitransient
xml, spp, renders, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
scene = mi.load_file(xml, spp=spp)
np.array(mi.render(scene, seed=10**6, spp=1024)[1])          # compile once, outside the timing
started = time.perf_counter()
for seed in range(renders):
    np.save(f"{out}/render_{seed}.npy", np.array(mi.render(scene, seed=seed)[1]))
print(time.perf_counter() - started)
"""


def study_scene():
    """The capture studied: default_relay_wall_scene as a 4 x 4 single scan lit at the wall's centre."""
    return default_relay_wall_scene(scan=Scan(type="single", grid=(4, 4)), name="mitransient-study")


def llvm_environment() -> dict:
    from transient.backend import choose_libllvm, find_llvm_libraries

    return os.environ | {"DRJIT_LIBLLVM_PATH": choose_libllvm(os.environ.get("DRJIT_LIBLLVM_PATH"),
                                                              find_llvm_libraries())}


def render_mitransient(scene, shift: float, spp: int, renders: int, out: Path) -> tuple[np.ndarray, float]:
    """``(R, P, N)`` films of mitransient, and the seconds its renders took (kept in ``out``: a second
    run with the same settings reads them back)."""
    import json

    from interop.mitransient.export_relay_wall import export_relay_wall
    from validation.check import read_data

    out.mkdir(parents=True, exist_ok=True)
    stamp = out / "renders.json"
    settings = {"spp": spp, "renders": renders, "shift": shift}
    if not (stamp.is_file() and json.loads(stamp.read_text())["settings"] == settings):
        export_relay_wall(scene, out / "xml", "mitransient", spp=spp, world_offset=(shift, 0.0, 0.0))
        done = subprocess.run([sys.executable, "-c", _RENDER, str(out / "xml" / "scene.xml"), str(spp),
                               str(renders), str(out)], capture_output=True, text=True, env=llvm_environment(),
                              timeout=7200)
        if done.returncode != 0:
            raise RuntimeError(done.stderr[-3000:])
        save_json(stamp, {"settings": settings, "seconds": float(done.stdout.strip().splitlines()[-1])})
    seconds = json.loads(stamp.read_text())["seconds"]
    return np.stack([read_data(out / f"render_{seed}.npy", scene) for seed in range(renders)]), seconds


def pair_fits(scene, replicas: np.ndarray, model_at) -> list[dict]:
    """Scale and offset fitted to each pair's bins alone (jackknife errors over the replicas)."""
    from validation.check import fit_scale_offset

    mean = replicas.mean(axis=0)
    error = replicas.std(axis=0, ddof=1) / math.sqrt(len(replicas))
    fits = []
    for p in range(mean.shape[0]):
        mask = np.zeros(mean.shape, dtype=bool)
        mask[p] = (error[p] > 0) & (error[p] < 0.1 * np.abs(mean[p]))
        fit = fit_scale_offset(mean, np.where(mask, error, 1.0), mask, model_at, scene.sampling.bin_width_opl,
                               replicas=replicas)
        fits.append(fit.as_dict())
    return fits


def predicted_fit(scene, expected: np.ndarray, error: np.ndarray, model_at, rows=None) -> dict:
    """The scale and offset a fit would find for data equal to ``expected`` with these errors (no noise)."""
    from validation.check import fit_scale_offset

    mask = (error > 0) & (error < 0.1 * np.abs(expected))
    if rows is not None:
        mask &= np.isin(np.arange(mask.shape[0]), rows)[:, None]
    fit = fit_scale_offset(expected, np.where(mask, error, 1.0), mask, model_at, scene.sampling.bin_width_opl)
    return {"scale": fit.scale, "offset_opl": fit.offset_opl}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--spp", type=int, default=2**20)
    parser.add_argument("--renders", type=int, default=16)
    parser.add_argument("--shifts", type=float, nargs="+", default=[0.0, 10.0])
    parser.add_argument("--emulated", type=int, default=2**20, help="emulated points per pair (the cross-check)")
    parser.add_argument("--pair-fits", type=float, nargs="*", default=[0.0],
                        help="the shifts whose pairs are also fitted one by one (32 fits: minutes each shift)")
    args = parser.parse_args(argv)
    from analytic.operator.matrix_free import forward
    from validation.check import ShiftedModel, check_transient
    from interop.mitransient import moved_read_points, offset_model, spawn_offset_difference

    scene = study_scene()
    model = forward(scene)
    model_at = ShiftedModel(scene, model)
    results = {"machine": cpu_model(), "scene": scene.name, "spp": args.spp, "renders": args.renders,
               "shifts": {}}
    print(f"machine: {cpu_model()}; {args.renders} mitransient renders of {args.spp} samples per read point, "
          f"4 x 4 single scan")
    for shift in args.shifts:
        replicas, seconds = render_mitransient(scene, shift, args.spp, args.renders, args.out / f"shift_{shift:g}")
        error = replicas.std(axis=0, ddof=1) / math.sqrt(len(replicas))
        measured = check_transient(scene, replicas, model=model)
        expected = offset_model(scene, world_offset=(shift, 0.0, 0.0))
        stated = check_transient(scene, replicas, model=expected,
                                 evaluate=lambda shifted: offset_model(shifted, world_offset=(shift, 0.0, 0.0)))
        emulated = spawn_offset_difference(scene, world_offset=(shift, 0.0, 0.0), samples=args.emulated)
        sums = model.sum(axis=1)
        emulation_gap = float(np.max(np.abs((emulated.sum(axis=1) - (expected - model).sum(axis=1)) / sums)))
        epsilon = moved_read_points(scene, world_offset=(shift, 0.0, 0.0))[:, 2]
        per_pair = pair_fits(scene, replicas, model_at) if shift in args.pair_fits else []
        predicted = [predicted_fit(scene, expected, error, model_at, rows=[p]) for p in range(len(per_pair))]
        overall = predicted_fit(scene, expected, error, model_at)
        strip_share = float(np.max(1 - expected.sum(axis=1) / sums))
        fit = measured.fit
        results["shifts"][f"{shift:g}"] = {
            "render_seconds": seconds, "epsilon_range": [float(epsilon.min()), float(epsilon.max())],
            "as_given": {"agrees": measured.agrees, "chi2_per_dof": measured.chi2_per_dof,
                         "max_abs_z": measured.max_abs_z, "fit": fit.as_dict(),
                         "agrees_after_fit": measured.agrees_after_fit,
                         "chi2_per_dof_after_fit": measured.chi2_per_dof_after_fit},
            "stated": {"agrees": stated.agrees, "chi2_per_dof": stated.chi2_per_dof, "max_abs_z": stated.max_abs_z,
                       "fit": stated.fit.as_dict()},
            "predicted_fit": overall, "pairs": per_pair, "predicted_pairs": predicted,
            "emulation_vs_closed_form_time_sums": emulation_gap, "largest_time_sum_change": strip_share}
        print(f"\nscene moved {shift:g} m along x (mitransient: {seconds:.0f} s); ray offsets "
              f"{epsilon.min():.3e} to {epsilon.max():.3e} m")
        print(f"  against the model: {'agrees' if measured.agrees else 'DISAGREES'} (chi2/dof "
              f"{measured.chi2_per_dof:.3f}, max|z| {measured.max_abs_z:.2f}); after the best scale and offset: "
              f"{'agrees' if measured.agrees_after_fit else 'DISAGREES'} (chi2/dof "
              f"{measured.chi2_per_dof_after_fit:.3f})")
        print(f"  against mitransient's estimator stated in closed form: {'agrees' if stated.agrees else 'DISAGREES'} "
              f"(chi2/dof {stated.chi2_per_dof:.3f}, max|z| {stated.max_abs_z:.2f}); its fit: scale "
              f"{stated.fit.scale:.6f} ± {stated.fit.scale_stderr:.6f}, offset {stated.fit.offset_opl:+.1e} ± "
              f"{stated.fit.offset_stderr:.1e} m")
        print(f"  closed form against an emulation of mitransient's code ({args.emulated} points per pair): "
              f"time sums within {emulation_gap:.1e} of the model's")
        print(f"  {'pair':>6} {'measured scale':>22} {'predicted':>10} {'measured offset (m)':>24} {'predicted':>10}")
        print(f"  {'all':>6} {fit.scale:>12.6f} ± {fit.scale_stderr:.6f} {overall['scale']:>10.6f} "
              f"{fit.offset_opl:>13.3e} ± {fit.offset_stderr:.1e} {overall['offset_opl']:>10.3e}")
        for p, (ours, theirs) in enumerate(zip(per_pair, predicted)):
            print(f"  {p:>6} {ours['scale']:>12.6f} ± {ours['scale_stderr']:.6f} {theirs['scale']:>10.6f} "
                  f"{ours['offset_opl']:>13.3e} ± {ours['offset_stderr']:.1e} {theirs['offset_opl']:>10.3e}")
        save_json(args.out / "results.json", results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
