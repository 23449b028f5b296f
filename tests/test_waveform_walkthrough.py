"""docs/design.md, "Where each extension goes", "A waveform": a toy waveform added from this module alone.

The toy (a linear ramp s(t) = t / w on [0, w], unit peak at w) is declared as
a waveform module declares itself (NAME, SUMMARY, PARAMETERS, build), with a
key of its own that no project file names (``rise`` = w), and registered; no
project file is edited. The scene file reads it, the scene checks and holds
its key (``illumination.rise``), the scene's tables, the renderer's
properties carry it both ways, the plugins' docs list it, and ``forward``
models it: the model is linear in s, so the sum over a window that holds the
whole response is the pulse's area w / 2 times the impulse's sum, and the
response starts where the impulse's does.
"""

from __future__ import annotations

import types

import numpy as np
import pytest

from analytic.errors import SceneError
from analytic.operator.matrix_free import forward
from analytic.scenes.common import Illumination, Sampling, Scene
from analytic.scenes.scene_file import scene_from_dict, scene_to_tables
from analytic.waveforms import builders, make_waveform
from analytic.waveforms.pieces import POLYNOMIAL, make_terms
from analytic.waveforms.waveform import Parameter, Waveform


def _build(illumination, period):
    """s(t) = t / w on [0, w]: S = t² / (2w) there, w / 2 beyond (its own ``rise`` key, required)."""
    del period
    if illumination.rise is None:
        raise SceneError("illumination.rise", "required with waveform = 'ramp'")
    width = float(illumination.rise)
    pieces = [(0.0, True, 0.0, POLYNOMIAL, 0.0, [0.0, 0.0, 0.5 / width]),
              (width, True, 0.5 * width, POLYNOMIAL, 0.0, [])]
    return Waveform("ramp", make_terms(pieces, duration=width), f"ramp of width {width:g} m", width,
                    {"rise": width})


RAMP = types.SimpleNamespace(NAME="ramp", SUMMARY="linear ramp up to unit peak at ``rise``",
                             PARAMETERS=(Parameter("rise", "length", "m", "required", plugin="ramp_rise"),),
                             build=_build)


@pytest.fixture()
def ramp():
    builders.register(RAMP)
    try:
        yield RAMP
    finally:
        del builders.WAVEFORMS["ramp"]


def test_a_toy_waveform_registered_from_a_test_is_modelled_by_forward(ramp):
    width = 0.06
    scene = scene_from_dict({"plane": {"pixels": 6}, "sensors": {"positions": [[0.3, 0.7, 0.6]]},
                             "source": {"position": [0.6, 0.4, 0.9]},
                             "illumination": {"waveform": "ramp", "rise": width},
                             "sampling": {"period": 0.02, "start": 1.0, "count": 120}})
    assert scene.illumination == Illumination(waveform="ramp", rise=width) and scene.illumination.rise == width
    assert scene_to_tables(scene)["illumination"] == {"waveform": "ramp", "rise": width}
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    assert waveform.energy == pytest.approx(width / 2, rel=1e-15)
    y = forward(scene)
    impulse = forward(scene.replace(illumination=Illumination()))
    assert np.all(y >= 0) and y.sum() > 0
    # the window holds the whole response (its last bins are dark), so κ_n sums to the area for every path
    assert impulse[:, -10:].max() == 0 and y[:, -2:].max() == 0
    assert y.sum() == pytest.approx(width / 2 * impulse.sum(), rel=1e-8)
    first = np.flatnonzero(impulse[0])[0]
    assert np.flatnonzero(y[0])[0] == first


def test_a_toy_waveform_reaches_the_schema_the_renderer_properties_and_the_plugin_docs(ramp):
    with pytest.raises(SceneError, match="illumination.fwhm: does not apply to waveform = 'ramp'"):
        Illumination(waveform="ramp", rise=0.1, fwhm=0.1)
    with pytest.raises(SceneError, match="illumination.rise: does not apply to waveform = 'gaussian'"):
        Illumination(waveform="gaussian", fwhm=0.1, rise=0.1)
    with pytest.raises(SceneError, match="illumination.rise"):
        Illumination(waveform="ramp", rise=-0.1)               # a length, checked as the registry declares it
    illumination = Illumination(waveform="ramp", rise=0.1)
    assert illumination.fwhm is None and illumination != Illumination(waveform="ramp", rise=0.2)
    entries = builders.plugin_entries(illumination, 0.02)
    assert entries == {"waveform": "ramp", "ramp_rise": 0.1}
    options = builders.illumination_options(entries.get)
    assert Illumination(waveform=entries["waveform"], **options) == illumination
    assert "``ramp``" in builders.plugin_rows()


def test_the_scene_format_names_every_registered_waveform_and_its_keys():
    """docs/files.md's [illumination] block, which users copy, lists each waveform and key of the registry."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "files.md").read_text(encoding="utf-8")
    block = text[text.index("[illumination]"):text.index("[sensors]")]
    for name in builders.WAVEFORMS:
        assert f'"{name}"' in block, name
    for key in builders.keys():
        assert f"# {key} = " in block or f"{key} =" in block, key


def test_the_toy_is_gone_after_the_test_and_a_name_is_registered_once():
    assert "ramp" not in builders.WAVEFORMS and "rise" not in builders.keys()
    with pytest.raises(SceneError, match="illumination.waveform: must be one of"):
        Illumination(waveform="ramp")
    with pytest.raises(TypeError, match="unexpected keyword argument 'rise'"):
        Illumination(waveform="square", rise=0.1)
    with pytest.raises(ValueError, match="registered already"):
        builders.register(builders.WAVEFORMS["gaussian"])
