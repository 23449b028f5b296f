"""Derivatives of the model's samples y with respect to the scene's parameters (docs/design.md section 9).

:func:`jacobian` returns ∂y/∂θ for parameters named by scene-file keys
(:mod:`.parameters`), by one of two routes (docs/derivatives.md):

- ``"exact"`` (default): the interior and bin-edge terms for a plane
  scene, every waveform (:mod:`.sensitivity` for the impulse,
  :mod:`.waveform_sensitivity` for the others): ``source.position.*``,
  ``sensors.positions.k.*``, ``sampling.start``, the plane's rigid motions
  (``plane.translation.*``, ``plane.rotation.*``: the points moving the
  other way, so the same columns combined) and ``plane.size`` (by the
  model's scaling law, from the same columns and the moment -∫ f a d κ_n').
  Two parameters are exact by linearity for every scene: a reflectance
  scale (∂y/∂s = y) and the source's intensity (∂y/∂I = y / I). A relay
  wall's ``laser.position.*`` and ``sensor.position.*`` are exact through
  the laser leg's factor (:mod:`.relay_wall_legs`) unless the end legs are
  counted; ``sampling.start``, ``hidden.center.*``, ``hidden.rotation.*``,
  ``hidden.u.*``, ``hidden.v.*``, ``scan.laser_point.*`` and the laser's and
  sensor's positions with the end legs counted are exact through the
  rectangle's frame (:mod:`.relay_wall_sensitivity`, the waveforms the
  plane's routes take). The pulse's widths (``illumination.fwhm``,
  ``.tail``, ``.width``, and ``.cutoff`` with the default duration) are
  exact by the unit-peak pulse's scaling law and, for the EMG's ``fwhm``,
  the heat equation (:func:`.waveform_sensitivity.width_column`), on both
  scene kinds. Every other key (a Butterworth's stated ``duration`` and the
  ``cutoff`` beside it) still takes the differences below.
- ``"differences"``: Richardson-extrapolated central differences of the
  model assembled at tolerance :data:`TOLERANCE`, for every key (the tests'
  independent reference).

``errors=True`` also returns a bound on each (row, key) column's entries
(:func:`_differences`, docs/derivatives.md "Error estimates").
"""

from __future__ import annotations

import numpy as np

from ..errors import OptionError
from ..scenes.scene_file import scene_of
from ..waveforms import make_waveform
from .parameters import Parameter, parameter, parameters, rotation, value_of, with_values
from .general_routes import progress_bar
from .matrix_free import forward
from .relay_wall_legs import leg_column, supports_leg
from .relay_wall_sensitivity import relay_column, relay_parts, supports_relay
from .sensitivity import position_derivatives
from .waveform_sensitivity import supports_width, waveform_derivatives, width_column

__all__ = ["jacobian", "derivative", "exact_keys", "ROUTES", "TOLERANCE", "STEP"]

#: The routes :func:`jacobian` takes.
ROUTES = ("exact", "differences")
#: The stems the exact route covers (plane scenes, :func:`_exact_plane`).
_EXACT_STEMS = ("source.position", "sensors.positions", "sampling.start", "plane.translation", "plane.rotation",
                "plane.size")

#: The model's tolerance inside the differences: its error over the step bounds the derivative's.
TOLERANCE = 1e-10
#: The first step of the differences, as a fraction of the parameter's scale (halved for Richardson).
STEP = 1e-3


def _scale(scene, item: Parameter) -> float:
    """The size against which a parameter's step is taken: the scene's extent, 1 rad, or the value."""
    if item.unit == "rad":
        return 1.0
    if item.stem.startswith("illumination.") or item.stem == "plane.size":
        return abs(value_of(scene, item))
    if scene.kind == "plane":
        points = np.vstack([np.asarray(scene.source)[None, :], np.asarray(scene.sensors)])
        return max(float(scene.size), float(np.max(np.abs(points))))
    return max(float(np.max(scene.wall_size)), float(np.linalg.norm(scene.center)))


def _tight(scene):
    return scene.replace(tolerance=min(TOLERANCE, scene.tolerance))


