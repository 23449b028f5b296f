"""The compiled kernels: a closed sub-package, cached by its own sources, in a folder a user can write."""

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

from numba.core.caching import CacheImpl

from analytic.kernels import cache
from analytic.kernels.cache import KernelCacheLocator, sources_stamp
from scene_files import tilted_relay_wall

KERNELS = Path(cache.__file__).resolve().parent
PACKAGE = KERNELS.parent
ROOT = PACKAGE.parent
#: What a kernel module may import besides its siblings: compiled code and constants only.
ALLOWED = {"__future__", "math", "typing", "numpy", "numba", "numba.extending", "numba.core",
           "numba.core.caching", "numba.core.config", "contextlib", "functools", "hashlib", "os", "sys", "tempfile",
           "threading", "pathlib", "fcntl", "lazy_loader", "signal"}


def test_the_kernels_import_only_each_other_numpy_numba_and_the_standard_library():
    for path in sorted(KERNELS.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                name = node.module or ""
                assert node.level == 1 or name in ALLOWED, f"{path.name} imports {name} (level {node.level})"
                assert node.level <= 1, f"{path.name} imports from outside the kernels ({'.' * node.level}{name})"
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    assert alias.name in ALLOWED, f"{path.name} imports {alias.name}"


def _copy(tmp_path) -> Path:
    copy = tmp_path / "copy" / "analytic"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    return copy


def test_the_stamp_follows_the_kernels_sources_and_nothing_else(tmp_path, monkeypatch):
    """On a copy of the package: editing the real sources, even for a moment, would make every cached kernel stale
    for another process loading one meanwhile (a second pytest-xdist worker, a user's command)."""
    copy = _copy(tmp_path)
    monkeypatch.setattr(cache, "_KERNELS", copy / "kernels")
    before = sources_stamp()
    assert before == sources_stamp()
    outside = copy / "geometry.py"
    outside.write_text(outside.read_text(encoding="utf-8") + "# an edit of plain Python\n", encoding="utf-8")
    assert sources_stamp() == before
    inside = copy / "kernels" / "pieces.py"
    original = inside.read_bytes()
    status = inside.stat()
    os.utime(inside, ns=(status.st_atime_ns, status.st_mtime_ns + 10**9))
    assert sources_stamp() == before                     # touched, not changed
    inside.write_bytes(original + b"# edited\n")
    assert sources_stamp() != before
    inside.write_bytes(original)
    assert sources_stamp() == before


def test_only_the_kernels_are_served():
    assert CacheImpl._locator_classes[0] is KernelCacheLocator
    assert KernelCacheLocator.from_function(os.path.join, os.path.__file__) is None
    geometry = PACKAGE / "geometry.py"
    assert KernelCacheLocator.from_function(test_only_the_kernels_are_served, str(geometry)) is None


def _run(code: str, env: dict, cwd: Path) -> subprocess.CompletedProcess:
    environment = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    environment.update(env)
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=environment, capture_output=True, text=True,
                          timeout=300)


def test_an_install_whose_folder_cannot_be_written_keeps_its_kernels_in_the_users_cache_folder(tmp_path):
    """A read-only install (a system or shared one, a container), as any user, root included: its kernels'
    ``__pycache__`` cannot be made (here a file stands in its place)."""
    copy = _copy(tmp_path)
    (copy / "kernels" / "__pycache__").write_text("not a folder", encoding="utf-8")
    done = _run("from analytic.kernels.cache import cache_folder; print(cache_folder())",
                {"PYTHONPATH": str(copy.parent), "XDG_CACHE_HOME": str(tmp_path / "cache")}, tmp_path)
    assert done.returncode == 0, done.stderr
    assert Path(done.stdout.strip()).parent == tmp_path / "cache" / "diffuse-imaging" / "kernels"


def test_the_cache_folder_is_beside_the_sources_where_they_can_be_written_or_under_numba_cache_dir(tmp_path):
    done = _run("from analytic.kernels.cache import cache_folder; print(cache_folder())",
                {"PYTHONPATH": str(ROOT)}, tmp_path)
    assert Path(done.stdout.strip()).parent == KERNELS / "__pycache__", done.stderr
    done = _run("from analytic.kernels.cache import cache_folder; print(cache_folder())",
                {"PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": str(tmp_path / "numba")}, tmp_path)
    assert Path(done.stdout.strip()).parent == tmp_path / "numba" / "diffuse-imaging" / "kernels", done.stderr


