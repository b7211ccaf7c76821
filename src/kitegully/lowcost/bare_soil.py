"""Bare-soil maps of the low-cost mosaics by the obia stage's kite-scale OBIA, with NDVI and with ExG (rule ``lowcost_bare_soil``)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.config import config_section
from kitegully.io.raster import Raster, read_raster
from kitegully.io.tables import write_table

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BareSoilParams:
    """The ``lowcost.bare_soil`` section: the obia stage's kite-scale map on the mosaics.

    Attributes
    ----------
    tile_cells : int
        Tile side of the segmentation (cells) [I] 1024: the 2 cm mosaic of the strip is two tiles.
    min_reflectance : float
        Mosaic cells darker than this in every visible band are no data for both maps [I]
        0.01: no lit natural ground (dark water included, 3-6 %) reflects under 1 % in all
        visible bands, so such cells are unlit or beyond the imaged ground (the twin's
        strip ends in black); their chromatic coordinates, and so ExG, are noise.
    obia : ObiaParams
        The obia stage's method keys (``features`` ... ``classification``, checked by
        :meth:`kitegully.obia.scene.ObiaParams.from_config`); Mayr et al.'s 2 cm settings
        [P 001] suit the 2 cm mosaics. ``classification.index: ndvi`` is this site's choice
        (a NIR band exists); the ExG map of the RGB camera alone is made beside it with
        the same keys.
    """

    tile_cells: int
    obia: Any
    min_reflectance: float

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "BareSoilParams":
        """Build from ``lowcost.bare_soil`` (``obia`` checked by ``ObiaParams``); raises InputError naming a bad key."""
        from kitegully.obia.scene import ObiaParams
        config_section(cfg, "lowcost.bare_soil", ["tile_cells", "min_reflectance", "obia"])
        p = ObiaParams.from_config(cfg["obia"])
        if int(cfg["tile_cells"]) < 4 * p.seed_bandwidth_cells:
            raise InputError(f"lowcost.bare_soil.tile_cells: must be at least 4 seed band widths "
                             f"({4 * p.seed_bandwidth_cells} cells), got {cfg['tile_cells']!r}")
        if not 0 <= float(cfg["min_reflectance"]) < 1:
            raise InputError(f"lowcost.bare_soil.min_reflectance: must lie in [0, 1), got {cfg['min_reflectance']!r}")
        return cls(int(cfg["tile_cells"]), p, float(cfg["min_reflectance"]))


def map_bare_soil(rgb_path: str | Path, nir_path: str | Path, dsm_path: str | Path, cfg: Mapping[str, Any],
                  out_dir: str | Path) -> pd.DataFrame:
    """Bare-soil maps of the mosaics by the obia stage's kite-scale OBIA, with each index.

    ``bare_soil_ndvi.tif``: the configured parameters with ``index: ndvi`` (segmentation on
    R, G, B, NIR and slope; NDVI of the NIR camera's and the RGB camera's red channels);
    ``bare_soil_exg.tif``: the same parameters on the RGB mosaic alone with ``index: exg``
    (what an RGB-only team maps; no water mask, ExG cannot see water). Thresholds come from
    each index's own histogram (valley, Otsu alongside), never from the truth. Cells darker
    than ``min_reflectance`` in R, G and B are no data in both. Writes
    ``bare_soil_thresholds.csv`` and returns it. Cost: two OBIA runs, O(N log N) in cells.

    Parameters
    ----------
    rgb_path : path
        White-balanced RGB mosaic (3 bands, reflectance).
    nir_path : path
        NIR mosaic on the same grid.
    dsm_path : path
        DSM of the survey.
    cfg : mapping
        The ``lowcost.bare_soil`` section (:class:`BareSoilParams`).
    out_dir : path
        Output folder, created if missing.

    Returns
    -------
    DataFrame
        One row per index (ndvi, exg): thresholds, water, dark and mapped cells, bare share
        and seconds.
    """
    import tempfile

    p = BareSoilParams.from_config(cfg)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    nd = p.obia if p.obia.index == "ndvi" else replace(p.obia, index="ndvi")
    rgb = Raster.read(rgb_path, band=None)
    if rgb.data.ndim != 3 or rgb.data.shape[0] < 3:
        raise InputError(f"{rgb_path}: RGB mosaic needs 3 bands, has shape {rgb.data.shape}")
    dark = np.all(rgb.data < p.min_reflectance, axis=0)
    rows = []
    with tempfile.TemporaryDirectory(dir=out) as tmp:
        masked = Path(tmp) / "rgb_orthomosaic_lit.tif"
        rgb.with_data(np.where(dark[None], np.nan, rgb.data[:3]).astype(np.float32)).write(masked, band_names=["red", "green", "blue"])
        runs = {"ndvi": (nd, nir_path), "exg": (replace(p.obia, index="exg", water_ndvi_below=None), None)}
        for name, (params, nir) in runs.items():
            rows.append(_bare_soil_run(name, masked, dsm_path, out, params, p.tile_cells, nir, int(dark.sum())))
    tab = pd.DataFrame(rows)
    write_table(tab, out / "bare_soil_thresholds.csv")
    return tab


def _bare_soil_run(name: str, rgb_path: Path, dsm_path: str | Path, out: Path, params, tile_cells: int,
                   nir: str | Path | None, dark_cells: int) -> dict:
    """One OBIA map (:func:`map_bare_soil`) and its row of ``bare_soil_thresholds.csv``."""
    from kitegully.obia.kite import bare_soil_map

    t0 = time.perf_counter()
    path = out / f"bare_soil_{name}.tif"
    thr = bare_soil_map(rgb_path, dsm_path, path, params, tile_cells, nir_path=nir)
    cls, _ = read_raster(path)
    mapped = cls != 255
    row = {"index": name, **thr.as_dict(), "water_cells": thr.water_cells or 0, "dark_cells": dark_cells,
           "mapped_cells": int(mapped.sum()), "bare_share": float(np.mean(cls[mapped] == 1)) if mapped.any() else np.nan,
           "seconds": time.perf_counter() - t0}
    log.info("bare soil by %s: valley %s, Otsu %s, bare share %.3f", name, thr.valley, thr.otsu, row["bare_share"])
    return row
