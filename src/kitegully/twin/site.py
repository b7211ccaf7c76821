"""The twin site: configuration, planning and the tiled generator of one epoch.

:func:`build_site` plans everything global and cheap (valley, field layout, gully network
on a coarse tracing grid, buildings). :func:`generate_epoch` then streams the DEM grid in
tiles (``tile_cells``): each tile's DTM, DSM and land cover are computed from the plan
alone, so memory stays at a few tiles whatever the site size. GCPs and checkpoints are
chosen on the written rasters; the texture is a second tiled pass.
"""

from __future__ import annotations

import copy
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import geopandas as gpd
import numpy as np
import pandas as pd
import rasterio
from rasterio.windows import Window
from scipy.spatial import cKDTree

from kitegully import InputError
from kitegully.config import config_section
from kitegully.io.raster import GridSpec, Raster, _profile
from kitegully.io.tables import write_table
from kitegully.io.vectors import write_vector
from kitegully.seeds import rng_for
from kitegully.twin import epochs, gullies as gl, landcover as lcm, survey, targets as tg, texture as tx
from kitegully.twin.gully_truth import centrelines, heads, polygons
from kitegully.twin.noise import fbm_grid
from kitegully.twin.terrain import Valley, pregully_grid, relief_octaves, valley_from_config

log = logging.getLogger(__name__)

TRUTH_FILES = ["dtm.tif", "dsm.tif", "landcover.tif", "landcover_classes.csv", "texture.tif", "targets.csv",
               "gully_centrelines.gpkg", "gully_polygons.gpkg", "gully_heads.gpkg", "checkpoints.csv", "site_statistics.csv"]
OBSERVED_FILES = ["gcp_survey.csv", "checkpoints.csv", "field_network.gpkg", "gully_heads.gpkg"]


def sub_seed(seed: int, *names: str) -> int:
    """Integer seed for a noise field, derived from the master seed and names."""
    return int(rng_for(seed, "twin", *names).integers(0, 2**31 - 1))


#: ``twin`` keys that planning a site needs (:func:`build_site` of epoch 1, ``site.json``).
PLAN_KEYS = ("extent", "dem_cell_m", "texture_cell_m", "site_json_elevation_step_m", "terrain", "reservoir", "fields",
             "gullies", "landcover")
#: ``twin`` keys that writing an epoch needs besides the plan (:func:`generate_epoch`).
EPOCH_KEYS = ("tile_cells", "texture_tile_cells", "texture", "targets", "survey")
#: ``twin`` keys of the second epoch's erosion.
EPOCH2_KEYS = ("epoch2",)


def _frozen(group: Any) -> Mapping[str, Any]:
    """Read-only copy of a config group (its top-level keys cannot be rebound)."""
    return MappingProxyType(copy.deepcopy(dict(group)))


