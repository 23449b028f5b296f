"""Exact ∂y/∂θ of a plane scene under any waveform but the impulse (docs/derivatives.md).

    ∂y_k[n]/∂θ = I ∫ f ∂a_k/∂θ κ_n(d) dx  +  I ∫ f a_k ∂d/∂θ κ_n'(d) dx,
    κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ),   κ_n'(τ) = s(t_n - τ) - s(t_{n+1} - τ),

integrated over each reflectance cell directly (:mod:`analytic.kernels.sensitivity_waveform`): the
integrand is analytic on a cell except along the isochrones d = t_e - b_i (a bin edge shifted back by a
kink b_i of the waveform), where the cell is cut. The time zero's column is -I ∫ f a κ_n'(d) dx (every
edge moving), and ``moment`` = -I ∫ f a d κ_n'(d) dx is what the scaling law of ``plane.size`` needs
(for the impulse, t_{n+1} G(t_{n+1}) - t_n G(t_n)). Same cells as the impulse's route
(:func:`analytic.operator.sensitivity.position_derivatives`), split near the feet.

The pulse's widths (:func:`width_column`, docs/derivatives.md "The pulse's widths"): every pulse has
unit peak, so scaling all its widths by λ gives S_λ(u) = λ S(u/λ) and Σ_w w ∂S/∂w = S(u) - u s(u);
a pulse of one width w (the Gaussian's and sech²'s ``fwhm``, the square's ``width``, the Butterworth's
``cutoff`` with its default duration 3 / cutoff, w = 1 / cutoff) has w ∂y/∂w = I ∫ f a [S - u s]
between the bin's edges. The EMG's Gaussian width σ by the heat equation: ∂F/∂σ = σ F'' for its
unit-area cumulative F, and its peak P = f(t*) moves by ∂P/∂σ = σ f''(t*) (t* the mode, f' = 0
there), f''(t*) = -t* P / (σ² τ) (τ f' + f = g, the Gaussian density, equal to f at t*); so
σ ∂S/∂σ = σ² s'(u) + (t*/τ) S(u), and the tail's share is the scaling law's rest.
"""

from __future__ import annotations

import numpy as np

from ..kernels.bins import TimeAxis
from ..kernels.sensitivity_waveform import OUTPUTS, waveform_pair_sums
from ..waveforms import cumulative_array, derivative_array, make_waveform
from ..waveforms.gaussian import FWHM_PER_SIGMA
from ..waveforms.pieces import without_tail_kinks
from .sensitivity import _cells, pair_geometry, run_sensors

__all__ = ["waveform_derivatives", "kernel_scales", "supports_width", "width_column"]

#: Samples of τ per waveform span for :func:`kernel_scales` (a scale, not a value: a few per cent will do).
_SCALE_SAMPLES = 4001


def kernel_scales(terms, width: float, scaling: bool = False, heat: bool = False) -> tuple[float, float, float, float]:
    """max_τ κ_n(τ) (metres), max_τ |κ_n'(τ)|, with ``scaling`` max_τ |[S - u s]| (metres) and with
    ``heat`` max_τ |[s']| (1/m) of a waveform and bin width, sampled (a scale of each); inf for the last
    two without (the kernel's outputs 9 and 10 then never split a cell: [s'] is the costlier).

    κ_n(τ) = S(u + T) - S(u), κ_n'(τ) = s(u) - s(u + T) and [g] = g(u + T) - g(u) with u = t_n - τ,
    over the span the waveform reaches, its kinks included (s' by central differences: a scale).
    """
    lead, duration = float(terms.lead), float(terms.duration)
    starts = np.asarray(terms.starts, dtype=np.float64)
    u = np.concatenate([np.linspace(lead - width, duration, _SCALE_SAMPLES), starts, starts - width])
    u = np.concatenate([u, np.nextafter(u, np.inf), np.nextafter(u, -np.inf)])
    kernel = cumulative_array(terms, u + width) - cumulative_array(terms, u)
    slope = derivative_array(terms, u) - derivative_array(terms, u + width)
    scaled = curvature = np.inf
    if scaling:
        scaled = float(np.max(np.abs(kernel - (u + width) * derivative_array(terms, u + width)
                                     + u * derivative_array(terms, u))))
    if heat:
        step = 1e-5 * (duration - lead + width)

        def curve(v):
            return (derivative_array(terms, v + step) - derivative_array(terms, v - step)) / (2.0 * step)

        curvature = float(np.max(np.abs(curve(u + width) - curve(u))))
    return float(np.max(np.abs(kernel))), float(np.max(np.abs(slope))), scaled, curvature


