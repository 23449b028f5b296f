"""``check`` of relay-wall (NLOS) captures: our renders as plain arrays, tal captures and mitransient films.

The data are replicas from our own renderer (``transient_opl_nlos``, which
tests/transient/test_nlos.py holds to the model), written in each format a
user brings; the reference is the exact model. Every format must give the
same verdict on the same numbers, and a film read with its grid transposed
must disagree (the readers' orientation has power).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scene_files import write_relay_wall_file

from interop.tal import write_relay_wall_capture
from analytic.scenes.relay_wall import RelayWallScene, Scan
from analytic.scenes.common import Sampling
from validation.cli import main

REPLICAS = 16


def scene_of(**changes) -> RelayWallScene:
    image = np.arange(16, dtype=np.float64).reshape(4, 4) / 20.0 + 0.1           # asymmetric: catches flips
    values = dict(name="nlos", pixels=4, reflectance=image, center=(0.1, 0.05, 0.9), u=(0.8, 0.0, 0.0),
                  v=(0.0, -0.7, 0.0), scan=Scan(type="single", grid=(3, 3), laser_point=(0.4, -0.3, 0.0)),
                  sampling=Sampling(bin_width_opl=0.04, start_opl=1.84, count=30))
    return RelayWallScene(**(values | changes))


def our_replicas(scene, spp=2**15, seed=5) -> np.ndarray:
    """``(R, P, N)`` replicas of our renderer, in units of y."""
    from transient.backend import select_variant

    select_variant()
    import mitsuba as mi

    from transient.chunks import ReplicaLayout
    from transient.mitsuba_scene import relay_wall_scene_dict

    loaded = mi.load_dict(relay_wall_scene_dict(scene))
    layout = ReplicaLayout.for_samples(spp, REPLICAS)
    sums = loaded.integrator().render_chunk_per_unit_intensity(loaded, seed=seed, layout=layout, first=0,
                                                               count=layout.samples)
    return sums / layout.size * scene.intensity


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    folder = tmp_path_factory.mktemp("nlos")
    scene = scene_of()
    return folder, write_relay_wall_file(folder, scene), scene, our_replicas(scene)


def as_film(replica: np.ndarray, scene) -> np.ndarray:
    """mitransient's (H, W, T, 1) film of a single scan: row j, column i holds pair j W + i."""
    width, height = scene.scan.grid
    return replica.reshape(height, width, -1)[..., None]


def _saved_film(folder, scene, replica, r):
    np.save(folder / f"right_way_{r}.npy", as_film(replica, scene))
    return folder / f"right_way_{r}.npy"


def run(*argv) -> int:
    return main([*map(str, argv), "--quiet"])


def check(folder, scene_file, files, name) -> dict:
    status = run("check", scene_file, "--data", *files, "--out", folder / name)
    metrics = json.loads((folder / name / "metrics.json").read_text())
    return status, metrics


def save_formats(folder, scene, replicas) -> dict:
    """Each replica as a (P, N) array, a mitransient film (float32, as it saves them) and our tal capture."""
    files = {"arrays": [], "films": [], "captures": []}
    for r, replica in enumerate(replicas):
        files["arrays"].append(folder / f"replica_{r}.npy")
        np.save(files["arrays"][-1], replica)
        files["films"].append(folder / f"film_{r}.npy")
        np.save(files["films"][-1], as_film(replica, scene).astype(np.float32))
        files["captures"].append(write_relay_wall_capture(folder / f"capture_{r}.h5", replica, scene, scene_info={}))
    return files


def test_a_mitransient_film_of_our_render_agrees_and_every_format_reads_the_same(rendered):
    from validation.check import read_data

    folder, scene_file, scene, replicas = rendered
    files = save_formats(folder, scene, replicas)
    for r, replica in enumerate(replicas):
        assert np.array_equal(read_data(files["arrays"][r], scene), replica)
        assert np.array_equal(read_data(files["captures"][r], scene), replica)
        assert np.array_equal(read_data(files["films"][r], scene), replica.astype(np.float32))
    status, metrics = check(folder, scene_file, files["films"], "films")
    assert status == 0 and metrics["agrees"] is True, metrics["diagnosis"]
    assert abs(metrics["fit"]["scale"] - 1) < 4 * metrics["fit"]["scale_stderr"]
    assert (folder / "films" / "check_scan_z.png").is_file()
    assert "check_scan_z.png" in (folder / "films" / "report.md").read_text()


