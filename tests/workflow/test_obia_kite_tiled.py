"""Issue 21: the kite-scale OBIA map as tile jobs on the tiny twin equals the untiled rule's map.

The dense stage's orthophoto and DSM are fabricated (the synthetic site of
tests/obia/test_kite.py, 240 x 240 cells), mapped in blocks of 64 cells (the schema minimum)
by the tiled site (tests/workflow/tiny_twin_tiled.yaml: 2 x 2 tiles) with 4
``obia_kite_histogram`` + 4 ``obia_kite_tile`` jobs and ``obia_kite_merge``; the reference is
the untiled rule's library call (``bare_soil_map``) with the same parameters (one Snakemake
run, not two: the file stays near a minute on the loaded 2-core machine).
"""

from __future__ import annotations

import json

import geopandas as gpd
import numpy as np
import pytest
import yaml

from kitegully.io.raster import read_raster, write_raster
from obia.test_kite import _site
from snakemake_utils import REPO, run_snakemake

SITE = REPO / "config" / "sites" / "tiny_twin.yaml"
TILED = REPO / "tests" / "workflow" / "tiny_twin_tiled.yaml"


def _params():
    from kitegully.config import load_yaml
    from kitegully.obia.scene import ObiaParams
    from kitegully.obia.stage import METHOD_KEYS

    cfg = load_yaml(SITE)["obia"]
    return ObiaParams.from_config({k: cfg[k] for k in METHOD_KEYS})


def _run(results, blocks_yaml, tiled):
    root = results / "tiny_twin"
    grid, rgb, dsm, _ = _site(seed=11)
    write_raster(root / "dense" / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(root / "dense" / "dsm.tif", dsm, grid)
    out = root / "obia" / "kite"
    files = [str(SITE), *([str(TILED)] if tiled else []), str(blocks_yaml)]
    rules = ["obia_kite_histogram", "obia_kite_tile", "obia_kite_merge"] if tiled else ["obia_kite_scale"]
    proc = run_snakemake(SITE, results, [str(out / "bare_soil.tif"), str(out / "bare_soil.gpkg")],
                         extra=["--configfile", *files, "--allowed-rules", *rules, "--printshellcmds"], cores=2)
    return out, proc.stdout + proc.stderr


@pytest.mark.slow
def test_tiled_kite_map_equals_untiled(tmp_path):
    blocks = tmp_path / "blocks.yaml"  # both runs: blocks of 64 cells (4 x 4 on the 240-cell orthophoto)
    blocks.write_text(yaml.safe_dump({"obia": {"kite_scale": {"tile_cells": 64}}}))
    from kitegully.obia.kite import bare_soil_map

    out, log = _run(tmp_path / "tiled", blocks, tiled=True)
    ref = tmp_path / "untiled"
    dense = tmp_path / "tiled" / "tiny_twin" / "dense"
    thr = bare_soil_map(dense / "orthophoto.tif", dense / "dsm.tif", ref / "bare_soil.tif", _params(), 64)
    assert log.count("rule obia_kite_tile:") == 4 and log.count("rule obia_kite_histogram:") == 4
    assert "rule obia_kite_scale:" not in log
    a, ga = read_raster(ref / "bare_soil.tif")
    b, gb = read_raster(out / "bare_soil.tif")
    assert ga == gb and np.array_equal(a, b)  # measured: 0 of 57 600 cells differ
    assert (a == 1).any() and (a == 0).any()
    assert json.loads(json.dumps(thr.as_dict())) == json.loads((out / "threshold.json").read_text())
    pb = gpd.read_file(out / "bare_soil.gpkg")
    assert abs(pb.area.sum() - (b == 1).sum() * gb.cell**2) < 1e-6  # the polygons are the merged map's bare cells
    assert (out / "bare_soil_map.png").stat().st_size > 10_000
    assert not list((out / "tiles").glob("*.npz"))  # temp() tile files removed after the merge
