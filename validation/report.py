"""report.md, metrics.json and the PNG plots of a validation run (matplotlib imported lazily)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from analytic.io import atomic_write, save_json
from validation.plots import plot_transients, save_figure

__all__ = ["write_report"]


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_z_map(path: Path, z: np.ndarray, threshold: float, title: str):
    """z-scores over sensors x bins; grey where the bin was not judged."""
    plt = _pyplot()
    figure, axis = plt.subplots(figsize=(7, 0.4 * z.shape[0] + 1.6))
    limit = max(threshold, float(np.nanmax(np.abs(z))) if np.isfinite(z).any() else threshold)
    cmap = plt.get_cmap("RdBu_r").copy()
    cmap.set_bad("0.85")
    image = axis.imshow(np.ma.masked_invalid(z), aspect="auto", cmap=cmap, vmin=-limit, vmax=limit,
                        interpolation="nearest")
    figure.colorbar(image, ax=axis, label=f"z (limit ±{threshold:.2f})")
    axis.set_xlabel("bin n")
    axis.set_ylabel("sensor k")
    axis.set_title(title, fontsize=9)
    figure.tight_layout()
    save_figure(figure, path, dpi=100)


def plot_convergence(path: Path, check):
    plt = _pyplot()
    figure, (left, right) = plt.subplots(1, 2, figsize=(8, 3.2))
    rows = check.render_convergence
    samples = np.array([r["samples"] for r in rows], float)
    errors = np.array([r["relative_l2"] for r in rows])
    left.loglog(samples, errors, "o-", label=f"render (slope {check.metrics.get('render_slope', 0):.3f})")
    left.loglog(samples, errors[0] * (samples / samples[0]) ** -0.5, ":", color="grey", label="N^-1/2")
    left.set_xlabel("samples N")
    left.set_ylabel("relative L2 vs model")
    left.legend(fontsize=7)
    tolerance = [r["tolerance"] for r in check.model_convergence]
    over = [max(r["over_stderr"], 1e-18) for r in check.model_convergence]
    right.loglog(tolerance, over, "s-")
    right.axhline(1.0, color="red", lw=0.8, label="render noise (se of each bin)")
    right.set_xlabel("model tolerance")
    right.set_ylabel("max over bins |y - y(1e-7)| / se")
    right.invert_xaxis()
    right.legend(fontsize=7)
    figure.suptitle(f"{check.name}: convergence", fontsize=9)
    figure.tight_layout()
    save_figure(figure, path, dpi=100)


def plot_reconstructions(path: Path, check):
    plt = _pyplot()
    panels = [("true image", check.scene.reflectance, "")]
    for key in ("model", "render"):
        item = check.reconstructions[key]
        panels.append((f"from {key} data", item["image"], f"PSNR {item['psnr']:.1f} dB"))
    figure, axes = plt.subplots(1, 3, figsize=(8, 3))
    for axis, (title, image, note) in zip(axes, panels):
        axis.imshow(image, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        axis.set_title(f"{title}\n{note}", fontsize=8)
        axis.axis("off")
    figure.suptitle(f"{check.name}: λ = {check.reconstructions['lambda']:.3g} for both", fontsize=9)
    figure.tight_layout()
    save_figure(figure, path, dpi=100)


def _row(check) -> str:
    a = check.agreement
    costs = check.metrics.get("simplifications", {})
    recon = check.metrics.get("reconstruction", {})
    psnr = (f"{recon['model']['psnr']:.1f} / {recon['render']['psnr']:.1f}"
            if "model" in recon else "-")
    model_noise = (f"{check.model_convergence[-1]['over_stderr']:.1e}"
                   if check.model_convergence else "-")
    slope = f"{check.metrics['render_slope']:.2f}" if "render_slope" in check.metrics else "-"
    return (f"| {check.name} | **{'agree' if a.agrees else 'DISAGREE'}** | {check.spp:.3g} | "
            f"{a.chi2_per_dof:.3f} [{a.chi2_interval[0]:.2f}, {a.chi2_interval[1]:.2f}] | "
            f"{a.max_abs_z:.2f} (≤ {a.z_threshold:.2f}) | {a.bins} | {a.relative_l2:.2e} | {model_noise} | "
            f"{slope} | {costs.get('paper_attenuation', float('nan')):.2f} / "
            f"{costs.get('paper_attenuation_shape', float('nan')):.3f} | "
            f"{costs.get('no_coarea_factor', float('nan')):.3f} | {psnr} |")


def write_report(out: Path, checks: list, corner: dict | None = None, *, false_alarm: float = 1e-3) -> dict:
    """Write report.md, metrics.json and plots for a list of SceneCheck (and the corner result)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    lines = ["# Cross-check: Monte Carlo render against the exact model", "",
             f"Per bin z = (y_render − y_model) / se_render over bins with se < 0.1 y_render. "
             f"A scene agrees when χ²/dof lies in the central interval that pure noise leaves with "
             f"probability 1 − α/2 and max |z| is below the Šidák limit at α/2; together the "
             f"false-alarm rate is α = {false_alarm:g} per scene. Relative L2 is reported beside the "
             f"verdict. 'model err / se' is the model's own quadrature error at its default tolerance "
             f"(against tolerance 1e-7) over each judged bin's standard error, worst bin: far below 1 means the "
             f"model is exact at this noise level. Paper attenuation: relative difference of eq. (1) "
             f"from physical transport (raw / after rescaling to the same norm). No coarea: relative "
             f"shape difference of eq. (3)'s contour integral from the correct one. PSNR: "
             f"reconstruction from modelled / rendered data with the same λ (oracle on the model data).",
             "",
             "| scene | verdict | samples | χ²/dof [accept] | max abs z (limit) | bins | rel. L2 | "
             "model err / se | slope | paper atten. | no coarea | PSNR model / render (dB) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [_row(check) for check in checks]
    metrics = {"false_alarm": false_alarm, "scenes": {}}
    for check in checks:
        folder = out / check.name
        folder.mkdir(parents=True, exist_ok=True)
        plot_transients(folder / "transients.png", check.scene.sampling.edges,
                        {"model": check.model, "render": check.render}, errors={"render": check.stderr},
                        title=f"{check.name}: model (line) and render (points, ±1 se)")
        plot_z_map(folder / "z_map.png", check.agreement.z, check.agreement.z_threshold,
                   f"{check.name}: z over sensors x bins")
        lines += ["", f"## {check.name}", "", check.agreement.summary(), "",
                  f"![transients]({check.name}/transients.png)", f"![z map]({check.name}/z_map.png)"]
        if check.render_convergence:
            plot_convergence(folder / "convergence.png", check)
            lines.append(f"![convergence]({check.name}/convergence.png)")
        if "model" in check.reconstructions:
            plot_reconstructions(folder / "reconstructions.png", check)
            lines.append(f"![reconstructions]({check.name}/reconstructions.png)")
        metrics["scenes"][check.name] = check.metrics
    if corner is not None:
        lines += ["", "## corner (outside the one-bounce model)", "", corner["text"], "",
                  "![corner](corner/transients.png)"]
        metrics["corner"] = {key: value for key, value in corner.items() if key not in ("text", "arrays")}
        arrays = corner["arrays"]
        plot_transients(out / "corner" / "transients.png", arrays["edges"],
                        {"one-bounce model": arrays["model"], "render, 1 bounce": arrays["one"],
                         "render, 3 bounces": arrays["many"]},
                        errors={"render, 1 bounce": arrays["one_se"], "render, 3 bounces": arrays["many_se"]},
                        title="corner: one-bounce model against renders")
    metrics["all_agree"] = all(check.agreement.agrees for check in checks) and (
        corner is None or corner["one_bounce_agrees"])
    atomic_write(out / "report.md", lambda temporary: Path(temporary).write_text("\n".join(lines) + "\n"))
    save_json(out / "metrics.json", metrics)
    return metrics
