"""Writing a Mitsuba 3 scene as XML: elements, doubles that read back exactly, and the file's text.

Shared by :mod:`interop.mitransient.export` (the plane) and :mod:`interop.mitransient.export_relay_wall`
(a relay-wall capture). No Mitsuba import: the files are plain XML.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

__all__ = ["number", "add", "point", "transform", "comment_text", "verify_xml", "scene_text", "waveform_entries",
           "add_entries", "textured_diffuse", "write_scene_files"]


def number(value) -> str:
    """Shortest text that reads back as the same double."""
    return repr(float(value))


def add(parent, tag: str, name: str | None = None, **attributes) -> ET.Element:
    """A child element ``<tag name=... key=value .../>`` (values as text)."""
    if name is not None:
        attributes = {"name": name, **attributes}
    return ET.SubElement(parent, tag, {key: str(value) for key, value in attributes.items()})


def point(parent, name: str, values) -> ET.Element:
    return add(parent, "point", name, value=", ".join(number(v) for v in values))


def transform(parent, name: str, matrix: np.ndarray) -> ET.Element:
    element = add(parent, "transform", name)
    add(element, "matrix", value=" ".join(number(v) for v in np.asarray(matrix).ravel()))
    return element


# Characters XML 1.0 cannot hold at all (C0 controls but tab, newline and carriage return; surrogates,
# which file names that are not UTF-8 decode to; U+FFFE and U+FFFF), and "-" where a comment forbids it:
# in "--" and before the closing "-->".
_NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def comment_text(text: str) -> str:
    """``text`` made safe inside an XML comment: what XML cannot hold as ``\\uXXXX``, "--" as "- -".

    Parameters
    ----------
    text : str
        Any text (a scene's name: a file name may hold anything but "/").

    Returns
    -------
    str
        Text a conforming parser reads inside ``<!-- ... -->``, readable as
        the original: every character XML allows is kept, non-ASCII included.
    """
    text = _NOT_XML.sub(lambda match: f"\\u{ord(match.group()):04x}", text)
    while "--" in text:
        text = text.replace("--", "- -")
    return text + " " if text.endswith("-") else text


def verify_xml(temporary: str) -> None:
    """The written scene parses as XML (a torn or malformed file is not renamed into place)."""
    ET.parse(temporary)


def scene_text(root: ET.Element, name: str, format: str) -> str:
    """The XML file's text: declaration, a comment naming the scene (made safe), the indented scene."""
    ET.indent(root)
    return ('<?xml version="1.0" encoding="utf-8"?>\n'
            f"<!-- {comment_text(name)}: exported by diffuse-imaging for {format}; lengths in "
            f"metres, time as optical path length (c = 1) -->\n"
            + ET.tostring(root, encoding="unicode") + "\n")


def waveform_entries(illumination, bin_width_opl: float) -> dict:
    """Our integrators' waveform properties for an illumination, as its waveform module declares them.

    :func:`analytic.waveforms.builders.plugin_entries`: the plugins build their waveform with the same
    :func:`analytic.waveforms.make_waveform` and period, so the scene's own fields (defaults unset) give
    the same pulse.
    """
    from analytic.waveforms.builders import plugin_entries

    return plugin_entries(illumination, bin_width_opl)


def add_entries(parent, entries: dict) -> None:
    """``<string>``, ``<integer>`` or ``<float>`` children for a dict of plugin parameters."""
    for key, value in entries.items():
        if isinstance(value, str):
            add(parent, "string", key, value=value)
        elif isinstance(value, (int, np.integer)):
            add(parent, "integer", key, value=int(value))
        else:
            add(parent, "float", key, value=number(value))


def textured_diffuse(shape) -> None:
    """A ``diffuse`` BSDF reading ``reflectance.exr`` raw, nearest-neighbour, clamped (the image as it is)."""
    bsdf = add(shape, "bsdf", type="diffuse")
    texture = add(bsdf, "texture", "reflectance", type="bitmap")
    add(texture, "string", "filename", value="reflectance.exr")
    add(texture, "boolean", "raw", value="true")
    add(texture, "string", "filter_type", value="nearest")
    add(texture, "string", "wrap_mode", value="clamp")


def write_scene_files(out_dir, image: np.ndarray, text: str, readme: str) -> dict[str, Path]:
    """``reflectance.exr`` (the image flipped: a bitmap's row 0 lies at v = 0, the image's row 0 at v's far
    end), ``scene.xml`` (parsed back before its rename) and ``README.md``, written together."""
    from analytic.files import save_exr, save_text, staged_writes

    out_dir = Path(out_dir)
    texture = np.ascontiguousarray(np.flipud(image), dtype=np.float32)
    written = {}
    with staged_writes():
        written["reflectance.exr"] = save_exr(out_dir / "reflectance.exr", texture)
        written["scene.xml"] = save_text(out_dir / "scene.xml", text, verify=verify_xml)
        written["README.md"] = save_text(out_dir / "README.md", readme)
    return written
