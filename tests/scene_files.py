"""Scene-file text shared by the tests: docs/design.md section 5's example, small."""

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
