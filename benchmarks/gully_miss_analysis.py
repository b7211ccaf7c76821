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
  than the tolerance from the reference; split into ``beside: head snapped off the gully``
  (every head of that gully was snapped farther than ``--on-gully`` m from its true
  centreline: a snapping miss) and ``beside: path leaves the gully`` (a head sits on the
  gully, the path leaves it further down: a tracing miss).

Every sample carries ``near_flat_any`` (the same test for matched samples too: the flag's base
rate; on a noisy DSM small fills lie near most of the reference) and ``near_object`` (a true
shrub or tree cell within 1 m). Every missed sample is also flagged ``near_flat`` (within the tolerance of a cell raised by
the depression fill of the tracing surface: a filled depression or flat the path crosses by
flat resolution) and ``near_nodata`` (within the tolerance of a DSM hole, open water or the
DSM edge). A per-head table gives the distance of each used head, as digitised and as
snapped, to the nearest true centreline (``--heads-out``).

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
from kitegully.gully.heads import HeadDetectionParams
from kitegully.gully.relief import dsm_noise_at_checkpoints
from kitegully.gully.inputs import read_heads
from kitegully.gully.network import topological_order
from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import map_gullies
from kitegully.gully.surface import tracing_surface
from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector
from kitegully.terrain.fill import priority_flood_fill

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


def analyse(cfg: dict, site: Path, heads: str, step: float = 1.0, head_reach_m: float | None = None,
            on_gully_m: float = 2.0, samples_out: bool = False):
    """Per-gully table of reference, matched and missed length by reason; and the run's scores.

    Returns ``(per_gully, totals, scores, result)``, with ``samples_out`` also the per-sample
    table (``x, y, gully_no, reason, length_m, near_flat, near_nodata, traced_where, kind``) and the per-head
    table (distances of each used head, digitised and snapped, to the true centrelines).
    A head is ``snapped_on_gully`` within ``on_gully_m`` of its gully's true centreline
    (default 2 m: the 1 m matching window plus the widest head's half width, 0.75 m, rounded up).
    """
    g = cfg["gully"]
    crs = cfg["site"]["crs"]
    tol = float(g["validation"]["tolerance_m"])
    dem, grid = read_raster(site / "dense/dsm.tif")
    dem = np.asarray(dem, dtype=np.float32)
    twin = site / "twin"
    hx, hy = read_heads(str(twin / "observed/gully_heads.gpkg"), crs) if heads != "automatic" else (np.zeros(0), np.zeros(0))
    sz = dsm_noise_at_checkpoints(dem, grid, read_checkpoints(twin / "observed/checkpoints.csv"))
    ip = HeadDetectionParams.from_config(g["automatic_heads"], sz)
    auto = ip if heads != "digitised" else None
    params = GullyParams.from_config(g)
    ortho = None
    if params.crowns.enabled:  # gully.crowns: the orthophoto on the DSM grid
        from kitegully.gully.inputs import read_orthophoto_on_grid

        ortho = read_orthophoto_on_grid(site / "dense/orthophoto.tif", grid)
    res = map_gullies(dem, grid, hx, hy, params, workers=1, auto_heads=auto, incision=ip, ortho=ortho)
    # cells raised by the fill of the tracing surface (filled depressions and flats) and nodata
    _zh, zt, _n = tracing_surface(dem, grid, params, 1, ip, hidden=res.crowns)
    filled, _r = priority_flood_fill(zt, params.fill_epsilon_m if params.flat_routing == "epsilon" else 0.0)
    raised = np.isfinite(zt) & (filled > zt + 1e-6)
    nodata = ~np.isfinite(zt)
    del _zh, zt, filled
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
    # each used head as snapped (cell centre): distance to the nearest true centreline, and to its own gully's
    snapped = np.full((len(used), 2), np.nan)
    hc = res.network.head_cells[:len(used)]  # heads only: edge inlets are traced after them
    ok = hc >= 0
    snapped[ok] = grid.flat_xy(hc[ok])
    d_dig, i_dig = tree.query(used, k=1) if len(used) else (np.zeros(0), np.zeros(0, int))
    d_snap = np.full(len(used), np.nan)
    if ok.any():
        d_snap[ok] = tree.query(snapped[ok], k=1)[0]
    head_gully = np.where(d_dig <= reach, gid_of_vertex[i_dig] if len(used) else 0, -1)
    # distance of the snapped head to its own gully's centreline (the gully the digitised head belongs to)
    own = np.full(len(used), np.nan)
    for gid in np.unique(head_gully[head_gully >= 0]):
        sel = (head_gully == gid) & ok
        if sel.any():
            own[sel] = cKDTree(verts[gid_of_vertex == gid]).query(snapped[sel], k=1)[0]
    on_gully = own <= on_gully_m
    heads_tab = pd.DataFrame({"source": ["digitised"] * len(hx) + ["automatic"] * (len(used) - len(hx)),
                              "x": used[:, 0], "y": used[:, 1], "gully_id": head_gully,
                              "digitised_to_centreline_m": d_dig, "snapped_to_centreline_m": d_snap,
                              "snapped_to_own_gully_m": own, "snapped_on_gully": on_gully})
    snapped_on = {int(gid): bool(on_gully[head_gully == gid].any()) for gid in np.unique(head_gully[head_gully >= 0])}
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
        elif not snapped_on.get(int(gno[k]), False):
            reason[k] = "beside: head snapped off the gully"
        else:
            reason[k] = "beside: path leaves the gully"
    # where the unmapped traced cells lie on their path (nearest traced cell of each such sample)
    keep = res.gully if res.bridged is None else res.gully | res.bridged
    net = res.network
    where_cell = unmapped_position(net.cells, net.pos_down, keep.ravel()[net.cells])
    where = np.full(len(pts), "", dtype=object)
    tnm = np.flatnonzero(reason == "traced, not mapped")
    if tnm.size and net.cells.size:
        unm = np.flatnonzero(where_cell != "mapped")
        if unm.size:
            _d, ii = cKDTree(grid.flat_xy(net.cells[unm])).query(pts[tnm], k=1)
            where[tnm] = where_cell[unm][ii]
    tol_cells = int(np.ceil(tol / grid.cell))
    near_flat = _near(raised, tol_cells, pts, grid)
    near_nodata = _near(nodata, tol_cells, pts, grid, outside=True)
    kind_of_gully = cl.groupby("gully_id")["kind"].first() if "kind" in cl.columns else pd.Series(dtype=object)
    # true shrub or tree cells within 1 m of the sample (a crown over the gully hides its floor from the DSM)
    lc_path = twin / "truth/landcover.tif"
    near_object = np.zeros(len(pts), dtype=bool)
    if lc_path.exists():
        from kitegully.twin.landcover import CODE

        lc, _g = read_raster(lc_path)
        obj = np.isin(lc, [CODE["shrub"], CODE["tree"]])
        near_object = _near(obj, int(np.ceil(1.0 / grid.cell)), pts, grid)
        del lc, obj
    df = pd.DataFrame({"x": pts[:, 0], "y": pts[:, 1], "gully_no": gno, "reason": reason, "length_m": step, "near_flat": near_flat & miss,
                       "near_flat_any": near_flat, "near_object": near_object, "near_nodata": near_nodata & miss,
                       "traced_where": where, "kind": [kind_of_gully.get(int(i), "?") for i in gno]})
    tab = df.pivot_table(index="gully_no", columns="reason", values="length_m", aggfunc="sum", fill_value=0.0)
    heads_t = th.set_index("gully_id")
    first = cl.sort_values(["gully_id"]).groupby("gully_id").first()
    tab["bank"] = [heads_t["bank"].get(i, "valley") for i in tab.index]
    tab["head_depth_m"] = [first["depth_m"].get(i, np.nan) for i in tab.index]
    tab["head_width_m"] = [first["width_m"].get(i, np.nan) for i in tab.index]
    tab["heads_used"] = [len(head_s.get(int(i), [])) for i in tab.index]
    totals = df.groupby("reason")["length_m"].sum()
    if samples_out:
        return tab.reset_index(), totals, scores, res, df, heads_tab
    return tab.reset_index(), totals, scores, res


