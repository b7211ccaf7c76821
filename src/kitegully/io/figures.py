"""Figure helpers: a consistent publication style and print-resolution PNG output."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

if TYPE_CHECKING:
    from typing import Any

    from matplotlib.figure import Figure

PRINT_DPI = 300

STYLE = {
    "figure.dpi": 100,
    "savefig.dpi": PRINT_DPI,
    "font.size": 9,
    "axes.titlesize": 10,
    "axes.labelsize": 9,
    "legend.fontsize": 8,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "savefig.bbox": "tight",
}


def new_figure(*args: Any, **kwargs: Any) -> tuple[Figure, Any]:
    """``plt.subplots`` under the project style."""
    with plt.rc_context(STYLE):
        return plt.subplots(*args, **kwargs)


def map_axes(ax: Any, extent: tuple[float, float, float, float] | None = None) -> None:
    """Axes of a map in projected coordinates: easting and northing in metres, written in full, one metre per metre.

    Matplotlib's default writes UTM northings as an offset (``+4.081e6``) that a reader has to add
    back; every map of the project uses this instead.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The map's axes.
    extent : (xmin, xmax, ymin, ymax) or None
        Limits of the axes (m); None keeps what the plotted data set.
    """
    ax.set_xlabel("easting (m)")
    ax.set_ylabel("northing (m)")
    if extent is not None:
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.set_aspect("equal")


def save_figure(fig: Figure, path: str | Path, attribution: str | None = None) -> None:
    """Save ``fig`` as PNG at print resolution and close it; add an attribution line if given.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure to save.
    path : str or Path
        Output PNG file; its folder is created.
    attribution : str or None
        Small grey line written below the figure, at the right.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with plt.rc_context(STYLE):
        if attribution:
            # hung below what the figure draws, at its right edge: the tight bounding box grows to
            # include it, so it never overlaps axis labels, and a map whose equal aspect leaves the
            # figure's lower part empty gets no blank band above the line
            fig.draw_without_rendering()
            drawn = fig.get_tightbbox()  # inches
            w, h = fig.get_size_inches()
            fig.text(drawn.x1 / w, drawn.y0 / h, attribution, ha="right", va="top", fontsize=6, color="0.35")
        fig.savefig(path, dpi=PRINT_DPI)
    plt.close(fig)
