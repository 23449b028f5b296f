"""``calibrate``'s files: calibration.json, the fitted scene.toml, report.md and the before/after residual figure.

Everything is written together (:func:`analytic.files.staged_writes`): an
interrupted command leaves none of them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from analytic.files import json_ready, save_exr, save_json, save_text, staged_writes
from analytic.scenes.scene_file import scene_to_tables

from .verdict import UNDETERMINED, Calibration

__all__ = ["write_calibration", "scene_toml", "toml_value", "residual_figure", "FIGURE", "IMAGE"]

#: The before/after residual figure's file.
FIGURE = "calibration_residuals.png"
#: A non-uniform reflectance image of the fitted scene, beside scene.toml (float32 EXR, as the scene files read).
IMAGE = "reflectance.exr"


def toml_value(value) -> str:
    """A scene table's value as TOML text: floats by their shortest round-trip text, lists nested."""
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return repr(float(value))          # the shortest text that reads back to the same float64


def scene_toml(scene) -> tuple[str, np.ndarray | None]:
    """The scene as scene-file text (:func:`analytic.scenes.scene_file.scene_to_tables`), and the reflectance
    image to write beside it as :data:`IMAGE` (None when uniform: the number is in the text)."""
    tables = scene_to_tables(scene)
    lines = [f"name = {toml_value(tables.pop('name'))}"]
    image = None
    for table, entries in tables.items():
        lines += ["", f"[{table}]"]
        for key, value in entries.items():
            if key == "reflectance" and isinstance(value, np.ndarray):
                image, value = value, IMAGE
            lines.append(f"{key} = {toml_value(value)}")
    return "\n".join(lines) + "\n", image


def residual_figure(result: Calibration, title: str = ""):
    """Normalised residuals (d - model) / σ per row and bin, before (the starting scene, its best scale) and
    after the fit, on one scale."""
    from validation.plots import new_figure
    from validation.plots.common import plain_text

    before = np.where(result.stderr > 0, (result.data - result.start_model) / np.where(result.stderr > 0,
                                                                                      result.stderr, 1.0), np.nan)
    after = np.where(result.stderr > 0, (result.data - result.model) / np.where(result.stderr > 0,
                                                                               result.stderr, 1.0), np.nan)
    figure = new_figure(9.0, 3.6)
    axes = figure.subplots(1, 2, sharey=True)
    edges = result.scene.sampling.edges
    centres = 0.5 * (edges[:-1] + edges[1:])
    start_centres = centres - result.scene.sampling.start_opl + result.start_scene.sampling.start_opl
    for panel, residual, times, label in ((axes[0], before, start_centres, "before (start)"),
                                          (axes[1], after, centres, "after the fit")):
        for row in range(residual.shape[0]):
            panel.plot(times, residual[row], marker=".", linewidth=0.8, label=f"{row}" if row < 8 else None)
        chi2 = np.nansum(residual**2) / max(int(np.sum(np.isfinite(residual))), 1)
        panel.axhline(0.0, color="black", linewidth=0.6)
        for level in (-1.0, 1.0):
            panel.axhline(level, color="grey", linewidth=0.5, linestyle=":")
        panel.set_title(f"{label}: mean z² = {chi2:.3g}", fontsize=9)
        panel.set_xlabel("path length, bin centre (m)")
    axes[0].set_ylabel("(data - model) / σ")
    if residual.shape[0] <= 8:
        axes[1].legend(title=result.start_scene.row_noun, fontsize=7, title_fontsize=7, frameon=False)
    figure.suptitle(plain_text(title or "calibrate: residuals before and after the fit"), fontsize=10)
    return figure


def _report_lines(result: Calibration, scene_name: str, data_paths) -> list[str]:
    lines = [f"# calibrate: {scene_name or 'scene'}", ""]
    if data_paths:
        lines += ["Data: " + ", ".join(f"`{p}`" for p in data_paths), ""]
    verdict = "converged" if result.converged else "did **not** converge"
    lines += [f"**The fit {verdict}; the data {'agree' if result.agrees else 'DISAGREE'} with the fitted model** "
              f"(false-alarm rate {result.false_alarm:g}, docs/design.md section 6). χ²/dof "
              f"{result.start_chi2_dof:.4g} at the start, {result.chi2_dof:.4g} after "
              f"{result.iterations} iteration(s).", "",
              "| parameter | start | fitted | standard error | unit |", "|---|---|---|---|---|"]
    lines += [f"| {name if name == 'scale' else f'`{name}`'} | {start} | {value} | {error} | {unit} |"
              for name, start, value, error, unit in result.rows()]
    lines.append("")
    for entry in result.degenerate:
        lines += [f"Not determined by the data: the direction {entry['text']} (moving the parameters along it "
                  f"changes the model by less than {1e-4:g} of what they change alone; fix one of them, or "
                  f"bring data that tell them apart). scene.toml holds one point of that set.", ""]
    lines += [f"Verdict on the data against the fitted model: {result.agreement.summary()}", "",
              f"![residuals before and after]({FIGURE})", "",
              "Files: `calibration.json` (values, standard errors from the covariance, χ²/dof, convergence), "
              "`scene.toml` (the scene with the fitted values)."]
    return lines


def write_calibration(out: str | Path, result: Calibration, *, scene_name: str = "", data_paths=()) -> dict:
    """Write calibration.json, scene.toml (and its image), report.md and the figure into ``out``, together.

    Returns
    -------
    dict
        calibration.json's content (NaN and infinity as None).
    """
    out = Path(out)
    content = json_ready(result.as_dict())
    text, image = scene_toml(result.scene)
    figure = residual_figure(result, f"calibrate {scene_name}: (data - model) / σ before and after the fit")
    from validation.plots import save_figure
    from validation.runs.report import write_markdown

    with staged_writes():
        save_json(out / "calibration.json", content)
        save_text(out / "scene.toml", text)
        if image is not None:
            save_exr(out / IMAGE, image)
        save_figure(figure, out / FIGURE)
        write_markdown(out / "report.md", _report_lines(result, scene_name, data_paths))
    return content
