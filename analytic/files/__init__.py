"""Files: atomic writes and folder locks, the file formats, a transient's files and metadata, tal's HDF5.

A one-way corner of :mod:`analytic`: it reads the scene (and the waveform's
name for the metadata), and nothing of the model imports it. Each module
has one job:

- :mod:`.atomic`: every file through a checked temporary, renamed into
  place (:func:`atomic_write`, :func:`staged_writes`), abandoned
  temporaries removed;
- :mod:`.locks`: one writing command per folder (:func:`output_folder`),
  readers kept out of a half-written one (:func:`reading_folder`);
- :mod:`.formats`: one writer and one reader per format (``.npy``, JSON,
  text, EXR, PNG; tal's HDF5 is :mod:`interop.tal`);
- :mod:`.transients`: the metadata schema (:func:`build_meta`) and a
  transient's files (:func:`write_transient`, :func:`read_transient`).

Names are loaded on first use (``lazy_loader``), as in every package of
this project; ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "atomic": ["atomic_write", "staged_writes", "discard", "remove_temporaries", "TEMPORARY_PREFIX"],
    "locks": ["output_folder", "reading_folder", "LOCK_FILE", "LOCK_WAIT_SECONDS"],
    "formats": ["save_npy", "read_npy", "save_json", "save_text", "json_ready", "json_default", "save_exr",
                "read_exr", "read_exr_channels", "save_png_image", "float32_problem", "PrecisionWarning"],
    "transients": ["build_meta", "write_transient", "read_transient", "transient_format",
                   "transient_in_folder", "UNITS", "RELAY_WALL_UNITS", "RELAY_WALL_KEYS", "KIND_KEYS",
                   "TRANSIENT_FILES"],
})
