"""``diffuse-imaging calibrate``: a scene's free parameters and a scale fitted to a capture (docs/calibration.md)."""

from __future__ import annotations

from pathlib import Path

from .common import (UsageError, add_quiet, load_scene_argument, parameter_option, refuse_unmodellable,
                     release_warnings)

__all__ = ["add_commands", "command_calibrate"]


def command_calibrate(args) -> int:
    """Fit ``--free`` and a scale to ``--data``; exit 0 when the fit converged and agrees with the data, else 1.

    The work is :func:`validation.calibration.calibrate` (this command's messages name its options); its
    files are :func:`validation.calibration.files.write_calibration`'s.
    """
    from analytic.files import output_folder
    from validation.calibration.verdict import calibrate_inputs
    from validation.calibration.files import write_calibration
    from validation.check.inputs import COMMAND_WORDS

    scene = load_scene_argument(args.scene)
    if args.stderr is not None and len(args.data) > 1:
        raise UsageError("--stderr: give it with one --data file; several files are replicas whose spread is "
                         "their error")
    refuse_unmodellable(scene)
    parameter_option(scene, args.free, "--free")       # a bad key names the option, before any reading
    data = args.data[0] if len(args.data) == 1 else list(args.data)
    if args.counts and (args.stderr is not None or len(args.data) > 1):
        raise UsageError("--counts: give one --data histogram, without --stderr (counts carry their own error)")
    result = calibrate_inputs(scene, data, args.free, stderr=args.stderr, counts=args.counts,
                              fixed_scale=args.fixed_scale,
                              false_alarm=args.false_alarm, words=COMMAND_WORDS, checked=release_warnings)
    with output_folder(args.out) as out:
        write_calibration(out, result, scene_name=scene.name, data_paths=args.data)
    if not args.quiet:
        print(result.summary())
        print(f"-> {Path(args.out) / 'report.md'}")
    return 0 if result.verdict else 1


def _false_alarm(text: str) -> float:
    import argparse

    from analytic.errors import OptionError
    from validation.judging.arrays import false_alarm_rate

    try:
        return false_alarm_rate(float(text))
    except (ValueError, OptionError) as error:
        message = str(error) if isinstance(error, OptionError) else f"expected a number, got {text!r}"
        raise argparse.ArgumentTypeError(f"--false-alarm: {message.removeprefix('false_alarm: ')}") from None


def add_commands(commands) -> None:
    """Add ``calibrate``."""
    calibrate = commands.add_parser(
        "calibrate", help="fit scene parameters (positions, time zero, pulse width) to a capture",
        description="Fit the --free parameters of SCENE (keys of docs/design.md section 9: "
                    "source.position.x, sensors.positions.3.z, sampling.start, illumination.fwhm, ...) and an "
                    "overall scale to --data by Levenberg-Marquardt on the exact Jacobian, weighted by the "
                    "data's standard errors; with sampling.start free, the time axis the data state is its "
                    "starting value. Writes calibration.json, scene.toml (the fitted scene), report.md and "
                    "a residual figure. Exit 0 when the fit converged and the data agree with the fitted "
                    "model (docs/design.md section 6), 1 when not, 2 on bad input.")
    calibrate.add_argument("scene", help="scene TOML: the starting values and everything held fixed")
    calibrate.add_argument("--data", nargs="+", required=True, metavar="FILE",
                           help="what check reads: our transient.npy/.exr/.h5 or its folder (its replicas or "
                                "standard error come with it), a (K, N) .npy with --stderr, tal's HDF5; "
                                "several files are independent replicas")
    calibrate.add_argument("--stderr", metavar="FILE", help="per-bin standard error of a single --data file")
    calibrate.add_argument("--counts", action="store_true",
                           help="--data is a histogram of photon counts (counts.npy or its folder) of the scene's "
                                "[detector] without dead time: fitted by its Poisson likelihood, judged by "
                                "check --counts' deviance test")
    calibrate.add_argument("--free", nargs="+", required=True, metavar="KEY",
                           help="the parameters to fit, scene-file keys (docs/design.md section 9)")
    calibrate.add_argument("--fixed-scale", action="store_true",
                           help="hold the overall scale at 1 (data in the model's units)")
    calibrate.add_argument("--false-alarm", type=_false_alarm, default=1e-3, metavar="ALPHA",
                           help="the verdict's false-alarm rate (default 0.001)")
    calibrate.add_argument("--out", required=True, help="output folder")
    add_quiet(calibrate)
    calibrate.set_defaults(run=command_calibrate)
