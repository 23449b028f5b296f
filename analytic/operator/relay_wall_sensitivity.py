"""Exact ∂y/∂θ of a relay-wall capture for its geometric keys (docs/derivatives.md).

In the hidden rectangle's frame (x, y along its edges from its corner, heights along its normal) a pair
(l, s) is the plane's problem with l in the source's place, s in the sensor's, the rectangle's pixels as
the cells, and the attenuation multiplied by the wall's cosines at both ends, c_l = n·(x - l) / |x - l|
and c_s = n·(x - s) / |x - s| (:meth:`analytic.scenes.relay_wall.RelayWallScene.geometry`; n the wall's
normal, fixed in the frame while l and s move): :func:`analytic.kernels.sensitivity.pair_sums` (the
impulse) or :func:`analytic.kernels.sensitivity_waveform.waveform_pair_sums` (the other waveforms the
plane's exact route takes) with :class:`~analytic.kernels.sensitivity.PairGeometry`'s ``surfaces`` gives
the interior and bin-edge terms of ∂y/∂l and ∂y/∂s and the time zero's column, on the pair's time axis
shifted by -o_p (o_p the added path of the end legs when the scan counts them). The keys follow by the chain rule:

- ``sampling.start``: every edge moving, -I ∫ f a κ_n'(d + o_p) dx (for the impulse, the impulse response at the edges);
- ``laser.position.*`` with the end legs counted: the laser leg's factor (:mod:`.relay_wall_legs`) plus
  the time shift, -∂y/∂t_0 ∂o_p/∂o_l with ∂o_p/∂o_l = (o_l - l) / |o_l - l|; ``sensor.position.*`` the
  time shift alone, ∂o_p/∂o_s = (o_s - s) / |o_s - s|;
- ``hidden.center.*``: a translation of the rectangle is l and s moving the other way in its frame,
  -(∂y/∂l + ∂y/∂s) (the wall's normal unchanged, the legs untouched);
- ``hidden.rotation.*``: l, s and n turning the other way in the frame (:func:`_rotation`; n's share
  from the kernels' ∂a/∂n);
- ``scan.laser_point.{x,y}`` (single scan): ∂y/∂l plus the laser leg's factor (its l-derivative, the
  negative of its o_l-derivative) and the time shift with ∂o_p/∂l = (l - o_l) / |o_l - l|;
- ``hidden.u.*``, ``hidden.v.*``: a stretch about the centre (the kernels' moments about it) plus a
  turn (:func:`_edge_vector`);
- ``illumination.*``: the pulse's widths as the plane's (:func:`.waveform_sensitivity.width_column`: the
  pair's shifted time axis changes nothing, κ depending on t_e - o_p - d alone).

So every key comes from one pass, and where the pairs are translates of a few by whole pixels
(:mod:`.offsets`) from one pass over each distinct offset (:mod:`.relay_wall_offsets`).
"""

from __future__ import annotations

import numpy as np

from ..kernels.bins import TimeAxis
from ..kernels.sensitivity import RELAY_AMPLITUDES, pair_sums
from ..kernels.sensitivity_waveform import OUTPUTS, waveform_pair_sums
from ..resources import require_memory
from ..scenes.relay_wall import WALL_NORMAL
from ..waveforms import make_waveform
from .parameters import rotation
from .relay_wall_legs import leg_column
from .relay_wall_offsets import WAVEFORM_COLUMNS, offset_parts, pulse_terms
from .sensitivity import edge_columns, pair_geometry, pixel_cells, run_sensors, warn_edges_on_arrivals
from .waveform_sensitivity import supports_width, width_column

__all__ = ["supports_relay", "relay_parts", "relay_column"]

#: The kernels' sums of one block of pairs, in doubles (256 MB).
_BLOCK_DOUBLES = 2 ** 25

_STEMS = ("sampling.start", "laser.position", "sensor.position", "hidden.center", "hidden.rotation",
          "scan.laser_point", "hidden.u", "hidden.v")


