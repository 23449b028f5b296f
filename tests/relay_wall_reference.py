"""An independent reference for captures through a relay wall: docs/design.md section 7's formula by QUADPACK.

The formula is written out again in world coordinates (its own frame of the
hidden rectangle, its own cosines at the wall and on the hidden plane) and
integrated with tests/reference.py's nested QUADPACK, which shares nothing
with the model.
"""

from __future__ import annotations

import math

import numpy as np
from reference import bin_kernel, pixel_entry


def hidden_frame(scene):
    """Orthonormal axes of the hidden rectangle and its corner, computed here (not by the model)."""
    u, v = np.asarray(scene.u, float), np.asarray(scene.v, float)
    x_axis, y_axis = u / np.linalg.norm(u), v / np.linalg.norm(v)
    normal = np.cross(x_axis, y_axis)
    corner = np.asarray(scene.center, float) - 0.5 * (u + v)
    return corner, np.array([x_axis, y_axis, normal])


def pixel_region(scene, pixel):
    """(x0, x1, y0, y1) of hidden pixel r M + c in the rectangle's frame: image[r, c] covers u-fraction
    [c/M, (c+1)/M), v-fraction [1-(r+1)/M, 1-r/M)."""
    m = scene.pixels
    r, c = divmod(int(pixel), m)
    du, dv = np.linalg.norm(scene.u) / m, np.linalg.norm(scene.v) / m
    return c * du, (c + 1) * du, (m - r - 1) * dv, (m - r) * dv


def reference_bin(scene, pair, n, box=None):
    """H(l, s)[n] of unit hidden reflectance over ``box`` (x0, x1, y0, y1) of the rectangle's frame (default:
    all of it), by nested QUADPACK: A[(pair, n), pixel] for a pixel's box."""
    corner, axes = hidden_frame(scene)
    lit, read = (np.asarray(a)[pair] for a in scene.pair_points)
    local_l, local_s = (axes @ (point - corner) for point in (lit, read))
    wall = np.array([0.0, 0.0, 1.0])

    def weight(x, y):
        world = corner + x * axes[0] + y * axes[1]
        to_l, to_s = world - lit, world - read
        d_l, d_s = np.linalg.norm(to_l), np.linalg.norm(to_s)
        cos_x_l, cos_x_s = local_l[2] / d_l, local_s[2] / d_s            # at x, toward l and s
        cos_l_x, cos_s_x = (wall @ to_l) / d_l, (wall @ to_s) / d_s       # at l and s, toward x
        return cos_x_l * cos_x_s * cos_l_x * cos_s_x / (math.pi * d_l**2 * d_s**2)

    to_laser = np.asarray(scene.laser_position) - lit
    leg = (scene.intensity * (to_laser[2] / np.linalg.norm(to_laser)) / (to_laser @ to_laser)
           * (scene.wall_reflectance / math.pi) ** 2)
    offset = 0.0
    if scene.scan.account_first_and_last_bounces:
        offset = np.linalg.norm(to_laser) + np.linalg.norm(read - np.asarray(scene.sensor_position))
    kernel, breakpoints = bin_kernel(scene.illumination, scene.sampling.start_opl - offset,
                                     scene.sampling.bin_width_opl, n)
    if box is None:
        box = (0.0, float(np.linalg.norm(scene.u)), 0.0, float(np.linalg.norm(scene.v)))
    return leg * pixel_entry(box, local_l, local_s, kernel, breakpoints, weight=weight)


def brute_force_path_range(scene, cells: int = 400):
    """(min, max) path length |x - l| + |x - s| (plus the legs when counted) over a cells x cells grid of the
    hidden rectangle, corners included, for every pair: from above and below the exact range by at most the
    grid's spacing's effect."""
    corner, _ = hidden_frame(scene)
    u, v = np.asarray(scene.u, float), np.asarray(scene.v, float)
    a, b = np.meshgrid(np.linspace(0.0, 1.0, cells + 1), np.linspace(0.0, 1.0, cells + 1))
    points = corner + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    low, high = math.inf, -math.inf
    lit_points, read_points = scene.pair_points
    for lit, read in zip(lit_points, read_points):
        lengths = np.linalg.norm(points - lit, axis=1) + np.linalg.norm(points - read, axis=1)
        if scene.scan.account_first_and_last_bounces:
            lengths += (np.linalg.norm(np.asarray(scene.laser_position) - lit)
                        + np.linalg.norm(read - np.asarray(scene.sensor_position)))
        low, high = min(low, float(lengths.min())), max(high, float(lengths.max()))
    return low, high
