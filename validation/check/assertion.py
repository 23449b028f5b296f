"""A renderer's regression test in one call: :func:`assert_agrees`, ``check`` as a pytest assertion."""

from __future__ import annotations

from .result import CheckResult
from .verdict import check_transient

__all__ = ["assert_agrees"]


def assert_agrees(scene, data, *, stderr=None, expect=None, false_alarm: float = 1e-3, **options) -> CheckResult:
    """Judge data against the exact model as ``check`` does, and raise AssertionError unless they agree.

    Parameters
    ----------
    scene : Scene, RelayWallScene, str or Path
        The scene (or its file: TOML, or a tal YAML configuration).
    data : array_like, str, Path or list
        Anything ``check --data`` reads, in memory or by path: one
        ``(K, N)`` transient with ``stderr``, ``(R, K, N)`` replicas or a
        list of them, mitransient's films as ``np.array(film)`` gives them
        (sensors stacked, or a list of one per sensor, replicas of either),
        our render's folder, tal's captures (see
        :func:`~validation.check.check_transient`).
    stderr : array_like, str or Path, optional
        The standard error of one transient.
    expect : str or Convention, optional
        The convention the data follow, by ``check --expect``'s names
        (``"irradiancemeter"`` for mitransient's irradiancemeter spheres,
        ``"transient_nlos_path"``) or as a :class:`~validation.check.Convention`.
        The verdict is then the stated convention's, its scale and offset
        tested too.
    false_alarm : float
        α: the probability that correct data fail the assertion.
    **options
        The other keywords of :func:`~validation.check.check_transient`
        (``dof``, ``radius``, ``model``, ``shape_only``, ...).

    Returns
    -------
    CheckResult
        Everything ``check`` reports (``verdict``, ``fit``, ``detectable``,
        ``judgement`` with its thresholds, ``summary()``).

    Raises
    ------
    AssertionError
        When the verdict that matters disagrees (with ``expect``, the stated
        convention's): its first line is that verdict with its statistics,
        then the fitted scale as a ratio to the stated one, the worst bins,
        and what these data can detect (``detectable``).
    analytic.errors.UserError
        What ``check`` refuses (:class:`~analytic.errors.DataError`,
        :class:`~analytic.errors.OptionError`,
        :class:`~analytic.errors.SceneError`), with its one-line message.

    Examples
    --------
    >>> import validation                                               # doctest: +SKIP
    >>> validation.assert_agrees("scene.toml", [np.array(film) for film in renders],
    ...                          expect="irradiancemeter")              # doctest: +SKIP
    """
    result = check_transient(scene, data, stderr=stderr, expect=expect, false_alarm=false_alarm, **options)
    if not result.verdict:
        raise AssertionError(result.failure())
    return result
