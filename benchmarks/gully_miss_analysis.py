"""Why reference gully length is missed on a twin's photogrammetric DSM (issue 15; evaluation only).

Maps the gullies with the site's ``gully:`` settings on ``<site>/dense/dsm.tif`` (library
call, as rule ``gully_map``) and, for every metre of the scored reference (the paper's
protocol) that no mapped network line matches within the tolerance, says why:

* ``traced, not mapped``: a traced path runs within the tolerance, but the cells there are
  not in a kept depth patch (too shallow for the depth threshold), so the map-clipped
  network (the one that is scored) drops it;
* ``no head on this gully``: the gully (field ``gully_no``) has no head used within
  ``--head-reach`` of its true centreline, and no traced path from another head passes;
* ``head downstream``: the gully has a head, the miss lies upstream of it along the
  true centreline (the operator placed the head where the incision became visible);
* ``traced beside``: the gully has a head upstream of the miss, but the path runs farther
  than the tolerance from the reference.

Reads the twin's truth (centrelines, heads): never part of the pipeline. Usage:
    python benchmarks/gully_miss_analysis.py --config config/sites/kamech_twin.yaml \
        --site results/kamech_twin [--heads digitised|automatic|both] [--out results/kamech_twin/gully_analysis]
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np
import pandas as pd
import shapely
import yaml
from scipy.spatial import cKDTree

from kitegully.evaluate.dem import read_checkpoints
from kitegully.evaluate.gully_run import score_gully_run
from kitegully.evaluate.network import footprint, scored_reference
from kitegully.gully.heads import HeadDetectionParams, dsm_noise_at_checkpoints
from kitegully.gully.inputs import read_heads
from kitegully.gully.pipeline import GullyParams, map_gullies
from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector

log = logging.getLogger("gully_miss_analysis")


def sample_line(geom, step: float) -> np.ndarray:
    """Points every ``step`` m along the parts of a (multi)line, (n, 2)."""
    pts = []
    for part in getattr(geom, "geoms", [geom]):
        if part.length == 0:
            continue
        d = np.arange(step / 2, part.length, step)
        pts.append(shapely.get_coordinates(shapely.line_interpolate_point(part, d)))
    return np.concatenate(pts) if pts else np.zeros((0, 2))


def dist_to_lines(pts: np.ndarray, lines) -> np.ndarray:
    """Distance (m) of every point to the union of ``lines``; inf when there are none."""
    geoms = [g for g in lines if g is not None and not g.is_empty]
    if not geoms or pts.size == 0:
        return np.full(len(pts), np.inf)
    u = shapely.union_all(geoms)
    return shapely.distance(shapely.points(pts), u)


def analyse(cfg: dict, site: Path, heads: str, step: float = 1.0, head_reach_m: float | None = None):
    """Per-gully table of reference, matched and missed length by reason; and the run's scores."""
    g = cfg["gully"]
    crs = cfg["site"]["crs"]
    tol = float(g["validation"]["tolerance_m"])
    dem, grid = read_raster(site / "dense/dsm.tif")
    dem = np.asarray(dem, dtype=np.float32)
    twin = site / "twin"
    hx, hy = read_heads(str(twin / "observed/gully_heads.gpkg"), crs) if heads != "automatic" else (np.zeros(0), np.zeros(0))
    auto = None
    if heads != "digitised":
        sz = dsm_noise_at_checkpoints(dem, grid, read_checkpoints(twin / "observed/checkpoints.csv"))
        auto = HeadDetectionParams.from_config(g["automatic_heads"], sz)
    params = GullyParams.from_config(g)
    res = map_gullies(dem, grid, hx, hy, params, workers=1, auto_heads=auto)
    xs, ys = grid.cell_centres()
    r, c = np.divmod(res.auto_heads, grid.width)
    used = np.concatenate([np.column_stack([hx, hy]), np.column_stack([xs[c], ys[r]])])
    ref = read_vector(twin / "observed/field_network.gpkg", crs=crs)
    polys = read_vector(twin / "truth/gully_polygons.gpkg", crs=crs)
    th = read_vector(twin / "truth/gully_heads.gpkg", crs=crs)
    cl = read_vector(twin / "truth/gully_centrelines.gpkg", crs=crs)
    valid = np.isfinite(dem)
    scores = score_gully_run(res.gully, res.extracted_lines, valid, grid, ref, polys, (tol,),
                             g["validation"]["reference_join_m"], used, np.column_stack([th.geometry.x, th.geometry.y]))
    domain = footprint(valid, grid, near=[*ref.geometry, *res.extracted_lines.geometry])
    scored, _n, _c = scored_reference(ref, domain, float(g["validation"]["reference_join_m"]))
    pts = sample_line(scored, step)
    # gully of each sample: the nearest field section's gully_no
    sec = ref.reset_index(drop=True)
    d_sec = np.stack([shapely.distance(shapely.points(pts), geom) for geom in sec.geometry])
    gno = sec["gully_no"].to_numpy()[np.argmin(d_sec, axis=0)]
    d_map = dist_to_lines(pts, res.extracted_lines.geometry)
    d_trace = dist_to_lines(pts, res.lines.geometry)
    # heads per true gully: a used head within reach of the gully's true centreline
    reach = head_reach_m if head_reach_m is not None else params.head_snap_radius_m + tol
    gid_of_vertex, verts, s_of_vertex = [], [], []
    for gid, grp in cl.groupby("gully_id"):
        co = np.concatenate([shapely.get_coordinates(geom) for geom in grp.geometry])
        gid_of_vertex.append(np.full(len(co), gid))
        verts.append(co)
        s_of_vertex.append(np.concatenate([[0], np.cumsum(np.hypot(*np.diff(co, axis=0).T))]))
    gid_of_vertex, verts, s_of_vertex = map(np.concatenate, (gid_of_vertex, verts, s_of_vertex))
    tree = cKDTree(verts)
    # position of each used head along its gully (nearest true vertex within reach)
    head_s: dict[int, list[float]] = {}
    if len(used):
        dd, ii = tree.query(used, k=1)
        for d, i in zip(dd, ii):
            if d <= reach:
                head_s.setdefault(int(gid_of_vertex[i]), []).append(float(s_of_vertex[i]))
    # position of each reference sample along its gully
    _, vi = tree.query(pts, k=1)
    s_pts = s_of_vertex[vi]
    same = gid_of_vertex[vi] == gno
    reason = np.full(len(pts), "matched", dtype=object)
    miss = d_map > tol
    reason[miss & (d_trace <= tol)] = "traced, not mapped"
    rest = miss & (d_trace > tol)
    for k in np.flatnonzero(rest):
        hs = head_s.get(int(gno[k]))
        if not hs:
            reason[k] = "no head on this gully"
        elif same[k] and s_pts[k] < min(hs):
            reason[k] = "head downstream"
        else:
            reason[k] = "traced beside"
    df = pd.DataFrame({"gully_no": gno, "reason": reason, "length_m": step})
    tab = df.pivot_table(index="gully_no", columns="reason", values="length_m", aggfunc="sum", fill_value=0.0)
    heads_t = th.set_index("gully_id")
    first = cl.sort_values(["gully_id"]).groupby("gully_id").first()
    tab["bank"] = [heads_t["bank"].get(i, "valley") for i in tab.index]
    tab["head_depth_m"] = [first["depth_m"].get(i, np.nan) for i in tab.index]
    tab["head_width_m"] = [first["width_m"].get(i, np.nan) for i in tab.index]
    tab["heads_used"] = [len(head_s.get(int(i), [])) for i in tab.index]
    totals = df.groupby("reason")["length_m"].sum()
    return tab.reset_index(), totals, scores, res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="config/sites/kamech_twin.yaml")
    ap.add_argument("--site", default="results/kamech_twin")
    ap.add_argument("--heads", default=None, help="override gully.heads")
    ap.add_argument("--set", action="append", default=[], help="gully key=value (yaml value) overrides")
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    cfg = yaml.safe_load(Path(a.config).read_text())
    for kv in a.set:
        k, v = kv.split("=", 1)
        cfg["gully"][k] = yaml.safe_load(v)
    heads = a.heads or cfg["gully"]["heads"]
    cfg["gully"]["heads"] = heads
    tab, totals, scores, _ = analyse(cfg, Path(a.site), heads)
    ref = totals.sum()
    print(f"heads: {heads}; scored reference {ref:.0f} m")
    for k, v in totals.items():
        print(f"  {k:25s} {v:7.0f} m  {100 * v / ref:5.1f} %")
    print({k: round(v, 3) for k, v in scores.items()})
    cols = [c for c in tab.columns if c != "matched"]
    print(tab[tab.drop(columns=["gully_no", "bank", "head_depth_m", "head_width_m", "heads_used", "matched"],
                       errors="ignore").sum(axis=1) > 0][["gully_no", *[c for c in cols if c != "gully_no"]]].round(2).to_string())
    if a.out:
        out = Path(a.out)
        out.mkdir(parents=True, exist_ok=True)
        write_table(tab, out / f"missed_by_gully_{heads}.csv", floatfmt=".2f")
        write_table(totals.rename("length_m").reset_index(), out / f"missed_by_reason_{heads}.csv", floatfmt=".1f")


if __name__ == "__main__":
    main()
