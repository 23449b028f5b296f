"""A measured instrument response's samples: read from a file and checked (NumPy only, no Numba).

The ``sampled`` waveform (docs/design.md section 8) takes its samples from
``[illumination] file`` (.npy: a 1-D array; .csv or .txt: one number per
line, blank lines and lines starting with ``#`` skipped; .h5 or .hdf5: a tal
capture holding one histogram, whose bin centres are the samples, read by
the response reader :mod:`analytic.formats` has for its suffix) or inline as
``[illumination] samples = [...]``. :func:`check_samples` is what the
scene's :class:`~analytic.scenes.common.Illumination` runs on either.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import DataError, SceneError
from ..formats import readers, reader_for
from ..values import exact, huge_integer

__all__ = ["read_samples", "histogram_axis", "check_samples", "sample_width_metres", "finite_span", "MAX_SAMPLES",
           "METRES_PER_PICOSECOND", "SUFFIXES", "is_histogram"]

#: Most samples accepted: each is a kink of the pulse, where the model cuts its integrals.
MAX_SAMPLES = 100_000
#: Path length light travels in one picosecond, metres (c = 299 792 458 m/s).
METRES_PER_PICOSECOND = 2.99792458e-4
#: File types read here.
SUFFIXES = (".npy", ".csv", ".txt")
#: Largest file read, bytes (a text file of MAX_SAMPLES numbers is ~2.5 MB).
_MAX_BYTES = 16 << 20


def read_samples(path, key: str = "illumination.file") -> np.ndarray:
    """The samples of an instrument-response file, float64, checked by :func:`check_samples`.

    Parameters
    ----------
    path : str or Path
        A .npy file holding a 1-D array, a .csv / .txt file with one
        number per line, or a tal HDF5 capture (``H``) of one histogram
        (:func:`histogram_axis` gives its spacing and first bin centre).
    key : str
        The scene key named in errors.

    Raises
    ------
    SceneError
        Missing or unreadable file, another type, more than one column,
        a value that is not a number, or samples :func:`check_samples` refuses.
    """
    path = Path(path)
    shown = str(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES and not is_histogram(path):
        known = SUFFIXES + tuple(readers("response"))
        raise SceneError(key, f"{shown}: expected a {', '.join(known)} file of samples, got {suffix or 'no suffix'!r}")
    if not path.is_file():
        raise SceneError(key, f"{shown}: no such file (paths are relative to the scene file)")
    if path.stat().st_size > _MAX_BYTES:
        raise SceneError(key, f"{shown}: larger than {_MAX_BYTES >> 20} MiB; is it an instrument response?")
    try:
        if suffix == ".npy":
            with open(path, "rb") as stream:
                values = np.load(stream, allow_pickle=False)
        elif suffix not in SUFFIXES:
            values = _histogram(path, key).transient[0]
        else:
            values = _read_text(path, key)
    except (OSError, ValueError, EOFError) as error:
        if isinstance(error, SceneError):
            raise
        raise SceneError(key, f"{shown}: cannot read it ({error})") from None
    values = np.asarray(values)
    if values.ndim != 1:
        raise SceneError(key, f"{shown}: expected a 1-D array of samples, got shape {values.shape}")
    if not (np.issubdtype(values.dtype, np.floating) or np.issubdtype(values.dtype, np.integer)):
        raise SceneError(key, f"{shown}: expected numbers, got dtype {values.dtype}")
    return check_samples(values.astype(np.float64), key)


def is_histogram(path) -> bool:
    """Whether ``path`` is another tool's histogram (a tal capture) by its suffix: its own time axis gives the
    samples' spacing and start (:func:`histogram_axis`)."""
    suffix = Path(path).suffix.lower()
    return suffix not in SUFFIXES and reader_for("response", suffix) is not None


def _histogram(path: Path, key: str):
    """The histogram record of :mod:`analytic.formats`' response reader for ``path``'s suffix."""
    try:
        capture = reader_for("response", path.suffix).read(path)
    except DataError as error:
        raise SceneError(key, str(error)) from None
    if capture.transient.shape[0] != 1:
        raise SceneError(key, f"{path}: holds {capture.transient.shape[0]} histograms; an instrument response "
                              f"is one (write the pixel you measured it on alone)")
    return capture


