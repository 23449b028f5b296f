"""analytic.formats: other tools' readers and writers by suffix, registered once, each suffix read by one."""

import pytest

from analytic import formats


@pytest.fixture()
def registry(monkeypatch):
    """A fresh, loaded registry for the test (the process's own is left as it was)."""
    monkeypatch.setattr(formats, "_READERS", {role: {} for role in formats.ROLES})
    monkeypatch.setattr(formats, "_WRITERS", {})
    monkeypatch.setattr(formats, "_loaded", True)
    return formats


def _read(path):
    return path


def test_a_reader_is_found_by_its_suffix_in_any_case(registry):
    registry.register_reader("transient", "toy", (".toy",), _read)
    assert registry.reader_for("transient", ".TOY") == formats.Reader("toy", _read)
    assert registry.reader_for("scene", ".toy") is None                 # per role
    registry.register_reader("transient", "toy", (".toy",), _read)     # the same again: harmless


def test_a_suffix_taken_by_another_reader_or_a_bad_declaration_is_refused(registry):
    registry.register_reader("response", "toy", (".toy",), _read)
    with pytest.raises(ValueError, match=r"response files \.toy: read by toy already"):
        registry.register_reader("response", "other", (".toy",), lambda path: path)
    with pytest.raises(ValueError, match="role: one of scene, transient, response"):
        registry.register_reader("image", "toy", (".toy",), _read)
    with pytest.raises(ValueError, match="lower case with its dot"):
        registry.register_reader("scene", "toy", ("TOY",), _read)
    registry.register_writer("toy.bin", _read)
    with pytest.raises(ValueError, match="toy.bin: written by"):
        registry.register_writer("toy.bin", lambda *values: None)
    assert registry.writers() == {"toy.bin": _read}


def test_the_packages_entry_point_registers_tals_files():
    """What pyproject.toml's entry point registers (called here directly: the registry is the process's)."""
    from interop.tal.formats import register

    register()
    scenes = formats._READERS["scene"]
    assert scenes[".yaml"].name == scenes[".yml"].name == "tal configuration"
    assert formats._READERS["transient"][".h5"].name == "capture"
    assert set(formats._READERS["response"]) >= {".h5", ".hdf5"} and "transient.h5" in formats._WRITERS
