"""The ``transient_opl_path`` integrator: diffuse scenes with several bounces, binned by path length.

Any shapes with ``diffuse`` BSDFs, point and area emitters, ``omni_point``
sensors, up to ``max_depth`` surface bounces between emitter and sensor,
with visibility. Each sample draws a first vertex x1 on the scene's
surfaces by area and connects it to every sensor (a shadow ray and
cos θ_k / d_k²); from x1 the path continues by cosine-weighted BSDF
sampling, and at every vertex x_j (j <= max_depth) next-event estimation to
an emitter closes a path

    sensor <- x1 <- x2 <- ... <- x_j <- light,

whose optical length is binned with the illumination's kernel. Emission at
x1 itself closes the zero-bounce path sensor <- x1 (area emitters seen by
the sensor). Emission hit by a BSDF-sampled ray is not counted: next-event
estimation alone already samples each such path once.

A diffuse BSDF's value does not depend on the incident direction beyond its
hemisphere, so the path from x1 onward serves every sensor on x1's front
side; sensors behind it receive nothing from x1 (Mitsuba's ``diffuse`` is
one-sided).

Path lengths come from float32 ray tracing: each segment carries a relative
error of a few 2^-24 and each vertex an absolute one of about 2^-24 times
the scene's extent, so a path of total length ℓ through a scene of extent E
with j bounces is off by at most about :func:`path_length_error` (ℓ + j E)
x 2^-21 metres (1e-6 m for ℓ = 5 m, E = 1 m, j = 3). Bins should be far wider.

Samples are independent (one PCG32 stream per sample); the standard error
comes from the render's replicas like the plane estimator's.

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .chunks import ReplicaLayout, checked_chunk
from .common import (deposit, is_diffuse, opaque_f64, opaque_u32, reduce_mode, replica_of, sample_stream,
                     time_axis_and_waveform)

__all__ = ["TransientPathIntegrator", "PLUGIN_NAME", "path_length_error"]

PLUGIN_NAME = "transient_opl_path"

#: Relative rounding of float32 ray tracing per segment and per vertex
#: coordinate, with room: 8 ulps at 2^-24.
FLOAT32_PATH_ERROR = 2.0**-21


def path_length_error(length: float, extent: float, bounces: int) -> float:
    """Bound on the float32 error of a path's optical length, metres.

    Parameters
    ----------
    length : float
        The path's optical length ℓ, metres.
    extent : float
        Largest coordinate magnitude in the scene E, metres.
    bounces : int
        Surface vertices j on the path.

    Returns
    -------
    float
        (ℓ + j E) 2^-21: each segment's length is rounded relative to itself,
        each vertex's position relative to the scene's coordinates.
    """
    return (float(length) + int(bounces) * float(extent)) * FLOAT32_PATH_ERROR


class TransientPathIntegrator(mi.SamplingIntegrator):
    r"""
    .. _integrator-transient_opl_path:

    Multi-bounce path-length integrator (:monosp:`transient_opl_path`)
    ------------------------------------------------------------------

    .. pluginparameters::

     * - bins
       - |int|
       - Number of time bins N. (Required)
     * - start_opl
       - |float|
       - Lower edge t0 of bin 0, metres of optical path length. (Default: 0)
     * - bin_width_opl
       - |float|
       - Bin width T, metres of optical path length. (Required)
     * - waveform and its properties
       - 
       - The illumination, as for :monosp:`transient_opl`.
     * - max_depth
       - |int|
       - Most surface bounces between emitter and sensor (Default: 1).

    Shapes need ``diffuse`` BSDFs; emitters are ``point`` or ``area``;
    sensors ``omni_point``. Render with :meth:`render_chunk`.
    """

    def __init__(self, props):
        super().__init__(props)
        self.bins, self.start_opl, self.bin_width_opl, self.waveform = time_axis_and_waveform(
            props, "transient_opl_path")
        self.max_depth = int(props.get("max_depth", 1))
        if self.max_depth < 1:
            raise ValueError(f"transient_opl_path: max_depth must be >= 1, got {self.max_depth}")

    def to_string(self):
        return (f"TransientPathIntegrator[bins={self.bins}, start_opl={self.start_opl}, "
                f"bin_width_opl={self.bin_width_opl}, waveform={self.waveform.description!r}, "
                f"max_depth={self.max_depth}]")

    def _check_scene(self, scene) -> np.ndarray:
        """Sensor positions (float64), after refusing what this estimator does not model."""
        if not scene.emitters():
            raise ValueError("transient_opl_path: the scene has no emitter")
        for shape in scene.shapes():
            if not is_diffuse(shape.bsdf()):
                raise ValueError(f"transient_opl_path: shape {shape.id()!r} needs a 'diffuse' BSDF")
        for emitter in scene.emitters():
            if not (mi.has_flag(emitter.flags(), mi.EmitterFlags.DeltaPosition)
                    or mi.has_flag(emitter.flags(), mi.EmitterFlags.Surface)):
                raise ValueError("transient_opl_path: only point and area emitters are supported")
        sensors = scene.sensors()
        if not sensors or not all(hasattr(sensor, "position") for sensor in sensors):
            raise ValueError("transient_opl_path: every sensor must be an 'omni_point' sensor")
        return np.array([sensor.position for sensor in sensors], dtype=np.float64)

    def render_chunk(self, scene, *, seed: int, layout: ReplicaLayout, first: int, count: int) -> np.ndarray:
        """Per-replica sums Σc over samples [first, first + count) of a render.

        Same contract as :meth:`transient.plane.TransientPlaneIntegrator.render_chunk`:
        returns ``(replicas touched, K, N)`` float64, each replica's Σ c over
        the chunk's samples, c_k[n] one sample's contribution to y_k[n].
        """
        first, count = checked_chunk(layout, seed, first, count)
        sensors = self._check_scene(scene)
        size = layout.size
        first_replica = first // size
        rows = (first + count - 1) // size - first_replica + 1
        K, N = len(sensors), self.bins
        F64 = mi.Float64
        context = mi.BSDFContext()

        lane = dr.arange(mi.UInt32, count)
        index = mi.UInt64(lane) + dr.opaque(mi.UInt64, first)
        rng = sample_stream(opaque_u32(seed), mi.UInt32(index), mi.UInt32(index >> 32))
        replica, _ = replica_of(mi.Float64(lane) + opaque_f64(first - first_replica * size), opaque_f64(size))

        # x1: a shape with probability ∝ area, then a uniform point on it.
        shapes = scene.shapes_dr()
        areas = np.array(shapes.surface_area(), dtype=np.float64).ravel()
        chooser = mi.DiscreteDistribution(mi.Float(areas.astype(np.float32)))
        chosen, _ = chooser.sample_reuse(rng.next_float32())
        shape = dr.gather(mi.ShapePtr, shapes, chosen)
        position = shape.sample_position(0.0, mi.Point2f(rng.next_float32(), rng.next_float32()))
        density = F64(position.pdf * chooser.eval_pmf_normalized(chosen))      # per m² of surface
        first_vertex = mi.SurfaceInteraction3f(position, dr.zeros(mi.Color0f))
        first_vertex.shape = shape
        first_vertex.sh_frame = mi.Frame3f(first_vertex.n)
        first_vertex.wi = mi.Vector3f(0.0, 0.0, 1.0)       # any front-side direction: diffuse
        alive = density > 0.0
        origin = mi.Point3d(first_vertex.p)

        # Sensor connections at x1: cos θ_k / (d_k² p(x1)) with the shadow ray, and d_k.
        geometry, sensor_lengths = [], []
        for k in range(K):
            target = mi.Point3d(*map(float, sensors[k]))
            to_sensor = target - origin
            distance = dr.norm(to_sensor)
            cosine = dr.dot(to_sensor, mi.Vector3d(first_vertex.n)) / distance
            visible = ~scene.ray_test(first_vertex.spawn_ray_to(mi.Point3f(target)), alive)
            geometry.append(dr.select(visible & alive & (cosine > 0.0), cosine / (dr.square(distance) * density),
                                      F64(0.0)))
            sensor_lengths.append(distance)

        histogram = dr.zeros(mi.Float64, layout.histogram_rows * K * N)
        settings = dict(bins=N, start_opl=self.start_opl, bin_width_opl=self.bin_width_opl,
                        terms=self.waveform.terms, taps=self.waveform.bins_touched(self.bin_width_opl, self.bins),
                        mode=reduce_mode())

        def close(value, length, active):
            """Deposit a path closed at the current vertex, for every sensor."""
            for k in range(K):
                deposit(histogram, replica * K + k, geometry[k] * value, sensor_lengths[k] + length,
                        active, **settings)

        # Zero bounces: radiance x1 emits toward the sensors (its emitter, if any).
        emitter = shape.emitter()
        emitted = F64(emitter.eval(first_vertex, alive)[0])
        close(emitted, F64(0.0), alive & (emitted > 0.0))

        # --------------------------- loop state ---------------------------
        vertex = first_vertex          # x_j, the current surface vertex
        bsdf = first_vertex.bsdf()     # its BSDF
        throughput = F64(1.0)          # Π f cos / p over the bounces x1 -> x_j
        travelled = F64(0.0)           # optical length from x1 to x_j, metres
        for depth in range(1, self.max_depth + 1):
            # Next-event estimation at x_j (Mitsuba tests visibility).
            light, light_weight = scene.sample_emitter_direction(
                vertex, mi.Point2f(rng.next_float32(), rng.next_float32()), True, alive)
            value = F64(bsdf.eval(context, vertex, vertex.to_local(light.d), alive)[0]) * F64(light_weight[0])
            close(throughput * value, travelled + F64(light.dist), alive & (light.pdf > 0.0))
            if depth == self.max_depth:
                break
            # Continue by cosine-weighted BSDF sampling.
            bounce, bounce_weight = bsdf.sample(context, vertex, rng.next_float32(),
                                                mi.Point2f(rng.next_float32(), rng.next_float32()), alive)
            ray = vertex.spawn_ray(vertex.to_world(bounce.wo))
            following = scene.ray_intersect(ray, alive & (bounce.pdf > 0.0))
            alive = alive & (bounce.pdf > 0.0) & following.is_valid()
            throughput = throughput * F64(bounce_weight[0])
            travelled = travelled + F64(following.t)
            vertex, bsdf = following, following.bsdf()
        dr.eval(histogram)
        return np.array(histogram, dtype=np.float64).reshape(-1, K, N)[:rows]


mi.register_integrator(PLUGIN_NAME, lambda props: TransientPathIntegrator(props))
