"""The cross-check of renderers against the exact model, and the application around it.

A user writes, for example::

    import analytic, transient, validation
    result = transient.render(scene, spp=2**22, seed=1)
    agreement = validation.compare_transients(result.mean, result.stderr, analytic.forward(scene))
    validation.assert_agrees(scene, result.replica_means)                   # check, as a test
    validation.assert_agrees("scene.toml", films, expect="irradiancemeter")  # mitransient's renders

Every public call refuses a user's mistake with the library's own
exceptions, subclasses of :class:`analytic.errors.UserError`
(``DataError``, ``OptionError``, ``SceneError``), with the command line's
messages in Python's words.

Names are loaded on first use (``lazy_loader``, as in every package of this
project: the command line starts fast); ``__all__`` lists the public API.
The command line is :mod:`validation.cli`; ``check`` (:mod:`validation.check`)
and the figures (:mod:`validation.plots`) are packages of their own.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "judging.compare": ["Agreement", "compare_transients"],
    "runs.harness": ["SceneCheck", "check_scene", "data_driven_rule", "reconstruct_from_noisy_data"],
    "runs.suite": ["hard_cases", "validation_suite"],
    "runs.corner": ["check_corner"],
    "check": ["check_transient", "check_derivative", "assert_agrees", "CheckResult", "Convention", "irradiancemeter", "read_data"],
    "runs.report": ["write_report"],
    "runs.paper": ["reproduce"],
    "sweep": ["load_sweep", "run_sweep"],
    "runs.bench": ["speed_against_error"],
    "calibration": ["calibrate", "Calibration"],
})
