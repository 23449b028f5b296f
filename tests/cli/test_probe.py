"""Issue 22's second probe: a table of new malformed, extreme and hostile inputs, each judged by the contract.

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
import math
import os
import re
import shlex
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

#: Many cases draw the same figure (the same scene's transient): drawn once (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("figures_drawn_once")

PROGRAM = [sys.executable, "-m", "validation.cli"]
ERROR = "diffuse-imaging: error:"
WARNING = "diffuse-imaging: warning:"
LOCK_FILE = ".diffuse-imaging.lock"           # README "Files": the folder's lock
TEMPORARY_PREFIX = ".diffuse-imaging-tmp-"    # this program's temporaries


# ======================================================================== scenes and the reference

@dataclasses.dataclass
class Geometry:
    """A plane scene as plain numbers: written to TOML here, and integrated here by brute force."""

    size: float = 1.0
    pixels: int = 8
    reflectance: object = 0.5                  # a number, or an (M, M) array written to an image file
    source: tuple = (0.5, 0.5, 1.0)
    intensity: float = 1.0
    sensors: tuple = ((0.2, 0.7, 1.0),)
    period: float = 0.1
    start: float = 1.9
    count: int = 12
    attenuation: str = "lambertian"
    waveform: str = "impulse"
    width: float | None = None

    def toml(self, image: str | None = None, extra: str = "") -> str:
        """The scene file; ``image`` replaces the reflectance by that file name."""
        reflectance = f'"{image}"' if image is not None else _number(self.reflectance)
        sensors = ", ".join(_point(p) for p in self.sensors)
        width = "" if self.width is None else f"width = {_number(self.width)}\n"
        return (f"[plane]\nsize = {_number(self.size)}\npixels = {self.pixels}\nreflectance = {reflectance}\n"
                f"[source]\nposition = {_point(self.source)}\nintensity = {_number(self.intensity)}\n"
                f'[illumination]\nwaveform = "{self.waveform}"\n{width}'
                f"[sensors]\npositions = [{sensors}]\n"
                f"[sampling]\nperiod = {_number(self.period)}\nstart = {_number(self.start)}\n"
                f"count = {self.count}\n"
                f'[model]\nattenuation = "{self.attenuation}"\n{extra}')

    def scaled(self, factor: float) -> "Geometry":
        """Every length times ``factor`` (positions, size, period, start)."""
        return dataclasses.replace(
            self, size=self.size * factor, source=tuple(v * factor for v in self.source),
            sensors=tuple(tuple(v * factor for v in p) for p in self.sensors),
            period=self.period * factor, start=self.start * factor)

    def image(self) -> np.ndarray:
        if np.ndim(self.reflectance) == 0:
            return np.full((self.pixels, self.pixels), float(self.reflectance))
        return np.asarray(self.reflectance, dtype=np.float64)


def _number(value) -> str:
    return repr(float(value)) if not isinstance(value, int) else str(value)


def _point(point) -> str:
    return "[" + ", ".join(_number(v) for v in point) + "]"


def _samples(geometry: Geometry, grid: int):
    """Midpoints of a grid x grid partition of the plane (grid a multiple of M), their ρ and cell area."""
    assert grid % geometry.pixels == 0
    size = geometry.size
    step = size / grid
    centres = (np.arange(grid) + 0.5) * step
    x, y = np.meshgrid(centres, centres)
    # docs/design.md section 1: image[r, c] covers x in [cΔ, (c+1)Δ), y in [L-(r+1)Δ, L-rΔ)
    per_pixel = grid // geometry.pixels
    column = np.arange(grid) // per_pixel
    row = (grid - 1 - np.arange(grid)) // per_pixel            # y index counted from the bottom
    rho = geometry.image()[row[:, None], column[None, :]]
    return x.ravel(), y.ravel(), rho.ravel(), step


def _attenuation(geometry: Geometry, x, y, sensor):
    """docs/design.md section 2's a_k(x) and d(x), written out again."""
    sx, sy, sz = geometry.source
    kx, ky, kz = sensor
    ds = np.sqrt((x - sx) ** 2 + (y - sy) ** 2 + sz**2)
    dk = np.sqrt((x - kx) ** 2 + (y - ky) ** 2 + kz**2)
    cos_s, cos_k = sz / ds, kz / dk
    if geometry.attenuation == "lambertian":
        return cos_s * cos_k / (math.pi * ds**2 * dk**2), ds + dk
    return cos_s / (ds**2 * dk**2), ds + dk


def _edge_distance(length, geometry: Geometry):
    """Distance from each path length to the nearest bin edge, metres."""
    index = np.clip(np.rint((length - geometry.start) / geometry.period), 0, geometry.count)
    return np.abs(length - (geometry.start + index * geometry.period))


_REFERENCES: dict = {}


def reference(geometry: Geometry) -> tuple[np.ndarray, np.ndarray]:
    """:func:`binned_reference`, computed once per geometry."""
    key = repr(dataclasses.replace(geometry, reflectance=geometry.image().tobytes()))
    if key not in _REFERENCES:
        _REFERENCES[key] = binned_reference(geometry)
    y, bound = _REFERENCES[key]
    return y.copy(), bound.copy()


