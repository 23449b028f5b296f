"""validation.plots.worker: a figure drawn in a second process is the figure drawn here, byte for byte,
and anything but a clean drawing (an error, a warning, a dead worker, one core) is drawn here instead."""

import sys

import pytest
from plot_builds import failing, sampling, transient, warning

from validation.plots import save_figure, transient_figure
from validation.plots import worker as worker_module
from validation.plots.worker import FigureWorker


def _here(tmp_path, *args, **kwargs) -> bytes:
    return save_figure(transient_figure(*args, **kwargs), tmp_path / "here.png").read_bytes()


def test_the_worker_draws_the_same_bytes_as_this_process(tmp_path):
    with FigureWorker(start=True) as drawer:
        drawer.draw(transient_figure, sampling(), transient(), title="a test's title, ünïcode")
        drawer.save(tmp_path / "there.png")
        assert drawer.drawn_there == 1
        drawer.draw(transient_figure, sampling(), 2 * transient(), label="render")   # the worker serves on
        second = drawer.png()
        assert drawer.drawn_there == 2
    assert (tmp_path / "there.png").read_bytes() == _here(tmp_path, sampling(), transient(),
                                                          title="a test's title, ünïcode")
    assert second == _here(tmp_path, sampling(), 2 * transient(), label="render")
    assert second != (tmp_path / "there.png").read_bytes()


def test_an_error_in_the_figure_is_raised_here_as_itself():
    with FigureWorker(start=True) as drawer:
        drawer.draw(failing, "no such figure")
        with pytest.raises(ValueError, match="no such figure"):
            drawer.png()
        assert drawer.drawn_there == 0


def test_a_warning_while_drawing_is_warned_here(tmp_path):
    with FigureWorker(start=True) as drawer:
        drawer.draw(warning, "a notice from the figure")
        with pytest.warns(UserWarning, match="a notice from the figure"):
            png = drawer.png()
        assert drawer.drawn_there == 0
    assert png == _here(tmp_path, sampling(), transient(), title="warned")


def test_a_dead_worker_is_replaced_by_drawing_here(tmp_path):
    with FigureWorker(start=True) as drawer:
        drawer._process.kill()
        drawer._process.wait()
        drawer.draw(transient_figure, sampling(), transient())
        png = drawer.png()
        assert drawer.drawn_there == 0 and drawer._process is None
    assert png == _here(tmp_path, sampling(), transient())


def test_one_core_or_matplotlib_already_here_draws_here_without_a_worker(monkeypatch, tmp_path):
    _here(tmp_path, sampling(), transient())             # matplotlib imported here: nothing to overlap
    with FigureWorker() as drawer:
        assert drawer._process is None
    monkeypatch.delitem(sys.modules, "matplotlib.figure")
    monkeypatch.setattr(worker_module, "_cores", lambda: 2)
    with FigureWorker() as drawer:
        assert drawer._process is not None                # a command's start: matplotlib not yet imported
    monkeypatch.setattr(worker_module, "_cores", lambda: 1)
    with FigureWorker() as drawer:
        assert drawer._process is None
        drawer.draw(transient_figure, sampling(), transient())
        drawer.save(tmp_path / "one.png")
    assert (tmp_path / "one.png").read_bytes() == _here(tmp_path, sampling(), transient())


def test_leaving_the_block_ends_the_worker():
    with FigureWorker(start=True) as drawer:
        process = drawer._process
        assert process is not None and process.poll() is None
    assert process.poll() is not None


def test_queued_figures_larger_than_a_pipe_come_back_in_order(tmp_path):
    import numpy as np

    from analytic.scene import Sampling

    wide = Sampling(bin_width_opl=0.001, start_opl=2.0, count=1100)
    big = [np.random.default_rng(seed).random((8, 1100)) for seed in range(3)]       # 70 KB each, over a pipe's 64 KB
    with FigureWorker(start=True) as drawer:
        for y in big:
            drawer.draw(transient_figure, wide, y)
        drawn = [drawer.png() for _ in big]
        assert drawer.drawn_there == 3
    assert drawn == [_here(tmp_path, wide, y) for y in big]


def test_leaving_with_figures_not_taken_stops_the_worker_at_once():
    with FigureWorker(start=True) as drawer:
        process = drawer._process
        drawer.draw(transient_figure, sampling(), transient())
        drawer.draw(transient_figure, sampling(), 2 * transient())
    assert process.poll() is not None
