"""Every malformed or extreme input: exit status 2, one line naming the problem and no files,
or a finite answer equal to an independent reference.

The scene keys go through ``forward`` (in this process, for speed): each key
gets wrong types, 0, negative values, -0.0, NaN, infinities, 5e-324, 1e308
and huge integers. Legal extremes must give the brute-force reference of
:mod:`brute_force` (midpoint samples, binned; ~1 % accurate).
"""

from __future__ import annotations

import numpy as np
import pytest

from analytic.scenes.scene_file import load_scene
from brute_force import binned_transient, path_length_range, sensor_totals
from scene_files import GOOD, write_scene
from validation.cli import main

BAD_TYPES = {"text": '"x"', "bool": "true", "list": "[1, 2]", "table": "{ a = 1 }"}
NUMBERS = {"zero": "0", "negative": "-1", "negative_zero": "-0.0", "nan": "nan", "inf": "inf",
           "minus_inf": "-inf", "subnormal": "5e-324", "huge": "1e308",
           "huge_integer": "9223372036854775807"}


def _lines(key: str, value: str) -> tuple[str, str]:
    """(TOML text, the key an error must name) with ``key`` set to ``value`` in GOOD."""
    if key == "name":
        return f"name = {value}\n" + GOOD, "name"
    table, name = key.split(".")
    if table == "noise":
        kind = 'kind = "poisson"\n' if name == "photons" else ""
        return GOOD + f"\n[noise]\n{kind}{name} = {value}\n", key
    if table == "illumination" and name != "waveform":
        waveform = "square" if name == "width" else "butterworth"
        text = GOOD.replace('waveform = "impulse"', f'waveform = "{waveform}"\n{name} = {value}')
        return text, key
    section = f"[{table}]\n"
    start = GOOD.index(section) + len(section)
    end = GOOD.find("\n[", start)
    body = GOOD[start:end if end > 0 else len(GOOD)]
    entries = [line for line in body.strip().splitlines() if not line.startswith(f"{name} =")]
    text = GOOD[:start] + "\n".join(entries + [f"{name} = {value}"]) + "\n" + GOOD[end if end > 0 else len(GOOD):]
    return text, key


# key -> the NUMBERS that are legal for it (everything else must be refused)
LEGAL_NUMBERS = {
    "plane.size": set(),
    "plane.pixels": set(),
    "plane.reflectance": {"zero", "negative_zero", "subnormal"},
    "source.intensity": {"huge_integer"},   # a subnormal intensity: y below float64's normal range (refused)
    "sampling.period": set(),
    "sampling.start": {"zero", "negative", "negative_zero", "subnormal"},
    "sampling.count": set(),
    "model.tolerance": set(),
    "illumination.width": {"subnormal", "huge", "huge_integer"},
    "noise.sigma": {"zero", "negative_zero", "subnormal", "huge_integer"},
    "noise.photons": {"subnormal"},
    "noise.seed": {"zero", "negative_zero"},
    "sensors.extent": set(),
}
# keys that take a number, with a value that is legal (for the text-type cases' replacement)
NUMERIC_KEYS = sorted(LEGAL_NUMBERS)

CASES = []
for key in NUMERIC_KEYS:
    for label, value in BAD_TYPES.items():
        if key == "plane.reflectance" and label == "text":
            continue            # a string is an image path: tested with the files below
        CASES.append((key, label, value, False))
    for label, value in NUMBERS.items():
        CASES.append((key, label, value, label in LEGAL_NUMBERS[key]))
# points: each coordinate of the source and of a sensor
for key, position in (("source.position", "[0.5, 0.5, {}]"), ("sensors.positions", "[[0.2, 0.7, {}]]")):
    for label, value in NUMBERS.items():
        legal = label in ("huge_integer",) and False
        CASES.append((key, f"z_{label}", position.format(value), legal))
    for label, value in {**BAD_TYPES, "short": "[0.5, 0.5]", "empty": "[]"}.items():
        CASES.append((key, label, value, False))
