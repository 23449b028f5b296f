"""Exact ∂y/∂θ of a plane scene for the source's and sensors' positions and the time zero (docs/derivatives.md).

    y_k[n] = I ∫ f a_k κ_n(d) dx,   κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ)

    ∂y_k[n]/∂θ = I ∫ f ∂a_k/∂θ κ_n(d) dx  +  I ∫ f a_k ∂d/∂θ κ_n'(d) dx
                 (interior term)              (bin-edge term)

For the impulse, κ_n is the indicator of [t_n, t_{n+1}) and κ_n'(τ) =
δ(τ - t_n) - δ(τ - t_{n+1}), so with F_w(t) = ∫_{d < t} f w dx and its
t-derivative H_w(t) = ∫ f w δ(d - t) dx (the coarea integral along the
isochrone d = t):

    interior_n = F_{∂a/∂θ}(t_{n+1}) - F_{∂a/∂θ}(t_n),
    edge_n     = H_{a ∂d/∂θ}(t_n) - H_{a ∂d/∂θ}(t_{n+1}),
    ∂y_n/∂t_0  = H_a(t_{n+1}) - H_a(t_n)          (every edge moving).

Both are sums over the reflectance's pixels. For a pixel the isochrone
d = t crosses, the region d < t is the inside of an ellipse (d is convex),
integrated in x (outer) and y (inner): the inner y-interval is clipped by
the ellipse's two roots at x, and the outer integrand is analytic between
the ellipse's x-extremes (square-root ends, made analytic by the map
x = c_x - reach cos(πv) anchored at both) and the x where it crosses the
pixel's lower and upper edges, which cut the outer interval. H is the same outer integral of Σ_roots w / |∂d/∂y|. A pixel
wholly inside the ellipse (its four corners are, d being convex) is one
tensor Gauss rule. Pixels near a foot (where a has a peak as wide as the
height) are split in quadrants down to a quarter of their distance to it. The
rules (:mod:`analytic.kernels.sensitivity`) are judged against higher ones
and bisected to the scene's tolerance; tests hold the result
to Richardson differences of the model at tolerance 1e-10 and to a
point-like plane's closed form.

All position keys of all sensors come from one pass per sensor: the
amplitudes of the six position derivatives and of a are evaluated on the
same nodes.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..attenuation import attenuation_code
from ..kernels.formulas import LAMBERTIAN
from ..kernels.sensitivity import AMPLITUDES, PairGeometry, pair_sums
from .blocks import run_blocks
from .general_routes import progress_bar
from .system import QuadratureWarning

__all__ = ["position_derivatives", "supports", "pair_geometry", "run_sensors", "pixel_cells", "edge_columns",
           "EdgeOnArrivalWarning", "warn_edges_on_arrivals"]

#: Cells are at most this fraction of their distance to a foot's peak wide.
_CELL_OF_HEIGHT = 0.25
#: The cell integrals' accuracy, as a fraction of the scene's tolerance.
_SAFETY = 1.0
#: A bin edge this close (relative) to a pair's first arrival is on it.
_ON_ARRIVAL = 1e-9


class EdgeOnArrivalWarning(UserWarning):
    """A bin edge lies on a pair's first arrival, where the impulse response jumps: y has no derivative there."""


