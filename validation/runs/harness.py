"""The cross-check of one scene: model, render, judge, and what the paper's simplifications cost.

For a scene, :func:`check_scene`

1. assembles A and y = A f (the exact `lambertian` model);
2. renders y with the Monte Carlo renderer at ``spp`` samples and judges
   the difference with :func:`validation.judging.compare.compare_transients`
   (docs/design.md section 6), its limits from the render's replicas (valid
   whatever the correlation between bins), the render's scale and time
   offset tested against the model's, and states the smallest such errors
   it can detect (:attr:`validation.judging.agreement.Agreement.detectable`);
3. shows that the model's own quadrature error is far below the render's
   noise: y at looser tolerances against y at 1e-7, over each judged bin's
   standard error;
4. renders at spp/64, spp/16, spp/4 as well and fits the N^-1/2 slope of the
   relative L2 error;
5. measures the paper's simplifications as relative differences: eq. (1)'s
   attenuation against physical transport, and eq. (3)'s contour integral
   without the coarea factor against the correct one (a plane's: a capture
   through a relay wall has no paper attenuation to compare);
6. reconstructs the image from the modelled and from the rendered data, each
   with the scene's noise added (the same draw) and λ chosen by a
   data-driven rule (:func:`data_driven_rule`), and reports both errors
   against the true image beside the oracle λ's (a bound) and the best flat
   image's (the floor).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from analytic.errors import SceneError
from analytic.operator.response import impulse_response
from analytic.scenes.common import Scene
from analytic.scenes.kinds import for_kind
from analytic.operator.system import QuadratureWarning, system_matrix
from analytic.operator.matrix_free import forward
from validation.check.fit import ShiftedModel
from validation.check.readers import scene_of
from validation.check.verdict import DERIVATIVE_STEP
from validation.judging.compare import Agreement, compare_transients, model_tolerance_for, tighter_model_note

__all__ = ["SceneCheck", "check_scene", "refuse_dark", "imaging_problem", "simplification_costs", "model_convergence",
           "noise_sigma", "data_driven_rule", "reconstruct_from_noisy_data"]

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
    replicas: int = 0           # the render's R independent replicas (its stderr has R - 1 degrees of freedom)
    render_convergence: list = field(default_factory=list)
    model_convergence: list = field(default_factory=list)
    reconstructions: dict = field(default_factory=dict)

    def summary(self) -> str:
        """The agreement's summary, and the model's tolerance when the render needed a tighter one."""
        tighter = self.metrics.get("model_tolerance")
        note = "" if tighter is None else f"\n({tighter_model_note(tighter, self.scene.tolerance)})"
        return self.agreement.summary() + note


def _matrix(scene: Scene, tolerance: float | None = None):
    with warnings.catch_warnings():   # the 1e-7 reference may stop short of it; still ≪ noise
        warnings.simplefilter("ignore", QuadratureWarning)
        return system_matrix(scene, tolerance=tolerance)


def model_convergence(scene: Scene, stderr: np.ndarray, judged: np.ndarray, *,
                      known: dict | None = None, tolerances=TOLERANCES) -> list[dict]:
    """The model's own error at each tolerance against tolerance 1e-7.

    ``over_stderr`` is max over the judged bins of |y(tol) - y(1e-7)| / se:
    far below 1 means the model is exact at the render's noise level.
    ``known`` maps a tolerance to (y, seconds) already computed, so the
    scene's own assembly is not repeated.
    """
    known = known or {}
    reference = forward(scene, _matrix(scene, REFERENCE_TOLERANCE))
    rows = []
    for tolerance in tolerances:
        if tolerance in known:
            y, seconds = known[tolerance]
        else:
            started = time.perf_counter()
            y = forward(scene, _matrix(scene, tolerance))
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
    y_paper = forward(scene, _matrix(scene.replace(attenuation="paper")))
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
    # a response narrower than the samples' spacing (a 1e-9 m plane) can fall between them: no figure
    if right and np.linalg.norm(np.concatenate(right)) > 0:
        right, wrong = np.concatenate(right), np.concatenate(wrong)
        wrong = wrong * np.linalg.norm(right) / max(np.linalg.norm(wrong), 1e-300)
        result["no_coarea_factor"] = float(np.linalg.norm(wrong - right) / np.linalg.norm(right))
    return result


def noise_sigma(scene) -> float | None:
    """The scene's Gaussian noise level σ (units of y), or None when its noise is not one Gaussian σ > 0."""
    noise = scene.noise
    known = noise is not None and noise.kind == "gaussian" and noise.sigma > 0
    return float(noise.sigma) if known else None


