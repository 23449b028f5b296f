"""A crude, independent reference for a scene's transient: midpoint samples of the plane, binned.

Shares nothing with ``analytic`` but the scene's fields: the attenuation is
written out from docs/design.md section 2, the pulse's energy and cumulative come
from :mod:`waveform_reference`. Accurate to about 1 % of a sensor's total:
good enough to catch a wrong number at an extreme input, never a substitute
for the quadrature's own accuracy tests.
"""

from __future__ import annotations

import numpy as np

from waveform_reference import reference_cumulative


def _points(scene, grid: int):
    centres = (np.arange(grid) + 0.5) / grid * scene.size
    x, y = np.meshgrid(centres, centres)
    # reflectance at each point: image[r, c] covers x in [cΔ, (c+1)Δ), y in [L-(r+1)Δ, L-rΔ)
    delta = scene.size / scene.pixels
    column = np.minimum((x / delta).astype(int), scene.pixels - 1)
    row = np.minimum(((scene.size - y) / delta).astype(int), scene.pixels - 1)
    return x.ravel(), y.ravel(), scene.reflectance[row, column].ravel(), (scene.size / grid) ** 2


def _attenuation(scene, x, y, sensor):
    sx, sy, hs = scene.source
    kx, ky, hk = sensor
    ds = np.sqrt((x - sx) ** 2 + (y - sy) ** 2 + hs**2)
    dk = np.sqrt((x - kx) ** 2 + (y - ky) ** 2 + hk**2)
    if scene.attenuation == "lambertian":
        return (hs / ds) * (hk / dk) / (np.pi * ds**2 * dk**2), ds + dk
    return (hs / ds) / (ds**2 * dk**2), ds + dk


def _illumination_kwargs(scene):
    ill = scene.illumination
    return dict(period=scene.sampling.bin_width_opl, width=ill.width, cutoff=ill.cutoff,
                duration=ill.duration, order=ill.order)


def sensor_totals(scene, grid: int = 300) -> np.ndarray:
    """Σ_n y_k[n] over a window that holds all the light: I ∫ s dt ∫ f a_k dx, ``(K,)``."""
    x, y, f, area = _points(scene, grid)
    energy = float(reference_cumulative(scene.illumination.waveform, np.array([1e30]),
                                        **_illumination_kwargs(scene))[0])
    totals = [np.sum(f * _attenuation(scene, x, y, sensor)[0]) * area for sensor in scene.sensors]
    return scene.intensity * energy * np.array(totals)


def path_length_range(scene, grid: int = 300) -> tuple[float, float]:
    """(min, max) path length over the midpoint samples, metres."""
    x, y, _, _ = _points(scene, grid)
    lengths = np.concatenate([_attenuation(scene, x, y, sensor)[1] for sensor in scene.sensors])
    return float(lengths.min()), float(lengths.max())


def binned_transient(scene, grid: int = 300) -> np.ndarray:
    """y_k[n] for the impulse or a square pulse, ``(K, N)``.

    Impulse: each sample's f a ΔA in the bin of its path length τ. Square of
    width w: times the overlap of [τ, τ + w] with each bin,
    max(0, min(t_{n+1}, τ + w) − max(t_n, τ)).
    """
    waveform = scene.illumination.waveform
    if waveform not in ("impulse", "square"):
        raise ValueError("binned_transient: impulse or square only")
    width = (scene.illumination.width if scene.illumination.width is not None
             else scene.sampling.bin_width_opl / 5.0)
    x, y, f, area = _points(scene, grid)
    sampling = scene.sampling
    edges = sampling.edges
    out = np.zeros((scene.sensor_count, sampling.count))
    for k, sensor in enumerate(scene.sensors):
        weight, length = _attenuation(scene, x, y, sensor)
        if waveform == "impulse":
            index = np.floor((length - sampling.start_opl) / sampling.bin_width_opl).astype(np.int64)
            inside = (index >= 0) & (index < sampling.count)
            np.add.at(out[k], index[inside], (f * weight * area)[inside])
        else:
            overlap = np.maximum(0.0, np.minimum(edges[1:, None], length[None, :] + width)
                                 - np.maximum(edges[:-1, None], length[None, :]))
            out[k] = overlap @ (f * weight * area)
    return scene.intensity * out
