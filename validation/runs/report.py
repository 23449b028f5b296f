"""report.md, metrics.json and the figures of a validation run (``validate`` and ``run``).

Layout of the output folder
---------------------------
One scene (``run``, ``write_report(..., headline=True)``): everything at the
top of the folder::

    report.md  metrics.json  transients.png  z_map.png  [wall.png]  [convergence.png]  [reconstructions.png]

Several scenes (``validate``): the report at the top, each scene's figures
in a folder of its own, and the corner's in ``corner/``::

    report.md  metrics.json  <folder>/transients.png  <folder>/z_map.png  ...  corner/transients.png

``wall.png`` is drawn for a capture through a relay wall (docs/design.md
section 7): the model's transient per pair as an image, its light over the
scan, and the render's traces beside the model's.

A scene's folder is its name made safe by :func:`scene_folder_names`;
metrics.json's ``scenes`` is keyed by that folder and keeps the scene's own
name in each entry's ``name``. Nothing is ever written outside the output
folder, whatever the scenes are called.
"""

from __future__ import annotations

import re
from pathlib import Path

from analytic.files import save_json, save_text
from analytic.operator.window import FULL_SHARE
from validation.plots import (WallScan, convergence_figure, reconstructions_figure, relay_wall_figure, save_figure,
                              transients_figure, z_map_figure)
from validation.plots.worker import FigureWorker

__all__ = ["write_report", "write_markdown", "scene_folder_names", "FIGURE_FILES", "RESERVED_NAMES",
           "MAX_FOLDER_NAME"]

#: The figures drawn for one scene, in its folder (or, for ``run``, at the top).
FIGURE_FILES = ("transients.png", "z_map.png", "wall.png", "convergence.png", "reconstructions.png")
#: Names the report itself uses at the top of its folder: a scene folder never takes one.
RESERVED_NAMES = frozenset({"report.md", "metrics.json", "model", "render", "corner", *FIGURE_FILES})
#: Longest scene folder name, in characters (all ASCII, so also bytes), before a "-2" suffix.
MAX_FOLDER_NAME = 64

_UNSAFE = re.compile(r"[^A-Za-z0-9._-]")


def _safe_name(name: str) -> str:
    """One name made safe, before uniqueness (see :func:`scene_folder_names`)."""
    text = _UNSAFE.sub("_", name)[:MAX_FOLDER_NAME]
    # a leading dot hides the folder (and ".", ".." are not folders of their own); a trailing one
    # is dropped by some file systems, which would merge two names
    text = re.sub(r"^\.+", lambda dots: "_" * len(dots.group()), text)
    text = re.sub(r"\.+$", lambda dots: "_" * len(dots.group()), text)
    return text or "scene"


def scene_folder_names(names) -> list[str]:
    """The folder of each scene's files: its name made safe, unique and never one the report uses.

    The rule, applied to each name in order:

    1. every character outside ``A-Z a-z 0-9 . _ -`` becomes ``_`` (so no
       ``/``, no space, nothing outside ASCII);
    2. only the first 64 characters are kept;
    3. leading and trailing dots become ``_`` (no hidden folder, no ``..``);
       an empty name becomes ``scene``;
    4. a name already taken, by an earlier scene or by the report itself
       (:data:`RESERVED_NAMES`: ``report.md``, ``metrics.json``, ``model``,
       ``render``, ``corner`` and the figure files), compared without regard
       to case, gets the first free suffix ``-2``, ``-3``, ...

    Parameters
    ----------
    names : iterable of str
        The scenes' names, in report order.

    Returns
    -------
    list of str
        One folder name per scene, in the same order; all different, even
        on a file system that ignores case.

    Examples
    --------
    >>> scene_folder_names(["low", "../x", "metrics.json", "low", "a b"])
    ['low', '.._x', 'metrics.json-2', 'low-2', 'a_b']
    """
    taken = {name.lower() for name in RESERVED_NAMES}
    folders = []
    for name in names:
        base = _safe_name(name)
        folder, suffix = base, 1
        while folder.lower() in taken:
            suffix += 1
            folder = f"{base}-{suffix}"
        taken.add(folder.lower())
        folders.append(folder)
    return folders


def write_markdown(path: str | Path, lines: list[str]) -> Path:
    """Write a report (markdown lines), atomically."""
    return save_text(path, "\n".join(lines).rstrip("\n") + "\n")


def _markdown_text(text: str) -> str:
    """A scene's name as literal markdown text: its table pipes, links and emphasis escaped."""
    return re.sub(r"([\\|*`\[\]<>])", r"\\\1", text)


