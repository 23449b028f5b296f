"""The ``reconstruct`` and ``reproduce`` subcommands of ``diffuse-imaging``.

Wired into :mod:`validation.cli` with::

    from validation.cli_reconstruct import add_commands
    add_commands(commands)      # commands = parser.add_subparsers(...)

Each command returns an exit status. User mistakes raise
:class:`analytic.scene.SceneError` (naming the key or option),
:class:`analytic.reflectance.ImageError` or :class:`FileNotFoundError`,
which the main CLI turns into one line and exit status 2. Heavy modules
are imported inside the commands so that ``--help`` answers at once.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

__all__ = ["add_commands", "command_reconstruct", "command_reproduce", "plot_criterion",
           "parse_lambda"]

_CRITERION_LABELS = {
    "oracle": "||f_λ − f||² (squared image error)",
    "gcv": "GCV(λ) = ||r||² / trace(I − H)²",
    "lcurve": "L-curve curvature",
    "discrepancy": "||r||² − m σ²",
}


def parse_lambda(text: str):
    """``--lambda`` value: a rule name or a positive number (λ itself)."""
    from analytic.reconstruct import RULES
    from analytic.scene import SceneError

    if text in RULES:
        return text
    try:
        value = float(text)
    except ValueError:
        raise SceneError("--lambda", f"expected one of {', '.join(RULES)} or a number > 0, "
                                     f"got {text!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise SceneError("--lambda", f"a numeric λ must be finite and > 0, got {text!r}")
    return value


def _load_scene(path: str | None):
    from analytic.scene import default_scene, load_scene

    return default_scene() if path is None else load_scene(path)


def _read_data(path: str, scene) -> np.ndarray:
    from analytic.io import read_transient
    from analytic.reflectance import ImageError

    try:
        data = read_transient(path)
    except (ValueError, OSError) as error:
        if isinstance(error, FileNotFoundError):
            raise
        raise ImageError(f"--data: {error}") from None
    expected = (scene.sensor_count, scene.sampling.count)
    if data.shape != expected:
        raise ImageError(f"--data: shape {data.shape} does not match the scene's "
                         f"{expected[0]} sensors x {expected[1]} bins")
    if not np.all(np.isfinite(data)):
        raise ImageError("--data: contains NaN or infinity")
    return data


def plot_criterion(path, reconstruction, *, title: str = "") -> Path:
    """Plot the λ rule's criterion against λ with the chosen λ marked.

    Parameters
    ----------
    path : str or Path
        PNG to write (atomically).
    reconstruction : analytic.reconstruct.Reconstruction
        Its ``lambdas``, ``criterion``, ``residual_norms``, ``seminorms`` and ``lam``.
    title : str
        Figure title.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from analytic.io import save_figure

    r = reconstruction
    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8))
    finite = np.isfinite(r.criterion)
    if np.any(finite):
        values = r.criterion
        if r.rule in ("oracle", "gcv"):
            left.loglog(r.lambdas, values, ".-")
        elif r.rule == "discrepancy":
            left.semilogx(r.lambdas, values, ".-")
            left.axhline(0.0, color="0.5", lw=0.8)
        else:
            left.semilogx(r.lambdas, values, ".-")
        left.set_ylabel(_CRITERION_LABELS.get(r.rule, "criterion"), fontsize=8)
    else:
        left.text(0.5, 0.5, f"λ given: {r.lam:.3g}", ha="center", transform=left.transAxes)
    left.axvline(r.lam, color="C3", ls="--", label=f"chosen λ = {r.lam:.3g}")
    left.set_xlabel("λ (weight of ||D f||², unit pixel spacing)", fontsize=8)
    left.legend(fontsize=8)
    left.set_title(f"rule: {r.rule}", fontsize=9)
    right.loglog(r.residual_norms, np.maximum(r.seminorms, np.finfo(float).tiny), ".-", ms=3)
    right.loglog([r.residual_norm], [max(r.seminorm, np.finfo(float).tiny)], "o", color="C3",
                 label="chosen")
    right.set_xlabel("||A f − y||", fontsize=8)
    right.set_ylabel("||D f||", fontsize=8)
    right.set_title("L-curve", fontsize=9)
    right.legend(fontsize=8)
    if title:
        figure.suptitle(title, fontsize=10)
    figure.tight_layout()

    return save_figure(figure, path, dpi=110)