for label, value in {**BAD_TYPES, "unknown": '"laser"', "case": '"Impulse"'}.items():
    CASES.append(("illumination.waveform", label, value, False))
for label, value in {**BAD_TYPES, "unknown": '"phong"'}.items():
    CASES.append(("model.attenuation", label, value, False))
for label, value in {**BAD_TYPES, "unknown": '"uniform"'}.items():
    CASES.append(("noise.kind", label, value, False))
for label, value in {"number": "3", "bool": "true", "list": "[1]",
                     # a name labels reports and printed lines: one line of printable text (a file's
                     # C0 controls, a NUL or a newline, are escaped as \xNN when it is read; these are not)
                     "bidi_override": '"a\\u202eb"', "line_separator": '"a\\u2028b"',
                     "next_line": '"a\\u0085b"'}.items():
    CASES.append(("name", label, value, False))
for label, value in {"zero": "[0, 4]", "negative": "[-1, 4]", "huge": "[100000, 100000]",
                     "one": "[4]", "float": "[1.5, 2]", "text": '"4x4"'}.items():
    CASES.append(("sensors.grid", label, value, False))


def _grid_text(value: str) -> str:
    return GOOD.replace("positions = [[0.2, 0.7, 1.0]]", f"grid = {value}\ncenter = [0.5, 0.5, 1.0]")


def _extent_text(value: str) -> str:
    return GOOD.replace("positions = [[0.2, 0.7, 1.0]]", f"grid = [2, 2]\nextent = {value}\ncenter = [0.5, 0.5, 1.0]")


def _scene_text(key: str, value: str) -> tuple[str, str]:
    if key == "sensors.grid":
        return _grid_text(value), "sensors.grid"
    if key == "sensors.extent":
        return _extent_text(value), "sensors.extent"
    return _lines(key, value)


def test_the_table_has_at_least_150_cases():
    assert len(CASES) >= 150


@pytest.mark.filterwarnings("default::analytic.operator.window.WindowWarning")
@pytest.mark.parametrize("key, label, value, legal", CASES,
                         ids=[f"{key}={label}" for key, label, *_ in CASES])
def test_scene_value(tmp_path, capsys, key, label, value, legal):
    text, named = _scene_text(key, value)
    path = write_scene(tmp_path, text)
    out = tmp_path / "out"
    status = main(["forward", str(path), "--out", str(out), "--quiet"])
    error = [line for line in capsys.readouterr().err.splitlines() if "warning" not in line]
    if not legal:
        assert status == 2, f"{key} = {value} was accepted"
        assert len(error) == 1 and error[0].startswith("diffuse-imaging: error:"), error
        assert named.split("[")[0] in error[0], error[0]
        assert not out.exists()
        return
    assert status == 0 and not error, error
    y = np.load(out / "transient.npy")
    assert np.all(np.isfinite(y))
    _assert_matches_reference(load_scene(path), y)


def _assert_matches_reference(scene, y):
    if scene.illumination.waveform in ("impulse", "square"):
        reference = binned_transient(scene)
        scale = max(float(np.abs(reference).max()), np.finfo(float).tiny)
        # a midpoint sample near a bin edge lands in the neighbouring bin: 3 % of the peak
        np.testing.assert_allclose(y, reference, rtol=0, atol=3e-2 * scale)
        return
    low, high = path_length_range(scene)
    edges = scene.sampling.edges
    assert edges[0] <= low and high + 3.0 / (0.5 / scene.sampling.bin_width_opl) <= edges[-1], \
        "a legal Butterworth case must have a window that holds the whole pulse"
    np.testing.assert_allclose(y.sum(axis=1), sensor_totals(scene), rtol=1e-2)


# ---------------------------------------------------------------- command-line values

def _scene(tmp_path):
    return str(write_scene(tmp_path))