def waveform_derivatives(scene, *, progress: bool = False, pulse: bool = False):
    """y, its exact derivatives for every position coordinate and the time zero, the size's moment and
    the pulse's two integrals.

    Parameters
    ----------
    scene : Scene
        A plane scene whose waveform is not the impulse.
    progress : bool
        A progress bar on stderr, one step per sensor.
    pulse : bool
        The pulse's integrals judged to the tolerance too, [s'] only for the EMG, the one that needs it
        (else they come unjudged: a cell is split for the other outputs only).

    Returns
    -------
    y : numpy.ndarray
        ``(K, N)``, the model's samples from the same integrals.
    source, sensor : numpy.ndarray
        ``(K, N, 3)``: ∂y/∂source.position.{x, y, z} and ∂y_k/∂sensors.positions.k.{x, y, z}, per metre.
    start : numpy.ndarray
        ``(K, N)``: ∂y/∂sampling.start, per metre of path length.
    moment : numpy.ndarray
        ``(K, N)``: -I ∫ f a d κ_n'(d) dx, y's units (the scaling law of ``plane.size``).
    widths : numpy.ndarray
        ``(K, N, 2)``: I ∫ f a [S(u) - u s(u)] dx (y's units) and I ∫ f a [s'(u)] dx (y's units per m²),
        [g] = g(t_{n+1} - d) - g(t_n - d) (:func:`width_column`).
    """
    # a smooth pulse's truncated tails are no breakpoints: cutting at them is most of the work
    terms = without_tail_kinks(make_waveform(scene.illumination, scene.sampling.bin_width_opl).terms)
    sampling = scene.sampling
    axis = TimeAxis(float(sampling.start_opl), float(sampling.bin_width_opl), int(sampling.count))
    scales = kernel_scales(terms, axis.bin_width_opl, pulse, pulse and scene.illumination.waveform == "emg")
    cells = _cells(scene)
    count = scene.sensor_count
    sums = np.zeros((count, axis.count, OUTPUTS))
    rtol = float(scene.tolerance)

    def arguments(k):
        return (pair_geometry(scene.source, scene.sensors[k], scene.attenuation), cells, terms, axis, scales, rtol,
                sums[k])

    run_sensors(waveform_pair_sums, arguments, count, rtol, progress)
    sums *= float(scene.intensity)
    return sums[..., 0], sums[..., 1:4], sums[..., 4:7], sums[..., 7], sums[..., 8], sums[..., 9:11]


def supports_width(scene, stem: str) -> bool:
    """Whether ``stem`` is a width of the scene's pulse that :func:`width_column` gives exactly (a relay
    wall's from its own pass, :mod:`.relay_wall_sensitivity`).

    The Butterworth's ``cutoff`` only with the default duration (3 / cutoff, scaled with it): a stated
    duration is a truncation the cutoff does not scale, and ``duration`` itself moves that truncation
    alone; both stay on the differences.
    """
    if scene.kind not in ("plane", "relay_wall") or not stem.startswith("illumination."):
        return False
    illumination = scene.illumination
    widths = {"gaussian": ("fwhm",), "sech2": ("fwhm",), "square": ("width",), "emg": ("fwhm", "tail"),
              "butterworth": ("cutoff",) if illumination.duration is None else ()}
    return stem.split(".", 1)[1] in widths.get(illumination.waveform, ())


def width_column(scene, stem: str, y, widths) -> np.ndarray:
    """∂y/∂``stem`` for a width :func:`supports_width` takes, from y and ``widths`` of
    :func:`waveform_derivatives` (module docstring): per metre (per cycle/m for ``cutoff``)."""
    illumination, name = scene.illumination, stem.split(".", 1)[1]
    scaled, curved = widths[..., 0], widths[..., 1]
    if illumination.waveform == "butterworth":       # w = 1 / cutoff: -cutoff ∂y/∂cutoff = w ∂y/∂w
        return -scaled / float(illumination.cutoff)
    if illumination.waveform != "emg":
        return scaled / float(getattr(illumination, name))
    waveform = make_waveform(illumination, scene.sampling.bin_width_opl)
    sigma, tail = float(illumination.fwhm) / FWHM_PER_SIGMA, float(illumination.tail)
    gaussian = sigma * sigma * curved + (waveform.peak_time / tail) * y      # σ ∂y/∂σ = fwhm ∂y/∂fwhm
    return gaussian / float(illumination.fwhm) if name == "fwhm" else (scaled - gaussian) / tail
