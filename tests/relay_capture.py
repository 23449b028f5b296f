"""A small relay-wall capture for the tests: a 2 m wall, a 3 x 3 rectangle 0.8 m from it, 40 bins of 0.05 m."""

from analytic.scenes.scene_file import scene_of


def capture(tmp_path, scan, hidden="center = [0.1, -0.05, 0.8]\nu = [0.6, 0.0, 0.0]\nv = [0.0, -0.6, 0.0]",
            points="[laser]\nposition = [-0.4, 0.2, 0.3]\n[sensor]\nposition = [0.3, -0.1, 0.2]", start=1.4,
            light='waveform = "impulse"', tolerance=1e-6, pixels=3):
    text = f"""
[relay_wall]
size = [2.0, 2.0]
[hidden]
{hidden}
pixels = {pixels}
reflectance = 0.7
{points}
[scan]
{scan}
[sampling]
period = 0.05
start = {start}
count = 40
[illumination]
{light}
[model]
tolerance = {tolerance!r}
"""
    path = tmp_path / "capture.toml"
    path.write_text(text)
    return scene_of(path)
