#!/usr/bin/env python
"""Why are shrub cells mapped as bare on the low-sun twins? Shading against cover edges (evaluation only).

For one ensemble member: the bare-soil map (``--map``, on the orthophoto grid), the twin's
land cover and truth DSM (``<root>/<site>/twin/truth``) and the member's sun position
(``twin.texture.illumination``). Shrub and tree cells are grouped by the relative
illumination the twin's texture gives them (cos incidence / sin sun elevation on the
truth DSM, :func:`kitegully.twin.texture.hillshade`) and by their distance to the nearest
bare land-cover cell; the share mapped as bare is printed per group. Reads the truth:
an evaluation script, never part of the pipeline.

Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/obia_shrub_errors.py --root /work/wt/ensrun/results \\
        --member ens3 --map results/benchmarks/obia_ensemble/ens3/bare_soil.tif
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import rasterio
from rasterio.enums import Resampling
from rasterio.warp import reproject
from scipy import ndimage

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
sys.path.insert(0, str(REPO / "benchmarks"))

from obia_ensemble import _site, member_config  # noqa: E402

from kitegully.twin.texture import hillshade  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", required=True)
    ap.add_argument("--member", required=True)
    ap.add_argument("--map", required=True, help="bare-soil map (uint8, 1 = bare)")
    args = ap.parse_args()
    cfg = member_config(args.member)
    truth = Path(args.root) / _site(args.member, cfg) / "twin" / "truth"
    ill = cfg["twin"]["texture"]["illumination"]
    classes = pd.read_csv(truth / "landcover_classes.csv")
    code = dict(zip(classes["name"], classes["code"]))
    with rasterio.open(truth / "landcover.tif") as src:
        lc = src.read(1)
        tr, crs, cell = src.transform, src.crs, src.res[0]
    with rasterio.open(truth / "dsm.tif") as src:
        z = src.read(1).astype(np.float64)
    hs = hillshade(np.pad(z, 1, mode="edge"), cell, ill["sun_azimuth_deg"], ill["sun_elevation_deg"])[1:-1, 1:-1]
    light = np.clip(1.0 + ill["shading_strength"] * (hs - 1.0), ill["min_light"], None)
    bare = np.zeros(lc.shape, np.uint8)
    with rasterio.open(args.map) as src:
        reproject(rasterio.band(src, 1), bare, dst_transform=tr, dst_crs=crs, resampling=Resampling.mode)
    bare_cover = np.isin(lc, [code[n] for n in cfg["obia"]["kite_scale"]["bare_landcover_classes"]])
    dist = ndimage.distance_transform_edt(~bare_cover) * cell
    woody = np.isin(lc, [code["shrub"], code["tree"]]) & (bare != 255)
    rows = []
    for lo, hi in ((0.0, 0.3), (0.3, 0.6), (0.6, 0.9), (0.9, 1.1), (1.1, 9.0)):
        for dlo, dhi in ((0.0, 0.5), (0.5, 1.0), (1.0, 99.0)):
            k = woody & (light >= lo) & (light < hi) & (dist > dlo) & (dist <= dhi)
            if k.sum():
                rows.append({"light_from": lo, "light_to": hi, "dist_bare_from_m": dlo, "dist_bare_to_m": dhi,
                             "woody_cells": int(k.sum()), "share_of_woody_pct": 100 * k.sum() / woody.sum(),
                             "mapped_bare_pct": 100 * float(np.mean(bare[k] == 1))})
    df = pd.DataFrame(rows)
    print(f"{args.member}: sun elevation {ill['sun_elevation_deg']} deg; woody cells mapped bare "
          f"{100 * np.mean(bare[woody] == 1):.1f} %")
    print(df.to_string(index=False, float_format=lambda v: f"{v:.1f}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
