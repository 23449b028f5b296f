"""Shared pieces of issue 38's probe (tests/probe/): run a command in this process, judge its outcome, and an
independent midpoint-rule reference for relay-wall captures.

The promises judged (README "Refusals", docs/design.md sections 5, 7 and 8): a user's mistake ends in exit
status 2 and ONE line ``diffuse-imaging: error: ...`` naming the cause, before any file is written (the
``--out`` folder is not created); a legal input ends in exit 0 with finite values, which the cases check
against computations made here (never against the code's own saved output).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from validation.cli import main

ERROR = "diffuse-imaging: error:"


def run(capsys, args) -> tuple[int, list[str]]:
    """Run ``diffuse-imaging ARGS`` in this process: (exit status, the non-empty stderr lines)."""
    capsys.readouterr()
    try:
        status = main([str(a) for a in args])
    except SystemExit as exit_:           # argparse's usage errors leave main this way, as from the shell
        status = exit_.code
    err = capsys.readouterr().err
    return status, [line for line in err.splitlines() if line.strip()]


def assert_refused(capsys, args, out: Path | None, *needles: str) -> str:
    """Exit 2, exactly one stderr line, ``diffuse-imaging: error:`` naming every needle, no ``out`` written."""
    status, lines = run(capsys, args)
    assert status == 2, (status, lines)
    assert len(lines) == 1 and lines[0].startswith(ERROR), lines
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert "Traceback" not in lines[0]
    if out is not None:
        assert not Path(out).exists(), f"{out} written by a refused command"
    return lines[0]


def assert_forward_refuses(tmp_path, capsys, tables: dict, needle: str) -> str:
    """``forward`` of the scene ``tables`` (written as TOML) is refused in one line holding ``needle``."""
    scene = tmp_path / "scene.toml"
    scene.write_text(toml_text(tables))
    return assert_refused(capsys, ["forward", scene, "--out", tmp_path / "out"], tmp_path / "out", needle)


def assert_accepted(capsys, args) -> list[str]:
    """Exit 0 and no error line; returns the stderr lines (warnings may stand)."""
    status, lines = run(capsys, args)
    assert status == 0, (status, lines)
    assert not any(line.startswith(ERROR) for line in lines), lines
    return lines


# ======================================================================== relay walls by the midpoint rule

def grid_cells(grid, size) -> np.ndarray:
    """Docs/design.md section 7: cell (row j, column i) of a W x H grid is ((2i+1)/W - 1, (2j+1)/H - 1, 0)
    times the wall's half sizes, row-major: written here from the text, not imported."""
    width, height = grid
    return np.array([[((2 * i + 1) / width - 1) * size[0] / 2, ((2 * j + 1) / height - 1) * size[1] / 2, 0.0]
                     for j in range(height) for i in range(width)])


def wall_pairs(scan: dict, size) -> tuple[np.ndarray, np.ndarray]:
    """(lit points, read points) of a ``[scan]`` table in the pair order of docs/design.md section 7."""
    read = grid_cells(scan["grid"], size)
    if scan["type"] == "single":
        point = np.asarray(scan.get("laser_point", (0.0, 0.0, 0.0)), float)
        return np.repeat(point[None], len(read), axis=0), read
    if scan["type"] == "confocal":
        return read, read
    lit = grid_cells(scan.get("laser_grid", scan["grid"]), size)
    return np.repeat(lit, len(read), axis=0), np.tile(read, (len(lit), 1))


def _midpoint_totals(lit, read, hidden, steps: int) -> np.ndarray:
    center, u, v = (np.asarray(hidden[k], float) for k in ("center", "u", "v"))
    normal = np.cross(u, v)
    normal /= math.sqrt(normal @ normal)
    fractions = (np.arange(steps) + 0.5) / steps
    a, b = np.meshgrid(fractions, fractions, indexing="ij")
    points = (center - 0.5 * (u + v))[None] + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    area = math.sqrt(u @ u) * math.sqrt(v @ v) / steps**2
    totals = []
    for l_point, s_point in zip(lit, read):
        to_l, to_s = l_point - points, s_point - points            # from x toward l and s
        d_l, d_s = np.sqrt(np.sum(to_l**2, 1)), np.sqrt(np.sum(to_s**2, 1))
        cos_x = (to_l @ normal) / d_l * (to_s @ normal) / d_s       # at x
        cos_wall = (-to_l[:, 2]) / d_l * (-to_s[:, 2]) / d_s        # at l and s (wall normal +z), toward x
        totals.append(math.fsum(cos_x * cos_wall / (math.pi * d_l**2 * d_s**2)) * area)
    return np.array(totals)


