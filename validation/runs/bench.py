"""Speed against error: the renderer against mitransient side by side, and the model over its tolerance.

``diffuse-imaging bench --out DIR`` (and ``benchmarks/bench_render.py``)
runs, in one process, on two scenes (the 1 m plane of :func:`plane_scene`:
one sensor, 40 bins; the built-in default scene: 16 sensors, 40 bins,
M = 50):

- our renderer at 2^16 ... 2^26 samples, several seeds each: wall time and
  the RMS over seeds of the relative L2 error against the exact model;
- mitransient's ``transient_path`` with tiny-sphere ``irradiancemeter``
  sensors (factor and offset from
  :func:`transient.mitsuba_scene.irradiancemeter_correction`) at the same
  counts up to 2^22, in a subprocess, when it is installed
  (``pip install -e .[bench]``; a benchmark extra, never a runtime
  dependency); its error is split into noise (the spread over seeds) and
  bias;
- efficiency 1 / (error² x time) per run, and the time each method needs to
  an RMS relative error of 1e-3, 1e-4 and 1e-5 (measured where a run got
  there, extrapolated along each method's fitted convergence otherwise:
  mitransient's noise alone, in its favour);
- throughput: samples/s and sensor-samples/s for K = 1, 16, 64 sensors and
  M = 50, 256 pixels on the device of the chosen variant;
- the analytic model at tolerances 1e-2 ... 1e-7 on the plane.

Writes bench.md (tables), bench.png (error against wall time) and
metrics.json.
"""

from __future__ import annotations

import importlib.util
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analytic.files import atomic_write, save_json
from analytic.scenes.common import Sampling, Scene, default_scene, sensor_grid
from validation.plots import save_figure, speed_against_error_figure

__all__ = ["plane_scene", "throughput_scene", "MitransientRuns", "run_mitransient", "device_name", "cpu_model",
           "speed_against_error", "TARGETS"]

#: RMS relative errors whose time is reported.
TARGETS = (1e-3, 1e-4, 1e-5)


def plane_scene() -> Scene:
    """1 m x 1 m plane, reflectance 0.5, source 1 m above its centre, one off-centre sensor."""
    return Scene(name="plane 1x1", size=1.0, pixels=1, reflectance=0.5, source=(0.5, 0.5, 1.0),
                 sensors=[(0.8, 0.3, 1.0)], sampling=Sampling(bin_width_opl=0.05, start_opl=1.5, count=40))


def throughput_scene(sensors: int, pixels: int) -> Scene:
    """The default scene with M pixels and a √K x √K sensor array (extent 1 m, 1 m above the plane).

    One sensor sits off-centre, at the bench plane's (0.8, 0.3, 1.0): at the
    source's own position its distances would be the source's, which the
    kernel compiler merges, and the figure would flatter the renderer.
    """
    side = int(round(math.sqrt(sensors)))
    if side * side != sensors:
        raise ValueError(f"sensors must be a square number, got {sensors}")
    grid = sensor_grid((side, side), 1.0, (0.5, 0.5, 1.0)) if side > 1 else np.array([[0.8, 0.3, 1.0]])
    return default_scene(noise=None, pixels=pixels, sensors=grid).replace(name=f"K={sensors} M={pixels}")


# -- mitransient, in a subprocess ---------------------------------------------------

