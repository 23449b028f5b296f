"""What mitransient's ``transient_nlos_path`` renders for a relay-wall capture: the exact model plus its ray offsets.

mitransient's NLOS integrator samples a hidden point x from the read point s
(hidden-geometry sampling: x uniform on the hidden shapes, the relay wall
excluded) and traces the ray toward x with Mitsuba's ``si.spawn_ray``,
whose origin ``Interaction::offset_p`` moves off the wall by

    ε_s = (1 + max_i |s_i|) · RayEpsilon,   RayEpsilon = 1500 · 2⁻²⁴ m (float32 variants),

along the wall's normal, while the direction stays the one aimed from s.
The ray meets the hidden plane at x' ≠ x, and the estimator mixes the two:
the sampling weight ρ_w/π cos θ_s cos θ_x A / |x - s|² is evaluated at x,
everything after (the hidden BSDF toward l, the laser sampling, the wall at
l, the laser) at x', the path length is |x' - o| + |l - x'| (o the moved
origin), and a sample whose x' leaves the rectangle is lost. The laser leg
is traced with ``spawn_ray_to``, which aims from its moved origin at l
itself, and adds nothing. Path lengths come out short by about ε_s (more
where the ray is oblique) and the transient's shape changes a little with
x; a global fit reads this as an offset of ~1.5e-4 m and a scale ~1e-4
low near the origin, growing with the coordinates' magnitude
(docs/interop.md measures both).

:func:`spawn_offset_difference` evaluates that estimator and the exact one
on the same points (common random numbers), in float64: their difference
is what mitransient adds to the model, with no fitted parameter.
:func:`offset_model` is what :func:`validation.check.conventions.transient_nlos_path` states as a
convention for ``check --expect transient_nlos_path``. Nothing here changes the model's own numbers.
"""

from __future__ import annotations

import math

import numpy as np

from analytic.scenes.relay_wall import WALL_NORMAL, RelayWallScene
from transient.constants import RAY_EPSILON

__all__ = ["emulated_estimates", "spawn_offset_difference", "moved_read_points", "offset_model",
           "EMULATED_SAMPLES", "EDGE_POINTS"]

#: Points per edge of the line integral over the unsampled strip.
EDGE_POINTS = 2**15

#: (Sample, pair) evaluations of the emulation by default, shared among the pairs (at least 2^18 each).
EMULATED_SAMPLES = 2**26

_BLOCK = 2**20


def _rest(hit, scene: RelayWallScene, frame, lit, laser_leg):
    """The estimator's weight from the hidden point on (ρ_h/π cos θ_x, laser sampling's 1/pdf, the laser leg)
    and the length |l - hit|."""
    corner, u, v, normal = frame
    to_l = lit - hit
    length = np.linalg.norm(to_l, axis=1)
    cos_x, cos_l = (to_l @ normal) / length, -(to_l @ WALL_NORMAL) / length
    rows = np.clip(((1.0 - (hit - corner) @ v / (v @ v)) * scene.pixels).astype(int), 0, scene.pixels - 1)
    columns = np.clip((((hit - corner) @ u / (u @ u)) * scene.pixels).astype(int), 0, scene.pixels - 1)
    return scene.reflectance[rows, columns] / math.pi * cos_x * cos_l / length**2 * laser_leg, length


def _pair(scene: RelayWallScene, frame, area, read, lit, ends, points, ray_epsilon):
    """(Σ w_0 κ(L_0), Σ w_ε κ(L_ε)) binned, for one pair and a block of uniform hidden points."""
    corner, u, v, normal = frame
    laser, sensor = ends
    toward = laser - lit
    laser_leg = scene.intensity * (toward @ WALL_NORMAL) / np.linalg.norm(toward) ** 3 * scene.wall_reflectance / math.pi
    to_x = points - read
    length_s = np.linalg.norm(to_x, axis=1)
    d = to_x / length_s[:, None]
    sampled = scene.wall_reflectance / math.pi * (d @ WALL_NORMAL) * -(d @ normal) * area / length_s**2
    exact, length_l = _rest(points, scene, frame, lit, laser_leg)
    epsilon = (1.0 + np.max(np.abs(read))) * ray_epsilon
    origin = read + epsilon * WALL_NORMAL                 # offset_p: along n, on the side the ray leaves by
    t = ((corner - origin) @ normal) / (d @ normal)
    hit = origin + t[:, None] * d
    fu, fv = (hit - corner) @ u / (u @ u), (hit - corner) @ v / (v @ v)
    inside = (fu >= 0) & (fu <= 1) & (fv >= 0) & (fv <= 1)
    moved, moved_l = _rest(hit, scene, frame, lit, laser_leg)
    sampling = scene.sampling
    # the legs o_l -> l and o_s -> s: traced exactly (the sensor's ray starts at o_s; the laser's from l to o_l)
    legs = np.linalg.norm(laser - lit) + np.linalg.norm(read - sensor) if scene.scan.account_first_and_last_bounces \
        else 0.0
    sums = []
    for weights, lengths in ((sampled * exact, length_s + length_l),
                             (np.where(inside, sampled * moved, 0.0), t + moved_l)):
        bins = np.floor((lengths + legs - sampling.start_opl) / sampling.bin_width_opl)
        kept = (bins >= 0) & (bins < sampling.count)
        sums.append(np.bincount(bins[kept].astype(int), weights[kept], minlength=sampling.count))
    return sums