def unmapped_position(cells: np.ndarray, pos_down: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """Where each traced cell lies relative to the mapped cells of its path.

    Parameters
    ----------
    cells, pos_down : ndarray int64
        The traced network (:class:`kitegully.gully.network.GullyNetwork`).
    kept : ndarray bool
        Per traced cell: on the gully map.

    Returns
    -------
    ndarray of str
        ``mapped``, ``head reach``, ``gap``, ``tail`` or ``never mapped`` per traced cell.
        O(L) for L traced cells (:func:`kitegully.gully.network.topological_order`).
    """
    n = cells.size
    order, _indeg = topological_order(np.asarray(pos_down, dtype=np.int64))  # heads first
    up_mapped = np.zeros(n, dtype=bool)
    for i in order:
        j = pos_down[i]
        if j >= 0:
            up_mapped[j] |= up_mapped[i] | kept[i]
    down_mapped = np.zeros(n, dtype=bool)
    for i in order[::-1]:  # outlets first
        j = pos_down[i]
        if j >= 0:
            down_mapped[i] = kept[j] | down_mapped[j]
    out = np.full(n, "never mapped", dtype=object)
    out[up_mapped & down_mapped] = "gap"
    out[~up_mapped & down_mapped] = "head reach"
    out[up_mapped & ~down_mapped] = "tail"
    out[kept] = "mapped"
    return out


def _near(mask: np.ndarray, radius_cells: int, pts: np.ndarray, grid, outside: bool = False) -> np.ndarray:
    """True for points within ``radius_cells`` of a True cell of ``mask`` (off the grid counts when ``outside``)."""
    import cv2

    src = np.where(mask, 0, 1).astype(np.uint8)
    if outside:
        src = np.pad(src, 1, constant_values=0)
    dist = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    if outside:
        dist = dist[1:-1, 1:-1]
    r, c = grid.rowcol(pts[:, 0], pts[:, 1])
    r = np.clip(np.rint(r).astype(int), 0, mask.shape[0] - 1)
    c = np.clip(np.rint(c).astype(int), 0, mask.shape[1] - 1)
    return dist[r, c] <= radius_cells


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
