"""Figure helpers: map axes written in full, the project style, attribution inside the saved image."""

import numpy as np
from PIL import Image

from kitegully.io.figures import PRINT_DPI, map_axes, new_figure, save_figure


def test_map_axes_write_utm_coordinates_in_full():
    fig, ax = new_figure()
    ax.plot([578600.0, 579200.0], [4081200.0, 4081600.0])
    map_axes(ax, (578600.0, 579200.0, 4081200.0, 4081600.0))
    fig.canvas.draw()
    assert ax.get_xlabel() == "easting (m)" and ax.get_ylabel() == "northing (m)"
    assert ax.yaxis.get_major_formatter().get_offset() == ""           # no "+4.081e6" to add back
    assert any(t.get_text().startswith("40812") for t in ax.get_yticklabels())
    assert ax.get_aspect() == 1.0 and ax.get_xlim() == (578600.0, 579200.0)


def test_save_figure_writes_print_resolution_with_the_attribution(tmp_path):
    fig, ax = new_figure(figsize=(4, 3))
    ax.plot(np.arange(3))
    save_figure(fig, tmp_path / "a" / "f.png", "data: somebody")
    with Image.open(tmp_path / "a" / "f.png") as im:
        dpi = im.info["dpi"][0]
        height = im.size[1]
    assert round(dpi) == PRINT_DPI
    fig, ax = new_figure(figsize=(4, 3))
    ax.plot(np.arange(3))
    save_figure(fig, tmp_path / "g.png")
    with Image.open(tmp_path / "g.png") as im:
        assert im.size[1] < height                                         # the attribution line adds height below
