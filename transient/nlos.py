"""The ``transient_opl_nlos`` integrator: a capture through a relay wall, third bounce, binned by path length.

The scene is a relay wall (z = 0, normal +z), a hidden Lambertian rectangle
and a scan of wall points (docs/design.md section 7). Every path is
laser -> l -> x -> s -> sensor with x on the hidden rectangle: the third
bounce, which nothing can occlude when the rectangle faces the wall and
lies wholly in front of it (the only scenes :class:`analytic.relay_wall.RelayWallScene`
accepts), so no rays are traced. Each sample is a point x of the hidden
rectangle that serves *every* (l, s) pair of the scan: for pair p it adds

    c_p = L_p ρ_h(x) / π · cos θ_x^l cos θ_x^s cos θ_l^x cos θ_s^x / (|x - l|² |x - s|²) / p(x),

L_p = cos θ_l^las / |o_l - l|² (ρ_w / π)² the laser leg per unit intensity,
to the bins its path |x - l| + |x - s| (plus both legs when the scan counts
them) reaches, each with the illumination's kernel κ_n. The estimate is per
unit laser intensity; :func:`transient.render.render` multiplies by I once.
Geometry and sums are float64; only the hidden texture is float32
(Mitsuba's bitmaps).

Points are drawn uniformly over the rectangle, jittered-stratified in
Morton order per replica, as ``transient_opl`` does; lanes run over
(sample, pair), so one compiled kernel serves any number of pairs, in
launches of at most :data:`MAX_LANES` lanes.

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from analytic.relay_wall import WALL_NORMAL, grid_points

from .chunks import ReplicaLayout, checked_chunk
from .common import deposit, is_diffuse, jittered_point, opaque_f64, opaque_u32, reduce_mode, replica_of, \
    sample_stream, time_axis_and_waveform

__all__ = ["TransientNlosIntegrator", "PLUGIN_NAME", "MAX_LANES", "SCAN_TYPES"]

PLUGIN_NAME = "transient_opl_nlos"

#: Most (sample, pair) lanes of one kernel launch; a chunk with more is cut into launches.
MAX_LANES = 2**24

SCAN_TYPES = ("single", "confocal", "exhaustive")

# Agreement demanded between the double-precision rectangle this plugin is given and the float32 copy
# Mitsuba built the shape from.
_FLOAT32_MATCH = 1e-6


def _vector(props, name: str) -> np.ndarray:
    return np.array(props.get(name), dtype=np.float64).reshape(3)


class TransientNlosIntegrator(mi.SamplingIntegrator):
    r"""
    .. _integrator-transient_opl_nlos:

    Relay-wall path-length integrator (:monosp:`transient_opl_nlos`)
    ---------------------------------------------------------------

    .. pluginparameters::

     * - bins, start_opl, bin_width_opl, waveform, pulse_width, cutoff, duration, order
       - 
       - The bins and the illumination, as for ``transient_opl``.
     * - hidden_to_world
       - |transform|
       - The hidden rectangle's ``to_world`` in double precision (its local
         [-1, 1]² square; the lit face's normal is its +z); checked against
         the shape with id ``hidden``. (Required)
     * - wall_size_x, wall_size_y
       - |float|
       - The relay wall's sides, metres (centred at the origin in z = 0). (Required)
     * - wall_reflectance
       - |float|
       - ρ_w, in double precision. (Default: 1)
     * - laser_position, sensor_position
       - |point|
       - o_l and o_s, metres. (Required)
     * - scan_type
       - |string|
       - ``single``, ``confocal`` or ``exhaustive``. (Default: ``single``)
     * - grid_width, grid_height
       - |int|
       - The read points' W x H grid. (Required)
     * - laser_point
       - |point|
       - ``single`` only: l on the wall. (Default: its centre)
     * - laser_grid_width, laser_grid_height
       - |int|
       - ``exhaustive`` only: the lit points' grid. (Default: the read grid)
     * - account_first_and_last_bounces
       - |bool|
       - Path lengths add |o_l - l| + |s - o_s|. (Default: false)

    Render with :meth:`render_chunk_per_unit_intensity` (or
    :func:`transient.render.render`), not ``mi.render``.
    """

    def __init__(self, props):
        super().__init__(props)
        self.bins, self.start_opl, self.bin_width_opl, self.waveform = time_axis_and_waveform(props, PLUGIN_NAME)
        if "hidden_to_world" not in props:
            raise ValueError(f"{PLUGIN_NAME}: hidden_to_world is required")
        self.hidden_matrix = np.array(props.get("hidden_to_world").matrix, dtype=np.float64).reshape(4, 4)
        corner = self.hidden_matrix[:3, :3] @ np.array([-1.0, -1.0, 0.0]) + self.hidden_matrix[:3, 3]
        u, v = 2.0 * self.hidden_matrix[:3, 0], 2.0 * self.hidden_matrix[:3, 1]
        width, height = float(np.linalg.norm(u)), float(np.linalg.norm(v))
        if not (width > 0 and height > 0) or abs(u @ v) > 1e-12 * width * height:
            raise ValueError(f"{PLUGIN_NAME}: hidden_to_world must map the square to a rectangle")
        self.corner, self.u, self.v = corner, u, v
        self.normal = np.cross(u, v) / (width * height)
        self.area = width * height
        self.wall_size = (float(props.get("wall_size_x")), float(props.get("wall_size_y")))
        self.wall_reflectance = float(props.get("wall_reflectance", 1.0))
        self.laser_position = _vector(props, "laser_position")
        self.sensor_position = _vector(props, "sensor_position")
        self.scan_type = str(props.get("scan_type", "single"))
        if self.scan_type not in SCAN_TYPES:
            raise ValueError(f"{PLUGIN_NAME}: scan_type must be one of {SCAN_TYPES}, got {self.scan_type!r}")
        grid = (int(props.get("grid_width")), int(props.get("grid_height")))
        laser_point = _vector(props, "laser_point") if "laser_point" in props else np.zeros(3)
        laser_grid = (int(props.get("laser_grid_width", grid[0])), int(props.get("laser_grid_height", grid[1])))
        self.account = bool(props.get("account_first_and_last_bounces", False))
        read = grid_points(grid, self.wall_size)
        if self.scan_type == "single":
            lit, self.read = np.repeat(laser_point[None, :], len(read), axis=0), read
        elif self.scan_type == "confocal":
            lit, self.read = read, read.copy()
        else:
            lasers = grid_points(laser_grid, self.wall_size)
            lit, self.read = np.repeat(lasers, len(read), axis=0), np.tile(read, (len(lasers), 1))
        self.lit = lit
        toward = self.laser_position - lit
        distance = np.linalg.norm(toward, axis=1)
        # the laser leg per unit intensity: cos θ_l^las / |o_l - l|² (ρ_w / π)²
        self.leg = (toward @ WALL_NORMAL) / distance**3 * (self.wall_reflectance / math.pi) ** 2
        self.offsets = (distance + np.linalg.norm(self.read - self.sensor_position, axis=1) if self.account
                        else np.zeros(len(lit)))

    @property
    def pairs(self) -> int:
        """P, the (l, s) pairs: the rows of the transient."""
        return len(self.lit)

    def to_string(self):
        return (f"TransientNlosIntegrator[bins={self.bins}, start_opl={self.start_opl}, "
                f"bin_width_opl={self.bin_width_opl}, scan={self.scan_type!r}, pairs={self.pairs}]")

    def _hidden_shape(self, scene):
        """The shape with id ``hidden``, checked: a rectangle, a diffuse BSDF, the given to_world."""
        shapes = [shape for shape in scene.shapes() if shape.id() == "hidden"]
        if len(shapes) != 1 or shapes[0].shape_type() != mi.ShapeType.Rectangle:
            raise ValueError(f"{PLUGIN_NAME}: the scene must hold one 'rectangle' with id 'hidden'")
        hidden = shapes[0]
        if not is_diffuse(hidden.bsdf()):
            raise ValueError(f"{PLUGIN_NAME}: the hidden rectangle needs a 'diffuse' BSDF")
        matrix = np.array(mi.traverse(hidden)["to_world"].matrix, dtype=np.float64).reshape(4, 4)
        if not np.allclose(matrix, self.hidden_matrix, rtol=_FLOAT32_MATCH,
                           atol=_FLOAT32_MATCH * np.abs(self.hidden_matrix).max()):
            raise ValueError(f"{PLUGIN_NAME}: hidden_to_world differs from the hidden rectangle's to_world")
        return hidden

    def render_chunk_per_unit_intensity(self, scene, *, seed: int, layout: ReplicaLayout, first: int,
                                        count: int) -> np.ndarray:
        """Per-replica sums Σc over samples [first, first + count), per unit laser intensity.

        Returns
        -------
        numpy.ndarray
            ``(replicas touched, P, N)`` float64, as ``transient_opl``'s
            (``render_chunk_per_unit_intensity``), with the pairs as rows.
        """
        first, count = checked_chunk(layout, seed, first, count)
        hidden = self._hidden_shape(scene)
        size = layout.size
        first_replica = first // size
        rows = (first + count - 1) // size - first_replica + 1
        total = np.zeros((layout.histogram_rows, self.pairs, self.bins))
        per_launch = max(1, MAX_LANES // self.pairs)
        for start in range(first, first + count, per_launch):
            launch = min(per_launch, first + count - start)
            total += self._launch(hidden, seed, layout, first_replica, start, launch)
        return total[:rows]

    def _launch(self, hidden, seed, layout, first_replica, first, count):
        """One kernel launch: samples [first, first + count) x every pair; rows counted from first_replica."""
        size = layout.size
        pairs, bins = self.pairs, self.bins
        lane = dr.arange(mi.UInt32, count * pairs)
        sample = lane // opaque_u32(pairs)                              # within the launch
        pair = lane - sample * opaque_u32(pairs)
        index = mi.UInt64(sample) + dr.opaque(mi.UInt64, first)        # global sample index g
        rng = sample_stream(opaque_u32(seed), mi.UInt32(index), mi.UInt32(index >> 32))
        replica, in_replica = replica_of(mi.Float64(sample) + opaque_f64(first - first_replica * size),
                                         opaque_f64(size))
        jitter_u, jitter_v = rng.next_float64(), rng.next_float64()
        u, v = jittered_point(in_replica, opaque_u32(size), jitter_u, jitter_v)
        point = [float(self.corner[i]) + u * float(self.u[i]) + v * float(self.v[i]) for i in range(3)]
        reflectance = self._reflectance(hidden, u, v)

        def gathered(table):
            return dr.gather(mi.Float64, mi.Float64(np.ascontiguousarray(table, dtype=np.float64)), pair)

        lit = [gathered(self.lit[:, i]) for i in range(3)]
        read = [gathered(self.read[:, i]) for i in range(3)]
        to_lit = [lit[i] - point[i] for i in range(3)]
        to_read = [read[i] - point[i] for i in range(3)]
        lit_squared = dr.square(to_lit[0]) + dr.square(to_lit[1]) + dr.square(to_lit[2])
        read_squared = dr.square(to_read[0]) + dr.square(to_read[1]) + dr.square(to_read[2])
        lit_distance, read_distance = dr.sqrt(lit_squared), dr.sqrt(read_squared)
        normal = [float(c) for c in self.normal]
        # cos θ_x^l cos θ_x^s (at x, toward l and s) and cos θ_l^x cos θ_s^x (at the wall, toward x: its z)
        at_hidden = ((to_lit[0] * normal[0] + to_lit[1] * normal[1] + to_lit[2] * normal[2])
                     * (to_read[0] * normal[0] + to_read[1] * normal[1] + to_read[2] * normal[2]))
        at_wall = point[2] * point[2]
        weight = (gathered(self.leg) * reflectance * (self.area / math.pi) * at_hidden * at_wall
                  / (dr.square(lit_squared) * dr.square(read_squared)))
        length = lit_distance + read_distance + gathered(self.offsets)
        histogram = dr.zeros(mi.Float64, layout.histogram_rows * pairs * bins)
        deposit(histogram, replica * pairs + pair, weight, length, mi.Bool(True), bins=bins,
                start_opl=self.start_opl, bin_width_opl=self.bin_width_opl, terms=self.waveform.terms,
                taps=self.waveform.bins_touched(self.bin_width_opl, bins), mode=reduce_mode())
        dr.eval(histogram)
        return np.array(histogram, dtype=np.float64).reshape(layout.histogram_rows, pairs, bins)

    def _reflectance(self, hidden, u, v):
        """ρ_h at (u, v) of the hidden rectangle's texture (float32 as Mitsuba stores it), Float64."""
        interaction = dr.zeros(mi.SurfaceInteraction3f)
        interaction.uv = mi.Point2f(mi.Float(u), mi.Float(v))
        interaction.n = mi.Normal3f(0.0, 0.0, 1.0)
        interaction.sh_frame = mi.Frame3f(interaction.n)
        interaction.wi = mi.Vector3f(0.0, 0.0, 1.0)
        return mi.Float64(hidden.bsdf().eval_diffuse_reflectance(interaction)[0])


mi.register_integrator(PLUGIN_NAME, lambda props: TransientNlosIntegrator(props))
