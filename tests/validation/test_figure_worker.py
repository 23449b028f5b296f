"""validation.plots.worker: a figure drawn in a second process is the figure drawn here, byte for byte,
and anything but a clean drawing (an error, a warning, a dead worker, one core) is drawn here instead."""

import sys

import pytest
from plot_builds import failing, sampling, sized, transient, warning

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


def test_a_worker_starts_only_with_an_idle_core_and_matplotlib_not_yet_imported(monkeypatch, tmp_path):
    _here(tmp_path, sampling(), transient())             # matplotlib imported here: nothing to overlap
    monkeypatch.setattr(worker_module, "_idle_core", lambda: True)
    with FigureWorker() as drawer:
        assert drawer._process is None
    monkeypatch.delitem(sys.modules, "matplotlib")
    with FigureWorker() as drawer:
        assert drawer._process is not None                # a command's start on an idle machine
    monkeypatch.setattr(worker_module, "_idle_core", lambda: False)
    with FigureWorker() as drawer:                        # no idle core: drawn here
        assert drawer._process is None
        drawer.draw(transient_figure, sampling(), transient())
        drawer.save(tmp_path / "busy.png")
    assert (tmp_path / "busy.png").read_bytes() == _here(tmp_path, sampling(), transient())


def test_idle_core_counts_the_others_running(monkeypatch):
    assert worker_module._others_running() >= 0          # this process is not counted
    monkeypatch.setattr(worker_module, "_cores", lambda: 2)
    monkeypatch.setattr(worker_module, "_others_running", lambda: 0)
    assert worker_module._idle_core()
    monkeypatch.setattr(worker_module, "_others_running", lambda: 1)
    assert not worker_module._idle_core()
    monkeypatch.setattr(worker_module, "_cores", lambda: 1)
    monkeypatch.setattr(worker_module, "_others_running", lambda: 0)
    assert not worker_module._idle_core()


def test_stray_output_on_the_workers_pipe_is_not_taken_for_a_figure(tmp_path):
    with FigureWorker(start=True) as drawer:
        drawer._process.stdout = _Prefixed(b"a line some start-up code printed\n", drawer._process.stdout)
        drawer.draw(transient_figure, sampling(), transient())
        png = drawer.png()
        assert drawer.drawn_there == 0 and drawer._process is None
    assert png == _here(tmp_path, sampling(), transient())


class _Prefixed:
    """A stream that reads ``prefix`` before the wrapped one."""

    def __init__(self, prefix: bytes, stream):
        self.prefix, self.stream = prefix, stream

    def read(self, size: int) -> bytes:
        head, self.prefix = self.prefix[:size], self.prefix[size:]
        return head + (self.stream.read(size - len(head)) if size > len(head) else b"")

    def close(self) -> None:
        self.stream.close()


def test_leaving_the_block_ends_the_worker():
    with FigureWorker(start=True) as drawer:
        process = drawer._process
        assert process is not None and process.poll() is None
    assert process.poll() is not None


def test_queued_requests_larger_than_a_pipe_come_back_in_order(tmp_path):
    import numpy as np

    payloads = [np.full(100_000, float(seed)) for seed in range(3)]        # 800 KB each, a pipe holds 64 KB
    with FigureWorker(start=True) as drawer:
        for payload in payloads:
            drawer.draw(sized, payload)
        drawn = [drawer.png() for _ in payloads]
        assert drawer.drawn_there == 3
    assert drawn == [save_figure(sized(payload), tmp_path / "here.png").read_bytes() for payload in payloads]
    assert len(set(drawn)) == 3


def test_leaving_with_figures_not_taken_stops_the_worker_at_once():
    with FigureWorker(start=True) as drawer:
        process = drawer._process
        drawer.draw(transient_figure, sampling(), transient())
        drawer.draw(transient_figure, sampling(), 2 * transient())
    assert process.poll() is not None


def test_the_worker_imports_this_process_code_not_the_working_directorys(tmp_path, monkeypatch):
    shadow = tmp_path / "validation"
    shadow.mkdir()
    (shadow / "__init__.py").write_text("raise ImportError('a copy of the package in the working directory')\n")
    monkeypatch.chdir(tmp_path)
    with FigureWorker(start=True) as drawer:
        drawer.draw(transient_figure, sampling(), transient())
        drawer.png()
        assert drawer.drawn_there == 1
