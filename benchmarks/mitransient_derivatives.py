"""mitransient's forward-mode derivatives judged against the exact model's (issue 42; docs/mitransient-derivatives.md).

    python benchmarks/mitransient_derivatives.py --out out/mitransient-derivatives [--spp 4194304]
                                                 [--replicas 16] [--keys KEY ...] [--step 0.002]

For a small plane scene (:data:`SCENE_TEXT`: a 1 m plane of reflectance 0.5,
the source and one sensor 1 m above it, 24 bins of 4 cm), exported with
``diffuse-imaging export --format mitransient``, and each parameter key of
docs/design.md section 9 in :data:`MOTIONS`, this script

1. takes mitransient's forward-mode derivative: the matching entry of
   ``mi.traverse(scene)`` set as a function of one ``mi.Float`` t with
   ``dr.enable_grad(t)``, ``params.update()``, ``mi.render(scene, params,
   ...)`` of ``transient_path`` in ``llvm_ad_mono``, ``dr.forward(t)`` and
   ``dr.grad`` of the transient film; ``--replicas`` seeds, each written as
   ``<key>/ad_<seed>.npy`` in the layout of mitransient's films that
   ``check --data`` reads as replicas (``(K, 1, 1, N, 1)``). A derivative the
   API refuses is reported with the call and its message;
2. takes mitransient's own central finite differences of its primal renders
   (the same seed at t = ±``--step``: common random numbers) as the control,
   written as ``<key>/fd_<seed>.npy``: they carry every term of the
   derivative, bin edges included, so they separate "AD drops terms" from
   "the renderer's primal disagrees";
3. judges both against the exact column ∂y/∂key (:func:`analytic.jacobian`)
   under the irradiancemeter convention mitransient's spheres read (scale
   1/4, offset 2r/3 + RayEpsilon: :func:`validation.check.irradiancemeter`),
   with the comparison ``check`` uses for y (:func:`judge`: replicas' z,
   their sign-flip limits, the directed scale and offset tests), and the
   ratio of the sums over bins with its error from the replicas (the sum
   over bins telescopes away the bin-edge terms that box binning drops).

Prints the markdown table of docs/mitransient-derivatives.md and writes
results.json in --out. At the defaults: about 12 minutes on 2 busy cores.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analytic.files import save_json, save_npy, save_text
from analytic.scenes.scene_file import load_scene
from interop.mitransient.export import RADIUS

#: The scene studied: small, so that one derivative render of 2^22 samples takes a few seconds.
SCENE_TEXT = """\
# benchmarks/mitransient_derivatives.py: mitransient's derivatives against the exact model
[plane]
size = 1.0
pixels = 4
reflectance = 0.5

[source]
position = [0.5, 0.5, 1.0]

[sensors]
positions = [[0.2, 0.7, 1.0]]

