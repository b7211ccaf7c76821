#!/usr/bin/env python
"""Colour features of each true land-cover class in an ensemble member's orthophoto (evaluation only).

Per class (the twin's land cover, nearest-resampled onto every second orthophoto cell):
share of the site, unblurred ExG (10th/50th/90th percentile), hue (degrees, same
percentiles), median HSV saturation, median brightness (mean of R, G, B in DN), median
(G - B)/(R + G + B) and (R - G)/(R + G + B), and the share mapped as bare by a bare-soil map.
This is the measurement behind the README's "why" of the kite-scale bare-soil errors
(issue 15). Reads the truth: never part of the pipeline.

Usage::

    .venv/bin/python benchmarks/obia_class_features.py --root /work/wt/ensrun/results kamech_twin ens2 ens3 \\
        [--map-dir results/benchmarks/obia_ensemble]   # default: each member's stored obia/kite/bare_soil.tif
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", required=True)
    ap.add_argument("--map-dir", default=None, help="folder with <site>/bare_soil.tif (else <root>/<site>/obia/kite)")
    ap.add_argument("sites", nargs="+")
    args = ap.parse_args()
    for site in args.sites:
        base = Path(args.root) / site
        with rasterio.open(base / "dense" / "orthophoto.tif") as s:
            shape = (s.height // 2, s.width // 2)
            rgb = s.read([1, 2, 3], out_shape=(3, *shape), resampling=Resampling.nearest).astype(np.float32)
            tr, crs = s.transform * s.transform.scale(2, 2), s.crs
        lc = np.full(shape, 255, np.uint8)
        with rasterio.open(base / "twin" / "truth" / "landcover.tif") as s:
            reproject(rasterio.band(s, 1), lc, dst_transform=tr, dst_crs=crs, resampling=Resampling.nearest)
        bare_path = (Path(args.map_dir) / site if args.map_dir else base / "obia" / "kite") / "bare_soil.tif"
        with rasterio.open(bare_path) as s:
            bare = s.read(1, out_shape=shape, resampling=Resampling.nearest)
        r, g, b = rgb
        total = r + g + b
        ok = total > 0
        with np.errstate(invalid="ignore", divide="ignore"):
            exg = (2 * g - r - b) / total
            mx, mn = rgb.max(0), rgb.min(0)
            sat = np.where(mx > 0, (mx - mn) / np.maximum(mx, 1), 0.0)
            d = np.maximum(mx - mn, 1e-6)
            hue = np.where(mx == r, ((g - b) / d) % 6, np.where(mx == g, (b - r) / d + 2, (r - g) / d + 4)) * 60
            yb = (g - b) / total
            rg = (r - g) / total
        classes = pd.read_csv(base / "twin" / "truth" / "landcover_classes.csv")
        rows = []
        for code, name in zip(classes["code"], classes["name"]):
            k = (lc == code) & ok
            if not k.any():
                continue
            pe = np.nanpercentile(exg[k], [10, 50, 90])
            ph = np.nanpercentile(hue[k], [10, 50, 90])
            rows.append({"class": name, "share_pct": 100 * k.mean(), "exg_p10": pe[0], "exg_p50": pe[1], "exg_p90": pe[2],
                         "hue_p10_deg": ph[0], "hue_p50_deg": ph[1], "hue_p90_deg": ph[2], "saturation_p50": np.median(sat[k]),
                         "brightness_p50_dn": np.median(total[k]) / 3, "g_minus_b_p50": np.nanmedian(yb[k]),
                         "r_minus_g_p50": np.nanmedian(rg[k]), "mapped_bare_pct": 100 * np.mean(bare[k] == 1)})
        print(f"== {site}")
        print(pd.DataFrame(rows).to_string(index=False, float_format=lambda v: f"{v:.3f}"), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
