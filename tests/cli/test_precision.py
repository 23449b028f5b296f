"""Outputs float32 cannot hold: a legal scene whose y overflows or underflows float32 still ends with
exit 0 and exact float64 files; transient.exr is left unwritten, one warning line and meta.json say why.

The reference is physics: y scales exactly as I / s^2 when every length is multiplied by s (impulse
illumination: the attenuation goes as s^-4 and the area as s^2), so the scaled scene's y is the unit
scene's times a known factor.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from interop.tal import read_capture
from validation.cli import main

SCENE = """
[plane]
size = {length}
pixels = 8
reflectance = 0.5
[source]
position = [{half}, {half}, {length}]
intensity = {intensity}
[sensors]
positions = [[{near}, {far}, {length}]]
[sampling]
period = {period}
start = {start}
count = 12
"""


def _forward(tmp_path, name: str, scale: float, intensity: float, capsys) -> tuple[np.ndarray, list[str]]:
    scene = tmp_path / f"{name}.toml"
    scene.write_text(SCENE.format(length=scale, half=0.5 * scale, near=0.2 * scale, far=0.7 * scale,
                                  period=0.1 * scale, start=1.9 * scale, intensity=intensity))
    assert main(["forward", str(scene), "--out", str(tmp_path / name), "--quiet"]) == 0
    return np.load(tmp_path / name / "transient.npy"), capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("scale, intensity", [(1e-6, 1e30), (1.0, 1e-300)], ids=["overflow", "underflow"])
def test_a_legal_scene_beyond_float32_keeps_its_exact_record(tmp_path, capsys, scale, intensity):
    with warnings.catch_warnings():
        warnings.simplefilter("always")                   # as a user sees them: the CLI prints one line each
        unit, lines = _forward(tmp_path, "unit", 1.0, 1.0, capsys)
        assert lines == [] and (tmp_path / "unit" / "transient.exr").is_file()
        y, lines = _forward(tmp_path, "scaled", scale, intensity, capsys)
    factor = intensity / scale**2
    assert np.all(np.isfinite(y)) and np.max(y) > 0
    assert np.allclose(y, factor * unit, rtol=1e-9, atol=0)
    assert len(lines) == 1, lines
    assert lines[0].startswith("diffuse-imaging: warning:") and "transient.exr" in lines[0] \
        and "float32" in lines[0] and "exact record" in lines[0], lines
    assert not (tmp_path / "scaled" / "transient.exr").exists()
    assert json.loads((tmp_path / "scaled" / "meta.json").read_text())["exr"].startswith("not written")
    assert np.array_equal(read_capture(tmp_path / "scaled" / "transient.h5").transient, y)   # float64 too