def binned_reference(geometry: Geometry, grid: int = 256, levels: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(y, bound): the binned transient by midpoint samples, and a bound on each bin's error.

    The impulse puts each cell's f a ΔA in the bin of its midpoint's path
    length; a cell whose path lengths may cross a bin edge (|∇d| <= 2 and a
    half-diagonal of h/√2: its midpoint within √2 h of an edge) is cut into
    4 x 4 and looked at again, ``levels`` times; the weight of the cells
    still straddling an edge at the end bounds the binning error (added to
    the bins on both sides). A square pulse of width w spreads a cell's
    weight over [d, d + w], a continuous function of d. 2e-5 of the peak
    covers the midpoint rule's smooth error (h²/24 of the integrand's
    curvature, h = L/256).
    """
    edges = geometry.start + geometry.period * np.arange(geometry.count + 1)
    width = geometry.width if geometry.width is not None else geometry.period / 5.0
    out = np.zeros((len(geometry.sensors), geometry.count))
    bound = np.zeros_like(out)
    x0, y0, rho0, step0 = _samples(geometry, grid)

    def deposit(k, length, weight, into):
        index = np.floor((length - geometry.start) / geometry.period).astype(np.int64)
        inside = (index >= 0) & (index < geometry.count)
        into[k] += np.bincount(index[inside], weights=weight[inside], minlength=geometry.count)

    for k, sensor in enumerate(geometry.sensors):
        if geometry.waveform != "impulse":           # square: twice as fine, for the overlap's kinks
            x, y, rho, step = _samples(geometry, 2 * grid)
            weight, length = _attenuation(geometry, x, y, sensor)
            weight = rho * weight * step**2
            out[k] = np.maximum(0.0, np.minimum(edges[1:, None], length[None, :] + width)
                                - np.maximum(edges[:-1, None], length[None, :])) @ weight
            continue
        x, y, rho, step = x0, y0, rho0, step0
        for level in range(levels + 1):
            weight, length = _attenuation(geometry, x, y, sensor)
            weight = rho * weight * step**2
            near = _edge_distance(length, geometry) <= math.sqrt(2.0) * step
            if level == levels:
                deposit(k, length, weight, out)
                for shift in (-1.0, 0.0, 1.0):      # a straddling cell may belong to either side
                    deposit(k, length[near] + shift * geometry.period, weight[near], bound)
                break
            deposit(k, length[~near], weight[~near], out)
            offsets = ((np.arange(4) + 0.5) / 4 - 0.5) * step
            x = (x[near][:, None, None] + offsets[None, :, None] + 0 * offsets[None, None, :]).ravel()
            y = (y[near][:, None, None] + 0 * offsets[None, :, None] + offsets[None, None, :]).ravel()
            rho = np.repeat(rho[near], 16)
            step = step / 4
    y = geometry.intensity * out
    bound = geometry.intensity * bound + 2e-5 * np.abs(y).max()
    return y, bound


def reference_total(geometry: Geometry, grid: int = 2048) -> np.ndarray:
    """I ∫ f a_k dx per sensor (the impulse's whole response), ``(K,)``."""
    x, y, rho, step = _samples(geometry, grid)
    return geometry.intensity * np.array(
        [np.sum(rho * _attenuation(geometry, x, y, s)[0]) * step**2 for s in geometry.sensors])


# ======================================================================== image files, written here

def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bytes(samples: np.ndarray, bitdepth: int, colour_type: int, *, palette=None, trns: bytes | None = None,
              chunks=(), declared: tuple[int, int] | None = None) -> bytes:
    """A PNG, byte by byte: samples ``(H, W, planes)`` of unsigned integers, filter 0, no interlace."""
    samples = np.asarray(samples)
    height, width, planes = samples.shape
    rows = []
    for row in samples:
        flat = row.reshape(-1).astype(np.uint64)
        if bitdepth < 8:
            bits = ((flat[:, None] >> np.arange(bitdepth - 1, -1, -1, dtype=np.uint64)) & 1).astype(np.uint8)
            packed = np.packbits(bits.reshape(-1)).tobytes()
        elif bitdepth == 8:
            packed = flat.astype(np.uint8).tobytes()
        else:
            packed = flat.astype(">u2").tobytes()
        rows.append(b"\0" + packed)
    w, h = declared or (width, height)
    header = struct.pack(">IIBBBBB", w, h, bitdepth, colour_type, 0, 0, 0)
    body = [_chunk(b"IHDR", header)]
    body += [_chunk(kind, data) for kind, data in chunks]
    if palette is not None:
        body.append(_chunk(b"PLTE", bytes(np.asarray(palette, np.uint8)[:, :3].reshape(-1))))
    if trns is not None:
        body.append(_chunk(b"tRNS", trns))
    body.append(_chunk(b"IDAT", zlib.compress(b"".join(rows))))
    body.append(_chunk(b"IEND", b""))
    return b"\x89PNG\r\n\x1a\n" + b"".join(body)


def write_exr(path: Path, channels: dict, compression: str = "ZIP", tiled: bool = False) -> Path:
    import OpenEXR

    header = {"compression": getattr(OpenEXR, f"{compression}_COMPRESSION"),
              "type": OpenEXR.tiledimage if tiled else OpenEXR.scanlineimage}
    if tiled:
        tiles = OpenEXR.TileDescription()
        tiles.xSize, tiles.ySize, tiles.mode = 4, 4, OpenEXR.ONE_LEVEL
        header["tiles"] = tiles
    OpenEXR.File(header, channels).write(str(path))
    return path


def pattern(pixels: int, levels: int, seed: int = 7) -> np.ndarray:
    """A random image of integer levels 0 .. levels - 1 that uses the extremes."""
    values = np.random.default_rng(seed).integers(0, levels, size=(pixels, pixels))
    values.flat[0], values.flat[-1] = 0, levels - 1
    return values


# ======================================================================== the probe: run, observe, judge

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


CASES: list[Case] = []


def case(kind: str, name: str, expected: str, slow: bool = False):
    def register(function):
        CASES.append(Case(kind, name, expected, function, slow))
        return function
    return register


def forward(probe: Probe, scene, *more, **options):
    return probe.cli("forward", scene, "--out", probe.out, "--quiet", *more, **options)


# ======================================================================== TOML oddities (forward)

GOOD = Geometry()


def _toml_answer(kind_name: str, text_of, expected: str = "exit 0, y equal to the midpoint reference"):
    def run(probe: Probe):
        if forward(probe, probe.file("scene.toml", text_of(GOOD.toml()))).answered():
            probe.matches_reference(GOOD)
    case("toml", kind_name, expected)(run)


def _toml_refusal(kind_name: str, text_of, *words: str):
    def run(probe: Probe):
        forward(probe, probe.file("scene.toml", text_of(GOOD.toml()))).refused(*words)
    case("toml", kind_name, f"exit 2, one line naming {', '.join(words) or 'the file'}, no --out")(run)


_toml_answer("CRLF line endings", lambda t: t.replace("\n", "\r\n"))
_toml_answer("UTF-8 BOM and CRLF", lambda t: "\ufeff" + t.replace("\n", "\r\n"))
_toml_answer("tabs, blank lines and trailing comments",
             lambda t: "\n\n".join("\t" + line + "\t# note" if "=" in line else line for line in t.splitlines()))
_toml_answer("top-level dotted keys instead of tables",
             lambda t: "plane.size = 1.0\nplane.pixels = 8\nplane.reflectance = 0.5\n"
                       "source.position = [0.5, 0.5, 1.0]\nsensors.positions = [[0.2, 0.7, 1.0]]\n"
                       "sampling.period = 0.1\nsampling.start = 1.9\nsampling.count = 12\n")
_toml_answer("inline tables", lambda t: "plane = { size = 1.0, pixels = 8, reflectance = 0.5 }\n"
                                         "source = { position = [0.5, 0.5, 1.0] }\n"
                                         "sensors = { positions = [[0.2, 0.7, 1.0]] }\n"
                                         "sampling = { period = 0.1, start = 1.9, count = 12 }\n")
_toml_answer("quoted table names", lambda t: t.replace("[plane]", '["plane"]').replace("[sampling]", "['sampling']"))
_toml_answer("integer with underscores (count = 1_2)", lambda t: t.replace("count = 12", "count = 1_2"))
_toml_answer("hexadecimal pixels (0x8)", lambda t: t.replace("pixels = 8", "pixels = 0x8"))
_toml_answer("octal pixels (0o10)", lambda t: t.replace("pixels = 8", "pixels = 0o10"))
_toml_answer("binary pixels (0b1000)", lambda t: t.replace("pixels = 8", "pixels = 0b1000"))
_toml_answer("capital exponent (period = 1E-1)", lambda t: t.replace("period = 0.1", "period = 1E-1"))
_toml_answer("positive sign and integers in a point (+1)",
             lambda t: t.replace("[0.5, 0.5, 1.0]", "[0.5, 0.5, +1]"))
_toml_answer("literal string waveform ('impulse')", lambda t: t.replace('"impulse"', "'impulse'"))
_toml_answer("multi-line string waveform", lambda t: t.replace('"impulse"', '"""impulse"""'))
_toml_answer("a 200 kB comment line", lambda t: "# " + "x" * 200_000 + "\n" + t)


@case("toml", "start = -1e-400 (underflows to -0.0)", "exit 0, window from 0 (mostly empty: a one-line warning): "
                                                       "y equal to the reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, start=0.0, count=40)
    text = geometry.toml().replace("start = 0.0", "start = -1e-400")
    if forward(probe, probe.file("scene.toml", text)).answered(warnings=True):
        probe.matches_reference(geometry)


@case("toml", "pixels = 8.0 (a whole float)", "exit 2 naming plane.pixels, or exit 0 with M = 8")
def _(probe):
    if forward(probe, probe.file("scene.toml", GOOD.toml().replace("pixels = 8", "pixels = 8.0"))) \
            .refused_or_answered("plane.pixels"):
        probe.matches_reference(GOOD)


_toml_refusal("CR-only (old Mac) line endings", lambda t: t.replace("\n", "\r"), "scene.toml")
_toml_refusal("quoted key with a dot (\"plane.size\" = 1)", lambda t: '"plane.size" = 1.0\n' + t, "plane.size")
_toml_refusal("pixels = 8.5", lambda t: t.replace("pixels = 8", "pixels = 8.5"), "plane.pixels")
_toml_refusal("size = 1e400 (overflows to inf)", lambda t: t.replace("size = 1.0", "size = 1e400"), "plane.size")
_toml_refusal("waveform with a trailing space", lambda t: t.replace('"impulse"', '"impulse "'),
              "illumination.waveform")
_toml_refusal("table [Plane] capitalised", lambda t: t.replace("[plane]", "[Plane]"), "Plane")
_toml_refusal("[[sensors]] array of tables",
              lambda t: t.replace("[sensors]\npositions = [[0.2, 0.7, 1.0]]",
                                  "[[sensors]]\npositions = [[0.2, 0.7, 1.0]]"), "sensors")
_toml_refusal("a string inside the source position", lambda t: t.replace("[0.5, 0.5, 1.0]", '[0.5, 0.5, "1"]'),
              "source.position")
_toml_refusal("four coordinates for the source", lambda t: t.replace("[0.5, 0.5, 1.0]", "[0.5, 0.5, 1.0, 0.0]"),
              "source.position")
_toml_refusal("sensors.positions flat, not nested",
              lambda t: t.replace("[[0.2, 0.7, 1.0]]", "[0.2, 0.7, 1.0]"), "sensors.positions")
_toml_refusal("only comments and blank lines", lambda t: "# a scene\n\n# nothing else\n", "scene.toml")
_toml_refusal("larger than 1 MiB", lambda t: t + "# " + "x" * (1 << 20) + "\n", "scene.toml")
_toml_refusal("name inside [plane]", lambda t: t.replace("[plane]\n", '[plane]\nname = "x"\n'), "plane.name")
_toml_refusal("unknown key sigma_ in [noise]", lambda t: t + "[noise]\nsigma_ = 0.1\n", "noise.sigma_")
_toml_refusal("tolerance = 0.1 (upper bound excluded)", lambda t: t + "tolerance = 0.1\n", "model.tolerance")
_toml_refusal("tolerance = 1e-11 (below 1e-10)", lambda t: t + "tolerance = 1e-11\n", "model.tolerance")
_toml_refusal("butterworth order 21", lambda t: t.replace('"impulse"', '"butterworth"\norder = 21'),
              "illumination.order")
_toml_refusal("intensity just above 1e30", lambda t: t.replace("intensity = 1.0", "intensity = 1.0000001e30"),
              "source.intensity")
_toml_refusal("sensor 1e-10 above the plane (below 1e-9 of the extent)",
              lambda t: t.replace("[[0.2, 0.7, 1.0]]", "[[0.2, 0.7, 1e-10]]"), "sensors.positions")
_toml_refusal("grid of 25 x 41 = 1025 sensors",
              lambda t: t.replace("positions = [[0.2, 0.7, 1.0]]", "grid = [25, 41]\ncenter = [0.5, 0.5, 1.0]"),
              "sensors.grid")
_toml_refusal("[relay_wall] on a plane scene (NLOS keys mixed in)", lambda t: t + "[relay_wall]\nsize = [2.0, 2.0]\n",
              "relay_wall")


@case("toml", "scene path /dev/null", "exit 2, one line naming the device")
def _(probe):
    forward(probe, "/dev/null").refused("/dev/null")


@case("toml", "scene file name with a space and an accent", "exit 0, meta.json scene = the stem 'my scène'")
def _(probe):
    if forward(probe, probe.scene(name="my scène.toml")).answered():
        probe.matches_reference(GOOD)
        probe.check(probe.meta().get("scene") == "my scène", f"meta scene {probe.meta().get('scene')!r}")


@case("toml", "scene file name starting with '-' given bare", "exit 2, argparse's one line")
def _(probe):
    probe.scene(name="-scene.toml")
    probe.cli("forward", "-scene.toml", "--out", probe.out).refused()


@case("toml", "empty [noise] table: every noise default", "exit 0, transient_noisy.npy = y + N(0, 0.1²)")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra="[noise]\n"))).answered():
        y, noisy = probe.matches_reference(GOOD), probe.y("transient_noisy.npy")
        if y is not None and noisy is not None:
            noise = noisy - y
            probe.check(np.all(np.abs(noise) < 6 * 0.1) and np.any(noise != 0), f"noise {noise}")


# ======================================================================== numbers: laws and references

@case("numbers", "intensity law: I = 1e-300, 1e-30, 3.5, 1e30 against I = 1",
      "exit 0 each; y / I equal to 1e-14 across I, and to the reference at I = 1")
def _(probe):
    base = forward(probe, probe.scene(GOOD, "one.toml")).answered() and probe.matches_reference(GOOD)
    for intensity in (1e-300, 1e-30, 3.5, 1e30):
        geometry = dataclasses.replace(GOOD, intensity=intensity)
        forward(probe, probe.scene(geometry, f"i{intensity:g}.toml"))
        # at 1e-300 the EXR is not written, with a one-line warning (README "Files")
        if probe.answered(warnings=True) and base is not None:
            probe.close(probe.y() / intensity, base, rtol=1e-14, what=f"y / I at I = {intensity:g}")


for _factor in (1e-8, 1e-6, 1e6, 1e9):
    @case("numbers", f"similarity: every length x {_factor:g}", "exit 0; y s² equal to y at s = 1 (rtol 1e-5)")
    def _(probe, factor=_factor):
        geometry = GOOD.scaled(factor)
        if forward(probe, probe.scene(geometry)).answered():
            expected, bound = reference(GOOD)
            probe.close(probe.y() * factor**2, expected, atol=bound, what="y s²")


@case("numbers", "reciprocity: source and sensor swapped (lambertian)", "exit 0; y equal to the unswapped (1e-6)")
def _(probe):
    swapped = dataclasses.replace(GOOD, source=GOOD.sensors[0], sensors=(GOOD.source,))
    forward(probe, probe.scene(GOOD, "a.toml"))
    first = probe.y() if probe.answered() else None
    forward(probe, probe.scene(swapped, "b.toml"))
    if probe.answered() and first is not None:
        probe.close(probe.y(), first, rtol=1e-6, atol=1e-9 * np.abs(first).max(), what="swapped y")