def warn_edges_on_arrivals(geometries, cells, edges, what: str) -> None:
    """Warn once (:class:`EdgeOnArrivalWarning`) if a bin edge is on a pair's first arrival with light there.

    The impulse response of a pair jumps at its first arrival t_min when the point of first arrival (on
    the segment between the feet, h_s / (h_s + h_k) of the way from the source's) lies on a cell of
    non-zero reflectance: y is then not differentiable in anything that moves that edge or t_min, and the
    cell integrals (whose isochrone there is a point) return the one-sided value of the edge just before
    the arrival. ``geometries``: :class:`PairGeometry` per pair; ``cells``: rows (x0, x1, y0, y1, f);
    ``edges``: ``(P, E)`` each pair's bin edges on its own time axis, metres; ``what``: the pairs' name.
    """
    edges = np.asarray(edges, dtype=np.float64)
    hits = []
    for p, g in enumerate(geometries):
        near = np.flatnonzero(np.abs(edges[p] - g.first) <= _ON_ARRIVAL * g.first)
        if not near.size:
            continue
        share = g.sh / (g.sh + g.kh) if g.sh + g.kh > 0.0 else 0.5
        x, y = g.sx + share * (g.kx - g.sx), g.sy + share * (g.ky - g.sy)
        slack = _ON_ARRIVAL * g.first
        if np.any((cells[:, 0] - slack <= x) & (x <= cells[:, 1] + slack) & (cells[:, 2] - slack <= y)
                  & (y <= cells[:, 3] + slack)):
            hits.append((p, int(near[0])))
    if hits:
        (p, n), width = hits[0], float(edges[0, 1] - edges[0, 0]) if edges.shape[1] > 1 else 0.0
        edge, first = float(edges[p, n]), float(geometries[p].first)
        warnings.warn(f"bin edge {n} of {what} {p} (t = {edge!r} m on its time axis) lies on its first arrival "
                      f"({first!r} m), where the impulse response jumps ({len(hits)} pair(s) in all): y has no "
                      f"derivative there in sampling.start or any key that moves the arrival, and the exact "
                      f"route returns the one-sided value of the edge just before the arrival; move "
                      f"sampling.start by a fraction of a bin (e.g. {0.25 * width:g} m)",
                      EdgeOnArrivalWarning, stacklevel=4)


def supports(scene) -> bool:
    """Whether :func:`position_derivatives` applies: a plane scene with the impulse illumination."""
    return scene.kind == "plane" and scene.illumination.waveform == "impulse"


def _near(boxes, feet) -> np.ndarray:
    """Which cells (rows x0, x1, y0, y1) are wider than :data:`_CELL_OF_HEIGHT` of their distance to a
    foot's peak, (gap² + h²)^½ for each foot (x, y, h)."""
    x0, x1, y0, y1 = (boxes[:, i, None] for i in range(4))
    gap_x = np.maximum(0.0, np.maximum(x0 - feet[:, 0], feet[:, 0] - x1))
    gap_y = np.maximum(0.0, np.maximum(y0 - feet[:, 1], feet[:, 1] - y1))
    reach = np.sqrt(gap_x ** 2 + gap_y ** 2 + feet[:, 2] ** 2)
    return np.any(np.maximum(x1 - x0, y1 - y0) > _CELL_OF_HEIGHT * reach, axis=1)


def _cells(scene):
    """The plane's pixels of non-zero reflectance as boxes (x0, x1, y0, y1, f), split near the feet (:func:`pixel_cells`)."""
    size = float(scene.size)
    feet = np.vstack([np.asarray(scene.source, dtype=np.float64)[None, :], np.asarray(scene.sensors, dtype=np.float64)])
    return pixel_cells(size, size, scene.reflectance, feet)


def pixel_cells(width: float, height: float, reflectance, feet) -> np.ndarray:
    """The pixels of non-zero reflectance as boxes (x0, x1, y0, y1, f), split in quadrants near the feet.

    The image's M x M pixels tile [0, width] x [0, height] (image row r from
    the top). A's amplitude has a peak as wide as the height under each
    point of ``feet`` (rows x, y, height: complex singularities a height
    away): a cell is split until it is narrower than a quarter of its
    distance to them, so the cells shrink geometrically towards a foot (a
    few dozen per level) however low it is. Whole arrays at a time, one
    level of splitting after the other.
    """
    image = np.asarray(reflectance, dtype=np.float64)
    pixels = image.shape[0]
    du, dv = width / pixels, height / pixels
    rows, columns = np.nonzero(image)
    x0, y0 = columns * du, height - (rows + 1) * dv
    boxes = np.stack([x0, x0 + du, y0, y0 + dv, image[rows, columns]], axis=1)
    kept, pending = [], boxes
    while len(pending):
        near = _near(pending, feet)
        kept.append(pending[~near])
        split = pending[near]
        xm, ym = 0.5 * (split[:, 0] + split[:, 1]), 0.5 * (split[:, 2] + split[:, 3])
        pending = np.concatenate([np.stack([a, b, c, d, split[:, 4]], axis=1) for a, b in
                                  ((split[:, 0], xm), (xm, split[:, 1])) for c, d in
                                  ((split[:, 2], ym), (ym, split[:, 3]))])
    return np.concatenate(kept) if kept else boxes


