"""Scene files shared by the tests: docs/design.md section 5's example, small, and any Scene written as a file."""

import json
import textwrap

GOOD = """
[plane]
size = 1.0
pixels = 8
reflectance = 0.5

[source]
position = [0.5, 0.5, 1.0]

[illumination]
waveform = "impulse"

[sensors]
positions = [[0.2, 0.7, 1.0]]

[sampling]
period = 0.1
start = 0.0
count = 40

[model]
attenuation = "lambertian"
"""


def write_scene(folder, text=GOOD, name="scene.toml"):
    """Write scene-file text into ``folder``; returns its path."""
    path = folder / name
    path.write_text(textwrap.dedent(text))
    return path


def write_scene_file(folder, scene, name=None):
    """``scene`` as a scene file in ``folder`` (``<scene.name>.toml``), what a command reads; returns its path.

    A reflectance image that is not uniform goes into ``image.exr`` beside the file (float32, as a user's
    would); every other field is written exactly (floats by their shortest round-trip text). Noise is not
    written: a scene with noise is refused rather than silently written without it.
    """
    import numpy as np

    from analytic.files import save_exr

    if scene.noise is not None:
        raise ValueError("write_scene_file: scenes with noise are not supported")
    image = np.asarray(scene.reflectance)
    if np.all(image == image.flat[0]):
        reflectance = repr(float(image.flat[0]))
    else:
        save_exr(folder / "image.exr", image)
        reflectance = '"image.exr"'
    illumination = scene.illumination
    waveform = [f"waveform = {json.dumps(illumination.waveform)}"] + [
        f"{key} = {value!r}" for key in ("width", "cutoff", "duration", "order")
        if (value := getattr(illumination, key)) is not None]
    sampling = scene.sampling
    lines = [f"name = {json.dumps(scene.name)}",
             "[plane]", f"size = {scene.size!r}", f"pixels = {scene.pixels}", f"reflectance = {reflectance}",
             "[source]", f"position = {json.dumps(np.asarray(scene.source).tolist())}",
             f"intensity = {scene.intensity!r}",
             "[illumination]", *waveform,
             "[sensors]", f"positions = {json.dumps(np.asarray(scene.sensors).tolist())}",
             "[sampling]", f"period = {sampling.bin_width_opl!r}", f"start = {sampling.start_opl!r}",
             f"count = {sampling.count}",
             "[model]", f"attenuation = {json.dumps(scene.attenuation)}", f"tolerance = {scene.tolerance!r}"]
    path = folder / (name or f"{scene.name}.toml")
    path.write_text("\n".join(lines) + "\n")
    return path


def _toml_value(value) -> str:
    from validation.calibration.files import toml_value

    return toml_value(value)


def write_relay_wall_file(folder, scene, name=None):
    """A relay-wall scene as a scene file in ``folder`` (``<scene.name>.toml``); returns its path.

    Written from :func:`analytic.scenes.scene_file.scene_to_tables`; a hidden image that is not uniform goes into
    ``hidden.exr`` beside the file (float32, as a user's would).
    """
    from analytic.files import save_exr
    from analytic.scenes.scene_file import scene_to_tables

    if scene.noise is not None:
        raise ValueError("write_relay_wall_file: scenes with noise are not supported")
    tables = scene_to_tables(scene)
    lines = [f"name = {json.dumps(tables.pop('name'))}"]
    for table, entries in tables.items():
        lines.append(f"[{table}]")
        for key, value in entries.items():
            if table == "hidden" and key == "reflectance" and not isinstance(value, float):
                save_exr(folder / "hidden.exr", value)
                value = "hidden.exr"
            lines.append(f"{key} = {_toml_value(value)}")
    path = folder / (name or f"{scene.name}.toml")
    path.write_text("\n".join(lines) + "\n")
    return path


def tilted_relay_wall(pixels: int, grid: int) -> str:
    """A confocal capture of a tilted hidden square (no two pairs are translates: the relay wall's general
    route), ``pixels`` x ``pixels`` over a ``grid`` x ``grid`` scan, 64 bins."""
    return f"""\
name = "tilted"
[relay_wall]
size = [2.0, 2.0]
[hidden]
pixels = {pixels}
reflectance = 0.5
center = [0.1, 0.2, 1.2]
u = [0.7020660, 0.0, 0.3835404]
v = [0.0, -0.8, 0.0]
[scan]
type = "confocal"
grid = [{grid}, {grid}]
[sampling]
period = 0.05
start = 1.9
count = 64
"""
