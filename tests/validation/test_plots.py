"""Figures: axes that need no offset text, whatever the window's position and the data's scale."""

import numpy as np
import pytest

from analytic.scene import Sampling
from validation.plots import _power_of_ten, _round_origin, plot_transients, plot_z_map


@pytest.mark.parametrize("start, span, origin", [(1.9, 1.2, 0.0), (0.0, 4.0, 0.0), (800.0001, 0.0014, 800.0),
                                                 (-50.25, 0.01, None)])
def test_a_window_far_from_zero_is_drawn_from_a_round_origin(start, span, origin):
    found = _round_origin(np.array([start, start + span]))
    if origin is not None:
        assert found == pytest.approx(origin, abs=1e-12)
    if origin != 0:
        assert 0 <= start - found < 10 * span     # the ticks then read like the span itself


@pytest.mark.parametrize("peak, power", [(409.0, 0), (0.04, 0), (1.2e-14, -14), (3e7, 7), (0.0, 0)])
def test_y_outside_the_readable_range_gets_a_named_power_of_ten(peak, power):
    assert _power_of_ten(np.array([0.0, peak])) == power


def test_a_far_tiny_transient_is_drawn(tmp_path):
    sampling = Sampling(bin_width_opl=1e-6, start_opl=800.0001, count=50)
    y = 1e-14 * np.exp(-np.arange(50) / 10.0)[None, :]
    plot_transients(tmp_path / "t.png", sampling, {"model": y, "render": y * 1.01},
                    errors={"render": np.full_like(y, 1e-16)})
    plot_z_map(tmp_path / "z.png", np.zeros((1, 50)), 4.0, sampling, "z")
    assert (tmp_path / "t.png").stat().st_size > 0 and (tmp_path / "z.png").stat().st_size > 0
