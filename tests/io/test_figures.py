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


def test_attribution_sits_under_a_map_that_leaves_the_figure_bottom_empty(tmp_path):
    # a wide map in a tall figure: equal aspect leaves the lower half of the figure empty
    heights = {}
    for name, text in (("plain", None), ("attributed", "Photos CC-BY 3.0 somebody")):
        fig, ax = new_figure(figsize=(4, 8))
        ax.plot([0.0, 600.0], [0.0, 100.0])
        map_axes(ax, (0.0, 600.0, 0.0, 100.0))
        save_figure(fig, tmp_path / f"{name}.png", text)
        with Image.open(tmp_path / f"{name}.png") as im:
            heights[name] = im.size[1]
            if text:
                rows = np.asarray(im.convert("L"))
    extra = heights["attributed"] - heights["plain"]
    assert 0 < extra < 0.15 * PRINT_DPI  # one 6 pt line, not the empty half of an 8 in figure
    ink = np.flatnonzero((rows < 250).any(axis=1))
    assert ink[-1] >= rows.shape[0] - 0.15 * PRINT_DPI  # the line is at the bottom of the image (0.1 in pad)

