"""Issue 22's second probe (its harness and promises: tests/probe/cli_probe.py): data files for ``check`` and
``reconstruct``: formats, shapes, planted conventions and bad values.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from probe.cli_reference import GREY_LEVELS, png_bytes, reference
from probe.cli_probe import GOOD, Probe, case_table, case_test, check_command, forward, noisy_data


CASES, case = case_table()


def _fit_near(probe: Probe, scale: float, offset: float):
    fit = probe.metrics().get("fit") or {}
    for key, value in (("scale", scale), ("offset_opl", offset)):
        error = fit.get(f"{key.split('_')[0]}_stderr")
        if probe.check(key in fit and error is not None, f"no fit {key}: {fit}"):
            probe.check(abs(fit[key] - value) <= 4 * error + 1e-12,
                        f"fit {key} {fit[key]} ± {error}, expected {value}")


@case("data", "check: reference + noise with its stderr", "exit 0 (agrees); scale 1 and offset 0 within 4 se")
def _(probe):
    data, stderr = noisy_data()
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.answered():
        _fit_near(probe, 1.0, 0.0)


@case("data", "check: twice the reference", "exit 1 (disagrees as given); scale 2 within 4 se")
def _(probe):
    data, stderr = noisy_data(scale=2.0)
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.answered(status=1):
        _fit_near(probe, 2.0, 0.0)


@case("data", "check: a window read 0.02 m short", "exit 1; offset +0.02 m within 4 se, scale 1")
def _(probe):
    data, stderr = noisy_data(shift=0.02, relative_error=0.002)
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.answered(status=1):
        _fit_near(probe, 1.0, 0.02)


for _label, _convert in (("float32", lambda a: a.astype(np.float32)), ("big-endian >f8", lambda a: a.astype(">f8")),
                         ("Fortran order", np.asfortranarray), ("float16", lambda a: a.astype(np.float16))):
    @case("data", f"check: data as {_label}", "exit 0 (agrees); scale 1 within 4 se")
    def _(probe, convert=_convert):
        data, stderr = noisy_data()
        check_command(probe, probe.npy("y.npy", convert(data)), probe.npy("se.npy", convert(stderr)))
        if probe.answered():
            _fit_near(probe, 1.0, 0.0)


@case("data", "check: three replicas", "exit 0 (agrees, t with 2 dof); scale 1 within 4 se")
def _(probe):
    files = [probe.npy(f"r{seed}.npy", noisy_data(relative_error=0.02, seed=seed)[0]) for seed in range(3)]
    check_command(probe, files)
    if probe.answered(warnings=True):       # a one-line warning: few replicas
        _fit_near(probe, 1.0, 0.0)


@case("data", "check: mitransient films (K, 1, 1, N, 3) x 1/4, --expect-scale 0.25",
      "exit 0 (agrees as stated); scale 0.25 within 4 se")
def _(probe):
    files = []
    for seed in range(4):
        film = 0.25 * noisy_data(seed=seed)[0]
        files.append(probe.npy(f"film{seed}.npy", np.repeat(film[:, None, None, :, None], 3, axis=-1)))
    check_command(probe, files, None, "--expect-scale", "0.25")
    if probe.answered(warnings=True):
        _fit_near(probe, 0.25, 0.0)


@case("data", "check: stderr 0 in the bins without light", "exit 0 with finite metrics, or a one-line refusal")
def _(probe):
    data, stderr = noisy_data()
    truth, _ = reference(GOOD)
    dark = truth == 0
    data[dark], stderr[dark] = 0.0, 0.0
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.refused_or_answered("stderr"):
        text = (probe.out / "metrics.json").read_text()
        probe.check("NaN" not in text and "Infinity" not in text, "metrics.json not finite")


@case("data", "check: the negated reference", "exit 1 with finite metrics, or a one-line refusal")
def _(probe):
    data, stderr = noisy_data(scale=-1.0)
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.status != 2:
        probe.answered(status=1)


def data_refusal(name: str, make, *words: str, command: str = "check"):
    @case("data", f"{command}: {name}", f"exit 2, one line naming {', '.join(words)}, no --out")
    def _(probe):
        files = make(probe)
        data, stderr = (files, None) if not isinstance(files, tuple) else files
        if command == "check":
            check_command(probe, data, stderr)
        else:
            probe.cli("reconstruct", probe.scene(), "--data", data, "--out", probe.out, "--quiet")
        probe.refused(*words)


class _Planted:
    """Unpickling this object creates a marker folder: a .npy loader must never unpickle."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def _se(probe: Probe) -> Path:
    """The standard error file that goes with :func:`_data`."""
    return probe.npy("se.npy", noisy_data()[1])