# Runs apart so that mitransient's plugins never load into our process; it
# builds its scene with transient.mitsuba_scene (no plugin of ours is loaded).
_MITRANSIENT = r"""
import json, sys, time
import numpy as np, mitsuba as mi
spec = np.load(sys.argv[1], allow_pickle=False)
mi.set_variant(str(spec["variant"]))
import mitransient
from analytic.scenes.common import Sampling
from transient.mitsuba_scene import mitransient_planes, mitransient_scene_dict
sampling = Sampling(bin_width_opl=float(spec["bin_width_opl"]), start_opl=float(spec["start_opl"]),
                    count=int(spec["count"]))
if spec["reflectance"].size:
    from analytic.scenes.common import Scene
    plane = Scene(size=float(spec["size"]), pixels=spec["reflectance"].shape[0], reflectance=spec["reflectance"],
                  source=spec["source"], sensors=spec["sensors"], sampling=sampling)
    planes = mitransient_planes(plane)
else:
    planes = mitransient_planes(albedo=float(spec["albedo"]), size=float(spec["size"]))
def load(samples):
    return mi.load_dict(mitransient_scene_dict(planes=planes, source=spec["source"], sensors=spec["sensors"],
                                               sampling=sampling, max_depth=int(spec["max_depth"]),
                                               samples=samples, radius=float(spec["radius"]),
                                               intensity=float(spec["intensity"])))
warm = load(2**12)
for k in range(len(warm.sensors())):
    warm.integrator().render(warm, sensor=k, seed=0)
scene = load(int(spec["samples"]))
estimates, seconds = [], []
for seed in spec["seeds"]:
    rows, elapsed = [], 0.0
    for k in range(len(scene.sensors())):
        started = time.perf_counter()
        _, transient = scene.integrator().render(scene, sensor=k, seed=int(seed))
        rows.append(np.array(transient, dtype=np.float64).ravel())
        elapsed += time.perf_counter() - started
    estimates.append(rows)
    seconds.append(elapsed)
np.savez(sys.argv[2], estimates=np.array(estimates), seconds=np.array(seconds),
         version=np.array(mitransient.__version__))
"""


@dataclass(frozen=True)
class MitransientRuns:
    """mitransient renders of one scene, one per seed, corrected to omni point sensors.

    Attributes
    ----------
    estimates : numpy.ndarray
        ``(R, K, N)``: factor x the meters' transients (bins shifted by the
        offset), one render per seed.
    seconds : numpy.ndarray
        ``(R,)`` wall time of each seed's K renders, seconds.
    samples : int
        Samples per sensor and render.
    version : str
        mitransient's version.
    """

    estimates: np.ndarray
    seconds: np.ndarray
    samples: int
    version: str

    @property
    def mean(self) -> np.ndarray:
        """``(K, N)`` mean over the seeds."""
        return self.estimates.mean(axis=0)

    @property
    def stderr(self) -> np.ndarray:
        """``(K, N)`` standard error of :attr:`mean` from the spread of the seeds (R - 1 degrees of freedom)."""
        replicas = self.estimates.shape[0]
        return self.estimates.std(axis=0, ddof=1) / math.sqrt(replicas)

    @property
    def dof(self) -> int:
        return self.estimates.shape[0] - 1


def run_mitransient(*, source, sensors, sampling: Sampling, samples: int, seeds, max_depth: int = 1,
                    scene: Scene | None = None, albedo: float | None = None, size: float = 1.0,
                    variant: str = "llvm_ad_mono", timeout: float = 3600.0) -> MitransientRuns:
    """Render with mitransient's ``transient_path``, one render per seed and sensor.

    Parameters
    ----------
    source : array_like
        Point emitter, metres (the intensity is ``scene``'s, else 1 W/sr).
    sensors : array_like
        ``(K, 3)`` meter centres, metres.
    sampling : Sampling
        The omni sensors' bins (the meters' start earlier by the offset).
    samples : int
        Samples per sensor and render.
    seeds : sequence of int
        One render per seed.
    max_depth : int
        Surface bounces (ours; mitransient's is one more).
    scene : Scene, optional
        A single-plane scene: its plane and reflectance image.
    albedo : float, optional
        Without ``scene``: the corner's floor and wall of this albedo.
    size : float
        Corner side, metres.
    variant : str
        Mitsuba variant for mitransient (an ``_ad_`` variant).

    Raises
    ------
    RuntimeError
        mitransient missing or failing.
    """
    from transient.mitsuba_scene import METER_RADIUS, irradiancemeter_correction

    if importlib.util.find_spec("mitransient") is None:
        raise RuntimeError("mitransient not installed (pip install -e .[bench])")
    if (scene is None) == (albedo is None):
        raise ValueError("give either scene (a plane) or albedo (the corner)")
    with tempfile.TemporaryDirectory(prefix="mitransient-") as folder:
        spec, result = Path(folder) / "spec.npz", Path(folder) / "result.npz"
        reflectance = (np.asarray(scene.reflectance, dtype=np.float64) if scene is not None else np.zeros(0))
        np.savez(spec, variant=np.array(variant), reflectance=reflectance,
                 size=np.float64(scene.size if scene is not None else size),
                 albedo=np.float64(albedo if albedo is not None else 0.0),
                 source=np.asarray(source, dtype=np.float64), sensors=np.asarray(sensors, dtype=np.float64),
                 start_opl=np.float64(sampling.start_opl), bin_width_opl=np.float64(sampling.bin_width_opl),
                 count=np.int64(sampling.count), max_depth=np.int64(max_depth), samples=np.int64(samples),
                 seeds=np.asarray(list(seeds), dtype=np.int64), radius=np.float64(METER_RADIUS),
                 intensity=np.float64(scene.intensity if scene is not None else 1.0))
        # The subprocess imports this very copy of the packages.
        environment = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        done = subprocess.run([sys.executable, "-c", _MITRANSIENT, str(spec), str(result)], capture_output=True,
                              text=True, timeout=timeout, env=environment)
        if done.returncode != 0:
            raise RuntimeError("mitransient failed: " + " ".join(done.stderr.strip().splitlines()[-1:]))
        with np.load(result, allow_pickle=False) as saved:
            factor, _ = irradiancemeter_correction(METER_RADIUS)
            return MitransientRuns(factor * np.array(saved["estimates"]), np.array(saved["seconds"]),
                                   int(samples), str(saved["version"]))


