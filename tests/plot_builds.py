"""Figure builders for tests/validation/test_figure_worker.py: a module the worker process can import too."""

import warnings

import numpy as np

from analytic.scenes.common import Sampling
from validation.plots import transient_figure


def sampling():
    return Sampling(bin_width_opl=0.01, start_opl=2.0, count=20)


def transient():
    """A (3, 20) transient with a bump per sensor."""
    bins = np.arange(20)
    return np.stack([np.exp(-0.5 * ((bins - centre) / 2.0) ** 2) for centre in (6, 9, 12)])


def failing(message: str):
    raise ValueError(message)


def warning(message: str):
    warnings.warn(message, UserWarning, stacklevel=1)
    return transient_figure(sampling(), transient(), title="warned")


def sized(payload):
    """A small figure that depends on a large argument (its mean in the title)."""
    return transient_figure(sampling(), transient(), title=f"mean {np.mean(payload):g}")