def command_reconstruct(args) -> int:
    """Reconstruct the scene's image from a transient; write images, metrics, criterion plot."""
    from analytic.io import save_exr, save_json, save_npy, save_png_image
    from analytic.reconstruct import image_metrics, reconstruct
    from analytic.scene import SceneError
    from analytic.system import system_matrix

    scene = _load_scene(args.scene)
    rule = parse_lambda(args.rule)
    if args.regularizer == "tv" and rule in ("gcv", "lcurve"):
        raise SceneError("--lambda", f"{rule} is not defined for --regularizer tv "
                                     f"(use oracle, discrepancy or a number)")
    data = _read_data(args.data, scene)
    sigma = None
    if rule == "discrepancy":
        if scene.noise is None or scene.noise.kind != "gaussian":
            raise SceneError("noise.sigma", "--lambda discrepancy needs the scene's Gaussian "
                                            "noise level ([noise] kind = \"gaussian\", sigma = ...)")
        sigma = scene.noise.sigma
        if sigma <= 0:
            raise SceneError("noise.sigma", "--lambda discrepancy needs sigma > 0")
    assembly_started = time.perf_counter()
    matrix = system_matrix(scene, progress=not args.quiet)
    assembly = time.perf_counter() - assembly_started
    truth = np.asarray(scene.reflectance, dtype=np.float64)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = reconstruct(matrix, data, scene.pixels, rule=rule, truth=truth, sigma=sigma,
                             method=args.method, regularizer=args.regularizer)
    notes = [str(w.message) for w in caught]
    metrics = image_metrics(result.image, truth, data_range=1.0)
    out = Path(args.out)
    save_npy(out / "reconstruction.npy", result.image)
    save_exr(out / "reconstruction.exr", result.image,
             {"lambda": result.lam, "rule": result.rule, "method": result.method,
              "units": "reflectance (unclipped)"})
    save_png_image(out / "reconstruction.png", result.image)
    report = {
        "scene": scene.name,
        "data": str(args.data),
        "pixels": scene.pixels,
        "lambda": result.lam,
        "rule": result.rule,
        "method": result.method,
        "mse": metrics["mse"],
        "psnr_db": metrics["psnr"],
        "ssim": metrics["ssim"],
        "data_range": metrics["data_range"],
        "metrics_note": "against the scene's reflectance; PSNR and SSIM over a data range of 1.0 "
                        "(reflectance in [0, 1]); the estimate is not clipped (the PNG is)",
        "residual_norm": result.residual_norm,
        "seminorm": result.seminorm,
        "rank": result.rank,
        "unknowns": result.unknowns,
        "measurements": result.measurements,
        "sigma": sigma,
        "seconds": result.seconds,
        "assembly_seconds": assembly,
        "regularizer": ("squared 5-point Laplacian, reflecting (Neumann) boundaries, unit spacing"
                        if args.regularizer == "laplacian" else
                        "isotropic total variation (½||Af − y||² + λ TV), Neumann edges, PDHG"),
        "warnings": notes,
        "lambdas": result.lambdas,
        "criterion": [None if not np.isfinite(v) else float(v) for v in result.criterion],
    }
    save_json(out / "metrics.json", report)
    plot_criterion(out / "criterion.png", result,
                   title=f"{scene.name}: λ = {result.lam:.3g} ({result.rule}), "
                         f"PSNR {metrics['psnr']:.2f} dB")
    if not args.quiet:
        for note in notes:
            print(f"warning: {note}")
        print(f"reconstruct: M = {scene.pixels}, λ = {result.lam:.4g} ({result.rule}, "
              f"{result.method}) in {result.seconds:.2f} s (A assembled in {assembly:.2f} s); "
              f"PSNR {metrics['psnr']:.2f} dB, SSIM {metrics['ssim']:.3f} (range 1) -> {out}")
    return 0


def command_reproduce(args) -> int:
    """The paper's Figs. 7 and 8 and Section VII's device figures."""
    from analytic.experiments import reproduce

    summary = reproduce(args.out, quick=args.quick, progress=not args.quiet)
    if not args.quiet:
        print(f"reproduce: {summary['cases']} reconstructions in {summary['seconds']:.1f} s -> "
              f"{args.out} (report.md)")
    return 0


def add_commands(subparsers) -> None:
    """Add ``reconstruct`` and ``reproduce`` to the CLI's subparsers."""
    command = subparsers.add_parser(
        "reconstruct", help="recover the image from a transient (Laplacian-regularised LS)")
    command.add_argument("scene", nargs="?", help="scene TOML (default: the built-in scene)")
    command.add_argument("--data", required=True,
                         help="transient .npy or .exr, (K, N), from `forward` or `render`")
    command.add_argument("--out", required=True, help="output folder")
    command.add_argument("--lambda", dest="rule", default="gcv", metavar="RULE|VALUE",
                         help="oracle | gcv | lcurve | discrepancy (σ from [noise] sigma) "
                              "| a number > 0 (default gcv)")
    command.add_argument("--method", choices=("auto", "svd", "lsqr"), default="auto",
                         help="solver (default auto: dense DCT/SVD when it fits 2 GiB)")
    command.add_argument("--regularizer", choices=("laplacian", "tv"), default="laplacian",
                         help="laplacian (the paper's, default) or tv (total variation; "
                              "--lambda oracle, discrepancy or a number)")
    command.add_argument("--quiet", action="store_true", help="no progress or summary")
    command.set_defaults(run=command_reconstruct)

    command = subparsers.add_parser(
        "reproduce", help="the paper's Figs. 7-8 (impulsive vs low-pass) and device figures")
    command.add_argument("--out", required=True, help="output folder")
    command.add_argument("--quick", action="store_true",
                         help="fewer cases, M = 16 (a smoke run, not the paper's set-up)")
    command.add_argument("--quiet", action="store_true", help="no progress or summary")
    command.set_defaults(run=command_reproduce)