def pair_geometry(source, sensor, attenuation: str) -> PairGeometry:
    """The compiled kernels' record of a source-sensor pair above the plane z = 0."""
    source, sensor = np.asarray(source, dtype=np.float64), np.asarray(sensor, dtype=np.float64)
    offset = sensor[:2] - source[:2]
    distance = float(np.hypot(*offset))
    ex, ey = (offset / distance) if distance > 0 else (1.0, 0.0)
    return PairGeometry(*map(float, source), *map(float, sensor), attenuation_code(attenuation) == LAMBERTIAN,
                        float(ex), float(ey), distance, float(np.hypot(distance, source[2] + sensor[2])),
                        float(np.hypot(distance, source[2] - sensor[2])))


def run_sensors(kernel, arguments, count: int, rtol: float, progress: bool) -> None:
    """``kernel(*arguments(k))`` for each sensor k (threads, a progress bar); warns of pieces left unconverged."""
    bar = progress_bar(progress, count, "exact derivatives", "sensor")
    try:
        failures = sum(run_blocks(kernel, arguments, count, bar=bar))
    finally:
        if bar is not None:
            bar.close()
    if failures:
        warnings.warn(f"{failures} cell integrals of the exact derivatives stopped refining before reaching "
                      f"tolerance {rtol:g}", QuadratureWarning, stacklevel=4)


def position_derivatives(scene, *, progress: bool = False):
    """y and its exact derivatives for every position coordinate and the time zero, impulse illumination.

    Parameters
    ----------
    scene : Scene
        A plane scene (:func:`supports`).
    progress : bool
        A progress bar on stderr, one step per sensor.

    Returns
    -------
    y : numpy.ndarray
        ``(K, N)``, the model's samples from the same integrals (a check on them).
    source : numpy.ndarray
        ``(K, N, 3)``: ∂y/∂source.position.{x, y, z}, y's units per metre.
    sensor : numpy.ndarray
        ``(K, N, 3)``: ∂y_k/∂sensors.positions.k.{x, y, z} (row k depends on sensor k alone).
    start : numpy.ndarray
        ``(K, N)``: ∂y/∂sampling.start, y's units per metre of path length.
    response : numpy.ndarray
        ``(K, N + 1)``: the impulse response I ∫ f a δ(d - t) dx at each bin edge t, y's units per metre.
    """
    cells = _cells(scene)
    edges = np.asarray(scene.sampling.edges, dtype=np.float64)
    count, bins = scene.sensor_count, scene.sampling.count
    sums = np.zeros((count, 2, bins + 1, AMPLITUDES))
    rtol = _SAFETY * float(scene.tolerance)

    geometries = [pair_geometry(scene.source, sensor, scene.attenuation) for sensor in scene.sensors]
    warn_edges_on_arrivals(geometries, cells, np.broadcast_to(edges, (count, edges.size)), "sensor")

    def arguments(k):
        return geometries[k], cells, edges, rtol, sums[k, 0], sums[k, 1]

    run_sensors(pair_sums, arguments, count, rtol, progress)
    return edge_columns(sums, float(scene.intensity))


def edge_columns(sums, scale: float):
    """(y, ∂y/∂p_s, ∂y/∂p_k, ∂y/∂t_0, response) of :func:`position_derivatives` from :func:`pair_sums`' ``sums``
    ``(K, 2, E, 13)`` (F, H at the bin edges) and the rows' common factor ``scale``."""
    F, H = sums[:, 0], sums[:, 1]
    interior = np.diff(F, axis=1)                  # F(t_{n+1}) - F(t_n)
    moving = H[:, :-1] - H[:, 1:]                  # H(t_n) - H(t_{n+1})
    return (scale * interior[..., 0], scale * (interior[..., 1:4] + moving[..., 7:10]),
            scale * (interior[..., 4:7] + moving[..., 10:13]), -scale * moving[..., 0], scale * H[..., 0])
