"""Photon counts on the command line (docs/design.md section 8): written beside y, and judged by ``check --counts``.

A scene with a ``[detector]`` table makes ``forward``, ``render`` and
``run`` write ``counts_expected.npy`` (float64, the expected histogram
:func:`analytic.measurement.detector.expected_counts` of the folder's y) and
``counts.npy`` (int64, one draw of it, :func:`analytic.measurement.detector.draw_counts`
with the detector's seed) beside ``transient.npy``, the draw again as
``counts.h5`` in tal's capture layout (the layout of the folder's
``transient.h5``, read by ``tal.io.read_capture``), and the figure
``counts.png``; meta.json's ``detector`` records the table. A folder
written for a scene without one has none of the three (an earlier
command's are removed). A render's counts are those of its estimate of y,
drawn (by ``render`` and by ``run``) from a stream of their own, the seed
and 1, so that a model's and a render's draws are independent.

``check SCENE --data FILE --counts`` judges a histogram against the
scene's expected one by the deviance (:func:`validation.check.counts.judge_counts`:
Poisson without dead time, multinomial with it, at a stated false-alarm
rate) and, with ``--fit``, fits scale, offset and the pulse's width
(:func:`validation.check.counts.fit_counts`).
"""

from __future__ import annotations

from pathlib import Path

from analytic.waveforms.builders import WAVEFORMS, own_keys

from .common import UsageError, refuse_unmodellable

__all__ = ["COUNTS_FILES", "COUNTS_CAPTURE", "COUNTS_FIGURE", "draw_scene_counts", "refuse_unreachable_counts", "RENDER_STREAM", "write_counts",
           "write_render_counts",
           "discard_counts", "add_counts_options",
           "check_counts_options", "command_check_counts", "counts_figure"]

#: The expected histogram and its draw, beside transient.npy (docs/design.md section 8).
COUNTS_FILES = ("counts_expected.npy", "counts.npy")
#: The draw in tal's capture layout (as transient.h5: a plane's, or a relay-wall capture's NLOS layout).
COUNTS_CAPTURE = "counts.h5"
#: The figure of both, beside them.
COUNTS_FIGURE = "counts.png"
#: The stream a render's counts are drawn from (``render`` and ``run``): independent of ``forward``'s, the seed's own.
RENDER_STREAM = 1
# --fit's names (offset is offset_opl, as check's fit names it).
_FIT_ALIASES = {"scale": "scale", "offset": "offset_opl", "offset_opl": "offset_opl", "fwhm": "fwhm", "tail": "tail"}


def draw_scene_counts(scene, y, *, stream: int = 0) -> tuple[np.ndarray, np.ndarray] | None:
    """(expected, drawn) counts of y through the scene's detector, or None when it has no ``[detector]``.

    Called before any file is written: an expected count a Poisson draw cannot take is refused
    (:class:`analytic.errors.SceneError` naming ``detector.photons``) while the folder is still untouched.
    ``stream`` 0 draws with the detector's seed (``numpy.random.default_rng(seed)``); another draws
    from ``default_rng([seed, stream])``, independent of it (a render's, :data:`RENDER_STREAM`).
    """
    import numpy as np

    from analytic.measurement.detector import draw_counts, expected_counts

    if scene.detector is None:
        return None
    seed = scene.detector.seed
    rng = np.random.default_rng(seed if stream == 0 else [seed, stream])
    return expected_counts(y, scene.detector), draw_counts(y, scene.detector, rng=rng)


