"""docs/design.md "Where each extension goes", walked through: a scene kind added in this module alone (and lit by
the toy waveform of tests/test_waveform_walkthrough.py, whose key no project file names).

The toy kind is a Lambertian tile in any pose (a rectangle of corner, u and v)
under one point source, seen by point sensors: one dataclass that states what
the protocol asks (:class:`analytic.scenes.kinds.SceneKind`) and registers
itself. No project file knows it, yet the model, the files, the readers,
``check`` and its report take it; the layers written per kind (the renderer,
export) refuse it in one line instead of guessing. And the count that keeps
kinds in one place: code above the model tests a scene's class in at most two
places.
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

from analytic.errors import SceneError, UserError
from analytic.geometry import PointPairs, Rectangle
from analytic.scenes.common import Illumination, Sampling
from analytic.scenes.kinds import SCENE_KINDS, SceneKindError, is_scene, register_scene_kind
from test_waveform_walkthrough import ramp  # noqa: F401  (the toy waveform, registered for a test)

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True, kw_only=True, eq=False)
class Tile:
    """A square tile of side |u| (u ⟂ v, |u| = |v|) with uniform reflectance, imaged as M x M pixels."""

    corner: Any = (0.3, 0.4, 0.0)
    u: Any = (0.2, 0.0, 0.0)
    v: Any = (0.0, 0.2, 0.0)
    pixels: int = 1
    reflectance: Any = 0.7
    source: Any = (0.5, 0.5, 1.0)
    sensors: Any = ((0.2, 0.7, 1.0), (0.6, 0.3, 0.8))
    intensity: float = 2.0
    illumination: Illumination = field(default_factory=Illumination)
    sampling: Sampling = field(default_factory=lambda: Sampling(bin_width_opl=0.02, start_opl=1.7, count=40))
    tolerance: float = 1e-6
    noise: Any = None
    detector: Any = None
    name: str = "tile"

    kind: ClassVar[str] = "walkthrough_tile"
    row_noun: ClassVar[str] = "sensor"
    image_key: ClassVar[str] = "tile.reflectance"

    def __post_init__(self):
        for name in ("corner", "u", "v", "source"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        object.__setattr__(self, "sensors", np.asarray(self.sensors, dtype=np.float64).reshape(-1, 3))
        image = np.broadcast_to(np.asarray(self.reflectance, dtype=np.float64), (self.pixels, self.pixels))
        object.__setattr__(self, "reflectance", np.array(image))

    @property
    def sensor_count(self) -> int:
        return len(self.sensors)

    @property
    def pixel_size(self) -> tuple[float, float]:
        return float(np.linalg.norm(self.u)) / self.pixels, float(np.linalg.norm(self.v)) / self.pixels

    def geometry(self):
        count = self.sensor_count
        return (Rectangle(self.corner, self.u, self.v, self.pixels),
                PointPairs(np.repeat(self.source[None, :], count, axis=0), self.sensors,
                           scales=np.full(count, float(self.intensity))))

    def replace(self, **changes) -> "Tile":
        return replace(self, **changes)

    def describe(self) -> str:
        return f"{self.sensor_count} sensors over a tile"

    def darkness(self):
        return None if np.any(self.reflectance > 0) else ("tile.reflectance", "the tile is black")

    def meta_fields(self) -> dict:
        return {"geometry": self.kind, "source": self.source.tolist(), "sensor_positions": self.sensors.tolist(),
                "attenuation": "lambertian", "units": "as a plane's (W/sr x m^-2 x m of path length)",
                "tile": {"corner": self.corner.tolist(), "u": self.u.tolist(), "v": self.v.tolist()}}

    def to_tables(self, shared: dict) -> dict:
        return {"tile": {"corner": self.corner.tolist(), "u": self.u.tolist(), "v": self.v.tolist(),
                         "pixels": self.pixels, "reflectance": float(self.reflectance.flat[0])},
                "source": {"position": self.source.tolist(), "intensity": self.intensity},
                "sensors": {"positions": self.sensors.tolist()}, **shared}


@pytest.fixture(scope="module")
def tile_kind():
    """The toy kind, registered for this module's tests and removed after them."""
    register_scene_kind(Tile)
    yield Tile
    SCENE_KINDS.pop(Tile.kind)