# -- figures ------------------------------------------------------------------------


def device_name(variant: str) -> str:
    """The device a variant runs on: the CPU model and thread count, or the CUDA GPU's name."""
    import drjit as dr

    if variant.startswith("cuda"):
        try:
            done = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                                  text=True, timeout=30)
            names = done.stdout.strip().splitlines()
            if done.returncode == 0 and names:
                return names[0].strip()
        except (OSError, subprocess.SubprocessError):
            pass
        return "CUDA GPU (name unavailable)"
    return f"{cpu_model()}, {dr.thread_count()} threads"


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), or what the platform says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def _relative(estimate, reference) -> float:
    return float(np.linalg.norm(estimate - reference) / np.linalg.norm(reference))


def _model(scene: Scene, tolerance: float | None = None) -> tuple[np.ndarray, float]:
    from analytic.operator.system import QuadratureWarning, system_matrix
    from analytic.operator.matrix_free import forward

    with warnings.catch_warnings():
        # The reference's own error (1e-8 relative) is far below every error measured.
        warnings.simplefilter("ignore", QuadratureWarning)
        started = time.perf_counter()
        y = forward(scene, system_matrix(scene, tolerance=tolerance))
        return y, time.perf_counter() - started


def _ours(scene: Scene, reference: np.ndarray, powers, seeds: int, variant: str | None) -> list[dict]:
    from transient.render import render

    render(scene, spp=2**16, seed=99, variant=variant, progress=False)          # compile the kernel
    rows = []
    for power in powers:
        runs = [render(scene, spp=2**power, seed=1000 * power + s, variant=variant, progress=False)
                for s in range(seeds)]
        errors = np.array([_relative(run.mean, reference) for run in runs])
        seconds = float(np.mean([run.seconds for run in runs]))
        rms = float(np.sqrt(np.mean(errors**2)))
        rows.append({"method": "ours", "samples": 2**power, "seconds": seconds, "rms_error": rms,
                     "efficiency": 1.0 / (rms**2 * seconds), "variant": runs[0].variant})
    return rows