_AGREEMENT_COLUMNS = [
    ("scene", "the scene's name"),
    ("verdict", "agree, or DISAGREE: every test must pass (χ², max |z|, and the directed tests of the scale "
                "and time offset)"),
    ("samples", "Monte Carlo samples of the render"),
    ("χ²/dof [accept]", "the mean of z² over the judged bins (pure noise gives about 1) and the interval "
                        "that pure noise leaves with probability 1 − α/4"),
    ("max abs z (limit)", "the largest |z| of any judged bin, and the limit that pure noise stays "
                          "under with probability 1 − α/4"),
    ("scale t, offset t", "the render's scale and time offset against the model's, in standard errors "
                          "(the directed tests; each accepted within ± the limit of its share α/4)"),
    ("detectable", "the smallest relative scale error and time offset (m) these data flag half the time at "
                   "α: the render's power (falls as 1/sqrt(samples))"),
    ("bins", "bins judged (about 100 samples or more)"),
    ("rel. L2", "‖y_render − y_model‖ / ‖y_model‖: reported beside the verdict, never instead of it"),
    ("window", f"the share of the scene's light its time bins hold (**cut** below {100 * FULL_SHARE:g} %)"),
    ("model err / se", "the model's own quadrature error at its default tolerance (against tolerance "
                       "1e-7) over the standard error, worst judged bin: far below 1 means the model is "
                       "exact at this noise level"),
    ("slope", "the render error's slope against samples on log axes (−0.5 for Monte Carlo noise)"),
]

_COST_COLUMNS = [
    ("scene", "the scene's name"),
    ("eq. (1): error / shape error", "how far the paper's attenuation (eq. 1: no cos θ_k, no 1/π) is from "
                                     "physical transport: ‖y_eq1 − y‖ / ‖y‖ as is, and again after scaling "
                                     "y_eq1 to y's norm (what a constant factor cannot explain)"),
    ("eq. (3): shape error", "how far eq. (3)'s contour integral without the coarea factor 1/|∇d| is from "
                             "the correct impulse response g_k(t), both scaled to one norm"),
    ("PSNR model / render", "PSNR (dB, data range 1) of the images reconstructed from the model's and from "
                            "the render's transient, each with the scene's noise added (the same draw)"),
    ("rule: λ model / render", "the rule that chose the regularisation weight λ from the data alone, and "
                               "the λ it chose for each"),
    ("oracle PSNR (λ)", "the best PSNR any λ gives on the model's noisy data (a bound: it needs the true "
                        "image), and that λ"),
    ("flat PSNR", "the best flat image's PSNR (the floor: what knowing only the mean gives)"),
]


def _table(columns: list[tuple[str, str]], rows: list[str]) -> list[str]:
    return ["| " + " | ".join(title for title, _ in columns) + " |",
            "|" + "---|" * len(columns), *rows]


def _legend(columns: list[tuple[str, str]]) -> list[str]:
    return [f"- **{title}**: {meaning}." for title, meaning in columns]


def _agreement_row(check) -> str:
    a = check.agreement
    model_noise = (f"{check.model_convergence[-1]['over_stderr']:.1e}"
                   if check.model_convergence else "-")
    slope = f"{check.metrics['render_slope']:.2f}" if "render_slope" in check.metrics else "-"
    share = check.metrics.get("window_share")
    window = "-" if share is None else f"{100 * share:.2f} %" + (" **cut**" if share < FULL_SHARE else "")
    directed, detectable = a.directed, a.detectable
    tests = "-" if directed is None else (f"{directed.scale_t:+.2f}, " + (
        "-" if directed.shift_t is None else f"{directed.shift_t:+.2f}") + f" (±{directed.limit:.2f})")
    power = "-" if detectable is None else (f"{100 * detectable['scale']:.2g} %, " + (
        "-" if detectable["shift_opl"] is None else f"{detectable['shift_opl']:.2g} m"))
    return (f"| {_markdown_text(check.name)} | **{'agree' if a.agrees else 'DISAGREE'}** | {check.spp:.3g} | "
            f"{a.chi2_per_dof:.3f} [{a.chi2_interval[0]:.2f}, {a.chi2_interval[1]:.2f}] | "
            f"{a.max_abs_z:.2f} (≤ {a.z_threshold:.2f}) | {tests} | {power} | {a.bins} | {a.relative_l2:.2e} | "
            f"{window} | {model_noise} | {slope} |")