def histogram_axis(path, key: str = "illumination.file") -> tuple[float, float]:
    """``(sample_width, start)`` of a tal capture's histogram, metres of path.

    A histogram's bin n covers [t_start + n delta_t, t_start + (n + 1) delta_t):
    its count is taken as the response at the bin's centre, so the samples are
    ``delta_t`` apart from ``t_start + delta_t / 2``.
    """
    capture = _histogram(Path(path), key)
    return float(capture.bin_width_opl), float(capture.start_opl + capture.bin_width_opl / 2)


def _read_text(path: Path, key: str) -> np.ndarray:
    values = []
    with open(path, encoding="utf-8-sig") as stream:        # -sig: a byte-order mark (Excel's CSV) is skipped
        for number, line in enumerate(stream, 1):
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            if "," in text.rstrip(",") or len(text.split()) > 1:
                raise SceneError(key, f"{path}: line {number} has more than one column ({text[:40]!r}); "
                                      f"give one sample per line")
            try:
                values.append(float(text.rstrip(",")))
            except ValueError:
                raise SceneError(key, f"{path}: line {number} is not a number ({text[:40]!r})") from None
    return np.array(values, dtype=np.float64)


def check_samples(values, key: str = "illumination.samples") -> np.ndarray:
    """The samples as a read-only float64 array, or a SceneError naming ``key`` and the problem.

    Samples must be finite and >= 0 (an expected count cannot be
    negative: clip a background-subtracted response first), at least two,
    at most :data:`MAX_SAMPLES`, with a largest sample > 0 (they are divided
    by it).
    """
    if isinstance(values, np.ndarray):
        if values.dtype.kind not in "iuf":
            raise SceneError(key, f"expected numbers, got an array of dtype {values.dtype}")
    elif isinstance(values, (list, tuple)):
        # each one a number: np.array(["1"], float) would read the string "1" as 1, and True as 1
        for index, value in enumerate(values):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise SceneError(f"{key}[{index}]", f"expected a number, got {value!r}")
            try:
                float(value)
            except OverflowError:       # a whole number past 1.8e308
                raise SceneError(f"{key}[{index}]", huge_integer(value)) from None
    else:
        raise SceneError(key, f"expected a list of numbers, got {values!r}")
    try:
        array = np.array(values, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SceneError(key, "expected a list of numbers") from None
    if array.ndim != 1:
        raise SceneError(key, f"expected a 1-D list of samples, got shape {array.shape}")
    if not 2 <= array.size <= MAX_SAMPLES:
        raise SceneError(key, f"needs 2 to {MAX_SAMPLES} samples, got {array.size}")
    bad = np.flatnonzero(~np.isfinite(array) | (array < 0))
    if bad.size:
        raise SceneError(key, f"sample {bad[0]} is {exact(array[bad[0]])}; every sample must be finite and >= 0 "
                              f"(clip a background-subtracted response at 0)")
    if not array.max() > 0:
        raise SceneError(key, "every sample is 0; the response is divided by its largest sample")
    array.setflags(write=False)
    return array


def sample_width_metres(sample_width: float | None, sample_width_ps: float | None) -> float:
    """The sample spacing in metres of path from whichever of the two keys is given."""
    if sample_width is not None:
        return float(sample_width)
    return float(sample_width_ps) * METRES_PER_PICOSECOND


def finite_span(count: int, width: float, start: float, limit: float, resolution: float) -> None:
    """Refuse samples whose span leaves ±limit metres, or whose spacing float64 cannot resolve there.

    Parameters
    ----------
    count : int
        Samples n.
    width, start : float
        Spacing and first sample's path length, metres.
    limit : float
        Largest |path length| supported, metres.
    resolution : float
        Smallest spacing / largest |path length| (as the bins' own bound).
    """
    end = start + (count - 1) * width
    key = "illumination.sample_width"
    if not (math.isfinite(end) and abs(end) <= limit):
        raise SceneError(key, f"{count} samples of {exact(width)} m from {exact(start)} m end at {exact(end)} m, beyond the "
                              f"±{limit:g} m this tool resolves")
    if width < resolution * max(abs(start), abs(end)):
        raise SceneError(key, f"samples {exact(width)} m apart cannot be told apart at path lengths of "
                              f"{exact(max(abs(start), abs(end)))} m in float64 (need sample_width >= {resolution:g} x "
                              f"the largest |path length|)")
