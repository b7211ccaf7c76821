"""The OBIA bare-soil maps of the low-cost mosaics, by NDVI and by ExG."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.io.raster import GridSpec, read_raster, write_raster
from kitegully.lowcost import BareSoilParams, map_bare_soil


def _obia_cfg():
    return {"features": {"slope_window_cells": 5}, "seeds": {"bandwidth_cells": 15},
            "growing": {"position_weight": 0.0, "reference": "mean"}, "exg_blur": {"sigma_cells": 1.0, "radius_cells": 2},
            "threshold": {"bins": 256, "min_class_fraction": 0.01, "max_valley_ratio": 0.9, "unimodal_class": "grass"},
            "classification": {"segment_feature": "blurred", "min_area_m2": 0.0, "index": "ndvi", "water_ndvi_below": 0.0}}


def test_bare_soil_params_check_the_tile_size():
    p = BareSoilParams.from_config({"tile_cells": 1024, "min_reflectance": 0.01, "obia": _obia_cfg()})
    assert p.obia.index == "ndvi" and p.tile_cells == 1024 and p.min_reflectance == 0.01
    with pytest.raises(InputError, match=r"lowcost.bare_soil.tile_cells: must be at least 4 seed band widths \(60 cells\)"):
        BareSoilParams.from_config({"tile_cells": 40, "min_reflectance": 0.01, "obia": _obia_cfg()})
    with pytest.raises(InputError, match=r"lowcost.bare_soil.min_reflectance: must lie in \[0, 1\), got 1.5"):
        BareSoilParams.from_config({"tile_cells": 1024, "min_reflectance": 1.5, "obia": _obia_cfg()})


def test_map_bare_soil_masks_unlit_cells_and_maps_by_both_indices(tmp_path):
    n = 120
    grid = GridSpec(290000.0, 6115000.0, 0.02, n, n, "EPSG:32756")
    rows, cols = np.mgrid[0:n, 0:n]
    plants = (rows - 60) ** 2 + (cols - 50) ** 2 <= 30 ** 2
    rng = np.random.default_rng(0)
    rgbn = np.where(plants[None], np.array([0.05, 0.12, 0.04, 0.45])[:, None, None],
                    np.array([0.21, 0.19, 0.17, 0.23])[:, None, None]) * (1 + rng.normal(0, 0.1, (4, n, n)))
    rgbn[:, :10] = 1e-4                                                   # beyond the imaged ground: black
    write_raster(tmp_path / "rgb.tif", rgbn[:3].astype(np.float32), grid)
    write_raster(tmp_path / "nir.tif", rgbn[3:].astype(np.float32), grid)
    write_raster(tmp_path / "dsm.tif", np.ones((n, n), np.float32), grid)
    cfg = {"tile_cells": n, "min_reflectance": 0.01, "obia": _obia_cfg()}
    t = map_bare_soil(tmp_path / "rgb.tif", tmp_path / "nir.tif", tmp_path / "dsm.tif", cfg, tmp_path / "out").set_index("index")
    assert list(t.index) == ["ndvi", "exg"] and (t["dark_cells"] == 10 * n).all()
    assert t.loc["ndvi", "bimodal"] and t.loc["exg", "bimodal"]
    for name in ("ndvi", "exg"):
        m, _ = read_raster(tmp_path / "out" / f"bare_soil_{name}.tif")
        assert np.all(m[:10] == 255)
        inner = ~plants & (rows >= 30) | (plants & ((rows - 60) ** 2 + (cols - 50) ** 2 <= 12 ** 2))
        assert np.mean(m[inner] == np.where(plants, 0, 1)[inner]) > 0.97
    assert not list((tmp_path / "out").glob("tmp*"))                       # the masked mosaic is not left behind
