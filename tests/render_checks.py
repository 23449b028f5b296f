"""Shared by the renderer's tests: the exact model and the agreement test of docs/design.md section 6.

Agreement is judged per bin (validation.judging.compare): the render's standard
error comes from its 32 independent replicas, so each z is Student's t
with 31 degrees of freedom mapped to a normal score; over the bins with
enough samples, χ²/dof must lie inside the two-sided band and max |z|
below its limit, the two together at false-alarm rate 1e-3. Given the
replicas themselves (``result.replica_means``), the band and the limit
come from their sign flips, which hold when the bins are correlated (a
pulse wider than a bin); without them, from χ²(D) and Šidák, which assume
independent bins.
"""

import numpy as np

from analytic.scenes.common import Scene
from analytic.operator.matrix_free import forward
from transient.render import render_loaded
from validation.judging.compare import compare_transients

FALSE_ALARM = 1e-3


def model(scene: Scene) -> np.ndarray:
    """The exact analytic model's y for the scene."""
    return forward(scene)


def agreement(mean, stderr, reference, dof, replicas=None):
    """(χ²/dof, max |z|, bins judged, passes) by validation.judging.compare (docs/design.md section 6).

    ``replicas``: the render's ``(R, K, N)`` replica means, for limits that hold with correlated bins.
    """
    result = compare_transients(mean, stderr, reference, dof=dof, replicas=replicas, false_alarm=FALSE_ALARM)
    return result.chi2_per_dof, result.max_abs_z, result.bins, result.agrees


def render_dict(mitsuba, entries: dict, samples: int, seed: int):
    """Load a Mitsuba scene dict and render it (mean, stderr, dof from the replicas)."""
    return render_loaded(mitsuba.load_dict(entries), spp=samples, seed=seed)


def general_path_dict(entries: dict, **changes) -> dict:
    """The same scene for transient_opl_path (the single-plane keys dropped)."""
    general = {key: value for key, value in entries["integrator"].items()
               if key not in ("plane_to_world", "source_position")}
    return dict(entries, integrator=dict(general, type="transient_opl_path", **changes))