@dataclass(frozen=True)
class TwinParams:
    """Parameters of the twin (the ``twin`` config section, or the part a rule passes).

    The top-level groups are documented key by key in
    ``config/schema/stages/twin.schema.yaml`` and read by the modules named below; here they
    are read-only mappings. Rules pass only what they use: ``site.json`` the plan
    (:data:`PLAN_KEYS`), epoch 1 also :data:`EPOCH_KEYS`, epoch 2 also ``epoch2``.

    Attributes
    ----------
    extent : Mapping
        ``xmin, ymin, width_m, height_m`` of the site in its CRS (m).
    dem_cell_m : float
        Cell of the truth DTM/DSM and land cover (m).
    texture_cell_m : float
        Cell of the texture; divides ``dem_cell_m`` by a whole factor of at least 2 (m).
    site_json_elevation_step_m : float
        ``site.json`` rounds the elevation range to this step (m).
    terrain, reservoir : Mapping
        Valley, banks, micro-relief and the dam lake (``twin.terrain``).
    fields : Mapping
        Field layout, tillage (``twin.landcover.Fields``).
    gullies : Mapping
        Gully heads, tracing, shapes (``twin.gullies``).
    landcover : Mapping
        Tracks, buildings, trees, shrubs, bare patches (``twin.landcover``).
    tile_cells, texture_tile_cells : int or None
        Tile side of the DEM and texture passes (cells); None when the rule only plans.
    texture : Mapping or None
        Reflectance (``twin.texture``).
    targets : Mapping or None
        GCP targets (``twin.targets``).
    survey : Mapping or None
        RTK survey, checkpoints, field network, digitised heads (``twin.survey``).
    epoch2 : Mapping or None
        Second-epoch erosion (``twin.epochs``); None for epoch 1.
    """

    extent: Mapping[str, Any]
    dem_cell_m: float
    texture_cell_m: float
    site_json_elevation_step_m: float
    terrain: Mapping[str, Any]
    reservoir: Mapping[str, Any]
    fields: Mapping[str, Any]
    gullies: Mapping[str, Any]
    landcover: Mapping[str, Any]
    tile_cells: int | None = None
    texture_tile_cells: int | None = None
    texture: Mapping[str, Any] | None = None
    targets: Mapping[str, Any] | None = None
    survey: Mapping[str, Any] | None = None
    epoch2: Mapping[str, Any] | None = None

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "TwinParams":
        """Build from the ``twin`` section (or its plan / epoch keys); raises InputError naming a bad key.

        Checks the keys and what the schema cannot express: the texture cell divides the
        DEM cell by a whole factor of at least 2, the extent spans at least 20 DEM cells,
        and the epoch keys come all together.
        """
        config_section(cfg, "twin", PLAN_KEYS, optional=EPOCH_KEYS + EPOCH2_KEYS)
        given = [k for k in EPOCH_KEYS if k in cfg]
        if given and len(given) < len(EPOCH_KEYS):
            raise InputError(f"twin: missing key '{[k for k in EPOCH_KEYS if k not in cfg][0]}' (the epoch keys "
                             f"{', '.join(EPOCH_KEYS)} come together)")
        config_section(cfg["extent"], "twin.extent", ("xmin", "ymin", "width_m", "height_m"))
        check_config(cfg)
        groups = ("terrain", "reservoir", "fields", "gullies", "landcover", "texture", "targets", "survey", "epoch2")
        return cls(**{k: (_frozen(cfg[k]) if k in groups + ("extent",) else cfg[k]) for k in cfg})

    @property
    def tex_factor(self) -> int:
        """Texture cells per DEM cell side."""
        return int(round(self.dem_cell_m / self.texture_cell_m))

    def require(self, names: tuple[str, ...], what: str) -> None:
        """Raise InputError when one of ``names`` was not passed (None)."""
        missing = [n for n in names if getattr(self, n) is None]
        if missing:
            raise InputError(f"twin.{missing[0]}: needed to {what} but not in the parameters the rule passed")


