"""Issue 22's second probe, its harness: a table of new malformed, extreme and hostile inputs, each judged by the
contract. The tables are tests/cli/probe/test_*.py, one per theme; the reference is tests/probe/cli_reference.py.

Beside ``test_bad_inputs.py``'s table: TOML oddities, PNG and EXR files of
every colour type, depth and pixel type (written here byte by byte, or with
OpenEXR), names and paths, signals at random times and two commands on one
folder, the environment (HOME, locale, TMPDIR, stdout, a full or read-only
disk), and data files for ``check`` and ``reconstruct``.

The promises (README "Refusals" and "Files"): a user's mistake ends in exit
status 2 and one line ``diffuse-imaging: error: ...`` on stderr, before any
file is written (the ``--out`` folder is not created, or stays as it was); a
legal input gets a correct, finite answer (exit 0); never a traceback;
nothing written outside ``--out``; no user file touched; no library notice on
stderr. Each case states its expected outcome from the contract alone; the
numbers are checked against an independent reference: a midpoint-sampled
NumPy integral of docs/design.md section 2's formula (with a bound on its own
error from the samples that straddle a bin edge), closed-form limits, or
scaling laws (y proportional to I, y(s L) = y(L) / s², reciprocity of
the Lambertian attenuation).

Most cases run the command in this process (``validation.cli.main``); those
about the environment, signals and concurrency run ``python -m
validation.cli`` in a child process.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from probe.cli_reference import Geometry, reference

PROGRAM = [sys.executable, "-m", "validation.cli"]
ERROR = "diffuse-imaging: error:"
WARNING = "diffuse-imaging: warning:"
LOCK_FILE = ".diffuse-imaging.lock"           # README "Files": the folder's lock
TEMPORARY_PREFIX = ".diffuse-imaging-tmp-"    # this program's temporaries


def tree(folder: Path, skip: Path | None = None) -> dict[str, str]:
    """Every entry below ``folder`` (not following links) -> what it is (a file's hash)."""
    found = {}
    if not os.path.lexists(folder):
        return found
    for root, folders, files in os.walk(folder):
        root = Path(root)
        if skip is not None and root == skip:
            folders[:] = []
            continue
        for name in folders:
            path = root / name
            if skip is not None and path == skip:
                continue
            found[str(path.relative_to(folder))] = "link" if path.is_symlink() else "folder"
        for name in files:
            path = root / name
            relative = str(path.relative_to(folder))
            if path.is_symlink():
                found[relative] = "link -> " + os.readlink(path)
            elif path.is_file():
                found[relative] = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
            else:
                found[relative] = "special"
    return found


class Probe:
    """One case: its folder, the commands it ran, what they did, and what was wrong."""

    def __init__(self, tmp: Path, capfd):
        self.tmp = tmp
        self.capfd = capfd
        self.out = tmp / "out"
        self.commands: list[str] = []
        self.observed: list[str] = []
        self.problems: list[str] = []
        self.status = None
        self.lines: list[str] = []
        self.stdout = ""

    # ------------------------------------------------------------------ inputs
    def file(self, name: str, data: bytes | str) -> Path:
        path = self.tmp / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data.encode() if isinstance(data, str) else data)
        return path

    def scene(self, text: str | Geometry = None, name: str = "scene.toml", **toml) -> Path:
        text = Geometry() if text is None else text
        if isinstance(text, Geometry):
            text = text.toml(**toml)
        return self.file(name, text)

    def npy(self, name: str, array, **save) -> Path:
        path = self.tmp / name
        np.save(path, array, **save)
        return path

    # ------------------------------------------------------------------ running
    def _before(self):
        self._outside = tree(self.tmp, skip=self.out)
        self._inside = tree(self.out)
        self._existed = os.path.lexists(self.out)

    def _after(self, expect_outside_changes: bool):
        if not expect_outside_changes:
            outside = tree(self.tmp, skip=self.out)
            changed = sorted(set(outside.items()) ^ set(self._outside.items()))
            if changed:
                self.problem(f"files outside --out changed: {sorted({name for name, _ in changed})}")

    def cli(self, *argv, outside_changes: bool = False) -> "Probe":
        """Run ``diffuse-imaging ARGV`` in this process (validation.cli.main)."""
        from validation.cli import main

        argv = [str(a) for a in argv]
        self.commands.append("diffuse-imaging " + " ".join(shlex.quote(a) for a in argv))
        self._before()
        self.capfd.readouterr()
        try:
            self.status = main(argv)
        except SystemExit as exit:
            self.status = exit.code
        except BaseException as error:        # a traceback in the real command
            self.status = f"traceback ({type(error).__name__}: {' '.join(str(error).split())[:200]})"
        captured = self.capfd.readouterr()
        self._record(captured.out, captured.err)
        self._after(outside_changes)
        return self

    def sub(self, *argv, env: dict | None = None, unset=(), cwd: Path | None = None, timeout: float = 60,
            stdout=subprocess.PIPE, outside_changes: bool = False, prefix=()) -> "Probe":
        """Run ``python -m validation.cli ARGV`` in a child process."""
        argv = [str(a) for a in argv]
        environment = {**os.environ, **(env or {})}
        for name in unset:
            environment.pop(name, None)
        shown = " ".join(f"{k}={shlex.quote(v)}" for k, v in (env or {}).items())
        shown += "".join(f" -u {name}" for name in unset)
        wrapped = f" (run as: {' '.join(shlex.quote(str(p)) for p in prefix)} diffuse-imaging ...)" if prefix else ""
        self.commands.append(f"{shown} diffuse-imaging ".lstrip() + " ".join(shlex.quote(a) for a in argv) + wrapped)
        self._before()
        try:
            done = subprocess.run([*prefix, *PROGRAM, *argv], env=environment, cwd=cwd or self.tmp,
                                  stdout=stdout, stderr=subprocess.PIPE, timeout=timeout)
            self.status = done.returncode
            out = done.stdout.decode("utf-8", "replace") if done.stdout is not None else ""
            err = done.stderr.decode("utf-8", "replace")
        except subprocess.TimeoutExpired as expired:
            self.status = f"hung (killed after {timeout} s)"
            out, err = "", (expired.stderr or b"").decode("utf-8", "replace")
        self._record(out, err)
        self._after(outside_changes)
        return self

    def _record(self, out: str, err: str):
        self.stdout = out
        self.lines = [line for line in err.splitlines() if line.strip()]
        files = sorted(tree(self.out)) if os.path.isdir(self.out) else None
        shown = self.lines[:3] + ([f"... {len(self.lines) - 3} more"] if len(self.lines) > 3 else [])
        self.observed.append(f"exit {self.status}; stderr {len(self.lines)} line(s) {shown}; "
                             f"out: {'absent' if files is None else files}")
        if isinstance(self.status, str) or any(line.startswith("Traceback") for line in self.lines):
            self.problem(f"traceback or hang: {self.status}; {self.lines[-1:] }")

    # ------------------------------------------------------------------ judging
    def problem(self, text: str):
        self.problems.append(text)

    def check(self, condition, text: str):
        if not condition:
            self.problem(text)
        return bool(condition)

    def refused(self, *words: str, out_as_it_was: bool = True) -> "Probe":
        """Exit 2, one line naming the problem (each of ``words``), --out as it was."""
        self.check(self.status == 2, f"exit status {self.status}, expected 2")
        if self.check(len(self.lines) == 1, f"{len(self.lines)} stderr lines, expected 1: {self.lines[:4]}"):
            line = self.lines[0]
            # argparse's refusals name the command too: "diffuse-imaging render: error: ..."
            self.check(re.match(r"diffuse-imaging( [a-z]+)?: error: ", line),
                       f"the line does not start with {ERROR!r}: {line}")
            for word in words:
                self.check(word.lower() in line.lower(), f"the line does not name {word!r}: {line}")
        if out_as_it_was:
            self.out_unchanged()
        return self

    def out_unchanged(self):
        if not self._existed:
            self.check(not os.path.lexists(self.out), f"--out was created: {sorted(tree(self.out))}")
        else:
            self.check(tree(self.out) == self._inside, "--out changed: "
                       f"{sorted(set(tree(self.out).items()) ^ set(self._inside.items()))}")

    def answered(self, status: int = 0, warnings: bool = False) -> bool:
        """Exit ``status``, nothing on stderr (or only one-line warnings when allowed)."""
        ok = self.check(self.status == status, f"exit status {self.status}, expected {status}: {self.lines[:2]}")
        stray = [line for line in self.lines if not (warnings and line.startswith(WARNING))]
        ok &= self.check(not stray, f"unexpected stderr: {stray[:3]}")
        return ok

    def refused_or_answered(self, *words: str, warnings: bool = False) -> bool:
        """Either a one-line refusal, or exit 0 (with one-line warnings when allowed); True when it answered
        (its numbers are then checked)."""
        if self.status == 2:
            self.refused(*words)
            return False
        return self.answered(warnings=warnings)

    def y(self, name: str = "transient.npy") -> np.ndarray | None:
        path = self.out / name
        if not path.is_file():
            self.problem(f"{name} was not written")
            return None
        array = np.load(path)
        self.check(np.all(np.isfinite(array)), f"{name} holds non-finite values")
        return array

    def close(self, actual, expected, *, rtol=0.0, atol=None, what="y"):
        """``actual`` equals ``expected`` within ``atol`` (array or number) plus ``rtol`` of it."""
        if actual is None:
            return
        actual, expected = np.asarray(actual, float), np.asarray(expected, float)
        if actual.shape != expected.shape:
            self.problem(f"{what}: shape {actual.shape}, expected {expected.shape}")
            return
        limit = (0.0 if atol is None else atol) + rtol * np.abs(expected)
        excess = np.abs(actual - expected) - limit
        if np.any(excess > 0):
            worst = np.unravel_index(np.argmax(excess), excess.shape)
            self.problem(f"{what}: {actual[worst]:.10g} at {tuple(int(i) for i in worst)}, expected "
                         f"{expected[worst]:.10g} (within {np.broadcast_to(limit, excess.shape)[worst]:.3g})")

    def matches_reference(self, geometry: Geometry, name: str = "transient.npy"):
        y = self.y(name)
        expected, bound = reference(geometry)
        self.close(y, expected, atol=bound, what=f"{name} against the midpoint reference")
        return y

    def meta(self) -> dict:
        path = self.out / "meta.json"
        return json.loads(path.read_text()) if path.is_file() else {}

    def metrics(self) -> dict:
        path = self.out / "metrics.json"
        return json.loads(path.read_text()) if path.is_file() else {}