@case("numbers", "paper attenuation (eq. 1), two sensors", "exit 0; y equal to the midpoint reference of eq. 1")
def _(probe):
    geometry = dataclasses.replace(GOOD, attenuation="paper", sensors=((0.2, 0.7, 1.0), (0.9, 0.1, 0.4)),
                                   count=20, start=1.2)
    if forward(probe, probe.scene(geometry)).answered():
        probe.matches_reference(geometry)


@case("numbers", "one bin of 1e12 m from -5e11 m", "exit 0; y = the whole response I ∫ f a (1e-5)")
def _(probe):
    geometry = dataclasses.replace(GOOD, start=-5e11, period=1e12, count=1)
    if forward(probe, probe.scene(geometry)).answered():
        probe.close(probe.y()[:, 0], reference_total(geometry), rtol=1e-5, what="the one bin")


@case("numbers", "window far after the light (start 1e9)", "exit 0 with a one-line window warning; y = 0")
def _(probe):
    geometry = dataclasses.replace(GOOD, start=1e9)
    if forward(probe, probe.scene(geometry)).answered(warnings=True):
        probe.check(len(probe.lines) == 1 and "window" in probe.lines[0], f"warning {probe.lines}")
        y = probe.y()
        probe.check(y is not None and np.all(y == 0), "y is not 0 outside the light")


@case("numbers", "sensor at the source", "exit 0 (7 of 12 bins empty: a one-line warning); y equal to the reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, sensors=(GOOD.source,), start=1.9)
    if forward(probe, probe.scene(geometry)).answered(warnings=True):
        probe.matches_reference(geometry)


@case("numbers", "sensor 1e-6 m above the plane", "exit 0; total -> 2 ρ I cos θ_s / d_s² (the point's limit, 1e-4)")
def _(probe):
    geometry = dataclasses.replace(GOOD, sensors=((0.3, 0.6, 1e-6),), start=0.0, period=10.0, count=1)
    if forward(probe, probe.scene(geometry)).answered():
        d2 = 0.2**2 + 0.1**2 + 1.0
        limit = 2 * 0.5 * (1 / math.sqrt(d2)) / d2
        probe.close(probe.y()[0, 0], limit, rtol=1e-4, what="total under a low sensor")


@case("numbers", "source 1e-6 m above the plane, paper attenuation",
      "exit 0; total -> 2π ρ I / d_k² (eq. 1's limit, 1e-4)")
def _(probe):
    geometry = dataclasses.replace(GOOD, source=(0.4, 0.3, 1e-6), attenuation="paper", start=0.0, period=10.0,
                                   count=1)
    if forward(probe, probe.scene(geometry)).answered():
        d2 = 0.2**2 + 0.4**2 + 1.0
        probe.close(probe.y()[0, 0], 2 * math.pi * 0.5 / d2, rtol=1e-4, what="total under a low source")


@case("numbers", "grid [2, 2], extent 0.5", "exit 0; rows = the reference at centre ± W/2 (as a set)")
def _(probe):
    text = GOOD.toml().replace("positions = [[0.2, 0.7, 1.0]]", "grid = [2, 2]\nextent = 0.5\ncenter = [0.5, 0.5, 1.0]")
    if forward(probe, probe.file("scene.toml", text)).answered():
        points = tuple((x, y, 1.0) for x in (0.25, 0.75) for y in (0.25, 0.75))
        geometry = dataclasses.replace(GOOD, sensors=points)
        expected, bound = reference(geometry)
        y = probe.y()
        if y is not None and probe.check(y.shape == expected.shape, f"shape {y.shape}"):
            order = np.lexsort(expected.T[::-1])
            got = np.lexsort(y.T[::-1])
            probe.close(y[got], expected[order], atol=bound[order], what="grid rows")


@case("numbers", "grid [1, 1]", "exit 0; the one sensor at the centre")
def _(probe):
    text = GOOD.toml().replace("positions = [[0.2, 0.7, 1.0]]", "grid = [1, 1]\ncenter = [0.2, 0.7, 1.0]")
    if forward(probe, probe.file("scene.toml", text)).answered():
        probe.matches_reference(GOOD)


@case("numbers", "grid [32, 32]: 1024 sensors (the most)", "exit 0; y of shape (1024, 12), finite, ≥ 0", slow=True)
def _(probe):
    text = GOOD.toml().replace("positions = [[0.2, 0.7, 1.0]]", "grid = [32, 32]\ncenter = [0.5, 0.5, 1.0]")
    if forward(probe, probe.file("scene.toml", text)).answered():
        y = probe.y()
        probe.check(y is not None and y.shape == (1024, 12) and np.all(y >= 0), "y shape or sign")


@case("numbers", "two identical sensors", "exit 0; two equal rows, each the reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, sensors=GOOD.sensors * 2)
    if forward(probe, probe.scene(geometry)).answered():
        y = probe.matches_reference(geometry)
        probe.check(y is not None and np.array_equal(y[0], y[1]), "the rows differ")


@case("numbers", "pixels = 1", "exit 0; y equal to the reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, pixels=1)
    if forward(probe, probe.scene(geometry)).answered():
        probe.matches_reference(geometry)


@case("numbers", "square pulse of width 0.037", "exit 0; y equal to the reference (box of I over [d, d + w])")
def _(probe):
    geometry = dataclasses.replace(GOOD, waveform="square", width=0.037)
    if forward(probe, probe.scene(geometry)).answered():
        probe.matches_reference(geometry)


@case("numbers", "square pulse of width 1e-9", "exit 0; total = I w ∫ f a (1e-5)")
def _(probe):
    geometry = dataclasses.replace(GOOD, waveform="square", width=1e-9)
    if forward(probe, probe.scene(geometry)).answered():
        probe.close(probe.y().sum(), 1e-9 * reference_total(geometry)[0], rtol=1e-5, what="total")


@case("numbers", "butterworth order 1, cutoff 5, long duration",
      "exit 0; total = I/(2π fc) ∫ f a: s = exp(-2π fc t)")
def _(probe):
    text = GOOD.toml().replace('"impulse"', '"butterworth"\norder = 1\ncutoff = 5.0\nduration = 50.0') \
        .replace("count = 12", "count = 60")
    if forward(probe, probe.file("scene.toml", text)).answered(warnings=True):
        area = 1.0 / (2 * math.pi * 5.0)
        probe.close(probe.y().sum(), area * reference_total(GOOD)[0], rtol=1e-5, what="total")


@case("numbers", "butterworth order 20 (the most)", "exit 0; total = I ∫ s ∫ f a, ∫ s from the analogue filter")
def _(probe):
    from scipy import signal as scipy_signal

    cutoff, duration = 5.0, 4.0
    text = GOOD.toml().replace('"impulse"', f'"butterworth"\norder = 20\ncutoff = {cutoff}\nduration = {duration}') \
        .replace("count = 12", "count = 60")
    if forward(probe, probe.file("scene.toml", text)).answered(warnings=True):
        # the analogue filter's impulse response h: its peak on a fine grid, its integral to the
        # truncation from the step response
        b, a = scipy_signal.butter(20, 2 * math.pi * cutoff, analog=True)
        _, response = scipy_signal.impulse((b, a), T=np.linspace(0.0, duration, 20_001))
        _, step = scipy_signal.step((b, a), T=np.array([0.0, duration]))
        area = step[-1] / response.max()
        probe.close(probe.y().sum(), area * reference_total(GOOD)[0], rtol=1e-3, what="total")


@case("numbers", "poisson noise, photons = 1e25", "exit 0 with noisy y = y (to 1e-9), or a one-line refusal")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra='[noise]\nkind = "poisson"\nphotons = 1e25\n'))) \
            .refused_or_answered("noise.photons"):
        y, noisy = probe.y(), probe.y("transient_noisy.npy")
        probe.close(noisy, y, rtol=1e-9, what="noisy y")


@case("numbers", "poisson noise, photons = 1e-300", "exit 0, noisy y finite and ≥ 0, or a one-line refusal")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra='[noise]\nkind = "poisson"\nphotons = 1e-300\n'))) \
            .refused_or_answered("noise.photons"):
        noisy = probe.y("transient_noisy.npy")
        probe.check(noisy is not None and np.all(noisy >= 0), "noisy y negative")


@case("numbers", "gaussian sigma = 1e300", "exit 0, noisy y finite, or a one-line refusal")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra="[noise]\nsigma = 1e300\n"))).refused_or_answered("noise.sigma"):
        probe.y("transient_noisy.npy")


@case("numbers", "noise seed 2^32 - 1", "exit 0 with transient_noisy.npy")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra="[noise]\nseed = 4294967295\n"))).answered():
        probe.y("transient_noisy.npy")


@case("numbers", "pixels = 100000 (an image of 80 GB)", "exit 2, one line naming memory")
def _(probe):
    forward(probe, probe.scene(dataclasses.replace(GOOD, pixels=100000))).refused("memory")


@case("numbers", "tolerance 1e-10 (the finest)", "exit 0; y equal to the reference")
def _(probe):
    if forward(probe, probe.scene(GOOD.toml(extra="tolerance = 1e-10\n"))).answered():
        probe.matches_reference(GOOD)


# ======================================================================== images

def image_case(name: str, samples, bitdepth: int, colour_type: int, values, slow: bool = False, **png):
    """A legal PNG: y must equal the reference of the image ``values`` (exact fractions of the levels)."""
    @case("images", name, "exit 0; y equal to the reference of value/(2^d - 1)", slow=slow)
    def _(probe):
        probe.file("image.png", png_bytes(samples, bitdepth, colour_type, **png))
        geometry = dataclasses.replace(GOOD, reflectance=values)
        if forward(probe, probe.scene(geometry.toml(image="image.png"))).answered():
            probe.matches_reference(geometry)


def image_refusal(name: str, data: bytes, *words: str, file: str = "image.png", pixels: int = 8):
    @case("images", name, f"exit 2, one line naming {', '.join(words)}, no --out")
    def _(probe):
        probe.file(file, data)
        geometry = dataclasses.replace(GOOD, pixels=pixels)
        forward(probe, probe.scene(geometry.toml(image=file))).refused(*words)


# 2 and 4 bits are slow: 1 bit keeps sub-byte unpacking, 8 and 16 bits whole bytes, in the default suite
for _depth in (1, 2, 4, 8, 16):
    _levels = pattern(8, 2**_depth, seed=_depth)
    image_case(f"grey PNG, {_depth}-bit", _levels[..., None], _depth, 0, _levels / (2**_depth - 1),
               slow=_depth in (2, 4))
