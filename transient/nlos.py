"""The ``transient_opl_nlos`` integrator: a capture through a relay wall, third bounce, binned by path length.

The scene is a relay wall (z = 0, normal +z), a hidden Lambertian rectangle
and a scan of wall points (docs/design.md section 7). Every path is
laser -> l -> x -> s -> sensor with x on the hidden rectangle: the third
bounce, which nothing can occlude when the rectangle faces the wall and
lies wholly in front of it (the only scenes :class:`analytic.scenes.relay_wall.RelayWallScene`
accepts), so no rays are traced. Each sample is a point x of the hidden
rectangle that serves *every* (l, s) pair of the scan: for pair p it adds

    c_p = L_p ρ_h(x) / π · g_l(x) g_s(x) / p(x),   g_w = cos θ_x^w cos θ_w^x / |x - w|²,

L_p = cos θ_l^las / |o_l - l|² (ρ_w / π)² the laser leg per unit intensity,
to the bins its path |x - l| + |x - s| (plus both legs when the scan counts
them) reaches, each with the illumination's kernel κ_n. The estimate is per
unit laser intensity; :func:`transient.render.render` multiplies by I once.
Geometry and sums are float64; only the hidden texture is float32
(Mitsuba's bitmaps).

How x is drawn (:mod:`transient.plane_sampling`, chosen as for the plane
by :func:`transient.plane.techniques`, with a single scan's laser point l
in the source's place and the read points in the sensors'):

- ``mis`` (default): single scans by the solid angle l sees the rectangle
  under where g_l varies more than 3-fold over it (a rectangle near the
  wall), and, when some read point's g_s would then leave a weight over
  :data:`MIS_PEAK_RATIO` x its mean, the read points' own techniques
  too, all weighted by the balance heuristic; confocal and exhaustive
  scans share no laser point and sample by area;
- ``source``: l's technique alone; ``area``: uniformly (kept to measure
  the others against);
- a plan of area sampling alone draws its points by the hidden texture,
  in proportion to the reflectance (:class:`transient.nlos_sampling.PixelDensity`);
- each technique's share of a replica is an Owen-scrambled Sobol set
  (``sampler = sobol``, the default, :func:`transient.nlos_sampling.owen_sobol_point`),
  jittered-stratified in Morton order (``stratified``) or ``independent``.

The kernel's lanes are samples: the per-sample work (random stream,
stratified point, texture, density) is done once and a loop over the scan
(:meth:`TransientNlosIntegrator._deposit_pairs`) adds each pair with two
distances' worth of arithmetic and one scatter-add.

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from analytic.attenuation import LAMBERTIAN
from analytic.binning import bin_index
from analytic.scenes.relay_wall import WALL_NORMAL, grid_points

from .chunks import ReplicaLayout, checked_chunk
from .common import attenuation_of_distances, block_copy, deposit, is_diffuse, is_impulse, jittered_point, opaque_f64, \
    opaque_u32, reduce_mode, replica_of, sample_stream, thread_copies, time_axis_and_waveform
from .nlos_sampling import PixelDensity, owen_sobol_point
from .plane import STRATEGIES, plane_frame, techniques
from .plane_sampling import AREA, block_bounds, mixture_density, peak_ratio, warp

__all__ = ["TransientNlosIntegrator", "PLUGIN_NAME", "SCAN_TYPES", "STRATEGIES", "SAMPLERS", "MIS_PEAK_RATIO"]

PLUGIN_NAME = "transient_opl_nlos"

SCAN_TYPES = ("single", "confocal", "exhaustive")

#: How each technique's share of a replica places its points in the unit square (module docstring).
SAMPLERS = ("sobol", "stratified", "independent")

#: A single scan mixes in techniques of its read points only when, with points drawn for l alone, some
#: read point's largest weight exceeds its mean by more than this factor; then every read point over the
#: plane's :data:`transient.plane.PEAK_RATIO_LIMIT` (16) gets one, as on the plane. Below it l's technique
#: alone does better: each technique's share is stratified on its own, which costs more than peaks of
#: up to ~100 do (measured in docs/renderer.md).
MIS_PEAK_RATIO = 256.0

#: Read points along a grid row that one iteration of the kernel's loop handles, unrolled (a divisor of the
#: grid's width): their positions become literal offsets from the first, and the loop's bookkeeping is shared.
UNROLLED_READS = 16

# Agreement demanded between the double-precision rectangle this plugin is given and the float32 copy
# Mitsuba built the shape from.
_FLOAT32_MATCH = 1e-6


class _Point(NamedTuple):
    """Each sample's hidden point: x, y in the hidden rectangle's frame, z above the wall (metres)."""

    x: object
    y: object
    z: object


class _WallPoints(NamedTuple):
    """Wall points as the kernel reads them.

    Attributes
    ----------
    point : tuple of 3
        (x, y, h) in the hidden rectangle's frame, metres (h > 0: the lit face sees them).
    leg : array
        Laser leg per unit intensity L = cos θ_l^las / |o_l - l|² (ρ_w / π)², 1/m², of the point lit.
    offset : array
        Path length the scan adds to a path through the point, metres (0 unless the legs are counted).
    """

    point: tuple
    leg: object
    offset: object


class _Grid(NamedTuple):
    """A W x H grid of wall points, point (column i, row j) = origin + i column + j row (hidden frame, metres)."""

    origin: tuple
    column: tuple
    row: tuple
    width: int


def _vector(props, name: str) -> np.ndarray:
    return np.array(props.get(name), dtype=np.float64).reshape(3)


def _plus(value, amount: float):
    """value + amount, the addition left out for 0 (a literal 0 is not folded away)."""
    return value if amount == 0.0 else value + amount


class _Lit(NamedTuple):
    """Each sample's leg to a lit wall point l: l's height h_l above the hidden plane (metres), |x - l|² (m²)
    and |x - l| (metres), as the attenuation formula and the path length read them."""

    height: object
    squared: object
    distance: object


def _lit(point: _Point, wall) -> _Lit:
    """The leg from each sample's point x to a wall point l = (x, y, h) in the hidden frame."""
    squared = dr.square(point.x - wall[0]) + dr.square(point.y - wall[1]) + dr.square(wall[2])
    return _Lit(wall[2], squared, dr.sqrt(squared))


