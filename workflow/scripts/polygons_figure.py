"""Rule polygons_figure: TCI and dams, polygons by threshold over the hillshade, sections along one gully (Figs 8-11)."""

import pandas as pd

from kitegully.io.raster import Raster
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging
from kitegully.polygons.plots import polygon_map

log = setup_script_logging(snakemake.log[0])
inp, par = snakemake.input, snakemake.params
dem = Raster.read(inp.dem)
tci = Raster.read(inp.tci)
polys = {t: read_vector(p) for t, p in zip(par.thresholds, inp.polygons)}
polygon_map(dem.data, dem.grid, tci.data, par.tci_threshold, polys, read_vector(inp.thalweg), read_vector(inp.transects),
            read_vector(inp.axes), read_vector(inp.sections), pd.read_csv(inp.morphometry), snakemake.output.figure,
            max_px=par.max_px, attribution=par.attribution)