@dataclass
class TwinSite:
    """Everything planned for one epoch of a twin site (``tw``: its parameters)."""

    tw: TwinParams
    crs: str
    seed: int
    epoch: int
    grid: GridSpec
    tex_factor: int
    valley: Valley
    fields: lcm.Fields
    network: list[gl.Gully]
    segs: gl.Segments
    buildings: list[dict]
    wl: np.ndarray
    amp: np.ndarray
    z_trace_range: tuple[float, float]
    retreat: dict = field(default_factory=dict)

    @property
    def tex_grid(self) -> GridSpec:
        """The texture grid: the DEM grid refined by ``tex_factor``."""
        return self.grid.refined(self.tex_factor)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the DEM grid in map units."""
        return self.grid.bounds


def check_config(tw: Mapping[str, Any], source: str = "twin") -> int:
    """Cross-key checks the schema cannot express (on the ``twin`` section); returns the texture factor."""
    ratio = tw["dem_cell_m"] / tw["texture_cell_m"]
    k = int(round(ratio))
    if k < 2 or abs(ratio - k) > 1e-6:
        raise InputError(f"{source}: twin.texture_cell_m ({tw['texture_cell_m']}) must divide twin.dem_cell_m "
                         f"({tw['dem_cell_m']}) by a whole factor of at least 2")
    e = tw["extent"]
    if e["width_m"] < 20 * tw["dem_cell_m"] or e["height_m"] < 20 * tw["dem_cell_m"]:
        raise InputError(f"{source}: twin.extent is smaller than 20 DEM cells")
    return k


def build_site(tw: TwinParams, crs: str, seed: int, epoch: int = 1) -> TwinSite:
    """Plan a twin site: valley, fields, gully network (epoch 2: eroded), buildings.

    Parameters
    ----------
    tw : TwinParams
        The twin's parameters (the plan keys; ``epoch2`` too for epoch 2).
    crs : str
        Site CRS.
    seed : int
        Master seed.
    epoch : int
        1 or 2.

    Returns
    -------
    TwinSite
        The plan that :func:`generate_epoch` and :func:`write_site_json` write out.
    """
    if epoch == 2:
        tw.require(EPOCH2_KEYS, "plan epoch 2")
    k = tw.tex_factor
    e = tw.extent
    cell = tw.dem_cell_m
    W = int(round(e["width_m"] / cell))
    H = int(round(e["height_m"] / cell))
    grid = GridSpec(e["xmin"], e["ymin"] + H * cell, cell, W, H, crs)
    valley = valley_from_config(tw, grid.bounds)
    fields = lcm.Fields.from_config(tw.fields, sub_seed(seed, "fields"))
    wl, amp = relief_octaves(tw)
    t = tw.terrain
    tcell = t["trace_cell_m"]
    tgrid = grid.resampled(tcell, cover=True)
    txs, tys = tgrid.cell_centres()
    keep = wl >= t["trace_min_wavelength_m"]
    z_trace = pregully_grid(valley, txs, tys, sub_seed(seed, "relief"), wl[keep], amp[keep])
    gcfg = tw.gullies
    network = gl.plan_network(valley, fields, gcfg, grid.bounds, z_trace, tgrid, seed)
    retreat, widen = {}, None
    if epoch == 2:
        gl.assign_attributes(network, gcfg, valley, seed)  # epoch-1 attributes decide which heads have a headcut
        retreat = epochs.retreat_heads(network, tw.epoch2, seed)
        widen = epochs.widening(network, tw.epoch2, seed)
    gl.assign_attributes(network, gcfg, valley, seed, widen)
    segs = gl.Segments.from_network(network, gcfg["u_shape_exponent"])
    buildings = place_buildings(tw.landcover["buildings"], valley, fields, network, z_trace, tgrid, seed)
    log.info("planned epoch %d: %d x %d cells, %d gullies + wadi, %d buildings", epoch, W, H, len(network) - 1, len(buildings))
    return TwinSite(tw, crs, seed, epoch, grid, k, valley, fields, network, segs, buildings, wl, amp,
                    (float(np.nanmin(z_trace)), float(np.nanmax(z_trace))), retreat)


def place_buildings(bcfg: dict, valley: Valley, fields: lcm.Fields, network: list[gl.Gully], z_trace: np.ndarray,
                    tgrid: GridSpec, seed: int) -> list[dict]:
    """Farm buildings on gentle ground of the banks, away from gullies and each other.

    Parameters
    ----------
    bcfg : mapping
        ``twin.landcover.buildings``: count, spacing, clearance, slope limit, size ranges (m).
    valley : Valley
        The valley.
    fields : Fields
        The field layout; buildings stay off the valley floor and its margin.
    network : list of Gully
        The gully network, kept ``gully_clearance_m`` away.
    z_trace : ndarray
        Pre-gully surface (m) on ``tgrid``.
    tgrid : GridSpec
        The tracing grid.
    seed : int
        Master seed.

    Returns
    -------
    list of dict
        Per building: ``x``, ``y``, ``length_m``, ``width_m``, ``angle_rad``, ``height_m``, ``roof_z``
        (m); at most ``count``, from 200 tries.
    """
    rng = rng_for(seed, "twin", "buildings")
    if bcfg["count"] == 0:
        return []
    pts = np.concatenate([np.column_stack([g.x, g.y]) for g in network if len(g.x)])
    tree = cKDTree(pts)
    gy_r, gx = np.gradient(z_trace, tgrid.cell)
    slope = np.degrees(np.arctan(np.hypot(gx, gy_r)))
    xmin, ymin, xmax, ymax = tgrid.bounds
    out: list[dict] = []
    m = bcfg["edge_margin_m"]
    for _ in range(200):
        if len(out) >= bcfg["count"]:
            break
        x, y = rng.uniform(xmin + m, xmax - m), rng.uniform(ymin + m, ymax - m)
        r, c = tgrid.rowcol(x, y)
        ri, ci = int(round(float(r))), int(round(float(c)))
        u, vp = valley.u_vp(x, y)
        if abs(vp) < valley.floor_half_width + fields.floor_margin or valley.lake_zone(u) and z_trace[ri, ci] < valley.water_level + 2:
            continue
        if slope[ri, ci] > bcfg["max_slope_deg"] or tree.query([x, y])[0] < bcfg["gully_clearance_m"]:
            continue
        if any(np.hypot(b["x"] - x, b["y"] - y) < bcfg["min_spacing_m"] for b in out):
            continue
        L = rng.uniform(*bcfg["length_m"])
        Wd = rng.uniform(*bcfg["width_m"])
        h = rng.uniform(*bcfg["height_m"])
        ang = np.arctan2(valley.flow[1], valley.flow[0]) + rng.normal(0, np.deg2rad(10))
        out.append({"x": float(x), "y": float(y), "length_m": L, "width_m": Wd, "angle_rad": float(ang),
                    "height_m": h, "roof_z": float(z_trace[ri, ci] + h + bcfg["foundation_m"])})
    return out


# ---------------------------------------------------------------------------- tiles
@dataclass
class Tile:
    """Rasters of one tile of a twin site (:func:`compute_tile`).

    Attributes
    ----------
    dtm : ndarray float32
        Ground elevation (m): relief, field banks, gullies and furrows (epoch 2: sheet erosion too).
    dsm : ndarray float32
        Surface elevation (m): the ground plus shrubs, trees and roofs; the water level on water.
    lc : ndarray uint8
        Land-cover codes (:data:`kitegully.twin.landcover.CODE`).
    phase : ndarray float32
        Coordinate across the furrows (m), :func:`kitegully.twin.landcover.furrow_phase`.
    """

    dtm: np.ndarray
    dsm: np.ndarray
    lc: np.ndarray
    phase: np.ndarray


def compute_tile(site: TwinSite, r0: int, c0: int, nrow: int, ncol: int) -> Tile:
    """DTM, DSM, land cover and furrow phase for rows r0.., cols c0.. (may extend outside).

    Complexity O(cells·octaves + Σ nearby gully segment boxes).

    Parameters
    ----------
    site : TwinSite
        The planned site.
    r0, c0 : int
        First row and column on the DEM grid.
    nrow, ncol : int
        Tile size (cells).

    Returns
    -------
    Tile
    """
    tw, g, v, f = site.tw, site.grid, site.valley, site.fields
    xs, ys = g.cell_centres(r0, c0, nrow, ncol)
    X, Y = xs[None, :], ys[:, None]
    u, vp = v.u_vp(X, Y)
    z = v.base(X, Y) + fbm_grid(xs - v.cx, ys - v.cy, sub_seed(site.seed, "relief"), site.wl, site.amp)
    pi = lcm.plot_index(v, f, u, vp)
    gcfg = tw.gullies
    buf = gcfg["zone_buffer_m"]
    depth, rim = gl.carve(site.segs, g.window(r0, c0, nrow, ncol), buf)
    z = z + lcm.field_humps(f, pi) * np.clip(rim / f.hump_clearance, 0.0, 1.0) - depth
    lcfg = tw.landcover
    # --- classes, lowest priority first
    lc = lcm.plot_class(f, pi)
    strip = rim < buf
    nb = lcm.noise01(xs - v.cx, ys - v.cy, sub_seed(site.seed, "bare"), lcfg["bare_patches"]["wavelength_m"])
    mix = np.where(nb > lcfg["bare_patches"]["threshold"], lcm.CODE["bare_eroded"], lcm.CODE["grass"]).astype(np.uint8)
    lc = np.where((lc == 0) | strip, mix, lc)
    sc = lcfg["shrubs"]
    ns = lcm.noise01(xs - v.cx, ys - v.cy, sub_seed(site.seed, "shrubs"), sc["wavelength_m"])
    thr = np.where(strip, sc["threshold_gully"], np.where(lc == lcm.CODE["ploughed"], np.inf, sc["threshold_open"]))
    shrub_h = sc["height_m"] * np.sqrt(np.clip((ns - thr) / sc["ramp"], 0.0, 1.0))
    shrub_h = np.where(rim < 0, 0.0, shrub_h)
    shrub = shrub_h > sc["min_height_fraction"] * sc["height_m"]
    track = lcm.track_mask(v, lcfg["tracks"], u, vp)
    gully = depth > gcfg["class_min_depth_m"]
    trees = lcm.tree_heights(f, lcfg["trees"], pi, u)
    tree = (trees > lcfg["trees"]["min_height_m"]) & ~strip & ~track
    roof = lcm.building_heights(site.buildings, X, Y)
    building = np.isfinite(roof)
    water = (z < v.water_level) & v.lake_zone(u) & ~building
    lc = np.where(shrub & ~track, lcm.CODE["shrub"], lc)
    lc = np.where(track, lcm.CODE["track"], lc)
    lc = np.where(gully, lcm.CODE["gully"], lc)
    lc = np.where(tree & ~gully, lcm.CODE["tree"], lc)
    lc = np.where(building, lcm.CODE["building"], lc)
    lc = np.where(water, lcm.CODE["water"], lc).astype(np.uint8)
    phase = lcm.furrow_phase(f, pi, u)
    # furrows are ridges (>= 0) on ploughed plots outside gully strips, so erosion never raises them
    furrowed = (lcm.plot_class(f, pi) == lcm.CODE["ploughed"]) & ~strip & ~track & ~building & ~water
    z = z + np.where(furrowed, 0.5 * f.furrow_amplitude * (1.0 + np.sin(2 * np.pi * phase / f.furrow_period)), 0.0)
    if site.epoch == 2:
        e2 = tw.epoch2
        codes = [lcm.CODE[c] for c in e2["sheet_erosion_classes"]]
        lower = epochs.sheet_erosion(xs - v.cx, ys - v.cy, e2, sub_seed(site.seed, "sheet"))
        z = z - np.where(np.isin(lc, codes), lower, 0.0)
    obj = np.where(lc == lcm.CODE["shrub"], shrub_h, 0.0) + np.where(lc == lcm.CODE["tree"], trees, 0.0)
    dsm = z + obj
    dsm = np.where(building, np.maximum(roof, z), dsm)
    dsm = np.where(lc == lcm.CODE["water"], v.water_level, dsm)
    return Tile(z.astype(np.float32), dsm.astype(np.float32), lc, phase.astype(np.float32))


def _tiles(height: int, width: int, size: int):
    for r0 in range(0, height, size):
        for c0 in range(0, width, size):
            yield r0, c0, min(size, height - r0), min(size, width - c0)


# ------------------------------------------------------------------------- generation
def generate_epoch(site: TwinSite, out: Path, fixed_points: dict | None = None, texture: bool = True) -> dict:
    """Write one epoch: ``out/truth/*`` and ``out/observed/*``; returns its run times.

    ``fixed_points`` (epoch 2) holds the epoch-1 ``targets`` and ``checkpoints`` tables,
    re-surveyed on the eroded surface instead of being drawn again.

    Parameters
    ----------
    site : TwinSite
        The planned site; its parameters hold the epoch keys.
    out : Path
        The epoch's folder.
    fixed_points : dict or None
        See above; None draws the targets and checkpoints.
    texture : bool
        Write ``truth/texture.tif`` (the second tiled pass).

    Returns
    -------
    dict
        Run times (s): ``time_s``, ``terrain_s``, ``texture_s``.
    """
    site.tw.require(EPOCH_KEYS, "generate an epoch")
    t0 = time.perf_counter()
    out = Path(out)
    truth, obs = out / "truth", out / "observed"
    truth.mkdir(parents=True, exist_ok=True)
    obs.mkdir(parents=True, exist_ok=True)
    g = site.grid
    counts = np.zeros(max(lcm.CLASSES) + 1, dtype=np.int64)
    tags = {"epoch": str(site.epoch), "seed": str(site.seed), "generator": "kitegully.twin"}
    prof_f = _profile(g, 1, "float32", float("nan"))
    prof_u = _profile(g, 1, "uint8", 0)
    tiles = list(_tiles(g.height, g.width, site.tw.tile_cells))
    zmin, zmax = np.inf, -np.inf
    with rasterio.open(truth / "dtm.tif", "w", **prof_f) as ddtm, rasterio.open(truth / "dsm.tif", "w", **prof_f) as ddsm, \
            rasterio.open(truth / "landcover.tif", "w", **prof_u) as dlc:
        for i, (r0, c0, h, w) in enumerate(tiles):
            t = compute_tile(site, r0, c0, h, w)
            win = Window(c0, r0, w, h)
            ddtm.write(t.dtm, 1, window=win)
            ddsm.write(t.dsm, 1, window=win)
            dlc.write(t.lc, 1, window=win)
            counts += np.bincount(t.lc.ravel(), minlength=counts.size)
            zmin, zmax = min(zmin, float(t.dtm.min())), max(zmax, float(t.dtm.max()))
            log.info("terrain tile %d/%d done (%.1f s)", i + 1, len(tiles), time.perf_counter() - t0)
        for d, name in ((ddtm, "bare-earth elevation (m)"), (ddsm, "surface elevation (m)"), (dlc, "land-cover code")):
            d.descriptions = (name,)
            d.update_tags(**tags)
    t_terrain = time.perf_counter() - t0
    # --- points on the written rasters
    lc = Raster.read(truth / "landcover.tif").data
    dsm = Raster.read(truth / "dsm.tif").data
    dtm = Raster.read(truth / "dtm.tif").data
    scfg = site.tw.survey
    tcfg = site.tw.targets
    if fixed_points is None:
        gcps = tg.select_gcps(tcfg, lc, dsm, g, site.seed)
        centre = survey.lake_centre(lc, g, site.valley.xy(site.valley.u_dam, site.valley.axis_v(site.valley.u_dam)))
        cps = survey.sample_checkpoints(scfg["checkpoints"], lc, dtm, g, centre, site.seed)
    else:
        gcps = fixed_points["targets"].copy()
        if site.epoch == 2 and site.tw.epoch2:
            gcps, fate = epochs.disturb_targets(gcps, dict(site.tw.epoch2), site.seed, lc, g, list(tcfg["classes"]))
            for _, f in fate.iterrows():
                log.info("epoch 2: target %s %s%s", f["gcp_id"], f["fate"],
                         "" if f["fate"] == "lost" else f" by ({f['dx_m']:.2f}, {f['dy_m']:.2f}) m")
        gcps["z"] = tg.sample_bilinear(dsm, g, gcps["x"].to_numpy(), gcps["y"].to_numpy())
        cps = fixed_points["checkpoints"].copy()
        cps["z"] = tg.sample_bilinear(dtm, g, cps["x"].to_numpy(), cps["y"].to_numpy())
    del dsm, dtm
    ep = f"epoch{site.epoch}"
    write_table(gcps, truth / "targets.csv", markdown=False)
    write_table(cps, truth / "checkpoints.csv", markdown=False)
    rng = rng_for(site.seed, "twin", "rtk", ep)
    write_table(survey.rtk_observe(gcps, "gcp_id", scfg["rtk_sigma_h_m"], scfg["rtk_sigma_v_m"], rng), obs / "gcp_survey.csv", markdown=False)
    write_table(survey.rtk_observe(cps, "id", scfg["rtk_sigma_h_m"], scfg["rtk_sigma_v_m"], rng), obs / "checkpoints.csv", markdown=False)
    # --- texture pass
    t1 = time.perf_counter()
    if texture:
        write_texture(site, truth, gcps, lc)
    t_texture = time.perf_counter() - t1
    # --- vectors and tables
    classes = pd.DataFrame({"code": list(lcm.CLASSES), "name": list(lcm.CLASSES.values())})
    write_table(classes, truth / "landcover_classes.csv", markdown=False)
    gcfg = site.tw.gullies
    cl = centrelines(site.network, gcfg["min_depth_m"], gcfg["reach_length_m"], site.crs)
    write_vector(cl, truth / "gully_centrelines.gpkg")
    write_vector(polygons(site.network, gcfg["min_depth_m"], site.crs), truth / "gully_polygons.gpkg")
    write_vector(heads(site.network, site.crs, site.retreat), truth / "gully_heads.gpkg")
    sv = scfg["field_network"]
    write_vector(survey.field_network(site.network, sv, gcfg["min_depth_m"], site.crs, sub_seed(site.seed, "field", ep),
                                      water=lc == lcm.CODE["water"], grid=g), obs / "field_network.gpkg")
    write_vector(survey.digitised_heads(site.network, scfg["heads_sigma_m"], site.crs, sub_seed(site.seed, "heads", ep),
                                        scfg["heads_visibility"], gcfg["u_shape_exponent"], landcover=lc, grid=g),
                 obs / "gully_heads.gpkg")
    total = time.perf_counter() - t0
    stats = site_statistics(site, cl, counts, (zmin, zmax), len(gcps), len(cps), t_terrain, t_texture, total)
    write_table(stats, truth / "site_statistics.csv")
    log.info("epoch %d written to %s in %.1f s (terrain %.1f s, texture %.1f s)", site.epoch, out, total, t_terrain, t_texture)
    return {"time_s": total, "terrain_s": t_terrain, "texture_s": t_texture}


def write_texture(site: TwinSite, truth: Path, gcps: pd.DataFrame, lc_full: np.ndarray) -> None:
    """Second tiled pass: reflectance texture from the written DTM/DSM and land cover.

    Parameters
    ----------
    site : TwinSite
        The planned site.
    truth : Path
        Folder holding ``dtm.tif`` and ``dsm.tif``; ``texture.tif`` is written there.
    gcps : DataFrame
        GCP targets painted into the texture.
    lc_full : ndarray
        Land-cover codes on the whole DEM grid.
    """
    k = site.tex_factor
    tgrid = site.tex_grid
    prof = _profile(tgrid, 4, "uint8", None)
    prof.pop("nodata", None)
    prof["photometric"] = "MINISBLACK"
    g = site.grid
    size = site.tw.texture_tile_cells
    tiles = list(_tiles(g.height, g.width, size))
    tcfg = epochs.texture_config(dict(site.tw.texture), dict(site.tw.epoch2) if site.epoch == 2 and site.tw.epoch2 else None)
    seed = sub_seed(site.seed, "texture")
    t0 = time.perf_counter()
    with rasterio.open(truth / "dtm.tif") as sdtm, rasterio.open(truth / "dsm.tif") as sdsm, \
            rasterio.open(truth / "texture.tif", "w", **prof) as dst:
        for i, (r0, c0, h, w) in enumerate(tiles):
            dtm_pad = _read_padded(sdtm, r0, c0, h, w)
            dsm_pad = _read_padded(sdsm, r0, c0, h, w)
            phase_pad = compute_phase(site, r0 - 1, c0 - 1, h + 2, w + 2)
            lc = lc_full[r0:r0 + h, c0:c0 + w]
            txs, tys = tgrid.cell_centres(r0 * k, c0 * k, h * k, w * k)
            refl = tx.texture_tile(tcfg, lc, dtm_pad, dsm_pad, phase_pad, g.cell, k, txs - site.valley.cx, tys - site.valley.cy, seed)
            tg.paint_targets(refl, txs, tys, gcps, site.tw.targets)
            dst.write(tx.to_uint8(refl), window=Window(c0 * k, r0 * k, w * k, h * k))
            if (i + 1) % max(1, len(tiles) // 10) == 0:
                log.info("texture tile %d/%d (%.1f s)", i + 1, len(tiles), time.perf_counter() - t0)
        dst.descriptions = tuple(tx.BAND_NAMES)
        dst.update_tags(units="reflectance x 255", epoch=str(site.epoch))


def compute_phase(site: TwinSite, r0: int, c0: int, nrow: int, ncol: int) -> np.ndarray:
    """Furrow phase (m) on a block of the DEM grid (may extend outside the site).

    Parameters
    ----------
    site : TwinSite
        The planned site.
    r0, c0 : int
        First row and column on the DEM grid.
    nrow, ncol : int
        Block size (cells).

    Returns
    -------
    ndarray (nrow, ncol) float64
    """
    g, v = site.grid, site.valley
    xs, ys = g.cell_centres(r0, c0, nrow, ncol)
    u, vp = v.u_vp(xs[None, :], ys[:, None])
    return lcm.furrow_phase(site.fields, lcm.plot_index(v, site.fields, u, vp), u)


def _read_padded(src, r0: int, c0: int, h: int, w: int) -> np.ndarray:
    """Window with a one-cell border, edge cells repeated outside the raster."""
    rr0, cc0 = max(r0 - 1, 0), max(c0 - 1, 0)
    rr1, cc1 = min(r0 + h + 1, src.height), min(c0 + w + 1, src.width)
    a = src.read(1, window=Window(cc0, rr0, cc1 - cc0, rr1 - rr0)).astype(np.float64)
    pad = ((rr0 - (r0 - 1), (r0 + h + 1) - rr1), (cc0 - (c0 - 1), (c0 + w + 1) - cc1))
    return np.pad(a, pad, mode="edge")


# ---------------------------------------------------------------------------- vectors


def site_statistics(site: TwinSite, cl: gpd.GeoDataFrame, counts: np.ndarray, zr: tuple[float, float], n_gcp: int,
                    n_cp: int, t_terrain: float, t_texture: float, total: float) -> pd.DataFrame:
    """Area, gully numbers and lengths, land-cover shares, elevation range, timings.

    Parameters
    ----------
    site : TwinSite
        The planned site.
    cl : GeoDataFrame
        The truth centrelines, as from :func:`centrelines`.
    counts : ndarray
        Cells per land-cover code.
    zr : tuple of float
        Least and greatest DTM elevation (m).
    n_gcp, n_cp : int
        Numbers of GCP targets and checkpoints.
    t_terrain, t_texture, total : float
        Times of the terrain pass, the texture pass and the whole epoch (s).

    Returns
    -------
    DataFrame
        Columns ``quantity, value, unit``.
    """
    g = site.grid
    area = g.width * g.height * g.cell**2
    gul = cl[cl["kind"] != "wadi"] if len(cl) else cl
    rows = [
        ("epoch", site.epoch, "-"),
        ("area", area / 1e6, "km2"),
        ("dem_cells", g.width * g.height, "cells"),
        ("texture_cells", site.tex_grid.width * site.tex_grid.height, "cells"),
        ("elevation_min", zr[0], "m"),
        ("elevation_max", zr[1], "m"),
        ("gullies", int(gul["gully_id"].nunique()) if len(gul) else 0, "count"),
        ("gullies_shallow", int(gul.loc[gul["kind"] == "shallow", "gully_id"].nunique()) if len(gul) else 0, "count"),
        ("gullies_with_headcut", sum(1 for x in site.network if x.headcut), "count"),
        ("gully_length", float(gul["length_m"].sum()) if len(gul) else 0.0, "m"),
        ("wadi_length", float(cl.loc[cl["kind"] == "wadi", "length_m"].sum()) if len(cl) else 0.0, "m"),
        ("gcp_targets", n_gcp, "count"),
        ("checkpoints", n_cp, "count"),
    ]
    total_cells = max(int(counts.sum()), 1)
    for code, name in lcm.CLASSES.items():
        rows.append((f"share_{name}", 100.0 * counts[code] / total_cells, "%"))
    rows += [("time_terrain", t_terrain, "s"), ("time_texture", t_texture, "s"), ("time_total", total, "s")]
    return pd.DataFrame(rows, columns=["quantity", "value", "unit"])


def site_json(site: TwinSite) -> dict:
    """What a planner knows about the area: extent, CRS, cell sizes, rough elevation range."""
    xmin, ymin, xmax, ymax = site.bounds
    step = site.tw.site_json_elevation_step_m
    return {
        "name_hint": "twin",
        "crs": site.crs,
        "extent": {"xmin": xmin, "ymin": ymin, "xmax": xmax, "ymax": ymax},
        "dem_cell_m": site.grid.cell,
        "texture_cell_m": site.tex_grid.cell,
        "approx_elevation_m": {"min": float(np.floor(site.z_trace_range[0] / step) * step),
                               "max": float(np.ceil(site.z_trace_range[1] / step) * step)},
        "epochs": ["epoch1", "epoch2"],
    }


def write_site_json(site: TwinSite, path: Path) -> None:
    """Write :func:`site_json` of ``site`` as indented JSON, creating the parent folder.

    Parameters
    ----------
    site : TwinSite
        The planned site.
    path : Path
        The JSON file.
    """
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(site_json(site), indent=2) + "\n", encoding="utf-8")