def _brute_force(tile: Tile, steps: int = 600):
    """Per sensor: I ∫ ρ a_k dA over the tile (midpoint rule, Lambertian a_k of docs/design.md section 2) and the
    shortest and longest path length source -> x -> sensor, metres."""
    fractions = (np.arange(steps) + 0.5) / steps
    points = tile.corner + fractions[:, None, None] * tile.u + fractions[None, :, None] * tile.v
    normal = np.cross(tile.u, tile.v) / np.linalg.norm(np.cross(tile.u, tile.v))
    area = float(np.linalg.norm(np.cross(tile.u, tile.v))) / steps**2
    to_source = tile.source - points
    d_s = np.linalg.norm(to_source, axis=-1)
    totals, shortest, longest = [], [], []
    for sensor in tile.sensors:
        to_sensor = sensor - points
        d_k = np.linalg.norm(to_sensor, axis=-1)
        a = (to_source @ normal / d_s) * (to_sensor @ normal / d_k) / (math.pi * d_s**2 * d_k**2)
        totals.append(tile.intensity * float(tile.reflectance.flat[0]) * float(a.sum()) * area)
        shortest.append(float((d_s + d_k).min()))
        longest.append(float((d_s + d_k).max()))
    return np.array(totals), np.array(shortest), np.array(longest)


def test_toy_scene_kind_runs_through_the_model(tile_kind):
    """The model integrates the toy kind's tile: an impulse's light summed over bins is the tile's integral of
    I ρ a_k (an independent midpoint rule), and it arrives only between the shortest and longest paths."""
    from analytic.operator.matrix_free import forward

    tile = Tile()
    assert is_scene(tile) and tile.pixel_size == pytest.approx((0.2, 0.2))
    y = forward(tile)
    totals, shortest, longest = _brute_force(tile)
    assert y.shape == (2, 40) and np.all(y >= 0)
    assert y.sum(axis=1) == pytest.approx(totals, rel=1e-5)
    edges = tile.sampling.edges
    step = tile.sampling.bin_width_opl * 1e-3         # the midpoint grid's extremes lie within this of the true ones
    for k in range(2):
        outside = (edges[1:] < shortest[k] - step) | (edges[:-1] > longest[k] + step)
        assert outside.any() and np.all(y[k, outside] == 0.0)
    tilted = Tile(corner=(0.3, 0.4, 0.1), u=(0.2, 0.0, 0.0), v=(0.0, 0.2 * math.cos(0.3), -0.2 * math.sin(0.3)),
                  sampling=Sampling(bin_width_opl=0.02, start_opl=1.0, count=80))
    totals, shortest, longest = _brute_force(tilted)
    assert 1.0 < shortest.min() and longest.max() < 2.6          # the window holds all the light
    assert forward(tilted).sum(axis=1) == pytest.approx(totals, rel=1e-5)


def test_toy_scene_kind_in_files_readers_and_reports(tile_kind, tmp_path, rng):
    """Files, readers, ``check`` and its report take the toy kind without a line written for it."""
    from analytic.files import build_meta, write_transient
    from analytic.operator.matrix_free import forward
    from analytic.scenes.scene_file import scene_to_tables
    from validation.check import check_transient, read_data, write_check_report
    from validation.cli.common import rows_text
    from validation.runs.harness import imaging_problem, refuse_dark

    tile = Tile()
    y = forward(tile)
    meta = build_meta(tile, kind="model")
    assert meta["geometry"] == "walkthrough_tile" and meta["plane_size"] is None and meta["scan"] is None
    assert meta["tile"]["u"] == [0.2, 0.0, 0.0] and meta["sensors"] == 2 and meta["pixels"] == 1
    assert set(scene_to_tables(tile)) >= {"name", "tile", "illumination", "sampling"}
    write_transient(tmp_path / "model", y, meta)
    assert np.array_equal(read_data(tmp_path / "model", tile), y)
    assert rows_text(tile) == "2 sensors over a tile"
    assert imaging_problem(tile) is None
    with pytest.raises(SceneError, match="tile.reflectance: the tile is black"):
        refuse_dark(tile.replace(reflectance=0.0), 1.0)

    stderr = np.full_like(y, 0.01 * y.max())
    agrees = check_transient(tile, y + stderr * rng.standard_normal(y.shape), stderr=stderr)
    assert agrees.agrees
    # a render that reads 10 % high is 10 σ of the summed light off: the fit sees it
    high = check_transient(tile, 1.1 * y + stderr * rng.standard_normal(y.shape), stderr=stderr, expect=None)
    assert high.fit.scale == pytest.approx(1.1, abs=5 * high.fit.scale_stderr)
    metrics = write_check_report(tmp_path / "check", agrees, scene_name=tile.name, data_paths=[], scene=tile)
    assert metrics["agrees"] and (tmp_path / "check" / "report.md").is_file()


