"""The stereo twin's laboratory: box, frame marks, nails, survey and the per-cell reference."""

import numpy as np
import pytest

from kitegully.stereo.lab import BOX, box_grid, cell_truth, frame_marks, nail_positions, relief, survey_marks


def test_frame_marks_ring_the_box_outside_the_soil():
    m = frame_marks()
    x0, y0, x1, y1 = BOX
    assert m.shape == (10, 3) and np.allclose(m[:, 2], 0.01)
    inside = (m[:, 0] > x0) & (m[:, 0] < x1) & (m[:, 1] > y0) & (m[:, 1] < y1)
    assert not inside.any()  # every mark on the frame, none on the soil
    assert len({tuple(p) for p in np.round(m, 6)}) == 10


def test_nails_lie_inside_the_box():
    xy = nail_positions(np.random.default_rng(0))
    x0, y0, x1, y1 = BOX
    assert xy.shape == (20, 2)
    assert ((xy[:, 0] > x0) & (xy[:, 0] < x1) & (xy[:, 1] > y0) & (xy[:, 1] < y1)).all()


def test_box_grid_covers_the_central_share_of_the_box():
    g = box_grid(0.005)
    area = g.width * g.height * g.cell ** 2
    assert area == pytest.approx(0.8 * (BOX[2] - BOX[0]) * (BOX[3] - BOX[1]), rel=0.03)
    x0, y0, x1, y1 = g.bounds
    assert 0.5 * (x0 + x1) == pytest.approx(0.0, abs=1e-12) and 0.5 * (y0 + y1) == pytest.approx(0.0, abs=1e-12)


def test_cell_truth_is_the_cell_mean():
    g = box_grid(0.01)
    X, Y = np.meshgrid(*g.cell_centres())
    plane = cell_truth(lambda x, y: 0.1 * x - 0.2 * y, g)
    assert np.allclose(plane, 0.1 * X - 0.2 * Y)  # a plane's cell mean is its value at the centre
    # a sine of one cell's wavelength averages to ~0 over the cell (6 × 6 samples)
    flat = cell_truth(lambda x, y: np.sin(2 * np.pi * x / g.cell), g)
    assert np.abs(flat).max() < 1e-9
    assert np.abs(relief(X, Y)).max() <= 0.006


def test_survey_marks_scatter_by_the_stated_accuracy():
    m = np.zeros((20000, 3))
    s = survey_marks(m, np.random.default_rng(3), {"mark_sigma_mm": 0.1})
    assert s.std() == pytest.approx(1e-4, rel=0.02) and abs(s.mean()) < 3e-6