def data_driven_rule(scene: Scene, requested="auto") -> tuple:
    """The λ rule for a scene's data, and the σ it needs.

    ``"auto"``: ``discrepancy`` when the scene's noise is Gaussian with
    σ > 0 (σ is known), else ``gcv``. A named rule or a number is kept;
    ``discrepancy`` without a Gaussian σ is a SceneError naming
    ``noise.sigma``.

    Returns
    -------
    (rule, sigma)
        ``sigma`` is the scene's σ for ``discrepancy``, else None.
    """
    sigma = noise_sigma(scene)
    if requested == "auto":
        requested = "gcv" if sigma is None else "discrepancy"
    if requested == "discrepancy":
        if sigma is None:
            raise SceneError("noise.sigma", "the discrepancy rule needs the scene's Gaussian noise level "
                                            "([noise] kind = \"gaussian\", sigma > 0)")
        return "discrepancy", sigma
    return requested, None


def reconstruct_from_noisy_data(matrix, scene: Scene, model: np.ndarray, rendered: np.ndarray, *,
                                rule="auto", lambdas=None) -> dict:
    """Reconstruct from the model's and the render's data, each with the scene's noise.

    The same noise draw (the scene's ``noise.seed``) is added to both; the
    rule is data-driven (:func:`data_driven_rule`) unless given. Beside them:
    the oracle λ on the model's noisy data (a bound no data-driven rule can
    beat on average) and the best flat image, the true mean (the floor).

    Returns
    -------
    dict
        ``noise`` (the scene's, None when noiseless), ``rule``, ``data`` (the
        sentences saying which data and rule gave each number, how many
        numbers of the image the data fix, and the warnings about A and σ),
        ``information``: {``rank``, ``effective_rank``, ``sigma``,
        ``unknowns``, ``measurements``} (:mod:`analytic.inversion.information`;
        the same for both data), ``warnings``: the inversion's warnings
        about A and σ, once, ``{"category", "message"}``, ``model`` and
        ``render``: {``psnr``, ``ssim``, ``lambda``, ``image``,
        ``degrees_of_freedom``, ``warnings``: the inversion's warnings about
        these data}, ``oracle``: {``psnr``, ``lambda``, ``image``},
        ``flat_psnr``, ``error``: the model's estimate's exact bias and standard deviation at its λ beside
        the Cramér-Rao bound (:func:`analytic.inversion.tikhonov_error.scene_tikhonov_error`'s summary; None
        beyond its size), ``error_note``: why it is None, in words (else None).
    """
    from analytic.inversion import (RankDeficiencyWarning, RegularizationWarning, flat_image_psnr, image_metrics,
                                    reconstruct)
    from analytic.inversion.tikhonov_error import scene_tikhonov_error, tikhonov_error_skipped
    from analytic.measurement.noise import add_noise

    truth = scene.reflectance
    pixels = scene.pixels
    rule, _ = data_driven_rule(scene, rule)
    noise = scene.noise
    if noise is not None:
        model_data = add_noise(model, noise, rng=np.random.default_rng(noise.seed))
        render_data = add_noise(rendered, noise, rng=np.random.default_rng(noise.seed))
        what = (f"{noise.kind} noise (σ = {noise.sigma:g})" if noise.kind == "gaussian"
                else f"photon-counting noise ({noise.photons:g} photons per unit of y)")
    else:
        model_data, render_data, what = model, rendered, "no added noise"
    results = {}
    known_sigma = noise_sigma(scene)     # what the data fix at their noise is counted against it
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("ignore", RuntimeWarning)     # numerical notices of the solvers
        # the inversion's own warnings change what a number means: kept for the report (and run's stderr)
        warnings.simplefilter("always", RankDeficiencyWarning)
        warnings.simplefilter("always", RegularizationWarning)
        for key, data in (("model", model_data), ("render", render_data)):
            first = len(caught)
            result = reconstruct(matrix, data.ravel(), pixels, rule=rule, truth=truth, sigma=known_sigma,
                                 lambdas=lambdas)
            results[key] = {"image": result.image, "lambda": float(result.lam),
                            **{k: v for k, v in image_metrics(result.image, truth).items()
                               if k in ("psnr", "ssim")},
                            "degrees_of_freedom": result.degrees_of_freedom,
                            # what concerns A and σ (the same for both data) is kept once, below
                            "warnings": [{"category": w.category.__name__, "message": str(w.message)}
                                         for w in caught[first:]
                                         if not issubclass(w.category, RankDeficiencyWarning)]}
        oracle = reconstruct(matrix, model_data.ravel(), pixels, rule="oracle", truth=truth, lambdas=lambdas)
    # what the model's λ trades, exactly, beside the Cramér-Rao bound (analytic.inversion.tikhonov_error)
    tikhonov = scene_tikhonov_error(scene, matrix, results["model"]["lambda"])
    for unexpected in caught:       # anything else goes on to the caller, as it did
        if not issubclass(unexpected.category, (RankDeficiencyWarning, RegularizationWarning)):
            warnings.warn_explicit(unexpected.message, unexpected.category, unexpected.filename,
                                   unexpected.lineno)
    shared = []                     # A's and σ's warnings, once (both reconstructions issued them)
    for caught_warning in caught:
        entry = {"category": caught_warning.category.__name__, "message": str(caught_warning.message)}
        if issubclass(caught_warning.category, RankDeficiencyWarning) and entry not in shared:
            shared.append(entry)
    information = {"rank": result.rank, "effective_rank": result.effective_rank, "sigma": known_sigma,
                   "unknowns": result.unknowns, "measurements": result.measurements}
    rule_name = rule if isinstance(rule, str) else f"λ = {rule:g}"
    return {
        "noise": None if noise is None else {"kind": noise.kind, "sigma": noise.sigma,
                                             "photons": noise.photons, "seed": noise.seed},
        "rule": rule_name,
        "data": (f"The model's and the render's transients, "
                 + (f"each with the scene's {what} added (the same draw), " if noise is not None
                    else "as they are (the scene has no [noise]), ")
                 + f"reconstructed with λ by the {rule_name} rule; the oracle λ "
                 f"(the truth's) on the model's noisy data is a bound, the best flat image the floor. "
                 + _information_sentence(information)
                 + "".join(f" Warning: {entry['message']}." for entry in shared)),
        "information": information,
        "warnings": shared,
        **results,
        "oracle": {"image": oracle.image, "lambda": float(oracle.lam),
                   "psnr": image_metrics(oracle.image, truth)["psnr"]},
        "flat_psnr": flat_image_psnr(truth),
        "error": None if tikhonov is None else tikhonov[2],
        "error_note": None if tikhonov is not None else tikhonov_error_skipped(scene, matrix),
    }


