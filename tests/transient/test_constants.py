"""The renderer's constants: one definition each, importable without Mitsuba."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_ray_epsilon_is_defined_once_and_read_by_the_check_and_the_scenes():
    from transient import constants, mitsuba_scene
    from validation.check import RAY_EPSILON_FLOAT32

    assert RAY_EPSILON_FLOAT32 is constants.RAY_EPSILON
    assert mitsuba_scene.RAY_EPSILON is constants.RAY_EPSILON


def test_the_conventions_read_the_ray_epsilon_without_importing_mitsuba():
    code = ("import sys, validation.check.conventions\n"
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'mitsuba', 'drjit'}))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