for _depth in (1, 2, 4, 8):
    _indices = pattern(8, 2**_depth, seed=10 + _depth)
    _greys = np.random.default_rng(_depth).integers(0, 256, 2**_depth)
    _palette = np.stack([_greys] * 3, axis=1)
    image_case(f"grey palette PNG, {_depth}-bit", _indices[..., None], _depth, 3, _greys[_indices] / 255.0,
               palette=_palette, slow=_depth in (2, 4))
_indices = pattern(8, 4, seed=3)
image_case("palette PNG with an unused colour entry", _indices[..., None], 8, 3, (_indices * 60) / 255.0,
           palette=np.array([[0, 0, 0], [60, 60, 60], [120, 120, 120], [180, 180, 180], [255, 0, 0]]))
_levels = pattern(8, 256, seed=4)
image_case("grey + alpha PNG, 8-bit, opaque", np.stack([_levels, np.full_like(_levels, 255)], -1), 8, 4,
           _levels / 255.0)
_levels16 = pattern(8, 65536, seed=5)
_levels16.flat[3] = 200
image_case("RGB PNG, 16-bit, equal channels (holds 200/65535)", np.stack([_levels16] * 3, -1), 16, 2,
           _levels16 / 65535.0)
image_case("RGBA PNG, 16-bit, opaque", np.stack([_levels16] * 3 + [np.full_like(_levels16, 65535)], -1), 16, 6,
           _levels16 / 65535.0)
image_case("grey PNG with a tRNS value no pixel has", np.minimum(_levels, 254)[..., None], 8, 0,
           np.minimum(_levels, 254) / 255.0, trns=struct.pack(">H", 255))
image_case("grey PNG with gAMA, cHRM, sRGB, sBIT chunks (applied to nothing)", _levels[..., None], 8, 0,
           _levels / 255.0, chunks=[(b"gAMA", struct.pack(">I", 45455)), (b"sRGB", b"\0"),
                                    (b"cHRM", struct.pack(">8I", 31270, 32900, 64000, 33000, 30000, 60000,
                                                          15000, 6000)), (b"sBIT", b"\x05")])


@case("images", "interlaced (Adam7) grey PNG, 16-bit", "exit 0; y equal to the reference of value/65535")
def _(probe):
    import png

    with open(probe.tmp / "image.png", "wb") as stream:
        png.Writer(8, 8, greyscale=True, bitdepth=16, interlace=True).write(stream, _levels16.tolist())
    geometry = dataclasses.replace(GOOD, reflectance=_levels16 / 65535.0)
    if forward(probe, probe.scene(geometry.toml(image="image.png"))).answered():
        probe.matches_reference(geometry)


@case("images", "image named .PNG (capitals), absolute path", "exit 0; y equal to the reference")
def _(probe):
    path = probe.file("pictures/Image.PNG", png_bytes(_levels[..., None], 8, 0))
    geometry = dataclasses.replace(GOOD, reflectance=_levels / 255.0)
    if forward(probe, probe.scene(geometry.toml(image=str(path)))).answered():
        probe.matches_reference(geometry)


@case("images", "image path through '..' above the scene's folder", "exit 0; y equal to the reference")
def _(probe):
    probe.file("image.png", png_bytes(_levels[..., None], 8, 0))
    geometry = dataclasses.replace(GOOD, reflectance=_levels / 255.0)
    if forward(probe, probe.scene(geometry.toml(image="../image.png"), name="scenes/scene.toml")).answered():
        probe.matches_reference(geometry)


_palette_colour = np.array([[0, 0, 0], [10, 20, 30]])
image_refusal("palette PNG using a colour entry", png_bytes(pattern(8, 2)[..., None], 1, 3, palette=_palette_colour),
              "palette", "grey")
image_refusal("grey + alpha PNG, 16-bit, one pixel at 65534",
              png_bytes(np.stack([_levels16, np.where(np.arange(64).reshape(8, 8) == 9, 65534, 65535)], -1), 16, 4),
              "alpha", "1 pixel")
image_refusal("RGB PNG, 16-bit, G one level off in one pixel",
              png_bytes(np.stack([_levels16, _levels16 + (np.arange(64).reshape(8, 8) == 5), _levels16], -1)
                        .clip(0, 65535), 16, 2), "differ")
image_refusal("grey PNG whose tRNS value a pixel has", png_bytes(_levels[..., None], 8, 0, trns=struct.pack(">H", 255)),
              "tRNS")
_broken = bytearray(png_bytes(_levels[..., None], 8, 0))
_broken[29] ^= 0xFF                        # the IHDR checksum
image_refusal("PNG with a wrong IHDR checksum", bytes(_broken), "image.png")
_whole = png_bytes(_levels[..., None], 8, 0)
image_refusal("PNG cut inside its IDAT", _whole[:_whole.index(b"IDAT") + 20], "image.png")
image_refusal("PNG header of 2^31 - 1 x 2^31 - 1 pixels", png_bytes(_levels[..., None], 8, 0,
                                                                    declared=(2**31 - 1, 2**31 - 1)), "pixels")
image_refusal("PNG of 8 x 9 pixels for M = 8", png_bytes(pattern(9, 256)[:, :8, None], 8, 0), "8 x 9")
image_refusal("a PNG named .exr", _whole, "EXR", file="image.exr")
image_refusal("16-bit grey PNG for M = 4 (size first)", png_bytes(_levels16[..., None], 16, 0), "plane.pixels",
              pixels=4)


@case("images", "image path /dev/zero", "exit 2, one line naming the device")
def _(probe):
    forward(probe, probe.scene(GOOD.toml(image="/dev/zero"))).refused("/dev/zero")


@case("images", "an EXR named .png", "exit 2, one line naming the file")
def _(probe):
    write_exr(probe.tmp / "real.exr", {"Y": np.full((8, 8), 0.5, np.float32)})
    (probe.tmp / "image.png").write_bytes((probe.tmp / "real.exr").read_bytes())
    forward(probe, probe.scene(GOOD.toml(image="image.png"))).refused("image.png")


def exr_case(name: str, channels_of, values, compression="ZIP", tiled=False):
    @case("images", name, "exit 0; y equal to the reference of the stored values")
    def _(probe):
        write_exr(probe.tmp / "image.exr", channels_of(), compression, tiled)
        geometry = dataclasses.replace(GOOD, reflectance=values)
        if forward(probe, probe.scene(geometry.toml(image="image.exr"))).answered():
            probe.matches_reference(geometry)


def exr_refusal(name: str, channels_of, *words):
    @case("images", name, f"exit 2, one line naming {', '.join(words)}")
    def _(probe):
        write_exr(probe.tmp / "image.exr", channels_of())
        forward(probe, probe.scene(GOOD.toml(image="image.exr"))).refused(*words)


_values = np.random.default_rng(11).uniform(0, 1, (8, 8))
_half = _values.astype(np.float16)
_single = _values.astype(np.float32)
exr_case("EXR Y HALF", lambda: {"Y": _half}, _half.astype(np.float64))
exr_case("EXR Y FLOAT, PIZ", lambda: {"Y": _single}, _single.astype(np.float64), "PIZ")
exr_case("EXR Y FLOAT, tiled 4 x 4", lambda: {"Y": _single}, _single.astype(np.float64), tiled=True)
exr_case("EXR R, G, B HALF equal, NO_COMPRESSION", lambda: {"R": _half, "G": _half, "B": _half},
         _half.astype(np.float64), "NO")
exr_case("EXR R, G, B, A FLOAT with A = 1", lambda: {c: _single for c in "RGB"} | {"A": np.ones((8, 8), np.float32)},
         _single.astype(np.float64))
_tiny = np.full((8, 8), np.float16(2.0**-24))
exr_case("EXR Y of the smallest half subnormal (2^-24)", lambda: {"Y": _tiny}, np.full((8, 8), 2.0**-24))
exr_case("EXR Y of -0.0", lambda: {"Y": np.full((8, 8), -0.0, np.float32)}, np.zeros((8, 8)))
exr_refusal("EXR Y UINT", lambda: {"Y": np.ones((8, 8), np.uint32)}, "UINT")
exr_refusal("EXR R, G, B FLOAT unequal", lambda: {"R": _single, "G": _single, "B": _single * 0.5}, "differ")
exr_refusal("EXR A = 0.5 in one pixel", lambda: {"Y": _single, "A": np.where(np.arange(64).reshape(8, 8) == 0,
                                                                              np.float32(0.5), np.float32(1))},
            "alpha")
exr_refusal("EXR Y = 1.0000001 (float32 above 1)", lambda: {"Y": np.full((8, 8), np.nextafter(np.float32(1),
                                                                                            np.float32(2)))}, "[0, 1]")
exr_refusal("EXR Y with a NaN", lambda: {"Y": np.where(np.arange(64).reshape(8, 8) == 3, np.float32(np.nan), _single)},
            "NaN")
exr_refusal("EXR lowercase channel y", lambda: {"y": _single}, "y")
exr_refusal("EXR layer diffuse.Y", lambda: {"diffuse.Y": _single}, "diffuse.Y")
exr_refusal("EXR of 4 x 4 for M = 8", lambda: {"Y": _single[:4, :4]}, "4 x 4")


