"""Exact ∂y/∂θ of a plane scene under any waveform but the impulse (docs/derivatives.md).

    ∂y_k[n]/∂θ = I ∫ f ∂a_k/∂θ κ_n(d) dx  +  I ∫ f a_k ∂d/∂θ κ_n'(d) dx,
    κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ),   κ_n'(τ) = s(t_n - τ) - s(t_{n+1} - τ),

integrated over each reflectance cell directly (:mod:`analytic.kernels.sensitivity_waveform`): the
integrand is analytic on a cell except along the isochrones d = t_e - b_i (a bin edge shifted back by a
kink b_i of the waveform), where the cell is cut. The time zero's column is -I ∫ f a κ_n'(d) dx (every
edge moving), and ``moment`` = -I ∫ f a d κ_n'(d) dx is what the scaling law of ``plane.size`` needs
(for the impulse, t_{n+1} G(t_{n+1}) - t_n G(t_n)). Same cells as the impulse's route
(:func:`analytic.operator.sensitivity.position_derivatives`), split near the feet.
"""

from __future__ import annotations

import numpy as np

from ..kernels.bins import TimeAxis
from ..kernels.sensitivity_waveform import OUTPUTS, waveform_pair_sums
from ..waveforms import cumulative_array, derivative_array, make_waveform
from .sensitivity import _cells, pair_geometry, run_sensors

__all__ = ["waveform_derivatives", "kernel_scales"]

#: Samples of τ per waveform span for :func:`kernel_scales` (a scale, not a value: a few per cent will do).
_SCALE_SAMPLES = 4001


def kernel_scales(terms, width: float) -> tuple[float, float]:
    """max_τ κ_n(τ) (metres) and max_τ |κ_n'(τ)| of a waveform and bin width, sampled (a scale of each).

    κ_n(τ) = S(u + T) - S(u) and κ_n'(τ) = s(u) - s(u + T) with u = t_n - τ, over the span the waveform
    reaches, its kinks included.
    """
    lead, duration = float(terms.lead), float(terms.duration)
    starts = np.asarray(terms.starts, dtype=np.float64)
    u = np.concatenate([np.linspace(lead - width, duration, _SCALE_SAMPLES), starts, starts - width])
    u = np.concatenate([u, np.nextafter(u, np.inf), np.nextafter(u, -np.inf)])
    kernel = cumulative_array(terms, u + width) - cumulative_array(terms, u)
    slope = derivative_array(terms, u) - derivative_array(terms, u + width)
    return float(np.max(np.abs(kernel))), float(np.max(np.abs(slope)))


def waveform_derivatives(scene, *, progress: bool = False):
    """y, its exact derivatives for every position coordinate and the time zero, and the size's moment.

    Parameters
    ----------
    scene : Scene
        A plane scene whose waveform is not the impulse.
    progress : bool
        A progress bar on stderr, one step per sensor.

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
    """
    terms = make_waveform(scene.illumination, scene.sampling.bin_width_opl).terms
    sampling = scene.sampling
    axis = TimeAxis(float(sampling.start_opl), float(sampling.bin_width_opl), int(sampling.count))
    scales = kernel_scales(terms, axis.bin_width_opl)
    cells = _cells(scene)
    count = scene.sensor_count
    sums = np.zeros((count, axis.count, OUTPUTS))
    rtol = float(scene.tolerance)

    def arguments(k):
        return (pair_geometry(scene.source, scene.sensors[k], scene.attenuation), cells, terms, axis, scales, rtol,
                sums[k])

    run_sensors(waveform_pair_sums, arguments, count, rtol, progress)
    sums *= float(scene.intensity)
    return sums[..., 0], sums[..., 1:4], sums[..., 4:7], sums[..., 7], sums[..., 8]