[sampling]
period = 0.04
start = 1.9
count = 24
"""

#: A derivative whose largest bin is under this share of the exact column's largest is 0 (float32 rounding).
ROUNDING = 1e-6

#: Offset of the primal seeds of the derivative renders. Replica r renders its derivative with the
#: differential seed r + 1 and its differences with the seed r + 1: the same paths.
GRADIENT_SEEDS = 2**20

#: The reflectance of SCENE_TEXT, the scalar the second reflectance row renders.
UNIFORM_REFLECTANCE = 0.5

#: The sensor mitransient's export names after sensor 0 (a sphere carrying the irradiancemeter).
SENSOR_SHAPE = "sensor_000000"


@dataclass(frozen=True)
class Motion:
    """How one parameter key moves mitransient's scene.

    Attributes
    ----------
    parameter : str
        The entry of ``mi.traverse(scene)`` it changes.
    kind : {"scale", "translate", "point"}
        ``scale``: the entry times t (t = 1 at the scene); ``translate``:
        a transform composed with a translation by t along ``axis``;
        ``point``: a point moved by t along ``axis``.
    axis : int
        0, 1, 2 for x, y, z.
    scalar : bool
        Render the plane with a scalar reflectance (``reflectance.value``)
        instead of the exported bitmap texture.
    """

    parameter: str
    kind: str
    axis: int = 0
    scalar: bool = False

    @property
    def at(self) -> float:
        """t at the scene itself."""
        return 1.0 if self.kind == "scale" else 0.0


#: Our keys (docs/design.md section 9) and what each moves in mitransient's scene. The plane moving is, in
#: the model, the source and the sensors moving the other way (analytic.operator.parameters).
MOTIONS = {
    "plane.reflectance": Motion("plane.bsdf.reflectance.data", "scale"),
    "plane.reflectance (scalar)": Motion("plane.bsdf.reflectance.value", "scale", scalar=True),
    "source.position.z": Motion("source.position", "point", 2),
    "sensors.positions.0.z": Motion(f"{SENSOR_SHAPE}.to_world", "translate", 2),
    "plane.translation.z": Motion("plane.to_world", "translate", 2),
    "plane.translation.x": Motion("plane.to_world", "translate", 0),
}


def model_key(name: str) -> str:
    """The parameter key of a row (``plane.reflectance (scalar)`` is ``plane.reflectance``)."""
    return name.split(" ")[0]


# --------------------------------------------------------------------------- mitransient's side

def _move(mi, params, base, motion: Motion, t) -> None:
    """Set ``motion.parameter`` to its value at the scene moved by t (a number or an AD variable)."""
    value = base[motion.parameter]
    if motion.kind == "scale":
        params[motion.parameter] = value * t
    else:
        offset = mi.Vector3f(*[t if i == motion.axis else 0.0 for i in range(3)])
        params[motion.parameter] = (mi.Transform4f().translate(offset) @ value if motion.kind == "translate"
                                    else value + offset)
    params.update()


def _restore(params, base) -> None:
    for name, value in base.items():
        params[name] = type(value)(value)
    params.update()


class Renderer:
    """mitransient's scene (texture or scalar reflectance) with its parameters at the scene's values."""

    def __init__(self, xml: Path, spp: int):
        import mitsuba as mi

        mi.set_variant("llvm_ad_mono")
        import mitransient  # noqa: F401 (registers transient_path, transient_hdr_film)

        self.mi, self.spp = mi, spp
        self.scenes = {}
        for scalar in (False, True):
            path = xml if not scalar else _scalar_reflectance_xml(xml)
            scene = mi.load_file(str(path), spp=spp)
            params = mi.traverse(scene)
            base = {motion.parameter: type(params[motion.parameter])(params[motion.parameter])
                    for motion in MOTIONS.values() if motion.scalar == scalar}
            self.scenes[scalar] = (scene, params, base)

    def sensors(self) -> int:
        return len(self.scenes[False][0].sensors())

    def derivative(self, motion: Motion, seed: int) -> np.ndarray:
        """``(K, 1, 1, N, 1)`` mitransient's forward-mode derivative of each sensor's film along ``motion``
        (replica ``seed``: the paths of :meth:`difference`'s)."""
        import drjit as dr

        mi = self.mi
        scene, params, base = self.scenes[motion.scalar]
        films = []
        try:
            for k in range(len(scene.sensors())):
                t = mi.Float(motion.at)
                dr.enable_grad(t)
                _move(mi, params, base, motion, t)
                # the primal pass is discarded; Mitsuba refuses a differential seed equal to the primal's
                # and replaces a differential seed 0 by one derived from the primal's
                _, transient = mi.render(scene, params, sensor=k, seed=seed + GRADIENT_SEEDS, seed_grad=seed + 1,
                                         spp=self.spp, spp_grad=self.spp)
                dr.forward(t)
                films.append(np.array(dr.grad(transient), dtype=np.float64))
        finally:
            _restore(params, base)
        return np.stack(films)

    def path_derivatives(self, ours, motion: Motion, convention, points: int = 600) -> np.ndarray:
        """``(K, N)`` Mitsuba's own per-path derivative along a plane motion, integrated by quadrature.

        For each of ``points``² midpoints x0 of the unmoved plane, the ray
        from sensor k through x0 (started 2 sphere radii out, past the
        sphere) is intersected under ``dr.resume_grad`` and the emitter's
        contribution times the BSDF is evaluated as ``transient_path``
        evaluates it (``ds.d`` re-attached to ``si.p``); ``dr.forward(t)``
        gives each path's derivative, weighted by its solid angle
        cos θ_k dA / d_k² and binned at its unmoved length, under the
        irradiancemeter convention. What ``transient_path``'s forward mode
        would average to if it only summed these per-path derivatives over
        the directions it samples.
        """
        import drjit as dr

        mi = self.mi
        scene, params, base = self.scenes[motion.scalar]
        size, source, sampling = float(ours.size), np.asarray(ours.source, dtype=np.float64), ours.sampling
        centres = (np.arange(points) + 0.5) * size / points
        gx, gy = np.meshgrid(centres, centres, indexing="ij")
        plane = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=-1)
        rows = []
        try:
            for sensor in np.asarray(ours.sensors, dtype=np.float64):
                t = mi.Float(motion.at)
                dr.enable_grad(t)
                _move(mi, params, base, motion, t)
                toward = plane - sensor
                distance = np.linalg.norm(toward, axis=1)
                toward /= distance[:, None]
                origin = sensor + 2 * RADIUS * toward
                ray = mi.Ray3f(mi.Point3f(*origin.T), mi.Vector3f(*toward.T))
                with dr.resume_grad():
                    si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=True)
                    ds, _ = scene.sample_emitter_direction(dr.detach(si), mi.Point2f(0.5, 0.5), True)
                    ds.d = dr.replace_grad(ds.d, dr.normalize(ds.p - si.p))
                    value = (si.bsdf(ray).eval(mi.BSDFContext(), si, si.to_local(ds.d))
                             * scene.eval_emitter_direction(si, ds))
                    dr.forward(t, dr.ADFlag.ClearEdges)
                    derivative = np.array(dr.grad(value), dtype=np.float64).ravel()
                solid_angle = -toward[:, 2] / distance**2 * (size / points) ** 2
                length = np.linalg.norm(source - plane, axis=1) + distance
                bins = np.floor((length - sampling.start_opl - convention.offset_opl)
                                / sampling.bin_width_opl).astype(int)
                inside = (bins >= 0) & (bins < sampling.count)
                rows.append(np.bincount(bins[inside], weights=(derivative * solid_angle)[inside],
                                        minlength=sampling.count))
        finally:
            _restore(params, base)
        return convention.scale * np.array(rows)

    def difference(self, motion: Motion, seed: int, step: float) -> np.ndarray:
        """``(K, 1, 1, N, 1)`` the central difference (y(t + step) - y(t - step)) / (2 step) of mitransient's
        primal renders with one seed (common random numbers)."""
        mi = self.mi
        scene, params, base = self.scenes[motion.scalar]
        sides = []
        try:
            for sign in (1.0, -1.0):
                _move(mi, params, base, motion, motion.at + sign * step)
                sides.append(np.stack([np.array(mi.render(scene, sensor=k, seed=seed + 1, spp=self.spp)[1],
                                                dtype=np.float64) for k in range(len(scene.sensors()))]))
        finally:
            _restore(params, base)
        return (sides[0] - sides[1]) / (2.0 * step)


