"""A relay wall's exact derivatives by pixel offsets: each distinct (pair, pixel) offset integrated once.

The forward's offset route (:mod:`.offsets`) applies to the derivatives too: when the pairs are
translates of a few by whole pixels, every integral of :func:`.relay_wall_sensitivity._pass` over (pair,
pixel) is that of (its group's first pair, the pixel shifted) over the virtual rectangle, so the per-pair
sums are correlations of the image with per-pixel runs
(:func:`analytic.kernels.sensitivity_offsets.window_sums`), read as the forward reads A's
(:func:`analytic.kernels.sensitivity_offsets.window_products`). The outputs are those of the general
pass (y, ∂y/∂l, ∂y/∂s, ∂y/∂t_0, ∂y/∂n, the pulse's two) but for the stretch's moments, which the virtual
rectangle takes about its own centre c_v: a member shifted by (s_c, s_r) whole pixels sees x - x_c =
(x_v - c_v) + (c_v - s_c Δu - x_c) (x_c the real centre), so its moment is the virtual one plus that
constant times the unweighted (∂_l + ∂_s) column.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..kernels.bins import TimeAxis
from ..kernels.sensitivity_offsets import OUTPUTS, waveform_window_sums, window_products, window_sums
from ..kernels.sensitivity_waveform import OUTPUTS as WAVEFORM_OUTPUTS
from ..resources import require_memory
from ..waveforms import make_waveform
from ..waveforms.pieces import without_tail_kinks
from .blocks import run_blocks, thread_count
from .general_routes import progress_bar
from .offsets import offset_plan
from .sensitivity import pair_geometry, pixel_cells
from .system import QuadratureWarning, _problem
from .waveform_sensitivity import kernel_scales

__all__ = ["offset_parts", "pulse_terms", "WAVEFORM_COLUMNS"]

#: Blocks of virtual pixels per thread (the pixels' costs differ: more blocks balance the threads).
_BLOCKS_PER_THREAD = 8
#: The waveform route's outputs in :func:`.relay_wall_sensitivity._pass`'s order: y, ∂y/∂l, ∂y/∂s,
#: ∂y/∂t_0, ∂y/∂n, the moments, the pulse's two (analytic.kernels.sensitivity_waveform's 0-7, 11-15, 9-10).
WAVEFORM_COLUMNS = np.r_[0:8, 11:16, 9:11]


def pulse_terms(scene, pulse: bool):
    """(terms, scales) of the waveform route: the pulse's pieces without its tails' kinks (a smooth pulse's
    truncated tails are no breakpoints: cutting at them is most of the work) and the kernels' scales,
    the width outputs judged when ``pulse`` (the EMG's [s'] only for it)."""
    terms = without_tail_kinks(make_waveform(scene.illumination, scene.sampling.bin_width_opl).terms)
    return terms, kernel_scales(terms, float(scene.sampling.bin_width_opl), pulse,
                                pulse and scene.illumination.waveform == "emg")


def _reach(geometry, boxes):
    """Each box's nearest and deepest path (as :func:`analytic.kernels.sensitivity.pair_sums` bounds a cell:
    |∇d| <= 2, d convex), at least the first arrival."""
    x0, x1, y0, y1 = boxes.T

    def path(x, y):
        return (np.sqrt((x - geometry.sx) ** 2 + (y - geometry.sy) ** 2 + geometry.sh ** 2)
                + np.sqrt((x - geometry.kx) ** 2 + (y - geometry.ky) ** 2 + geometry.kh ** 2))

    deepest = np.maximum(np.maximum(path(x0, y0), path(x1, y0)), np.maximum(path(x0, y1), path(x1, y1)))
    nearest = np.maximum(path(0.5 * (x0 + x1), 0.5 * (y0 + y1)) - np.hypot(x1 - x0, y1 - y0), geometry.first)
    return nearest, deepest


def _windows(geometry, boxes, edges) -> np.ndarray:
    """Each box's (first, last) edge: the last at or below its nearest path, the first beyond its deepest."""
    nearest, deepest = _reach(geometry, boxes)
    low = np.maximum(np.searchsorted(edges, nearest, side="right") - 1, 0)
    high = np.minimum(np.searchsorted(edges, deepest, side="right"), edges.size - 1)
    return np.column_stack([low, high]).astype(np.int64)