def _cost_row(check) -> str:
    costs = check.metrics.get("simplifications", {})
    attenuation = (f"{costs['paper_attenuation']:.2f} / {costs['paper_attenuation_shape']:.3f}"
                   if "paper_attenuation" in costs else "-")
    coarea = f"{costs['no_coarea_factor']:.3f}" if "no_coarea_factor" in costs else "-"
    recon = check.metrics.get("reconstruction", {})
    if "model" in recon:
        cells = (f"{recon['model']['psnr']:.1f} / {recon['render']['psnr']:.1f} | "
                 f"{recon['rule']}: {recon['model']['lambda']:.3g} / {recon['render']['lambda']:.3g} | "
                 f"{recon['oracle']['psnr']:.1f} ({recon['oracle']['lambda']:.3g}) | {recon['flat_psnr']:.1f}")
    else:
        cells = "- | - | - | -"
    return f"| {_markdown_text(check.name)} | {attenuation} | {coarea} | {cells} |"


def _draw_scene(check, folder: Path, link: str, heading: str, drawer: FigureWorker) -> list[str]:
    """One scene's figures in ``folder`` (linked as ``link`` + file name) and its report section.

    The first two figures (about half of the drawing) go to ``drawer``, the others are drawn here meanwhile.
    """
    sampling = check.scene.sampling
    agreement = check.agreement
    row_kind = check.scene.row_noun      # what the transient's rows are
    drawer.draw(transients_figure, sampling, {"model": check.model, "render": check.render},
                errors={"render": check.stderr}, z_limit=agreement.z_threshold,
                title=f"{check.name}: the model (steps) against the render (points)", row_kind=row_kind)
    drawer.draw(z_map_figure, agreement.z, agreement.z_threshold, sampling,
                f"{check.name}: z over {row_kind}s x bins", row_kind=row_kind)
    lines = ["", heading, "", check.summary(), "",
             f"Transients of up to 8 {row_kind}s (named in the figure) with z below each; the z map shows "
             f"every {row_kind}.", "",
             f"![transients]({link}transients.png)", "", f"![z map]({link}z_map.png)"]
    scan = WallScan.for_scene(check.scene)
    if scan is not None:
        save_figure(relay_wall_figure(sampling, check.model, scan,
                                      title=f"{check.name}: {scan.type} scan through a relay wall, the model"),
                    folder / "wall.png")
        lines += ["", f"The model's transient of every (laser point, read point) pair as an image (time "
                      f"across, pairs down: p = j W + i over the {scan.grid[0]} x {scan.grid[1]} read grid"
                      + (", laser-major" if scan.type == "exhaustive" else "") + "), its light summed over "
                      "time over the scan, and the traces of the numbered pairs.", "",
                  f"![every pair's transient]({link}wall.png)"]
    if check.render_convergence:
        save_figure(convergence_figure(check.name, check.render_convergence, check.metrics.get("render_slope"),
                                       check.model_convergence), folder / "convergence.png")
        lines += ["", f"![convergence]({link}convergence.png)"]
    recon = check.reconstructions
    skipped = check.metrics.get("reconstruction", {}).get("skipped")
    if skipped:
        lines += ["", f"No reconstruction: {skipped}."]
    if "model" in recon:
        panels = [(f"from the model's data\n({recon['rule']})", recon["model"]["image"],
                   f"PSNR {recon['model']['psnr']:.1f} dB, λ = {recon['model']['lambda']:.3g}"),
                  (f"from the render's data\n({recon['rule']})", recon["render"]["image"],
                   f"PSNR {recon['render']['psnr']:.1f} dB, λ = {recon['render']['lambda']:.3g}"),
                  ("oracle λ (a bound)", recon["oracle"]["image"],
                   f"PSNR {recon['oracle']['psnr']:.1f} dB, λ = {recon['oracle']['lambda']:.3g}")]
        save_figure(reconstructions_figure(
            f"{check.name}: reconstructions (the best flat image scores {recon['flat_psnr']:.1f} dB)",
            check.scene.reflectance, panels), folder / "reconstructions.png")
        notes = [f"- warning, from the {data}'s data: {entry['message']}" for data in ("model", "render")
                 for entry in recon[data].get("warnings", ())]
        lines += ["", recon["data"] + f" λ chosen: {recon['model']['lambda']:.3g} (model's data), "
                                      f"{recon['render']['lambda']:.3g} (render's data); the oracle's "
                                      f"{recon['oracle']['lambda']:.3g}.",
                  *([""] + notes if notes else []),
                  "", f"![reconstructions]({link}reconstructions.png)"]
    drawer.save(folder / "transients.png")
    drawer.save(folder / "z_map.png")
    return lines


