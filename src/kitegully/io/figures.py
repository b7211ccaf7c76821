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
    if attribution:
        # hung below the figure edge; the tight bounding box grows to include it, so it never
        # overlaps axis labels
        fig.text(0.99, 0.0, attribution, ha="right", va="top", fontsize=6, color="0.35")
    with plt.rc_context(STYLE):
        fig.savefig(path, dpi=PRINT_DPI)
    plt.close(fig)