def _npz(probe: Probe) -> Path:
    np.savez(probe.tmp / "y.npz", y=noisy_data()[0])
    return probe.tmp / "y.npz"

data_refusal("bool data", lambda p: (p.npy("y.npy", noisy_data()[0] > 0), _se(p)), "y.npy", "bool")
data_refusal("a pickled object array (never unpickled)",
             lambda p: (p.npy("y.npy", np.array([_Planted(str(p.tmp / "PWNED"))], dtype=object), allow_pickle=True),
                        _se(p)), "y.npy")
data_refusal("a structured dtype",
             lambda p: (p.npy("y.npy", np.zeros((1, 12), dtype=[("a", "f8"), ("b", "f8")])), _se(p)), "y.npy")
data_refusal("shape (1, 13)", lambda p: (p.npy("y.npy", np.ones((1, 13))), _se(p)), "(1, 13)")
data_refusal("transposed (12, 1)", lambda p: (p.npy("y.npy", noisy_data()[0].T), _se(p)), "transposed")
data_refusal("a 0-byte .npy", lambda p: (p.file("y.npy", b""), _se(p)), "y.npy")
data_refusal("a .npy cut short", lambda p: (p.file("y.npy", p.npy("whole.npy", noisy_data()[0]).read_bytes()[:-40]),
                                            _se(p)), "y.npy")
data_refusal("an .npz", lambda p: (_npz(p), _se(p)), "y.npz")
data_refusal("a .csv", lambda p: (p.file("y.csv", ",".join(map(str, noisy_data()[0][0])) + "\n"), _se(p)), "y.csv")
data_refusal("stderr with a negative bin",
             lambda p: (p.npy("y.npy", noisy_data()[0]),
                        p.npy("se.npy", noisy_data()[1] * np.where(np.arange(12) == 4, -1, 1))),
             "negative")
data_refusal("stderr with a NaN",
             lambda p: (p.npy("y.npy", noisy_data()[0]),
                        p.npy("se.npy", np.where(np.arange(12) == 4, np.nan, noisy_data()[1]))),
             "se.npy")
data_refusal("stderr of shape (1, 11)", lambda p: (p.npy("y.npy", noisy_data()[0]), p.npy("se.npy", np.ones((1, 11)))),
             "(1, 11)")
data_refusal("replicas of two shapes", lambda p: [p.npy("a.npy", noisy_data()[0]), p.npy("b.npy", noisy_data()[0]),
                                                  p.npy("c.npy", np.ones((1, 13)))], "(1, 13)")
data_refusal("one file given three times", lambda p: [p.npy("a.npy", noisy_data()[0])] * 3, "zero spread")
data_refusal("film of 2 x 2 pixels", lambda p: [p.npy(f"f{i}.npy", np.ones((1, 2, 2, 12, 1))) for i in range(3)],
             "2 x 2")
data_refusal("film with unequal R, G, B", lambda p: [p.npy(f"f{i}.npy", np.stack(
    [noisy_data(seed=i)[0], noisy_data(seed=i)[0], 2 * noisy_data(seed=i)[0]], -1)[:, None, None]) for i in range(3)],
             "channels")
data_refusal("an HDF5 file that is text", lambda p: (p.file("y.h5", "not hdf5\n"), None), "y.h5")
data_refusal("data two sensors for a one-sensor scene", lambda p: p.npy("y.npy", np.ones((2, 12))), "(2, 12)",
             command="reconstruct")
data_refusal("data /dev/zero", lambda p: "/dev/zero", "/dev/zero", command="reconstruct")


@case("data", "check: a pickled object array never runs its payload", "the payload's folder does not appear")
def _(probe):
    marker = probe.tmp / "PWNED"
    data = probe.npy("y.npy", np.array([_Planted(str(marker))], dtype=object), allow_pickle=True)
    check_command(probe, data, probe.npy("se.npy", noisy_data()[1]))
    probe.check(not marker.exists(), "the pickle ran")


@case("data", "check: our own forward folder's h5 (tal layout), --shape-only", "exit 0; agrees by shape")
def _(probe):
    scene = probe.scene()
    forward(probe, scene)
    model = probe.tmp / "model"
    probe.out.rename(model)
    check_command(probe, model / "transient.h5", None, "--shape-only", scene=scene)
    probe.answered()


