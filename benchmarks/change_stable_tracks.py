#!/usr/bin/env python
"""Co-registration on the vegetated ground vs on digitised tracks, on a finished twin site (evaluation only).

The change stage co-registers epoch 2 onto epoch 1 on its stable ground. By default that is everything outside the
unstable masks (gully polygons and the kite bare-soil map), which on a ploughed catchment is the vegetation. If the
DSMs' error moves between the epochs by a different amount over soil than over plants, the soil keeps the difference
(docs/stages/11_kamech_full.md, "Session 42"). A surveyor can instead flag polygons of unchanged ground of the
measured cover as ``stable`` (:func:`kitegully.change.budget.stable_candidates`): here, the farm tracks.

The track polygons are SIMULATED as an operator would digitise them on the orthophoto. They are drawn from the twin's
epoch-1 land cover (class ``track``), kept 0.5 m inside the track's edge, and pieces under 20 m² are dropped as
missed [I]. Reading the land cover is this script's only use of truth before scoring.

The script runs :func:`kitegully.change.stage.detect_change` (untiled; equal to the tiled rules) twice on the site's
two dense DSMs with the site's own change parameters and masks, once as the stage does and once with the tracks
flagged ``stable``. It scores each run's whole-site net volume against the true surfaces, as
``change_evaluate`` does. Writes nothing under the site's results.

Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/change_stable_tracks.py --results results/kamech_full_cut600x400 \\
        --site config/sites/kamech_full.yaml [--override results/kamech_full_cut600x400.override.yaml] [--out FILE]

About 2 x 1 min for a 6 M-cell DoD on 2 cores.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import rasterio
from rasterio import features
from shapely.geometry import shape

from kitegully.change.dod import resample
from kitegully.change.params import ChangeParams
from kitegully.change.stage import detect_change, output_paths
from kitegully.config import load_yaml, merge_config
from kitegully.io.raster import Raster
from kitegully.io.tables import write_table

REPO = Path(__file__).resolve().parents[1]
EDGE_INSET_M = 0.5  # [I] an operator draws inside the track's visible edge
MIN_PIECE_M2 = 20.0  # [I] short pieces (a track end under a tree) are missed


def digitised_tracks(landcover: Path, classes: Path, crs: str) -> gpd.GeoDataFrame:
    """Polygons of the land cover's ``track`` class, EDGE_INSET_M inside the edge, pieces under MIN_PIECE_M2 dropped."""
    code = int(pd.read_csv(classes).set_index("name").loc["track", "code"])
    with rasterio.open(landcover) as src:
        lc = src.read(1)
        geoms = [shape(g).buffer(-EDGE_INSET_M) for g, v in features.shapes((lc == code).astype(np.uint8), transform=src.transform)
                 if v == 1]
    geoms = [g for g in geoms if not g.is_empty and g.area >= MIN_PIECE_M2]
    return gpd.GeoDataFrame({"track_id": range(1, len(geoms) + 1)}, geometry=geoms, crs=crs)


def run(results: Path, cfg: dict, masks: list[dict], work: Path) -> dict:
    """One detect_change run and its whole-site score."""
    change = cfg["change"]
    methods = {k: change[k] for k in ("coregistration", "thresholds", "budget", "headcuts", "quality", "widening") if k in change}
    params = ChangeParams.from_config(methods, seed=cfg["seed"])
    epochs = [{"name": f"epoch{n}", "dem": str(results / "dense" / ("" if n == 1 else "epoch2") / "dsm.tif"), "nodata": None,
               "correlation": str(results / "dense" / ("" if n == 1 else "epoch2") / "correlation.tif"),
               "accuracy": {"checkpoints": str(results / "inputs" / ("" if n == 1 else "epoch2") / "checkpoints.csv")}}
              for n in (1, 2)]
    out = output_paths(work)
    detect_change(epochs, masks, None, params, out, site_crs=cfg["site"]["crs"])
    dod_r = Raster.read(out["dod"])
    t1 = Raster.read(str(results / "twin" / "truth" / "dsm.tif"))
    t2 = Raster.read(str(results / "twin" / "epoch2" / "truth" / "dsm.tif"))
    true = resample(t2, dod_r.grid) - resample(t1, dod_r.grid)
    ok = np.isfinite(dod_r.data) & np.isfinite(true)
    true_net = float(true[ok].sum() * dod_r.grid.cell ** 2)
    b = pd.read_csv(out["budget"])
    site = b[(b["mask"] == "site") & (b["method"] == "raw")].iloc[0]
    co = pd.read_csv(out["coregistration"]).set_index("quantity")["value"]
    with rasterio.open(out["stable"]) as s:
        stable_m2 = float((s.read(1) == 1).sum() * dod_r.grid.cell ** 2)
    err = float(site["net_m3"]) - true_net
    return {"net_m3": float(site["net_m3"]), "true_net_m3": true_net, "error_pct": 100 * err / abs(true_net),
            "net_sd_m3": float(site["net_sd_m3"]), "z_sigma": abs(err) / float(site["net_sd_m3"]),
            "coreg_dz_m": float(co["dz_at_centre"]), "stable_m2": stable_m2}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, required=True, help="a finished twin site's results folder (both epochs)")
    ap.add_argument("--site", type=Path, required=True, help="the site's config file")
    ap.add_argument("--override", type=Path, default=None, help="a config laid over it (e.g. a corner's override)")
    ap.add_argument("--out", type=Path, default=None, help="write the table as <out>.csv and .md")
    a = ap.parse_args(argv)
    cfg = merge_config(load_yaml(REPO / "config" / "config.yaml"), load_yaml(a.site))
    if a.override is not None:
        cfg = merge_config(cfg, load_yaml(a.override))
    res = a.results
    masks = [{"name": "gully", "file": str(res / "gully" / "gully_polygons.gpkg"), "kind": "vector", "by": None, "unstable": True},
             {"name": "bare_soil", "file": str(res / "obia" / "kite" / "bare_soil.gpkg"), "kind": "vector", "by": None,
              "unstable": True}]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tracks = digitised_tracks(res / "twin" / "truth" / "landcover.tif", res / "twin" / "truth" / "landcover_classes.csv",
                                  cfg["site"]["crs"])
        tracks.to_file(Path(tmp) / "tracks.gpkg")
        track_mask = {"name": "tracks", "file": str(Path(tmp) / "tracks.gpkg"), "kind": "vector", "by": None, "stable": True}
        for name, m in (("stage: outside gully and bare-soil masks", masks), ("digitised tracks flagged stable", masks + [track_mask])):
            rows.append({"stable ground": name, **run(res, cfg, m, Path(tmp) / name.split(":")[0].replace(" ", "_"))})
        rows[-1]["tracks"] = len(tracks)
    table = pd.DataFrame(rows)
    print(table.to_markdown(index=False, floatfmt=".4g"))
    if a.out is not None:
        write_table(table, a.out.with_suffix(".csv"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
