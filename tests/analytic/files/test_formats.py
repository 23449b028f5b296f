"""analytic.files.formats: float32's limits measured, and one reader per format refusing what it cannot use."""

import numpy as np
import pytest

from analytic.errors import DataError
from analytic.files import float32_problem, read_npy, save_exr


def test_float32_problem_measures_the_rounding(tmp_path):
    assert float32_problem(np.array([1.0, 1e-45, 0.0])) is None           # 1e-45 errs by < 2^-24 of 1
    assert float32_problem(np.array([np.finfo(np.float32).max])) is None
    assert "exceeds" in float32_problem(np.array([1.0, 3.5e38]))
    assert "below float32's smallest normal" in float32_problem(np.array([1e-300, 0.0]))
    assert "below float32's smallest normal" in float32_problem(np.array([1e-39]))
    assert "NaN" in float32_problem(np.array([np.nan]))
    with pytest.raises(ValueError, match="float32"):                   # save_exr never writes inf
        save_exr(tmp_path / "never.exr", np.array([[1e40]]))
    assert not (tmp_path / "never.exr").exists()


def test_read_npy_takes_real_numbers_and_refuses_the_rest(tmp_path):
    np.save(tmp_path / "integers.npy", np.arange(6, dtype=np.int16).reshape(2, 3))
    back = read_npy(tmp_path / "integers.npy")
    assert back.dtype == np.float64 and np.array_equal(back, np.arange(6.0).reshape(2, 3))
    for name, values in (("words.npy", np.array(["a", "b"])), ("complex.npy", np.array([1 + 1j])),
                         ("flags.npy", np.array([True]))):
        np.save(tmp_path / name, values)
        with pytest.raises(DataError, match="not real numbers"):
            read_npy(tmp_path / name)
    (tmp_path / "cut.npy").write_bytes(b"\x93NUMPY")
    with pytest.raises(DataError, match="not a readable .npy"):
        read_npy(tmp_path / "cut.npy")
    np.savez(tmp_path / "archive.npz", y=np.zeros(3))
    (tmp_path / "archive.npz").rename(tmp_path / "archive.npy")     # np.load reads it as an archive
    with pytest.raises(DataError, match="npz archive"):
        read_npy(tmp_path / "archive.npy")


def test_read_npy_refuses_a_header_whose_shape_the_file_does_not_hold(tmp_path):
    """A header claiming 1.6e13 values on 64 bytes: one DataError by the file's size, not a 116 TiB allocation."""
    header = b"{'descr': '<f8', 'fortran_order': False, 'shape': (4000000, 4000000), }".ljust(117) + b"\n"
    (tmp_path / "forged.npy").write_bytes(b"\x93NUMPY\x01\x00v\x00" + header + b"\0" * 64)
    with pytest.raises(DataError, match="not a readable .npy"):
        read_npy(tmp_path / "forged.npy")
    np.save(tmp_path / "whole.npy", np.arange(6.0).reshape(2, 3))
    back = read_npy(tmp_path / "whole.npy")
    assert type(back) is np.ndarray and np.array_equal(back, np.arange(6.0).reshape(2, 3))   # a copy, not a map
