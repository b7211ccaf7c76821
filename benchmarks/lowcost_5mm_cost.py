"""What the low-cost survey at the paper's ~5 mm pixels costs (issue 18): measured on a few
full-size photos, extrapolated to the whole site.

    PYTHONPATH=src .venv/bin/python benchmarks/lowcost_5mm_cost.py \\
        --site config/sites/lowcost_twin.yaml --override config/sites/variants/lowcost_twin_5mm.yaml

Two phases, each its own process so that each peak memory (``ru_maxrss``) is its own:

``twin``   the ``lowcost_twin`` rule's work on the merged config: ground, texture, scene
           (the texture pyramid the renderer holds), then ``--photos`` RGB photos of the
           flight rendered at full size exactly as the rule renders them, written as JPEG.
``survey`` the ``lowcost_survey`` rule's heavy steps on those photos: image preparation and
           SIFT (the sfm stage's functions and keys), exhaustive matching of their pairs,
           the dense matcher on one ``survey.dense.tile_cells`` tile and an orthophoto on a
           window, both with the photos' TRUE poses (a stand-in for the SfM block: the
           cost of these steps depends on the geometry, not on who estimated it).

CPU times are user+sys of the process (all threads, ``getrusage``). The extrapolation to
the whole run multiplies the per-unit CPU by the site's counts (photos, pairs, tile-views,
mosaic cell-views) and takes what was not measured here (SfM mapping, the RTK bundle, the
OBIA maps, the spectral and evaluation rules) from the 1.95 cm run's numbers, scaled as
stated in the table. Truth is read only to place the camera poses (cost, not accuracy).
Writes ``<out>.csv`` and ``<out>.md``.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml


def load_config(site: str, override: str | None) -> dict:
    cfg = yaml.safe_load(Path(site).read_text())
    if override:
        from kitegully.config import merge_config
        cfg = merge_config(cfg, yaml.safe_load(Path(override).read_text()))
    return cfg


class Meter:
    """CPU (user+sys, all threads), wall and peak RSS of this process, per step."""

    def __init__(self) -> None:
        self.rows: list[dict] = []

    @staticmethod
    def _now() -> tuple[float, float]:
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime, time.perf_counter()

    def start(self) -> None:
        self._c0, self._w0 = self._now()

    def stop(self, phase: str, step: str, units: int, unit: str, **extra) -> dict:
        c, w = self._now()
        row = {"phase": phase, "step": step, "units": units, "unit": unit, "cpu_s": c - self._c0, "wall_s": w - self._w0,
               "cpu_per_unit_s": (c - self._c0) / max(units, 1),
               "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6, **extra}
        self.rows.append(row)
        print(json.dumps(row), flush=True)
        return row


def pick_photos(n_per_line: int, count: int) -> list[int]:
    """Indices of ``count`` RGB photos around the middle of the strip, half from each line
    (line 1 is flown back, so its index runs the other way)."""
    half = max(1, count // 2)
    mid = n_per_line // 2 - half // 2
    first = list(range(mid, mid + half))
    second = [n_per_line + (n_per_line - 1 - j) for j in first]
    return (first + second)[:count]


def phase_twin(cfg: dict, seed: int, out: Path, count: int, meter: Meter) -> None:
    from kitegully.lowcost import spectral as sp
    from kitegully.lowcost.twin_site import (LowcostTwinParams, camera_weights, flight_poses, make_camera, make_ground,
                                             make_texture, render_photo, target_layout)
    from kitegully.twin.exif import exif_bytes, write_jpeg
    from kitegully.twin.render import Photographic, make_scene
    from datetime import datetime, timezone

    p = LowcostTwinParams.from_config(cfg["lowcost"]["twin"])
    meter.start()
    grid, terrain, surface, cls = make_ground(p, seed)
    meter.stop("twin", "ground (DSM grid)", int(surface.size), "cell")
    meter.start()
    tex, tcell = make_texture(p, grid, cls, target_layout(p, seed), seed)
    n_tex = int(tex[0].size)
    meter.stop("twin", "texture (4 bands, uint8)", n_tex, "cell", texture_cell_m=tcell, texture_gb=tex.nbytes / 1e9)
    meter.start()
    scene = make_scene(surface, (grid.x0, grid.y0), grid.cell, tex, (grid.x0, grid.y0), tcell)
    del tex
    meter.stop("twin", "scene (texture pyramid)", n_tex, "cell", pyramid_gb=scene.tex.nbytes / 1e9)
    wl = np.arange(400.0, 901.0, 5.0)
    W = camera_weights(wl, sp.illuminant("D65", wl))
    W = {k: v / v.sum(axis=1).max() for k, v in W.items()}
    effects = Photographic.from_config(p.photographic)
    camera = make_camera(p.camera, "NEX-5")
    zmed = float(np.median(surface))
    poses = flight_poses(p, "rgb", seed, zmed)
    picks = pick_photos(len(poses) // 2, count)
    rng = np.random.default_rng(seed)
    (out / "images").mkdir(parents=True, exist_ok=True)
    rows = []
    ss = int(p.flight["supersampling"])
    for i in picks:
        meter.start()
        img = render_photo(scene, camera, poses[i], W["rgb"], effects, rng, ss)
        name = f"rgb_{i:03d}.jpg"
        write_jpeg(out / "images" / name, img, exif_bytes(camera, datetime(2012, 2, 14, tzinfo=timezone.utc),
                                                          effects.exposure_time_s), 95)
        meter.stop("twin", f"photo {name} ({camera.width} x {camera.height} px, {ss}x{ss} rays/px)", 1, "photo")
        P = poses[i]
        rows.append({"name": name, "R": P.R.tolist(), "C": P.C.tolist()})
    meter.start()
    render_photo(scene, camera, poses[picks[0]], W["rgb"], effects, rng, 1)
    meter.stop("twin", "photo, 1x1 ray/px (for comparison; not written)", 1, "photo")
    all_poses = [{"R": q.R.tolist(), "C": q.C.tolist()} for q in poses]
    (out / "poses.json").write_text(json.dumps({"picked": rows, "rgb_flight": all_poses, "zmed": zmed,
                                                "camera": {"w": camera.width, "h": camera.height, "f": camera.f,
                                                           "cx": camera.cx, "cy": camera.cy, "k1": camera.k1},
                                                "surface_grid": [grid.x0, grid.y0, grid.cell, grid.width, grid.height]}))
    np.save(out / "surface.npy", surface)


def phase_survey(cfg: dict, seed: int, out: Path, meter: Meter) -> None:
    from kitegully.dense.matching import MatchParams
    from kitegully.dense.ortho import orthophoto
    from kitegully.dense.surface import dense_surface
    from kitegully.dense.views import OrientedImage, ViewSet
    from kitegully.io.raster import GridSpec
    from kitegully.lowcost.stage import SurveyParams
    from kitegully.sfm import SfmParams
    from kitegully.sfm.images import list_images, prepare_images
    from kitegully.sfm.feature_cap import cap_features
    from kitegully.sfm.reconstruct import extract_features, match_features

    lc = cfg["lowcost"]
    sfm = SfmParams.from_config(lc["sfm"])
    sv = SurveyParams.from_config(lc["survey"])
    info = json.loads((out / "poses.json").read_text())
    n = len(info["picked"])
    work = out / "sfm"
    work.mkdir(exist_ok=True)
    meter.start()
    infos = prepare_images(list_images(out / "images"), work / "images", sfm.max_image_size, sfm.image_frame,
                           sfm.skip_unreadable, sfm.jpeg_quality)
    meter.stop("survey", "prepare images (JPEG re-encode)", n, "photo")
    db = work / "database.db"
    if db.exists():
        db.unlink()
    meter.start()
    extract_features(db, work / "images", infos, sfm.camera_model, sfm.default_focal_factor, sfm.max_num_features, 1,
                     sfm.first_octave)
    capped = cap_features(db, sfm.max_num_features)
    meter.stop("survey", "SIFT + feature cap (1 thread)", n, "photo", keypoints_before=capped["keypoints_before"],
               keypoints_after=capped["keypoints_after"])
    meter.start()
    match_features(db, n, "exhaustive", sfm.matching.overlap, 10**6, 1, seed=seed)
    meter.stop("survey", "exhaustive matching + verification (1 thread)", n * (n - 1) // 2, "pair")
    # dense and ortho on the true poses
    cam = info["camera"]
    x0, y0, cell, gw, gh = info["surface_grid"]
    surface = np.load(out / "surface.npy")
    offset = np.array([round(x0 + gw * cell / 2), round(y0 - gh * cell / 2), 0.0])
    imgs = [OrientedImage(r["name"], str(out / "images" / r["name"]), cam["w"], cam["h"], cam["f"], cam["cx"], cam["cy"],
                          cam["k1"], 0.0, np.array(r["R"]), np.array(r["C"]) - offset) for r in info["picked"]]
    Cs = np.array([r["C"] for r in info["picked"]])
    cx, cy = float(np.median(Cs[:, 0])), float(np.median(Cs[:, 1]))
    d = sv.dense
    T = d["tile_cells"]
    dcell = sv.dsm_cell_m
    grid = GridSpec(cx - T * dcell / 2, cy + T * dcell / 2, dcell, T, T, "")
    # the true surface's cells in the tile, as stand-in tie points (they bound the z search)
    ys, xs = np.mgrid[0:surface.shape[0]:4, 0:surface.shape[1]:4]
    X = x0 + (xs + 0.5) * cell
    Y = y0 - (ys + 0.5) * cell
    pts = np.column_stack([X.ravel(), Y.ravel(), surface[ys, xs].ravel()]) - offset
    views = ViewSet(imgs, offset, pts)
    mp: MatchParams = d["matching"]
    # two sizes of each step: the difference is the cost per cell-view, the rest is fixed
    # (reading and decoding the photos, building their pyramids)
    res = None
    for side in (T // 8, T // 2, T):             # the first (not recorded) loads the compiled kernels
        g = GridSpec(cx - side * dcell / 2, cy + side * dcell / 2, dcell, side, side, "")
        meter.start()
        r = dense_surface(views, g, mp, side, d["overlap_cells"], d["max_cached_images"])
        if side == T // 8:
            continue
        meter.stop("survey", f"dense matcher, one {side} x {side} tile at {dcell} m, {n} views",
                   (side + 2 * d["overlap_cells"]) ** 2 * n, "cell-view", matched_share=float(np.isfinite(r.dsm).mean()))
        res, grid = (r, g) if side == T else (res, grid)
    for q in (T // 16, T // 8, T // 4):           # the first (not recorded) loads the compiled kernels
        wg = GridSpec(cx - q * dcell / 2, cy + q * dcell / 2, dcell, q, q, "")
        r0 = int(round((grid.y0 - wg.y0) / dcell))
        c0 = int(round((wg.x0 - grid.x0) / dcell))
        dsm_w = np.where(np.isfinite(res.dsm), res.dsm, np.nanmedian(res.dsm))[r0:r0 + q, c0:c0 + q]
        meter.start()
        img, og, src = orthophoto(views, dsm_w.astype(np.float32), wg, upsample=sv.ortho_upsample, tile_cells=1024,
                                  overlap_m=2.0, occlusion_tolerance_m=sv.occlusion_tolerance_m)
        if q == T // 16:
            continue
        meter.stop("survey", f"orthophoto window {og.width} x {og.height} cells at {og.cell} m, {n} views",
                   og.width * og.height * n, "cell-view", filled=float((src >= 0).mean()))


def upper_per_unit(rows: pd.DataFrame, start: str) -> tuple[float, float, float]:
    """(CPU per unit, smaller CPU, larger CPU) of a step run at two sizes. At these sizes the
    step's CPU hardly grows with the cells (it is mostly reading, decoding and pyramiding
    the photos, a fixed cost per call), so the larger run's CPU over its units, reads
    included, is an UPPER bound of the cost per unit."""
    r = rows[rows.step.str.startswith(start)].sort_values("units")
    (u1, c1), (u2, c2) = r[["units", "cpu_s"]].to_numpy()[[0, -1]]
    return c2 / u2, c1, c2


def frame_counts(cfg: dict, out: Path) -> dict:
    """Per DSM tile and per mosaic cell: how many RGB photos of the whole flight see it
    (true poses, flat ground at the median height; for the extrapolation only)."""
    info = json.loads((out / "poses.json").read_text())
    cam = info["camera"]
    lc = cfg["lowcost"]
    p = lc["twin"]
    sv = lc["survey"]
    x0, y0 = p["origin_xy"]
    L, Wd = p["length_m"], p["width_m"]
    z = info["zmed"]

    def sees(pose, X):
        R, C = np.array(pose["R"]), np.array(pose["C"])
        Xc = (X - C) @ R.T
        u = cam["f"] * Xc[:, 0] / Xc[:, 2] + cam["cx"]
        v = cam["f"] * Xc[:, 1] / Xc[:, 2] + cam["cy"]
        return (Xc[:, 2] > 0) & (u >= 0) & (u < cam["w"]) & (v >= 0) & (v < cam["h"])

    # mosaic cells sampled every 0.25 m
    gx, gy = np.meshgrid(np.arange(x0 + 0.125, x0 + L, 0.25), np.arange(y0 + 0.125, y0 + Wd, 0.25))
    X = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
    per_cell = sum(sees(q, X).astype(int) for q in info["rgb_flight"])
    # DSM tiles (tile plus overlap): photos whose frame meets any of its sample points
    T, O, cell = sv["dense"]["tile_cells"], sv["dense"]["overlap_cells"], sv["dsm_cell_m"]
    side = T * cell
    tiles = []
    for tx in np.arange(x0, x0 + L, side):
        for ty in np.arange(y0, y0 + Wd, side):
            a = np.linspace(-O * cell, side + O * cell, 9)
            px, py = np.meshgrid(tx + a, ty + a)
            Xt = np.column_stack([px.ravel(), py.ravel(), np.full(px.size, z)])
            tiles.append(sum(int(sees(q, Xt).any()) for q in info["rgb_flight"]))
    return {"views_per_mosaic_cell_mean": float(per_cell.mean()), "tile_views": tiles, "n_tiles": len(tiles),
            "tile_cells_with_overlap": (T + 2 * O) ** 2}


def extrapolate(cfg: dict, rows: pd.DataFrame, counts: dict) -> pd.DataFrame:
    """Whole 5 mm run from the per-unit CPU (extrapolation; see the module docstring)."""
    lc = cfg["lowcost"]
    p = lc["twin"]
    n_line = len(np.arange(-p["flight"]["overrun_m"], p["length_m"] + p["flight"]["overrun_m"] + 1e-9, p["flight"]["spacing_m"]))
    n_photos = 2 * n_line * len(p["flight"]["lines_y_frac"])
    pairs = n_photos * (n_photos - 1) // 2

    def per(key_start: str) -> float:
        return float(np.mean([r["cpu_per_unit_s"] for r in rows.to_dict("records") if r["step"].startswith(key_start)]))

    cell = lc["survey"]["dsm_cell_m"]
    mosaic_cells = (p["length_m"] / (cell / lc["survey"]["ortho_upsample"])) * (p["width_m"] / (cell / lc["survey"]["ortho_upsample"]))
    tile_cell_views = sum(counts["tile_views"]) * counts["tile_cells_with_overlap"]
    dense_u, dense_1, dense_2 = upper_per_unit(rows, "dense")
    ortho_u, ortho_1, ortho_2 = upper_per_unit(rows, "orthophoto")
    out = [
        ("twin: ground + texture + scene", 1, "site", per("ground") * 1 + rows.loc[rows.step.str.startswith("texture"), "cpu_s"].sum()
         + rows.loc[rows.step.str.startswith("scene"), "cpu_s"].sum(), "measured once (the whole site's texture)"),
        ("twin: photos", n_photos, "photo", n_photos * per("photo rgb"), "per-photo CPU x photos (RGB and NIR cost the same)"),
        ("survey: prepare + SIFT", n_photos, "photo", n_photos * (per("prepare") + per("SIFT")), "per-photo CPU x photos"),
        ("survey: exhaustive matching", pairs, "pair", pairs * per("exhaustive"),
         "per-pair CPU x pairs (overlapping pairs cost more than the 1.95 cm run's mix of overlapping and disjoint ones)"),
        ("survey: SfM mapping", n_photos, "photo", 143.0, "NOT measured: the 1.95 cm run's 143 s wall (1 thread) for the same "
         "56 photos and the same 4096-feature cap"),
        ("survey: dense DSM", tile_cell_views, "cell-view", tile_cell_views * dense_u,
         f"UPPER bound: {dense_u * 1e6:.2f} us per cell-view (the larger tile's CPU {dense_2:.2f} s, photo reads included; "
         f"the tile of 1/4 the cells took {dense_1:.2f} s) x {counts['n_tiles']} tiles x (tile+overlap)^2 x RGB photos "
         f"meeting each tile (mean {np.mean(counts['tile_views']):.1f})"),
        ("survey: two 5 mm mosaics", int(2 * mosaic_cells * counts["views_per_mosaic_cell_mean"]), "cell-view",
         2 * mosaic_cells * counts["views_per_mosaic_cell_mean"] * ortho_u,
         f"UPPER bound: {ortho_u * 1e6:.2f} us per cell-view (the larger window's CPU {ortho_2:.2f} s, photo reads included; "
         f"the window of 1/4 the cells took {ortho_1:.2f} s) x 2 x {mosaic_cells / 1e6:.1f} M cells x "
         f"{counts['views_per_mosaic_cell_mean']:.1f} photos per cell; the 1.95 cm run's 4.3 us per cell (28 views, "
         f"wall) would give {2 * mosaic_cells * 4.3e-6:.0f} s"),
        ("rtk bundle", 1, "run", 75.0, "NOT measured: the 1.95 cm run's 75 s CPU (same photos, tie points capped at 5000)"),
        ("bare soil: two OBIA maps", int(2 * mosaic_cells), "cell", 2 * mosaic_cells * 6e-6,
         "NOT measured: the 1.95 cm run's ~6 us per cell (README) x cells"),
        ("spectral + evaluation", 1, "run", 30.0, "NOT measured: the 1.95 cm run's ~20 s + a few s (independent of the pixel)"),
    ]
    df = pd.DataFrame(out, columns=["part", "units", "unit", "cpu_s_extrapolated", "how"])
    df.loc[len(df)] = ["total", n_photos, "photo", df["cpu_s_extrapolated"].sum(), "sum (extrapolation)"]
    return df


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--site", default="config/sites/lowcost_twin.yaml")
    ap.add_argument("--override", default="config/sites/variants/lowcost_twin_5mm.yaml")
    ap.add_argument("--photos", type=int, default=6)
    ap.add_argument("--work", default="results/benchmarks/lowcost_5mm_work")
    ap.add_argument("--out", default="results/benchmarks/lowcost_5mm_cost")
    ap.add_argument("--phase", choices=["all", "twin", "survey"], default="all")
    ap.add_argument("--skip-twin", action="store_true", help="reuse the twin phase's photos and table in --work")
    ap.add_argument("--report-only", action="store_true", help="only redo the tables from the CSVs in --work")
    a = ap.parse_args(argv)
    cfg = load_config(a.site, a.override)
    seed = int(cfg["seed"])
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    if a.phase != "all":
        meter = Meter()
        phase_twin(cfg, seed, work, a.photos, meter) if a.phase == "twin" else phase_survey(cfg, seed, work, meter)
        pd.DataFrame(meter.rows).to_csv(work / f"{a.phase}.csv", index=False)
        return 0
    for phase in () if a.report_only else ("survey",) if a.skip_twin else ("twin", "survey"):
        subprocess.run([sys.executable, __file__, "--site", a.site, "--override", a.override, "--photos", str(a.photos),
                        "--work", str(work), "--phase", phase], check=True)
    rows = pd.concat([pd.read_csv(work / "twin.csv"), pd.read_csv(work / "survey.csv")], ignore_index=True)
    counts = frame_counts(cfg, work)
    ext = extrapolate(cfg, rows, counts)
    out = Path(a.out)
    rows.to_csv(out.with_suffix(".csv"), index=False)
    ext.to_csv(out.with_name(out.name + "_extrapolated.csv"), index=False)
    md = ["# Low-cost survey at ~5 mm pixels: measured steps (this machine, loaded) and the whole run (extrapolated)", "",
          f"Config: {a.site} + {a.override}. CPU = user+sys of the step's process (all threads).", "",
          "## Measured", "", rows.to_markdown(index=False, floatfmt=".3g"), "",
          "## Whole run: EXTRAPOLATION from the per-unit CPU above", "", ext.to_markdown(index=False, floatfmt=".4g"), "",
          f"Frame counts (true poses, flat ground): {json.dumps(counts)}", ""]
    out.with_suffix(".md").write_text("\n".join(md))
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