@case("images", "EXR cut to half its bytes", "exit 2, one line naming the file")
def _(probe):
    data = write_exr(probe.tmp / "full.exr", {"Y": np.random.default_rng(1).uniform(0, 1, (8, 8)).astype(np.float32)},
                     "NO").read_bytes()
    probe.file("image.exr", data[: len(data) // 2])
    forward(probe, probe.scene(GOOD.toml(image="image.exr"))).refused("image.exr")


# ======================================================================== names, paths, the --out folder

@case("paths", "--out with spaces, accents and an emoji", "exit 0; files there")
def _(probe):
    probe.out = probe.tmp / "out put é 🙂"
    if forward(probe, probe.scene()).answered():
        probe.matches_reference(GOOD)


@case("paths", "--out=DIR (one argument)", "exit 0; files there")
def _(probe):
    probe.cli("forward", probe.scene(), f"--out={probe.out}", "--quiet")
    if probe.answered():
        probe.matches_reference(GOOD)


@case("paths", "--out a link to a folder", "exit 0; files in the link's target")
def _(probe):
    target = probe.tmp / "target"
    target.mkdir()
    os.symlink(target, probe.tmp / "link")
    probe.out = probe.tmp / "link"
    if forward(probe, probe.scene(), outside_changes=True).answered():
        probe.check((target / "transient.npy").is_file(), "nothing in the link's target")


@case("paths", "--out/transient.npy a link to a user's file outside",
      "exit 0; the link replaced by the file, the user's file untouched")
def _(probe):
    user = probe.file("thesis/data.npy", b"the user's own bytes")
    probe.out.mkdir()
    os.symlink(user, probe.out / "transient.npy")
    if forward(probe, probe.scene()).answered():
        probe.check(user.read_bytes() == b"the user's own bytes", "the user's file was written through the link")
        probe.check(not (probe.out / "transient.npy").is_symlink(), "transient.npy is still a link")
        probe.matches_reference(GOOD)


@case("paths", "--out/transient.npy is a folder", "exit 2, one line naming transient.npy; --out as it was")
def _(probe):
    (probe.out / "transient.npy").mkdir(parents=True)
    forward(probe, probe.scene()).refused("transient.npy")


@case("paths", "--out/meta.json is a folder holding a file", "exit 2, one line naming meta.json; --out as it was")
def _(probe):
    (probe.out / "meta.json").mkdir(parents=True)
    (probe.out / "meta.json" / "keep.txt").write_text("mine")
    forward(probe, probe.scene()).refused("meta.json")


@case("paths", "--out holds a user's look-alike temporaries and notes",
      "exit 0; .x.tmp-1, .diffuse-imaging-tmp-notmine and notes.txt untouched")
def _(probe):
    probe.out.mkdir()
    mine = {".x.tmp-1": "a", f"{TEMPORARY_PREFIX}notmine": "b", "notes.txt": "c",
            f"{TEMPORARY_PREFIX}zzzzzzzz-1-transient.npy": "d"}
    for name, text in mine.items():
        (probe.out / name).write_text(text)
    if forward(probe, probe.scene()).answered():
        for name, text in mine.items():
            probe.check((probe.out / name).is_file() and (probe.out / name).read_text() == text, f"{name} touched")


@case("paths", "--out holds a stale lock file (a dead process's id)", "exit 0; no lock file left")
def _(probe):
    probe.out.mkdir()
    (probe.out / LOCK_FILE).write_text("999999999")
    if forward(probe, probe.scene()).answered():
        probe.check(not (probe.out / LOCK_FILE).exists(), "the lock file is left")
        probe.matches_reference(GOOD)


@case("paths", "--out below a file (scene.toml/out)", "exit 2, one line")
def _(probe):
    scene = probe.scene()
    probe.out = scene / "out"
    forward(probe, scene).refused("out")


@case("paths", "--out is the scene file", "exit 2, one line naming the file; the scene untouched")
def _(probe):
    scene = probe.scene()
    probe.out = scene
    forward(probe, scene).refused("scene.toml")


@case("paths", "--out is a FIFO", "exit 2, one line naming the FIFO")
def _(probe):
    os.mkfifo(probe.out)
    forward(probe, probe.scene()).refused("FIFO")


@case("paths", "--out 60 folders deep", "exit 0; files at the bottom")
def _(probe):
    probe.out = probe.tmp.joinpath(*["d"] * 60)
    if forward(probe, probe.scene(), outside_changes=True).answered():
        probe.matches_reference(GOOD)


@case("paths", "--out of 5000 bytes in names of 200", "exit 2, one line (path too long)")
def _(probe):
    probe.out = probe.tmp.joinpath(*["n" * 200] * 25)
    forward(probe, probe.scene()).refused()
    probe.check(not (probe.tmp / ("n" * 200)).exists(), "folders were left")


@case("paths", "--out the scene's own folder (user files beside)", "exit 0; the scene and the image untouched")
def _(probe):
    probe.out = probe.tmp
    probe.file("image.png", png_bytes(_levels[..., None], 8, 0))
    scene = probe.scene(dataclasses.replace(GOOD, reflectance=_levels / 255.0).toml(image="image.png"))
    before = (scene.read_bytes(), (probe.tmp / "image.png").read_bytes())
    if forward(probe, scene).answered():
        probe.check((scene.read_bytes(), (probe.tmp / "image.png").read_bytes()) == before, "user files changed")


@case("paths", "--out on a read-only file system (/proc/...)", "exit 2, one line")
def _(probe):
    probe.out = Path("/proc/diffuse-imaging-probe")
    forward(probe, probe.scene()).refused("/proc/diffuse-imaging-probe")


@case("paths", "export of a scene named 'a/../../b' (file name)", "exit 0; every file inside --out")
def _(probe):
    scene = probe.scene(GOOD.toml().replace("[plane]", 'name = "a/../../b"\n[plane]'))
    probe.cli("export", scene, "--format", "mitsuba", "--out", probe.out, "--quiet")
    if probe.answered():
        probe.check((probe.out / "scene.xml").is_file(), "no scene.xml")


@case("paths", "export --format mitransient of a paper-attenuation scene", "exit 2, one line; no --out")
def _(probe):
    scene = probe.scene(dataclasses.replace(GOOD, attenuation="paper"))
    probe.cli("export", scene, "--format", "mitransient", "--out", probe.out, "--quiet").refused("paper")


@case("paths", "validate of scenes named '', '.', '..' and 300 x 'a'",
      "exit 0; every folder inside --out, none outside")
def _(probe):
    scenes = []
    for index, name in enumerate(["", ".", "..", "a" * 300]):
        scenes.append(probe.scene(GOOD.toml().replace("[plane]", f'name = "{name}"\n[plane]'), f"s{index}.toml"))
    probe.cli("validate", *scenes, "--spp", "4096", "--fast", "--out", probe.out, "--quiet")
    if probe.refused_or_answered("name"):
        probe.check((probe.out / "report.md").is_file(), "no report.md")


# ======================================================================== data files: check and reconstruct

def _data(geometry: Geometry = GOOD, scale: float = 1.0, shift: float = 0.0, relative_error: float = 0.02,
          seed: int = 0):
    """(data, stderr): the reference times ``scale`` on a window read ``shift`` metres short, plus noise."""
    truth, _ = reference(dataclasses.replace(geometry, start=geometry.start + shift))
    stderr = np.full(truth.shape, relative_error * np.abs(truth).max())
    return scale * truth + np.random.default_rng(seed).normal(0, 1, truth.shape) * stderr, stderr


def check_command(probe: Probe, data, stderr=None, *more, scene=None):
    argv = ["check", scene or probe.scene(), "--data", *([data] if not isinstance(data, list) else data)]
    if stderr is not None:
        argv += ["--stderr", stderr]
    return probe.cli(*argv, *more, "--out", probe.out, "--quiet")


def _fit_near(probe: Probe, scale: float, offset: float):
    fit = probe.metrics().get("fit") or {}
    for key, value in (("scale", scale), ("offset_opl", offset)):
        error = fit.get(f"{key.split('_')[0]}_stderr")
        if probe.check(key in fit and error is not None, f"no fit {key}: {fit}"):
            probe.check(abs(fit[key] - value) <= 4 * error + 1e-12,
                        f"fit {key} {fit[key]} ± {error}, expected {value}")


@case("data", "check: reference + noise with its stderr", "exit 0 (agrees); scale 1 and offset 0 within 4 se")
def _(probe):
    data, stderr = _data()
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.answered():
        _fit_near(probe, 1.0, 0.0)


@case("data", "check: twice the reference", "exit 1 (disagrees as given); scale 2 within 4 se")
def _(probe):
    data, stderr = _data(scale=2.0)
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.answered(status=1):
        _fit_near(probe, 2.0, 0.0)


@case("data", "check: a window read 0.02 m short", "exit 1; offset +0.02 m within 4 se, scale 1")
def _(probe):
    data, stderr = _data(shift=0.02, relative_error=0.002)
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.answered(status=1):
        _fit_near(probe, 1.0, 0.02)


for _label, _convert in (("float32", lambda a: a.astype(np.float32)), ("big-endian >f8", lambda a: a.astype(">f8")),
                         ("Fortran order", np.asfortranarray), ("float16", lambda a: a.astype(np.float16))):
    @case("data", f"check: data as {_label}", "exit 0 (agrees); scale 1 within 4 se")
    def _(probe, convert=_convert):
        data, stderr = _data()
        check_command(probe, probe.npy("y.npy", convert(data)), probe.npy("se.npy", convert(stderr)))
        if probe.answered():
            _fit_near(probe, 1.0, 0.0)


@case("data", "check: three replicas", "exit 0 (agrees, t with 2 dof); scale 1 within 4 se")
def _(probe):
    files = [probe.npy(f"r{seed}.npy", _data(relative_error=0.02, seed=seed)[0]) for seed in range(3)]
    check_command(probe, files)
    if probe.answered(warnings=True):       # a one-line warning: few replicas
        _fit_near(probe, 1.0, 0.0)


@case("data", "check: mitransient films (K, 1, 1, N, 3) x 1/4, --expect-scale 0.25",
      "exit 0 (agrees as stated); scale 0.25 within 4 se")
def _(probe):
    files = []
    for seed in range(4):
        film = 0.25 * _data(seed=seed)[0]
        files.append(probe.npy(f"film{seed}.npy", np.repeat(film[:, None, None, :, None], 3, axis=-1)))
    check_command(probe, files, None, "--expect-scale", "0.25")
    if probe.answered(warnings=True):
        _fit_near(probe, 0.25, 0.0)


@case("data", "check: stderr 0 in the bins without light", "exit 0 with finite metrics, or a one-line refusal")
def _(probe):
    data, stderr = _data()
    truth, _ = reference(GOOD)
    dark = truth == 0
    data[dark], stderr[dark] = 0.0, 0.0
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.refused_or_answered("stderr"):
        text = (probe.out / "metrics.json").read_text()
        probe.check("NaN" not in text and "Infinity" not in text, "metrics.json not finite")


@case("data", "check: the negated reference", "exit 1 with finite metrics, or a one-line refusal")
def _(probe):
    data, stderr = _data(scale=-1.0)
    check_command(probe, probe.npy("y.npy", data), probe.npy("se.npy", stderr))
    if probe.status != 2:
        probe.answered(status=1)


def data_refusal(name: str, make, *words: str, command: str = "check"):
    @case("data", f"{command}: {name}", f"exit 2, one line naming {', '.join(words)}, no --out")
    def _(probe):
        files = make(probe)
        data, stderr = (files, None) if not isinstance(files, tuple) else files
        if command == "check":
            check_command(probe, data, stderr)
        else:
            probe.cli("reconstruct", probe.scene(), "--data", data, "--out", probe.out, "--quiet")
        probe.refused(*words)


class _Planted:
    """Unpickling this object creates a marker folder: a .npy loader must never unpickle."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def _se(probe: Probe) -> Path:
    """The standard error file that goes with :func:`_data`."""
    return probe.npy("se.npy", _data()[1])


def _npz(probe: Probe) -> Path:
    np.savez(probe.tmp / "y.npz", y=_data()[0])
    return probe.tmp / "y.npz"

data_refusal("bool data", lambda p: (p.npy("y.npy", _data()[0] > 0), _se(p)), "y.npy", "bool")
data_refusal("a pickled object array (never unpickled)",
             lambda p: (p.npy("y.npy", np.array([_Planted(str(p.tmp / "PWNED"))], dtype=object), allow_pickle=True),
                        _se(p)), "y.npy")
data_refusal("a structured dtype",
             lambda p: (p.npy("y.npy", np.zeros((1, 12), dtype=[("a", "f8"), ("b", "f8")])), _se(p)), "y.npy")
data_refusal("shape (1, 13)", lambda p: (p.npy("y.npy", np.ones((1, 13))), _se(p)), "(1, 13)")
data_refusal("transposed (12, 1)", lambda p: (p.npy("y.npy", _data()[0].T), _se(p)), "transposed")
data_refusal("a 0-byte .npy", lambda p: (p.file("y.npy", b""), _se(p)), "y.npy")
data_refusal("a .npy cut short", lambda p: (p.file("y.npy", p.npy("whole.npy", _data()[0]).read_bytes()[:-40]),
                                            _se(p)), "y.npy")
data_refusal("an .npz", lambda p: (_npz(p), _se(p)), "y.npz")
data_refusal("a .csv", lambda p: (p.file("y.csv", ",".join(map(str, _data()[0][0])) + "\n"), _se(p)), "y.csv")
data_refusal("stderr with a negative bin",
             lambda p: (p.npy("y.npy", _data()[0]), p.npy("se.npy", _data()[1] * np.where(np.arange(12) == 4, -1, 1))),
             "negative")
data_refusal("stderr with a NaN",
             lambda p: (p.npy("y.npy", _data()[0]), p.npy("se.npy", np.where(np.arange(12) == 4, np.nan, _data()[1]))),
             "se.npy")
data_refusal("stderr of shape (1, 11)", lambda p: (p.npy("y.npy", _data()[0]), p.npy("se.npy", np.ones((1, 11)))),
             "(1, 11)")
data_refusal("replicas of two shapes", lambda p: [p.npy("a.npy", _data()[0]), p.npy("b.npy", _data()[0]),
                                                  p.npy("c.npy", np.ones((1, 13)))], "(1, 13)")
data_refusal("one file given three times", lambda p: [p.npy("a.npy", _data()[0])] * 3, "zero spread")
data_refusal("film of 2 x 2 pixels", lambda p: [p.npy(f"f{i}.npy", np.ones((1, 2, 2, 12, 1))) for i in range(3)],
             "2 x 2")
data_refusal("film with unequal R, G, B", lambda p: [p.npy(f"f{i}.npy", np.stack(
    [_data(seed=i)[0], _data(seed=i)[0], 2 * _data(seed=i)[0]], -1)[:, None, None]) for i in range(3)], "channels")
data_refusal("an HDF5 file that is text", lambda p: (p.file("y.h5", "not hdf5\n"), None), "y.h5")
data_refusal("data two sensors for a one-sensor scene", lambda p: p.npy("y.npy", np.ones((2, 12))), "(2, 12)",
             command="reconstruct")
data_refusal("data /dev/zero", lambda p: "/dev/zero", "/dev/zero", command="reconstruct")


@case("data", "check: a pickled object array never runs its payload", "the payload's folder does not appear")
def _(probe):
    marker = probe.tmp / "PWNED"
    data = probe.npy("y.npy", np.array([_Planted(str(marker))], dtype=object), allow_pickle=True)
    check_command(probe, data, probe.npy("se.npy", _data()[1]))
    probe.check(not marker.exists(), "the pickle ran")


@case("data", "check: our own forward folder's h5 (tal layout), --shape-only", "exit 0; agrees by shape")
def _(probe):
    scene = probe.scene()
    forward(probe, scene)
    model = probe.tmp / "model"
    probe.out.rename(model)
    check_command(probe, model / "transient.h5", None, "--shape-only", scene=scene)
    probe.answered()


def _capture_case(name: str, change, *words: str):
    """Our forward's transient.h5 (tal's layout), changed by ``change(h5 file)``, given to check."""
    @case("data", f"check: tal capture with {name}", f"exit 2, one line naming {', '.join(words)}, no --out")
    def _(probe):
        import h5py

        scene = probe.scene()
        forward(probe, scene)
        capture = probe.tmp / "capture.h5"
        (probe.out / "transient.h5").rename(capture)
        import shutil

        shutil.rmtree(probe.out)
        with h5py.File(capture, "r+") as handle:
            change(handle)
        check_command(probe, capture, None, "--shape-only", scene=scene).refused(*words)


def _replace(name, value):
    def change(handle):
        del handle[name]
        handle[name] = value
    return change


_capture_case("no H", lambda handle: handle.__delitem__("H"), "H")
_capture_case("delta_t = -0.1", _replace("delta_t", -0.1), "capture.h5")
_capture_case("a NaN in H", _replace("H", np.where(np.arange(12)[:, None] == 3, np.nan, 0.01)), "NaN")
_capture_case("the sensor moved 1 cm", _replace("sensor_grid_xyz", np.array([[0.21, 0.7, 1.0]])), "sensor")
_capture_case("H as text", _replace("H", np.array([b"not numbers"])), "H")
data_refusal("data with a NaN", lambda p: (p.npy("y.npy", np.where(np.arange(12) == 2, np.nan, _data()[0])), _se(p)),
             "NaN")
data_refusal("a 0-byte .npy", lambda p: p.file("y.npy", b""), "y.npy", command="reconstruct")
data_refusal("data with an infinity", lambda p: p.npy("y.npy", np.where(np.arange(12) == 2, np.inf, _data()[0])),
             "inf", command="reconstruct")


@case("data", "reconstruct: the reference with --lambda 1e-300", "exit 0 with a finite image, or a one-line refusal")
def _(probe):
    data = probe.npy("y.npy", reference(GOOD)[0])
    probe.cli("reconstruct", probe.scene(), "--data", data, "--lambda", "1e-300", "--out", probe.out, "--quiet")
    if probe.refused_or_answered("--lambda", warnings=True):
        probe.y("reconstruction.npy")


@case("data", "reconstruct: all-zero data", "exit 0 with a finite image, or a one-line refusal")
def _(probe):
    data = probe.npy("y.npy", np.zeros((1, 12)))
    probe.cli("reconstruct", probe.scene(), "--data", data, "--out", probe.out, "--quiet")
    if probe.refused_or_answered("0", warnings=True):
        probe.y("reconstruction.npy")


@case("data", "reconstruct: --lambda-range 1e-300 1e300 --lambda-count 3", "exit 0 finite, or a one-line refusal")
def _(probe):
    data = probe.npy("y.npy", _data()[0])
    probe.cli("reconstruct", probe.scene(), "--data", data, "--lambda", "gcv", "--lambda-range", "1e-300", "1e300",
              "--lambda-count", "3", "--out", probe.out, "--quiet")
    if probe.refused_or_answered("--lambda", warnings=True):
        probe.y("reconstruction.npy")


@case("data", "reconstruct: our forward's EXR at I = 1e30", "exit 0; a finite image and finite metrics")
def _(probe):
    scene = probe.scene(dataclasses.replace(GOOD, intensity=1e30, reflectance=_levels / 255.0).toml(image="i.png"))
    probe.file("i.png", png_bytes(_levels[..., None], 8, 0))
    forward(probe, scene)
    (probe.tmp / "model").mkdir()
    for name in ("transient.exr", "meta.json"):
        (probe.out / name).rename(probe.tmp / "model" / name)
    import shutil

    shutil.rmtree(probe.out)
    probe.cli("reconstruct", scene, "--data", probe.tmp / "model" / "transient.exr", "--out", probe.out, "--quiet")
    if probe.answered(warnings=True):              # one sensor cannot fix 64 pixels: A's rank, in one line
        probe.y("reconstruction.npy")
        text = (probe.out / "metrics.json").read_text()
        probe.check("NaN" not in text and "Infinity" not in text, "metrics.json not finite")


# ======================================================================== command-line values

@case("flags", "render --spp 0x1000", "exit 0; 4096 samples")
def _(probe):
    if probe.cli("render", probe.scene(), "--spp", "0x1000", "--out", probe.out, "--quiet").answered():
        probe.check(probe.meta().get("samples") == 4096, f"samples {probe.meta().get('samples')}")


@case("flags", "render --spp 1e3", "exit 0; 1024 samples (1000 rounded up to 32 replicas)")
def _(probe):
    if probe.cli("render", probe.scene(), "--spp", "1e3", "--out", probe.out, "--quiet").answered():
        probe.check(probe.meta().get("samples") == 1024, f"samples {probe.meta().get('samples')}")


@case("flags", "render --spp 2^44 + 1", "exit 2, one line naming --spp")
def _(probe):
    probe.cli("render", probe.scene(), "--spp", str(2**44 + 1), "--out", probe.out).refused("--spp")


@case("flags", "render --variant cuda_ad_rgb (not offered)", "exit 2, one line naming the variant")
def _(probe):
    probe.cli("render", probe.scene(), "--spp", "64", "--variant", "cuda_ad_rgb", "--out", probe.out) \
        .refused("variant")


@case("flags", "render --resume of a folder that never rendered", "exit 2, one line naming the folder")
def _(probe):
    probe.out.mkdir()
    (probe.out / "notes.txt").write_text("mine")
    probe.cli("render", "--resume", probe.out, "--quiet").refused(str(probe.out))


@case("flags", "render --resume with a different --seed", "exit 2, one line naming --seed; the render as it was")
def _(probe):
    probe.cli("render", probe.scene(), "--spp", "4096", "--seed", "3", "--out", probe.out, "--quiet")
    if probe.answered():
        probe.cli("render", "--resume", probe.out, "--seed", "4", "--quiet").refused("--seed")


@case("flags", "render intensity law: I = 1e-300 and 1e30 against 1, same seed",
      "exit 0 each; y / I and stderr / I equal to 1e-14")
def _(probe):
    runs = {}
    for intensity in (1.0, 1e-300, 1e30):
        probe.out = probe.tmp / f"out{intensity:g}"
        scene = probe.scene(dataclasses.replace(GOOD, intensity=intensity), f"i{intensity:g}.toml")
        if probe.cli("render", scene, "--spp", "4096", "--seed", "5", "--out", probe.out, "--quiet",
                     outside_changes=True).answered(warnings=True):
            runs[intensity] = (probe.y() / intensity, probe.y("stderr.npy") / intensity)
    if 1.0 in runs:
        for intensity, (y, se) in runs.items():
            probe.close(y, runs[1.0][0], rtol=1e-14, what=f"y / I at {intensity:g}")
            probe.close(se, runs[1.0][1], rtol=1e-12, what=f"stderr / I at {intensity:g}")


@case("flags", "render paper attenuation, 2^16 samples", "exit 0; y within 5 stderr + 1e-3 of the eq. 1 reference")
def _(probe):
    geometry = dataclasses.replace(GOOD, attenuation="paper")
    if probe.cli("render", probe.scene(geometry), "--spp", "65536", "--out", probe.out, "--quiet").answered():
        y, se = probe.y(), probe.y("stderr.npy")
        expected, bound = reference(geometry)
        probe.close(y, expected, atol=5 * se + bound, what="render against eq. 1")


@case("flags", "render --resume after render_state.npz was cut to 100 bytes",
      "exit 2, one line naming render_state.npz; the folder as it was")
def _(probe):
    probe.cli("render", probe.scene(), "--spp", "4096", "--out", probe.out, "--quiet")
    state = probe.out / "render_state.npz"
    state.write_bytes(state.read_bytes()[:100])
    probe.cli("render", "--resume", probe.out, "--quiet").refused("render_state.npz")


@case("flags", "check of a render folder whose replicas.npy is empty",
      "exit 2, one line naming replicas.npy, no --out")
def _(probe):
    scene = probe.scene()
    rendered = probe.tmp / "rendered"
    probe.cli("render", scene, "--spp", "4096", "--out", rendered, "--quiet", outside_changes=True)
    (rendered / "replicas.npy").write_bytes(b"")
    check_command(probe, rendered, None, scene=scene).refused("replicas.npy")


@case("flags", "forward --tolerance 1e-300", "exit 2, one line naming --tolerance")
def _(probe):
    forward(probe, probe.scene(), "--tolerance", "1e-300").refused("tolerance")


@case("flags", "export --format MITSUBA (capitals)", "exit 2, one line naming --format")
def _(probe):
    probe.cli("export", probe.scene(), "--format", "MITSUBA", "--out", probe.out).refused("--format")


@case("flags", "export --format mitransient --spp 0", "exit 2, one line naming --spp")
def _(probe):
    probe.cli("export", probe.scene(), "--format", "mitransient", "--spp", "0", "--out", probe.out).refused("--spp")


@case("flags", "check --expect irradiancemeter --radius 5 (above the sensor)", "exit 2, one line naming --radius")
def _(probe):
    files = [probe.npy(f"r{seed}.npy", _data(seed=seed)[0]) for seed in range(3)]
    check_command(probe, files, None, "--expect", "irradiancemeter", "--radius", "5").refused("radius")


@case("flags", "reconstruct --regularizer TV (capitals)", "exit 2, one line naming --regularizer")
def _(probe):
    probe.cli("reconstruct", probe.scene(), "--data", probe.npy("y.npy", _data()[0]), "--regularizer", "TV",
              "--out", probe.out).refused("--regularizer")


@case("flags", "diffuse-imaging --version", "exit 0 with a version, or exit 2 in one line")
def _(probe):
    probe.cli("--version")
    if probe.status != 0:
        probe.refused()


@case("flags", "forward --quiet --quiet", "exit 0")
def _(probe):
    forward(probe, probe.scene(), "--quiet")
    probe.answered()


@case("flags", "run on a noisy 2 x 2-sensor scene, --spp 4096", "exit 0; the cross-check agrees; finite PSNRs")
def _(probe):
    text = dataclasses.replace(GOOD, intensity=1e4, reflectance=_levels / 255.0).toml(image="i.png") \
        .replace("positions = [[0.2, 0.7, 1.0]]", "grid = [2, 2]\ncenter = [0.5, 0.5, 1.0]") + "[noise]\nsigma = 0.1\n"
    probe.file("i.png", png_bytes(_levels[..., None], 8, 0))
    probe.cli("run", probe.scene(text), "--spp", "4096", "--out", probe.out, "--quiet")
    if probe.answered(warnings=True):
        metrics = probe.metrics()
        probe.check(metrics.get("agreement", {}).get("agrees") is True, f"agreement {metrics.get('agreement')}")
        reconstruction = metrics.get("reconstruction", {})
        for side in ("model", "render"):
            psnr = (reconstruction.get(side) or {}).get("psnr")
            probe.check(isinstance(psnr, float) and math.isfinite(psnr), f"{side} psnr {psnr}")


def sweep_refusal(name: str, text: str, *words: str):
    @case("flags", f"sweep: {name}", f"exit 2, one line naming {', '.join(words)}, before any worker starts")
    def _(probe):
        probe.scene(name="base.toml")
        head = 'scene = "base.toml"\nsamples = 4096\n'
        if "samples" in words:
            head = head.replace("4096", "0")
        if "missing.toml" in words:
            head = head.replace("base.toml", "missing.toml")
        sweep = probe.file("sweep.toml", head + text)
        probe.cli("sweep", sweep, "--out", probe.out, "--workers", "1", "--quiet").refused(*words)


sweep_refusal("a grid key with a typo", '[grid]\n"plane.sizee" = [1.0, 2.0]\n', "grid.plane.sizee")
sweep_refusal("a negative size in the grid", '[grid]\n"plane.size" = [1.0, -1.0]\n', "grid.plane.size")
sweep_refusal("an empty grid list", '[grid]\n"plane.size" = []\n', "grid.plane.size")
sweep_refusal("samples = 0", '[grid]\n"plane.size" = [1.0]\n', "samples")
sweep_refusal("its scene missing", '[grid]\n"plane.size" = [1.0]\n', "missing.toml")


# ======================================================================== environment (child processes)

@case("environment", "HOME unset: forward and render", "exit 0 each, stderr empty", slow=True)
def _(probe):
    scene = probe.scene()
    probe.sub("forward", scene, "--out", probe.tmp / "f", "--quiet", unset=("HOME",), outside_changes=True).answered()
    probe.sub("render", scene, "--spp", "4096", "--out", probe.tmp / "r", "--quiet", unset=("HOME",),
              outside_changes=True).answered()


@case("environment", "HOME a file (no ~/.config possible)", "exit 0, stderr empty (no library notice)")
def _(probe):
    probe.sub("forward", probe.scene(), "--out", probe.out, "--quiet", env={"HOME": str(probe.file("home", ""))})
    probe.answered()


@case("environment", "LC_ALL=C, a scene named 'scène ✓'", "exit 0, stderr empty, the summary escaped", slow=True)
def _(probe):
    scene = probe.scene(GOOD.toml().replace("[plane]", 'name = "scène ✓"\n[plane]'))
    probe.sub("forward", scene, "--out", probe.out, env={"LC_ALL": "C", "LANG": "C"})
    probe.answered()


@case("environment", "PYTHONIOENCODING=ascii, --out with accents", "exit 0, stderr empty", slow=True)
def _(probe):
    probe.out = probe.tmp / "sortie é"
    probe.sub("forward", probe.scene(), "--out", probe.out, env={"PYTHONIOENCODING": "ascii"}).answered()


@case("environment", "TMPDIR a missing folder, an EXR image", "exit 0, stderr empty, y equal to the reference")
def _(probe):
    write_exr(probe.tmp / "image.exr", {"Y": _single})
    geometry = dataclasses.replace(GOOD, reflectance=_single.astype(np.float64))
    probe.sub("forward", probe.scene(geometry.toml(image="image.exr")), "--out", probe.out, "--quiet",
              env={"TMPDIR": str(probe.tmp / "missing")})
    if probe.answered():
        probe.matches_reference(geometry)


@case("environment", "MPLCONFIGDIR unwritable (under /proc)", "exit 0, stderr empty (no matplotlib notice)")
def _(probe):
    probe.sub("forward", probe.scene(), "--out", probe.out, "--quiet",
              env={"MPLCONFIGDIR": "/proc/diffuse-imaging-mpl"}).answered()


@case("environment", "the working folder deleted, absolute paths", "exit 0", slow=True)
def _(probe):
    gone = probe.tmp / "gone"
    gone.mkdir()
    scene = probe.scene()
    probe.sub("forward", scene, "--out", probe.out, "--quiet", cwd=gone,
              prefix=["sh", "-c", 'rmdir "$0" && exec "$@"', str(gone)], outside_changes=True)
    probe.answered()


@case("environment", "the working folder deleted, a relative --out", "exit 2, one line")
def _(probe):
    gone = probe.tmp / "gone"
    gone.mkdir()
    scene = probe.scene()
    probe.out = gone / "out"
    probe.sub("forward", scene, "--out", "out", "--quiet", cwd=gone,
              prefix=["sh", "-c", 'rmdir "$0" && exec "$@"', str(gone)], outside_changes=True)
    probe.refused()


@case("environment", "stdout closed (>&-)", "exit 0 and the files, or exit 2 in one line")
def _(probe):
    probe.sub("forward", probe.scene(), "--out", probe.out, prefix=["sh", "-c", 'exec "$@" >&-', "sh"])
    if probe.status == 0:
        probe.answered()
        probe.matches_reference(GOOD)
    else:
        probe.check(probe.status == 2 and len(probe.lines) == 1, f"exit {probe.status}, {probe.lines}")


# slow: tests/cli/test_console.py's test_a_full_stdout_ends_with_one_line_and_status_2 keeps the property
@case("environment", "check with stdout on /dev/full", "exit 2, one line; its files written", slow=True)
def _(probe):
    data, stderr = _data()
    with open("/dev/full", "wb") as full:
        probe.sub("check", probe.scene(), "--data", probe.npy("y.npy", data), "--stderr", probe.npy("se.npy", stderr),
                  "--out", probe.out, stdout=full)
    probe.check(probe.status == 2 and len(probe.lines) == 1 and probe.lines[0].startswith(ERROR),
                f"exit {probe.status}, {probe.lines}")
    probe.check((probe.out / "metrics.json").is_file(), "no metrics.json")


@case("environment", "a refusal with stderr closed", "exit 2, no hang")
def _(probe):
    probe.sub("forward", probe.file("scene.toml", "[plane]\nsize = -1\n"), "--out", probe.out,
              prefix=["sh", "-c", 'exec "$@" 2>&-', "sh"])
    probe.check(probe.status == 2, f"exit {probe.status}")
    probe.check(not probe.out.exists(), "--out created")


@case("environment", "a full disk (a 64 kB tmpfs)", "exit 2, one line naming the disk; --out as it was")
def _(probe):
    mount = probe.tmp / "small"
    mount.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        (mount / "filler").write_bytes(b"\0" * 40_000)
        probe.out = mount / "out"
        probe.sub("forward", probe.scene(), "--out", probe.out, "--quiet", outside_changes=True)
        probe.refused("space")
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


@case("environment", "a read-only mount as --out, and as the working folder",
      "exit 2, one line naming read-only; nothing written; an absolute --out elsewhere works", slow=True)
def _(probe):
    mount = probe.tmp / "ro"
    mount.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,ro", "tmpfs", str(mount)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        probe.out = mount / "out"
        scene = probe.scene()
        probe.sub("forward", scene, "--out", probe.out, "--quiet").refused("read-only")
        # the same folder as the working folder: a relative --out is refused, an absolute one works
        probe.sub("forward", scene, "--out", "out", "--quiet", cwd=mount).refused("read-only")
        probe.out = probe.tmp / "elsewhere"
        probe.sub("forward", scene, "--out", probe.out, "--quiet", cwd=mount)
        if probe.answered():
            probe.matches_reference(GOOD)
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


@case("environment", "NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1", "exit 0; y equal to the reference", slow=True)
def _(probe):
    probe.sub("forward", probe.scene(), "--out", probe.out, "--quiet",
              env={"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
    if probe.answered():
        probe.matches_reference(GOOD)


# ======================================================================== signals and concurrency

def _spawn(probe: Probe, *argv, env=None):
    argv = [str(a) for a in argv]
    probe.commands.append("diffuse-imaging " + " ".join(shlex.quote(a) for a in argv) + " &")
    return subprocess.Popen([*PROGRAM, *argv], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            cwd=probe.tmp, env={**os.environ, **(env or {})})


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(TEMPORARY_PREFIX) or p.name == LOCK_FILE) \
        if folder.is_dir() else []


LONG_SPP = 2**29


def _signal_then_resume(probe: Probe, signum: int, seed: int, after_checkpoint: bool = False):
    """Render, deliver ``signum`` at a random time, resume; the result must be the uninterrupted render's.

    The time is drawn after the folder's lock appears (or its first checkpoint, ``after_checkpoint``).
    Before the first checkpoint nothing can be resumed: then the interrupted render says so, and
    ``--resume`` is refused in one line.
    """
    delay = np.random.default_rng(seed).uniform(0.0, 2.5)
    scene = probe.scene()
    child = _spawn(probe, "render", scene, "--spp", LONG_SPP, "--seed", "9", "--out", probe.out, "--quiet")
    _wait_for_lock(probe.out, child)
    deadline = time.monotonic() + 60
    while after_checkpoint and not (probe.out / "render_state.npz").exists() and child.poll() is None \
            and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(delay)
    child.send_signal(signum)
    try:
        _, err = child.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        child.kill()
        _, err = child.communicate()
        probe.problem(f"the render did not end within 60 s of signal {signum}")
    lines = [line for line in err.decode("utf-8", "replace").splitlines() if line.strip()]
    saved = (probe.out / "render_state.npz").exists()
    probe.observed.append(f"signal {signal.Signals(signum).name} {delay:.2f} s after the "
                          f"{'checkpoint' if after_checkpoint else 'lock'}: exit {child.returncode}, "
                          f"stderr {lines[:2]}, state saved: {saved}")
    probe.check(not any("Traceback" in line for line in lines), f"traceback: {lines[-3:]}")
    if child.returncode != 0:
        expected_status = {signal.SIGINT: 130, signal.SIGTERM: 130, signal.SIGKILL: -9}[signum]
        probe.check(child.returncode == expected_status, f"exit {child.returncode}, expected {expected_status}")
        if signum != signal.SIGKILL:
            said = "--resume" if saved else "nothing was saved"
            probe.check(len(lines) == 1 and said in lines[0], f"stderr {lines}, expected one line with {said!r}")
        probe.sub("render", "--resume", probe.out, "--quiet", timeout=120)
        if not saved:
            probe.refused("nothing to resume")
            return
        probe.answered()
    probe.check(not _leftovers(probe.out), f"left in --out: {_leftovers(probe.out)}")
    resumed = probe.y()
    straight = probe.tmp / "straight"
    probe.sub("render", scene, "--spp", LONG_SPP, "--seed", "9", "--out", straight, "--quiet", timeout=120,
              outside_changes=True)
    if probe.answered() and resumed is not None:
        # README: "continues from the last checkpoint to the same numbers": to float64 rounding (the
        # replica sums are regrouped at the checkpoint), not necessarily bit for bit
        whole = np.load(straight / "transient.npy")
        probe.observed.append(f"bit for bit: {np.array_equal(resumed, whole)}")
        probe.close(resumed, whole, rtol=1e-14, what="resumed y")
        # the standard error is a difference of nearly equal sums: compare it on the scale of y
        probe.close(np.load(probe.out / "stderr.npy"), np.load(straight / "stderr.npy"),
                    atol=1e-13 * np.abs(whole).max(), what="resumed stderr")


for _signum, _seed in ((signal.SIGINT, 1), (signal.SIGTERM, 2), (signal.SIGKILL, 3)):
    @case("signals", f"{signal.Signals(_signum).name} at a random time during render, then --resume",
          "exit 130 (SIGINT, SIGTERM; one line naming --resume) or killed; --resume gives the uninterrupted "
          "render bit for bit; no temporaries, no lock", slow=True)
    def _(probe, signum=_signum, seed=_seed):
        _signal_then_resume(probe, signum, seed, after_checkpoint=signum == signal.SIGKILL)


def _wait_for_lock(folder: Path, child, seconds: float = 60) -> bool:
    deadline = time.monotonic() + seconds
    while not (folder / LOCK_FILE).exists():
        if child.poll() is not None or time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


_BUSY = GOOD.toml().replace("positions = [[0.2, 0.7, 1.0]]", "grid = [8, 8]\ncenter = [0.5, 0.5, 1.0]") \
    .replace("pixels = 8", "pixels = 32").replace("count = 12", "count = 60").replace("period = 0.1", "period = 0.02")


@case("signals", "SIGKILL at a random time during forward, then forward again",
      "exit 0; no temporaries or lock left; y equal to an undisturbed forward", slow=True)
def _(probe):
    scene = probe.file("scene.toml", _BUSY)
    child = _spawn(probe, "forward", scene, "--out", probe.out, "--quiet")
    if _wait_for_lock(probe.out, child):
        time.sleep(np.random.default_rng(4).uniform(0.0, 1.0))
    child.kill()
    child.communicate()
    probe.observed.append(f"killed: exit {child.returncode}; left {sorted(tree(probe.out))}")
    probe.sub("forward", scene, "--out", probe.out, "--quiet", timeout=300)
    probe.answered()
    probe.check(not _leftovers(probe.out), f"left in --out: {_leftovers(probe.out)}")
    first = probe.y()
    probe.out = probe.tmp / "calm"
    probe.sub("forward", scene, "--out", probe.out, "--quiet", timeout=300)
    if probe.answered() and first is not None:
        probe.check(np.array_equal(first, probe.y()), "y differs from an undisturbed forward")


@case("signals", "SIGINT at a random time during forward", "exit 130, one line; the --out it created removed",
      slow=True)
def _(probe):
    child = _spawn(probe, "forward", probe.file("scene.toml", _BUSY), "--out", probe.out, "--quiet")
    if _wait_for_lock(probe.out, child):
        time.sleep(np.random.default_rng(5).uniform(0.0, 0.5))
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=120)
    lines = [line for line in err.decode("utf-8", "replace").splitlines() if line.strip()]
    probe.observed.append(f"exit {child.returncode}, stderr {lines[:3]}, out {sorted(tree(probe.out))}")
    if child.returncode == 0:
        probe.observed.append("finished before the signal; not judged")
        return
    probe.check(child.returncode == 130 and len(lines) == 1 and "interrupted" in lines[0],
                f"exit {child.returncode}, {lines[:3]}")
    probe.check(not os.path.lexists(probe.out), f"--out left: {sorted(tree(probe.out))}")


@case("concurrency", "two renders on one folder at once",
      "the first exit 0; the second exit 2 in one line naming the other's process id", slow=True)
def _(probe):
    scene = probe.scene()
    first = _spawn(probe, "render", scene, "--spp", LONG_SPP, "--out", probe.out, "--quiet")
    deadline = time.monotonic() + 30
    while not (probe.out / LOCK_FILE).exists() and time.monotonic() < deadline and first.poll() is None:
        time.sleep(0.02)
    time.sleep(0.2)
    probe.sub("render", scene, "--spp", "4096", "--out", probe.out, "--quiet", outside_changes=True)
    if first.poll() is None:
        probe.refused(str(first.pid), out_as_it_was=False)     # the first one is writing it
    else:
        probe.observed.append("the first render ended before the second started; not judged")
    _, err = first.communicate(timeout=120)
    probe.check(first.returncode == 0 and not err.strip(), f"the first: exit {first.returncode}, {err[-300:]}")
    probe.check(not _leftovers(probe.out), f"left in --out: {_leftovers(probe.out)}")


@case("concurrency", "check reading a folder a render is writing",
      "exit 2 in one line naming the writer, or it waits and judges the finished render", slow=True)
def _(probe):
    scene = probe.scene()
    render_out = probe.tmp / "render"
    writer = _spawn(probe, "render", scene, "--spp", LONG_SPP, "--out", render_out, "--quiet")
    deadline = time.monotonic() + 30
    while not (render_out / LOCK_FILE).exists() and time.monotonic() < deadline and writer.poll() is None:
        time.sleep(0.02)
    probe.sub("check", scene, "--data", render_out, "--out", probe.out, "--quiet", outside_changes=True)
    if probe.status == 2:
        probe.refused("writing")
    else:
        probe.check(probe.status in (0, 1) and not probe.lines, f"exit {probe.status}, {probe.lines}")
    writer.communicate(timeout=120)
    probe.check(writer.returncode == 0, f"the render: exit {writer.returncode}")


@case("concurrency", "six forwards on one folder at once",
      "each exit 0, or exit 2 in one line naming another process; the files the reference's; nothing left", slow=True)
def _(probe):
    scene = probe.scene()
    children = [_spawn(probe, "forward", scene, "--out", probe.out, "--quiet") for _ in range(6)]
    results = [(child.communicate(timeout=120)[1].decode(), child.returncode)[::-1] for child in children]
    probe.observed.append(f"exits {[status for status, _ in results]}")
    for status, err in results:
        lines = [line for line in err.splitlines() if line.strip()]
        if status == 0:
            probe.check(not lines, f"stderr {lines}")
        else:
            probe.check(status == 2 and len(lines) == 1 and "another diffuse-imaging command" in lines[0],
                        f"exit {status}, {lines}")
    probe.check(any(status == 0 for status, _ in results), "none succeeded")
    probe.matches_reference(GOOD)
    probe.check(not _leftovers(probe.out), f"left in --out: {_leftovers(probe.out)}")


# ======================================================================== the table

def test_the_table_has_at_least_100_cases():
    assert len(CASES) >= 100


@pytest.mark.filterwarnings("default")
@pytest.mark.parametrize("probe_case", [pytest.param(c, marks=[pytest.mark.slow] if c.slow else [],
                                                     id=f"{c.kind}: {c.name}") for c in CASES])
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
