"""Issue 22's second probe (its harness and promises: tests/probe/cli_probe.py): TOML oddities, each run through
``forward``: accepted as the same scene, or refused naming the key.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from probe.cli_probe import GOOD, Probe, case_table, case_test, forward


CASES, case = case_table()


def _toml_answer(kind_name: str, text_of, expected: str = "exit 0, y equal to the midpoint reference"):
    def run(probe: Probe):
        if forward(probe, probe.file("scene.toml", text_of(GOOD.toml()))).answered():
            probe.matches_reference(GOOD)
    case("toml", kind_name, expected)(run)


def _toml_refusal(kind_name: str, text_of, *words: str):
    def run(probe: Probe):
        forward(probe, probe.file("scene.toml", text_of(GOOD.toml()))).refused(*words)
    case("toml", kind_name, f"exit 2, one line naming {', '.join(words) or 'the file'}, no --out")(run)


_toml_answer("CRLF line endings", lambda t: t.replace("\n", "\r\n"))
_toml_answer("UTF-8 BOM and CRLF", lambda t: "\ufeff" + t.replace("\n", "\r\n"))
_toml_answer("tabs, blank lines and trailing comments",
             lambda t: "\n\n".join("\t" + line + "\t# note" if "=" in line else line for line in t.splitlines()))
_toml_answer("top-level dotted keys instead of tables",
             lambda t: "plane.size = 1.0\nplane.pixels = 8\nplane.reflectance = 0.5\n"
                       "source.position = [0.5, 0.5, 1.0]\nsensors.positions = [[0.2, 0.7, 1.0]]\n"
                       "sampling.period = 0.1\nsampling.start = 1.9\nsampling.count = 12\n")
_toml_answer("inline tables", lambda t: "plane = { size = 1.0, pixels = 8, reflectance = 0.5 }\n"
                                         "source = { position = [0.5, 0.5, 1.0] }\n"
                                         "sensors = { positions = [[0.2, 0.7, 1.0]] }\n"
                                         "sampling = { period = 0.1, start = 1.9, count = 12 }\n")
_toml_answer("quoted table names", lambda t: t.replace("[plane]", '["plane"]').replace("[sampling]", "['sampling']"))
_toml_answer("integer with underscores (count = 1_2)", lambda t: t.replace("count = 12", "count = 1_2"))
_toml_answer("hexadecimal pixels (0x8)", lambda t: t.replace("pixels = 8", "pixels = 0x8"))
_toml_answer("octal pixels (0o10)", lambda t: t.replace("pixels = 8", "pixels = 0o10"))
_toml_answer("binary pixels (0b1000)", lambda t: t.replace("pixels = 8", "pixels = 0b1000"))
_toml_answer("capital exponent (period = 1E-1)", lambda t: t.replace("period = 0.1", "period = 1E-1"))
_toml_answer("positive sign and integers in a point (+1)",
             lambda t: t.replace("[0.5, 0.5, 1.0]", "[0.5, 0.5, +1]"))
_toml_answer("literal string waveform ('impulse')", lambda t: t.replace('"impulse"', "'impulse'"))
_toml_answer("multi-line string waveform", lambda t: t.replace('"impulse"', '"""impulse"""'))
_toml_answer("a 200 kB comment line", lambda t: "# " + "x" * 200_000 + "\n" + t)


@case("toml", "start = -1e-400 (underflows to -0.0)", "exit 0, window from 0 (mostly empty: a one-line warning): "
                                                       "y equal to the reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, start=0.0, count=40)
    text = geometry.toml().replace("start = 0.0", "start = -1e-400")
    if forward(probe, probe.file("scene.toml", text)).answered(warnings=True):
        probe.matches_reference(geometry)


@case("toml", "pixels = 8.0 (a whole float)", "exit 2 naming plane.pixels, or exit 0 with M = 8")
def _(probe):
    if forward(probe, probe.file("scene.toml", GOOD.toml().replace("pixels = 8", "pixels = 8.0"))) \
            .refused_or_answered("plane.pixels"):
        probe.matches_reference(GOOD)


_toml_refusal("CR-only (old Mac) line endings", lambda t: t.replace("\n", "\r"), "scene.toml")
_toml_refusal("quoted key with a dot (\"plane.size\" = 1)", lambda t: '"plane.size" = 1.0\n' + t, "plane.size")
_toml_refusal("pixels = 8.5", lambda t: t.replace("pixels = 8", "pixels = 8.5"), "plane.pixels")
_toml_refusal("size = 1e400 (overflows to inf)", lambda t: t.replace("size = 1.0", "size = 1e400"), "plane.size")
_toml_refusal("waveform with a trailing space", lambda t: t.replace('"impulse"', '"impulse "'),
              "illumination.waveform")
_toml_refusal("table [Plane] capitalised", lambda t: t.replace("[plane]", "[Plane]"), "Plane")
_toml_refusal("[[sensors]] array of tables",
              lambda t: t.replace("[sensors]\npositions = [[0.2, 0.7, 1.0]]",
                                  "[[sensors]]\npositions = [[0.2, 0.7, 1.0]]"), "sensors")
_toml_refusal("a string inside the source position", lambda t: t.replace("[0.5, 0.5, 1.0]", '[0.5, 0.5, "1"]'),
              "source.position")
_toml_refusal("four coordinates for the source", lambda t: t.replace("[0.5, 0.5, 1.0]", "[0.5, 0.5, 1.0, 0.0]"),
              "source.position")
_toml_refusal("sensors.positions flat, not nested",
              lambda t: t.replace("[[0.2, 0.7, 1.0]]", "[0.2, 0.7, 1.0]"), "sensors.positions")
_toml_refusal("only comments and blank lines", lambda t: "# a scene\n\n# nothing else\n", "scene.toml")
_toml_refusal("larger than 1 MiB", lambda t: t + "# " + "x" * (1 << 20) + "\n", "scene.toml")
_toml_refusal("name inside [plane]", lambda t: t.replace("[plane]\n", '[plane]\nname = "x"\n'), "plane.name")
_toml_refusal("unknown key sigma_ in [noise]", lambda t: t + "[noise]\nsigma_ = 0.1\n", "noise.sigma_")
_toml_refusal("tolerance = 0.1 (upper bound excluded)", lambda t: t + "tolerance = 0.1\n", "model.tolerance")
_toml_refusal("tolerance = 1e-11 (below 1e-10)", lambda t: t + "tolerance = 1e-11\n", "model.tolerance")
_toml_refusal("butterworth order 21", lambda t: t.replace('"impulse"', '"butterworth"\norder = 21'),
              "illumination.order")
_toml_refusal("intensity just above 1e30", lambda t: t.replace("intensity = 1.0", "intensity = 1.0000001e30"),
              "source.intensity")
_toml_refusal("sensor 1e-10 above the plane (below 1e-9 of the extent)",
              lambda t: t.replace("[[0.2, 0.7, 1.0]]", "[[0.2, 0.7, 1e-10]]"), "sensors.positions")
_toml_refusal("grid of 25 x 41 = 1025 sensors",
              lambda t: t.replace("positions = [[0.2, 0.7, 1.0]]", "grid = [25, 41]\ncenter = [0.5, 0.5, 1.0]"),
              "sensors.grid")
_toml_refusal("[relay_wall] on a plane scene (NLOS keys mixed in)", lambda t: t + "[relay_wall]\nsize = [2.0, 2.0]\n",
              "relay_wall")


@case("toml", "scene path /dev/null", "exit 2, one line naming the device")
def _(probe):
    forward(probe, "/dev/null").refused("/dev/null")


@case("toml", "scene file name with a space and an accent", "exit 0, meta.json scene = the stem 'my scène'")
def _(probe):
    if forward(probe, probe.scene(name="my scène.toml")).answered():
        probe.matches_reference(GOOD)
        probe.check(probe.meta().get("scene") == "my scène", f"meta scene {probe.meta().get('scene')!r}")


@case("toml", "scene file name starting with '-' given bare", "exit 2, argparse's one line")
def _(probe):
    probe.scene(name="-scene.toml")
    probe.cli("forward", "-scene.toml", "--out", probe.out).refused()


@case("toml", "empty [noise] table: every noise default", "exit 0, transient_noisy.npy = y + N(0, 0.1²)")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra="[noise]\n"))).answered():
        y, noisy = probe.matches_reference(GOOD), probe.y("transient_noisy.npy")
        if y is not None and noisy is not None:
            noise = noisy - y
            probe.check(np.all(np.abs(noise) < 6 * 0.1) and np.any(noise != 0), f"noise {noise}")


test_case = case_test(CASES)
