#!/usr/bin/env python
"""Does the GCP bundle's tie-point budget shape the block? (issue 21, full-size dome; evaluation only)

The GCP bundle adjusts the SfM block with ``georef.max_tie_points`` tie points chosen by
:func:`kitegully.georef.model.select_tie_points` (balanced over ``tie_grid`` cells of every
image). The full-size Kamech site inherited 10 000 from the 57-photo default twin, where that
is about 175 points per photo; over 773 or 516 photos it is 13-19, so most of the 8 x 6 cells
of a photo hold no tie point and the photo's outer parts, which carry the radial distortion,
are barely observed. A near-nadir block whose distortion is weakly observed bends (a dome:
James & Robson 2014). This script runs the configured adjustment (no leave-one-out) on one
finished epoch's SfM model and GCP clicks for several tie budgets and measures, against the
twin's truth (evaluation only, nothing is written back):

* camera positions against the flight truth: RMSE, worst, mean height error;
* the adjusted intrinsics against the rendered camera (f, k1, k2);
* every SfM tie point re-triangulated with the adjusted block minus the true DSM: median,
  NMAD, a quadratic-in-plan fit (its range over the site = the dome) and the spread of
  250 m block medians;
* the same errors where the independent checkpoints are (median of the tie points within 10 m
  of each): the part of the checkpoint statistics that the block's shape makes;
* wall time of the adjustment.

``--f-true`` repeats each budget with the focal length fixed at the rendered camera's, to tell
the share of the dome that the focal length / flying height trade-off makes.

    PYTHONPATH=src .venv/bin/python benchmarks/georef_tie_density.py \\
        --site config/sites/kamech_full.yaml --results results/kamech_full --epoch epoch2/ \\
        --ties 10000,40000,100000 --out results/benchmarks/georef_tie_density_epoch2.csv

Cost: one adjustment per budget, O(iterations x (observations + P^3)) with P = 5 + 6 x photos;
the tie triangulation O(observations).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pycolmap
import rasterio
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.georef.control import solve  # noqa: E402
from kitegully.georef.observations import collect_observations, triangulate_gcps  # noqa: E402
from kitegully.georef.quality import select_gcps  # noqa: E402
from kitegully.georef.gcp_io import read_gcps  # noqa: E402
from kitegully.georef.geometry import camera_centres  # noqa: E402
from kitegully.georef.model import block_from_reconstruction, retriangulate_all  # noqa: E402
from kitegully.georef.stage import GeorefParams  # noqa: E402
from kitegully.io.tables import write_table  # noqa: E402
from kitegully.seeds import rng_for  # noqa: E402
from kitegully.sfm.stage import load_image_infos  # noqa: E402

log = logging.getLogger("georef_tie_density")


def sample_raster(z: np.ndarray, transform, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Nearest-cell values of the raster ``z`` (NaN nodata) at (x, y); NaN outside."""
    r, c = rasterio.transform.rowcol(transform, x, y)
    r, c = np.asarray(r), np.asarray(c)
    ok = (r >= 0) & (c >= 0) & (r < z.shape[0]) & (c < z.shape[1])
    out = np.full(len(x), np.nan)
    out[ok] = z[r[ok], c[ok]]
    return out


def dome(x: np.ndarray, y: np.ndarray, e: np.ndarray, block_m: float) -> dict:
    """Quadratic-in-plan fit of the height errors ``e`` and 250 m block medians.

    Returns the fit's value at the tie points' centre, its range over the tie points, the
    curvature terms (m/km²) and the 5-95 % spread of the block medians."""
    xc, yc = np.median(x), np.median(y)
    u, v = (x - xc) / 1e3, (y - yc) / 1e3
    A = np.c_[np.ones_like(u), u, v, u * u, v * v, u * v]
    c, *_ = np.linalg.lstsq(A, e, rcond=None)
    fit = A @ c
    bx, by = np.floor(x / block_m).astype(int), np.floor(y / block_m).astype(int)
    med = pd.Series(e).groupby([bx, by]).median()
    cnt = pd.Series(e).groupby([bx, by]).size()
    med = med[cnt >= 50]
    return {"dome_centre_m": c[0], "dome_range_m": float(np.ptp(fit)), "curv_xx_m_km2": c[3], "curv_yy_m_km2": c[4],
            "curv_xy_m_km2": c[5], "block_median_p5_m": float(np.percentile(med, 5)),
            "block_median_p95_m": float(np.percentile(med, 95)), "n_blocks": int(len(med))}