def supports_relay(scene, stem: str) -> bool:
    """Whether :func:`relay_column` gives ``stem``'s column: a relay wall whose waveform one of the plane's
    exact routes takes (every one but a step S other than the impulse), and of its pulse the widths the
    plane's take (:func:`.waveform_sensitivity.supports_width`)."""
    if scene.kind != "relay_wall" or (stem not in _STEMS and not supports_width(scene, stem)):
        return False
    light = scene.illumination
    return light.waveform == "impulse" or make_waveform(light, scene.sampling.bin_width_opl).terms.degree != 0


def _offsets(scene, lit, read) -> np.ndarray:
    """Each pair's added path o_p (the end legs when the scan counts them, else 0), metres."""
    if not scene.scan.account_first_and_last_bounces:
        return np.zeros(len(lit))
    return np.linalg.norm(scene.laser_position - lit, axis=1) + np.linalg.norm(read - scene.sensor_position, axis=1)


def _frame(scene):
    """The rectangle, each pair's (l, s) in its frame, and the wall's normal in it."""
    rectangle = scene.rectangle()
    lit, read = scene.pair_points
    return rectangle, rectangle.local(lit), rectangle.local(read), rectangle.axes @ WALL_NORMAL


def _cells(scene) -> np.ndarray:
    """The rectangle's pixels of non-zero reflectance as frame boxes, split near the pairs' feet."""
    rectangle, local_lit, local_read, _ = _frame(scene)
    return pixel_cells(rectangle.width, rectangle.height, scene.reflectance,
                       np.unique(np.vstack([local_lit, local_read]), axis=0))


