"""From nothing compiled to a first answer: the cold and warm runs of the commands a new user starts with.

The project is installed as a user installs it: ``pip install .`` of the checked-out revision (its files as
``git archive`` gives them, nothing compiled) into a fresh virtual environment. Each case then runs as a
user would, in a fresh process (``python -m validation.cli ...``), wall time:

- ``--help``: the start-up of a command;
- ``forward examples/paper.toml``: cold (the kernels' cache empty: a first run after ``pip install .``),
  then warm (the same command again);
- ``check`` of a render of the example: cold (kernels' cache empty again; the render itself is made
  first, warm) and warm;
- a read-only install: the installed kernels' ``__pycache__`` made impossible (a file stands in its place),
  run with a fresh user cache folder (``XDG_CACHE_HOME``): cold, then warm (found in that folder);
- with ``--before REV``: the cold ``forward`` of that revision too (a copy of it checked out beside, run
  from its sources), the baseline of the ratio.

Every cold case gets its own empty kernel cache (``NUMBA_CACHE_DIR`` in a temporary folder, or the fresh
user cache folder); the renderer's (Dr.Jit's) cache is left as it is. The install's own time is printed. Prints a table (seconds, and
cold / warm) and the compile notice each cold run printed on stderr. Usage::

    python3 benchmarks/bench_cold_start.py [--before REV]
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "paper.toml"
#: The commands' working folder: empty (``python -m`` puts it first on the path), made in main().
_EMPTY = Path(tempfile.gettempdir())


def _machine() -> str:
    name = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as handle:
            name = next(line.split(":", 1)[1].strip() for line in handle if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{name}, {os.cpu_count()} cores"


def _install(folder: Path) -> tuple[Path, float]:
    """(python, seconds): a fresh virtual environment in ``folder`` with ``pip install .`` of HEAD in it."""
    source = folder / "source"
    source.mkdir(parents=True)
    archive = subprocess.run(["git", "archive", "--format=tar", "HEAD"], cwd=ROOT, check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(source)], input=archive, check=True)
    subprocess.run([sys.executable, "-m", "venv", str(folder / "venv")], check=True)
    python = folder / "venv" / "bin" / "python"
    started = time.perf_counter()
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", str(source)],
                   check=True, capture_output=True)
    return python, time.perf_counter() - started


def _run(python: Path, arguments: list[str], *, env: dict | None = None,
         path: Path | None = None) -> tuple[float, str]:
    """(wall seconds, stderr) of ``python -m validation.cli ARGUMENTS`` (the sources at ``path`` if given).

    Run from a folder of its own: ``python -m`` puts its working folder first on the path.
    """
    environment = {key: value for key, value in os.environ.items()
                   if key not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    environment.update(env or {})
    if path is not None:
        environment["PYTHONPATH"] = str(path)
    started = time.perf_counter()
    done = subprocess.run([str(python), "-m", "validation.cli", *arguments], cwd=_EMPTY,
                          env=environment, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    allowed = (0, 1) if arguments[:1] == ["check"] else (0,)      # check: 1 when the data disagree
    if done.returncode not in allowed or "Traceback" in done.stderr:
        raise SystemExit(f"{' '.join(arguments)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    return seconds, done.stderr.strip()


def _make_read_only(python: Path) -> None:
    """The installed kernels' ``__pycache__`` emptied and made impossible (a file stands in its place)."""
    kernels = subprocess.run([str(python), "-c", "import analytic.kernels as k, os; print(os.path.dirname(k.__file__))"],
                             check=True, capture_output=True, text=True, cwd=_EMPTY).stdout.strip()
    assert Path(kernels).is_relative_to(python.parents[1]), kernels     # the installed copy, not these sources
    cache = Path(kernels) / "__pycache__"
    shutil.rmtree(cache, ignore_errors=True)
    cache.write_text("read-only install", encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", metavar="REV", help="also the cold forward of this revision")
    args = parser.parse_args()
    rows = []
    notices = []
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        global _EMPTY
        _EMPTY = scratch / "cwd"
        _EMPTY.mkdir()
        python, installed = _install(scratch / "install")
        rows.append(("pip install . (fresh environment)", installed, None))
        rows.append(("--help", _run(python, ["--help"])[0], None))
        forward = ["forward", str(EXAMPLE), "--quiet", "--out"]
        cold, notice = _run(python, forward + [str(scratch / "f1")])
        notices.append(("forward, cold", notice))
        warm = _run(python, forward + [str(scratch / "f2")])[0]
        rows.append(("forward examples/paper.toml", cold, warm))
        _run(python, ["render", str(EXAMPLE), "--spp", "65536", "--out", str(scratch / "render"), "--quiet"])
        check = ["check", str(EXAMPLE), "--data", str(scratch / "render"), "--quiet", "--out"]
        _make_read_only(python)       # empties the kernels' cache: the check below compiles afresh
        user = {"XDG_CACHE_HOME": str(scratch / "user-cache-check")}
        cold, notice = _run(python, check + [str(scratch / "c1")], env=user)
        notices.append(("check, cold", notice))
        warm = _run(python, check + [str(scratch / "c2")], env=user)[0]
        rows.append(("check of a render (65,536 samples)", cold, warm))
        user = {"XDG_CACHE_HOME": str(scratch / "user-cache")}
        cold, notice = _run(python, forward + [str(scratch / "r1")], env=user)
        notices.append(("read-only install, new user, cold", notice))
        warm = _run(python, forward + [str(scratch / "r2")], env=user)[0]
        rows.append(("forward, read-only install, new user", cold, warm))
        if args.before:
            before = scratch / "before"
            subprocess.run(["git", "worktree", "add", "--detach", str(before), args.before], cwd=ROOT, check=True,
                           capture_output=True)
            try:
                seconds = _run(python, forward + [str(scratch / "b1")],
                               env={"NUMBA_CACHE_DIR": str(scratch / "cache-before")}, path=before)[0]
                rows.append((f"forward examples/paper.toml at {args.before}", seconds, None))
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(before)], cwd=ROOT, capture_output=True)
    print(f"machine: {_machine()}; Python {platform.python_version()}")
    print(f"{'case':44s} {'cold s':>8s} {'warm s':>8s} {'cold/warm':>9s}")
    for name, cold, warm in rows:
        ratio = f"{cold / warm:9.1f}" if warm else " " * 9
        print(f"{name:44s} {cold:8.2f} {warm if warm is not None else float('nan'):8.2f} {ratio}")
    for name, notice in notices:
        print(f"{name}: stderr: {notice or '(nothing)'}")


if __name__ == "__main__":
    main()
