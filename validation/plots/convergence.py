"""Figures of error against cost: a render's error against its samples, ours and mitransient's against time."""

from __future__ import annotations

import numpy as np

from .axes import finish_log_axes, log_plot
from .common import new_figure, plain_text, suptitle

__all__ = ["convergence_figure", "speed_against_error_figure"]


def convergence_figure(name: str, render_rows: list, slope: float | None, model_rows: list):
    """Render error against samples (with N^-1/2) and the model's error against tolerance.

    An error of exactly 0 cannot be drawn on the log axes and is left out
    (:func:`log_plot`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    figure = new_figure(8.5, 3.4, dpi=100)
    left, right = figure.subplots(1, 2)
    samples = np.array([r["samples"] for r in render_rows], float)
    errors = np.array([r["relative_l2"] for r in render_rows], float)
    label = "render" + ("" if slope is None else f" (slope {slope:.3f})")
    if log_plot(left, samples, errors, "o-", label=label):
        anchor = int(np.argmax(np.isfinite(errors) & (errors > 0)))
        log_plot(left, samples, errors[anchor] * (samples / samples[anchor]) ** -0.5, ":", color="grey",
                  label="N^-1/2")
        left.legend(fontsize=7)
    left.set_xlabel("samples N")
    left.set_ylabel("relative L2 error against the model")
    finish_log_axes(left)
    if model_rows:
        tolerance = [r["tolerance"] for r in model_rows]
        over = [max(r["over_stderr"], 1e-18) for r in model_rows]
        log_plot(right, tolerance, over, "s-", label="model error / se (worst judged bin)")
        right.axhline(1.0, color="red", lw=0.8, label="the render's noise")
        right.set_xlabel("model tolerance (requested)")
        right.set_ylabel("max |y(tol) − y(1e-7)| / se")
        finish_log_axes(right)
        right.invert_xaxis()
        right.legend(fontsize=7)
    else:
        right.set_axis_off()
    suptitle(figure, f"{name}: convergence", fontsize=9)
    return figure


def speed_against_error_figure(report: dict):
    """RMS error against wall time, ours and mitransient's, one panel per bench scene.

    Parameters
    ----------
    report : dict
        :func:`validation.runs.bench.speed_against_error`'s report: ``scenes`` ->
        {``ours``, ``mitransient``: rows with ``seconds`` and ``rms_error``},
        and ``device``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    scenes = report["scenes"]
    figure = new_figure(5.0 * len(scenes), 3.9)
    axes = np.atleast_1d(figure.subplots(1, len(scenes), squeeze=False)[0])
    for axis, (name, entry) in zip(axes, scenes.items()):
        for label, rows in (("ours", entry["ours"]), ("mitransient", entry.get("mitransient", []))):
            if rows:
                log_plot(axis, [r["seconds"] for r in rows], [r["rms_error"] for r in rows], "o-", label=label)
        axis.set_xlabel("wall time (s)")
        axis.set_ylabel("RMS relative L2 error against the model")
        axis.set_title(plain_text(name), fontsize=9, parse_math=False)
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize=8)
        finish_log_axes(axis)
    suptitle(figure, f"speed against error ({report['device']})", fontsize=9)
    return figure