def emulated_estimates(scene: RelayWallScene, *, world_offset=None, samples: int | None = None, seed: int = 0,
                       ray_epsilon: float = RAY_EPSILON) -> tuple[np.ndarray, np.ndarray]:
    """mitransient's estimator of a relay-wall capture, emulated in float64, without and with its ray offsets.

    Parameters
    ----------
    scene : RelayWallScene
        The capture, rendered by mitransient as ``export --format mitransient`` writes it (impulse).
    world_offset : array_like, optional
        Where mitransient's scene was moved (metres; the offsets grow with the coordinates).
    samples : int, optional
        Uniform hidden points per pair, jittered-stratified (default: :data:`EMULATED_SAMPLES` shared
        among the pairs, at least 2^18 each).
    seed : int
        Seed of the jitter.
    ray_epsilon : float
        Mitsuba's ``math::RayEpsilon``, metres (float32 variants: 1500 x 2⁻²⁴).

    Returns
    -------
    exact, offset : numpy.ndarray
        ``(P, N)`` each, units of y, on the same points: the estimator with the ray aimed and started at
        s (an unbiased estimate of the model), and as mitransient traces it (module docstring).

    Raises
    ------
    ValueError
        A waveform other than the impulse (mitransient renders no other).
    """
    if scene.illumination.waveform != "impulse":
        raise ValueError("scene: mitransient renders the impulse response only; its bias is emulated for that")
    shift = np.zeros(3) if world_offset is None else np.asarray(world_offset, dtype=np.float64).reshape(3)
    rectangle = scene.rectangle()
    frame = (rectangle.corner + shift, rectangle.u, rectangle.v, rectangle.normal)
    area = float(np.linalg.norm(rectangle.u) * np.linalg.norm(rectangle.v))
    lit, read = scene.pair_points
    if samples is None:
        samples = max(2**18, EMULATED_SAMPLES // len(read))
    side = max(1, math.isqrt(int(samples)))
    rng = np.random.default_rng(seed)
    sums = np.zeros((2, len(read), scene.sampling.count))
    ends = (scene.laser_position + shift, scene.sensor_position + shift)
    for p in range(len(read)):
        for first in range(0, side * side, _BLOCK):
            cell = np.arange(first, min(first + _BLOCK, side * side))
            a = (cell // side + rng.random(cell.size)) / side
            b = (cell % side + rng.random(cell.size)) / side
            points = frame[0] + a[:, None] * frame[1] + b[:, None] * frame[2]
            exact, moved = _pair(scene, frame, area, read[p] + shift, lit[p] + shift, ends, points, ray_epsilon)
            sums[0, p] += exact
            sums[1, p] += moved
    sums /= side * side
    return sums[0], sums[1]


def spawn_offset_difference(scene: RelayWallScene, **options) -> np.ndarray:
    """What mitransient's ray offsets add to the model: ``(P, N)``, units of y (an impulse illumination).

    The emulated estimator with its offsets minus without, on the same points (:func:`emulated_estimates`,
    whose ``options`` it takes): only the samples whose bin or inclusion the offsets change contribute, so
    its own Monte Carlo error is far below either estimator's.
    """
    exact, moved = emulated_estimates(scene, **options)
    return moved - exact


def moved_read_points(scene: RelayWallScene, *, world_offset=None, ray_epsilon: float = RAY_EPSILON) -> np.ndarray:
    """Where mitransient's rays toward the hidden scene start: o = s + (1 + max_i |s_i|) RayEpsilon n, ``(P, 3)``.

    In the scene's coordinates (the wall at the origin); ``world_offset`` is where mitransient's scene was
    moved, which sets max_i |s_i|.
    """
    shift = np.zeros(3) if world_offset is None else np.asarray(world_offset, dtype=np.float64).reshape(3)
    _, read = scene.pair_points
    epsilon = (1.0 + np.max(np.abs(read + shift), axis=1)) * ray_epsilon
    return read + epsilon[:, None] * WALL_NORMAL


def _unsampled_strip(scene: RelayWallScene, pairs, origins: np.ndarray, points: int) -> np.ndarray:
    """``(P, N)``: the light of the strip along the edges whose x' no sample reaches (a line integral)."""
    rectangle = scene.rectangle()
    corner, u, v, normal = rectangle.corner, rectangle.u, rectangle.v, rectangle.normal
    sampling = scene.sampling
    centre = corner + 0.5 * (u + v)
    fractions = (np.arange(points) + 0.5) / points
    edges = [(corner, u), (corner, v), (corner + v, u), (corner + u, v)]
    lost = np.zeros((len(origins), sampling.count))
    for start, along in edges:
        q = start + fractions[:, None] * along
        midpoint = start + 0.5 * along
        outward = (midpoint - centre) - ((midpoint - centre) @ along) / (along @ along) * along
        outward /= np.linalg.norm(outward)
        inside = q - 1e-9 * np.linalg.norm(along) * outward          # the pixel on the rectangle's side
        fu, fv = (inside - corner) @ u / (u @ u), (inside - corner) @ v / (v @ v)
        rows = np.clip(((1.0 - fv) * scene.pixels).astype(int), 0, scene.pixels - 1)
        columns = np.clip((fu * scene.pixels).astype(int), 0, scene.pixels - 1)
        albedo = scene.reflectance[rows, columns] / math.pi
        step = float(np.linalg.norm(along)) / points
        for p in range(len(origins)):
            read, lit, o = pairs.sensors[p], pairs.sources[p], origins[p]
            to_q = q - o
            length_o = np.linalg.norm(to_q, axis=1)
            d = to_q / length_o[:, None]
            along_d = d @ normal
            x = read + (((corner - read) @ normal) / along_d)[:, None] * d     # the sampled point, from s
            width = np.maximum(0.0, -((q - x) @ outward))
            to_l = lit - q
            length_l = np.linalg.norm(to_l, axis=1)
            value = (pairs.scales[p] * albedo * (d @ WALL_NORMAL) * -along_d * (to_l @ normal) / length_l
                     * -(to_l @ WALL_NORMAL) / length_l / (length_o**2 * length_l**2))
            lengths = length_o + length_l + pairs.offsets[p]
            bins = np.floor((lengths - sampling.start_opl) / sampling.bin_width_opl)
            kept = (bins >= 0) & (bins < sampling.count) & (width > 0)
            lost[p] += np.bincount(bins[kept].astype(int), (value * width * step)[kept], minlength=sampling.count)
    return lost


def offset_model(scene: RelayWallScene, *, world_offset=None, ray_epsilon: float = RAY_EPSILON,
                 edge_points: int = EDGE_POINTS) -> np.ndarray:
    """mitransient's expected transient in closed form: the model read from o, less the unsampled strip.

    Parameters
    ----------
    scene : RelayWallScene
        The capture (impulse illumination), rendered by mitransient as ``export --format mitransient``
        writes it.
    world_offset : array_like, optional
        Where mitransient's scene was moved, metres.
    ray_epsilon : float
        Mitsuba's ``math::RayEpsilon``, metres.
    edge_points : int
        Points per edge of the strip's line integral (the strip holds ~1e-4 of the light: its
        midpoint-rule error is far below the model's tolerance).

    Returns
    -------
    numpy.ndarray
        ``(P, N)`` units of y: the exact model of the scene with each read point at
        :func:`moved_read_points` (same lit points, legs and scales), minus the strip (module docstring).
    """
    from analytic.geometry import PointPairs
    from analytic.operator.system import rectangle_matrix
    from analytic.waveforms import make_waveform

    if scene.illumination.waveform != "impulse":
        raise ValueError("scene: mitransient renders the impulse response only; its bias is stated for that")
    rectangle, pairs = scene.geometry()
    origins = moved_read_points(scene, world_offset=world_offset, ray_epsilon=ray_epsilon)
    moved = PointPairs(pairs.sources, origins, offsets=pairs.offsets, source_normals=pairs.source_normals,
                       sensor_normals=pairs.sensor_normals, scales=pairs.scales)
    matrix = rectangle_matrix(rectangle, moved, scene.sampling,
                              make_waveform(scene.illumination, scene.sampling.bin_width_opl),
                              tolerance=scene.tolerance)
    from_o = (matrix @ scene.reflectance.ravel()).reshape(scene.sensor_count, scene.sampling.count)
    return from_o - _unsampled_strip(scene, pairs, origins, edge_points)