def test_toy_scene_kind_lit_by_a_toy_waveform_with_a_key_of_its_own(tile_kind, ramp):  # noqa: F811
    """Both doors at once, neither known to a project file: the toy tile under the toy ramp (key ``rise``). The
    model is linear in s: over a window holding all the light, y sums to the ramp's area rise / 2 times the
    impulse's; the metadata and the scene's tables carry the key."""
    from analytic.files import build_meta
    from analytic.operator.matrix_free import forward
    from analytic.scenes.scene_file import scene_to_tables

    window = Sampling(bin_width_opl=0.02, start_opl=1.6, count=60)
    lit = Tile(illumination=Illumination(waveform="ramp", rise=0.08), sampling=window)
    impulse = forward(Tile(sampling=window))
    assert impulse[:, :3].max() == 0 and impulse[:, -10:].max() == 0        # the window holds every path
    # each side within the model's tolerance (1e-6 relative) of the exact integral
    assert forward(lit).sum(axis=1) == pytest.approx(0.04 * impulse.sum(axis=1), rel=10 * lit.tolerance)
    meta = build_meta(lit, kind="model")
    assert meta["illumination"] == "ramp" and meta["illumination_parameters"] == {"rise": 0.08}
    assert scene_to_tables(lit)["illumination"] == {"waveform": "ramp", "rise": 0.08}

def test_layers_written_per_kind_refuse_the_toy_kind_in_one_line(tile_kind, tmp_path):
    """The renderer and export have no handler for a kind they were not written for: a clear user error."""
    from interop.mitransient.export import export_scene
    from transient.render import _load

    tile = Tile()
    with pytest.raises(SceneKindError, match="export: a scene of kind 'walkthrough_tile' is not supported"):
        export_scene(tile, tmp_path / "export", "mitsuba")
    assert not (tmp_path / "export").exists()
    with pytest.raises(UserError, match="render: a scene of kind 'walkthrough_tile'"):
        _load(tile, {})


def test_registry_refuses_a_kind_that_misses_part_of_the_protocol_or_takes_a_name_twice():
    """What the protocol asks is checked where a kind registers, naming what is missing."""

    class Sketch:
        kind = "walkthrough_sketch"

    with pytest.raises(TypeError, match=r"Sketch: a scene kind needs darkness, describe, detector, geometry"):
        register_scene_kind(Sketch)

    @dataclass(frozen=True, kw_only=True, eq=False)
    class Twin(Tile):
        kind: ClassVar[str] = "plane"

    with pytest.raises(ValueError, match="scene kind 'plane' is registered already"):
        register_scene_kind(Twin)
    assert "walkthrough_sketch" not in SCENE_KINDS and SCENE_KINDS["plane"].__name__ == "Scene"


#: The project's packages (tests may test classes freely).
PACKAGES = ("analytic", "transient", "validation", "interop", "benchmarks", "scripts")
#: Names whose isinstance test asks a scene's kind: the kinds' classes, and the registry's own.
KIND_NAMES = {"Scene", "RelayWallScene", "TalScene", "SCENE_KINDS", *(
    cls.__name__ for cls in SCENE_KINDS.values())}


def _kind_tests() -> list[str]:
    """Every ``isinstance(x, K)`` in the project whose K names a scene kind (alone, in a tuple or a union)."""
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "isinstance"
                        and len(node.args) == 2):
                    names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                    names |= {n.attr for n in ast.walk(node.args[1]) if isinstance(n, ast.Attribute)}
                    if names & KIND_NAMES:
                        found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return found


def test_code_asks_a_scene_its_kind_in_at_most_two_places():
    """Code above the model asks the kind (its attributes, or a handler table by kind name), never its class:
    at most two isinstance tests on scene kinds in the whole project."""
    found = _kind_tests()
    assert len(found) <= 2, f"isinstance on scene kinds at {found}: ask the kind (analytic.scenes.kinds) instead"
    assert found, "the registry's own test (analytic.scenes.kinds.is_scene) is no longer found: update the count"
