"""Matplotlib figures drawn by the Agg canvas, without pyplot.

Reports, signal plots and replay stills are drawn off screen. A figure made here has its own
Agg canvas, so nothing selects a global backend (``matplotlib.use``) or keeps figures in
pyplot's registry: the metrics package can be imported beside any GUI an application uses.
"""

from __future__ import annotations

from typing import Any


def new_figure(**kwargs: Any):
    """A :class:`matplotlib.figure.Figure` (``kwargs`` as its constructor takes) on an Agg canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(**kwargs)
    FigureCanvasAgg(figure)
    return figure