def _scalar_reflectance_xml(xml: Path) -> Path:
    """The exported scene with the plane's bitmap texture replaced by its (uniform) value as a number."""
    import xml.etree.ElementTree as ET

    tree = ET.parse(xml)
    for bsdf in tree.getroot().iter("bsdf"):
        texture = bsdf.find("texture[@name='reflectance']")
        if texture is not None:
            bsdf.remove(texture)
            ET.SubElement(bsdf, "float", name="reflectance", value=repr(UNIFORM_REFLECTANCE))
    return save_text(xml.with_name("scene_scalar.xml"), ET.tostring(tree.getroot(), encoding="unicode"))


def failure_text(error: BaseException) -> str:
    """The innermost message of an exception chain (Dr.Jit wraps the integrator's in its loop's)."""
    while error.__cause__ is not None:
        error = error.__cause__
    return f"{type(error).__name__}: {error}"


# --------------------------------------------------------------------------- the exact side and the verdict

def exact_column(scene, key: str, convention) -> np.ndarray:
    """``(2, K, N)`` what mitransient's spheres should read as ∂y/∂key, and its derivative along a time
    offset (per metre of path): scale · ∂y/∂key at start_opl + offset_opl, as ``check`` states y."""
    from analytic import jacobian
    from analytic.operator.parameters import with_values
    from validation.check.verdict import DERIVATIVE_STEP

    def column(offset: float) -> np.ndarray:
        moved = with_values(scene, {"sampling.start": scene.sampling.start_opl + offset})
        return convention.scale * jacobian(moved, [key])[..., 0]

    step = DERIVATIVE_STEP * scene.sampling.bin_width_opl
    at = column(convention.offset_opl)
    return np.stack([at, (column(convention.offset_opl + step) - at) / step])


