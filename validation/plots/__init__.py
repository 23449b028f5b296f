"""Every figure the project draws, by family; each plotting function returns a Figure.

One convention: a plotting function builds a
:class:`matplotlib.figure.Figure` on the Agg canvas (never pyplot's global
state) with its resolution, and returns it; the caller writes it with
:func:`save_figure` (PNG, atomically). matplotlib is imported inside the
functions, so that the command line starts fast.

- :mod:`.common`: :func:`new_figure`, :func:`save_figure`, a user's text as it is;
- :mod:`.axes`: readable log axes and cropped path-length axes;
- :mod:`.transients`: model against render, the model alone, the z map;
- :mod:`.captures`: a capture over a grid of wall points (tal's HDF5);
- :mod:`.relay_wall`: a relay-wall capture's transient per pair, its light over the scan;
- :mod:`.check`: ``check``'s data against the model and its z;
- :mod:`.reconstruction`: images, the λ rule's criterion, spectra, the paper's panels;
- :mod:`.convergence`: error against samples and against wall time;
- :mod:`.worker`: a figure drawn in a second process while a command computes its data.

Names are loaded on first use (``lazy_loader``); ``__all__`` lists the
public API.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "common": ["new_figure", "save_figure", "figure_png", "save_png", "NANOSECONDS_PER_METRE", "Y_LABEL"],
    "transients": ["transients_figure", "model_figure", "z_map_figure", "transient_figure", "finish_time_figure"],
    "captures": ["capture_figure"],
    "relay_wall": ["relay_wall_figure", "scene_transient_figure", "WallScan", "RELAY_WALL_LABEL"],
    "check": ["check_transients_figure", "check_z_figure"],
    "reconstruction": ["reconstructions_figure", "reconstruction_figure", "criterion_figure",
                       "conditioning_figure", "panels_figure"],
    "convergence": ["convergence_figure", "speed_against_error_figure"],
    "worker": ["FigureWorker"],
})