def _data(tmp_path, name="y.npy", values=None):
    data = tmp_path / name
    np.save(data, np.zeros((1, 40)) if values is None else values)
    return str(data)


CLI_CASES = [
    # (id, argv (with {scene}, {data}, {out}), words the one-line error must hold)
    ("render spp missing", ["render", "{scene}", "--out", "{out}"], "--spp"),
    ("render spp 0", ["render", "{scene}", "--spp", "0", "--out", "{out}"], "--spp"),
    ("render spp 1", ["render", "{scene}", "--spp", "1", "--out", "{out}"], "--spp"),
    ("render spp -5", ["render", "{scene}", "--spp", "-5", "--out", "{out}"], "--spp"),
    ("render spp 2^70", ["render", "{scene}", "--spp", str(2**70), "--out", "{out}"], "--spp"),
    ("render spp text", ["render", "{scene}", "--spp", "many", "--out", "{out}"], "--spp"),
    ("render spp fraction", ["render", "{scene}", "--spp", "10.5", "--out", "{out}"], "--spp"),
    ("render spp nan", ["render", "{scene}", "--spp", "nan", "--out", "{out}"], "--spp"),
    ("render seed -1", ["render", "{scene}", "--spp", "64", "--seed", "-1", "--out", "{out}"], "--seed"),
    ("render seed 2^32", ["render", "{scene}", "--spp", "64", "--seed", str(2**32), "--out", "{out}"], "--seed"),
    ("render seed 2^64", ["render", "{scene}", "--spp", "64", "--seed", str(2**64), "--out", "{out}"], "--seed"),
    ("render seed text", ["render", "{scene}", "--spp", "64", "--seed", "abc", "--out", "{out}"], "--seed"),
    ("render out and resume", ["render", "{scene}", "--spp", "64", "--out", "{out}", "--resume", "{out}"],
     "--resume"),
    ("render variant bogus", ["render", "{scene}", "--spp", "64", "--variant", "scalar_rgb", "--out", "{out}"],
     "variant"),
    ("run spp 0", ["run", "{scene}", "--spp", "0", "--out", "{out}"], "--spp"),
    ("run spp 1", ["run", "{scene}", "--spp", "1", "--out", "{out}"], "--spp"),
    ("run spp -5", ["run", "{scene}", "--spp", "-5", "--out", "{out}"], "--spp"),
    ("run seed 2^32", ["run", "{scene}", "--seed", str(2**32), "--out", "{out}"], "--seed"),
    ("validate spp 0", ["validate", "{scene}", "--spp", "0", "--out", "{out}"], "--spp"),
    ("validate spp 1", ["validate", "{scene}", "--spp", "1", "--out", "{out}"], "--spp"),
    ("validate seed -1", ["validate", "{scene}", "--seed", "-1", "--out", "{out}"], "--seed"),
    ("forward tolerance 0", ["forward", "{scene}", "--tolerance", "0", "--out", "{out}"], "--tolerance"),
    ("forward tolerance -1", ["forward", "{scene}", "--tolerance", "-1", "--out", "{out}"], "--tolerance"),
    ("forward tolerance nan", ["forward", "{scene}", "--tolerance", "nan", "--out", "{out}"], "--tolerance"),
    ("forward tolerance 0.5", ["forward", "{scene}", "--tolerance", "0.5", "--out", "{out}"], "tolerance"),
    ("forward no out", ["forward", "{scene}"], "--out"),
    ("forward unknown flag", ["forward", "{scene}", "--out", "{out}", "--fast"], "--fast"),
    ("no command", [], "COMMAND"),
    ("unknown command", ["draw"], "draw"),
    ("reconstruct lambda text", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}", "--lambda",
                                 "best"], "--lambda"),
    ("reconstruct lambda 0", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}", "--lambda", "0"],
     "--lambda"),
    ("reconstruct lambda inf", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}", "--lambda",
                                "inf"], "--lambda"),
    ("reconstruct range reversed", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}",
                                    "--lambda-range", "1", "1e-3"], "--lambda-range"),
    ("reconstruct range zero", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}",
                                "--lambda-range", "0", "1"], "--lambda-range"),
    ("reconstruct count alone", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}",
                                 "--lambda-count", "4"], "--lambda-count"),
    ("reconstruct count zero", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}",
                                "--lambda-range", "1e-3", "1", "--lambda-count", "0"], "--lambda"),
    ("reconstruct discrepancy without noise", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}",
                                               "--lambda", "discrepancy"], "noise.sigma"),
    ("reconstruct data missing", ["reconstruct", "{scene}", "--data", "{out}.npy", "--out", "{out}"],
     "no such file"),
    ("reconstruct tv gcv", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}", "--regularizer",
                            "tv", "--lambda", "gcv"], "tv"),
    ("reconstruct method bogus", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}", "--method",
                                  "cholesky"], "--method"),
    ("run spp 64", ["run", "{scene}", "--spp", "64", "--out", "{out}"], "--spp"),
    ("validate spp 64", ["validate", "{scene}", "--spp", "64", "--out", "{out}"], "--spp"),
    ("run lambda discrepancy without noise", ["run", "{scene}", "--lambda", "discrepancy", "--out", "{out}"],
     "noise.sigma"),
    ("run lambda text", ["run", "{scene}", "--lambda", "best", "--out", "{out}"], "--lambda"),
    ("forward out empty", ["forward", "{scene}", "--out", ""], "--out"),
    ("render out empty", ["render", "{scene}", "--spp", "64", "--out", ""], "--out"),
    ("reconstruct data huge", ["reconstruct", "{scene}", "--data", "{huge}", "--out", "{out}"], "largest |y|"),
    ("reconstruct data complex", ["reconstruct", "{scene}", "--data", "{complex}", "--out", "{out}"],
     "real number"),
    ("reconstruct tv without a rule", ["reconstruct", "{scene}", "--data", "{data}", "--out", "{out}",
                                       "--regularizer", "tv"], "--regularizer tv"),
    ("check zeros by shape", ["check", "{scene}", "--data", "{data}", "--shape-only", "--out", "{out}"],
     "every value is 0"),
    ("check huge by shape", ["check", "{scene}", "--data", "{huge}", "--shape-only", "--out", "{out}"],
     "largest |y|"),
    ("check data complex", ["check", "{scene}", "--data", "{complex}", "--shape-only", "--out", "{out}"],
     "real number"),
    ("check data missing", ["check", "{scene}", "--data", "{out}.npy", "--shape-only", "--out", "{out}"],
     "no such file"),
    ("sweep file missing", ["sweep", "{out}.toml", "--out", "{out}"], "sweep file"),
    ("sweep workers 0", ["sweep", "{scene}", "--workers", "0", "--out", "{out}"], "workers"),
]