def detached_expectation(scene, axis: int, convention, points: int = 3000, step: float = 1e-5) -> np.ndarray:
    """``(K, N)`` what a detached estimator's ∂y/∂(plane translation along ``axis``) averages to, by quadrature.

    The derivative that ``transient_path``'s forward mode estimates for a
    moving plane: each path keeps its sensor ray, its hit point slides along
    that ray with the moved plane (``scene.ray_intersect`` under
    ``dr.resume_grad``), the emitter's contribution is differentiated there,
    and the path stays in the bin of its unmoved length. Written as the
    derivative of the unmoved directions' light with the bins frozen, by a
    central difference over ``points``² midpoints of the plane (uniform
    reflectance only), under the irradiancemeter convention. Neither the
    bin edges nor the plane's moving outline (the silhouette, seen from the
    sensor) contribute: an exact derivative minus both.

    Notes
    -----
    With p the sensor, x0 a point of the unmoved plane and θ the plane's
    height, the ray p -> x0 meets the moved plane at
    x(θ) = p + (p_z - θ)/p_z (x0 - p); its radiance is
    f/π I cos θ_s / d_s² at x(θ), over the fixed solid angle
    cos θ_k dA / d_k² of x0. A motion within the plane (x, y) leaves every
    x(θ) where it was: 0.
    """
    reflectance = np.asarray(scene.reflectance, dtype=np.float64)
    if np.ptp(reflectance) != 0:
        raise ValueError("detached_expectation: a uniform reflectance only")
    size, source = float(scene.size), np.asarray(scene.source, dtype=np.float64)
    centres = (np.arange(points) + 0.5) * size / points
    gx, gy = np.meshgrid(centres, centres, indexing="ij")
    plane = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=-1)
    sampling = scene.sampling
    rows = []
    for sensor in np.asarray(scene.sensors, dtype=np.float64):
        to_sensor = sensor - plane
        sensor_distance = np.linalg.norm(to_sensor, axis=1)
        solid_angle = to_sensor[:, 2] / sensor_distance**3 * (size / points) ** 2
        length = np.linalg.norm(source - plane, axis=1) + sensor_distance
        bins = np.floor((length - sampling.start_opl - convention.offset_opl) / sampling.bin_width_opl).astype(int)
        inside = (bins >= 0) & (bins < sampling.count)

        def light(height: float) -> np.ndarray:
            hit = sensor + ((sensor[2] - height) / sensor[2]) * (plane - sensor)
            to_source = source - hit
            distance = np.linalg.norm(to_source, axis=1)
            radiance = reflectance.flat[0] / np.pi * scene.intensity * to_source[:, 2] / distance**3
            return np.bincount(bins[inside], weights=(radiance * solid_angle)[inside], minlength=sampling.count)

        rows.append((light(step) - light(-step)) / (2 * step) if axis == 2 else np.zeros(sampling.count))
    return convention.scale * np.array(rows)


