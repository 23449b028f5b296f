"""Axis conventions of our tal capture, read through tal itself: no rendering needed.

An off-centre, turned hidden rectangle and a 5 x 3 single scan (a grid that is not square, so Sx and Sy
cannot trade places unseen): ``forward`` writes transient.h5, ``tal.io.read_capture`` (in .venv-tal)
reads it, and the first bin where light arrives at each (Sx, Sy) of tal's H must be the bin of the
shortest path laser point -> rectangle -> read point, computed here from tal's own formulas (the
grid's cell centres, the lookat's pixel / W, to_world = T Rz Ry Rx S by SciPy) and a convex
minimisation over the rectangle, with no code of ours.
"""

import json
import math

import numpy as np
import yaml
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from tal_env import TAL_READ, needs_tal, run_tal
from validation.cli import main

WIDTH, HEIGHT, LOOKAT = 5, 3, (1, 2)
SCALE, ANGLES, SHIFT = (0.35, 0.2, 1.0), (165.0, 20.0, -35.0), (0.4, -0.3, 0.8)
START, BIN, COUNT = 1.2, 0.004, 700
CONFIG = {
    "name": "axes", "integrator_filter_bounces": 2, "num_bins": COUNT, "bin_width_opl": BIN, "start_opl": START,
    "scan_type": "single", "sensor_width": WIDTH, "sensor_height": HEIGHT,
    "laser_lookat_x": LOOKAT[0], "laser_lookat_y": LOOKAT[1],
    "geometry": [
        {"name": "plane", "mesh": {"type": "rectangle"}, "material": {"id": "white"},
         **{f"scale_{a}": s for a, s in zip("xyz", SCALE)},
         **{f"rot_degrees_{a}": t for a, t in zip("xyz", ANGLES)},
         **{f"displacement_{a}": d for a, d in zip("xyz", SHIFT)}},
        {"name": "relay_wall", "mesh": {"type": "rectangle"}, "displacement_x": 0.0, "displacement_y": 0.0,
         "displacement_z": 0.0, "scale_x": 1, "scale_y": 1, "material": {"id": "white"}}],
    "relay_wall": "relay_wall", "diffuse_imaging": {"pixels": 8},
}


def shortest_path(laser_point, read_point):
    """min over the rectangle of |l - x| + |x - s| (convex in the rectangle's own (a, b) in [-1, 1]²)."""
    rotation = Rotation.from_euler("xyz", ANGLES, degrees=True)

    def length(ab):
        x = rotation.apply(np.array([ab[0], ab[1], 0.0]) * SCALE) + SHIFT
        return np.linalg.norm(x - laser_point) + np.linalg.norm(x - read_point)

    best = min((minimize(length, start, bounds=[(-1, 1), (-1, 1)], method="L-BFGS-B", options={"ftol": 1e-15})
                for start in ([0, 0], [0.9, 0.9], [-0.9, -0.9])), key=lambda r: r.fun)
    return float(best.fun)


@needs_tal
def test_first_arrivals_in_tals_reading_of_our_capture_follow_the_geometry(tmp_path):
    scene_file = tmp_path / "axes.yaml"
    scene_file.write_text(yaml.safe_dump(CONFIG))
    out = tmp_path / "out"
    assert main(["forward", str(scene_file), "--out", str(out), "--quiet"]) == 0
    read = json.loads(run_tal(TAL_READ, out / "transient.h5", tmp_path / "H.npy"))
    H = np.load(tmp_path / "H.npy")
    assert read["H_format"] == "T_Sx_Sy" and H.shape == (COUNT, WIDTH, HEIGHT)
    assert math.isclose(read["t_start"], START) and math.isclose(read["delta_t"], BIN)
    # tal's formulas: read points at cell centres, x along world +x with the first index
    xs = (2 * np.arange(WIDTH) + 1) / WIDTH - 1
    ys = (2 * np.arange(HEIGHT) + 1) / HEIGHT - 1
    grid = np.array(read["sensor_grid_xyz"])
    np.testing.assert_allclose(grid[..., 0], np.broadcast_to(xs[:, None], (WIDTH, HEIGHT)), atol=1e-12)
    np.testing.assert_allclose(grid[..., 1], np.broadcast_to(ys[None, :], (WIDTH, HEIGHT)), atol=1e-12)
    laser_point = np.array([2 * LOOKAT[0] / WIDTH - 1, 2 * LOOKAT[1] / HEIGHT - 1, 0.0])
    np.testing.assert_allclose(np.reshape(read["laser_grid_xyz"], -1), laser_point, atol=1e-12)
    expected = np.empty((WIDTH, HEIGHT), dtype=int)
    for i, x in enumerate(xs):
        for j, y in enumerate(ys):
            position = (shortest_path(laser_point, np.array([x, y, 0.0])) - START) / BIN
            assert abs(position - round(position)) > 1e-3, "the shortest path sits on a bin edge: move the scene"
            expected[i, j] = math.floor(position)
    first = np.argmax(H > 0, axis=0)
    assert np.all(H.max(axis=0) > 0)
    # the geometry separates the read points: a flipped or transposed reading would not match
    assert len(np.unique(expected)) >= 10
    assert not np.array_equal(expected, expected[::-1, :]) and not np.array_equal(expected, expected[:, ::-1])
    np.testing.assert_array_equal(first, expected)
