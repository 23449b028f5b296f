"""The corner's further bounces against a renderer nobody here wrote (mitransient's transient_path)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from transient import backend
from validation.judging.compare import combined_dof, compare_transients
from validation.runs.corner import corner_against_mitransient, default_corner, render_corner


def test_irradiancemeter_offset_uses_mitsubas_ray_epsilon():
    backend.select_variant()
    import mitsuba as mi

    from transient.mitsuba_scene import RAY_EPSILON, irradiancemeter_correction

    assert RAY_EPSILON == pytest.approx(float(mi.math.RayEpsilon), rel=1e-6)
    factor, offset = irradiancemeter_correction(3e-4)
    assert factor == 4.0 and offset == pytest.approx(2e-4 + RAY_EPSILON)


@pytest.mark.slow
def test_three_bounces_agree_with_mitransient():
    """Per-bin errors from both sides' replicas (Welch–Satterthwaite degrees of freedom)."""
    if importlib.util.find_spec("mitransient") is None:
        pytest.skip("mitransient not installed (pip install -e .[bench])")
    corner = default_corner()
    ours = render_corner(corner, spp=2**23, seed=5, max_depth=3)
    verdict, theirs = corner_against_mitransient(corner, ours, samples=2**20, replicas=16, seed=100)
    assert verdict.bins >= 80
    assert verdict.agrees, verdict.summary()
    # The check has the power to see the further bounces: one bounce is not mitransient's three.
    one = render_corner(corner, spp=2**23, seed=6, max_depth=1)
    stderr = np.sqrt(one.stderr**2 + theirs.stderr**2)
    wrong = compare_transients(one.mean, stderr, theirs.mean, dof=combined_dof(one.stderr, one.dof, theirs.stderr,
                                                                                 theirs.dof))
    assert not wrong.agrees