def _mitransient(scene: Scene, reference: np.ndarray, powers, seeds: int, variant: str) -> tuple[list[dict], str]:
    rows, version = [], ""
    norm = float(np.linalg.norm(reference))
    for power in powers:
        runs = run_mitransient(source=scene.source, sensors=scene.sensors, sampling=scene.sampling,
                               samples=2**power, seeds=range(1000 * power, 1000 * power + seeds), scene=scene,
                               variant=variant)
        version = runs.version
        errors = np.array([_relative(estimate, reference) for estimate in runs.estimates])
        rms = float(np.sqrt(np.mean(errors**2)))
        # Split error² into noise² (the seeds' spread) and bias² (their mean's offset beyond it).
        noise2 = float(np.sum(runs.estimates.var(axis=0, ddof=1))) / norm**2
        bias2 = max(float(np.sum((runs.mean - reference) ** 2)) / norm**2 - noise2 / seeds, 0.0)
        seconds = float(np.mean(runs.seconds))
        rows.append({"method": f"mitransient {version}", "samples": 2**power, "seconds": seconds,
                     "rms_error": rms, "efficiency": 1.0 / (rms**2 * seconds),
                     "noise_error": math.sqrt(noise2), "bias_error": math.sqrt(bias2),
                     "noise_efficiency": 1.0 / (noise2 * seconds) if noise2 > 0 else float("inf")})
    return rows, version


def _time_to(rows: list[dict], target: float, *, noise_only: bool) -> dict:
    """Time to an RMS relative error ``target``: the first run that reached it, or an extrapolation."""
    reached = [r for r in rows if r["rms_error"] <= target]
    if reached:
        first = min(reached, key=lambda r: r["seconds"])
        return {"seconds": first["seconds"], "how": "measured"}
    if noise_only:
        # Error² = noise² + bias²; noise² ∝ 1/time. In mitransient's favour: bias left out.
        last = rows[-1]
        return {"seconds": 1.0 / (last["noise_efficiency"] * target**2), "how": "extrapolated (noise only)",
                "bias_error": last["bias_error"]}
    # Ours: fit log error against log time over the last three runs.
    tail = rows[-3:]
    slope, intercept = np.polyfit(np.log([r["seconds"] for r in tail]), np.log([r["rms_error"] for r in tail]), 1)
    return {"seconds": float(math.exp((math.log(target) - intercept) / slope)),
            "how": f"extrapolated (error ∝ time^{slope:.2f})"}


def _throughput(variant: str | None, samples: int) -> list[dict]:
    from transient.render import render

    rows = []
    for sensors in (1, 16, 64):
        for pixels in (50, 256):
            scene = throughput_scene(sensors, pixels)
            render(scene, spp=2**16, seed=1, variant=variant, progress=False)   # compile
            result = render(scene, spp=samples, seed=2, variant=variant, progress=False)
            rate = result.samples / result.seconds
            rows.append({"sensors": sensors, "pixels": pixels, "bins": scene.sampling.count,
                         "samples": result.samples, "seconds": result.seconds, "samples_per_second": rate,
                         "sensor_samples_per_second": rate * sensors})
    return rows


def speed_against_error(out: str | Path, *, powers=range(16, 27, 2), variant: str | None = None,
                        seeds: int = 4, mitransient_powers=range(16, 23, 2),
                        throughput_samples: int = 2**24) -> dict:
    """Run ours and mitransient on both bench scenes, the throughput table and the model; write the report.

    Parameters
    ----------
    out : str or Path
        Output folder (bench.md, bench.png, metrics.json).
    powers : iterable of int
        Our sample counts 2^p.
    variant : str, optional
        Mitsuba variant for our renderer (default: the CPU one); mitransient
        runs on the matching ``_ad_`` variant of the same device.
    seeds : int
        Renders per sample count (the RMS is over them).
    mitransient_powers : iterable of int
        mitransient's sample counts (per sensor).
    throughput_samples : int
        Samples of each throughput render.

    Returns
    -------
    dict
        ``markdown`` and everything in metrics.json.
    """
    from transient.backend import select_variant

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    variant = select_variant(variant)
    other = "cuda_ad_mono" if variant.startswith("cuda") else "llvm_ad_mono"
    powers, mitransient_powers = list(powers), list(mitransient_powers)
    report = {"device": device_name(variant), "variant": variant, "mitransient_variant": other,
              "scenes": {}, "mitransient": {"status": "ok"}}
    for scene in (plane_scene(), default_scene(noise=None)):
        reference, _ = _model(scene, 1e-8)
        entry = {"sensors": scene.sensor_count, "bins": scene.sampling.count, "pixels": scene.pixels,
                 "ours": _ours(scene, reference, powers, seeds, variant)}
        if report["mitransient"]["status"] == "ok":
            try:
                entry["mitransient"], version = _mitransient(scene, reference, mitransient_powers, seeds, other)
                report["mitransient"]["version"] = version
            except RuntimeError as error:
                report["mitransient"] = {"status": str(error)}
        entry["time_to_error"] = {}
        for target in TARGETS:
            ours = _time_to(entry["ours"], target, noise_only=False)
            row = {"ours": ours}
            if "mitransient" in entry:
                theirs = _time_to(entry["mitransient"], target, noise_only=True)
                row.update(mitransient=theirs, efficiency_ratio=theirs["seconds"] / ours["seconds"])
            entry["time_to_error"][f"{target:g}"] = row
        report["scenes"][scene.name] = entry
    report["throughput"] = _throughput(variant, throughput_samples)
    report["model"] = _model_rows()
    markdown = _markdown(report)
    atomic_write(out / "bench.md", lambda temporary: Path(temporary).write_text(markdown + "\n"))
    save_json(out / "metrics.json", report)
    save_figure(speed_against_error_figure(report), out / "bench.png")
    return dict(report, markdown=markdown)