def _differences(scene, item: Parameter, step: float, centre=None):
    """Richardson's (4 D(h/2) - D(h)) / 3 of central differences D, step h, and a bound on its error.

    With ``centre`` (the model at tolerance :data:`TOLERANCE`, unmoved) the
    bound per entry is the larger of the pair's disagreement |D(h/2) - D(h)| / 3
    (the error of D(h/2), far above Richardson's where y is smooth: h² y‴ / 24)
    and h times the largest change of the second differences of the five
    values, between the stencil's halves and between its scales (h² y‴ / 2
    where y is smooth; where a kink of y, slope jump J, lies in the stencil,
    at least 4 J / 7 against Richardson's error of at most J / 2, wherever it
    lies), plus the model's tolerance over the step (3 ε / h, ε =
    tolerance x the row's largest |y|), the largest over each (row, key)
    column. Several kinks in one stencil are outside that argument (the
    tests measure it on the impulse's). Without ``centre``, ``None``.
    """
    tight = _tight(scene)
    start = value_of(scene, item)
    y = {shift: forward(with_values(tight, {item.key: start + shift * step})) for shift in (-1.0, -0.5, 0.5, 1.0)}

    def central(scale):
        return (y[scale] - y[-scale]) / (2.0 * scale * step)

    column = (4.0 * central(0.5) - central(1.0)) / 3.0
    if centre is None:
        return column, None
    half = step / 2.0
    left = (centre - 2.0 * y[-0.5] + y[-1.0]) / half ** 2
    right = (y[1.0] - 2.0 * y[0.5] + centre) / half ** 2
    wide, narrow = (y[1.0] - 2.0 * centre + y[-1.0]) / step ** 2, (y[0.5] - 2.0 * centre + y[-0.5]) / half ** 2
    truncation = np.maximum(np.abs(central(0.5) - central(1.0)) / 3.0,
                            step * np.maximum(np.abs(left - right), np.abs(wide - narrow)))
    model = 3.0 * tight.tolerance * np.abs(centre).max(axis=-1, keepdims=True) / step
    return column, (truncation + model).max(axis=-1)


#: ``plane.size`` by the scaling law only while every point is this fraction of the scene's extent above the
#: plane: below, Σ p·∂y/∂p cancels to a few digits (6e-5 of the column at 1e-5, docs/derivatives.md).
_SIZE_HEIGHT = 1e-3


def _exact_plane(scene) -> bool:
    """A plane scene whose waveform one of the exact routes takes (every one but a step S other than the impulse)."""
    if scene.kind != "plane":
        return False
    if scene.illumination.waveform == "impulse":
        return True
    return make_waveform(scene.illumination, scene.sampling.bin_width_opl).terms.degree != 0


def _position_parts(scene, progress: bool, pulse: bool = False):
    """(y, ∂y/∂p_s, ∂y/∂p_k, ∂y/∂t_0, moment, widths) of :func:`.waveform_sensitivity.waveform_derivatives`,
    any waveform (``widths`` None for the impulse; judged to the tolerance with ``pulse``)."""
    if scene.illumination.waveform != "impulse":
        return waveform_derivatives(scene, progress=progress, pulse=pulse)
    y, source, sensor, start, response = position_derivatives(scene, progress=progress)
    edges = np.asarray(scene.sampling.edges, dtype=np.float64)
    # -I ∫ f a d κ_n'(d) dx with κ_n' = δ(d - t_n) - δ(d - t_{n+1}): t_{n+1} G(t_{n+1}) - t_n G(t_n)
    return y, source, sensor, start, edges[1:] * response[:, 1:] - edges[:-1] * response[:, :-1], None


def exact_keys(scene, items) -> list[bool]:
    """Whether each :class:`Parameter` takes the exact route in this scene (the linear ones always do)."""
    plane = _exact_plane(scene)
    if plane:
        heights = np.vstack([np.asarray(scene.source)[None, :], np.asarray(scene.sensors)])[:, 2]
        high = heights.min() >= _SIZE_HEIGHT * _scale(scene, parameter(scene, "source.position.x"))
    return [item.stem.endswith(".reflectance") or item.unit == "W/sr" or supports_leg(scene, item.stem)
            or supports_relay(scene, item.stem) or (plane and supports_width(scene, item.stem))
            or (plane and item.stem in _EXACT_STEMS and (item.stem != "plane.size" or high)) for item in items]


def _exact_column(scene, item: Parameter, parts) -> np.ndarray:
    """One column from :func:`analytic.operator.sensitivity.position_derivatives`' ``parts``."""
    y, source, sensor, start, moment, widths = parts
    stem, index = item.stem, item.index
    if stem.startswith("illumination."):
        return width_column(scene, stem, y, widths)
    if stem == "source.position":
        return source[..., index[0]]
    if stem == "sensors.positions":
        column = np.zeros_like(start)
        column[index[0]] = sensor[index[0], :, index[1]]
        return column
    if stem == "sampling.start":
        return start
    points = np.vstack([np.asarray(scene.source, dtype=np.float64)[None, :], np.asarray(scene.sensors)])
    if stem == "plane.size":
        # scaling every length by λ (plane, points, bin edges, the waveform's time axis) scales y by λ^-2
        # (a ~ λ^-4, dx ~ λ²), so L ∂y/∂L = -2 y - Σ_points p·∂y/∂p - [the edges' and waveform's share], the
        # last -I ∫ f a d κ_n'(d) dx (κ_n(d) = S(t_{n+1} - d) - S(t_n - d) depends on them through t_e - d alone)
        moved = (np.einsum("knj,j->kn", source, points[0]) + np.einsum("knj,kj->kn", sensor, points[1:]) + moment)
        return -(2.0 * y + moved) / float(scene.size)
    # a rigid motion of the plane is every point moving the other way: dp/dθ of each point, then the chain rule
    if stem == "plane.translation":
        velocity = np.zeros_like(points)
        velocity[:, index[0]] = -1.0
    else:       # points turned by -θ about the axis through the plane's centre: dp/dθ = -e × (p - c)
        centre = np.array([0.5 * scene.size, 0.5 * scene.size, 0.0])
        generator = rotation(index[0], 1.0) - rotation(index[0], -1.0)      # 2 sin(1) [e]x
        velocity = -(points - centre) @ (generator / (2.0 * np.sin(1.0))).T
    return (np.einsum("knj,j->kn", source, velocity[0])
            + np.einsum("knj,kj->kn", sensor, velocity[1:]))