def _pass(scene, normal, progress: bool = False, pulse: bool = False):
    """(y, ∂y/∂l, ∂y/∂s, ∂y/∂t_0, ∂y/∂n, the stretch's moments, the pulse's two) of every pair, frame
    axes, the ends' cosines about the wall's ``normal`` (frame), times the laser leg's factor: ``(P, N)``,
    ``(P, N, 3)`` twice, ``(P, N)``, ``(P, N, 3)``, ``(P, N, 2)`` (about the rectangle's centre,
    :func:`_edge_vector`) and ``(P, N, 2)`` (:func:`.waveform_sensitivity.width_column`; None for the impulse).

    The impulse: :func:`pair_sums` (F, H at the pair's bin edges t_e - o_p); any other waveform:
    :func:`waveform_pair_sums` on the pair's time axis shifted by -o_p (``pulse``: its width outputs judged).
    """
    rectangle, local_lit, local_read, _ = _frame(scene)
    lit, read = scene.pair_points
    cells = _cells(scene)
    offsets = _offsets(scene, lit, read)
    count, rtol, sampling = len(lit), float(scene.tolerance), scene.sampling
    nx, ny, nz = map(float, normal)
    middle = (0.5 * rectangle.width, 0.5 * rectangle.height)

    def geometry(p):
        return pair_geometry(local_lit[p], local_read[p], "lambertian")._replace(
            surfaces=True, snx=nx, sny=ny, snz=nz, knx=nx, kny=ny, knz=nz, mx=middle[0], my=middle[1],
            mscale=float(np.hypot(*middle)))

    leg = scene.laser_leg(lit)
    bins = int(sampling.count)
    impulse = scene.illumination.waveform == "impulse"
    columns = 13 if impulse else 15
    # the columns above (13 doubles per entry, 15 with the pulse's), then the kernels' sums a block of pairs at a time
    require_memory(8 * columns * count * bins, f"the exact derivatives of {count:,} pairs x {bins} bins",
                   "take fewer keys on the exact route, or a smaller scan")
    out = np.zeros((count, bins, columns))
    if impulse:
        edges = np.asarray(sampling.edges, dtype=np.float64)
        shifted = edges[None, :] - offsets[:, None]
        width = 2 * edges.size * RELAY_AMPLITUDES
    else:
        terms, scales = pulse_terms(scene, pulse)
        width = bins * OUTPUTS
    block = max(1, _BLOCK_DOUBLES // width)
    for first in range(0, count, block):
        pairs = range(first, min(count, first + block))
        if impulse:
            sums = np.zeros((len(pairs), 2, edges.size, RELAY_AMPLITUDES))
            run_sensors(pair_sums, lambda i: (geometry(pairs[i]), cells, shifted[pairs[i]], rtol, sums[i, 0],
                                              sums[i, 1]), len(pairs), rtol, progress)
            parts = relay_edge_columns(sums)
        else:
            sums = np.zeros((len(pairs), bins, OUTPUTS))

            def arguments(i):
                axis = TimeAxis(float(sampling.start_opl) - offsets[pairs[i]], float(sampling.bin_width_opl), bins)
                return geometry(pairs[i]), cells, terms, axis, scales, rtol, sums[i]

            run_sensors(waveform_pair_sums, arguments, len(pairs), rtol, progress)
            parts = (sums[..., WAVEFORM_COLUMNS],)
        out[first:first + len(pairs)] = np.concatenate(parts, axis=-1) * leg[pairs.start:pairs.stop, None, None]
    return (out[..., 0], out[..., 1:4], out[..., 4:7], out[..., 7], out[..., 8:11], out[..., 11:13],
            None if impulse else out[..., 13:15])


def relay_edge_columns(sums) -> tuple:
    """(y, ∂y/∂l, ∂y/∂s, ∂y/∂t_0, ∂y/∂n, the stretch's moments) per bin, as ``(..., N, c)`` arrays (c = 1, 3,
    3, 1, 3, 2), from :func:`pair_sums`' ``sums`` ``(..., 2, E, 20)`` (F and H at the bin edges)."""
    y, source, sensor, start, _ = edge_columns(sums, 1.0)
    F, H = sums[..., 0, :, :], sums[..., 1, :, :]
    interior = np.diff(F, axis=-2)                   # F(t_{n+1}) - F(t_n)
    moving = H[..., :-1, :] - H[..., 1:, :]          # H(t_n) - H(t_{n+1})
    return (y[..., None], source, sensor, start[..., None], interior[..., 13:16],
            interior[..., 16:18] + moving[..., 18:20])


def relay_parts(scene, *, progress: bool = False, pulse: bool = False):
    """y and its derivatives of every pair: :func:`_pass`'s, ∂y/∂l and ∂y/∂s in world axes (the wall's
    normal fixed).

    Returns
    -------
    tuple of numpy.ndarray
        y ``(P, N)``, y's units; ∂y/∂l and ∂y/∂s ``(P, N, 3)``, per metre (l and s each pair's own
        points, the laser leg's factor held); ∂y/∂t_0 ``(P, N)``, per metre of path length; ∂y/∂n
        ``(P, N, 3)`` (the wall's normal in the rectangle's frame, both ends' cosines); the stretch's
        moments ``(P, N, 2)`` (:func:`_edge_vector`); the pulse's two ``(P, N, 2)`` (None for the impulse).

    Where the pairs are translates of a few, the offset route (:func:`.relay_wall_offsets.offset_parts`):
    each distinct (pair, pixel) offset integrated once.
    """
    rectangle, local_lit, local_read, normal = _frame(scene)
    if scene.illumination.waveform == "impulse":
        offsets = _offsets(scene, *scene.pair_points)
        geometries = [pair_geometry(l, s, "lambertian") for l, s in zip(local_lit, local_read)]
        edges = np.asarray(scene.sampling.edges, dtype=np.float64)
        warn_edges_on_arrivals(geometries, _cells(scene), edges[None, :] - offsets[:, None], "pair")
    parts = offset_parts(scene, normal, progress=progress, pulse=pulse)
    y, source, sensor, start, *rest = _pass(scene, normal, progress, pulse) if parts is None else parts
    # the frame's coordinates are axes (p - corner): a world gradient is axesᵀ times the frame's
    return (y, source @ rectangle.axes, sensor @ rectangle.axes, start, *rest)


def _rotation(scene, axis: int, parts) -> np.ndarray:
    """∂y/∂hidden.rotation.{axis}: the rectangle turning by θ about the world axis through its centre is, in
    its frame, l, s and the wall's normal n turning by -θ: dp/dθ = -e × (p - c), dn/dθ = -e × n.

    The points' share is the chain rule on ∂y/∂l and ∂y/∂s; n enters through the cosines alone,
    ∂(c_l c_s)/∂n·v = c_s v·(x - l)/|x - l| + c_l v·(x - s)/|x - s| (no path length moves: no edge
    term): the kernels' ∂a/∂n dotted with v = dn/dθ (frame).
    """
    generator = rotation(axis, 1.0) - rotation(axis, -1.0)          # 2 sin(1) [e]x
    return _turn(scene, -generator / (2.0 * np.sin(1.0)), parts)     # v ↦ -e × v


def _turn(scene, turn, parts) -> np.ndarray:
    """∂y/∂θ of the rectangle turning about its centre, ``turn`` the world matrix v ↦ -e × v."""
    lit_gradient, read_gradient = parts[1], parts[2]
    rectangle = _frame(scene)[0]
    lit, read = scene.pair_points
    column = (np.einsum("pnj,pj->pn", lit_gradient, (lit - scene.center) @ turn.T)
              + np.einsum("pnj,pj->pn", read_gradient, (read - scene.center) @ turn.T))
    return column + _normal_turn(rectangle.axes @ (turn @ WALL_NORMAL), parts[4])


def _normal_turn(velocity, gradient) -> np.ndarray:
    """∂y/∂θ of the wall's normal turning at ``velocity`` (frame), the points held: the interior integral
    of a (c_s v·(x - l)/|x - l| + c_l v·(x - s)/|x - s|), ``(P, N)``, i.e. the pass's ∂y/∂n ``gradient``
    dotted with v."""
    return gradient @ velocity


def _edge_vector(scene, stem: str, axis: int, parts) -> np.ndarray:
    """∂y/∂hidden.u.{axis} (or v), the centre and the other edge held, the pixel count fixed.

    A component of u along ê = u/|u| stretches the rectangle about its centre: with the pixels fixed
    in (ξ/|u|, η/|v|), u → (1 + ε) u gives dy/dε = y + ∫ ξ' f ∂_ê(a κ) dx (ξ' = ξ - |u|/2, the area
    element's change and the points' stretch), and ∂_x(a κ) = -(∂_l + ∂_s)(a κ) in the frame (a κ
    depends on x through x - l and x - s, the normals fixed): the pass's moments about the centre. A
    component along the lit face's normal n turns the rectangle about e = ê × n by δ/|u|
    (:func:`_turn`). One along the other edge breaks u ⊥ v: :func:`.parameters.parameter` refuses it.
    """
    y = parts[0]
    rectangle = _frame(scene)[0]
    side = 0 if stem == "hidden.u" else 1
    length = (rectangle.width, rectangle.height)[side]
    along, face = rectangle.axes[side], rectangle.axes[2]
    column = np.zeros_like(y)
    if along[axis] != 0.0:
        column += along[axis] / length * (y - parts[5][..., side])
    if face[axis] != 0.0:
        e = np.cross(along, face)
        turn = -np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])
        column += face[axis] / length * _turn(scene, turn, parts)
    return column


