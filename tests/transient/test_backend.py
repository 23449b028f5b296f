"""The backend: libLLVM choice (LLVM >= 16) and variants, each refusal one line."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from transient import backend
from transient.backend import BackendError, choose_libllvm, find_llvm_libraries, llvm_version_of


def test_backend_error_without_a_cuda_device():
    import drjit as dr

    backend.select_variant()
    if dr.has_backend(dr.JitBackend.CUDA):
        pytest.skip("a CUDA device is present")
    with pytest.raises(BackendError) as error:
        backend.select_variant("cuda_ad_mono")
    assert "\n" not in str(error.value) and "CUDA" in str(error.value)
    assert backend.select_variant() in ("llvm_mono", "llvm_ad_mono")


@pytest.mark.parametrize("name, version", [
    ("libLLVM-19.so", 19), ("libLLVM.so.19.1", 19), ("libLLVM-15.so.1", 15),
    ("libLLVM-14.0.6.so.1", 14), ("libLLVM.so.18", 18), ("libLLVMCore.so", None),
])
def test_llvm_version_of_names(name, version):
    assert llvm_version_of(f"/nonexistent/{name}") == version


def test_llvm_version_inside_versioned_folder():
    assert llvm_version_of("/nonexistent/llvm-17/lib/libLLVM.so") == 17


def test_choose_libllvm():
    old = [(14, "/lib/libLLVM-14.so.1"), (15, "/lib/libLLVM-15.so.1")]
    new = old + [(19, "/lib/libLLVM.so.19.1"), (17, "/usr/lib/llvm-17/lib/libLLVM-17.so")]
    assert choose_libllvm(None, new) == "/lib/libLLVM.so.19.1"
    assert choose_libllvm("", new) == "/lib/libLLVM.so.19.1"
    with pytest.raises(BackendError) as error:
        choose_libllvm(None, old)
    message = str(error.value)
    assert "\n" not in message
    assert "LLVM 15 at /lib/libLLVM-15.so.1" in message and "apt-get install -y libllvm19" in message
    with pytest.raises(BackendError, match="LLVM 15"):
        choose_libllvm("/lib/libLLVM-15.so.1", new)
    with pytest.raises(BackendError, match="no libLLVM"):
        choose_libllvm(None, [])
    # A user's library of unreadable version is kept (and checked after loading).
    assert choose_libllvm("/opt/custom/libLLVM.so", old) == "/opt/custom/libLLVM.so"


def test_find_llvm_libraries(tmp_path):
    for name in ("libLLVM-15.so.1", "libLLVM.so.19.1", "libLLVMCore.a", "libLLVMX86CodeGen.so"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "libLLVM-19.so").symlink_to("libLLVM.so.19.1")
    (tmp_path / "libLLVM-15.so").symlink_to("libLLVM-15.so.1")
    found = find_llvm_libraries([str(tmp_path / "libLLVM*.so*")])
    assert [version for version, _ in found] == [15, 19]
    assert choose_libllvm(None, found).endswith(("libLLVM-19.so", "libLLVM.so.19.1"))


def _fresh_python(code: str, environment: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], env=environment, capture_output=True,
                          text=True, timeout=120)


def test_fresh_process_without_environment_gets_llvm_16_or_newer():
    if not any(version >= backend.MIN_LLVM for version, _ in find_llvm_libraries()):
        pytest.skip("no libLLVM >= 16 on this machine")
    environment = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    code = ("import os\n"
            "from transient.backend import select_variant\n"
            "variant = select_variant()\n"
            "import drjit as dr, mitsuba as mi\n"
            "value = dr.maximum(mi.Float([1.0, 3.0]), 2.0)\n"   # aborts the process on LLVM 15
            "print(variant, dr.detail.llvm_version()[0], os.environ['DRJIT_LIBLLVM_PATH'], list(value))\n")
    done = _fresh_python(code, environment)
    assert done.returncode == 0, done.stderr
    variant, version, path, *_ = done.stdout.split()
    assert variant in ("llvm_mono", "llvm_ad_mono")
    assert int(version) >= backend.MIN_LLVM and llvm_version_of(path) >= backend.MIN_LLVM


def test_fresh_process_refuses_llvm_15():
    environment = dict(os.environ, DRJIT_LIBLLVM_PATH="/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1")
    code = ("import sys\n"
            "from transient.backend import select_variant, BackendError\n"
            "try:\n    select_variant()\n"
            "except BackendError as error:\n    print(error); sys.exit(3)\n"
            "print('drjit' in sys.modules)\n")
    done = _fresh_python(code, environment)
    assert done.returncode == 3, done.stdout + done.stderr
    assert "LLVM 15" in done.stdout and "apt-get install -y libllvm19" in done.stdout
    assert done.stdout.count("\n") == 1


def test_without_home_dr_jit_keeps_its_kernel_cache_and_stays_quiet(tmp_path):
    """HOME unset: Dr.Jit warned "HOME ... not set, disabling the kernel cache" on stderr. The backend names
    the folder HOME would have given for Dr.Jit's import only: no noise, a cache, no variable left behind."""
    environment = {k: v for k, v in os.environ.items() if k not in ("HOME", "DRJIT_CACHE_DIR")}
    code = ("import os\n"
            "from transient.backend import select_variant\n"
            "select_variant()\n"
            "import drjit as dr, mitsuba as mi\n"
            "dr.eval(mi.Float64(dr.arange(mi.Float, 7)) * 3.0)\n"
            "print('DRJIT_CACHE_DIR' in os.environ, 'HOME' in os.environ)\n")
    done = _fresh_python(code, environment)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    assert done.stdout.split() == ["False", "False"]


def test_kernel_cache_folder_falls_back_to_a_private_temporary_folder(tmp_path, monkeypatch):
    """A user without a home in the password database gets a temporary folder only they can write."""
    import stat

    def no_such_user(uid):
        raise KeyError(uid)

    monkeypatch.delenv("HOME", raising=False)
    monkeypatch.delenv("DRJIT_CACHE_DIR", raising=False)
    monkeypatch.setattr(backend.tempfile, "gettempdir", lambda: str(tmp_path))
    monkeypatch.setattr(backend.pwd, "getpwuid", no_such_user)
    folder = backend.kernel_cache_folder()
    assert folder == str(tmp_path / f"drjit-{os.getuid()}")
    assert stat.S_IMODE(os.stat(folder).st_mode) == 0o700
    os.chmod(folder, 0o777)                       # writable by others: not a place to run kernels from
    assert backend.kernel_cache_folder() is None
    monkeypatch.setenv("HOME", str(tmp_path))
    assert backend.kernel_cache_folder() is None  # Dr.Jit finds its own
