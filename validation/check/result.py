"""What ``check`` found (:class:`CheckResult`): the verdicts as given, as stated and after the fit, and every
figure behind them, as attributes, a summary, metrics.json's numbers and the message of a failed test."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from validation.judging.agreement import Agreement, detectable_text
from validation.judging.compare import tighter_model_note

from .conventions import Convention
from .fit import Fit

__all__ = ["CheckResult", "expected_sentence"]


@dataclass(frozen=True, kw_only=True)
class CheckResult:
    """What ``check`` found: the verdict as given, the fitted conventions, the verdict after them.

    Built by keyword; what a judgement did not make (a fit, a stated
    convention, the statistical verdicts of a shape-only judgement) keeps
    its default, None.

    Attributes
    ----------
    agrees : bool
        The data agree with the model as given.
    judged_by : {"stderr", "replicas", "shape"}
        Where the per-bin error came from.
    relative_l2 : float
        ||y_data - y_model|| / ||y_model|| as given.
    diagnosis : str
        One sentence for the user.
    data, model, fitted_model : numpy.ndarray
        ``(K, N)``: the (mean) data, the model as given and
        scale · y_model(start_opl + offset) (the model as given without a
        fit).
    edges : numpy.ndarray
        ``(N + 1,)`` bin edges of the scene, metres of path length.
    stderr : numpy.ndarray or None
        ``(K, N)`` the data's standard error (None by shape).
    replicas : int
        Number of data arrays averaged (1 unless replicas).
    dof : int or None
        Student-t degrees of freedom of z (R - 1), None for Gaussian z.
    as_given : Agreement or None
        The full verdict as given (None when judged by shape only). With
        replicas z is judged as Student's t (see Notes of
        :func:`check_transient`).
    fit : Fit or None
        Best scale and offset; None when too few bins allow no fit
        (``fit_skipped`` says why).
    fit_skipped : str or None
        Why no scale and offset were fitted.
    agrees_after_fit : bool or None
        The data agree with scale · y_model(start_opl + offset) (None
        without a fit).
    relative_l2_after_fit : float or None
        After the fit (None without a fit).
    after_fit : Agreement or None
        The full verdict after the fit (None by shape only, or without a fit).
    expected : Convention or None
        The convention the user stated (``check --expect``).
    agrees_as_expected : bool or None
        The data agree with the stated convention's model.
    relative_l2_as_expected : float or None
        ||y_data - y_expected|| / ||y_expected||.
    as_expected : Agreement or None
        Its full verdict (None by shape only or without a stated convention).
    shape_tolerance : float or None
        The relative L2 tolerance when judged by shape only.
    model_tolerance : float or None
        The tolerance the model was evaluated at when the data's errors
        needed a tighter one than the scene's
        (:func:`validation.judging.compare.model_tolerance_for`); None: the scene's.
    scene_tolerance : float or None
        The scene's own tolerance.
    replica_data : numpy.ndarray or None
        ``(R, K, N)`` the replicas judged (None for one transient): sums over
        bins take their error from them.
    false_alarm : float or None
        α of each statistical verdict (None by shape only).

    Notes
    -----
    The verdict that matters (:attr:`verdict`, ``check``'s exit status) is
    the stated convention's when there is one, else the data as given; its
    full figures are :attr:`judgement` (an :class:`Agreement`: χ²/dof and
    max |z| with their limits, the directed tests of the scale and offset,
    the worst bins) and its power :attr:`detectable`.
    """

    agrees: bool
    judged_by: str
    relative_l2: float
    diagnosis: str
    data: np.ndarray = field(repr=False)
    model: np.ndarray = field(repr=False)
    fitted_model: np.ndarray = field(repr=False)
    edges: np.ndarray = field(repr=False)
    stderr: np.ndarray | None = field(default=None, repr=False)
    replicas: int = 1
    dof: int | None = None
    as_given: Agreement | None = field(default=None, repr=False)
    fit: Fit | None = None
    fit_skipped: str | None = None
    agrees_after_fit: bool | None = None
    relative_l2_after_fit: float | None = None
    after_fit: Agreement | None = field(default=None, repr=False)
    expected: Convention | None = None
    agrees_as_expected: bool | None = None
    relative_l2_as_expected: float | None = None
    as_expected: Agreement | None = field(default=None, repr=False)
    shape_tolerance: float | None = None
    model_tolerance: float | None = None
    scene_tolerance: float | None = None
    replica_data: np.ndarray | None = field(default=None, repr=False)
    false_alarm: float | None = None

    @property
    def chi2_per_dof(self) -> float | None:
        """χ²/dof as given (None when judged by shape only)."""
        return None if self.as_given is None else self.as_given.chi2_per_dof

    @property
    def max_abs_z(self) -> float | None:
        """max |z| as given (None when judged by shape only)."""
        return None if self.as_given is None else self.as_given.max_abs_z

    @property
    def judgement(self) -> Agreement | None:
        """The full figures of the verdict that matters: as stated when a convention is, else as given
        (None by shape only); its thresholds are ``chi2_interval``, ``z_threshold`` and ``directed.limit``."""
        return self.as_expected if self.expected is not None else self.as_given

    @property
    def detectable(self) -> dict | None:
        """{"scale": s, "shift_opl": d}: the smallest relative scale error and time shift (metres of path) that
        these data flag with probability 1/2 at the false-alarm rate, by the verdict that matters
        (docs/design.md section 6); None by shape only or with too few bins for the directed tests."""
        return None if self.judgement is None else self.judgement.detectable

    @property
    def chi2_per_dof_after_fit(self) -> float | None:
        """χ²/dof after the fit (None by shape only or without a fit)."""
        return None if self.after_fit is None else self.after_fit.chi2_per_dof

    @property
    def max_abs_z_after_fit(self) -> float | None:
        """max |z| after the fit (None by shape only or without a fit)."""
        return None if self.after_fit is None else self.after_fit.max_abs_z

    @property
    def model_tolerance_note(self) -> str | None:
        """Why the model was evaluated at a tighter tolerance than the scene's (None when it was not)."""
        if self.model_tolerance is None:
            return None
        return tighter_model_note(self.model_tolerance, self.scene_tolerance)

    @property
    def verdict(self) -> bool:
        """What the exit status reports: agreement with the stated convention, else as given."""
        return bool(self.agrees_as_expected) if self.expected is not None else self.agrees

    def as_dict(self) -> dict:
        """metrics.json: docs/design.md section 5's keys plus the figures behind them."""
        result = {"agrees": self.agrees, "chi2_per_dof": self.chi2_per_dof, "max_abs_z": self.max_abs_z,
                  "fit": None if self.fit is None else self.fit.as_dict(),
                  "agrees_after_fit": self.agrees_after_fit, "fit_skipped": self.fit_skipped,
                  "judged_by": self.judged_by, "replicas": self.replicas, "dof": self.dof,
                  "relative_l2": self.relative_l2, "relative_l2_after_fit": self.relative_l2_after_fit,
                  "chi2_per_dof_after_fit": self.chi2_per_dof_after_fit,
                  "max_abs_z_after_fit": self.max_abs_z_after_fit, "diagnosis": self.diagnosis,
                  "model_tolerance": self.model_tolerance, "detectable": self.detectable,
                  "false_alarm": self.false_alarm}
        if self.expected is not None:
            result["expected"] = self.expected.as_dict() | {
                "agrees": self.agrees_as_expected, "relative_l2": self.relative_l2_as_expected}
            if self.as_expected is not None:
                result["expected"] |= {"chi2_per_dof": self.as_expected.chi2_per_dof,
                                       "max_abs_z": self.as_expected.max_abs_z,
                                       "detectable": self.as_expected.detectable}
        if self.as_given is not None:
            result["null"] = self.as_given.null
            result["as_given_detail"] = self.as_given.as_dict()
            result["after_fit_detail"] = None if self.after_fit is None else self.after_fit.as_dict()
            if self.as_expected is not None:
                result["as_expected_detail"] = self.as_expected.as_dict()
        else:
            result["shape_tolerance"] = self.shape_tolerance
        return result

    def summary(self) -> str:
        """The verdict as given, the stated convention's when there is one, and the diagnosis."""
        if self.judged_by == "shape":
            head = (f"{'AGREES' if self.agrees else 'DISAGREES'} by shape only (no errors given): "
                    f"relative L2 = {self.relative_l2:.3e} (tolerance {self.shape_tolerance:g})")
        else:
            source = (f"{self.replicas} replicas, t with {self.dof} dof" if self.judged_by == "replicas"
                      else "given standard errors")
            head = (f"{'AGREES' if self.agrees else 'DISAGREES'} as given ({source}; {self.as_given.null_note}): "
                    f"χ²/dof = {self.chi2_per_dof:.3f}, max |z| = {self.max_abs_z:.2f}, "
                    f"relative L2 = {self.relative_l2:.3e}")
        lines = [head]
        if self.model_tolerance_note:
            lines.append(f"({self.model_tolerance_note})")
        if self.expected is not None:
            lines.append(expected_sentence(self))
        if self.judgement is not None:
            if self.judgement.directed is not None:
                lines.append(self.judgement.directed.text())
            lines.append(detectable_text(self.detectable).capitalize())
        return "\n".join(lines + [self.diagnosis])

    def failure(self) -> str:
        """Why the verdict that matters fails, for an AssertionError: the verdict first, then the fitted scale
        as a ratio to the stated one, the worst bins and what the data can detect."""
        judgement = self.judgement
        if judgement is None:
            lines = [self.summary().splitlines()[0]]
        else:
            stated = self.expected
            lines = [expected_sentence(self) if stated is not None else
                     f"DISAGREES as given: χ²/dof = {judgement.chi2_per_dof:.3f} (accept "
                     f"[{judgement.chi2_interval[0]:.3f}, {judgement.chi2_interval[1]:.3f}]), max |z| = "
                     f"{judgement.max_abs_z:.2f} (accept ≤ {judgement.z_threshold:.2f})"
                     + _directed_clause(judgement)]
        if self.fit is not None:
            scale, offset = (1.0, 0.0) if self.expected is None else (self.expected.scale, self.expected.offset_opl)
            lines.append(f"fitted scale {self.fit.scale / scale:.5g} ± {self.fit.scale_stderr / scale:.2g} x the "
                         f"{'stated' if self.expected is not None else 'model'}'s, offset {self.fit.offset_opl:+.4g} ± "
                         f"{self.fit.offset_stderr:.2g} m (stated {offset:+.4g} m)")
        if judgement is not None and judgement.worst:
            lines.append("worst bins: " + ", ".join(f"(k = {k}, bin {n}, z = {z:+.2f})" for k, n, z in judgement.worst[:5]))
        lines.append(detectable_text(self.detectable))
        return "\n".join(lines + [self.diagnosis])


def expected_sentence(result: CheckResult) -> str:
    """One line: the verdict against the stated convention and its figures."""
    expected = result.expected
    stated = (f"{expected.name}: scale {expected.scale:.6g}, offset {expected.offset_opl:+.6g} m")
    judged = result.as_expected
    if judged is None:
        figures = f"relative L2 = {result.relative_l2_as_expected:.3e}"
    else:
        figures = (f"χ²/dof = {judged.chi2_per_dof:.3f} (accept [{judged.chi2_interval[0]:.3f}, "
                   f"{judged.chi2_interval[1]:.3f}]), max |z| = {judged.max_abs_z:.2f} (accept ≤ "
                   f"{judged.z_threshold:.2f})" + _directed_clause(judged))
    verdict = "AGREES" if result.agrees_as_expected else "DISAGREES"
    return f"{verdict} with the stated convention ({stated}): {figures}"


def _directed_clause(judged: Agreement) -> str:
    """', scale t = +7.30, offset t = -0.40 (accept |t| ≤ 4.9)' of a verdict's directed tests ('' without)."""
    directed = judged.directed
    if directed is None:
        return ""
    shift = "" if directed.shift_t is None else f", offset t = {directed.shift_t:+.2f}"
    return f", scale t = {directed.scale_t:+.2f}{shift} (accept |t| ≤ {directed.limit:.2f})"


