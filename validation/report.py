"""report.md, metrics.json and the figures of a validation run (``validate`` and ``run``)."""

from __future__ import annotations

from pathlib import Path

from analytic.io import save_json, save_text
from analytic.window import FULL_SHARE
from validation.plots import (plot_convergence, plot_reconstructions, plot_transients, plot_z_map)

__all__ = ["write_report", "write_markdown"]


def write_markdown(path: str | Path, lines: list[str]) -> Path:
    """Write a report (markdown lines), atomically."""
    return save_text(path, "\n".join(lines).rstrip("\n") + "\n")


def _reconstruction_cell(check) -> str:
    recon = check.metrics.get("reconstruction", {})
    if "model" not in recon:
        return "-"
    return (f"{recon['model']['psnr']:.1f} / {recon['render']['psnr']:.1f} ({recon['rule']}); "
            f"oracle {recon['oracle']['psnr']:.1f}, flat {recon['flat_psnr']:.1f}")


def _row(check) -> str:
    a = check.agreement
    costs = check.metrics.get("simplifications", {})
    model_noise = (f"{check.model_convergence[-1]['over_stderr']:.1e}"
                   if check.model_convergence else "-")
    slope = f"{check.metrics['render_slope']:.2f}" if "render_slope" in check.metrics else "-"
    share = check.metrics.get("window_share")
    window = "-" if share is None else f"{100 * share:.2f} %" + (" **cut**" if share < FULL_SHARE else "")
    coarea = f"{costs['no_coarea_factor']:.3f}" if "no_coarea_factor" in costs else "-"
    return (f"| {check.name} | **{'agree' if a.agrees else 'DISAGREE'}** | {check.spp:.3g} | "
            f"{a.chi2_per_dof:.3f} [{a.chi2_interval[0]:.2f}, {a.chi2_interval[1]:.2f}] | "
            f"{a.max_abs_z:.2f} (≤ {a.z_threshold:.2f}) | {a.bins} | {a.relative_l2:.2e} | {window} | "
            f"{model_noise} | {slope} | {costs.get('paper_attenuation', float('nan')):.2f} / "
            f"{costs.get('paper_attenuation_shape', float('nan')):.3f} | {coarea} | "
            f"{_reconstruction_cell(check)} |")


def write_report(out: Path, checks: list, corner: dict | None = None, *, false_alarm: float = 1e-3,
                 headline: bool = False) -> dict:
    """Write report.md, metrics.json and the figures for a list of SceneCheck (and the corner result).

    With ``headline`` (one scene: the ``run`` command) metrics.json also holds
    that scene's ``agreement``, ``window_share`` and ``reconstruction`` at its
    top level (DESIGN.md section 5).

    Returns
    -------
    dict
        What metrics.json holds: per scene its metrics, the corner's, and
        ``all_agree``.
    """
    out = Path(out)
    lines = ["# Cross-check: Monte Carlo render against the exact model", "",
             f"Per bin z = (y_render − y_model) / se_render over bins with se < 0.1 y_render. "
             f"A scene agrees when χ²/dof lies in the central interval that pure noise leaves with "
             f"probability 1 − α/2 and max |z| is below the Šidák limit at α/2; together the "
             f"false-alarm rate is α = {false_alarm:g} per scene. Relative L2 is reported beside the "
             f"verdict. 'window' is the share of the light the scene's bins hold (cut below "
             f"{100 * FULL_SHARE:g} %). 'model err / se' is the model's own quadrature error at its "
             f"default tolerance (against tolerance 1e-7) over each judged bin's standard error, worst "
             f"bin: far below 1 means the model is exact at this noise level. Paper attenuation: relative "
             f"difference of eq. (1) from physical transport (raw / after rescaling to the same norm). No "
             f"coarea: relative shape difference of eq. (3)'s contour integral from the correct one. "
             f"Reconstruction: PSNR (dB, range 1) of images recovered from the model's / the render's "
             f"transient, each with the scene's noise added (the same draw), λ by the named rule; the "
             f"oracle λ (a bound) and the best flat image (the floor) beside them.",
             "",
             "| scene | verdict | samples | χ²/dof [accept] | max abs z (limit) | bins | rel. L2 | window | "
             "model err / se | slope | paper atten. | no coarea | reconstruction PSNR model / render (rule) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [_row(check) for check in checks]
    metrics = {"false_alarm": false_alarm, "scenes": {}}
    for check in checks:
        folder = out / check.name
        sampling = check.scene.sampling
        plot_transients(folder / "transients.png", sampling, {"model": check.model, "render": check.render},
                        errors={"render": check.stderr},
                        title=f"{check.name}: model (steps) and render (points, ±1 se; z below)")
        plot_z_map(folder / "z_map.png", check.agreement.z, check.agreement.z_threshold, sampling,
                   f"{check.name}: z over sensors x bins")
        lines += ["", f"## {check.name}", "", check.agreement.summary(), "",
                  f"![transients]({check.name}/transients.png)", "", f"![z map]({check.name}/z_map.png)"]
        if check.render_convergence:
            plot_convergence(folder / "convergence.png", check.name, check.render_convergence,
                             check.metrics.get("render_slope"), check.model_convergence)
            lines += ["", f"![convergence]({check.name}/convergence.png)"]
        recon = check.reconstructions
        if "model" in recon:
            panels = [(f"from the model's data\n({recon['rule']})", recon["model"]["image"],
                       f"PSNR {recon['model']['psnr']:.1f} dB"),
                      (f"from the render's data\n({recon['rule']})", recon["render"]["image"],
                       f"PSNR {recon['render']['psnr']:.1f} dB"),
                      ("oracle λ (a bound)", recon["oracle"]["image"], f"PSNR {recon['oracle']['psnr']:.1f} dB")]
            plot_reconstructions(folder / "reconstructions.png",
                                 f"{check.name}: reconstructions (the best flat image scores {recon['flat_psnr']:.1f} dB)",
                                 check.scene.reflectance,
                                 panels)
            lines += ["", recon["data"], "", f"![reconstructions]({check.name}/reconstructions.png)"]
        metrics["scenes"][check.name] = check.metrics
    if corner is not None:
        lines += ["", "## corner (outside the one-bounce model)", "", corner["text"], "",
                  "![corner](corner/transients.png)"]
        metrics["corner"] = {key: value for key, value in corner.items() if key not in ("text", "arrays")}
        arrays = corner["arrays"]
        plot_transients(out / "corner" / "transients.png", arrays["sampling"],
                        {"one-bounce model": arrays["model"], "render, 1 bounce": arrays["one"],
                         "render, 3 bounces": arrays["many"]},
                        errors={"render, 1 bounce": arrays["one_se"], "render, 3 bounces": arrays["many_se"]},
                        title="corner: one-bounce model against renders")
    metrics["all_agree"] = all(check.agreement.agrees for check in checks) and (
        corner is None or (corner["one_bounce_agrees"] and corner["mitransient"].get("agrees") is not False))
    if headline:
        (check,) = checks
        metrics.update({key: check.metrics[key] for key in ("agreement", "window_share", "reconstruction")
                        if key in check.metrics})
    write_markdown(out / "report.md", lines)
    save_json(out / "metrics.json", metrics)
    return metrics
