"""The cross-check of one scene: model, render, judge, and what the paper's simplifications cost.

For a scene, :func:`check_scene`

1. assembles A and y = A f (the exact `lambertian` model);
2. renders y with the Monte Carlo renderer at ``spp`` samples and judges
   the difference with :func:`validation.compare.compare_transients`
   (DESIGN.md section 6);
3. shows that the model's own quadrature error is far below the render's
   noise: y at looser tolerances against y at 1e-7, over each judged bin's
   standard error;
4. renders at spp/64, spp/16, spp/4 as well and fits the N^-1/2 slope of the
   relative L2 error;
5. measures the paper's simplifications as relative differences: eq. (1)'s
   attenuation against physical transport, and eq. (3)'s contour integral
   without the coarea factor against the correct one;
6. reconstructs the image from the rendered and from the modelled data with
   the same λ and reports both errors against the true image.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from analytic.response import impulse_response
from analytic.scene import Scene
from analytic.system import QuadratureWarning, system_matrix
from validation.compare import Agreement, compare_transients

__all__ = ["SceneCheck", "check_scene", "simplification_costs", "model_convergence",
           "binned_contour_model"]

TOLERANCES = (1e-2, 1e-4, 1e-6)
REFERENCE_TOLERANCE = 1e-7


@dataclass
class SceneCheck:
    """Everything the report shows for one scene."""

    name: str
    scene: Scene
    spp: int
    seed: int
    model: np.ndarray
    render: np.ndarray
    stderr: np.ndarray
    agreement: Agreement
    metrics: dict = field(default_factory=dict)
    render_convergence: list = field(default_factory=list)
    model_convergence: list = field(default_factory=list)
    reconstructions: dict = field(default_factory=dict)


def _matrix(scene: Scene, tolerance: float | None = None):
    with warnings.catch_warnings():   # the 1e-7 reference may stop short of it; still ≪ noise
        warnings.simplefilter("ignore", QuadratureWarning)
        return system_matrix(scene, tolerance=tolerance)


def _y(matrix, scene: Scene) -> np.ndarray:
    return (matrix @ scene.reflectance.ravel()).reshape(scene.sensor_count, scene.sampling.count)


def model_convergence(scene: Scene, stderr: np.ndarray, judged: np.ndarray, *,
                      known: dict | None = None, tolerances=TOLERANCES) -> list[dict]:
    """The model's own error at each tolerance against tolerance 1e-7.

    ``over_stderr`` is max over the judged bins of |y(tol) - y(1e-7)| / se:
    far below 1 means the model is exact at the render's noise level.
    ``known`` maps a tolerance to (y, seconds) already computed, so the
    scene's own assembly is not repeated.
    """
    known = known or {}
    reference = _y(_matrix(scene, REFERENCE_TOLERANCE), scene)
    rows = []
    for tolerance in tolerances:
        if tolerance in known:
            y, seconds = known[tolerance]
        else:
            started = time.perf_counter()
            y = _y(_matrix(scene, tolerance), scene)
            seconds = time.perf_counter() - started
        difference = np.abs(y - reference)
        rows.append({"tolerance": tolerance, "seconds": seconds,
                     "max_abs_error": float(difference.max()),
                     "relative_to_peak": float(difference.max() / np.max(reference)),
                     "over_stderr": float(np.max(difference[judged] / stderr[judged]))
                     if judged.any() else float("nan")})
    return rows


def simplification_costs(scene: Scene, y_lambertian: np.ndarray, *, sensors: int = 4,
                         times: int = 48) -> dict:
    """Relative L2 differences caused by the paper's eq. (1) and eq. (3).

    ``paper_attenuation``: ||y_paper - y|| / ||y|| (no cos θ_k, no 1/π).
    ``paper_attenuation_shape``: the same after scaling y_paper to y's norm
    (how much more than a constant factor it changes).
    ``no_coarea_factor``: ||g_eq3 - g|| / ||g|| for the impulse responses of
    the first ``sensors`` sensors on ``times`` path lengths across each response,
    g_eq3 the unit-speed contour integral without 1/|∇d|, scaled to g's norm
    (the omission changes the shape, not only the scale).
    """
    y_paper = _y(_matrix(scene.replace(attenuation="paper")), scene)
    norm = float(np.linalg.norm(y_lambertian))
    scaled = y_paper * norm / float(np.linalg.norm(y_paper))
    result = {"paper_attenuation": float(np.linalg.norm(y_paper - y_lambertian) / norm),
              "paper_attenuation_shape": float(np.linalg.norm(scaled - y_lambertian) / norm)}
    right, wrong = [], []
    edges = scene.sampling.edges
    for k in range(min(sensors, scene.sensor_count)):
        lit = np.nonzero(y_lambertian[k] > 0)[0]
        if len(lit) == 0:
            continue
        t = np.linspace(edges[lit[0]], edges[lit[-1] + 1], times + 2)[1:-1]
        right.append(impulse_response(scene, k, t))
        wrong.append(impulse_response(scene, k, t, coarea=False))
    if right:
        right, wrong = np.concatenate(right), np.concatenate(wrong)
        wrong = wrong * np.linalg.norm(right) / max(np.linalg.norm(wrong), 1e-300)
        result["no_coarea_factor"] = float(np.linalg.norm(wrong - right) / np.linalg.norm(right))
    return result


def binned_contour_model(scene: Scene, *, coarea: bool = True, pieces: int = 8, nodes: int = 8) -> np.ndarray:
    """y for the impulse illumination from the contour form: ∫_bin g_k(t) dt, ``(K, N)``.

    ``coarea=False`` integrates the paper's eq. (3) instead (no 1/|∇d|): a
    deliberately wrong model for the harness's tests. Composite
    Gauss–Legendre over each bin (``pieces`` x ``nodes`` points); bins
    outside [t_min, d_max] are skipped.
    """
    if scene.illumination.waveform != "impulse":
        raise ValueError("binned_contour_model: only the impulse illumination")
    unit, weights = np.polynomial.legendre.leggauss(nodes)
    edges = scene.sampling.edges
    y = np.zeros((scene.sensor_count, scene.sampling.count))
    for k in range(scene.sensor_count):
        for n in range(scene.sampling.count):
            cuts = np.linspace(edges[n], edges[n + 1], pieces + 1)
            centres, halves = 0.5 * (cuts[1:] + cuts[:-1]), 0.5 * np.diff(cuts)
            t = (centres[:, None] + halves[:, None] * unit[None, :]).ravel()
            values = impulse_response(scene, k, t, coarea=coarea).reshape(pieces, nodes)
            y[k, n] = float(np.sum(values * weights[None, :] * halves[:, None]))
    return y


def _reconstructions(matrix, scene: Scene, model: np.ndarray, rendered: np.ndarray) -> dict:
    """Same λ (oracle on the modelled data) for both data sets; errors against the true image."""
    from analytic.reconstruct import image_metrics, reconstruct

    truth = scene.reflectance
    pixels = scene.pixels
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)     # rank-deficient A: regularised answer
        from_model = reconstruct(matrix, model.ravel(), pixels, rule="oracle", truth=truth)
        from_render = reconstruct(matrix, rendered.ravel(), pixels, rule=float(from_model.lam))
    return {"lambda": float(from_model.lam),
            "model": {"image": from_model.image, **image_metrics(from_model.image, truth)},
            "render": {"image": from_render.image, **image_metrics(from_render.image, truth)}}


def check_scene(scene: Scene, *, spp: int, seed: int = 0, convergence: bool = True,
                reconstruction: bool = True, progress: bool = False) -> SceneCheck:
    """Model, render and compare one scene; see the module docstring.

    Parameters
    ----------
    scene : Scene
        A one-plane scene.
    spp : int
        Samples of the main render.
    seed : int
        Render seed (the convergence renders use seed + 1, + 2, + 3).
    convergence : bool
        Also run the model's tolerance sweep and the smaller renders.
    reconstruction : bool
        Also reconstruct from both data sets.
    progress : bool
        Progress bars for the renders.
    """
    from transient.render import render

    timings = {}
    started = time.perf_counter()
    matrix = _matrix(scene)
    model = _y(matrix, scene)
    timings["model_seconds"] = time.perf_counter() - started
    result = render(scene, spp=spp, seed=seed, progress=progress)
    timings["render_seconds"] = result.seconds
    agreement = compare_transients(result.mean, result.stderr, model, dof=result.dof)
    check = SceneCheck(scene.name, scene, spp, seed, model, result.mean, result.stderr, agreement)
    check.metrics.update(timings)
    check.metrics["agreement"] = agreement.as_dict()
    judged = np.isfinite(agreement.z)
    if convergence:
        check.model_convergence = model_convergence(
            scene, result.stderr, judged, known={scene.tolerance: (model, timings["model_seconds"])})
        rows = []
        for step, divisor in enumerate((64, 16, 4)):
            count = max(spp // divisor, 1024)
            smaller = render(scene, spp=count, seed=seed + 1 + step, progress=False)
            rows.append({"samples": count, "relative_l2": compare_transients(
                smaller.mean, smaller.stderr, model).relative_l2})
        rows.append({"samples": spp, "relative_l2": agreement.relative_l2})
        x = np.log([r["samples"] for r in rows])
        y = np.log([r["relative_l2"] for r in rows])
        check.render_convergence = rows
        check.metrics["render_slope"] = float(np.polyfit(x, y, 1)[0])
        check.metrics["model_convergence"] = check.model_convergence
        check.metrics["render_convergence"] = rows
    check.metrics["simplifications"] = simplification_costs(scene, model)
    if reconstruction:
        check.reconstructions = _reconstructions(matrix, scene, model, result.mean)
        check.metrics["reconstruction"] = {
            key: ({k: v for k, v in value.items() if k != "image"} if isinstance(value, dict) else value)
            for key, value in check.reconstructions.items()}
    return check