def _information_sentence(information: dict) -> str:
    """:func:`analytic.inversion.information.information_summary` as a sentence (or "")."""
    from analytic.inversion.information import information_summary

    text = information_summary(**{name: information[name] for name in ("rank", "effective_rank", "sigma",
                                                                        "unknowns")})
    return f"{text[0].upper()}{text[1:]}; the Laplacian prior fills the rest." if text else ""


def imaging_problem(scene) -> str | None:
    """Why no image can be reconstructed from this scene's transient (one sentence), or None.

    One sensor (or pair) sees path lengths only: each bin is an elliptical
    annulus of the surface, so the image is known up to everything that
    keeps each annulus' integral, and the λ rules pick λ ≈ 0 on its nearly
    noiseless data (the spad example read 235 dB from the model's data and
    -26 dB from the render's).
    """
    if scene.sensor_count >= 2:
        return None
    return (f"one {scene.row_noun} sees only path lengths (each bin "
            f"is an elliptical annulus of the surface), which no image can be recovered from; give two or more "
            f"to reconstruct")


def _no_simplifications(scene, y) -> None:
    """A kind the paper's eq. (1) and eq. (3) do not describe: nothing to measure."""
    return None


#: The costs of the paper's simplifications, for the kinds its equations describe (the plane).
_SIMPLIFICATIONS = {"plane": simplification_costs}


