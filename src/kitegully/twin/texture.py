"""Surface reflectance of the twin (R, G, B, NIR) at a cell finer than the DEM.

Each land-cover class has a base reflectance (config ``twin.texture.palette``); grass is
mixed between dry and green by ``grass_greenness`` so the Excess Green index
``2g − r − b`` separates grass from bare soil. High-frequency, multi-scale noise is added
to every class so image matching finds features everywhere; ploughed plots get furrow
stripes along their tillage direction; gully walls show marl/sandstone strata; the DSM
is shaded by the sun (``illumination``). Values are reflectance × 255 as uint8.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates

from kitegully.twin.landcover import CLASSES, CODE
from kitegully.twin.noise import fbm_grid

BAND_NAMES = ["red", "green", "blue", "nir"]


def palette(tcfg: dict) -> np.ndarray:
    """Reflectance table (code → R, G, B, NIR), grass mixed by greenness."""
    pal = np.zeros((max(CLASSES) + 1, 4), dtype=np.float32)
    p = tcfg["palette"]
    for code, name in CLASSES.items():
        if name == "grass":
            g = tcfg["grass_greenness"]
            pal[code] = (1 - g) * np.asarray(p["grass_dry"]) + g * np.asarray(p["grass_green"])
        else:
            pal[code] = p[name]
    return pal


def hillshade(z: np.ndarray, cell: float, azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """cos(incidence)/sin(sun elevation): 1 on flat ground; z padded by one cell each side.

    Parameters
    ----------
    z : ndarray (H, W)
        Elevation (m), padded.
    cell : float
        Cell size (m).
    azimuth_deg : float
        Sun azimuth (degrees clockwise from north).
    elevation_deg : float
        Sun elevation (degrees).

    Returns
    -------
    ndarray (H, W)
        Relative illumination (≥ 0) per cell, the padding included.
    """
    dzdy_r, dzdx = np.gradient(z, cell)
    dzdy = -dzdy_r
    az = np.deg2rad(azimuth_deg)
    el = np.deg2rad(elevation_deg)
    sx, sy, sz = np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)
    n = np.sqrt(dzdx**2 + dzdy**2 + 1.0)
    cosi = (-dzdx * sx - dzdy * sy + sz) / n
    return np.clip(cosi, 0.0, None) / sz


def upsample(a_pad: np.ndarray, k: int) -> np.ndarray:
    """Bilinear upsampling by ``k`` of a one-cell-padded array to the texel grid of its core."""
    nr, nc = a_pad.shape[0] - 2, a_pad.shape[1] - 2
    rr = (np.arange(nr * k) + 0.5) / k - 0.5 + 1.0
    cc = (np.arange(nc * k) + 0.5) / k - 0.5 + 1.0
    R, C = np.meshgrid(rr, cc, indexing="ij")
    return map_coordinates(a_pad, [R, C], order=1, mode="nearest")


def texture_tile(tcfg: dict, lc: np.ndarray, dtm_pad: np.ndarray, dsm_pad: np.ndarray, phase_pad: np.ndarray,
                 cell: float, k: int, tx: np.ndarray, ty: np.ndarray, seed: int) -> np.ndarray:
    """Reflectance (4, rows·k, cols·k) float32 in [0, 1] for one tile of the DEM grid.

    ``lc`` is the tile's land cover; ``*_pad`` are DTM, DSM and furrow phase with a
    one-cell border; ``tx, ty`` are the texel-centre coordinates relative to the site
    centre. Complexity O(texels·octaves).

    Parameters
    ----------
    tcfg : mapping
        ``twin.texture``: palette, noise, contrasts, furrow and strata periods, illumination.
    lc : ndarray (rows, cols) uint8
        Land-cover codes of the tile.
    dtm_pad, dsm_pad, phase_pad : ndarray (rows + 2, cols + 2)
        DTM (m), DSM (m) and furrow phase (m) with a one-cell border.
    cell : float
        DEM cell (m).
    k : int
        Texels per DEM cell side.
    tx : ndarray (cols·k,)
        Texel-centre x relative to the site centre (m).
    ty : ndarray (rows·k,)
        Texel-centre y relative to the site centre (m).
    seed : int
        Seed of the noise field.

    Returns
    -------
    ndarray (4, rows·k, cols·k) float32
        Reflectance of R, G, B and NIR.
    """
    lc_up = np.repeat(np.repeat(lc, k, axis=0), k, axis=1)
    pal = palette(tcfg)
    refl = np.moveaxis(pal[lc_up], -1, 0)  # (4, H, W)
    tex_cell = cell / k
    n = tcfg["noise"]
    wl = np.array([n["coarse_wavelength_m"], n["medium_wavelength_m"], n["fine_texels"] * tex_cell, 1.0 * tex_cell * 1.5])
    amp = np.array([n["coarse_amplitude"], n["medium_amplitude"], n["fine_amplitude"], n["grain_amplitude"]])
    noise = fbm_grid(tx, ty, seed, wl, amp).astype(np.float32)
    contrast = np.zeros(max(CLASSES) + 1, dtype=np.float32)
    for code, name in CLASSES.items():
        contrast[code] = tcfg["class_contrast"][name]
    mod = 1.0 + contrast[lc_up] * noise
    ploughed = lc_up == CODE["ploughed"]
    if ploughed.any():
        ph = upsample(phase_pad, k)
        mod = np.where(ploughed, mod * (1.0 + tcfg["furrow_contrast"] * np.sin(2 * np.pi * ph / tcfg["furrow_period_m"])), mod)
    gully = lc_up == CODE["gully"]
    if gully.any():
        z = upsample(dtm_pad, k)
        mod = np.where(gully, mod * (1.0 + tcfg["strata_contrast"] * np.sin(2 * np.pi * z / tcfg["strata_period_m"])), mod)
    ill = tcfg["illumination"]
    hs = upsample(hillshade(dsm_pad, cell, ill["sun_azimuth_deg"], ill["sun_elevation_deg"]), k)
    light = ill["gain"] * (1.0 + ill["shading_strength"] * (hs - 1.0))
    refl = refl * (mod * np.clip(light, ill["min_light"], None)).astype(np.float32)[None]
    return np.clip(refl, 0.0, 1.0)


def to_uint8(refl: np.ndarray) -> np.ndarray:
    """Reflectance [0, 1] → uint8 (× 255, rounded)."""
    return np.round(refl * 255.0).astype(np.uint8)