def _bin_windows(geometry, boxes, axis, terms) -> np.ndarray:
    """Each box's bins (first, last + 1) that light leaving it reaches under the pulse ``terms`` (one bin
    more on each side than :func:`analytic.kernels.bins.pixel_bins` finds: the rounding of its edges)."""
    nearest, deepest = _reach(geometry, boxes)
    first = np.floor((nearest + terms.lead - axis.start_opl) / axis.bin_width_opl) - 1
    last = np.floor((deepest + terms.duration - axis.start_opl) / axis.bin_width_opl) + 1
    first, last = np.clip(first, 0, axis.count), np.clip(last + 1, 0, axis.count)
    return np.column_stack([first, np.maximum(first, last)]).astype(np.int64)


def _pixels(geometry, side, size):
    """(cells, bounds, boxes) of the Mv x Mv virtual pixels (``size`` = (Wv, Hv)): every pixel's cells (f = 1),
    pixel j's rows ``bounds[j]:bounds[j + 1]``, and its box (x0, x1, y0, y1)."""
    width, height = size
    du, dv = width / side, height / side
    index = np.arange(1, side * side + 1, dtype=np.float64).reshape(side, side)
    feet = np.array([[geometry.sx, geometry.sy, geometry.sh], [geometry.kx, geometry.ky, geometry.kh]])
    cells = pixel_cells(width, height, index, feet)          # f = the pixel's index + 1 (row from the top)
    owners = cells[:, 4].astype(np.int64) - 1
    order = np.argsort(owners, kind="stable")
    cells, owners = np.ascontiguousarray(cells[order]), owners[order]
    cells[:, 4] = 1.0
    bounds = np.searchsorted(owners, np.arange(side * side + 1)).astype(np.int64)
    rows, columns = np.divmod(np.arange(side * side), side)
    boxes = np.column_stack([columns * du, (columns + 1) * du, height - (rows + 1) * dv, height - rows * dv])
    return cells, bounds, boxes


def _group_runs(geometry, side, size, pulse, rtol, progress):
    """(first bins, starts, values, failures) of one group's pair over the Mv x Mv virtual pixels: the
    impulse's runs (``pulse`` = the pair's bin edges) or another waveform's (``pulse`` = (terms, scales,
    the pair's TimeAxis))."""
    cells, bounds, boxes = _pixels(geometry, side, size)
    impulse = isinstance(pulse, np.ndarray)
    windows = _windows(geometry, boxes, pulse) if impulse else _bin_windows(geometry, boxes, pulse[2], pulse[0])
    starts = np.zeros(side * side + 1, dtype=np.int64)
    np.cumsum(np.maximum(windows[:, 1] - windows[:, 0], 0), out=starts[1:])
    width = OUTPUTS if impulse else WAVEFORM_OUTPUTS
    require_memory(8 * width * int(starts[-1]), f"the exact derivatives' runs of {side * side:,} virtual pixels",
                   "take fewer keys on the exact route, or fewer pixels")
    values = np.zeros((int(starts[-1]), width))
    blocks = min(side * side, _BLOCKS_PER_THREAD * thread_count())
    split = (np.arange(blocks + 1) * side * side) // blocks

    def arguments(b):
        span = int(split[b]), int(split[b + 1])
        if impulse:
            return geometry, cells, bounds, windows, pulse, rtol, starts, *span, values
        terms, scales, axis = pulse
        return geometry, (cells, bounds, windows, starts), terms, axis, scales, rtol, span, values

    bar = progress_bar(progress, blocks, "exact derivatives by pixel offsets", "block")
    try:
        failures = sum(run_blocks(window_sums if impulse else waveform_window_sums, arguments, blocks, bar=bar))
    finally:
        if bar is not None:
            bar.close()
    return windows[:, 0], starts, values, failures