@pytest.mark.slow
def test_every_format_gives_the_same_verdict(rendered):
    folder, scene_file, scene, replicas = rendered
    verdicts = {}
    (folder / "formats").mkdir(exist_ok=True)
    for name, files in save_formats(folder / "formats", scene, replicas).items():
        status, metrics = check(folder, scene_file, files, name)
        assert status == 0 and metrics["agrees"] is True, (name, metrics["diagnosis"])
        verdicts[name] = (metrics["chi2_per_dof"], metrics["max_abs_z"])
    assert verdicts["arrays"] == verdicts["captures"]                          # the same float64 numbers
    assert np.allclose(verdicts["films"], verdicts["arrays"], rtol=1e-3)       # float32 storage only


def test_a_film_read_with_its_grid_transposed_disagrees(rendered):
    """The films go through the command's reader, then the verdict through ``check_transient`` in this
    process: the command's report (three figures, ~10 s) adds nothing to the orientation's power, and the
    test above holds the command's files and exit status."""
    from validation.check import check_transient, read_data

    folder, scene_file, scene, replicas = rendered
    read = []
    for r, replica in enumerate(replicas):
        np.save(folder / f"transposed_{r}.npy", as_film(replica, scene).transpose(1, 0, 2, 3))   # column-major
        read.append(read_data(folder / f"transposed_{r}.npy", scene))
    result = check_transient(scene, np.stack(read))
    assert not result.verdict and not result.agrees and not result.agrees_after_fit, result.summary()
    # the same films read the right way agree: the transposition alone makes the difference
    assert check_transient(scene, np.stack([read_data(_saved_film(folder, scene, replica, r), scene)
                                            for r, replica in enumerate(replicas)])).agrees


@pytest.mark.parametrize("array, words", [
    (np.ones((3, 4, 30, 1)), r"film of H x W = 3 x 4 points and 30 bins, the scene's 3 x 3 and 30 bins"),
    (np.ones((3, 3, 29, 1)), r"film of H x W = 3 x 3 points and 29 bins"),
    (np.ones((3, 3, 30, 2)), "2 channels"),
    (np.ones((3, 3, 2, 2, 30, 1)), r"needs mitransient's \(H, W, T, C\) film"),
    (np.ones((10, 30)), r"shape \(10, 30\) does not match the scene's 9 pairs x 30 bins"),
])
def test_mismatched_films_are_refused_in_one_line(tmp_path, capsys, array, words):
    scene_file = write_relay_wall_file(tmp_path, scene_of())
    files = []
    for r in range(3):
        files.append(tmp_path / f"film_{r}.npy")
        np.save(files[-1], array * (1 + r))
    assert run("check", scene_file, "--data", *files, "--out", tmp_path / "out") == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("diffuse-imaging: error:"), lines
    assert __import__("re").search(words, lines[0]), lines[0]
    assert not (tmp_path / "out").exists()


def test_irradiancemeter_convention_is_refused_for_a_relay_wall(tmp_path, capsys):
    scene_file = write_relay_wall_file(tmp_path, scene_of())
    np.save(tmp_path / "y.npy", np.ones((9, 30)))
    assert run("check", scene_file, "--data", tmp_path / "y.npy", "--expect", "irradiancemeter",
               "--out", tmp_path / "out") == 2
    assert "nlos_capture_meter reads the model's own units" in capsys.readouterr().err


def test_a_render_more_precise_than_the_scenes_tolerance_agrees(tmp_path):
    """A 1 mm hidden square renders to ~1e-12 of its value, under the model's 1e-6: check evaluates the model
    tighter instead of failing the render on the model's own error (χ²/dof 425 against the 1e-6 model)."""
    scene = scene_of(pixels=1, reflectance=0.5, center=(0.0, 0.0, 1.0), u=(0.001, 0.0, 0.0), v=(0.0, -0.001, 0.0),
                     scan=Scan(type="single", grid=(2, 2)), sampling=Sampling(bin_width_opl=0.01, start_opl=2.22,
                                                                              count=1))
    replicas = our_replicas(scene, spp=2**16)
    scene_file = write_relay_wall_file(tmp_path, scene)
    for r, replica in enumerate(replicas):
        np.save(tmp_path / f"replica_{r}.npy", replica)
    mean, error = replicas.mean(axis=0), replicas.std(axis=0, ddof=1) / np.sqrt(len(replicas))
    lit = mean > 0
    assert np.max(error[lit] / mean[lit]) < 1e-8               # the case: far under the scene's tolerance
    status, metrics = check(tmp_path, scene_file, sorted(tmp_path.glob("replica_*.npy")), "out")
    assert status == 0 and metrics["agrees"], metrics["diagnosis"]
    assert metrics["model_tolerance"] is not None and metrics["model_tolerance"] < scene.tolerance
