"""Synthetic close-range scenes of eroded patches on a steep grass slope (after Mayr et al. 2016).

Each scene is what 001's terrestrial SfM delivered: a 2 cm RGB orthophoto and DEM of a
30-40 degree grass slope with one main eroded (bare-soil) patch of a few to ~60 m², plus
the truth a careful manual mapper would draw.  What makes the scenes hard is modelled
explicitly, not tuned to any classifier:

* the patch outline is lobed at a few cm (turf torn along its root mat), which the
  manual reference smooths over;
* the patch has sharp scarps on its upslope and lateral edges and a gradual transition
  at its downslope edge: a band where the grass cover thins out into discrete tufts
  with bare soil between them (each 2 cm cell is grass or soil, the share of grass
  cells follows the cover);
* grass clods lie inside the patch (raised, grass-covered), and pioneer plants have
  re-colonised part of the patch floor (succession; sparse green tufts on soil);
* low sun casts shadows from the scarps onto the patch floor, shaded light is bluish;
* grass colour goes from green (July) to senescent brown (September) by a greenness
  value: the share of green tillers, mixed at blade scale with dead ones whose
  reflectance has lost the chlorophyll green peak (R > G > B, close to soil); dry
  blotches and dark gaps between blades; soil has moisture patches and stones;
* white spherical GCP markers (radius 10 cm) stand on the grass;
* the orthophoto is a mosaic of several photos, each with its own exposure and white
  balance (seamlines between Voronoi cells); the camera adds gamma encoding, blur and
  sensor noise, quantised to 8 bit.

The truth mask is the manual mapper's reading of the fuzzy boundary: ``eroded`` where
the smooth vegetation-cover field is below a cover threshold that drifts along the
boundary within ``reference_cover_threshold`` (observer subjectivity at gradual edges,
001 sect. 4); clods count as grass, pioneer plants on the patch floor as eroded.  The
markers are written as a separate truth mask and as an observed marker list (surveyed
centres with RTK noise).

Cost: O(N * K) for N cells, K shadow-ray steps (about depth / tan(sun elevation) / cell).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for


@dataclass
class CloseRangeScene:
    """One generated scene.

    Attributes
    ----------
    name : str
    grid : GridSpec
    rgb : numpy.ndarray
        (3, rows, cols) uint8 orthophoto.
    dem : numpy.ndarray
        float32 DEM (m).
    truth_eroded : numpy.ndarray
        uint8, 1 = eroded (bare), 0 = grass.
    truth_markers : numpy.ndarray
        uint8, 1 = GCP sphere.
    markers : pandas.DataFrame
        Observed marker centres ``gcp_id, x, y, z, radius_m`` (with survey noise).
    meta : dict
        Scene parameters and the reference eroded area (m²).
    """

    name: str
    grid: GridSpec
    rgb: np.ndarray
    dem: np.ndarray
    truth_eroded: np.ndarray
    truth_markers: np.ndarray
    markers: pd.DataFrame
    meta: dict


def scene_rng(seed: int, name: str) -> np.random.Generator:
    """Independent random stream per scene, from the master seed (``kitegully.seeds.rng_for``)."""
    return rng_for(seed, "obia-closerange", name)


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], sigma_cells: float) -> np.ndarray:
    """Gaussian random field with unit SD and correlation length ~ sigma_cells."""
    white = rng.standard_normal(shape)
    if sigma_cells > 0:
        white = ndimage.gaussian_filter(white, sigma_cells, mode="wrap")
    sd = white.std()
    return (white / sd if sd > 0 else white).astype(np.float32)


def _uniform_field(rng: np.random.Generator, shape: tuple[int, int], sigma_cells: float) -> np.ndarray:
    """Spatially correlated field with a uniform marginal on (0, 1) (Gaussian field -> CDF)."""
    from scipy.special import ndtr

    return ndtr(_smooth_noise(rng, shape, sigma_cells)).astype(np.float32)


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _patch_radius(rng: np.random.Generator, area_m2: float, elongation: float, roughness: float):
    """Radial outline r(theta) of a blob with the requested area (m²)."""
    n_harm = 5
    amps = roughness * rng.uniform(0.3, 1.0, n_harm) / np.arange(2, 2 + n_harm)
    phases = rng.uniform(0, 2 * np.pi, n_harm)

    def shape_fn(theta):
        wobble = 1.0 + sum(a * np.cos(k * theta + p) for k, a, p in zip(range(2, 2 + n_harm), amps, phases))
        # elongated along the slope (x, downslope): ellipse radius factor
        ell = 1.0 / np.sqrt((np.cos(theta) / elongation) ** 2 + np.sin(theta) ** 2)
        return wobble * ell

    th = np.linspace(0, 2 * np.pi, 4096, endpoint=False)
    unit_area = 0.5 * np.mean(shape_fn(th) ** 2) * 2 * np.pi
    r0 = np.sqrt(area_m2 / unit_area)
    return lambda theta: r0 * shape_fn(theta), r0


def _cast_shadow(dem: np.ndarray, cell: float, sun_az_deg: float, sun_el_deg: float, max_dist_m: float) -> np.ndarray:
    """Boolean mask of cells in cast shadow (ray marching towards the sun on the DEM)."""
    az = np.radians(sun_az_deg)
    dx, dy = np.sin(az), np.cos(az)  # east, north components towards the sun
    tan_el = np.tan(np.radians(sun_el_deg))
    steps = int(np.ceil(max_dist_m / cell))
    shadow = np.zeros(dem.shape, dtype=bool)
    for k in range(1, steps + 1):
        dist = k * cell
        # rows go south: moving north means a negative row shift
        shifted = ndimage.shift(dem, (dy * k, -dx * k), order=1, mode="nearest", prefilter=False)
        shadow |= shifted > dem + dist * tan_el
    return shadow


@dataclass
class _Frame:
    """Scene coordinates relative to its top-left corner: x east, y north (≤ 0)."""

    n: int  # cells per side
    cell: float
    xs: np.ndarray  # (n,) cell-centre distance east of the left edge (m)
    ys: np.ndarray  # (n,) cell-centre distance south of the top edge (m)
    X: np.ndarray  # (n, n) easting
    Y: np.ndarray  # (n, n) northing relative to the top edge (= -ys)

    @property
    def size(self) -> float:
        return self.n * self.cell

    @classmethod
    def square(cls, side: float, cell: float) -> "_Frame":
        n = int(round(side / cell))
        xs = (np.arange(n) + 0.5) * cell
        ys = (np.arange(n) + 0.5) * cell  # distance south of the top edge
        X, Ys = np.meshgrid(xs, ys)
        return cls(n, cell, xs, ys, X, -Ys)


@dataclass
class _Patch:
    """Vegetation cover of the eroded patch (1 grass, 0 bare) and its clods."""

    v_smooth: np.ndarray  # cover as the mapper generalises it
    v_phys: np.ndarray  # actual cover: torn, lobed turf edge
    clod_mask: np.ndarray


def _scene_side(rng: np.random.Generator, params: dict, area: float):
    """Side of the square scene and the patch outline (``None`` without patch).

    The photographer frames the eroded area and its direct surroundings (001 sect. 3.1):
    square scene = patch reach + a margin each side, at most ``size_m``; ``size_m``
    without patch."""
    side = float(params["size_m"])
    radius_fn, reach = None, 0.0
    if area > 0:
        radius_fn, _r0 = _patch_radius(rng, area, params["patch_elongation"], params["patch_roughness"])
        reach = float(np.max(radius_fn(np.linspace(0, 2 * np.pi, 720))))
        side = min(side, 2.0 * (reach + float(params["aoi_margin_m"])))
    return side, radius_fn, reach


def _terrain(rng: np.random.Generator, params: dict, fr: _Frame) -> tuple[np.ndarray, float]:
    """Plane dipping east (downslope = +x), undulations, micro-roughness; returns (dem, slope °)."""
    n, cell = fr.n, fr.cell
    slope = rng.uniform(*params["slope_deg"])
    tex = params["texture"]
    dem = -np.tan(np.radians(slope)) * fr.X
    dem += tex["undulation_m"] * _smooth_noise(rng, (n, n), tex["undulation_scale_m"] / cell)
    dem += tex["grass_roughness_m"] * _smooth_noise(rng, (n, n), 1.0)
    return dem, slope


def _eroded_patch(rng: np.random.Generator, params: dict, fr: _Frame, dem: np.ndarray, radius_fn, reach: float) -> tuple[np.ndarray, _Patch]:
    """Carve the eroded patch into ``dem``: smooth (truth) and torn (physical) cover, clods."""
    n, cell, size, X, Y, xs, ys = fr.n, fr.cell, fr.size, fr.X, fr.Y, fr.xs, fr.ys
    margin = min(reach + 0.3, size / 2)
    centre = (rng.uniform(margin, size - margin) if size - 2 * margin > 0 else size / 2,
              -(rng.uniform(margin, size - margin) if size - 2 * margin > 0 else size / 2))
    dxp, dyp = X - centre[0], Y - centre[1]
    rho = np.hypot(dxp, dyp)
    theta = np.arctan2(dyp, dxp)
    s = rho - radius_fn(theta)  # signed radial distance, > 0 outside
    # edge width: scarp everywhere except the downslope (east) side, which is gradual
    downslope = np.clip(np.cos(theta), 0.0, 1.0) ** 2
    w = params["scarp_width_m"] + (params["gradual_edge_width_m"] - params["scarp_width_m"]) * downslope
    v_smooth = _smoothstep((s + w / 2) / w)
    # turf tears along its root mat: lobes of a few cm that a manual mapper smooths over
    rag = float(params["edge_raggedness_m"]) * _smooth_noise(rng, (n, n), float(params["edge_raggedness_scale_m"]) / cell)
    v_phys = _smoothstep((s + rag + w / 2) / w)
    # clods of grass inside the patch
    clod_mask = np.zeros((n, n), dtype=bool)
    n_clods = int(rng.integers(params["clods"][0], params["clods"][1] + 1))
    inner = np.argwhere(s < -0.3)
    for _ in range(n_clods if len(inner) else 0):
        cr, cc = inner[rng.integers(len(inner))]
        a_m2 = rng.uniform(*params["clod_area_m2"])
        ax = np.sqrt(a_m2 / np.pi) * rng.uniform(0.7, 1.4)
        ay = a_m2 / (np.pi * ax)
        ang = rng.uniform(0, np.pi)
        u = (X - xs[cc]) * np.cos(ang) + (Y + ys[cr]) * np.sin(ang)
        t = -(X - xs[cc]) * np.sin(ang) + (Y + ys[cr]) * np.cos(ang)
        clod_mask |= (u / ax) ** 2 + (t / ay) ** 2 <= 1.0
    depth = rng.uniform(*params["patch_depth_m"])
    floor_tilt = 0.05 * (X - centre[0])  # floor slightly steeper than the slope [I]
    clod_relief = ndimage.gaussian_filter(clod_mask.astype(np.float64), 1.5)
    dem += -(depth + floor_tilt.clip(-depth * 0.5, depth * 0.5)) * (1.0 - v_phys) + depth * 0.7 * clod_relief * (1 - v_phys)
    v_smooth = np.where(clod_mask, 1.0, v_smooth)
    v_phys = np.where(clod_mask, 1.0, v_phys)
    return dem, _Patch(v_smooth, v_phys, clod_mask)


def _reference(rng: np.random.Generator, params: dict, fr: _Frame, v_smooth: np.ndarray) -> np.ndarray:
    """Manual reference (uint8, 1 = eroded): boundary drawn at a cover level that drifts along the outline."""
    n = fr.n
    c_lo, c_hi = params["reference_cover_threshold"]
    c_ref = 0.5 * (c_lo + c_hi) + 0.5 * (c_hi - c_lo) * np.tanh(_smooth_noise(rng, (n, n), 1.0 / fr.cell))
    return (v_smooth < c_ref).astype(np.uint8)


def _visible_cover(rng: np.random.Generator, params: dict, fr: _Frame, v_phys: np.ndarray, area: float) -> tuple[np.ndarray, float]:
    """Visible cover as discrete tufts, plus pioneer plants on the patch floor; returns (cover, regrowth).

    A cell is grass where the cover exceeds a uniform tuft field, so a band of cover v
    shows grass on a share v of its cells [I]."""
    n, cell = fr.n, fr.cell
    tex = params["texture"]
    tuft_sigma = float(tex["tuft_size_m"]) / cell / 2.0
    soft = float(tex["tuft_edge_softness"])

    def tufts(cover: np.ndarray, sigma: float) -> np.ndarray:
        # u in (soft/2, 1 - soft/2): cover 0 gives no grass, cover 1 full grass
        u = 0.5 * soft + (1.0 - soft) * _uniform_field(rng, (n, n), sigma)
        return _smoothstep((cover - u) / soft + 0.5)

    v_vis = tufts(v_phys, tuft_sigma)
    # pioneer plants on the patch floor: tufts in a share of the bare cells, denser
    # where the patch is older (smooth field at 1 m) [I]
    regrowth = rng.uniform(*params["regrowth_cover"]) if area > 0 else 0.0
    if regrowth > 0:
        density = np.clip(regrowth * 2.0 * _uniform_field(rng, (n, n), 1.0 / cell), 0.0, 1.0)
        v_vis = np.maximum(v_vis, tufts(density, 0.5 * tuft_sigma) * (1.0 - v_phys))
    return v_vis, regrowth


def _place_markers(rng: np.random.Generator, params: dict, fr: _Frame, grid: GridSpec, dem: np.ndarray,
                   v_phys: np.ndarray) -> tuple[np.ndarray, np.ndarray, pd.DataFrame, int]:
    """GCP markers: white spheres on the grass, away from the patch.

    Returns the DEM with the spheres, their mask, the surveyed centres (with survey
    noise; z without the base elevation) and the number placed."""
    n, cell, size, X, Y = fr.n, fr.cell, fr.size, fr.X, fr.Y
    marker_r = float(params["marker_radius_m"])
    truth_markers = np.zeros((n, n), dtype=np.uint8)
    rows = []
    placed = 0
    tries = 0
    while placed < int(params["marker_count"]) and tries < 1000:
        tries += 1
        mx, my = rng.uniform(0.4, size - 0.4), -rng.uniform(0.4, size - 0.4)
        ci, cj = int(-my / cell), int(mx / cell)
        if v_phys[max(ci - 25, 0):ci + 25, max(cj - 25, 0):cj + 25].min() < 0.99:
            continue
        if any(np.hypot(mx - r["_x"], my - r["_y"]) < 1.0 for r in rows):
            continue
        d2 = (X - mx) ** 2 + (Y - my) ** 2
        inside = d2 <= marker_r ** 2
        ground = float(dem[ci, cj])
        cap = np.sqrt(np.clip(marker_r ** 2 - d2, 0.0, None))
        dem = np.where(inside, np.maximum(dem, ground + marker_r + cap), dem)
        truth_markers[inside] = 1
        rows.append({"_x": mx, "_y": my, "z": ground + marker_r})
        placed += 1
    sd = float(params["marker_survey_sd_m"])
    markers = pd.DataFrame(
        {
            "gcp_id": [f"S{i + 1}" for i in range(len(rows))],
            "x": [grid.x0 + r["_x"] + rng.normal(0, sd) for r in rows],
            "y": [grid.y0 + r["_y"] + rng.normal(0, sd) for r in rows],
            "z": [r["z"] + rng.normal(0, sd) for r in rows],
            "radius_m": marker_r,
        }
    )
    return dem, truth_markers, markers, placed


def _reflectance(rng: np.random.Generator, params: dict, scene: dict, fr: _Frame, v_vis: np.ndarray,
                 truth_markers: np.ndarray) -> np.ndarray:
    """Linear reflectance (n, n, 3) in 0..1: grass (greenness, blades, gaps), soil, stones, markers."""
    n = fr.n
    col = params["colours"]
    tex = params["texture"]
    green = np.asarray(col["grass_green"], dtype=np.float64)
    brown = np.asarray(col["grass_brown"], dtype=np.float64)
    g_local = np.clip(
        float(scene["greenness"])
        + tex["greenness_variation"] * _smooth_noise(rng, (n, n), 25.0)
        + tex["greenness_blade_sd"] * _smooth_noise(rng, (n, n), 0.6),
        0.0, 1.0,
    )
    grass = brown[None, None, :] + g_local[..., None] * (green - brown)[None, None, :]
    blade = np.exp(tex["grass_blade_sd"] * _smooth_noise(rng, (n, n), 0.6))
    gap = np.clip(float(params["grass_gap_fraction"]) * (1.0 + _smooth_noise(rng, (n, n), 0.8)), 0.0, 0.9)
    litter = np.asarray(col["litter"], dtype=np.float64)
    grass = (grass * blade[..., None]) * (1 - gap[..., None]) + litter * gap[..., None]
    soil = np.asarray(col["soil"], dtype=np.float64)[None, None, :] * np.exp(tex["soil_moisture_sd"] * _smooth_noise(rng, (n, n), 12.0))[..., None]
    soil *= np.exp(tex["soil_grain_sd"] * _smooth_noise(rng, (n, n), 0.5))[..., None]
    stones = _smooth_noise(rng, (n, n), 1.5) > tex["stone_quantile_z"]
    soil[stones] = np.asarray(col["stone"], dtype=np.float64) * rng.uniform(0.8, 1.2)
    refl = v_vis[..., None] * grass + (1 - v_vis[..., None]) * soil
    refl[truth_markers == 1] = np.asarray(col["marker"], dtype=np.float64)
    return refl


def _irradiance(params: dict, scene: dict, fr: _Frame, dem: np.ndarray, slope: float) -> tuple[np.ndarray, np.ndarray]:
    """Diffuse (bluish sky) + direct sun with cast shadows, relative to the mean plane;
    returns (irradiance (n, n, 3), lit mask). No randomness."""
    cell, size = fr.cell, fr.size
    col = params["colours"]
    el, az = float(scene["sun_elevation_deg"]), float(scene["sun_azimuth_deg"])
    diffuse = float(scene["diffuse_fraction"])
    gy, gx = np.gradient(dem, cell)  # gy along rows (south)
    nx, ny, nz = -gx, gy, np.ones_like(dem)  # upward normal (east, north, up)
    norm = np.sqrt(nx ** 2 + ny ** 2 + nz ** 2)
    sun = np.array([np.sin(np.radians(az)) * np.cos(np.radians(el)), np.cos(np.radians(az)) * np.cos(np.radians(el)), np.sin(np.radians(el))])
    cos_i = np.clip((nx * sun[0] + ny * sun[1] + nz * sun[2]) / norm, 0.0, None)
    plane_n = np.array([np.sin(np.radians(slope)), 0.0, np.cos(np.radians(slope))])
    cos_plane = max(float(plane_n @ sun), 0.05)
    lit = np.ones_like(dem, dtype=bool)
    if diffuse < 1.0:
        relief = float(np.nanmax(dem - ndimage.minimum_filter(dem, size=int(1.0 / cell))))
        max_dist = min(size, (relief + 0.5) / np.tan(np.radians(el)))
        lit = ~_cast_shadow(dem, cell, az, el, max_dist)
    sky = np.asarray(col["sky_tint"], dtype=np.float64)
    sun_tint = np.asarray(col["sun_tint"], dtype=np.float64)
    direct = (1.0 - diffuse) * (cos_i / cos_plane * lit)[..., None] * sun_tint
    return diffuse * sky + direct, lit


def _photograph(rng: np.random.Generator, params: dict, fr: _Frame, radiance: np.ndarray) -> np.ndarray:
    """Camera: mosaic exposure/white balance, blur, exposure, gamma, noise; (3, n, n) uint8."""
    n = fr.n
    cam = params["camera"]
    n_img = int(cam["mosaic_images"])
    if n_img > 1:
        # each Voronoi cell of the mosaic comes from one photo: own exposure and white balance
        pts = rng.uniform(0.0, n, (n_img, 2))
        rr, cc = np.mgrid[0:n, 0:n]
        owner = np.argmin([(rr - pr) ** 2 + (cc - pc) ** 2 for pr, pc in pts], axis=0)
        gains = np.exp(rng.normal(0.0, cam["mosaic_exposure_sd"], (n_img, 1)) + rng.normal(0.0, cam["mosaic_colour_sd"], (n_img, 3)))
        radiance = radiance * gains[owner]
    radiance = ndimage.gaussian_filter(radiance, (cam["blur_sigma_px"], cam["blur_sigma_px"], 0))
    exposure = cam["target_median"] / float(np.median(radiance.mean(axis=-1)))
    encoded = np.clip(radiance * exposure * rng.uniform(0.9, 1.1), 0.0, 1.0) ** (1.0 / cam["gamma"])
    dn = encoded * 255.0 + rng.normal(0.0, cam["noise_dn"], encoded.shape)
    return np.clip(np.round(dn), 0, 255).astype(np.uint8).transpose(2, 0, 1)


def generate_scene(name: str, params: dict, scene: dict, seed: int, crs: str, origin: tuple[float, float]) -> CloseRangeScene:
    """Generate one close-range scene.

    Phases, in the order they draw from the scene's one random stream: framing
    (:func:`_scene_side`), terrain, eroded patch, manual reference, visible cover,
    markers, reflectance, then illumination (no draws) and the photograph.

    Parameters
    ----------
    name
        Scene name (also seeds its random stream).
    params
        Generator parameters shared by the scenes (config ``obia.scenes`` without
        ``list``): ``cell_m, size_m, aoi_margin_m, slope_deg, patch_depth_m, scarp_width_m,
        gradual_edge_width_m, patch_elongation, patch_roughness, clods, clod_area_m2,
        edge_raggedness_m, edge_raggedness_scale_m, regrowth_cover, reference_cover_threshold, marker_count, marker_radius_m,
        marker_survey_sd_m, colours, grass_gap_fraction, texture, camera``.
    scene
        Per-scene values: ``area_m2`` (0 = no eroded patch), ``greenness`` (1 = green
        July grass, 0 = brown September grass), ``sun_elevation_deg``,
        ``sun_azimuth_deg``, ``diffuse_fraction`` (1 = overcast).
    seed
        Master seed of the configuration.
    crs, origin
        Site CRS and the top-left corner (x, y) of the scene.
    """
    rng = scene_rng(seed, name)
    cell = float(params["cell_m"])
    area = float(scene["area_m2"])
    side, radius_fn, reach = _scene_side(rng, params, area)
    fr = _Frame.square(side, cell)
    n = fr.n
    grid = GridSpec(float(origin[0]), float(origin[1]), cell, n, n, crs)
    dem, slope = _terrain(rng, params, fr)
    grass = np.ones((n, n), dtype=np.float64)
    patch = _Patch(grass, grass, np.zeros((n, n), dtype=bool))  # no patch: grass everywhere
    if area > 0:
        dem, patch = _eroded_patch(rng, params, fr, dem, radius_fn, reach)
    truth_eroded = _reference(rng, params, fr, patch.v_smooth)
    v_vis, regrowth = _visible_cover(rng, params, fr, patch.v_phys, area)
    dem, truth_markers, markers, placed = _place_markers(rng, params, fr, grid, dem, patch.v_phys)
    refl = _reflectance(rng, params, scene, fr, v_vis, truth_markers)
    irradiance, lit = _irradiance(params, scene, fr, dem, slope)
    rgb = _photograph(rng, params, fr, refl * irradiance)

    dem_abs = (dem + float(params["base_elevation_m"])).astype(np.float32)
    markers["z"] += float(params["base_elevation_m"])
    diffuse = float(scene["diffuse_fraction"])
    meta = {
        "scene": name,
        "slope_deg": float(slope),
        "area_requested_m2": area,
        "area_ref_m2": float(truth_eroded.sum() * cell * cell),
        "greenness": float(scene["greenness"]),
        "sun_elevation_deg": float(scene["sun_elevation_deg"]),
        "sun_azimuth_deg": float(scene["sun_azimuth_deg"]),
        "diffuse_fraction": diffuse,
        "shadow_fraction": float(1.0 - lit.mean()) if diffuse < 1.0 else 0.0,
        "clod_area_m2": float((patch.clod_mask & (truth_eroded == 0)).sum() * cell * cell),
        "regrowth_cover": float(regrowth),
        "markers": int(placed),
    }
    return CloseRangeScene(name, grid, rgb, dem_abs, truth_eroded, truth_markers, markers, meta)


def scene_names(count: int) -> list[str]:
    """Names ``scene_01 .. scene_NN``."""
    return [f"scene_{i + 1:02d}" for i in range(count)]


def scene_origin(index: int, params: dict) -> tuple[float, float]:
    """Top-left corner of scene ``index`` (0-based): scenes sit side by side along y."""
    x0, y0 = params["origin_xy"]
    return float(x0), float(y0) - index * (float(params["size_m"]) + float(params["spacing_m"]))