def offset_parts(scene, normal, *, progress: bool = False, pulse: bool = False):
    """(y, ∂y/∂l, ∂y/∂s, ∂y/∂t_0, ∂y/∂n, the stretch's moments, the pulse's two) of every pair, frame axes,
    as :func:`.relay_wall_sensitivity._pass` gives them (``normal``: the wall's normal in the rectangle's
    frame; ``pulse``: the width outputs judged), or None where the offset route does not apply
    (:func:`.offsets.offset_plan`)."""
    sampling = scene.sampling
    rectangle, pairs = scene.geometry()
    waveform = make_waveform(scene.illumination, sampling.bin_width_opl)
    plan = offset_plan(_problem(rectangle, pairs, sampling, waveform))
    if plan is None:
        return None
    virtual = plan.virtual
    side = virtual.grid.pixels
    size = (virtual.grid.width, virtual.grid.height)
    middle = (0.5 * size[0], 0.5 * size[1])
    impulse = scene.illumination.waveform == "impulse"
    if not impulse:
        terms, scales = pulse_terms(scene, pulse)
    nx, ny, nz = map(float, normal)
    starts, firsts, values, failures = [], [], [], 0
    for table in virtual.pairs:
        geometry = pair_geometry((table["source_x"], table["source_y"], table["source_height"]),
                                 (table["sensor_x"], table["sensor_y"], table["sensor_height"]), "lambertian")
        geometry = geometry._replace(surfaces=True, snx=nx, sny=ny, snz=nz, knx=nx, kny=ny, knz=nz,
                                     mx=middle[0], my=middle[1], mscale=float(np.hypot(*middle)))
        start = float(sampling.start_opl) - float(table["offset"])
        pulse = (np.asarray(sampling.edges, dtype=np.float64) - float(table["offset"]) if impulse else
                 (terms, scales, TimeAxis(start, float(sampling.bin_width_opl), int(sampling.count))))
        group_firsts, group_starts, group_values, group_failures = _group_runs(
            geometry, side, size, pulse, float(scene.tolerance), progress)
        offset = sum(len(v) for v in values)
        starts.append(group_starts[:-1] + offset)
        firsts.append(group_firsts)
        values.append(group_values)
        failures += group_failures
    if failures:
        warnings.warn(f"{failures} cell integrals of the exact derivatives stopped refining before reaching "
                      f"tolerance {float(scene.tolerance):g}", QuadratureWarning, stacklevel=4)
    values = np.concatenate(values)
    starts = np.append(np.concatenate(starts), len(values)).astype(np.int64)
    firsts = np.concatenate(firsts).astype(np.int64)
    image = np.ascontiguousarray(scene.reflectance, dtype=np.float64).ravel()
    count = len(plan.groups)
    out = np.zeros((count, plan.bins, values.shape[1]))
    blocks = min(count, thread_count())
    split = (np.arange(blocks + 1) * count) // blocks
    run_blocks(window_products, lambda b: ((starts, firsts, values), plan.shape,
                                           tuple(m[split[b]:split[b + 1]] for m in plan.mapping),
                                           plan.scales[split[b]:split[b + 1]], image, out[split[b]:split[b + 1]]),
               blocks)
    if not impulse:
        out = out[..., WAVEFORM_COLUMNS]         # in the impulse's order, the pulse's two after
    moments = _about_the_centre(out[..., 11:13], out, plan, rectangle, middle)
    return (out[..., 0], out[..., 1:4], out[..., 4:7], out[..., 7], out[..., 8:11], moments,
            None if impulse else out[..., 13:15])


def _about_the_centre(moments, out, plan, rectangle, middle) -> np.ndarray:
    """The stretch's moments of every pair about the real rectangle's centre from those about the virtual
    one's, ``middle`` (module docstring)."""
    du, dv = rectangle.width / plan.pixels, rectangle.height / plan.pixels
    shift_x = middle[0] - plan.shift_c * du - 0.5 * rectangle.width
    shift_y = middle[1] - plan.shift_r * dv - 0.5 * rectangle.height
    return moments + np.stack([shift_x[:, None] * (out[..., 1] + out[..., 4]),
                               shift_y[:, None] * (out[..., 2] + out[..., 5])], axis=-1)