def at_checkpoints(xy: np.ndarray, e: np.ndarray, checkpoints: pd.DataFrame, radius_m: float) -> dict:
    """The block's height error where the checkpoints are: the median of ``e`` over the tie points
    within ``radius_m`` of each checkpoint (at least 5), then mean and SD over the checkpoints: what
    the checkpoint validation of a DSM from this block would see of the block's shape."""
    from scipy.spatial import cKDTree

    tree = cKDTree(xy)
    near = tree.query_ball_point(checkpoints[["x", "y"]].to_numpy(), radius_m)
    med = np.array([np.median(e[i]) if len(i) >= 5 else np.nan for i in near])
    med = med[np.isfinite(med)]
    return {"checkpoints_n": int(med.size), "checkpoints_block_mean_m": float(med.mean()) if med.size else np.nan,
            "checkpoints_block_sd_m": float(med.std(ddof=1)) if med.size > 1 else np.nan}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--site", default=str(REPO / "config" / "sites" / "kamech_full.yaml"))
    ap.add_argument("--results", default=str(REPO / "results" / "kamech_full"))
    ap.add_argument("--epoch", default="epoch2/", help="epoch folder with its slash ('' for a one-epoch site)")
    ap.add_argument("--ties", default="10000,40000,100000", help="comma-separated max_tie_points (0 = all)")
    ap.add_argument("--block-m", type=float, default=250.0)
    ap.add_argument("--checkpoint-radius-m", type=float, default=10.0)
    ap.add_argument("--rel-tolerance", type=float, default=None,
                    help="the bundle's stop (relative cost decrease) instead of the site's; with --max-iterations")
    ap.add_argument("--max-iterations", type=int, default=None)
    ap.add_argument("--f-true", action="store_true",
                    help="also adjust each budget with f fixed at the rendered camera's (diagnosis: is the dome f's?)")
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "georef_tie_density.csv"))
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    R, pre = Path(a.results), a.epoch
    cfg = yaml.safe_load(Path(a.site).read_text())
    P = GeorefParams.from_config(cfg["georef"])
    if a.rel_tolerance is not None or a.max_iterations is not None:
        P = dataclasses.replace(P, bundle=dataclasses.replace(
            P.bundle, rel_tolerance=a.rel_tolerance if a.rel_tolerance is not None else P.bundle.rel_tolerance,
            max_iterations=a.max_iterations if a.max_iterations is not None else P.bundle.max_iterations))
    t0 = time.perf_counter()
    rec = pycolmap.Reconstruction(str(R / "sfm" / pre / "model"))
    infos = load_image_infos(R / "sfm" / pre / "image_info.json")
    sfm_to_name = {i.sfm_name: i.name for i in infos}
    poses = pd.read_csv(R / "flight" / pre / "truth" / "poses.csv").set_index("image")
    cam = json.loads((R / "flight" / pre / "truth" / "camera.json").read_text())
    with rasterio.open(R / "twin" / pre / "truth" / "dsm.tif") as ds:  # read once: 80 M cells at full size
        dsm = ds.read(1, masked=True).filled(np.nan).astype(np.float32)
        dsm_transform = ds.transform
    checkpoints = pd.read_csv(R / "twin" / pre / "observed" / "checkpoints.csv")
    gcps = read_gcps(R / "flight" / pre / "observed" / "gcp_list.txt", cfg["site"]["crs"], P.gcp_format)
    seed = int(rng_for(cfg["seed"], "georef").integers(2**31 - 1))  # the rule's seed
    log.info("model %d images, %d points (%.0f s)", rec.num_reg_images(), rec.num_points3D(), time.perf_counter() - t0)
    rows = []
    cases = [(int(v), False) for v in a.ties.split(",")]
    if a.f_true:
        cases += [(n, True) for n, _ in cases]
    for n_ties, f_true in cases:
        block, index = block_from_reconstruction(rec, n_ties, seed, P.tie_grid)
        settings = P.bundle
        if f_true:
            block.intr[:, 0] = cam["colmap_params"][0]
            settings = dataclasses.replace(P.bundle, refine=tuple(r for r in P.bundle.refine if r != "f"))
        names = [sfm_to_name[n] for n in index.image_names]
        image_rows = {n.split("/")[-1]: k for k, n in enumerate(index.image_names)}
        obs = collect_observations(gcps, infos, image_rows, P.gcp_pixel_frame, cfg["sfm"]["image_frame"], P.gcp_pixel_scale,
                                   P.qa.coords_tolerance_m, P.gcp_pixel_offset_px)
        xyz = np.array([o.gcp.xyz for o in obs])
        off = np.round(np.median(xyz, 0) / 100) * 100
        off[2] = 0
        Xm, rp = triangulate_gcps(block, obs)
        use = select_gcps(obs, Xm, rp, xyz - off, P.qa, P.method)
        t1 = time.perf_counter()
        local, _, rep = solve(block, obs, xyz - off, Xm, use, P.method, settings)
        wall = time.perf_counter() - t1
        d = camera_centres(local.rv, local.t) - (poses.loc[names, ["x_m", "y_m", "z_m"]].to_numpy() - off)
        d3 = np.sqrt((d ** 2).sum(1))
        # every SfM point (not only the adjusted ties) through the adjusted block
        Xt, _ = retriangulate_all(local, index)
        Xt = Xt[np.all(np.isfinite(Xt), 1)] + off
        e = Xt[:, 2] - sample_raster(dsm, dsm_transform, Xt[:, 0], Xt[:, 1])
        med = np.nanmedian(e)
        ok = np.isfinite(e) & (np.abs(e - med) < 1.0)  # plants and blunders out of the fit
        nmad = 1.4826 * np.median(np.abs(e[ok] - np.median(e[ok])))
        row = {"epoch": pre.strip("/") or "single", "max_tie_points": n_ties, "f": "true, fixed" if f_true else "adjusted", "ties_used": int(block.points.shape[0]),
               "photos": len(names), "ties_per_photo": block.points.shape[0] / len(names), "adjust_wall_s": wall,
               "rel_tolerance": settings.rel_tolerance, "iterations": rep.get("n_iterations"),
               "f_px": local.intr[0, 0], "f_true_px": cam["colmap_params"][0], "k1": local.intr[0, 3],
               "k1_true": cam["colmap_params"][3], "k2": local.intr[0, 4], "k2_true": cam["colmap_params"][4],
               "camera_rmse_m": float(np.sqrt((d3 ** 2).mean())), "camera_max_m": float(d3.max()),
               "camera_mean_dz_m": float(d[:, 2].mean()), "tie_points_scored": int(ok.sum()),
               "ties_minus_true_dsm_median_m": float(np.median(e[ok])), "ties_minus_true_dsm_nmad_m": float(nmad)}
        row.update(dome(Xt[ok, 0], Xt[ok, 1], e[ok], a.block_m))
        row.update(at_checkpoints(Xt[ok, :2], e[ok], checkpoints, a.checkpoint_radius_m))
        row = {k: (float(v) if isinstance(v, np.floating) else v) for k, v in row.items()}
        rows.append(row)
        log.info("%s", {k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()})
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_table(pd.DataFrame(rows), out)
    log.info("wrote %s", out)


if __name__ == "__main__":
    main()