def _capture_case(name: str, change, *words: str):
    """Our forward's transient.h5 (tal's layout), changed by ``change(h5 file)``, given to check."""
    @case("data", f"check: tal capture with {name}", f"exit 2, one line naming {', '.join(words)}, no --out")
    def _(probe):
        import h5py

        scene = probe.scene()
        forward(probe, scene)
        capture = probe.tmp / "capture.h5"
        (probe.out / "transient.h5").rename(capture)
        import shutil

        shutil.rmtree(probe.out)
        with h5py.File(capture, "r+") as handle:
            change(handle)
        check_command(probe, capture, None, "--shape-only", scene=scene).refused(*words)


def _replace(name, value):
    def change(handle):
        del handle[name]
        handle[name] = value
    return change


_capture_case("no H", lambda handle: handle.__delitem__("H"), "H")
_capture_case("delta_t = -0.1", _replace("delta_t", -0.1), "capture.h5")
_capture_case("a NaN in H", _replace("H", np.where(np.arange(12)[:, None] == 3, np.nan, 0.01)), "NaN")
_capture_case("the sensor moved 1 cm", _replace("sensor_grid_xyz", np.array([[0.21, 0.7, 1.0]])), "sensor")
_capture_case("H as text", _replace("H", np.array([b"not numbers"])), "H")
data_refusal("data with a NaN",
             lambda p: (p.npy("y.npy", np.where(np.arange(12) == 2, np.nan, noisy_data()[0])), _se(p)), "NaN")
data_refusal("a 0-byte .npy", lambda p: p.file("y.npy", b""), "y.npy", command="reconstruct")
data_refusal("data with an infinity", lambda p: p.npy("y.npy", np.where(np.arange(12) == 2, np.inf, noisy_data()[0])),
             "inf", command="reconstruct")


@case("data", "reconstruct: the reference with --lambda 1e-300", "exit 0 with a finite image, or a one-line refusal")
def _(probe):
    data = probe.npy("y.npy", reference(GOOD)[0])
    probe.cli("reconstruct", probe.scene(), "--data", data, "--lambda", "1e-300", "--out", probe.out, "--quiet")
    if probe.refused_or_answered("--lambda", warnings=True):
        probe.y("reconstruction.npy")


@case("data", "reconstruct: all-zero data", "exit 0 with a finite image, or a one-line refusal")
def _(probe):
    data = probe.npy("y.npy", np.zeros((1, 12)))
    probe.cli("reconstruct", probe.scene(), "--data", data, "--out", probe.out, "--quiet")
    if probe.refused_or_answered("0", warnings=True):
        probe.y("reconstruction.npy")


@case("data", "reconstruct: --lambda-range 1e-300 1e300 --lambda-count 3", "exit 0 finite, or a one-line refusal")
def _(probe):
    data = probe.npy("y.npy", noisy_data()[0])
    probe.cli("reconstruct", probe.scene(), "--data", data, "--lambda", "gcv", "--lambda-range", "1e-300", "1e300",
              "--lambda-count", "3", "--out", probe.out, "--quiet")
    if probe.refused_or_answered("--lambda", warnings=True):
        probe.y("reconstruction.npy")


@case("data", "reconstruct: our forward's EXR at I = 1e30", "exit 0; a finite image and finite metrics")
def _(probe):
    scene = probe.scene(dataclasses.replace(GOOD, intensity=1e30, reflectance=GREY_LEVELS / 255.0).toml(image="i.png"))
    probe.file("i.png", png_bytes(GREY_LEVELS[..., None], 8, 0))
    forward(probe, scene)
    (probe.tmp / "model").mkdir()
    for name in ("transient.exr", "meta.json"):
        (probe.out / name).rename(probe.tmp / "model" / name)
    import shutil

    shutil.rmtree(probe.out)
    probe.cli("reconstruct", scene, "--data", probe.tmp / "model" / "transient.exr", "--out", probe.out, "--quiet")
    if probe.answered(warnings=True):              # one sensor cannot fix 64 pixels: A's rank, in one line
        probe.y("reconstruction.npy")
        text = (probe.out / "metrics.json").read_text()
        probe.check("NaN" not in text and "Infinity" not in text, "metrics.json not finite")


test_case = case_test(CASES)
