"""The ``omni_point`` sensor: ∫ L dω over the whole sphere at one exact point.

Mitsuba's own ``irradiancemeter`` is the child of a shape: it measures
irradiance averaged over the shape's surface (for a small sphere a quarter of
the fluence rate) and starts its rays on that surface, so path lengths come
out short by up to the sphere's radius. The paper's sensor is a point that
integrates incident radiance over all directions, no cosine; this plugin is
exactly that, with its position kept in float64 so that path lengths of
hundreds of metres stay exact to the nanometre.

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

__all__ = ["OmniPointSensor", "PLUGIN_NAME"]

PLUGIN_NAME = "omni_point"


def _position(props) -> np.ndarray:
    """Sensor position (x, y, z) in metres, float64, from ``position`` or ``to_world``."""
    has_position = "position" in props
    has_transform = "to_world" in props
    if has_position and has_transform:
        raise ValueError("omni_point: give either 'position' or 'to_world', not both")
    if has_position:
        # A list property arrives as Array3f64: double precision end to end.
        return np.array(props.get("position"), dtype=np.float64).reshape(3)
    transform = props.get("to_world", mi.ScalarTransform4d())
    return np.array(transform @ mi.ScalarPoint3d(0.0, 0.0, 0.0), dtype=np.float64).reshape(3)


class OmniPointSensor(mi.Sensor):
    r"""
    .. _sensor-omni_point:

    Omnidirectional point sensor (:monosp:`omni_point`)
    ----------------------------------------------------

    .. pluginparameters::

     * - position
       - |point|
       - Sensor position in metres, read in double precision. Exclusive
         with ``to_world``. (Default: origin)
     * - to_world
       - |transform|
       - Alternative to ``position``: the sensor sits at ``to_world``
         applied to the origin (double precision).
     * - film, sampler
       - |film|, |sampler|
       - As for every Mitsuba sensor; a 1 x 1 ``luminance`` film avoids
         allocating the default 768 x 576 one. The transient renderer
         never develops it.

    Measures the fluence rate φ = ∫_{S²} L(p, ω) dω at the point p:
    importance 1 for every direction, no cosine, and no ray-epsilon
    offset (rays and path lengths start exactly at p).
    """

    def __init__(self, props):
        position = _position(props)
        super().__init__(props)
        self.position = position
        self.position.setflags(write=False)

    def _origin(self):
        return mi.Point3f(*map(float, self.position))

    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        # Uniform sphere: pdf 1/(4π) per steradian, importance 1 -> weight 4π.
        direction = mi.warp.square_to_uniform_sphere(sample2)
        return mi.Ray3f(self._origin(), direction, time), mi.Spectrum(4.0 * dr.pi)

    def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
        ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
        return mi.RayDifferential3f(ray), weight

    def sample_direction(self, it, sample, active=True):
        # Delta position: the only "direction sample" is the point itself;
        # importance 1 per steradian seen from it becomes 1/d² per unit area.
        record = dr.zeros(mi.DirectionSample3f)
        record.p = self._origin()
        record.d = record.p - it.p
        record.dist = dr.norm(record.d)
        record.d = record.d / record.dist
        record.pdf = mi.Float(1.0)
        record.delta = mi.Bool(True)
        record.n = -record.d
        return record, mi.Spectrum(dr.rcp(dr.square(record.dist)))

    def pdf_direction(self, it, ds, active=True):
        return mi.Float(0.0)

    def eval(self, si, active=True):
        # A point cannot be hit by a ray.
        return mi.Spectrum(0.0)

    def bbox(self):
        return mi.ScalarBoundingBox3f(mi.ScalarPoint3f(*map(float, self.position)))

    def to_string(self):
        return f"OmniPointSensor[position={self.position.tolist()}]"


mi.register_sensor(PLUGIN_NAME, lambda props: OmniPointSensor(props))
