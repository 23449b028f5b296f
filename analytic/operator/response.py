"""Continuous impulse responses g_k(t) from the contour (coarea) form, and the samples they give.

    g_k(t) = ∫ f a_k δ(t - d_k) dx = ∮_{d_k = t} f a_k / |∇d_k| ds     (coarea formula)

The paper's eq. (3) writes the same contour integral with unit speed and no
1/|∇d| (docs/design.md section 3.1); ``coarea=False`` evaluates that form, so the
cost of the omission can be measured. |∇d| = |(x - p_s)/d_s + (x - p_k)/d_k|
(projected on the plane) varies along the ellipse, from small near the
first-arrival point to about 2 far from it.

The isochrone is cut where it crosses pixel edges, so each arc sees one
reflectance value and a smooth integrand, integrated by Gauss–Legendre on
pieces of at most ``max_arc`` radians. :func:`binned_contour_model`
integrates g_k over each bin: the samples y_k[n] for the impulse
illumination by a route independent of the system matrix's quadrature.
"""

from __future__ import annotations

import numpy as np

from ..attenuation import attenuation, attenuation_code
from ..kernels.isochrone import ellipse, make_frame
from ..scenes.common import Scene

__all__ = ["impulse_response", "binned_contour_model"]


def impulse_response(scene: Scene, sensor: int, times, *, coarea: bool = True, nodes: int = 24,
                     max_arc: float = 0.2) -> np.ndarray:
    """g_k(t) of the scene's reflectance at path lengths ``times``.

    Parameters
    ----------
    scene : Scene
        Geometry, reflectance and attenuation.
    sensor : int
        Sensor index k.
    times : array_like
        Path lengths t, metres (c = 1).
    coarea : bool
        Include the coarea factor 1/|∇d| (correct). False gives the paper's
        eq. (3) unit-speed contour integral (wrong; for comparison).
    nodes : int
        Gauss–Legendre nodes per arc piece.
    max_arc : float
        Longest arc piece, radians of the ellipse's parameter.

    Returns
    -------
    numpy.ndarray
        g_k(t) = I ∫ f a_k δ(t - d_k) dx, the source's intensity I included:
        units of y per metre of path length (W m⁻²). With ``coarea=False``
        the units differ (per metre of arc length).
    """
    times = np.atleast_1d(np.asarray(times, dtype=np.float64))
    mode = attenuation_code(scene.attenuation)
    source = np.asarray(scene.source, dtype=np.float64)
    position = np.asarray(scene.sensors[sensor], dtype=np.float64)
    frame = make_frame(source, position, mode)
    unit_nodes, unit_weights = np.polynomial.legendre.leggauss(nodes)
    out = np.zeros(times.shape)
    for i, t in enumerate(times.ravel()):
        if t <= frame.first_arrival:
            continue
        out.flat[i] = _contour(scene, frame, source, position, t, coarea, unit_nodes, unit_weights, max_arc)
    return scene.intensity * out