def write_report(out: Path, checks: list, corner: dict | None = None, *, false_alarm: float = 1e-3,
                 headline: bool = False, drawer: FigureWorker | None = None) -> dict:
    """Write report.md, metrics.json and the figures for a list of SceneCheck (and the corner result).

    Parameters
    ----------
    out : Path
        The output folder; the layout is the module docstring's.
    checks : list of SceneCheck
        The scenes, in report order.
    corner : dict, optional
        :func:`validation.runs.corner.check_corner`'s result.
    false_alarm : float
        α, the false-alarm rate per scene the verdicts used.
    headline : bool
        One scene (the ``run`` command): its figures at the top of ``out``
        beside report.md, and metrics.json also holds that scene's
        ``agreement``, ``window_share`` and ``reconstruction`` at its top
        level (docs/design.md section 5). Without it each scene's figures are in
        its folder (:func:`scene_folder_names`).
    drawer : FigureWorker, optional
        Draws part of each scene's figures in a second process while the
        rest are drawn here (default: all here).

    Returns
    -------
    dict
        What metrics.json holds: per scene (keyed by its folder name) its
        metrics and ``name``, the corner's, and ``all_agree``.
    """
    out = Path(out)
    if headline and len(checks) != 1:
        raise ValueError(f"headline: one scene, got {len(checks)}")
    lines = ["# Cross-check: Monte Carlo render against the exact model", "",
             f"Per bin z = (y_render − y_model) / se_render over the bins that hold about 100 samples or more. "
             f"A scene agrees when χ²/dof lies in the central interval that pure noise leaves with probability "
             f"1 − α/4, max |z| is below the limit pure noise stays under with probability 1 − α/4, and the "
             f"render's scale and time offset, estimated along the model's derivatives, are each within the "
             f"limits of their share α/4 of the model's (the directed tests); together the false-alarm rate is "
             f"α = {false_alarm:g} per scene. 'detectable' is each render's power: the smallest scale error and "
             f"offset it flags half the time.", "", "## Agreement", ""]
    lines += _table(_AGREEMENT_COLUMNS, [_agreement_row(check) for check in checks])
    lines += ["", *_legend(_AGREEMENT_COLUMNS), "",
              "## What the paper's simplifications cost, and the reconstructions", ""]
    lines += _table(_COST_COLUMNS, [_cost_row(check) for check in checks])
    lines += ["", *_legend(_COST_COLUMNS)]
    metrics = {"false_alarm": false_alarm, "scenes": {}}
    folders = scene_folder_names(check.name for check in checks)
    drawer = FigureWorker(start=False) if drawer is None else drawer
    for check, folder in zip(checks, folders):
        heading = f"## {_markdown_text(check.name)}"
        if headline:
            lines += _draw_scene(check, out, "", heading, drawer)
        else:
            if folder != check.name:
                heading += f" (files in `{folder}/`)"
            lines += _draw_scene(check, out / folder, f"{folder}/", heading, drawer)
        metrics["scenes"][folder] = {"name": check.name, **check.metrics}
    if corner is not None:
        lines += ["", "## corner (outside the one-bounce model)", "", corner["text"], "",
                  "![corner](corner/transients.png)"]
        metrics["corner"] = {key: value for key, value in corner.items() if key not in ("text", "arrays")}
        arrays = corner["arrays"]
        save_figure(transients_figure(arrays["sampling"],
                                      {"one-bounce model": arrays["model"], "render, 1 bounce": arrays["one"],
                                       "render, 3 bounces": arrays["many"]},
                                      errors={"render, 1 bounce": arrays["one_se"],
                                              "render, 3 bounces": arrays["many_se"]},
                                      z_limit=corner["one_bounce"]["z_threshold"],
                                      title="corner: one-bounce model against renders"),
                    out / "corner" / "transients.png")
    metrics["all_agree"] = all(check.agreement.agrees for check in checks) and (
        corner is None or (corner["one_bounce_agrees"] and corner["mitransient"].get("agrees") is not False))
    if headline:
        (check,) = checks
        metrics.update({key: check.metrics[key] for key in ("agreement", "detectable", "window_share",
                                                             "reconstruction") if key in check.metrics})
    write_markdown(out / "report.md", lines)
    save_json(out / "metrics.json", metrics)
    return metrics
