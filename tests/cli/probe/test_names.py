"""Issue 22's second probe (its harness and promises: tests/probe/cli_probe.py): names and paths: odd file names,
links, the ``--out`` folder and what a command may write.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from probe.cli_reference import GREY_LEVELS, png_bytes
from probe.cli_probe import GOOD, LOCK_FILE, TEMPORARY_PREFIX, case_table, case_test, forward


CASES, case = case_table()


@case("paths", "--out with spaces, accents and an emoji", "exit 0; files there")
def _(probe):
    probe.out = probe.tmp / "out put é 🙂"
    if forward(probe, probe.scene()).answered():
        probe.matches_reference(GOOD)


@case("paths", "--out=DIR (one argument)", "exit 0; files there")
def _(probe):
    probe.cli("forward", probe.scene(), f"--out={probe.out}", "--quiet")
    if probe.answered():
        probe.matches_reference(GOOD)


@case("paths", "--out a link to a folder", "exit 0; files in the link's target")
def _(probe):
    target = probe.tmp / "target"
    target.mkdir()
    os.symlink(target, probe.tmp / "link")
    probe.out = probe.tmp / "link"
    if forward(probe, probe.scene(), outside_changes=True).answered():
        probe.check((target / "transient.npy").is_file(), "nothing in the link's target")


@case("paths", "--out/transient.npy a link to a user's file outside",
      "exit 0; the link replaced by the file, the user's file untouched")
def _(probe):
    user = probe.file("thesis/data.npy", b"the user's own bytes")
    probe.out.mkdir()
    os.symlink(user, probe.out / "transient.npy")
    if forward(probe, probe.scene()).answered():
        probe.check(user.read_bytes() == b"the user's own bytes", "the user's file was written through the link")
        probe.check(not (probe.out / "transient.npy").is_symlink(), "transient.npy is still a link")
        probe.matches_reference(GOOD)


@case("paths", "--out/transient.npy is a folder", "exit 2, one line naming transient.npy; --out as it was")
def _(probe):
    (probe.out / "transient.npy").mkdir(parents=True)
    forward(probe, probe.scene()).refused("transient.npy")


@case("paths", "--out/meta.json is a folder holding a file", "exit 2, one line naming meta.json; --out as it was")
def _(probe):
    (probe.out / "meta.json").mkdir(parents=True)
    (probe.out / "meta.json" / "keep.txt").write_text("mine")
    forward(probe, probe.scene()).refused("meta.json")


@case("paths", "--out holds a user's look-alike temporaries and notes",
      "exit 0; .x.tmp-1, .diffuse-imaging-tmp-notmine and notes.txt untouched")
def _(probe):
    probe.out.mkdir()
    mine = {".x.tmp-1": "a", f"{TEMPORARY_PREFIX}notmine": "b", "notes.txt": "c",
            f"{TEMPORARY_PREFIX}zzzzzzzz-1-transient.npy": "d"}
    for name, text in mine.items():
        (probe.out / name).write_text(text)
    if forward(probe, probe.scene()).answered():
        for name, text in mine.items():
            probe.check((probe.out / name).is_file() and (probe.out / name).read_text() == text, f"{name} touched")


@case("paths", "--out holds a stale lock file (a dead process's id)", "exit 0; no lock file left")
def _(probe):
    probe.out.mkdir()
    (probe.out / LOCK_FILE).write_text("999999999")
    if forward(probe, probe.scene()).answered():
        probe.check(not (probe.out / LOCK_FILE).exists(), "the lock file is left")
        probe.matches_reference(GOOD)


@case("paths", "--out below a file (scene.toml/out)", "exit 2, one line")
def _(probe):
    scene = probe.scene()
    probe.out = scene / "out"
    forward(probe, scene).refused("out")


@case("paths", "--out is the scene file", "exit 2, one line naming the file; the scene untouched")
def _(probe):
    scene = probe.scene()
    probe.out = scene
    forward(probe, scene).refused("scene.toml")


@case("paths", "--out is a FIFO", "exit 2, one line naming the FIFO")
def _(probe):
    os.mkfifo(probe.out)
    forward(probe, probe.scene()).refused("FIFO")


@case("paths", "--out 60 folders deep", "exit 0; files at the bottom")
def _(probe):
    probe.out = probe.tmp.joinpath(*["d"] * 60)
    if forward(probe, probe.scene(), outside_changes=True).answered():
        probe.matches_reference(GOOD)


@case("paths", "--out of 5000 bytes in names of 200", "exit 2, one line (path too long)")
def _(probe):
    probe.out = probe.tmp.joinpath(*["n" * 200] * 25)
    forward(probe, probe.scene()).refused()
    probe.check(not (probe.tmp / ("n" * 200)).exists(), "folders were left")


@case("paths", "--out the scene's own folder (user files beside)", "exit 0; the scene and the image untouched")
def _(probe):
    probe.out = probe.tmp
    probe.file("image.png", png_bytes(GREY_LEVELS[..., None], 8, 0))
    scene = probe.scene(dataclasses.replace(GOOD, reflectance=GREY_LEVELS / 255.0).toml(image="image.png"))
    before = (scene.read_bytes(), (probe.tmp / "image.png").read_bytes())
    if forward(probe, scene).answered():
        probe.check((scene.read_bytes(), (probe.tmp / "image.png").read_bytes()) == before, "user files changed")


@case("paths", "--out on a read-only file system (/proc/...)", "exit 2, one line")
def _(probe):
    probe.out = Path("/proc/diffuse-imaging-probe")
    forward(probe, probe.scene()).refused("/proc/diffuse-imaging-probe")


@case("paths", "export of a scene named 'a/../../b' (file name)", "exit 0; every file inside --out")
def _(probe):
    scene = probe.scene(GOOD.toml().replace("[plane]", 'name = "a/../../b"\n[plane]'))
    probe.cli("export", scene, "--format", "mitsuba", "--out", probe.out, "--quiet")
    if probe.answered():
        probe.check((probe.out / "scene.xml").is_file(), "no scene.xml")


@case("paths", "export --format mitransient of a paper-attenuation scene", "exit 2, one line; no --out")
def _(probe):
    scene = probe.scene(dataclasses.replace(GOOD, attenuation="paper"))
    probe.cli("export", scene, "--format", "mitransient", "--out", probe.out, "--quiet").refused("paper")


@case("paths", "validate of scenes named '', '.', '..' and 300 x 'a'",
      "exit 0; every folder inside --out, none outside")
def _(probe):
    scenes = []
    for index, name in enumerate(["", ".", "..", "a" * 300]):
        scenes.append(probe.scene(GOOD.toml().replace("[plane]", f'name = "{name}"\n[plane]'), f"s{index}.toml"))
    probe.cli("validate", *scenes, "--spp", "4096", "--fast", "--out", probe.out, "--quiet")
    if probe.refused_or_answered("name"):
        probe.check((probe.out / "report.md").is_file(), "no report.md")


test_case = case_test(CASES)
