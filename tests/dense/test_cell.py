"""dense.cell_m: auto = 2 x the GSD measured on the model, rounded; explicit numbers unchanged."""

from __future__ import annotations

import logging

import numpy as np
import pytest

import dense_synthetic as ds
from kitegully import InputError
from kitegully.config import load_schema
from kitegully.dense.cell import choose_cell, measured_gsd, round_cell
from kitegully.dense.views import ViewSet


def _block(height_m: float, f_px: float, n_points: int = 400) -> ViewSet:
    """Nadir strip at ``height_m`` above a ground at z = 100 with ±2 m relief."""
    rng = np.random.default_rng(5)
    views = [ds.nadir_view(f"v{k}", (k * 0.2 * height_m, 0.0, 100.0 + height_m), f=f_px, width=4000, height=3000)
             for k in range(5)]
    xy = rng.uniform([-0.5 * height_m, -0.5 * height_m], [1.3 * height_m, 0.5 * height_m], (n_points, 2))
    z = 100.0 + rng.uniform(-2, 2, n_points)
    return ViewSet(views, np.zeros(3), np.column_stack([xy, z]))


@pytest.mark.parametrize("height_m, f_px, gsd", [(100.0, 10000.0, 0.01), (120.0, 600.0, 0.2), (150.0, 4000.0, 0.0375)])
def test_measured_gsd_is_flying_height_over_focal_length(height_m, f_px, gsd):
    assert measured_gsd(_block(height_m, f_px)) == pytest.approx(gsd, rel=0.01)


@pytest.mark.parametrize("x, cell", [(0.54, 0.5), (0.02, 0.02), (0.4, 0.4), (0.075, 0.08), (0.046, 0.05), (2.6, 3.0), (0.15, 0.2)])
def test_round_cell_keeps_one_significant_digit(x, cell):
    assert round_cell(x) == cell


def test_auto_cell_for_1_cm_and_20_cm_photos(caplog):
    with caplog.at_level(logging.INFO, logger="kitegully.dense.cell"):
        fine = choose_cell("auto", _block(100.0, 10000.0), window_half_cells=2)
        coarse = choose_cell("auto", _block(120.0, 600.0), window_half_cells=2)
    assert (fine.cell_m, coarse.cell_m) == (0.02, 0.4)
    assert fine.auto and fine.window_m == pytest.approx(0.1) and coarse.window_m == pytest.approx(2.0)
    assert fine.window_px == pytest.approx(10.0, rel=0.02) and coarse.window_px == pytest.approx(10.0, rel=0.02)
    assert "dense.cell_m auto: measured GSD 0.0100 m" in caplog.text and "-> cell 0.02 m" in caplog.text


def test_explicit_cell_is_used_unchanged():
    c = choose_cell(0.5, _block(120.0, 600.0), window_half_cells=2)
    assert c.cell_m == 0.5 and not c.auto and c.gsd_m == pytest.approx(0.2, rel=0.01)
    few = ViewSet(_block(120.0, 600.0).images, np.zeros(3), np.zeros((0, 3)))
    c = choose_cell(0.25, few, window_half_cells=2)  # no tie points: explicit cell still works
    assert c.cell_m == 0.25 and np.isnan(c.gsd_m)
    with pytest.raises(InputError, match="dense.cell_m is auto but the model has 0 tie points"):
        choose_cell("auto", few, window_half_cells=2)


def test_dense_params_take_a_number_or_auto():
    import copy

    from kitegully.config import load_yaml
    from kitegully.dense import DenseParams
    from snakemake_utils import REPO

    dense = load_yaml(REPO / "config/sites/tiny_twin.yaml")["dense"]
    for ok in ("auto", 0.2):
        assert DenseParams.from_config({**copy.deepcopy(dense), "cell_m": ok}).cell_m == ok
    for bad, msg in (("Auto", "must be a number of metres or 'auto'"), (0, "must be positive")):
        with pytest.raises(InputError, match=f"dense.cell_m: {msg}"):
            DenseParams.from_config({**copy.deepcopy(dense), "cell_m": bad})


def test_schema_takes_a_number_or_auto():
    import jsonschema

    sub = load_schema()["properties"]["dense"]["properties"]["cell_m"]
    for ok in (0.2, "auto"):
        jsonschema.validate(ok, sub)
    for bad in (0, -1, "Auto", None):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, sub)