def judge(scene, files: list[Path], directions: np.ndarray, false_alarm: float = 1e-3) -> dict:
    """Judge replicas of ∂y/∂key (files ``check --data`` reads) against the exact column ``directions[0]``.

    The comparison ``check`` applies to y (docs/design.md section 6:
    Student-t z from the replicas, limits from their sign flips, directed
    tests of a scale and a time offset). ``diffuse-imaging check SCENE
    --data FILES --derivative KEY --expect irradiancemeter`` is meant to
    replace this call (see docs/mitransient-derivatives.md).
    """
    from analytic.errors import DataError
    from validation.check import read_data
    from validation.check.verdict import MAX_RELATIVE_STDERR
    from validation.judging import compare_transients

    replicas = np.stack([read_data(path, scene) for path in files])
    count = replicas.shape[0]
    mean = replicas.mean(axis=0)
    stderr = replicas.std(axis=0, ddof=1) / math.sqrt(count)
    column = directions[0]
    sums = replicas.sum(axis=2)                                  # (R, K): each replica's sum over bins
    sum_stderr = sums.std(axis=0, ddof=1) / math.sqrt(count)
    result = {"replicas": count, "sum": mean.sum(axis=1).tolist(), "sum_stderr": sum_stderr.tolist(),
              "exact_sum": column.sum(axis=1).tolist()}
    result["ratio_of_sums"] = float(mean.sum() / column.sum())
    result["ratio_stderr"] = float(math.sqrt(np.sum(sum_stderr**2)) / abs(column.sum()))
    total_error = math.sqrt(float(np.sum(sum_stderr**2)))
    result["sum_z"] = float((mean.sum() - column.sum()) / total_error) if total_error > 0 else None
    result["mean"] = mean.tolist()
    largest = float(np.max(np.abs(mean)))
    if largest <= ROUNDING * float(np.max(np.abs(column))):
        result.update(verdict="zero", largest_relative=largest / float(np.max(np.abs(column))),
                      note="0 in every bin" if largest == 0 else "0 up to float32 rounding")
        return result
    try:
        agreement = compare_transients(mean, stderr, column, replicas=replicas, false_alarm=false_alarm,
                                       max_relative_stderr=MAX_RELATIVE_STDERR, directions=directions)
    except DataError as error:                              # e.g. every bin too noisy to judge
        result.update(verdict="not judged", note=str(error))
        return result
    result.update(agreement.as_dict())
    result["verdict"] = "agrees" if agreement.agrees else "disagrees"
    result["summary"] = agreement.summary()
    if agreement.directed is not None:
        result["scale"] = 1.0 + agreement.directed.scale_error
        result["scale_stderr"] = agreement.directed.scale_stderr
    return result


# --------------------------------------------------------------------------- the run

def _cell(result: dict | None) -> str:
    """One table cell: ratio of sums ± error, χ²/dof, max |z|, the directed scale, the verdict."""
    if result is None:
        return "not run"
    if "failed" in result:
        return f"**fails**: `{result['failed'][:120]}`"
    ratio = f"Σ ratio {result['ratio_of_sums']:.4f} ± {result['ratio_stderr']:.4f}"
    if result["verdict"] == "zero":
        return (f"**{result['note']}** (largest bin {result['largest_relative']:.1e} of the exact's): Σ ratio "
                f"{result['ratio_of_sums']:.1e}")
    if result["verdict"] == "not judged":
        return f"{ratio}; not judged: {result['note'][:80]}"
    scale = (f", scale {result['scale']:.4f} ± {result['scale_stderr']:.4f}" if "scale" in result else "")
    sum_z = f", Σ z {result['sum_z']:+.1f}" if result.get("sum_z") is not None else ""
    return (f"{ratio}{sum_z}; χ²/dof {result['chi2_per_dof']:.2f} over {result['bins']} bins, max abs z "
            f"{result['max_abs_z']:.1f}{scale}: **{result['verdict']}**")


def table(results: dict) -> str:
    """The markdown table of docs/mitransient-derivatives.md."""
    lines = ["| key | mitransient AD (`dr.forward`) vs exact | FD control (CRN, ± step) vs exact | replicas | "
             "samples | seconds (AD, FD) |", "|---|---|---|---|---|---|"]
    for name, row in results["rows"].items():
        lines.append(f"| `{name}` | {_cell(row.get('ad'))} | {_cell(row.get('fd'))} | {results['replicas']} | "
                     f"2^{int(math.log2(results['spp']))} | {row['seconds']['ad']:.0f}, {row['seconds']['fd']:.0f} |")
    return "\n".join(lines)


