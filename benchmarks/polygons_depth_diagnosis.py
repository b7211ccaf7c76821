#!/usr/bin/env python
"""Where the polygons stage's section depth error comes from, section by section (issue 16).

For each member (default twin and the ensemble members), the stage runs once on the member's
photogrammetric DSM; each of its t = 0.5 m cross-sections is then re-measured, with the *same*
geometry and the morphometry settings before session 9 (clipped section, ends prolonged to the rims
or left on the outline, 4 m ground opening, ``line`` reference: the errors this script decomposes),
on:

- ``dsm``: the stage DEM (what the stage reports; checked against the stored depth);
- ``true_dsm_minz`` / ``true_dtm_minz``: the twin's true DSM / ground brought to the stage grid by the
  stage's own minimum-z resampling;
- ``true_dtm_02``: the twin's true ground at its own 0.2 m cell, draped directly;

and compared with four truths, all evaluation-only (the twin's plan is rebuilt from the member's
configuration to carve the true incision depth D(x, y) on the 0.2 m grid; pre-incision surface
z0 = true DTM + D):

- ``depth_reach``: the nearest true reach's mean depth within 2 m (what ``morphometry_errors`` scores);
- ``depth_local``: max D along the section's reference line (the true incision depth where the section lies);
- ``ref_err_true``: line-between-rims reference minus z0 at the deepest point, on the true DTM (what the
  rim reference adds to a perfect surface: the pre-incision surface's curvature across the gully, rims
  placed off the true edge);
- ``floor_lift``: DSM minus true DTM at the deepest point of the section, ``rim_lift``: the same at the
  reference ends (their mean; ground profile of both).

Diagnosis only: it reads the truth, and nothing here feeds a setting of the stage.

``--volume-split`` instead splits the total volume error of the site settings into mapping and
sections (:func:`volume_split`).

Usage::

    .venv/bin/python benchmarks/polygons_depth_diagnosis.py [--volume-split] [--members default,ens1] [--default-root /work/run10/results]
        [--root /work/wt/ensrun/results]

Writes ``results/benchmarks/polygons_depth_diagnosis_sections.csv`` (per section) and
``polygons_depth_diagnosis.md`` (medians per member and section shape).
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import shapely

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
sys.path.insert(0, str(REPO / "benchmarks"))

from polygons_ensemble import ENSEMBLE_DIR, member_config  # noqa: E402

from kitegully.io.raster import Raster  # noqa: E402
from kitegully.io.vectors import read_vector  # noqa: E402
from kitegully.polygons import PolygonParams, measure_polygons  # noqa: E402
from kitegully.polygons.dem_prep import min_z_resample  # noqa: E402
from kitegully.polygons.morphometry import _ground_drape, extend_to_rims  # noqa: E402
from kitegully.polygons.profiles import drape, section_profile  # noqa: E402


CACHE: Path | None = None


def true_incision(cfg: dict, grid) -> np.ndarray:
    """The twin's carved incision depth D on ``grid`` (rebuilt from the member's plan; evaluation only)."""
    from kitegully.twin import gullies as gl
    from kitegully.twin.site import TwinParams, build_site

    tw = TwinParams.from_config(cfg["twin"])
    site = build_site(tw, cfg["site"].get("crs", cfg.get("crs")), cfg["seed"])
    depth, _ = gl.carve(site.segs, grid, tw.gullies["zone_buffer_m"])
    return depth


def _profile(line, z, grid, step, seg):
    if seg > 0:
        return _ground_drape(line, z, grid, step, seg)
    s, _, _, zz = drape(line, z, grid, step)
    return s, zz


def diagnose(member: str, root: Path) -> pd.DataFrame:
    cfg = member_config(member)
    poly = cfg["polygons"]
    site = root / cfg["site"]["name"]
    truth = site / "twin" / "truth"
    p = PolygonParams.from_config(poly)
    cache = CACHE / f"{member}.pkl" if CACHE else None
    t0 = time.perf_counter()
    if cache is not None and cache.exists():
        res = pickle.loads(cache.read_bytes())
    else:
        r = Raster.read(site / "dense" / "dsm.tif")
        res = measure_polygons(r.data, r.grid, p, dem_name=member)
        if cache is not None:
            cache.parent.mkdir(parents=True, exist_ok=True)
            cache.write_bytes(pickle.dumps(res))
    print(f"{member}: stage {time.perf_counter() - t0:.1f} s, {len(res.sections)} sections", flush=True)
    dtm = Raster.read(truth / "dtm.tif")
    D = true_incision(cfg, dtm.grid)
    z0 = dtm.data.astype(np.float64) + D
    h, w = res.dem.shape
    surf = {"dsm": (res.dem.astype(np.float64), res.grid)}
    for name, path in (("true_dsm_minz", truth / "dsm.tif"), ("true_dtm_minz", truth / "dtm.tif")):
        rr = Raster.read(path)
        z, _ = min_z_resample(rr.data, rr.grid, p.cell_m)
        z = np.asarray(z, np.float64)[:h, :w]
        surf[name] = (np.where(np.isfinite(z), z, res.dem), res.grid)
    surf["true_dtm_02"] = (dtm.data.astype(np.float64), dtm.grid)
    cl = read_vector(truth / "gully_centrelines.gpkg").reset_index(drop=True)
    tree = shapely.STRtree(cl.geometry.values)
    match_m = poly["evaluation"]["match_distance_m"]
    step = 0.5 * p.cell_m
    rows = []
    for sec in res.sections.itertuples():
        piece = shapely.LineString(np.asarray(sec.geometry.coords)[:, :2])
        line, off = extend_to_rims(piece, res.rims, res.grid, p.rim_search_m)
        ext_a, ext_b = off, line.length - piece.length - off
        row = {"member": member, "polygon_id": sec.polygon_id, "branch": sec.branch, "station_m": sec.station_m, "width_m": sec.width_m,
               "depth_m": sec.depth_m, "area_m2": sec.area_m2, "slab_m": sec.slab_m, "ref_len_m": line.length, "ext_a": ext_a, "ext_b": ext_b}
        prof = {}
        for name, (z, g) in surf.items():
            s, zz = _profile(line, z, g, step, p.ground_segment_m)
            prof[name] = (s, zz)
            d, a = section_profile(s, zz, "line")
            row[f"depth_{name}"], row[f"area_{name}"] = d, a
        # truths along the reference line (0.2 m grid)
        s02, _, _, Dl = drape(line, D, dtm.grid, step)
        _, _, _, z0l = drape(line, z0, dtm.grid, step)
        row["depth_local"] = float(Dl.max())
        inside = Dl > 0.05
        row["width_local"] = float(inside.sum() * step) if inside.any() else 0.0
        row["area_local"] = float(np.sum(0.5 * (Dl[1:] + Dl[:-1]) * np.diff(s02)))
        s, zt = prof["true_dtm_02"]
        zr = zt[0] + (zt[-1] - zt[0]) * s / s[-1] if s[-1] > 0 else np.full_like(zt, zt[0])
        k = int(np.argmax(zr - zt))
        z0k = np.interp(s[k], s02, z0l)
        row["ref_err_true"] = float(zr[k] - z0k)
        kk = int(np.argmax(Dl))
        run = Dl > 0
        ia = kk - (int(np.argmin(run[kk::-1])) if not run[kk::-1].all() else kk + 1) + 1
        ib = kk + (int(np.argmin(run[kk:])) if not run[kk:].all() else run.size - kk) - 1
        row["edge_off_a"], row["edge_off_b"] = float(s02[ia]), float(s02[-1] - s02[ib])  # > 0: reference end outside the true edge
        chord = z0l[ia] + (z0l[ib] - z0l[ia]) * (s02[kk] - s02[ia]) / max(s02[ib] - s02[ia], 1e-9)
        row["ref_curv_true"] = float(chord - z0l[kk])  # chord of the pre-incision surface between the true edges, above it at the axis
  # rim line above the pre-incision surface at the deepest point
        row["floor_err_true"] = float(zt[k] - (z0k - np.interp(s[k], s02, Dl)))  # drape/ground profile vs carved floor there
        sd, zd = prof["dsm"]
        sm, zm = prof["true_dtm_minz"]
        kd = int(np.argmax((zd[0] + (zd[-1] - zd[0]) * sd / max(sd[-1], 1e-9)) - zd))
        row["floor_lift"] = float(zd[kd] - np.interp(sd[kd], sm, zm))
        row["rim_lift"] = float(0.5 * ((zd[0] - zm[0]) + (zd[-1] - zm[-1])))
        row["floor_lift_minz"] = float(np.interp(sd[kd], sm, zm) - np.interp(sd[kd], s, zt))  # min-z resampling of the true ground at the floor
        row["rim_lift_minz"] = float(0.5 * ((zm[0] - zt[0]) + (zm[-1] - zt[-1])))
        mid = shapely.line_interpolate_point(piece, 0.5, normalized=True)
        j = tree.query_nearest(mid, max_distance=match_m)
        if len(j):
            j = int(j[0])
            row.update({"gully_id": int(cl.loc[j, "gully_id"]), "shape": cl.loc[j, "shape"], "depth_reach": cl.loc[j, "depth_m"],
                        "width_reach": cl.loc[j, "width_m"]})
        rows.append(row)
    return pd.DataFrame(rows)


def volume_split(member: str, root: Path, reference: str | None = None, surface: str = "dsm") -> dict:
    """Total volume split into mapping and sections: the true incision volume inside the t = 0.5 m polygons.

    ``true_in_polygons_pct``: share of the true incision volume (Σ D · cell² on the 0.2 m grid) whose cells lie
    in a polygon, ``..._rims_pct`` the same with the polygons grown by ``rim_search_m`` (the sections' references
    reach that far); ``sections_over_in_rims_pct``: the sections' volume (Σ area · slab, site settings) against
    the latter. ``reference`` overrides the site's; ``surface`` ``true_dtm`` drapes the same sections on the true
    ground (minimum-z resampled to the stage cell). Evaluation only.
    """
    import scipy.ndimage as ndi

    from kitegully.polygons.evaluation import rasterize
    from kitegully.polygons.morphometry import measure_sections

    cfg = member_config(member)
    p = PolygonParams.from_config(cfg["polygons"])
    res = pickle.loads((CACHE / f"{member}.pkl").read_bytes())
    truth = root / cfg["site"]["name"] / "twin" / "truth"
    dtm = Raster.read(truth / "dtm.tif")
    D = true_incision(cfg, dtm.grid)
    thr = p.morph_threshold_m
    ref = reference or p.reference
    z = res.dem
    if surface == "true_dtm":
        zt, _ = min_z_resample(dtm.data, dtm.grid, p.cell_m)
        zt = np.asarray(zt, np.float64)[: z.shape[0], : z.shape[1]]
        z = np.where(np.isfinite(zt), zt, res.dem)
    _, sec, _ = measure_sections(res.labels[thr], res.polygons[thr], z, res.level, res.grid, p.section_spacing_m, ref,
                                 p.smooth_step_m, p.snakes_alpha, p.snakes_beta, p.branches, res.rims, p.rim_search_m, p.prolong_axes,
                                 p.ground_segment_m, p.bank_fit_m if p.bank_fit_m > 0 else p.rim_search_m, no_rim=p.no_rim)
    inside = rasterize(res.polygons[thr].geometry, dtm.grid).astype(bool)
    grown = ndi.distance_transform_edt(~inside, sampling=dtm.grid.cell) <= p.rim_search_m
    ca = dtm.grid.cell ** 2
    v_true = float(D.sum() * ca)
    v_in, v_grown = float(D[inside].sum() * ca), float(D[grown].sum() * ca)
    v_sec = float((sec["area_m2"] * sec["slab_m"]).sum())
    reach = read_vector(truth / "gully_centrelines.gpkg")
    p_exp = np.where(reach["shape"] == "U", cfg["twin"]["gullies"]["u_shape_exponent"], 1.0)
    v_reach = float((reach["width_m"] * reach["depth_m"] * p_exp / (p_exp + 1) * reach["length_m"]).sum())
    return {"member": member, "reference": ref, "surface": surface, "true_volume_reaches_m3": v_reach, "true_volume_raster_m3": v_true,
            "true_in_polygons_pct": 100 * v_in / v_true, "true_in_polygons_grown_to_rims_pct": 100 * v_grown / v_true,
            "sections_m3": v_sec, "sections_over_in_rims_pct": 100 * v_sec / v_grown, "volume_error_pct": 100 * (v_sec - v_reach) / v_reach}


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    m = df.dropna(subset=["depth_reach"]).copy()
    m["err_dsm"] = m["depth_dsm"] - m["depth_reach"]
    cols = {"n": ("err_dsm", "size"), "dsm_vs_reach": ("err_dsm", "median"), "dsm_abs": ("abs_dsm", "median"),
            "truedsm_vs_reach": ("e_tdsm", "median"), "dtm_minz_vs_reach": ("e_tdtm", "median"), "dtm_minz_abs": ("abs_tdtm", "median"),
            "dtm02_vs_reach": ("e_02", "median"), "dtm02_abs": ("abs_02", "median"), "local_vs_reach": ("e_loc", "median"),
            "dsm_vs_local_abs": ("abs_dsm_loc", "median"), "ref_err_true": ("ref_err_true", "median"), "floor_lift": ("floor_lift", "median"),
            "rim_lift": ("rim_lift", "median"), "floor_lift_minz": ("floor_lift_minz", "median"), "rim_lift_minz": ("rim_lift_minz", "median"),
            "width_reach": ("width_reach", "median"), "depth_reach": ("depth_reach", "median")}
    m["abs_dsm"] = m["err_dsm"].abs()
    m["e_tdsm"] = m["depth_true_dsm_minz"] - m["depth_reach"]
    m["e_tdtm"] = m["depth_true_dtm_minz"] - m["depth_reach"]
    m["abs_tdtm"] = m["e_tdtm"].abs()
    m["e_02"] = m["depth_true_dtm_02"] - m["depth_reach"]
    m["abs_02"] = m["e_02"].abs()
    m["e_loc"] = m["depth_local"] - m["depth_reach"]
    m["abs_dsm_loc"] = (m["depth_dsm"] - m["depth_local"]).abs()
    out = []
    for (mem, shp), g in list(m.groupby(["member", "shape"])) + [((k, "all"), g) for k, g in m.groupby("member")]:
        out.append({"member": mem, "shape": shp, **{k: g[c].agg(f) for k, (c, f) in cols.items()}})
    return pd.DataFrame(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default="/work/wt/ensrun/results", help="results folder of the ensemble members")
    ap.add_argument("--default-root", default="/work/run10/results", help="results folder of the default twin")
    ap.add_argument("--members", default="default," + ",".join(p.stem for p in sorted(ENSEMBLE_DIR.glob("*.yaml"))))
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "polygons_depth_diagnosis"))
    ap.add_argument("--volume-split", action="store_true", help="only the volume split (needs the cached stage results)")
    ap.add_argument("--cache", default=str(REPO / "results" / "benchmarks" / "polygons_depth_cache"), help="pickled stage results ('' = none)")
    args = ap.parse_args()
    global CACHE
    CACHE = Path(args.cache) if args.cache else None
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if args.volume_split:
        vs = pd.DataFrame([volume_split(m, Path(args.default_root if m == "default" else args.root), ref, surf)
                           for m in args.members.split(",") for ref in ("banks",) for surf in ("dsm", "true_dtm")])
        vs.to_csv(out.with_name(out.name + "_volume.csv"), index=False)
        text = "# Polygons: the total volume split into mapping and sections\n\n" + vs.to_markdown(index=False, floatfmt=".1f") + "\n"
        out.with_name(out.name + "_volume.md").write_text(text, encoding="utf-8")
        print(text)
        return
    frames = []
    for mem in args.members.split(","):
        frames.append(diagnose(mem, Path(args.default_root if mem == "default" else args.root)))
        df = pd.concat(frames, ignore_index=True)
        df.to_csv(out.with_name(out.name + "_sections.csv"), index=False)
        summ = summarise(df)
        print(summ.to_string(float_format=lambda v: f"{v:.3f}"), flush=True)
    out.with_suffix(".md").write_text("# Polygons: where the section depth error comes from\n\n" + summ.to_markdown(index=False, floatfmt=".3f") + "\n",
                                      encoding="utf-8")


if __name__ == "__main__":
    main()
