"""The gully map's products on disk (kitegully.gully.products.write_map_products), on the ``mapped`` V gully of conftest."""

from __future__ import annotations

from dataclasses import replace

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import rasterio

from kitegully.gully.network import GullyNetwork
from kitegully.gully.products import write_map_products


def _paths(folder, digitised):
    names = {"gully_map": "gully_map.tif", "gully_map_whole": "whole.tif", "network": "network.gpkg",
             "mapped_network": "mapped.gpkg", "polygons": "polygons.gpkg", "network_cells": "cells.npz",
             "patches": "patches.csv"}
    if digitised:
        names["mapped_network_digitised"] = "mapped_digitised.gpkg"
    return {k: str(folder / v) for k, v in names.items()}


@pytest.mark.parametrize("digitised", [False, True])
def test_every_product_is_written_and_reads_back_as_the_run(mapped, tmp_path, digitised):
    grid, z, _, res = mapped
    if digitised:  # as gully.heads: both keeps it; here the same lines stand in for it
        res = replace(res, given_extracted_lines=res.extracted_lines)
    paths = _paths(tmp_path, digitised)
    write_map_products(res, np.isfinite(z), grid, paths)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.split("/")[-1] for p in paths.values())
    with rasterio.open(paths["gully_map"]) as src:
        m = src.read(1)
        assert src.nodata == 255 and src.transform == grid.transform
    assert np.array_equal(m == 1, res.gully & np.isfinite(z)) and np.all(m[~np.isfinite(z)] == 255)
    assert len(gpd.read_file(paths["mapped_network"])) == len(res.extracted_lines)
    assert len(gpd.read_file(paths["polygons"])) == len(res.polygons)
    assert len(pd.read_csv(paths["patches"])) == len(res.patch_table)
    assert GullyNetwork.load(paths["network_cells"]).n_segments == res.network.n_segments