def refuse_dark(scene, share: float) -> None:
    """Refuse a scene whose sensors get no light in the window: model and render would both be exactly zero,
    with nothing to judge the render by (every standard error zero) and no image to recover.

    ``share`` is the window's share of the light (:func:`analytic.operator.window.window_share`).
    """
    dark = scene.darkness()
    if dark is not None:
        (key, why), fix = dark, "a reflectance above 0"
    elif share == 0:
        key, why, fix = "sampling", "the window holds none of the light", "a window that holds it (--window auto)"
    else:
        return
    raise SceneError(key, f"{why}, so the model and the render are both exactly zero in every bin: there is "
                          f"nothing to judge or reconstruct; forward and render model such a scene, or give {fix}")


def check_scene(scene: Scene, *, spp: int, seed: int = 0, convergence: bool = True,
                reconstruction: bool = True, progress: bool = False, rule="auto",
                lambdas=None, share: float | None = None) -> SceneCheck:
    """Model, render and compare one scene; see the module docstring.

    Parameters
    ----------
    scene : Scene, analytic.scenes.relay_wall.RelayWallScene, str or Path
        A one-plane scene, or a capture through a relay wall (its pairs as
        the sensors, the hidden image as the image), or its file.
    spp : int
        Samples of the main render, in [2, 2^48].
    seed : int
        Render seed (the convergence renders use seed + 1, + 2, + 3).
    convergence : bool
        Also run the model's tolerance sweep and the smaller renders.
    reconstruction : bool
        Also reconstruct from both data sets (:func:`reconstruct_from_noisy_data`), unless the scene
        cannot be imaged (:func:`imaging_problem`: then ``metrics["reconstruction"]`` is ``{"skipped":
        why}``).
    progress : bool
        Progress bars for the renders.
    rule : str or float
        λ rule of the reconstructions: ``"auto"`` (:func:`data_driven_rule`),
        a rule's name, or λ itself.
    lambdas : array_like, optional
        The λ grid the rules search (default: from A's singular values).
    share : float, optional
        The window's share of the light, when the caller has it
        (:func:`analytic.operator.window.window_share`, computed here otherwise).
    """
    from transient.render import render

    from analytic.operator.window import warn_if_cut, window_share

    scene = scene_of(scene)          # spp and seed: the renderer refuses them (OptionError) before any work
    timings = {}
    share = window_share(scene) if share is None else share
    refuse_dark(scene, share)
    warn_if_cut(scene, share)
    started = time.perf_counter()
    matrix = _matrix(scene)
    model = forward(scene, matrix)
    timings["model_seconds"] = time.perf_counter() - started
    result = render(scene, spp=spp, seed=seed, progress=progress)
    timings["render_seconds"] = result.seconds
    # a render more precise than the scene's tolerance is judged against the model evaluated tighter
    tighter = model_tolerance_for(scene.tolerance, result.mean, result.stderr)
    judged_scene = scene if tighter is None else scene.replace(tolerance=tighter)
    judged_model = ShiftedModel(judged_scene, model if tighter is None else None)
    # the replicas give the null of χ² and max |z| whatever the correlation between bins; the model's scale
    # and time offset are tested too, and the verdict states what it can detect (docs/design.md section 6)
    step = DERIVATIVE_STEP * scene.sampling.bin_width_opl
    directions = np.stack([judged_model(0.0), (judged_model(step) - judged_model(0.0)) / step])
    agreement = compare_transients(result.mean, result.stderr, judged_model(0.0), dof=result.dof,
                                   replicas=result.replica_means, directions=directions)
    check = SceneCheck(scene.name, scene, spp, seed, model, result.mean, result.stderr, agreement,
                       replicas=result.replicas)
    check.metrics.update(timings)
    check.metrics["window_share"] = share
    check.metrics["model_tolerance"] = tighter
    check.metrics["agreement"] = agreement.as_dict()
    check.metrics["detectable"] = agreement.detectable
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
    simplifications = for_kind(_SIMPLIFICATIONS, scene, "simplifications", default=_no_simplifications)
    costs = simplifications(scene, model)
    if costs is not None:
        check.metrics["simplifications"] = costs
    unimageable = imaging_problem(scene) if reconstruction else None
    if unimageable is not None:
        check.metrics["reconstruction"] = {"skipped": unimageable}
    elif reconstruction:
        check.reconstructions = reconstruct_from_noisy_data(matrix, scene, model, result.mean, rule=rule,
                                                            lambdas=lambdas)
        check.metrics["reconstruction"] = {
            key: ({k: v for k, v in value.items() if k != "image"} if isinstance(value, dict) else value)
            for key, value in check.reconstructions.items()}
    return check
