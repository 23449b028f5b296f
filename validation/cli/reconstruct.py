"""``diffuse-imaging reconstruct`` and ``reproduce``: the image from a transient, and the paper's experiments."""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from .common import (UsageError, add_quiet, announce_model, load_scene_argument, positive_float_type,
                     refuse_unmodellable, release_warnings, rows_text, show_progress)

__all__ = ["add_commands", "command_reconstruct", "command_reproduce", "lambda_argument", "lambda_grid_of",
           "add_lambda_options", "error_text"]


def lambda_argument(text: str):
    """``--lambda``: a rule name, ``auto``, or a positive number (λ itself)."""
    from analytic.inversion import RULES

    if text in RULES or text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--lambda: expected auto, {', '.join(RULES)} or a number > 0, "
                                         f"got {text!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"--lambda: a numeric λ must be finite and > 0, got {text!r}")
    return value


def lambda_grid_of(args):
    """The λ grid of ``--lambda-range MIN MAX`` and ``--lambda-count N``, or None for the default."""
    from analytic.inversion import DEFAULT_LAMBDA_COUNT, lambda_grid

    if args.lambda_range is None:
        if args.lambda_count is not None:
            raise UsageError("--lambda-count: needs --lambda-range MIN MAX")
        return None
    minimum, maximum = args.lambda_range
    try:
        count = DEFAULT_LAMBDA_COUNT if args.lambda_count is None else args.lambda_count
        return lambda_grid(minimum, maximum, count)
    except ValueError as error:
        raise UsageError(f"--lambda-range/--lambda-count: {error}") from None


def add_lambda_options(parser, *, default: str) -> None:
    """``--lambda``, ``--lambda-range`` and ``--lambda-count``, shared by reconstruct and run."""
    parser.add_argument("--lambda", dest="rule", default=default, type=lambda_argument,
                        metavar="RULE|VALUE",
                        help="auto (discrepancy when the scene has Gaussian noise, else gcv) | oracle "
                             "| gcv | lcurve | discrepancy | a number > 0 (λ itself) "
                             f"(default {default})")
    parser.add_argument("--lambda-range", nargs=2, type=positive_float_type("--lambda-range"),
                        metavar=("MIN", "MAX"), help="λ grid the rule searches (default: from A's "
                                                     "singular values)")
    parser.add_argument("--lambda-count", type=int, metavar="N",
                        help="values in the λ grid, log-spaced (default 40)")


