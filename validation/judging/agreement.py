"""The verdict of a cross-check (:func:`validation.judging.compare.compare_transients`) and its report.

:class:`Agreement` holds the verdict and every figure behind it: the
normal scores, the two statistics and their acceptance limits, the null
distribution the limits came from, the worst bins, the directed tests of
the scale and offset and the errors they can detect; it writes them as one
paragraph (:meth:`Agreement.summary`) or as JSON-ready numbers
(:meth:`Agreement.as_dict`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from validation.judging.directed import DirectedTests

__all__ = ["Agreement", "SIGN_FLIP", "INDEPENDENT", "null_note", "detectable_text"]

#: Names of the null distributions (Agreement.null).
SIGN_FLIP, INDEPENDENT = "sign-flip", "independent"


@dataclass(frozen=True)
class Agreement:
    """The verdict and every figure behind it.

    Attributes
    ----------
    agrees : bool
        True when neither test rejects and no unsampled bin holds model light.
    z : numpy.ndarray
        ``(K, N)`` normal scores of t (equal to t when ν = ∞), NaN where the
        bin is not judged.
    dof : float
        ν, the standard errors' degrees of freedom (``inf``: normal; the
        smallest when they differ per bin).
    bins : int
        D, bins judged (0 < se < max_relative_stderr |y_render|).
    skipped : int
        Bins with 0 < se but too few samples to judge.
    chi2, chi2_per_dof : float
        Σ z² and Σ z² / D.
    chi2_interval : (float, float)
        Acceptance interval of χ² / D.
    max_abs_z, z_threshold : float
        Largest |z| and its acceptance limit z*.
    false_alarm : float
        α, the probability that pure noise fails the check.
    relative_l2 : float
        ||y_render - y_model|| / ||y_model||.
    worst : list of (k, bin, z)
        The largest |z|, worst first; k is the sensor (a plane) or the pair
        (a relay-wall capture), the row group of y.
    unsampled_light : list of (k, bin, model value)
        Bins with se = 0 but model light above z* x max(se).
    null : {"sign-flip", "independent"}
        Where the limits come from: sign flips of the replicas (valid
        whatever the correlation between bins), or χ²(D) and Šidák, which
        assume independent bins.
    null_note : str
        One sentence saying so, for reports.
    flips : int
        Sign patterns drawn (0 for the independent-bins null).
    directed : DirectedTests or None
        The data's scale and offset tested against the model's
        (:mod:`validation.judging.directed`); None where the caller gave no
        directions or too few bins are judged.
    """

    agrees: bool
    z: np.ndarray
    dof: float
    bins: int
    skipped: int
    chi2: float
    chi2_per_dof: float
    chi2_interval: tuple
    max_abs_z: float
    z_threshold: float
    false_alarm: float
    relative_l2: float
    worst: list = field(default_factory=list)
    unsampled_light: list = field(default_factory=list)
    null: str = INDEPENDENT
    null_note: str = ""
    flips: int = 0
    directed: DirectedTests | None = None

    @property
    def detectable(self) -> dict | None:
        """{"scale": s, "shift_opl": d}: the smallest relative scale error and time shift (metres of path)
        these data flag with probability 1/2 at the false-alarm rate (docs/design.md section 6); None
        without directed tests (``shift_opl`` None where the offset is not tested)."""
        return None if self.directed is None else self.directed.detectable

    def summary(self) -> str:
        """One paragraph: verdict, χ²/dof, max |z|, thresholds and their null, worst bins."""
        verdict = "AGREE" if self.agrees else "DISAGREE"
        low, high = self.chi2_interval
        # k: the row's sensor (a plane) or its (laser, sensor) pair (a relay-wall capture)
        worst = ", ".join(f"(k = {k}, bin {n}, z = {z:+.2f})" for k, n, z in self.worst[:5])
        reference = "normal" if np.isinf(self.dof) else f"Student t, {self.dof:g} degrees of freedom"
        text = (f"{verdict} ({reference}): χ²/dof = {self.chi2_per_dof:.3f} over {self.bins} bins "
                f"({self.skipped} with too few samples not judged) "
                f"(accept [{low:.3f}, {high:.3f}]), max |z| = {self.max_abs_z:.2f} "
                f"(accept ≤ {self.z_threshold:.2f}); false-alarm rate {self.false_alarm:g}, {self.null_note}; "
                f"relative L2 = {self.relative_l2:.3e}. Worst bins: {worst}")
        if self.unsampled_light:
            text += f". Unsampled bins with model light: {self.unsampled_light[:5]}"
        if self.directed is not None:
            text += f". {self.directed.text()}; {detectable_text(self.detectable)}"
        return text

    def as_dict(self) -> dict:
        """JSON-ready figures (without the z array)."""
        return {"agrees": self.agrees, "dof": float(self.dof), "bins": self.bins, "skipped": self.skipped, "chi2": self.chi2,
                "chi2_per_dof": self.chi2_per_dof, "chi2_interval": list(self.chi2_interval),
                "max_abs_z": self.max_abs_z, "z_threshold": self.z_threshold,
                "false_alarm": self.false_alarm, "null": self.null, "null_note": self.null_note,
                "flips": self.flips, "relative_l2": self.relative_l2,
                "worst": [list(map(float, w)) for w in self.worst],
                "unsampled_light": [list(map(float, w)) for w in self.unsampled_light],
                "directed": None if self.directed is None else self.directed.as_dict(),
                "detectable": self.detectable}


def null_note(null: str, replicas: int | None, flips: int, false_alarm: float) -> str:
    """One sentence for reports: where the limits came from, and what they assume."""
    if null == SIGN_FLIP:
        return (f"limits from {flips} sign flips of the {replicas} replicas' deviations from the model judged, "
                f"valid whatever the correlation between bins")
    if replicas is None:
        return "limits χ²(D) and Šidák, which assume independent bins (no replicas given)"
    return (f"limits χ²(D) and Šidák, which assume independent bins ({replicas} replicas are too few for "
            f"sign flips at α = {false_alarm:g})")


def detectable_text(detectable: dict | None) -> str:
    """'detectable: a scale error of 0.42 %, a shift of 3.1e-04 m' (with probability 1/2), for reports."""
    if detectable is None:
        return "detectable: not stated (too few bins judged for the directed tests)"
    shift = ("no shift (the offset cannot be told from the scale)" if detectable["shift_opl"] is None
             else f"a shift of {detectable['shift_opl']:.2g} m")
    return f"detectable (flagged half the time): a scale error of {100 * detectable['scale']:.2g} %, {shift}"