def _contour(scene, frame, source, sensor, t, coarea, unit_nodes, unit_weights, max_arc):
    cx, cy, a, b, *_ = ellipse(frame, t)
    e1, e2 = frame.axis_x, frame.axis_y
    size, pixels = scene.size, scene.pixels
    delta = scene.pixel_size[0]     # the plane's pixels are square: (Δ, Δ)
    lines = np.arange(pixels + 1) * delta
    # x(φ) = cx + R1 cos(φ + ψ1), y(φ) = cy + R2 cos(φ - ψ2)
    r1, psi1 = np.hypot(a * e1, b * e2), np.arctan2(b * e2, a * e1)
    r2, psi2 = np.hypot(a * e2, b * e1), np.arctan2(b * e1, a * e2)
    angles = [np.zeros(1)]
    for level, radius, offset in ((lines - cx, r1, -psi1), (lines - cy, r2, psi2)):
        if radius > 0:
            ratio = level / radius
            ratio = ratio[np.abs(ratio) < 1.0]
            base = np.arccos(ratio)
            angles.extend([(offset + base) % (2 * np.pi), (offset - base) % (2 * np.pi)])
    cuts = np.unique(np.concatenate(angles))
    cuts = np.append(cuts, 2 * np.pi)
    # split long arcs so that fixed Gauss-Legendre stays accurate
    pieces = np.maximum(1, np.ceil(np.diff(cuts) / max_arc).astype(int))
    lows = np.repeat(cuts[:-1], pieces) + np.concatenate(
        [np.arange(n) * (h - l) / n for n, l, h in zip(pieces, cuts[:-1], cuts[1:])])
    widths = np.repeat(np.diff(cuts) / pieces, pieces)
    phi = lows[:, None] + 0.5 * widths[:, None] * (unit_nodes[None, :] + 1.0)
    weight = 0.5 * widths[:, None] * unit_weights[None, :]
    cos_phi, sin_phi = np.cos(phi), np.sin(phi)
    x = cx + a * cos_phi * e1 - b * sin_phi * e2
    y = cy + a * cos_phi * e2 + b * sin_phi * e1
    # reflectance of the arc piece's pixel (each piece lies in one pixel)
    xm = cx + a * np.cos(lows + 0.5 * widths) * e1 - b * np.sin(lows + 0.5 * widths) * e2
    ym = cy + a * np.cos(lows + 0.5 * widths) * e2 + b * np.sin(lows + 0.5 * widths) * e1
    inside = (xm >= 0) & (xm < size) & (ym >= 0) & (ym < size)
    column = np.clip(np.floor(xm / delta).astype(int), 0, pixels - 1)
    row = np.clip(np.floor((size - ym) / delta).astype(int), 0, pixels - 1)
    reflectance = np.where(inside, scene.reflectance[row, column], 0.0)
    atten = attenuation(np.stack([x, y], axis=-1), source, sensor, scene.attenuation)
    speed = np.sqrt((a * sin_phi) ** 2 + (b * cos_phi) ** 2)        # |dx/dφ|
    integrand = atten * speed
    if coarea:
        # |∇d| projected on the plane: the sum of the unit vectors from the source and the sensor
        d_source = np.sqrt((x - source[0]) ** 2 + (y - source[1]) ** 2 + source[2] ** 2)
        d_sensor = np.sqrt((x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2)
        gradient = np.hypot((x - source[0]) / d_source + (x - sensor[0]) / d_sensor,
                            (y - source[1]) / d_source + (y - sensor[1]) / d_sensor)
        integrand = integrand / gradient
    return float(np.sum(reflectance[:, None] * integrand * weight))


def binned_contour_model(scene: Scene, *, coarea: bool = True, pieces: int = 8, nodes: int = 8) -> np.ndarray:
    """y for the impulse illumination from the contour form: ∫_bin g_k(t) dt, ``(K, N)``.

    Parameters
    ----------
    scene : Scene
        A scene with the impulse illumination.
    coarea : bool
        False integrates the paper's eq. (3) instead (no 1/|∇d|): a
        deliberately wrong model for the cross-check's own tests.
    pieces, nodes : int
        Composite Gauss–Legendre over each bin: ``pieces`` equal pieces of
        ``nodes`` points.

    Returns
    -------
    numpy.ndarray
        ``(K, N)``, units of y.

    Notes
    -----
    y_k[n] = ∫_{t_n}^{t_{n+1}} g_k(t) dt for s = δ (docs/design.md section 2);
    g_k is zero before the first arrival, where it contributes nothing.
    """
    if scene.illumination.waveform != "impulse":
        raise ValueError("binned_contour_model: only the impulse illumination")
    unit, weights = np.polynomial.legendre.leggauss(nodes)
    edges = scene.sampling.edges
    y = np.zeros((scene.sensor_count, scene.sampling.count))
    for k in range(scene.sensor_count):
        for n in range(scene.sampling.count):
            cuts = np.linspace(edges[n], edges[n + 1], pieces + 1)
            centres, halves = 0.5 * (cuts[1:] + cuts[:-1]), 0.5 * np.diff(cuts)
            t = (centres[:, None] + halves[:, None] * unit[None, :]).ravel()
            values = impulse_response(scene, k, t, coarea=coarea).reshape(pieces, nodes)
            y[k, n] = float(np.sum(values * weights[None, :] * halves[:, None]))
    return y