def _model_rows() -> list[dict]:
    scene = plane_scene()
    _model(scene, 1e-6)                                  # compile / load the kernels
    reference, _ = _model(scene, 1e-8)
    peak = float(np.max(reference))
    rows = []
    for tolerance in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7):
        y, seconds = _model(scene, tolerance)
        rows.append({"tolerance": tolerance, "seconds": seconds,
                     "max_error_over_peak": float(np.max(np.abs(y - reference)) / peak)})
    return rows


def _markdown(report: dict) -> str:
    lines = [f"Device: {report['device']} (ours: {report['variant']}; mitransient: "
             f"{report['mitransient_variant']}). Errors are RMS over seeds of ||y - y_model|| / ||y_model||; "
             f"efficiency = 1 / (error² x seconds).", ""]
    for name, entry in report["scenes"].items():
        lines += [f"### {name} ({entry['sensors']} sensors, {entry['bins']} bins, M = {entry['pixels']})", "",
                  "| method | samples | seconds | RMS error | efficiency | noise / bias |", "|---|---|---|---|---|---|"]
        for row in entry["ours"] + entry.get("mitransient", []):
            split = (f"{row['noise_error']:.2e} / {row['bias_error']:.2e}" if "noise_error" in row else "-")
            lines.append(f"| {row['method']} | 2^{int(round(math.log2(row['samples'])))} | {row['seconds']:.4g} | "
                         f"{row['rms_error']:.2e} | {row['efficiency']:.3g} | {split} |")
        lines += ["", "| RMS error | ours (s) | mitransient (s) | efficiency ratio |", "|---|---|---|---|"]
        for target, row in entry["time_to_error"].items():
            theirs = row.get("mitransient")
            lines.append(f"| {target} | {row['ours']['seconds']:.3g} ({row['ours']['how']}) | "
                         + (f"{theirs['seconds']:.3g} ({theirs['how']}) | {row['efficiency_ratio']:.3g} |"
                            if theirs else "- | - |"))
        lines.append("")
    if report["mitransient"]["status"] != "ok":
        lines += [f"mitransient: {report['mitransient']['status']}", ""]
    lines += ["### Throughput", "", "| K | M | bins | samples | seconds | samples/s | sensor-samples/s |",
              "|---|---|---|---|---|---|---|"]
    for row in report["throughput"]:
        lines.append(f"| {row['sensors']} | {row['pixels']} | {row['bins']} | 2^{int(round(math.log2(row['samples'])))}"
                     f" | {row['seconds']:.3g} | {row['samples_per_second']:.3g} | "
                     f"{row['sensor_samples_per_second']:.3g} |")
    lines += ["", "### Model (plane 1x1)", "", "| tolerance | seconds | max error / peak |", "|---|---|---|"]
    lines += [f"| {r['tolerance']:g} | {r['seconds']:.4f} | {r['max_error_over_peak']:.2e} |" for r in report["model"]]
    return "\n".join(lines)