class TransientNlosIntegrator(mi.SamplingIntegrator):
    r"""
    .. _integrator-transient_opl_nlos:

    Relay-wall path-length integrator (:monosp:`transient_opl_nlos`)
    ---------------------------------------------------------------

    .. pluginparameters::

     * - bins, start_opl, bin_width_opl, waveform and its properties
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
     * - strategy
       - |string|
       - ``mis`` (single scans: l's solid angle where it pays, strongly
         peaked read points' own, balance heuristic; others by area),
         ``source`` (l's alone) or ``area`` (Default: ``mis``).
     * - sampler
       - |string|
       - ``sobol`` (Owen-scrambled Sobol points), ``stratified`` (jittered,
         Morton order) or ``independent`` (Default: ``sobol``).

    Render with :meth:`render_chunk_per_unit_intensity` (or
    :func:`transient.render.render`), not ``mi.render``.
    """

    def __init__(self, props):
        super().__init__(props)
        self.bins, self.start_opl, self.bin_width_opl, self.waveform = time_axis_and_waveform(props, PLUGIN_NAME)
        if "hidden_to_world" not in props:
            raise ValueError(f"{PLUGIN_NAME}: hidden_to_world is required")
        self.hidden_matrix = np.array(props.get("hidden_to_world").matrix, dtype=np.float64).reshape(4, 4)
        try:
            self.corner, x_axis, y_axis, _, self.width, self.height = plane_frame(self.hidden_matrix)
        except ValueError:
            raise ValueError(f"{PLUGIN_NAME}: hidden_to_world must map the square to a rectangle") from None
        self.axes = (x_axis, y_axis, np.cross(x_axis, y_axis))      # the lit face's normal u x v / |u x v|
        self.wall_size = (float(props.get("wall_size_x")), float(props.get("wall_size_y")))
        self.wall_reflectance = float(props.get("wall_reflectance", 1.0))
        self.laser_position = _vector(props, "laser_position")
        self.sensor_position = _vector(props, "sensor_position")
        self.scan_type = str(props.get("scan_type", "single"))
        if self.scan_type not in SCAN_TYPES:
            raise ValueError(f"{PLUGIN_NAME}: scan_type must be one of {SCAN_TYPES}, got {self.scan_type!r}")
        self.strategy = str(props.get("strategy", "mis"))
        if self.strategy not in STRATEGIES:
            raise ValueError(f"{PLUGIN_NAME}: strategy must be one of {STRATEGIES}, got {self.strategy!r}")
        self.sampler = str(props.get("sampler", "sobol"))
        if self.sampler not in SAMPLERS:
            raise ValueError(f"{PLUGIN_NAME}: sampler must be one of {SAMPLERS}, got {self.sampler!r}")
        grid = (int(props.get("grid_width")), int(props.get("grid_height")))
        laser_point = _vector(props, "laser_point") if "laser_point" in props else np.zeros(3)
        laser_grid = (int(props.get("laser_grid_width", grid[0])), int(props.get("laser_grid_height", grid[1])))
        self.account = bool(props.get("account_first_and_last_bounces", False))
        self.read_points = grid_points(grid, self.wall_size)
        self.laser_points = {"single": laser_point[None, :], "confocal": self.read_points,
                             "exhaustive": grid_points(laser_grid, self.wall_size)}[self.scan_type]
        self._lasers = self._wall_points(self.laser_points, self.laser_position)
        reads = self._wall_points(self.read_points, self.sensor_position)
        if self.scan_type == "confocal":              # l = s: each read point's own leg, both offsets
            reads = reads._replace(leg=self._lasers.leg, offset=reads.offset + self._lasers.offset)
        # the kernel's read points: the grid, computed (_Grid); their legs (confocal) and offsets, gathered
        self._read_grid = self._grid_in_hidden_frame(grid)
        self._read_leg, self._read_offset = mi.Float64(reads.leg), mi.Float64(reads.offset)
        # per pair, in the pair order (the kernel computes them from the tables above): l, s, L_p, offsets
        if self.scan_type == "confocal":
            self.lit, self.read, self.leg, self.offsets = self.read_points, self.read_points, reads.leg, reads.offset
        else:
            lasers, count = len(self.laser_points), len(self.read_points)
            self.lit, self.read = np.repeat(self.laser_points, count, axis=0), np.tile(self.read_points, (lasers, 1))
            self.leg = np.repeat(self._lasers.leg, count)
            self.offsets = np.repeat(self._lasers.offset, count) + np.tile(reads.offset, lasers)
        self.plan = self._techniques()
        self._taps = self.waveform.bins_touched(self.bin_width_opl, self.bins)
        self._pixel_cache = (None, None)             # (texture values, their PixelDensity)

    def _wall_points(self, points: np.ndarray, origin: np.ndarray) -> _WallPoints:
        """Wall points in the hidden frame, the leg from the laser if lit from ``origin``, the offset to it."""
        toward = origin - points
        distance = np.linalg.norm(toward, axis=1)
        leg = (toward @ WALL_NORMAL) / distance**3 * (self.wall_reflectance / math.pi) ** 2
        offset = distance if self.account else np.zeros(len(points))
        return _WallPoints(tuple(np.ascontiguousarray(c) for c in self.to_hidden(points).T), leg, offset)

    def _grid_in_hidden_frame(self, grid) -> "_Grid":
        """The read grid's cell centres as origin + column · step + row · step in the hidden frame."""
        origin = self.to_hidden(grid_points(grid, self.wall_size)[0])
        # a step along the wall is a rotation of it in the hidden frame (no translation)
        column, row = (np.stack(self.axes) @ step for step in np.diag([self.wall_size[0] / grid[0],
                                                                          self.wall_size[1] / grid[1], 0.0])[:2])
        return _Grid(tuple(float(c) for c in origin), tuple(float(c) for c in column),
                     tuple(float(c) for c in row), int(grid[0]))

    def to_hidden(self, points) -> np.ndarray:
        """World points ``(..., 3)`` in the hidden frame: (x, y) along its edges from the corner, h along its normal."""
        offset = np.asarray(points, dtype=np.float64) - self.corner
        return np.stack([offset @ axis for axis in self.axes], axis=-1)

    def _techniques(self):
        """The sampling plan of :data:`STRATEGIES` (module docstring); confocal and exhaustive scans by area."""
        lit = self.to_hidden(self.laser_points[0])
        if self.strategy == "area" or self.scan_type != "single":
            return techniques(lit, np.zeros((0, 3)), self.width, self.height, "area")
        first = techniques(lit, np.zeros((0, 3)), self.width, self.height, "source")
        reads = self.to_hidden(self.read_points)
        if self.strategy == "source" or max(peak_ratio(first[0], tuple(read), self.width, self.height)
                                            for read in reads) <= MIS_PEAK_RATIO:
            return first
        return techniques(lit, reads, self.width, self.height, "mis")

    @property
    def pairs(self) -> int:
        """P, the (l, s) pairs: the rows of the transient."""
        return len(self.read_points) * (1 if self.scan_type == "confocal" else len(self.laser_points))

    def to_string(self):
        return (f"TransientNlosIntegrator[bins={self.bins}, start_opl={self.start_opl}, "
                f"bin_width_opl={self.bin_width_opl}, scan={self.scan_type!r}, pairs={self.pairs}, "
                f"strategy={self.strategy!r}, sampler={self.sampler!r}]")

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

        Notes
        -----
        One kernel launch: lanes are samples, each looping over every pair
        (:meth:`_deposit_pairs`); every value that changes between chunks
        reaches the kernel as an opaque value, so one compiled kernel
        serves every chunk of every render of the scene.
        """
        first, count = checked_chunk(layout, seed, first, count)
        hidden = self._hidden_shape(scene)
        size = layout.size
        first_replica = first // size
        rows = (first + count - 1) // size - first_replica + 1
        plan = self.plan
        bounds = block_bounds([t.share for t in plan], size)

        # -- per sample: index, random stream, replica, technique block, point, ρ_h / (π p)
        lane = dr.arange(mi.UInt32, count)                            # sample within the chunk
        index = mi.UInt64(lane) + dr.opaque(mi.UInt64, first)        # global sample index g
        rng = sample_stream(opaque_u32(seed), mi.UInt32(index), mi.UInt32(index >> 32))
        replica, in_replica = replica_of(mi.Float64(lane) + opaque_f64(first - first_replica * size),
                                         opaque_f64(size))
        technique, block_start, block_size = mi.UInt32(0), opaque_u32(0), opaque_u32(bounds[1] - bounds[0])
        for t in range(1, len(plan)):
            later = in_replica >= opaque_u32(bounds[t])
            technique = dr.select(later, mi.UInt32(t), technique)
            block_start = dr.select(later, opaque_u32(bounds[t]), block_start)
            block_size = dr.select(later, opaque_u32(bounds[t + 1] - bounds[t]), block_size)
        jitter_u, jitter_v = rng.next_float64(), rng.next_float64()
        if self.sampler == "sobol":
            # one scramble per (render seed, replica, technique): the replicas stay independent
            code = (replica + dr.opaque(mi.UInt32, first_replica)) * len(plan) + technique
            seed_u, seed_v = mi.sample_tea_32(opaque_u32(seed), code, 16)
            u, v = owen_sobol_point(in_replica - block_start, seed_u, seed_v, jitter_u, jitter_v)
        elif self.sampler == "stratified":
            u, v = jittered_point(in_replica - block_start, block_size, jitter_u, jitter_v)
        else:
            u, v = jitter_u, jitter_v
        pixels = self._pixel_density(hidden)
        if pixels is not None:                       # area alone: by the texture instead
            u, v, density = pixels.sample(u, v)
            x, y = u * self.width, v * self.height
        else:
            x, y = warp(plan, technique, u, v, self.width, self.height)
            shares = [opaque_f64((bounds[t + 1] - bounds[t]) / size) for t in range(len(plan))]
            # the balance heuristic: each point weighted by the density of all techniques together
            density = mixture_density(plan, shares, x, y, self.width, self.height)
        scale = self._reflectance(hidden, x / self.width, y / self.height) / density   # ρ_h's 1/π: in a_k
        height = float(self.corner[2]) + x * float(self.axes[0][2]) + y * float(self.axes[1][2])  # x's z

        # a copy of the histogram per LLVM thread (block_copy), summed here
        cells = layout.histogram_rows * self.pairs * self.bins
        copies = thread_copies(cells, size)
        histogram = dr.zeros(mi.Float64, copies * cells)
        row = block_copy(lane, count, copies) * opaque_u32(layout.histogram_rows) + replica
        self._deposit_pairs(histogram, row * opaque_u32(self.pairs), _Point(x, y, height), scale)
        dr.eval(histogram)
        sums = np.array(histogram, dtype=np.float64).reshape(copies, -1, self.pairs, self.bins)
        return (sums[0] if copies == 1 else sums.sum(axis=0))[:rows]

    def _deposit_pairs(self, histogram, row_base, point, scale):
        """Deposit every pair's path through each sample's point: a loop over the scan, per-pair work minimal.

        Parameters
        ----------
        histogram : mi.Float64
            ``(copies x rows, P, N)`` flat accumulator.
        row_base : mi.UInt32
            Each sample's row (its histogram copy's, then its replica's) times P.
        point : _Point
            Each sample's hidden point (hidden frame x, y; world z), metres.
        scale : mi.Float64
            ρ_h(x) / p(x), m² (the hidden surface's 1/π is the attenuation's).

        Notes
        -----
        Pair (l, s) adds L_p ρ_h / p a_k(x) cos θ_l cos θ_s at |x - l| +
        |x - s| (+ offsets): a_k is the model's Lambertian attenuation of
        docs/design.md section 2 (:func:`~transient.common.attenuation_of_distances`,
        from the heights h_l, h_s above the hidden plane and the squared
        distances), and each wall end's cosine n·(x - w) / |x - w| =
        z_x / |x - w| multiplies it (z_x: x's height above the wall), as in
        the model's relay-wall pairs. Single scans compute l's leg once per
        sample, exhaustive ones each laser point's once per laser in an
        outer loop; confocal ones read l = s. The read points are the grid's cell centres,
        an affine function of (column, row) in the hidden frame: computed,
        not gathered (a gather of the loop's index costs more than the
        arithmetic on the CPU).
        """
        grid, bins = self._read_grid, self.bins
        # LLVM: plain atomics, 1.1 to 1.8 x faster here than the per-thread copies of reduce_mode()'s Auto
        # and 1.5 x faster than Local (the deposits of one sample spread over P rows; docs/renderer.md).
        # CUDA: as reduce_mode().
        mode = reduce_mode() if dr.backend_v(mi.Float64) == dr.JitBackend.CUDA else dr.ReduceMode.Direct
        taps = self._taps
        impulse = is_impulse(self.waveform.terms)   # not taps == 1: a one-bin window caps every pulse at one tap
        # read points per loop iteration: the largest divisor of the grid's width up to UNROLLED_READS
        group = max(d for d in range(1, UNROLLED_READS + 1) if grid.width % d == 0)

        def deposit_reads(row, weight, lit, laser_offset):
            """Loop over the read points: one distance, one attenuation, one deposit each (``lit``: l's leg,
            None confocal)."""
            # s's cosine z_x / |x - s|: z_x once per sample (confocal: l's too)
            weight = weight * (dr.square(point.z) if lit is None else point.z)
            # the path's length less |x - s| (less 2 |x - s| confocal), shifted for the product below
            extra = laser_offset if self.account and laser_offset is not None else 0.0
            base = extra if lit is None else lit.distance + extra

            def body(b, column, line, slot):
                # a group of read points along a grid row, unrolled: each one's offset from the first is a literal
                first = [grid.origin[k] + column * grid.column[k] + line * grid.row[k] for k in range(3)]
                offsets = (point.x - first[0], point.y - first[1], first[2])
                for j in range(group):
                    dx, dy, height = (_plus(offsets[k], -j * grid.column[k] if k < 2 else j * grid.column[k])
                                      for k in range(3))
                    squared = dr.square(dx) + dr.square(dy) + dr.square(height)
                    distance = dr.sqrt(squared)
                    if lit is None:                  # confocal: l = s, both cosines z_x / |x - s|
                        attenuation = attenuation_of_distances(LAMBERTIAN, height, squared, height, squared)
                        weight_b = weight * dr.gather(mi.Float64, self._read_leg, b + j) * attenuation / squared
                        length = 2.0 * distance + base
                    else:
                        attenuation = attenuation_of_distances(LAMBERTIAN, lit.height, lit.squared, height, squared)
                        weight_b, length = weight * attenuation / distance, base + distance
                    if self.account:
                        length += dr.gather(mi.Float64, self._read_offset, b + j)
                    if impulse:                      # one bin (the impulse has no lead), the model's binning
                        position, inside = bin_index(length, self.start_opl, self.bin_width_opl, bins,
                                                     floor=dr.floor)
                        index = mi.UInt32(dr.select(inside, position, 0.0))
                        dr.scatter_reduce(dr.ReduceOp.Add, histogram, weight_b, slot + (index + j * bins),
                                          active=inside, mode=mode)
                    else:
                        deposit(histogram, row + b + j, weight_b, length, mi.Bool(True), bins=bins,
                                start_opl=self.start_opl, bin_width_opl=self.bin_width_opl,
                                terms=self.waveform.terms, taps=taps, mode=mode)
                column += float(group)
                wrap = column == float(grid.width)
                return (b + group, dr.select(wrap, 0.0, column), dr.select(wrap, line + 1.0, line),
                        slot + group * bins)

            dr.while_loop((mi.UInt32(0), mi.Float64(0.0), mi.Float64(0.0), row * bins),
                          lambda b, column, line, slot: b < opaque_u32(len(self.read_points)), body,
                          label="nlos_reads")

        if self.scan_type == "confocal":
            deposit_reads(row_base, scale, None, None)
            return
        lasers = self._lasers
        if len(lasers.leg) == 1:                      # single: l's leg once per sample
            lit = _lit(point, [float(c[0]) for c in lasers.point])
            deposit_reads(row_base, scale * float(lasers.leg[0]) * point.z / lit.distance, lit,
                          float(lasers.offset[0]))
            return
        tables = [mi.Float64(table) for table in (*lasers.point, lasers.leg, lasers.offset)]

        def body(a):
            lit_x, lit_y, lit_h, leg, offset = (dr.gather(mi.Float64, table, a) for table in tables)
            lit = _lit(point, (lit_x, lit_y, lit_h))
            deposit_reads(row_base + a * opaque_u32(len(self.read_points)), scale * leg * point.z / lit.distance, lit,
                          offset)
            return (a + 1,)

        dr.while_loop((mi.UInt32(0),), lambda a: a < opaque_u32(len(lasers.leg)), body, label="nlos_lasers")

    def _pixel_density(self, hidden):
        """The texture's :class:`PixelDensity` when the plan is area sampling alone and ρ is a bitmap, else None."""
        if len(self.plan) != 1 or self.plan[0].kind != AREA:
            return None
        parameters = mi.traverse(hidden.bsdf())
        if "reflectance.data" not in parameters or len(parameters["reflectance.data"].shape) != 3:
            return None                              # a constant reflectance: area sampling is the density
        # texel (row j, column i) covers v in [j / H, (j + 1) / H), u in [i / W, (i + 1) / W) (the texture's values
        # as stored: any positive density is unbiased, these make it efficient)
        data = np.array(parameters["reflectance.data"], dtype=np.float64)[..., 0]
        values, density = self._pixel_cache
        if values is None or not np.array_equal(values, data):     # built once per texture
            density = PixelDensity(data, self.width * self.height)
            self._pixel_cache = (data, density)
        return density

    def _reflectance(self, hidden, u, v):
        """ρ_h at (u, v) of the hidden rectangle's texture (float32 as Mitsuba stores it), Float64."""
        interaction = dr.zeros(mi.SurfaceInteraction3f)
        interaction.uv = mi.Point2f(mi.Float(u), mi.Float(v))
        interaction.n = mi.Normal3f(0.0, 0.0, 1.0)
        interaction.sh_frame = mi.Frame3f(interaction.n)
        interaction.wi = mi.Vector3f(0.0, 0.0, 1.0)
        return mi.Float64(hidden.bsdf().eval_diffuse_reflectance(interaction)[0])


mi.register_integrator(PLUGIN_NAME, lambda props: TransientNlosIntegrator(props))