def refuse_unreachable_counts(scene, *, margin: float = 2.0) -> None:
    """Before a render (``margin`` 2) or a model (1): refuse a ``[detector]`` whose expected counts would pass what a Poisson draw takes.

    A render's y is known only at its end, after its files; its counts are drawn then. A cheap
    bound comes first: :func:`analytic.operator.window.impulse_totals` x (1 for the impulse, else the period
    T: a pulse of unit peak) bounds every bin of y. Only when that bound, with ``margin`` for the
    estimate's noise, would pass :data:`analytic.measurement.detector.MAX_MEAN` is the exact model's y
    computed, and the scene refused (``detector.photons``) when its largest bin, with the margin,
    does. The dead-time detector draws multinomially from at most ``cycles``: no limit.
    """
    import numpy as np

    from analytic.measurement.detector import MAX_MEAN, excess_key
    from analytic.errors import SceneError
    from analytic.operator.matrix_free import forward
    from analytic.values import exact
    from analytic.operator.window import impulse_totals

    detector = scene.detector
    if detector is None or detector.dead_time != "none":
        return

    def largest(y_bound: float) -> float:
        return detector.cycles * (detector.photons * y_bound * margin + detector.background)

    pulse = 1.0 if scene.illumination.waveform == "impulse" else scene.sampling.bin_width_opl
    if largest(float(np.max(impulse_totals(scene), initial=0.0)) * pulse) <= MAX_MEAN:
        return
    expected = largest(float(np.max(forward(scene), initial=0.0)))
    if not expected <= MAX_MEAN:
        noise = f" (x {margin:g} for a render's noise)" if margin != 1.0 else ""
        key = excess_key(detector, MAX_MEAN)
        raise SceneError(key, f"the largest expected count, {exact(expected / margin)}{noise}, is beyond the "
                              f"{MAX_MEAN:g} a Poisson draw supports; lower {key.split('.')[1]} or cycles")


def write_counts(out: str | Path, scene, counts: tuple[np.ndarray, np.ndarray] | None, *, label: str = "model"
                 ) -> None:
    """Write ``counts_expected.npy``, ``counts.npy``, ``counts.h5`` and ``counts.png`` into ``out`` (inside the caller's
    :func:`analytic.files.staged_writes`), or remove an earlier command's when ``counts`` is None.

    Parameters
    ----------
    out : str or Path
        The folder of the transient.
    scene : Scene or RelayWallScene
    counts : (expected, drawn) or None
        From :func:`draw_scene_counts`.
    label : str
        Whose y the counts are of ("model", "render"), for the figure.
    """
    import numpy as np

    from analytic.files import save_npy
    from validation.plots import save_figure

    out = Path(out)
    if counts is None:
        discard_counts(out)
        return
    expected, drawn = counts
    save_npy(out / COUNTS_FILES[0], np.asarray(expected, dtype=np.float64))
    save_npy(out / COUNTS_FILES[1], np.asarray(drawn, dtype=np.int64))
    _write_counts_capture(out / COUNTS_CAPTURE, scene, drawn)
    save_figure(counts_figure(scene, expected, drawn, title=f"{scene.name}: counts of the {label}'s y",
                              expected_label=f"expected (of the {label}'s y)"), out / COUNTS_FIGURE)


def _write_counts_capture(path: Path, scene, drawn) -> None:
    """The drawn counts as a tal capture (H = counts, float64), laid out as the folder's transient.h5."""
    import numpy as np

    from interop.tal import write_scene_capture

    sampling = scene.sampling
    info = {"quantity": "photon counts (a draw; counts.npy)", "scene": scene.name,
            "detector": scene.detector.as_dict(), "start_opl": sampling.start_opl,
            "bin_width_opl": sampling.bin_width_opl}
    write_scene_capture(path, np.asarray(drawn, dtype=np.float64), scene, scene_info=info)


def discard_counts(out: str | Path) -> None:
    """Remove an earlier command's counts from ``out`` (a new render starts: they are not of its y)."""
    from analytic.files import discard

    for name in (*COUNTS_FILES, COUNTS_CAPTURE, COUNTS_FIGURE):
        discard(Path(out) / name)


def write_render_counts(out: str | Path, scene, mean) -> None:
    """A finished render's counts (of its estimate ``mean`` of y) beside its transient, together; none
    (and an earlier command's removed) for a scene without ``[detector]``."""
    from analytic.files import staged_writes

    counts = draw_scene_counts(scene, mean, stream=RENDER_STREAM)
    with staged_writes():
        write_counts(out, scene, counts, label="render")


