"""Conventions: what a renderer's sensor reads against the model, stated or recognised in a fitted scale and offset.

A :class:`Convention` states that data read scale · y_model(start_opl +
offset_opl) (``check --expect``): :func:`irradiancemeter` derives it for
mitransient's irradiancemeter spheres; :func:`convention` makes one from
its name (:data:`CONVENTIONS`, ``check --expect``'s names, also taken by
``validation.check_transient`` and ``validation.assert_agrees``).
:func:`diagnose` names the known
conventions (:data:`KNOWN_SCALES`, whole-bin offsets, short or long path
lengths) that explain a fitted scale and offset.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

import numpy as np

from analytic.errors import OptionError
from analytic.scenes.common import Scene
# Mitsuba's ``math::RayEpsilon`` in single-precision variants (1500 x 2⁻²⁴ m): an irradiancemeter starts its
# rays this far off its sphere (mitransient runs float32 variants). One definition, the renderer's.
from transient.constants import RAY_EPSILON as RAY_EPSILON_FLOAT32

from .fit import Fit

__all__ = ["Convention", "irradiancemeter", "transient_nlos_path", "convention", "check_expect", "diagnose", "CONVENTIONS", "KNOWN_SCALES",
           "RAY_EPSILON_FLOAT32"]

#: The conventions stated by name (``check --expect NAME``, ``expect="NAME"``).
CONVENTIONS = ("irradiancemeter", "transient_nlos_path")

#: The scene kind each named convention describes, and why it describes no other.
_CONVENTION_KINDS = {
    "irradiancemeter": ("plane", "states mitransient's irradiancemeter spheres of a plane scene; a relay-wall "
                                 "scene's nlos_capture_meter reads the model's own units (judge it as given, or "
                                 "state transient_nlos_path or a scale and offset)"),
    "transient_nlos_path": ("relay_wall", "states mitransient's NLOS integrator, for a relay-wall scene; a plane "
                                          "scene's mitransient renders are irradiancemeter"),
}

# Relative accuracy of the model (the system matrix's default tolerance): a
# fitted scale within it of 1, or an offset within it of a bin of 0, is none.
_RESOLUTION = 1e-6

#: Scale factors (data / model) that a known convention explains.
KNOWN_SCALES = (
    (1.0, "reads the fluence, as the model"),
    (0.25, "reads 1/4 of the fluence (the mean irradiance over a sphere)"),
    (4.0, "reads 4 times the fluence"),
    (1.0 / math.pi, "reads 1/π of the fluence (an extra 1/π: BRDF or sensor normalisation)"),
    (math.pi, "reads π times the fluence (a missing 1/π: BRDF or sensor normalisation)"),
    (0.25 / math.pi, "reads radiance averaged over directions (fluence / 4π)"),
    (4.0 * math.pi, "reads 4π times the fluence"),
)


@dataclass(frozen=True)
class Convention:
    """What the data are stated to read: scale · y_model(start_opl + offset_opl) (+ added).

    Attributes
    ----------
    scale : float
        Data / model, dimensionless (as :attr:`Fit.scale`).
    offset_opl : float
        Metres of path length added to the model's start_opl before the
        comparison: positive when the data read path lengths short (as
        :attr:`Fit.offset_opl`).
    name : str
        What states it, for reports.
    added : numpy.ndarray or None
        ``(K, N)`` a stated difference added to the scaled, shifted model
        (units of y), derived without reference to the data (e.g.
        :func:`transient_nlos_path`); None for none.
    """

    scale: float
    offset_opl: float
    name: str
    added: np.ndarray | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        for key, value in (("scale", self.scale), ("offset_opl", self.offset_opl)):
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise OptionError(f"{key}: the stated {key} must be a number, got {value!r}")
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise OptionError(f"scale: the stated scale must be a finite number > 0, got {self.scale!r}")
        if not math.isfinite(self.offset_opl):
            raise OptionError(f"offset_opl: the stated offset must be a finite number of metres, got "
                              f"{self.offset_opl!r}")

    def as_dict(self) -> dict:
        stated = {"name": self.name, "scale": self.scale, "offset_opl": self.offset_opl}
        if self.added is not None:
            stated["added_l2"] = float(np.linalg.norm(self.added))     # ||added||, units of y
        return stated


def irradiancemeter(scene: Scene, radius: float, *, ray_epsilon: float = RAY_EPSILON_FLOAT32) -> Convention:
    """What mitransient's irradiancemeter spheres read, against the model's point sensors.

    Parameters
    ----------
    scene : Scene
        The scene; each sensor is a sphere of ``radius`` centred on its
        position (``diffuse-imaging export --format mitransient``).
    radius : float
        Sphere radius r, metres: 0 < r < every sensor's height, so that no
        sphere reaches the plane (the export's bound).
    ray_epsilon : float
        Metres the meter moves each ray's origin off the sphere: Mitsuba's
        ``math::RayEpsilon``, :data:`RAY_EPSILON_FLOAT32` in the
        single-precision variants mitransient runs (1500 x 2⁻⁵³ m, i.e.
        negligible, in double ones).

    Returns
    -------
    Convention
        scale 1/4, offset_opl 2r/3 + ε.

    Raises
    ------
    OptionError
        A radius outside (0, lowest sensor height), or a negative ``ray_epsilon``.

    Notes
    -----
    Mitsuba's ``irradiancemeter`` (``src/sensors/irradiancemeter.cpp``)
    starts each ray at a uniform point of its sphere, in a cosine-weighted
    direction about the outward normal, with weight π, from the point moved
    ε along the ray, and mitransient's ``transient_path`` bins the path
    length from that origin. It reads the irradiance averaged over the
    sphere, Ē = P / (4π r²), P the power the sphere intercepts.

    *Scale: exactly 1/4, with no finite-sphere correction.* A Lambertian
    element dA of the plane, of radiance B/π, sends the sphere
    P = (B/π) dA Ω⊥, Ω⊥ the sphere's solid angle projected on dA's plane.
    By Nusselt's analogue Ω⊥ is the area of the orthographic projection,
    onto dA's plane, of the cap the sphere's cone cuts from the unit
    hemisphere: a circle of radius sin α = r/d tilted by θ, which projects
    to an ellipse of area π (r/d)² cos θ, exactly, whenever the whole cap
    lies above dA's horizon (the sphere above the plane). d is the distance
    from dA to the centre and θ the angle between the plane's normal and
    the centre's direction. The same element adds (B/π) dA cos θ / d² to
    the fluence rate Φ at the centre, which the model's point sensor reads,
    so every element, hence every bin of every sensor, gives Ē = Φ / 4,
    whatever r/d. (Light from an isotropic point source would give
    Ē / Φ = 1 / (2 (1 + sqrt(1 - (r/d)²))) = (1/4)(1 + (r/d)²/4 + ...):
    the Lambertian element's cosine is what removes the correction.)

    *Offset: 2r/3 + ε.* The light from dA that the sphere intercepts fills
    its cone with an intensity that varies across it only at first order in
    r/d, and oddly; to first order it crosses the plane through the centre
    perpendicular to the cone's axis uniformly within the disc of radius r,
    at distance b from the axis, after meeting the sphere sqrt(r² - b²)
    before that plane: path lengths short by 2r/3 on average, plus ε where
    the meter's rays start, for every element, sensor and bin.

    Neglected: O(r²/d) in the offset, the spread of the shortfall
    (standard deviation r/sqrt(18)) within a bin of width T, a relative
    O((r/T)²) effect, and the sphere's own shadow on the plane, O(r²)
    relative: ~1e-6 of y for r = 1 mm, d ~ 1 m, T ~ 0.05 m.
    """
    lowest = float(np.min(scene.sensors[:, 2]))
    if isinstance(radius, bool) or not isinstance(radius, numbers.Real) or not (
            math.isfinite(radius) and 0.0 < radius < lowest):
        raise OptionError(f"radius: must lie in (0, {lowest:g}) m, below the lowest sensor's height (the spheres "
                          f"must not reach the plane), got {radius!r}")
    radius = float(radius)
    if isinstance(ray_epsilon, bool) or not isinstance(ray_epsilon, numbers.Real) or not (
            math.isfinite(ray_epsilon) and ray_epsilon >= 0):
        raise OptionError(f"ray_epsilon: must be a finite number of metres >= 0, got {ray_epsilon!r}")
    return Convention(scale=0.25, offset_opl=2.0 * radius / 3.0 + float(ray_epsilon),
                      name=f"irradiancemeter spheres of radius {radius:g} m")


def check_expect(expect, scene, radius, words) -> None:
    """Refuse, before any work, a stated convention that does not exist or does not apply to ``scene``.

    Parameters
    ----------
    expect : str, Convention or None
        A name of :data:`CONVENTIONS`, a :class:`Convention`, or None.
    scene : Scene or RelayWallScene
        The scene judged.
    radius : float or None
        The irradiancemeter spheres' radius (``irradiancemeter`` only).
    words : validation.check.inputs.Words
        The caller's names of the options, for messages.

    Raises
    ------
    OptionError
        An unknown name, a convention for the other kind of scene, a radius
        without ``irradiancemeter``.
    """
    if radius is not None and expect != "irradiancemeter":
        raise OptionError(f"{words.radius}: applies to {words.expect} irradiancemeter only")
    if expect is None or isinstance(expect, Convention):
        return
    if not isinstance(expect, str) or expect not in CONVENTIONS:
        raise OptionError(f"{words.expect}: {expect!r} is no convention; give one of {', '.join(CONVENTIONS)} or a "
                          f"Convention(scale, offset_opl, name)")
    kind, why = _CONVENTION_KINDS[expect]
    if scene.kind != kind:
        raise OptionError(f"{words.expect} {expect}: {why}")
    if expect == "transient_nlos_path":
        if scene.illumination.waveform != "impulse":
            raise OptionError(f"{words.expect} transient_nlos_path: mitransient renders the impulse response only; "
                              f"give the scene with waveform = \"impulse\"")


def transient_nlos_path(scene, *, model: np.ndarray | None = None) -> Convention:
    """The convention ``check --expect transient_nlos_path`` states: the model plus mitransient's ray offsets.

    Parameters
    ----------
    scene : RelayWallScene
        The capture exported with ``export --format mitransient`` (its scene at the origin).
    model : numpy.ndarray, optional
        ``forward(scene)`` if already computed.

    Returns
    -------
    Convention
        Scale 1, offset 0, and ``added`` = :func:`interop.mitransient.nlos.offset_model` minus the model:
        derived, no fitted parameter.
    """
    from analytic.operator.matrix_free import forward
    from interop.mitransient.nlos import offset_model

    model = forward(scene) if model is None else model
    return Convention(scale=1.0, offset_opl=0.0, added=offset_model(scene) - model,
                      name="mitransient's transient_nlos_path: the model read from s + (1 + max|s_i|) RayEpsilon n, "
                           "less the strip its sampling misses")


def convention(expect, scene, radius, words, *, model=None) -> Convention | None:
    """The :class:`Convention` that ``expect`` states for ``scene`` (checked by :func:`check_expect`).

    ``"irradiancemeter"``: :func:`irradiancemeter` with ``radius`` (default
    the export's, :data:`interop.mitransient.export.RADIUS`); ``"transient_nlos_path"``:
    :func:`transient_nlos_path` (``model``: the scene's, if
    computed); a Convention as itself; None for None.
    """
    check_expect(expect, scene, radius, words)
    if expect is None or isinstance(expect, Convention):
        return expect
    if expect == "transient_nlos_path":
        return transient_nlos_path(scene, model=model)
    from interop.mitransient.export import RADIUS

    try:
        return irradiancemeter(scene, RADIUS if radius is None else radius)
    except OptionError as error:
        raise OptionError(f"{words.radius}{str(error).removeprefix('radius')}") from None


def _plus_minus(value: float, error: float, unit: str = "") -> str:
    """'+1.55e-4 ± 0.10e-4 m': value and error to the error's precision, one exponent."""
    if value == 0 and error == 0:
        return f"+0 ± 0{unit}"
    magnitude = max(abs(value), error)
    exponent = int(math.floor(math.log10(magnitude)))
    if -2 <= exponent <= 2:
        exponent = 0
    factor = 10.0**exponent
    if error > 0:
        # One significant digit of the error, two when it starts with 1 or 2.
        leading = int(math.floor(math.log10(error / factor)))
        digits = 2 if error / factor / 10.0**leading < 3 else 1
        decimals = max(0, digits - 1 - leading)
    else:
        decimals = 4
    suffix = f"e{exponent}" if exponent else ""
    return f"{value / factor:+.{decimals}f}{suffix} ± {error / factor:.{decimals}f}{suffix}{unit}"


def diagnose(fit: Fit, *, agrees: bool, agrees_after_fit: bool, bin_width_opl: float,
             stating: str = "--expect irradiancemeter") -> str:
    """One sentence naming the conventions that explain the fitted scale and offset.

    Parameters
    ----------
    fit : Fit
        The fitted scale and offset.
    agrees, agrees_after_fit : bool
        Verdicts as given and after the fit.
    bin_width_opl : float
        T, metres: an offset of whole bins is named as such.
    stating : str
        How the caller states the irradiancemeter's convention, for the hint.
    """
    scale_text = f"scale {_plus_minus(fit.scale, fit.scale_stderr)}".replace("scale +", "scale ")
    offset_text = f"offset {_plus_minus(fit.offset_opl, fit.offset_stderr, ' m')}"
    if agrees:
        return f"agrees as given ({scale_text}, {offset_text})."
    if not agrees_after_fit:
        return (f"disagrees even after the best {scale_text} and {offset_text}: not a scale or "
                f"time-offset convention (a different model, scene or a bug?).")
    margin = max(3 * fit.scale_stderr, 0.01 * abs(fit.scale))
    factor, meaning = min(KNOWN_SCALES, key=lambda item: abs(math.log(abs(fit.scale) / item[0])))
    parts = []
    # Differences under the model's own accuracy (_RESOLUTION) are no convention.
    if abs(fit.scale - factor) <= margin and factor != 1.0:
        parts.append(f"a sensor that {meaning}")
    elif abs(fit.scale - 1.0) > max(3 * fit.scale_stderr, _RESOLUTION):
        parts.append(f"y scaled by {fit.scale:.4g} (units or source intensity?)")
    shifted = abs(fit.offset_opl) > max(3 * fit.offset_stderr, _RESOLUTION * bin_width_opl)
    bins = fit.offset_opl / bin_width_opl
    if shifted and round(bins) != 0 and abs(bins - round(bins)) * bin_width_opl <= max(
            3 * fit.offset_stderr, 0.01 * bin_width_opl):
        parts.append(f"a time axis off by {round(bins):+d} bin(s) (another start_opl convention?)")
    elif shifted and fit.offset_opl > 0:
        parts.append("path lengths short (paths that start on a sphere's surface, not its centre?)")
    elif shifted:
        parts.append("path lengths long (an extra leg or a late start?)")
    explanation = " and ".join(parts) if parts else "within its errors of the model"
    if factor == 0.25 and parts and parts[0].startswith("a sensor") and shifted and fit.offset_opl > 0:
        explanation = ("a sensor that reads 1/4 of the fluence and path lengths short (an irradiancemeter? "
                       f"{stating} states that convention)")
    return f"agrees after {scale_text} and {offset_text}: {explanation}."