def relay_column(scene, stem: str, axis: int, parts) -> np.ndarray:
    """∂y/∂(``stem``'s ``axis`` component), ``(P, N)``, from :func:`relay_parts`' ``parts``."""
    y, lit_gradient, read_gradient, start = parts[:4]
    if stem.startswith("illumination."):
        return width_column(scene, stem, y, parts[6])
    if stem in ("hidden.u", "hidden.v"):
        return _edge_vector(scene, stem, axis, parts)
    if stem == "sampling.start":
        return start
    if stem == "hidden.center":
        return -(lit_gradient[..., axis] + read_gradient[..., axis])
    if stem == "hidden.rotation":
        return _rotation(scene, axis, parts)
    lit, read = scene.pair_points
    counted = bool(scene.scan.account_first_and_last_bounces)
    if stem == "sensor.position":
        toward = scene.sensor_position - read
        shift = toward[:, axis] / np.linalg.norm(toward, axis=1)
        return -start * shift[:, None] if counted else np.zeros_like(y)
    toward = scene.laser_position - lit
    shift = toward[:, axis] / np.linalg.norm(toward, axis=1)           # ∂o_p/∂o_l
    leg = leg_column(scene, "laser.position", axis, y)                   # y ∂ln c_l/∂o_l
    column = leg - (start * shift[:, None] if counted else 0.0)
    if stem == "laser.position":
        return column
    # scan.laser_point: l moves (o_l - l turns the other way: the leg's and the shift's signs flip)
    return lit_gradient[..., axis] - column
