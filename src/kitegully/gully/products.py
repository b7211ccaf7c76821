"""The gully map's products on disk: the rasters, vectors and tables of one :func:`map_gullies` run."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from kitegully.gully.pipeline import GullyResult, map_raster
from kitegully.io.raster import GridSpec, write_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import write_vector


def write_map_products(res: GullyResult, valid: np.ndarray, grid: GridSpec, paths: Mapping[str, str]) -> None:
    """Write the products of a :func:`~kitegully.gully.pipeline.map_gullies` run to the rule's outputs.

    Parameters
    ----------
    res : GullyResult
        The mapping run.
    valid : ndarray (H, W) bool
        Cells of the DEM with data; the others are 255 (off the DEM) in both gully maps.
    grid : GridSpec
        Grid of the DEM.
    paths : mapping
        Output paths by name (a Snakemake output list or a dict): ``gully_map``, ``gully_map_whole``
        (uint8 rasters, :func:`~kitegully.gully.pipeline.map_raster`), ``network``, ``mapped_network``,
        ``polygons`` (GeoPackages), ``network_cells`` (the network's cells, ``.npz``), ``patches`` (CSV) and,
        where the digitised heads' network alone is kept (``gully.heads: both``), ``mapped_network_digitised``.
    """
    write_raster(paths["gully_map"], map_raster(res.gully, valid), grid, nodata=255)
    write_raster(paths["gully_map_whole"], map_raster(res.gully_whole_patches, valid), grid, nodata=255)
    write_vector(res.lines, paths["network"], layer="gully_network")
    write_vector(res.extracted_lines, paths["mapped_network"], layer="gully_network_mapped")
    if "mapped_network_digitised" in paths.keys():  # the paper's procedure, scored beside the combined network
        write_vector(res.given_extracted_lines, paths["mapped_network_digitised"], layer="gully_network_mapped")
    write_vector(res.polygons, paths["polygons"], layer="gully_polygons")
    res.network.save(paths["network_cells"])
    write_table(res.patch_table, paths["patches"], markdown=False)
