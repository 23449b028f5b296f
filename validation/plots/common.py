"""What every figure shares: a Figure on the Agg canvas, one way to save it, a user's text drawn as it is.

Every plotting function of :mod:`validation.plots` returns a
:class:`matplotlib.figure.Figure` built by :func:`new_figure` (never
through pyplot's global state), with its resolution set; the caller writes
it with :func:`save_figure`, atomically. matplotlib is imported inside
the functions, so that importing this package costs nothing.

Figures draw without warnings, whatever the data and the scene's name: a
user's text (a scene's name in a title) is drawn as it is, never as
mathtext, with characters the font lacks as U+FFFD.
"""

from __future__ import annotations

import contextlib
import functools
import io
import logging
from pathlib import Path

from analytic.files import atomic_write

__all__ = ["new_figure", "save_figure", "figure_png", "save_png", "plain_text", "suptitle", "columns_for_legend", "NANOSECONDS_PER_METRE",
           "Y_LABEL"]

#: Light travels 1 m of path in 3.3356 ns.
NANOSECONDS_PER_METRE = 1e9 / 299_792_458.0
#: y's units for a source intensity in W/sr (docs/design.md section 1; the README explains them).
Y_LABEL = "y_k[n] (W m⁻¹)"


@contextlib.contextmanager
def _quiet_first_import():
    """matplotlib's first import without its notices about an unusable config folder.

    With ``HOME`` or ``MPLCONFIGDIR`` unwritable it falls back to a temporary
    folder (which works) and logs two lines through a logger with no handler,
    so logging's last resort prints them on stderr: a page of advice about a
    cache that changes no number. Only those imports are quietened.
    """
    logger = logging.getLogger("matplotlib")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def new_figure(width: float, height: float, layout: str | None = "constrained", dpi: int = 110):
    """A Figure on an Agg canvas (no pyplot state), constrained layout unless ``layout=None``.

    Parameters
    ----------
    width, height : float
        Inches.
    layout : str or None
        matplotlib's layout engine; None for a layout the caller fixes.
    dpi : int
        Dots per inch of the PNG :func:`save_figure` writes.
    """
    with _quiet_first_import():
        from matplotlib import font_manager  # noqa: F401 (the import that looks for the cache folder)
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), layout=layout, dpi=dpi)
    FigureCanvasAgg(figure)
    return figure


def figure_png(figure) -> bytes:
    """A figure as PNG at its own resolution (``figure.dpi``): the bytes :func:`save_figure` writes."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=figure.dpi)
    return buffer.getvalue()


def save_png(png: bytes, path: str | Path) -> Path:
    """Write PNG bytes (:func:`figure_png`'s, here or from :mod:`.worker`) atomically."""
    return atomic_write(path, lambda temporary: Path(temporary).write_bytes(png))


def save_figure(figure, path: str | Path) -> Path:
    """Write a figure as PNG at its own resolution (``figure.dpi``), atomically."""
    return save_png(figure_png(figure), path)


@functools.lru_cache(maxsize=1)
def _font_characters() -> frozenset:
    """Code points the default font can draw."""
    with _quiet_first_import():
        from matplotlib import font_manager

    font = font_manager.get_font(font_manager.findfont(font_manager.FontProperties()))
    return frozenset(font.get_charmap())


def plain_text(text: str) -> str:
    """Text from a user (a scene's name) with every character the default font lacks as U+FFFD.

    Such a character would draw as an empty box and make matplotlib warn.
    Draw the result with ``parse_math=False`` (:func:`suptitle`): a ``$``
    would otherwise start mathtext, where ``a$\\frac$b`` is an error, not a
    title.
    """
    drawable = _font_characters()
    return "".join(c if c == "\n" or ord(c) in drawable else "\ufffd" for c in text)


def suptitle(figure, text: str, **options) -> None:
    """A figure title that may hold a user's text, drawn as it is (:func:`plain_text`)."""
    figure.suptitle(plain_text(text), parse_math=False, **options)


def columns_for_legend(names: list[str], width: float) -> int:
    """Most legend columns whose widest row of 8-point entries fits ``width`` inches."""
    entries = [0.06 * len(name) + 0.75 for name in names]     # 8-point text and its handle, inches
    for columns in range(len(names), 1, -1):
        if sum(sorted(entries, reverse=True)[:columns]) <= 0.95 * width:
            return columns
    return 1
