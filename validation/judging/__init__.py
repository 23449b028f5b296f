"""How agreement is judged (docs/design.md section 6): z per bin, χ² and max |z| against their null, directed tests.

- :mod:`.compare`: :func:`compare_transients`, a render against the model, bin by bin;
- :mod:`.agreement`: its verdict (:class:`Agreement`) and the words that report it;
- :mod:`.null_distribution`: normal scores of t, and the limits' null distributions (sign flips or independent bins);
- :mod:`.directed`: the data's scale and time offset against the stated ones, and the power they state;
- :mod:`.arrays`: a user's numbers checked (real, finite, of the shape a call needs).

``check`` (:mod:`validation.check`) judges any tool's transient with these.
Names are loaded on first use (``lazy_loader``); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "compare": ["Agreement", "compare_transients", "judged_bins", "CorrelationWarning"],
    "directed": ["DirectedTests", "directed_tests"],
    "null_distribution": ["normal_scores"],
})
