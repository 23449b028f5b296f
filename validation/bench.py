"""Speed against error: the model over its tolerance, the renderer (and mitransient) over samples.

``diffuse-imaging bench --out DIR`` runs, on one scene (the 1 m plane of
:func:`plane_scene`) in one process:

- the analytic model at tolerances 1e-2 ... 1e-7: wall time and max error
  against the tolerance-1e-8 assembly, relative to the largest sample;
- the renderer at 2^16 ... 2^26 samples: wall time and relative L2 error
  against the model;
- mitransient's ``transient_path`` with a tiny-sphere ``irradiancemeter``
  (its 1/4 factor and its start-on-the-sphere offset corrected) at the same
  sample counts, when it is installed (``pip install -e .[bench]``; a
  benchmark extra, never a runtime dependency).

Writes bench.md (a table), bench.png (log-log error against wall time) and
metrics.json.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from analytic.io import atomic_write, save_json
from analytic.scene import Sampling, Scene
from validation.plots import save_figure

__all__ = ["plane_scene", "run_mitransient", "speed_against_error", "RADIUS"]

RADIUS = 1e-3   # mitransient's irradiancemeter sphere, metres


def plane_scene() -> Scene:
    """1 m x 1 m plane, reflectance 0.5, source 1 m above its centre, one off-centre sensor."""
    return Scene(name="plane 1x1", size=1.0, pixels=1, reflectance=0.5, source=(0.5, 0.5, 1.0),
                 sensors=[(0.8, 0.3, 1.0)], sampling=Sampling(bin_width_opl=0.05, start_opl=1.5, count=40))


# Runs in a subprocess so that mitransient's plugins never load into our process.
_MITRANSIENT = r"""
import json, sys, time
import numpy as np, mitsuba as mi
mi.set_variant(sys.argv[1])
import mitransient
spp, bins, start, width = int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])
RADIUS = float(sys.argv[6])
T = mi.ScalarTransform4f
def scene(spp):
    return mi.load_dict({'type': 'scene', 'integrator': {'type': 'transient_path', 'max_depth': 2},
      'plane': {'type': 'rectangle', 'to_world': T().translate([0.5, 0.5, 0]).scale([0.5, 0.5, 1]),
                'bsdf': {'type': 'diffuse', 'reflectance': {'type': 'uniform', 'value': 0.5}}},
      'light': {'type': 'point', 'position': [0.5, 0.5, 1.0], 'intensity': 1.0},
      'meter': {'type': 'sphere', 'center': [0.8, 0.3, 1.0], 'radius': RADIUS, 'bsdf': {'type': 'null'},
                'sensor': {'type': 'irradiancemeter',
                           'sampler': {'type': 'independent', 'sample_count': spp},
                           'film': {'type': 'transient_hdr_film', 'width': 1, 'height': 1,
                                    'temporal_bins': bins, 'start_opl': start, 'bin_width_opl': width,
                                    'rfilter': {'type': 'box'}}}}})
warm = scene(2**16); warm.integrator().render(warm, seed=0)
s = scene(spp)
t = time.perf_counter(); steady, transient = s.integrator().render(s, seed=1)
h = np.array(transient).ravel(); seconds = time.perf_counter() - t
print(json.dumps({'version': mitransient.__version__, 'samples': spp, 'seconds': seconds,
                  'samples_per_second': spp / seconds, 'transient': h.tolist()}))
