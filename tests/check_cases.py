"""Synthetic cases of the check tests (tests/validation/check): a small scene, data made from the model at a
known scale and start offset plus noise of known size, and our render folders."""

from __future__ import annotations

import numpy as np

import scene_files
from analytic.files import build_meta, write_transient
from analytic.scenes.common import Sampling, Scene
from analytic.operator.matrix_free import forward
from validation.cli import main

START, WIDTH, COUNT = 1.7, 0.05, 24


def small_scene(**changes) -> Scene:
    """4 x 4 asymmetric image, two sensors at different heights, 24 bins around the light."""
    image = np.arange(16, dtype=np.float64).reshape(4, 4) / 20.0
    values = dict(name="small", size=1.0, pixels=4, reflectance=image, source=(0.5, 0.5, 1.0),
                  sensors=[(0.8, 0.3, 1.0), (0.25, 0.7, 0.8)],
                  sampling=Sampling(bin_width_opl=WIDTH, start_opl=START, count=COUNT))
    return Scene(**(values | changes))


def shifted(scene: Scene, offset: float) -> np.ndarray:
    """The model with every bin edge moved by +offset: what data short by `offset` read."""
    sampling = Sampling(bin_width_opl=WIDTH, start_opl=START + offset, count=COUNT)
    return forward(scene.replace(sampling=sampling))


def noisy_replicas(truth: np.ndarray, rng, replicas: int = 6) -> np.ndarray:
    """Independent replicas: truth + Gaussian noise of 1 % of each bin plus a floor."""
    sigma = 0.01 * np.abs(truth) + 1e-4 * np.max(truth)
    return truth + sigma * rng.standard_normal((replicas,) + truth.shape)


def one_bin_scene() -> Scene:
    """One sensor and one bin holding the whole response: nothing to fit a scale and an offset to."""
    return small_scene(sensors=[(0.8, 0.3, 1.0)], sampling=Sampling(bin_width_opl=1.5, start_opl=1.5, count=1))


def render_folder(folder, scene, replicas: np.ndarray):
    """A render's output as `render` writes it: the replicas' mean, their standard error, replicas.npy."""
    count = replicas.shape[0]
    meta = build_meta(scene, kind="render", samples=count, seed=0, replicas=count, dof=count - 1)
    write_transient(folder, replicas.mean(axis=0), meta,
                    stderr=replicas.std(axis=0, ddof=1) / np.sqrt(count))
    np.save(folder / "replicas.npy", replicas)
    return folder


def run_check(*argv) -> int:
    return main(["check", *map(str, argv), "--quiet"])


def write_scene_file(tmp_path):
    """small_scene as a scene file (its image an EXR beside it): what the command reads."""
    return scene_files.write_scene_file(tmp_path, small_scene())
