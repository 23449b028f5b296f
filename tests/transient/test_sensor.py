"""The omni_point sensor."""

from __future__ import annotations


import numpy as np
import pytest



def test_omni_point_sensor(mitsuba):
    import drjit as dr

    film = {"type": "hdrfilm", "width": 1, "height": 1, "pixel_format": "luminance"}
    sensor = mitsuba.load_dict({"type": "omni_point", "position": [0.2, 0.7, 400.3], "film": film})
    # Double precision survives: float32 would give 400.29998779296875.
    assert sensor.position.tolist() == [0.2, 0.7, 400.3]
    moved = mitsuba.load_dict({"type": "omni_point", "film": film,
                               "to_world": mitsuba.ScalarTransform4d().translate([0.1, 0.2, 0.3])})
    np.testing.assert_array_equal(moved.position, [0.1, 0.2, 0.3])
    with pytest.raises(RuntimeError, match="not both"):
        mitsuba.load_dict({"type": "omni_point", "position": [0, 0, 1], "film": film,
                           "to_world": mitsuba.ScalarTransform4d()})
    it = dr.zeros(mitsuba.Interaction3f)
    it.p = mitsuba.Point3f(0.2, 0.7, 398.3)
    record, weight = sensor.sample_direction(it, mitsuba.Point2f(0.5, 0.5))
    assert float(record.dist[0]) == pytest.approx(2.0, rel=1e-6)
    assert float(weight[0][0]) == pytest.approx(0.25, rel=1e-6)       # 1/d², no 1/4 factor
    ray, ray_weight = sensor.sample_ray(0.0, 0.5, mitsuba.Point2f(0.3, 0.8), mitsuba.Point2f(0.5, 0.5))
    assert float(ray_weight[0][0]) == pytest.approx(4 * np.pi)        # ∫ dω over the sphere
    assert abs(float(dr.norm(ray.d)[0]) - 1.0) < 1e-6