"""




def run_mitransient(sampling: Sampling, samples: int, variant: str = "llvm_ad_mono"):
    """mitransient on :func:`plane_scene`: (corrected estimate ``(1, N)``, run info).

    The irradiancemeter reports 1/4 of ∫ L dω (multiplied back by 4) and
    starts its path lengths on the sphere's surface, on average 2r/3 closer to
    the plane than its centre for cosine-distributed rays (bins shifted by
    that).

    Raises
    ------
    RuntimeError
        mitransient missing or failing.
    """
    if importlib.util.find_spec("mitransient") is None:
        raise RuntimeError("mitransient not installed (pip install -e .[bench])")
    done = subprocess.run([sys.executable, "-c", _MITRANSIENT, variant, str(samples), str(sampling.count),
                           str(sampling.start_opl - 2 * RADIUS / 3), str(sampling.bin_width_opl), str(RADIUS)],
                          capture_output=True, text=True, timeout=1800)
    if done.returncode != 0:
        raise RuntimeError("mitransient failed: " + " ".join(done.stderr.strip().splitlines()[-1:]))
    run = json.loads(done.stdout.strip().splitlines()[-1])
    estimate = 4.0 * np.asarray(run.pop("transient"), dtype=np.float64).reshape(1, -1)
    return estimate, run


def speed_against_error(out: str | Path, *, powers=range(16, 27, 2)) -> dict:
    """Run the three methods on :func:`plane_scene`; write bench.md, bench.png, metrics.json."""
    from analytic.system import QuadratureWarning, system_matrix
    from transient.render import render

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    scene = plane_scene()
    shape = (scene.sensor_count, scene.sampling.count)

    def model_at(tolerance):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadratureWarning)
            started = time.perf_counter()
            y = (system_matrix(scene, tolerance=tolerance) @ scene.reflectance.ravel()).reshape(shape)
            return y, time.perf_counter() - started

    model_at(1e-6)                                  # compile / load the kernels
    reference, _ = model_at(1e-8)
    peak = float(np.max(reference))
    rows = []
    for tolerance in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7):
        y, seconds = model_at(tolerance)
        rows.append({"method": "model", "setting": f"tolerance {tolerance:g}", "seconds": seconds,
                     "error": float(np.max(np.abs(y - reference)) / peak),
                     "error_kind": "max abs error / peak"})
    render(scene, spp=2**16, seed=99, progress=False)  # compile the kernel
    norm = float(np.linalg.norm(reference))
    for power in powers:
        result = render(scene, spp=2**power, seed=power, progress=False)
        rows.append({"method": "render (ours)", "setting": f"2^{power} samples", "seconds": result.seconds,
                     "error": float(np.linalg.norm(result.mean - reference) / norm),
                     "error_kind": "relative L2"})
    mitransient = {"status": "ok"}
    for power in powers:
        try:
            estimate, run = run_mitransient(scene.sampling, 2**power)
        except RuntimeError as error:
            mitransient = {"status": str(error)}
            break
        mitransient["version"] = run["version"]
        rows.append({"method": f"mitransient {run['version']}", "setting": f"2^{power} samples",
                     "seconds": run["seconds"], "error": float(np.linalg.norm(estimate - reference) / norm),
                     "error_kind": "relative L2"})
    lines = [f"Scene: {scene.name} (source 1 m above the centre, one off-centre sensor, "
             f"{scene.sampling.count} bins of {scene.sampling.bin_width_opl} m).", "",
             "| method | setting | wall time (s) | error | error measure |", "|---|---|---|---|---|"]
    lines += [f"| {r['method']} | {r['setting']} | {r['seconds']:.4f} | {r['error']:.2e} | {r['error_kind']} |"
              for r in rows]
    if mitransient["status"] != "ok":
        lines += ["", f"mitransient: {mitransient['status']}"]
    atomic_write(out / "bench.md", lambda temporary: Path(temporary).write_text("\n".join(lines) + "\n"))
    save_json(out / "metrics.json", {"scene": scene.name, "rows": rows, "mitransient": mitransient})
    _plot(out / "bench.png", rows)
    return {"rows": rows, "markdown": "\n".join(lines)}


def _plot(path: Path, rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(5.5, 3.8))
    for method in dict.fromkeys(r["method"] for r in rows):
        chosen = [r for r in rows if r["method"] == method]
        axis.loglog([r["seconds"] for r in chosen], [max(r["error"], 1e-17) for r in chosen], "o-",
                    label=method)
    axis.set_xlabel("wall time (s)")
    axis.set_ylabel("error against the converged model")
    axis.legend(fontsize=8)
    axis.set_title("speed against error (plane 1x1)", fontsize=9)
    figure.tight_layout()
    save_figure(figure, path)
