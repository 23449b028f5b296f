"""Brute force for comparison: A by midpoint supersampling, in plain NumPy.

    python benchmarks/supersampled.py SCENE.toml --factor S --out DIR

Reads the scene file itself (tomllib; impulse illumination, lambertian
attenuation, a uniform reflectance number), builds A from S x S midpoint
samples per pixel binned by path length, computes y = A f and writes
``DIR/transient.npy``. It imports neither the project nor Numba: it is what
a user would write instead of the exact model, and the benchmark times it
from process start to file written.
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

import numpy as np
import scipy.sparse


def sensor_positions(sensors: dict) -> np.ndarray:
    """``[sensors]`` of a scene file as a (K, 3) array (explicit positions or a grid)."""
    if "positions" in sensors:
        return np.asarray(sensors["positions"], dtype=np.float64)
    nx, ny = sensors["grid"]
    extent = float(sensors["extent"])
    centre = np.asarray(sensors["center"], dtype=np.float64)

    def offsets(n):
        return np.zeros(1) if n == 1 else extent * (np.arange(n) / (n - 1) - 0.5)

    gx, gy = np.meshgrid(centre[0] + offsets(nx), centre[1] + offsets(ny))
    return np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, centre[2])])


def supersampled(size: float, pixels: int, source, sensors, start_opl: float, bin_width_opl: float,
                 count: int, factor: int, intensity: float = 1.0) -> scipy.sparse.csr_array:
    """A from factor² midpoint samples per pixel: row k N + n, column r M + c (docs/design.md section 2).

    Each sample x of a pixel adds I a_k(x) (Δ/factor)² to the bin of its path
    length d_k(x); a_k = h_s h_k / (π d_s³ d_k³), I the source's intensity (W/sr).
    """
    delta = size / pixels
    u = (np.arange(pixels * factor) + 0.5) * (delta / factor)
    x = u[None, :]
    y = size - u[:, None]                       # row r counts from the top
    cell = np.arange(pixels * factor) // factor
    pixel = (cell[:, None] * pixels + cell[None, :]).ravel()
    area = (delta / factor) ** 2
    source = np.asarray(source, dtype=np.float64)
    d_source = np.sqrt((x - source[0]) ** 2 + (y - source[1]) ** 2 + source[2] ** 2)
    from_source = intensity * source[2] / d_source**3 * (area / np.pi)
    blocks = []
    for sensor in np.asarray(sensors, dtype=np.float64):
        d_sensor = np.sqrt((x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2)
        n = np.floor((d_source + d_sensor - start_opl) / bin_width_opl).ravel()
        inside = (n >= 0) & (n < count)
        weight = (from_source * sensor[2] / d_sensor**3).ravel()[inside]
        key = n[inside].astype(np.int64) * pixels**2 + pixel[inside]
        dense = np.bincount(key, weights=weight, minlength=count * pixels**2).reshape(count, pixels**2)
        blocks.append(scipy.sparse.csr_array(dense))
    return scipy.sparse.vstack(blocks, format="csr")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--factor", type=int, required=True, help="samples per pixel side")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    with open(args.scene, "rb") as handle:
        scene = tomllib.load(handle)
    plane, sampling = scene["plane"], scene["sampling"]
    matrix = supersampled(plane["size"], plane["pixels"], scene["source"]["position"],
                          sensor_positions(scene["sensors"]), sampling["start"], sampling["period"],
                          sampling["count"], args.factor, scene["source"].get("intensity", 1.0))
    image = np.full(plane["pixels"] ** 2, float(plane["reflectance"]))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "transient.npy", (matrix @ image).reshape(-1, sampling["count"]))


if __name__ == "__main__":
    main()