def command_reconstruct(args) -> int:
    """Reconstruct the scene's image from a transient; write images, metrics, figures, report."""
    from analytic.errors import SceneError
    from analytic.files import (PrecisionWarning, discard, float32_problem, output_folder, reading_folder,
                             save_exr, save_json, save_npy, save_png_image, staged_writes)
    from analytic.inversion import RankDeficiencyWarning, RegularizationWarning, image_metrics, reconstruct
    from analytic.inversion.tikhonov_error import scene_tikhonov_error, tikhonov_error_skipped
    from analytic.operator.offset_operator import OffsetOperator
    from validation.plots.bounds import tikhonov_error_figure
    from validation.runs.harness import data_driven_rule, noise_sigma
    from validation.plots import criterion_figure, reconstruction_figure, save_figure
    from validation.runs.report import write_markdown

    scene = load_scene_argument(args.scene)
    cost = refuse_unmodellable(scene)
    rule, sigma = data_driven_rule(scene, args.rule)
    known_sigma = noise_sigma(scene)       # counts what the data fix at their noise, whatever the rule
    if args.regularizer == "tv":
        if rule in ("gcv", "lcurve") and args.rule == "auto":
            raise UsageError("--regularizer tv: its default rule, discrepancy, needs the scene's Gaussian σ "
                             "([noise] sigma); give --lambda oracle or a number")
        if rule in ("gcv", "lcurve"):
            raise UsageError(f"--lambda {rule}: not defined for --regularizer tv "
                             f"(use oracle, discrepancy or a number)")
        if args.method is not None:
            raise UsageError("--method: applies to --regularizer laplacian only")
    grid = lambda_grid_of(args)
    with reading_folder(args.data, option="--data"):    # no command writes the data while they are read
        data = _read_data(args.data, scene)
    release_warnings()                                   # the inputs are accepted: what they warned of first
    with output_folder(args.out) as out:
        announce_model(args, cost, "reconstruct")
        assembly_started = time.perf_counter()
        matrix = reconstruction_matrix(scene, args.regularizer, args.method, progress=show_progress(args))
        assembly = time.perf_counter() - assembly_started
        if matrix.nnz == 0:
            raise SceneError("sampling", "the window holds none of the light: no sample sees the plane (or "
                                         "the hidden rectangle), nothing to reconstruct; widen [sampling] "
                                         "start/count")
        truth = np.asarray(scene.reflectance, dtype=np.float64)
        options = {} if args.regularizer == "tv" else {"method": args.method, "progress": show_progress(args)}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = reconstruct(matrix, data, scene.pixels, rule=rule, truth=truth, sigma=known_sigma,
                                 lambdas=grid, regularizer=args.regularizer, **options)
        notes = [str(w.message) for w in caught]
        metrics = image_metrics(result.image, truth, data_range=1.0)
        report = {
            "scene": scene.name, "data": str(args.data), "pixels": scene.pixels,
            "lambda": result.lam, "rule": result.rule, "method": result.method,
            "mse": metrics["mse"], "psnr": metrics["psnr"], "ssim": metrics["ssim"],
            "data_range": metrics["data_range"],
            "metrics_note": "against the scene's reflectance; PSNR and SSIM over a data range of 1.0 "
                            "(reflectance in [0, 1]); the estimate is not clipped (the PNG is)",
            "residual_norm": result.residual_norm, "seminorm": result.seminorm, "rank": result.rank,
            "effective_rank": result.effective_rank, "degrees_of_freedom": result.degrees_of_freedom,
            "unknowns": result.unknowns, "measurements": result.measurements, "sigma": known_sigma,
            "seconds": result.seconds, "assembly_seconds": assembly, "stopping": result.stopping,
            "regularizer": ("squared 5-point Laplacian, reflecting (Neumann) boundaries, unit spacing"
                            if args.regularizer == "laplacian" else
                            "isotropic total variation (½||Af − y||² + λ TV), Neumann edges, PDHG"),
            "warnings": notes, "lambdas": result.lambdas, "criterion": result.criterion,
            "operator": ("A applied matrix-free, by FFT over the capture's pixel offsets "
                         "(analytic.operator.offset_operator)" if isinstance(matrix, OffsetOperator) else
                         "A assembled sparse (analytic.operator.system)"),
        }
        tikhonov = (scene_tikhonov_error(scene, matrix, result.lam) if args.regularizer == "laplacian" else None)
        report["tikhonov_error"] = None if tikhonov is None else tikhonov[2]
        if args.regularizer == "laplacian" and tikhonov is None:
            report["tikhonov_error_note"] = tikhonov_error_skipped(scene, matrix)
        exr_problem = float32_problem(result.image)
        report["exr"] = ("written: float32, every value within float32's rounding of reconstruction.npy"
                         if exr_problem is None else
                         f"not written: {exr_problem}; reconstruction.npy is the exact record")
        how = (f"λ = {result.lam:.3g} by the {result.rule} rule" if result.rule != "value"
               else f"λ = {result.lam:.3g} as given")
        with staged_writes():
            save_npy(out / "reconstruction.npy", result.image)
            if exr_problem is None:
                save_exr(out / "reconstruction.exr", result.image,
                         {"lambda": result.lam, "rule": result.rule, "method": result.method,
                          "units": "reflectance (unclipped)"})
            else:
                discard(out / "reconstruction.exr")      # an earlier run's: not this image
            save_png_image(out / "reconstruction.png", result.image)
            save_json(out / "metrics.json", report)
            save_figure(criterion_figure(result, title=f"{scene.name}: {how}"), out / "criterion.png")
            if tikhonov is not None:
                save_figure(tikhonov_error_figure(tikhonov[0].bias, tikhonov[0].stddev, tikhonov[1],
                                                  title=f"{scene.name}: {how}"), out / "error.png")
            save_figure(reconstruction_figure(truth, result.image,
                                              title=f"{scene.name}: {how}, PSNR {metrics['psnr']:.2f} dB, "
                                                    f"SSIM {metrics['ssim']:.3f}"), out / "comparison.png")
            write_markdown(out / "report.md", [
                f"# Reconstruction of {scene.name}", "",
                f"From `{args.data}` ({rows_text(scene)} x {scene.sampling.count} bins), "
                f"M = {scene.pixels}, {report['regularizer']}; {how}"
                + (f" (σ = {sigma:g} from the scene's [noise])" if sigma is not None else "") + ". "
                f"PSNR {metrics['psnr']:.2f} dB, SSIM {metrics['ssim']:.3f} against the scene's "
                f"reflectance (data range 1).", "",
                *_result_table(result, metrics, sigma, args.regularizer, scene.noise), "",
                "![truth, reconstruction and error](comparison.png)", "",
                "![the λ rule's criterion and the L-curve](criterion.png)", "",
                *([] if tikhonov is None else [f"Error of this estimate (exact at λ): {error_text(tikhonov[2])}.", "",
                                               "![bias, standard deviation and Cramér-Rao bound](error.png)", ""]),
                *_warning_lines(notes)])
    # after the files: the inversion's own warnings again (rank deficiency, a λ rule that could not do what
    # it was asked), for the one-line policy; the report holds every warning
    for caught_warning in caught:
        if issubclass(caught_warning.category, (RankDeficiencyWarning, RegularizationWarning)):
            warnings.warn_explicit(caught_warning.message, caught_warning.category, caught_warning.filename,
                                   caught_warning.lineno)
    if exr_problem is not None:
        warnings.warn(f"{out / 'reconstruction.exr'}: not written, {exr_problem}; reconstruction.npy "
                      f"(float64) is the exact record", PrecisionWarning, stacklevel=1)
    if not args.quiet:
        built = "A's FFT operator made" if isinstance(matrix, OffsetOperator) else "A assembled"
        print(f"reconstruct: M = {scene.pixels}, {how} ({result.method}) in {result.seconds:.2f} s "
              f"({built} in {assembly:.2f} s); {information_text(result)}PSNR {metrics['psnr']:.2f} dB, "
              f"SSIM {metrics['ssim']:.3f} (range 1) -> {out}")
        if tikhonov is not None:
            print(f"reconstruct: error at λ: {error_text(tikhonov[2])}")
        elif "tikhonov_error_note" in report:
            print(f"reconstruct: error at λ: {report['tikhonov_error_note']}")
    return 0