def relay_wall_totals(tables: dict, steps: int = 160) -> tuple[np.ndarray, np.ndarray]:
    """Per pair, the light summed over all time, Σ_n H[n] (impulse, window holding all of it), and a bound on
    the midpoint rule's own error: docs/design.md section 7's formula with constant ρ_h, by the midpoint
    rule on ``steps`` x ``steps`` cells and on twice as many (the error of the finer is about a third of
    their difference for a smooth integrand; three times the difference is stated)."""
    size = tables["relay_wall"]["size"]
    rho_w = tables["relay_wall"].get("reflectance", 1.0)
    hidden = {"center": (0.0, 0.0, 1.0), "u": (1.0, 0.0, 0.0), "v": (0.0, -1.0, 0.0), **tables.get("hidden", {})}
    laser = np.asarray(tables.get("laser", {}).get("position", (-0.5, 0.0, 0.25)), float)
    intensity = tables.get("laser", {}).get("intensity", 1.0)
    rho_h = hidden.get("reflectance", 0.5)
    lit, read = wall_pairs(tables["scan"], size)
    to_laser = laser[None] - lit
    distance = np.sqrt(np.sum(to_laser**2, 1))
    leg = intensity * (to_laser[:, 2] / distance) / distance**2 * (rho_w / math.pi) ** 2 * rho_h
    coarse = _midpoint_totals(lit, read, hidden, steps) * leg
    fine = _midpoint_totals(lit, read, hidden, 2 * steps) * leg
    return fine, 3.0 * np.abs(fine - coarse)


def relay_wall_path_range(tables: dict, steps: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Per pair, a lower bound on the shortest path |l - x| + |x - s| over the hidden rectangle (grid
    minimum less the Lipschitz bound 2 x half a cell's diagonal) and the longest (at a corner: convex)."""
    size = tables["relay_wall"]["size"]
    hidden = {"center": (0.0, 0.0, 1.0), "u": (1.0, 0.0, 0.0), "v": (0.0, -1.0, 0.0), **tables.get("hidden", {})}
    center, u, v = (np.asarray(hidden[k], float) for k in ("center", "u", "v"))
    lit, read = wall_pairs(tables["scan"], size)
    fractions = np.linspace(0.0, 1.0, steps + 1)
    a, b = np.meshgrid(fractions, fractions, indexing="ij")
    points = (center - 0.5 * (u + v))[None] + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    slack = 2 * 0.5 * math.hypot(math.sqrt(u @ u), math.sqrt(v @ v)) / steps
    shortest, longest = [], []
    for l_point, s_point in zip(lit, read):
        paths = np.sqrt(np.sum((points - l_point) ** 2, 1)) + np.sqrt(np.sum((points - s_point) ** 2, 1))
        shortest.append(paths.min() - slack)
        longest.append(paths.max())
    return np.array(shortest), np.array(longest)


def toml_value(value) -> str:
    """A Python value as TOML (numbers with every digit, strings quoted, lists bracketed)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    return str(value)


def toml_text(tables: dict) -> str:
    """Nested dict of tables -> TOML text."""
    parts = []
    for table, keys in tables.items():
        parts.append(f"[{table}]")
        parts.extend(f"{key} = {toml_value(value)}" for key, value in keys.items())
    return "\n".join(parts) + "\n"


def merged(base: dict, changes: dict) -> dict:
    """``base`` with each table updated by ``changes`` (a value None removes the key)."""
    tables = {table: dict(keys) for table, keys in base.items()}
    for table, keys in changes.items():
        target = tables.setdefault(table, {})
        for key, value in keys.items():
            if value is None:
                target.pop(key, None)
            else:
                target[key] = value
    return tables