@pytest.mark.parametrize("argv, words", [case[1:] for case in CLI_CASES], ids=[case[0] for case in CLI_CASES])
def test_command_line_value(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    values = {"scene": _scene(tmp_path), "data": _data(tmp_path), "out": str(out),
              "huge": _data(tmp_path, "huge.npy", np.full((1, 40), 1e160)),
              "complex": _data(tmp_path, "complex.npy", np.ones((1, 40)) * (1 + 1j))}
    argv = [part.format(**values) for part in argv]
    try:
        status = main(argv)
    except SystemExit as exit:        # argparse's own refusals
        status = exit.code
    error = capsys.readouterr().err.strip().splitlines()
    assert status == 2, argv
    assert len(error) == 1 and words in error[0], error
    assert not out.exists()


@pytest.mark.parametrize("name", ["a\x00b", "two\nlines", "a\u202eb", "a\u2028b"])
def test_a_scene_refuses_an_unprintable_name(name):
    from analytic.errors import SceneError
    from analytic.scenes.common import Scene

    with pytest.raises(SceneError) as caught:
        Scene(name=name)
    assert caught.value.key == "name" and "\n" not in str(caught.value)


# ---------------------------------------------------------------- refusals that need the whole command

def test_validate_refuses_an_spp_some_suite_scene_cannot_be_judged_at(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["validate", "--spp", "4096", "--fast", "--out", str(out)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    # the scenes that cannot be judged, why, and the count that can
    assert line.startswith("diffuse-imaging: error: --spp 4096") and "fine" in line and "far" in line
    assert "--spp 65536" in line
    assert not out.exists()


def test_validate_names_the_scene_it_cannot_judge(tmp_path, capsys):
    # 2,000 bins of 0.5 mm: at 4,096 samples no bin has a standard error under 0.1 of its value
    spread = write_scene(tmp_path, GOOD.replace("period = 0.1\nstart = 0.0\ncount = 40",
                                                "period = 0.0005\nstart = 1.9\ncount = 2000"), "spread.toml")
    good = write_scene(tmp_path, GOOD, "good.toml")
    out = tmp_path / "out"
    assert main(["validate", str(good), str(spread), "--spp", "4096", "--fast", "--out", str(out)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("diffuse-imaging: error: scene 'spread'") and str(spread) in line
    assert "4,096 samples" in line and "render more samples" in line
    assert not out.exists()


SAMPLED = GOOD.replace('waveform = "impulse"', 'waveform = "sampled"\nsamples = [0.0, 1.0, 0.5, 0.0]\n'
                                               'sample_width = 0.05')
WALL = """
[relay_wall]
size = [2.0, 2.0]
[hidden]
u = [1.0, 0.0, 0.0]
[scan]
type = "confocal"
grid = [2, 2]
"""


@pytest.mark.parametrize("text, old, new, key", [
    (SAMPLED, "samples = [0.0, 1.0, 0.5, 0.0]", 'samples = [0, "1", 0]', "illumination.samples[1]"),
    (SAMPLED, "samples = [0.0, 1.0, 0.5, 0.0]", "samples = [0, true, 0]", "illumination.samples[1]"),
    (GOOD, "positions = [[0.2, 0.7, 1.0]]", 'positions = [[0.2, "0.7", 1.0]]', "sensors.positions[0][1]"),
    (GOOD, "position = [0.5, 0.5, 1.0]", 'position = ["0.5", 0.5, 1.0]', "source.position[0]"),
    (WALL, "u = [1.0, 0.0, 0.0]", 'u = [1.0, "0", 0.0]', "hidden.u[1]"),
    (WALL, "size = [2.0, 2.0]", 'size = [2.0, "2"]', "relay_wall.size[1]"),
    (WALL, "grid = [2, 2]", 'grid = ["2", 2]', "scan.grid[0]"),
], ids=["samples-text", "samples-bool", "sensor", "source", "hidden.u", "wall-size", "scan-grid"])
def test_a_string_in_a_list_of_numbers_is_refused_naming_its_place(tmp_path, capsys, text, old, new, key):
    assert old in text
    path = write_scene(tmp_path, text.replace(old, new))
    assert main(["forward", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and error[0].startswith(f"diffuse-imaging: error: {key}: expected "), error


@pytest.mark.filterwarnings("ignore::analytic.operator.window.WindowWarning")
def test_a_response_csv_with_a_byte_order_mark_is_read(tmp_path):
    (tmp_path / "irf.csv").write_bytes(b"\xef\xbb\xbf0\n1\n0.5\n0\n")
    text = SAMPLED.replace("samples = [0.0, 1.0, 0.5, 0.0]", 'file = "irf.csv"')
    for name, scene in (("file", text), ("inline", SAMPLED)):
        path = write_scene(tmp_path, scene, name=f"{name}.toml")
        assert main(["forward", str(path), "--out", str(tmp_path / name), "--quiet"]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "file" / "transient.npy"),
                                  np.load(tmp_path / "inline" / "transient.npy"))