def reconstruction_matrix(scene, regularizer: str, method: str | None, *, progress: bool = False):
    """A for reconstructing ``scene``: sparse, or where the lsqr method will run (asked for, or chosen because
    the svd method's dense copies exceed its limit) on a capture of pixel offsets, the matrix-free FFT operator
    (:func:`analytic.operator.offset_operator.capture_operator`: A's products to rounding, without A)."""
    from analytic.inversion.information import DEFAULT_MEMORY_LIMIT
    from analytic.operator.offset_operator import capture_operator
    from analytic.operator.system import system_matrix

    rows = scene.sensor_count * scene.sampling.count
    lsqr = method == "lsqr" or (method in (None, "auto") and 3 * rows * scene.pixels**2 * 8 > DEFAULT_MEMORY_LIMIT)
    operator = capture_operator(scene, progress=progress) if regularizer == "laplacian" and lsqr else None
    return system_matrix(scene, progress=progress) if operator is None else operator


def error_text(summary: dict) -> str:
    """The Tikhonov estimate's bias and spread beside the Cramér-Rao bound, in one clause."""
    text = (f"bias rms {summary['bias_rms']:.3g}, standard deviation median {summary['stddev_median']:.3g} per "
            f"pixel (expected rms error {summary['rmse_expected']:.3g})")
    if "crb_median" in summary:
        unbounded = summary["crb_unbounded_pixels"]
        if summary["crb_median"] == float("inf"):
            return text + (f"; Cramér-Rao bound: no unbiased estimate of any pixel exists (the data leave every "
                           f"pixel a component they cannot fix: the prior sets it)")
        text += (f"; Cramér-Rao bound on unbiased estimates: median {summary['crb_median']:.3g}"
                 + (f", {unbounded} pixels unbounded (the data cannot fix them without the prior)" if unbounded else ""))
    return text


def information_text(result) -> str:
    """:func:`analytic.inversion.information.information_summary` as a clause ending in "; " (or "").

    ``result`` is a :class:`analytic.inversion.Reconstruction`, or a dict with its ``rank``,
    ``effective_rank``, ``sigma`` and ``unknowns``.
    """
    from analytic.inversion.information import information_summary

    fields = result if isinstance(result, dict) else vars(result)
    text = information_summary(**{name: fields[name] for name in ("rank", "effective_rank", "sigma", "unknowns")})
    return f"{text}; " if text else ""


def _noise_why(noise) -> str:
    """Why no effective rank was counted, in a few words."""
    if noise is None:
        return "the scene states no noise"
    if noise.kind != "gaussian":
        return f"the scene's noise is {noise.kind}, not one Gaussian σ"
    return "A is too large for a dense SVD"


