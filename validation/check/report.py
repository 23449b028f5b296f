"""``check``'s report: report.md (embedding its figures), metrics.json and the PNG figures, written together."""

from __future__ import annotations

from pathlib import Path

from analytic.files import json_ready, save_json, staged_writes
from validation.plots import WallScan, check_transients_figure, check_z_figure, save_figure
from validation.runs.report import write_markdown


from .scan_figure import scan_z_figure
from validation.judging.agreement import detectable_text

from .result import CheckResult, expected_sentence

__all__ = ["write_check_report"]


def write_check_report(out: str | Path, result: CheckResult, *, scene_name: str = "",
                       data_paths=(), scene=None) -> dict:
    """Write report.md (embedding its figures), metrics.json and the PNGs into ``out``, together.

    Parameters
    ----------
    out : str or Path
        Output folder (created).
    result : CheckResult
        What :func:`check_transient` returned.
    scene_name : str
        The scene's label, for the report.
    data_paths : sequence of str
        The files judged, listed in the report.
    scene : Scene or RelayWallScene, optional
        The scene judged against: a scene with a scan grid (a relay-wall capture) adds ``check_scan_z.png``
        (z over pairs x bins and on the scan grid, :func:`.scan_figure.scan_z_figure`).

    Returns
    -------
    dict
        The metrics written to metrics.json (NaN and infinity as None).
    """
    out = Path(out)
    metrics = json_ready(result.as_dict() | {"scene": scene_name, "data": [str(p) for p in data_paths]})
    lines = [f"# check: {scene_name or 'scene'}", ""]
    if data_paths:
        lines += ["Data: " + ", ".join(f"`{p}`" for p in data_paths), ""]
    lines += [f"**{'Agrees' if result.agrees else 'Disagrees'} as given.** {result.diagnosis}", ""]
    if result.expected is not None:
        lines += [f"**{expected_sentence(result)}.**", ""]
    if result.judged_by == "shape":
        lines += _shape_lines(result)
    else:
        lines += _statistical_lines(result)
    lines += _fit_lines(result)
    lines += _power_lines(result)
    with staged_writes():
        save_json(out / "metrics.json", metrics)
        if result.fit is not None:    # the figures draw the fitted model beside the data
            save_figure(check_transients_figure(result), out / "check_transients.png")
            lines += ["![data against the model](check_transients.png)", ""]
            if result.as_given is not None:
                save_figure(check_z_figure(result), out / "check_z.png")
                lines += ["![z by bin, as given and after the fit](check_z.png)", ""]
                if scene is not None and WallScan.for_scene(scene) is not None:     # a scan grid to draw z on
                    save_figure(scan_z_figure(result, scene), out / "check_scan_z.png")
                    lines += ["![z over pairs x bins and on the scan grid](check_scan_z.png)", ""]
        write_markdown(out / "report.md", lines)
    return metrics


def _shape_lines(result: CheckResult) -> list[str]:
    rows = [("as given", result.relative_l2)]
    if result.expected is not None:
        rows.append(("as stated", result.relative_l2_as_expected))
    if result.fit is not None:
        rows.append(("after the fit", result.relative_l2_after_fit))
    return (["Judged by shape only: no standard error was given, so there is no statistical test; "
             f"the verdict is relative L2 ≤ {result.shape_tolerance:g}.", "",
             "| | relative L2 |", "|---|---|"] + [f"| {name} | {value:.3e} |" for name, value in rows])


def _statistical_lines(result: CheckResult) -> list[str]:
    source = (f"{result.replicas} independent replicas (z ~ Student's t, {result.dof} dof)"
              if result.judged_by == "replicas" else "the standard error given with the data"
              + ("" if result.dof is None else f" (z ~ Student's t, {result.dof} dof)"))
    given = result.as_given
    rows = [("as given", given, result.relative_l2)]
    if result.as_expected is not None:
        rows.append(("as stated", result.as_expected, result.relative_l2_as_expected))
    if result.after_fit is not None:
        rows.append(("after the fit", result.after_fit, result.relative_l2_after_fit))
    return ([f"Per-bin error from {source}, over {given.bins} judged bin(s) ({given.skipped} with too few "
             f"samples not judged). False-alarm rate {given.false_alarm:g}: {given.null_note}."
             + (f" The {result.model_tolerance_note}." if result.model_tolerance_note else ""), "",
             "| | verdict | χ²/dof [accepted] | max \\|z\\| (limit) | relative L2 |", "|---|---|---|---|---|"]
            + [f"| {name} | {'agrees' if agreement.agrees else 'disagrees'} | {agreement.chi2_per_dof:.4g} "
               f"[{agreement.chi2_interval[0]:.3f}, {agreement.chi2_interval[1]:.3f}] | {agreement.max_abs_z:.3g} "
               f"(≤ {agreement.z_threshold:.2f}) | {relative:.3e} |" for name, agreement, relative in rows])


def _power_lines(result: CheckResult) -> list[str]:
    """The directed tests of the verdict that matters and what these data can detect."""
    judgement = result.judgement
    if judgement is None:
        return []
    lines = [f"**Power.** {detectable_text(result.detectable)} at the false-alarm rate "
             f"{judgement.false_alarm:g}, by the verdict {'as stated' if result.expected is not None else 'as given'} "
             f"(its directed tests of the scale and offset). The standard errors fall as 1/sqrt(samples): to "
             f"detect an error k times smaller, render k² times as many samples.", ""]
    if judgement.directed is not None:
        lines[0:0] = [f"{judgement.directed.text()} (each test at α = {judgement.directed.false_alarm_each:g}; "
                      f"χ² and max |z| share the rest).", ""]
    return lines


def _fit_lines(result: CheckResult) -> list[str]:
    fit = result.fit
    if fit is None:
        return ["", "No figures: they draw the fitted model beside the data, and there is none.", ""]
    return ["", "| fitted | value | standard error |", "|---|---|---|",
            f"| scale (data / model) | {fit.scale:.6g} | {fit.scale_stderr:.2g} |",
            f"| offset_opl (m, add to the data's start_opl) | {fit.offset_opl:+.6g} | {fit.offset_stderr:.2g} |",
            "", f"Gauss–Newton: {fit.iterations} iteration(s), "
            f"{'converged' if fit.converged else 'NOT converged'}.", ""]