def run_key(renderer: Renderer, scene, name: str, out: Path, replicas: int, step: float, convention) -> dict:
    """Render, write and judge one key's AD and FD replicas."""
    motion = MOTIONS[name]
    folder = out / name.replace(" ", "_").replace("(", "").replace(")", "")
    directions = exact_column(scene, model_key(name), convention)
    save_npy(folder / "exact.npy", directions[0])
    row = {"parameter": motion.parameter, "kind": motion.kind, "seconds": {}}
    for method in ("ad", "fd"):
        started = time.perf_counter()
        files = []
        try:
            for seed in range(replicas):
                film = (renderer.derivative(motion, seed) if method == "ad"
                        else renderer.difference(motion, seed, step))
                files.append(save_npy(folder / f"{method}_{seed:02d}.npy", film))
        except Exception as error:                           # the API's refusal is the result
            row[method] = {"failed": failure_text(error)}
        row["seconds"][method] = time.perf_counter() - started
        if method not in row:
            row[method] = judge(scene, files, directions)
    if model_key(name).startswith("plane.translation") and "failed" not in row["ad"]:
        expected = detached_expectation(scene, "xyz".index(name[-1]), convention)
        save_npy(folder / "detached_expectation.npy", expected)
        row["detached"] = {"sum": float(expected.sum()), "ratio_to_exact": float(expected.sum() / directions[0].sum())}
        paths = renderer.path_derivatives(scene, motion, convention)
        save_npy(folder / "path_derivatives.npy", paths)
        if expected.any():
            lit = np.abs(expected) > 0.01 * np.max(np.abs(expected))
            row["detached"]["paths_largest_difference"] = float(np.max(np.abs(paths[lit] / expected[lit] - 1)))
            mean = np.array(row["ad"]["mean"])
            row["detached"].update(ad_ratio=float(mean.sum() / expected.sum()),
                                   bin_ratios=[float(np.min(mean[lit] / expected[lit])),
                                               float(np.max(mean[lit] / expected[lit]))])
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--spp", type=int, default=2**22, help="samples per derivative render (a power of 2)")
    parser.add_argument("--replicas", type=int, default=16, help="seeds per derivative (16: sign-flip limits)")
    parser.add_argument("--keys", nargs="+", default=list(MOTIONS), choices=list(MOTIONS), metavar="KEY")
    parser.add_argument("--step", type=float, default=2e-3,
                        help="the finite differences' half step (metres; relative for reflectance)")
    args = parser.parse_args(argv)
    from interop.mitransient import export_scene
    from validation.check import irradiancemeter
    from validation.runs.bench import cpu_model

    scene_path = args.out / "scene.toml"
    save_text(scene_path, SCENE_TEXT)
    scene = load_scene(scene_path)
    export_scene(scene, args.out / "xml", "mitransient")
    convention = irradiancemeter(scene, RADIUS)
    renderer = Renderer(args.out / "xml" / "scene.xml", args.spp)
    renderer.difference(MOTIONS["plane.reflectance"], 10**6, 0.5)          # compile once, outside the timing
    results = {"machine": cpu_model(), "spp": args.spp, "replicas": args.replicas, "step": args.step,
               "convention": {"scale": convention.scale, "offset_opl": convention.offset_opl}, "rows": {}}
    for name in args.keys:
        results["rows"][name] = run_key(renderer, scene, name, args.out, args.replicas, args.step, convention)
        save_json(args.out / "results.json", results)
        print(f"{name}: done", file=sys.stderr)
    print(f"machine: {results['machine']}; mitransient transient_path, llvm_ad_mono; exact columns under the "
          f"irradiancemeter convention (scale {convention.scale:g}, offset {convention.offset_opl:.3e} m)\n")
    print(table(results))
    for name, row in results["rows"].items():
        if "detached" in row:
            detached = row["detached"]
            ad = ("" if "ad_ratio" not in detached else f"; mitransient's AD / this: Σ {detached['ad_ratio']:.4f}, "
                  f"bins {detached['bin_ratios'][0]:.3f} to {detached['bin_ratios'][1]:.3f}; Mitsuba's per-path "
                  f"derivatives integrated over the plane: within {detached['paths_largest_difference']:.1e} of it "
                  f"in every lit bin")
            print(f"\n{name}: a detached estimator (no bin-edge, no silhouette term) averages to Σ = "
                  f"{detached['sum']:.5g}, {detached['ratio_to_exact']:.4f} of the exact Σ{ad}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
