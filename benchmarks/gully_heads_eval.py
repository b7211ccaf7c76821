"""Gully stage alone on a twin's truth-plus-noise stand-in: digitised vs automatic heads, area IoU.

Evaluation only (reads the twin's truth). Usage:
    python benchmarks/gully_heads_eval.py --config config/sites/kamech_twin.yaml --twin results/kamech_twin/twin \
        --heads results/kamech_twin/twin/observed/gully_heads.gpkg [--set sigma_m=6 ...] [--out table.csv]
The stand-in is the truth DTM plus correlated noise (gully.standin): NOT the photogrammetric DSM;
``--dem results/<site>/dense/dsm.tif`` maps the photogrammetric DSM instead.
"""

from __future__ import annotations

import argparse
import copy
import logging
import time

import numpy as np
import pandas as pd
import yaml

from kitegully.evaluate.gully_run import score_gully_run
from kitegully.evaluate.dem import read_checkpoints
from kitegully.gully.heads import HeadDetectionParams
from kitegully.gully.relief import dsm_noise_at_checkpoints
from kitegully.gully.inputs import read_heads
from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import map_gullies
from kitegully.gully.standin import noisy_dem
from kitegully.io.raster import read_raster
from kitegully.io.vectors import read_vector


def run(cfg: dict, twin: str, heads_path: str | None, modes=("digitised", "automatic"), dem=None, grid=None,
        mask_water: bool = False) -> list[dict]:
    """One row per head source on one DEM.

    ``mask_water`` leaves the stand-in empty over open water (truth land cover), as dense
    matching leaves the reservoir: the network then ends at the shore as on the DSM.
    """
    g = cfg["gully"]
    crs = cfg["site"]["crs"]
    if dem is None:
        dtm, grid = read_raster(f"{twin}/truth/dtm.tif")
        dem = noisy_dem(dtm, grid.cell, g["standin"]["noise_sd_m"], g["standin"]["noise_correlation_m"], cfg["seed"])
        if mask_water:
            lc, _ = read_raster(f"{twin}/truth/landcover.tif")
            classes = pd.read_csv(f"{twin}/truth/landcover_classes.csv")
            dem[np.asarray(lc) == int(classes.loc[classes["name"] == "water", "code"].iloc[0])] = np.nan
    ref = read_vector(f"{twin}/observed/field_network.gpkg", crs=crs)
    polys = read_vector(f"{twin}/truth/gully_polygons.gpkg", crs=crs)
    th = read_vector(f"{twin}/truth/gully_heads.gpkg", crs=crs)
    true_xy = np.column_stack([th.geometry.x, th.geometry.y])
    hx, hy = read_heads(heads_path or f"{twin}/observed/gully_heads.gpkg", crs)
    # the detector's noise level is that of the DEM it sees, measured at the observed checkpoints
    sz = dsm_noise_at_checkpoints(dem, grid, read_checkpoints(f"{twin}/observed/checkpoints.csv"))
    rows = []
    for mode in modes:
        t0 = time.perf_counter()
        auto = HeadDetectionParams.from_config(g["automatic_heads"], sz) if mode != "digitised" else None
        x, y = (hx, hy) if mode != "automatic" else (np.zeros(0), np.zeros(0))
        res = map_gullies(dem, grid, x, y, GullyParams.from_config(g), workers=1, auto_heads=auto)
        xs, ys = grid.cell_centres()
        if mode == "automatic":
            r, c = np.divmod(res.auto_heads, grid.width)
            used = np.column_stack([xs[c], ys[r]])
        else:
            used = np.column_stack([x, y])
        row = {"heads": mode, "n_heads": len(used), "dsm_sigma_z_m": sz, "time_s": round(time.perf_counter() - t0, 1)}
        row.update(score_gully_run(res.gully, res.extracted_lines, np.isfinite(dem), grid, ref, polys,
                                   tolerances_m=(2.0, 5.0, 15.0), reference_join_m=g["validation"]["reference_join_m"],
                                   heads_xy=used, true_heads_xy=true_xy))
        rows.append(row)
        logging.info("%s", row)
    return rows


