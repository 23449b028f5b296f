"""The ``diffuse-imaging`` command line.

One module per group of commands: :mod:`.model` (forward), :mod:`.render`,
:mod:`.plot`, :mod:`.checks` (validate, run), :mod:`.reconstruct` (reconstruct,
reproduce), :mod:`.sweep`, :mod:`.bench`, :mod:`.interop` (check, export);
:mod:`.common` holds what they share and :mod:`.program` the parser, a
command's run and the policy for errors, warnings and output. Heavy modules
(Numba kernels, Mitsuba, Dask, matplotlib) are imported inside each command,
so ``--help`` and argument errors answer at once.

Names are loaded on first use (``lazy_loader``, as in every package of this
project); ``__all__`` lists the public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "program": ["main", "console", "build_parser"],
    "common": ["UsageError"],
})
