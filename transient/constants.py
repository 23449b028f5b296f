"""Constants of the renderer that code outside Mitsuba needs: importing this module imports no Mitsuba or Dr.Jit."""

__all__ = ["RAY_EPSILON"]

#: Mitsuba's ``math::RayEpsilon`` for single-precision variants
#: (``Epsilon<float> * 1500``, Epsilon = 2^-24): the irradiancemeter starts
#: its rays this far off its shape. mitransient runs on float32 variants.
RAY_EPSILON = 1500 * 2.0**-24