def test_sources_of_another_stamp_never_share_a_cache_folder(tmp_path):
    """An index written by other sources is never read: here a kernels module that these sources lack.

    Numba unpickles an index before it compares its stamp; the same folder for two versions of the
    kernels made a user's upgrade (or a second checkout sharing NUMBA_CACHE_DIR) fail with
    ModuleNotFoundError instead of compiling.
    """
    copy = _copy(tmp_path)
    code = ("from analytic.kernels.bins import TimeAxis, bin_of\n"
            "print(bin_of(0.35, TimeAxis(0.0, 0.1, 10)))")
    env = {"PYTHONPATH": str(copy.parent), "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    first = _run(code, env, tmp_path)
    assert first.returncode == 0 and first.stdout.strip() == "3", first.stderr
    # the other version: a kernels module of its own that an index of these kernels will name
    (copy / "kernels" / "renamed.py").write_text(
        "from typing import NamedTuple\nfrom .bins import bin_of  # noqa: F401\n\n\n"
        "class Axis(NamedTuple):\n    start_opl: float\n    bin_width_opl: float\n    count: int\n")
    other = ("import analytic.kernels.renamed as renamed\n"          # bin_of's index now names renamed.Axis
             "print(renamed.bin_of(0.35, renamed.Axis(0.0, 0.1, 10)))")
    assert _run(other, env, tmp_path).returncode == 0
    (copy / "kernels" / "renamed.py").unlink()      # back to the first sources: their own folder
    again = _run(code, env, tmp_path)
    assert again.returncode == 0 and again.stdout.strip() == "3", again.stderr
    assert len(list((tmp_path / "numba" / "diffuse-imaging" / "kernels").iterdir())) == 2


def test_a_long_compile_says_so_once_on_stderr(tmp_path):
    """A compile into an empty cache, with the notice's delay set to 0: one line naming what and where."""
    code = ("import analytic.kernels.cache as cache; cache.NOTICE_SECONDS = 0.0\n"
            "from analytic.kernels.bins import TimeAxis, bin_of\n"
            "from analytic.kernels.isochrone import PixelBox\n"
            "print(bin_of(0.5, TimeAxis(0.0, 0.1, 10)))\n")
    done = _run(code, {"PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": str(tmp_path / "numba")}, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "5"
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("diffuse-imaging: compiling the model's kernels (bins.bin_of)")
    assert str(tmp_path / "numba" / "diffuse-imaging" / "kernels") in lines[0]
    again = _run(code, {"PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": str(tmp_path / "numba")}, tmp_path)
    assert again.returncode == 0 and again.stderr.strip() == ""      # loaded from the cache: no compile, no line


def test_a_save_into_the_kernels_cache_holds_the_index_lock(monkeypatch, tmp_path):
    """Numba saves an entry with no lock (read the index, take the first free data file, write both): two
    processes saving two signatures of one kernel could take the same data file, and the index then map one
    signature to the other's code. Our saves hold a lock file beside the index for the whole save."""
    import fcntl
    from types import SimpleNamespace

    import analytic.kernels.cache as cache

    folder = tmp_path / "stamp"
    folder.mkdir()
    monkeypatch.setattr(cache, "cache_folder", lambda: folder)
    index = SimpleNamespace(_cache_path=str(folder), _index_path=str(folder / "kernel-1.py311.nbi"))
    held = []

    def save(self, key, data):
        with open(self._index_path + ".lock", "a") as other:      # another process's attempt, meanwhile
            try:
                fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
                held.append(False)
            except BlockingIOError:
                held.append(True)

    monkeypatch.setattr(cache, "_numba_save", save)
    from numba.core.caching import IndexDataCacheFile
    assert IndexDataCacheFile.save is cache._locked_save
    IndexDataCacheFile.save(index, "key", b"data")
    elsewhere = SimpleNamespace(_cache_path=str(tmp_path), _index_path=str(tmp_path / "other.nbi"))
    IndexDataCacheFile.save(elsewhere, "key", b"data")             # another package's cache: no lock of ours
    assert held == [True, False]


#: A child that models a tilted hidden square (the relay wall's general route: many kernels loaded on first
#: use) while another thread sends it SIGINT every few milliseconds; each KeyboardInterrupt is caught and the model
#: started again, until one whole run ends (the interrupts stop after 2 s). Ctrl-C while Numba loads or
#: compiles a kernel used to reach Python inside LLVM's callback into llvmlite, which dropped the exception
#: and crashed (exit -11).
_BARRAGE = """\
import os, random, signal, sys, threading, time
from analytic import forward
from analytic.scenes.scene_file import load_scene

scene = load_scene(sys.argv[1])
done = threading.Event()
inside = False
interrupts = 0

def interrupt(number, frame):
    # Ctrl-C's KeyboardInterrupt, raised once per attempt, only inside its try (not in this loop's own code)
    global inside, interrupts
    if inside:
        inside = False
        interrupts += 1
        raise KeyboardInterrupt

def send():
    # for 2 s, while the first kernels load, at random moments (then the model runs through)
    pause = random.Random(int(sys.argv[2])).uniform
    ends = time.monotonic() + 2.0
    while time.monotonic() < ends and not done.wait(pause(0.0002, 0.005)):
        os.kill(os.getpid(), signal.SIGINT)

signal.signal(signal.SIGINT, interrupt)
threading.Thread(target=send, daemon=True).start()
while True:
    try:
        inside = True
        y = forward(scene)
        inside = False
        break
    except KeyboardInterrupt:
        pass
done.set()
print(interrupts, float(abs(y).sum()) > 0)
"""



def test_ctrl_c_while_the_kernels_load_waits_for_the_load_and_never_crashes(tmp_path):
    scene = tmp_path / "tilted.toml"
    scene.write_text(tilted_relay_wall(4, 4))
    for seed in range(1):       # a fresh process: every kernel is loaded anew under the barrage
        child = subprocess.run([sys.executable, "-c", _BARRAGE, str(scene), str(seed)], capture_output=True, text=True,
                               timeout=300)
        assert child.returncode == 0, child.stderr[-2000:]
        interrupts, finite = child.stdout.split()
        assert int(interrupts) > 0 and finite == "True"      # interrupted, and then it ran to its end