@dataclasses.dataclass
class Case:
    kind: str
    name: str
    expected: str
    run: object
    slow: bool = False


def case_table():
    """A module's table of cases, and the decorator that adds one: ``@case(kind, name, expected, slow=False)``."""
    cases: list[Case] = []

    def case(kind: str, name: str, expected: str, slow: bool = False):
        def register(function):
            cases.append(Case(kind, name, expected, function, slow))
            return function
        return register
    return cases, case


def case_test(cases: list[Case]):
    """The test that runs each case of a module's table (node id ``test_case[kind: name]``)."""
    # many cases draw the same figure (the same scene's transient): drawn once (tests/conftest.py)
    @pytest.mark.usefixtures("figures_drawn_once")
    @pytest.mark.filterwarnings("default")
    @pytest.mark.parametrize("probe_case", [pytest.param(c, marks=[pytest.mark.slow] if c.slow else [],
                                                         id=f"{c.kind}: {c.name}") for c in cases])
    def test_case(probe_case, tmp_path, capfd, record_property):
        probe = Probe(tmp_path, capfd)
        try:
            probe_case.run(probe)
        finally:
            record_property("expected", probe_case.expected)
            record_property("commands", " ; ".join(probe.commands))
            record_property("observed", " | ".join(probe.observed))
            record_property("problems", " | ".join(probe.problems))
        assert not probe.problems, probe.problems
    return test_case


def forward(probe: Probe, scene, *more, **options):
    return probe.cli("forward", scene, "--out", probe.out, "--quiet", *more, **options)


#: The probe's plane scene, legal in every respect.
GOOD = Geometry()


def noisy_data(geometry: Geometry = GOOD, scale: float = 1.0, shift: float = 0.0, relative_error: float = 0.02,
          seed: int = 0):
    """(data, stderr): the reference times ``scale`` on a window read ``shift`` metres short, plus noise."""
    truth, _ = reference(dataclasses.replace(geometry, start=geometry.start + shift))
    stderr = np.full(truth.shape, relative_error * np.abs(truth).max())
    return scale * truth + np.random.default_rng(seed).normal(0, 1, truth.shape) * stderr, stderr


def check_command(probe: Probe, data, stderr=None, *more, scene=None):
    """``check`` of ``data`` (a file or a list of replicas) against the probe's scene, into ``--out``."""
    argv = ["check", scene or probe.scene(), "--data", *([data] if not isinstance(data, list) else data)]
    if stderr is not None:
        argv += ["--stderr", stderr]
    return probe.cli(*argv, *more, "--out", probe.out, "--quiet")