def counts_figure(scene, expected, drawn, *, fitted=None, title: str = "", expected_label: str = "expected (model)"):
    """Drawn (or measured) counts against the expected histogram, for the row with the most expected counts.

    Parameters
    ----------
    scene : Scene or RelayWallScene
        Its bins and detector.
    expected, drawn : numpy.ndarray
        ``(K, N)`` expected and drawn counts.
    fitted : numpy.ndarray, optional
        ``(K, N)`` the fitted model's expected counts.
    title : str
    expected_label : str
        The legend's name of ``expected``.
    """
    import numpy as np

    from validation.plots.common import new_figure, plain_text

    expected = np.asarray(expected, dtype=np.float64)
    row = int(np.argmax(expected.sum(axis=1)))
    edges = scene.sampling.edges
    detector = scene.detector
    figure = new_figure(7, 3.6)
    axes = figure.subplots()
    axes.stairs(np.asarray(drawn)[row], edges, color="0.6", fill=True, label="counts")
    axes.stairs(expected[row], edges, color="C3", linewidth=1.5, label=expected_label)
    if fitted is not None:
        axes.stairs(np.asarray(fitted)[row], edges, color="C0", linewidth=1.2, linestyle="--",
                    label="expected (fitted)")
    lit = np.flatnonzero(expected[row] > expected[row].max() * 1e-3)
    if lit.size:
        pad = max(2, (lit[-1] - lit[0]) // 10)
        axes.set_xlim(edges[max(lit[0] - pad, 0)], edges[min(lit[-1] + 1 + pad, len(edges) - 1)])
    axes.set_xlabel("path length (m)")
    axes.set_ylabel("counts per bin")
    rows = scene.row_noun
    axes.set_title(plain_text(f"{title} ({rows} {row}; {detector.cycles:g} cycles, dead time "
                              f"{detector.dead_time})"), fontsize=9)
    axes.legend(frameon=False, fontsize=8)
    return figure


def add_counts_options(check) -> None:
    """``check``'s ``--counts``, ``--fit`` and ``--false-alarm``."""
    check.add_argument("--counts", action="store_true",
                       help="--data is a histogram of photon counts (counts.npy, (K, N) whole numbers, or the "
                            "folder holding it), judged against the expected counts of the scene's [detector] "
                            "by the Poisson (dead_time none) or multinomial (dead_time cycle) deviance at "
                            "--false-alarm; exit 0 when it agrees")
    check.add_argument("--fit", metavar="NAMES",
                       help="--counts: fit these, comma-separated, from scale, offset (offset_opl), fwhm and "
                            "tail (fwhm for a gaussian or emg pulse, tail for an emg), and judge again")
    check.add_argument("--false-alarm", type=_rate, default=None, metavar="ALPHA",
                       help="--counts: the probability that counts drawn from the model fail, in (0, 0.5] "
                            "(default 0.01)")


#: Smallest --false-alarm: the null distribution is drawn, about 20 / alpha histograms.
MIN_FALSE_ALARM = 1e-4


def _rate(text: str) -> float:
    import argparse

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--false-alarm: expected a number, got {text!r}") from None
    if not MIN_FALSE_ALARM <= value <= 0.5:
        # the judge draws ~20 / alpha reference histograms: 1e-4 is 2e5 of them, smaller would not fit in memory
        raise argparse.ArgumentTypeError(f"--false-alarm: must be in [{MIN_FALSE_ALARM:g}, 0.5], got {text}")
    return value


def check_counts_options(args, scene) -> tuple[str, ...]:
    """Refuse what --counts cannot take, before any work; the names to fit (empty: no fit).

    Raises
    ------
    UsageError
        --fit or --false-alarm without --counts, --counts with options of a transient's check, a scene
        without ``[detector]``, an unknown or repeated name in --fit, a width for a pulse without one.
    """
    if not args.counts:
        if args.fit is not None or args.false_alarm is not None:
            raise UsageError("--fit/--false-alarm: apply to --counts only (a histogram of photon counts); a "
                             "transient's check always fits scale and offset")
        return ()
    given = [option for option, value in (("--stderr", args.stderr), ("--shape-only", args.shape_only),
                                          ("--expect", args.expect), ("--expect-scale", args.expect_scale),
                                          ("--expect-offset", args.expect_offset), ("--radius", args.radius))
             if value not in (None, False)]
    if given:
        raise UsageError(f"{given[0]}: does not apply to --counts (counts carry their own Poisson error, and "
                         f"the detector's model is the scene's [detector] table)")
    if len(args.data) != 1:
        raise UsageError("--counts: give one --data file (a (K, N) histogram of counts)")
    if scene.detector is None:
        raise UsageError(f"--counts: the scene {scene.name!r} has no [detector] table to model counts by; add "
                         f"one (photons, background, cycles, dead_time; docs/detector.md)")
    if args.fit is None:
        return ()
    names = [name.strip() for name in args.fit.split(",")]
    unknown = [name for name in names if name not in _FIT_ALIASES]
    if unknown or not names:
        raise UsageError(f"--fit: {', '.join(unknown) or 'nothing'} is not one of scale, offset, fwhm, tail")
    fitted = tuple(_FIT_ALIASES[name] for name in names)
    if len(set(fitted)) != len(fitted):
        raise UsageError(f"--fit: each name once, got {args.fit}")
    waveform = scene.illumination.waveform
    for key in ("fwhm", "tail"):
        if key in fitted and key not in own_keys(waveform):
            takers = " or ".join(name for name in WAVEFORMS if key in own_keys(name))
            raise UsageError(f"--fit {key}: the scene's pulse ({waveform!r}) has no {key}; it is fitted for a "
                             f"{takers} illumination")
    return fitted


def _read_counts(path: str, scene) -> np.ndarray:
    """The (K, N) histogram in ``path`` (a .npy, or a folder holding counts.npy), checked before any work."""
    import numpy as np

    from analytic.errors import DataError
    from analytic.files import read_npy, reading_folder

    with reading_folder(path, option="--data"):
        file = Path(path) / COUNTS_FILES[1] if Path(path).is_dir() else Path(path)
        if Path(path).is_dir() and not file.is_file():
            raise DataError(f"{path}: a folder without {COUNTS_FILES[1]}; give the counts file itself")
        if file.suffix.lower() != ".npy":
            raise DataError(f"{file}: --counts reads a .npy histogram of counts ((K, N) whole numbers)")
        counts = read_npy(file)
    shape = (scene.sensor_count, scene.sampling.count)
    if counts.shape != shape:
        raise DataError(f"{file}: counts of shape {counts.shape}, the scene's rows x bins are {shape}")
    values = counts.astype(np.float64)
    if not np.all(np.isfinite(values)) or np.any(values < 0) or np.any(values != np.round(values)):
        raise DataError(f"{file}: every count must be a finite whole number >= 0")
    detector = scene.detector
    if detector.dead_time == "cycle" and np.any(values.sum(axis=1) > detector.cycles):
        raise DataError(f"{file}: a row holds more counts than the {detector.cycles:.0f} cycles a first-photon "
                        f"detector records (the scene's dead_time = 'cycle'); is it a dead-time-free histogram?")
    return values


def command_check_counts(args, scene) -> int:
    """``check --counts``: judge a histogram of counts (and fit it with --fit); exit 0 when it agrees as given.

    Writes report.md, metrics.json (``agrees``, ``counts``: the verdict's figures, ``fit``: the fitted
    parameters, their standard errors and ``agrees_after_fit``) and ``check_counts.png``, together.
    """
    import numpy as np

    from analytic.measurement.detector import expected_counts
    from analytic.files import json_ready, output_folder, save_json, staged_writes
    from analytic.operator.matrix_free import forward
    from validation.check.counts import DEFAULT_FALSE_ALARM, SceneModel, fit_counts, judge_counts
    from validation.plots import save_figure
    from validation.runs.report import write_markdown

    from .common import announce_window

    names = check_counts_options(args, scene)
    refuse_unmodellable(scene, matrix=False)       # y = A f only: no A needed
    counts = _read_counts(args.data[0], scene)
    detector = scene.detector
    alpha = DEFAULT_FALSE_ALARM if args.false_alarm is None else args.false_alarm
    draws = max(2000, int(np.ceil(20 / alpha)))
    model = SceneModel(scene)
    expected = expected_counts(model(), detector)
    verdict = judge_counts(counts, expected, detector, false_alarm=alpha, draws=draws)
    fit = fit_counts(counts, model, detector, fit=names, false_alarm=alpha, draws=draws) if names else None
    fitted = None
    if fit is not None:
        p = fit.parameters
        fitted = expected_counts(p.get("scale", 1.0) * model(p.get("offset_opl", 0.0), p.get("fwhm"), p.get("tail")),
                                 detector)
    metrics = {"scene": scene.name, "data": [str(args.data[0])], "judged_by": "counts",
               "agrees": verdict.agrees, "detector": detector.as_dict(), "counts": verdict.as_dict(),
               "total_counts": float(counts.sum()), "expected_total": float(expected.sum()),
               "fit": None if fit is None else {"parameters": fit.parameters, "stderr": fit.stderr,
                                                "deviance": fit.statistic, "evaluations": fit.evaluations,
                                                **{"after_fit": fit.verdict.as_dict()}},
               "agrees_after_fit": None if fit is None else fit.verdict.agrees}
    lines = _report_lines(scene, args.data[0], verdict, fit, counts, expected)
    with output_folder(args.out) as out:
        announce_window(args, scene)
        with staged_writes():
            save_json(out / "metrics.json", json_ready(metrics))
            save_figure(counts_figure(scene, expected, counts, fitted=fitted,
                                      title=f"check: {scene.name}"), out / "check_counts.png")
            write_markdown(out / "report.md", lines + ["![counts against the model](check_counts.png)", ""])
    if not args.quiet:
        print(_summary(verdict, fit))
        print(f"-> {Path(args.out) / 'report.md'}")
    return 0 if verdict.agrees else 1


def _verdict_text(verdict) -> str:
    return (f"{'AGREES' if verdict.agrees else 'DISAGREES'}: {verdict.statistic} deviance {verdict.deviance:.2f} "
            f"{'<=' if verdict.agrees else '>'} {verdict.threshold:.2f} (the {1 - verdict.false_alarm:g} quantile of "
            f"{verdict.draws} histograms drawn from the model; false-alarm rate {verdict.false_alarm:g}), "
            f"p = {verdict.p_value:.3g}, {verdict.bins} bins")


def _fit_text(fit) -> str:
    values = ", ".join(f"{name} {value:.6g} ± {fit.stderr.get(name, float('nan')):.2g}"
                       for name, value in fit.parameters.items())
    return f"fit: {values}; after the fit {_verdict_text(fit.verdict)}"


def _summary(verdict, fit) -> str:
    return _verdict_text(verdict) + ("" if fit is None else "\n" + _fit_text(fit))


def _report_lines(scene, path, verdict, fit, counts, expected) -> list[str]:
    detector = scene.detector
    lines = [f"# check of counts: {scene.name}", "", f"Data: `{path}`: {counts.sum():.0f} counts "
             f"(the model expects {expected.sum():.6g}) over {detector.cycles:g} cycles, dead time "
             f"`{detector.dead_time}`, background {detector.background:g} photons per bin per cycle.", "",
             f"**{_verdict_text(verdict)}.**", ""]
    if fit is not None:
        lines += ["| fitted | value | standard error |", "|---|---|---|"]
        lines += [f"| {name} | {value:.6g} | {fit.stderr.get(name, float('nan')):.2g} |"
                  for name, value in fit.parameters.items()]
        lines += ["", f"After the fit ({fit.evaluations} exact models): {_verdict_text(fit.verdict)}.", ""]
    return lines