def _result_table(result, metrics: dict, sigma: float | None, regularizer: str, noise=None) -> list[str]:
    """The reconstruction's numbers as a table, with what each means in words below it."""
    rank = "-" if result.rank is None else f"{result.rank} of {result.unknowns}"
    effective = (f"{result.effective_rank} of {result.unknowns} (σ = {result.sigma:g})"
                 if result.effective_rank is not None else f"- ({_noise_why(noise)})")
    freedom = "-" if result.degrees_of_freedom is None else f"{result.degrees_of_freedom:.1f}"
    penalty = (("‖D f‖", "the image's roughness, the penalty's size (D the 5-point Laplacian)")
               if regularizer == "laplacian" else
               ("TV(f)", "the image's total variation, the penalty's size"))
    rule = {"value": "given (--lambda VALUE)", "oracle": "oracle (needs the true image: a bound)",
            "gcv": "generalised cross-validation", "lcurve": "L-curve corner",
            "discrepancy": f"discrepancy (‖A f − y‖² = m σ², σ = {sigma:g})" if sigma is not None
            else "discrepancy"}.get(result.rule, result.rule)
    rows = [
        ("λ", f"{result.lam:.4g}", "the weight of the penalty on roughness the image was found with: larger "
                                   "gives a smoother image that fits the data less closely"),
        ("rule", rule, "how λ was chosen from the data"),
        ("PSNR (dB)", f"{metrics['psnr']:.2f}", "peak signal-to-noise ratio against the scene's reflectance over a "
                                               "data range of 1: higher is closer"),
        ("SSIM", f"{metrics['ssim']:.3f}", "structural similarity against the scene's reflectance (1 is equal)"),
        ("‖A f − y‖", f"{result.residual_norm:.4g}", "the residual: how far the image's modelled transient is "
                                                     "from the data (units of y)"),
        (penalty[0], f"{result.seminorm:.4g}", penalty[1]),
        ("rank of A", rank, "how many independent numbers of the image noiseless data would fix: A's numerical "
                            "rank (svd method, or any when σ is known)"),
        ("fixed at the noise", effective, "how many numbers of the image these data fix at their noise σ: the "
                                          "singular values of A/σ above 1 (an image component along one of "
                                          "the others reaches the data below the noise); the penalty fills "
                                          "the rest"),
        ("degrees of freedom", freedom, "trace of the fit's influence matrix: how many numbers the chosen λ "
                                        "lets the data set (svd method)"),
        ("m", f"{result.measurements}", "measurements: sensors (or pairs) x bins, the rows of A"),
    ]
    if result.stopping is not None:
        rows.append(("solver", result.stopping, "when the iterative solves stopped (docs/model.md, Reconstruction)"))
    return (["| quantity | value |", "|---|---|"] + [f"| {name} | {value} |" for name, value, _ in rows]
            + [""] + [f"- **{name}**: {meaning}." for name, _, meaning in rows])


def _warning_lines(notes: list[str]) -> list[str]:
    """The warnings section of the report: each changes what a number above means."""
    if not notes:
        return []
    return (["## Warnings", "", "Each changes what a number above means (also shown on stderr):", ""]
            + [f"- warning: {note}" for note in notes])


def _read_data(path: str, scene) -> np.ndarray:
    """The transient, read and checked as ``check`` reads it: shape, finite values, and the time axis
    (and source) that the file states, against the scene's."""
    from validation.check import read_data
    return read_data(path, scene)


def command_reproduce(args) -> int:
    """The paper's Figs. 7 and 8 and Section VII's device figures; exit status 0."""
    from analytic.files import output_folder
    from validation.runs.paper import reproduce

    release_warnings()
    with output_folder(args.out) as out:
        summary = reproduce(out, quick=args.quick, progress=show_progress(args))
    if not args.quiet:
        print(f"reproduce: {summary['cases']} reconstructions in {summary['seconds']:.1f} s -> "
              f"{out} (report.md)")
    return 0


def add_commands(subparsers) -> None:
    """Add ``reconstruct`` and ``reproduce``."""
    command = subparsers.add_parser(
        "reconstruct", help="recover the image from a transient (Laplacian-regularised LS)")
    command.add_argument("scene", nargs="?", help="scene TOML, a plane or a relay-wall capture (its hidden image "
                                                  "is recovered) (default: the built-in scene)")
    command.add_argument("--data", required=True,
                         help="transient .npy, .exr or tal .h5, (K, N) (a relay-wall capture's: (P, N), .npy or "
                              ".exr), e.g. from `forward` or `render`")
    command.add_argument("--out", required=True, help="output folder")
    add_lambda_options(command, default="auto")
    command.add_argument("--method", choices=("auto", "svd", "lsqr"),
                         help="solver for the Laplacian (default auto: dense DCT/SVD when it fits 2 GiB)")
    command.add_argument("--regularizer", choices=("laplacian", "tv"), default="laplacian",
                         help="laplacian (the paper's, default) or tv (total variation; "
                              "--lambda oracle, discrepancy or a number)")
    add_quiet(command)
    command.set_defaults(run=command_reconstruct)

    command = subparsers.add_parser(
        "reproduce", help="the paper's Figs. 7-8 (impulsive vs low-pass) and device figures")
    command.add_argument("--out", required=True, help="output folder")
    command.add_argument("--quick", action="store_true",
                         help="fewer cases, M = 16 (a smoke run, not the paper's set-up)")
    add_quiet(command)
    command.set_defaults(run=command_reproduce)
