"""``check``: judge a transient from any tool against the exact model, and diagnose its conventions.

One job per module:

- :mod:`.readers`: the files users bring (our outputs, any ``(K, N)``
  ``.npy``, tal's HDF5, mitransient's films), read with
  :mod:`analytic.files`' readers and checked against the scene; our
  render's own errors beside its output;
- :mod:`.fit`: the best global scale and time offset (Gauss–Newton on the
  exact model);
- :mod:`.conventions`: a stated convention (``--expect``) and the known
  ones a fit is diagnosed by;
- :mod:`.inputs`: what ``check`` is given (arrays, films, lists, files), as the arrays it judges;
- :mod:`.verdict`: :func:`check_transient`; :mod:`.result`: its :class:`CheckResult`;
- :mod:`.assertion`: :func:`assert_agrees`, a renderer's regression test;
- :mod:`.report`: report.md, metrics.json and the figures;
- :mod:`.scan_figure`: a relay-wall capture's z over pairs x bins and on its scan grid;

Names are loaded on first use (``lazy_loader``); ``__all__`` lists the
public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "readers": ["read_data", "read_stderr", "stderr_beside", "replicas_beside"],
    "fit": ["Fit", "ShiftedModel", "fit_scale_offset"],
    "conventions": ["Convention", "irradiancemeter", "convention", "diagnose", "CONVENTIONS", "KNOWN_SCALES",
                    "RAY_EPSILON_FLOAT32"],
    "inputs": ["read_inputs", "scene_of"],
    "verdict": ["check_transient", "check_derivative", "DerivativeColumn", "FIT_BINS", "MAX_DATA", "MAX_RELATIVE_STDERR"],
    "result": ["CheckResult"],
    "assertion": ["assert_agrees"],
    "report": ["write_check_report"],
    "scan_figure": ["scan_z_figure", "summed_z"],
})