def jacobian(scene, keys, *, step: float | None = None, route: str = "exact", progress: bool = False,
             errors: bool = False):
    """∂y/∂θ for each named parameter θ.

    Parameters
    ----------
    scene : SceneKind, str or Path
        A plane or relay-wall scene, or its file.
    keys : sequence of str
        Parameter keys of docs/design.md section 9 (``source.position.x``,
        ``sensors.positions.3.z``, ``sampling.start``, ...).
    step : float, optional
        The differences' first step as a fraction of each parameter's scale
        (default :data:`STEP`).
    route : {"exact", "differences"}
        "exact": the exact route for the keys it covers (:func:`exact_keys`),
        the differences for the rest; "differences": every key by differences.
    progress : bool
        Progress bars on stderr (the exact pass's sensors, then the keys).
    errors : bool
        Also return each column's error bound (one more model, at
        :data:`TOLERANCE`, when a key takes the differences).

    Returns
    -------
    numpy.ndarray
        ``(K, N, P)`` float64: y's units per unit of each parameter (per
        metre, per radian, per W/sr, or per unit scale), K sensors (pairs
        for a relay wall), N bins, P keys in the order given.
    numpy.ndarray
        Only with ``errors``: ``(K, P)``, a bound on |error| of every entry
        of the (row, key) column, in the column's units: the scene's
        tolerance times the column's largest |entry| on the exact route
        (what its integrals are judged to); :func:`_differences`' bound on
        the differences.
    """
    scene = scene_of(scene)
    if isinstance(keys, str):
        keys = [keys]
    items = parameters(scene, list(keys))
    fraction = STEP if step is None else float(step)
    if not np.isfinite(fraction) or fraction <= 0.0:
        raise OptionError(f"step: expected a positive fraction, got {step!r}")
    if route not in ROUTES:
        raise OptionError(f"route: expected one of {', '.join(ROUTES)}, got {route!r}")
    exact = exact_keys(scene, items) if route == "exact" else [False] * len(items)
    y = parts = relay = centre = None
    pulse = any(closed and item.stem.startswith("illumination.") for item, closed in zip(items, exact))
    if any(closed and supports_relay(scene, item.stem) and not supports_leg(scene, item.stem)
           for item, closed in zip(items, exact)):
        relay = relay_parts(scene, progress=progress, pulse=pulse)     # its y serves the linear and legs' keys
        y = relay[0]
    columns, bounds = [], []
    bar = progress_bar(progress and not all(exact), len(items), "jacobian", "key")
    for item, closed in zip(items, exact):
        if bar is not None:
            bar.update(1)
        if closed and (item.stem.endswith(".reflectance") or item.unit == "W/sr"):
            y = forward(scene) if y is None else y
            columns.append(y if item.unit == "1" else y / value_of(scene, item))
        elif closed and supports_leg(scene, item.stem):
            y = forward(scene) if y is None else y
            columns.append(leg_column(scene, item.stem, item.index[0], y))
        elif closed and supports_relay(scene, item.stem):
            relay = relay_parts(scene, progress=progress, pulse=pulse) if relay is None else relay
            columns.append(relay_column(scene, item.stem, item.index[0] if item.index else 0, relay))
        elif closed:
            parts = _position_parts(scene, progress, pulse) if parts is None else parts
            columns.append(_exact_column(scene, item, parts))
        else:
            if errors and centre is None:
                centre = forward(_tight(scene))
            column, bound = _differences(scene, item, fraction * _scale(scene, item), centre)
            columns.append(column)
            bounds.append(bound)
            continue
        bounds.append(float(scene.tolerance) * np.abs(columns[-1]).max(axis=-1))
    if bar is not None:
        bar.close()
    values = np.stack(columns, axis=-1)
    return (values, np.stack(bounds, axis=-1)) if errors else values


def derivative(scene, key: str, *, step: float | None = None, route: str = "exact") -> np.ndarray:
    """∂y/∂θ for one parameter: ``jacobian(scene, [key])[..., 0]``, ``(K, N)``."""
    return jacobian(scene, [key], step=step, route=route)[..., 0]