def sigma_table(cfg: dict, twin: str, heads_path: str | None, sigmas, thresholds, dem=None, grid=None) -> pd.DataFrame:
    """Area and network scores over sigma x depth threshold (network traced once, digitised heads).

    ``dem``/``grid``: map this DEM (e.g. the photogrammetric DSM) instead of the stand-in.
    """
    from kitegully.evaluate.network import footprint, rasterize_polygons
    from kitegully.gully.network import network_lines
    from kitegully.gully.sensitivity import sensitivity_table

    g = cfg["gully"]
    crs = cfg["site"]["crs"]
    if dem is None:
        dtm, grid = read_raster(f"{twin}/truth/dtm.tif")
        dem = noisy_dem(dtm, grid.cell, g["standin"]["noise_sd_m"], g["standin"]["noise_correlation_m"], cfg["seed"])
    hx, hy = read_heads(heads_path or f"{twin}/observed/gully_heads.gpkg", crs)
    res = map_gullies(dem, grid, hx, hy, GullyParams.from_config(g), workers=1)
    ref = read_vector(f"{twin}/observed/field_network.gpkg", crs=crs)
    truth = rasterize_polygons(read_vector(f"{twin}/truth/gully_polygons.gpkg", crs=crs), grid) & np.isfinite(dem)
    dom = footprint(np.isfinite(dem), grid, near=[*ref.geometry, *network_lines(res.network, grid).geometry])
    return sensitivity_table(dem, grid, res.network, sigmas, thresholds, g["min_patch_volume_m3"], g["buffer_m"],
                             g["connectivity"], g["truncate_sigmas"], reference=ref,
                             tolerance_m=g["validation"]["tolerance_m"], domain=dom, truth_mask=truth)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--config", required=True)
    ap.add_argument("--twin", required=True)
    ap.add_argument("--heads", default=None)
    ap.add_argument("--set", action="append", default=[], help="gully key=value overrides (YAML value)")
    ap.add_argument("--modes", default="digitised,automatic")
    ap.add_argument("--mask-water", action="store_true", help="stand-in empty over open water, like the DSM")
    ap.add_argument("--out", default=None)
    ap.add_argument("--sigmas", default=None, help="comma list: also a sigma x threshold table (sensitivity_table) "
                    "with the digitised heads' network, against the truth polygons and the unfiltered reference")
    ap.add_argument("--thresholds", default="0.15,0.25")
    ap.add_argument("--dem", default=None, help="map this DEM (e.g. results/<site>/dense/dsm.tif) instead of the stand-in")
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    cfg = yaml.safe_load(open(a.config))
    cfg = copy.deepcopy(cfg)
    cfg["gully"]["crowns"] = {"enabled": False}  # stand-in DEMs have no orthophoto (gully.crowns needs one): off here
    for kv in a.set:
        k, v = kv.split("=", 1)
        cfg["gully"][k] = yaml.safe_load(v)
    dem = grid = None
    if a.dem:
        dem, grid = read_raster(a.dem)
        dem = np.asarray(dem, dtype=np.float32)
    if a.sigmas:
        tab = sigma_table(cfg, a.twin, a.heads, [float(v) for v in a.sigmas.split(",")],
                          [float(v) for v in a.thresholds.split(",")], dem, grid)
        print(tab.to_string())
        if a.out:
            tab.to_csv(a.out, index=False)
        return
    rows = run(cfg, a.twin, a.heads, a.modes.split(","), dem=dem, grid=grid, mask_water=a.mask_water)
    df = pd.DataFrame(rows)
    pd.set_option("display.width", 250)
    print(df.T.to_string())
    if a.out:
        df.to_csv(a.out, index=False)


if __name__ == "__main__":
    main()
