"""Rule obia_kite_accuracy: the kite-scale bare-soil map against the twin's land-cover truth (evaluation rule).

Reference classes and the per-class table: :func:`kitegully.obia.stage.kite_accuracy`.
"""

import pandas as pd

from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.obia import kite_accuracy

log = setup_script_logging(snakemake.log[0])
inp, par, out = snakemake.input, snakemake.params, snakemake.output
bare, grid = read_raster(inp.bare_soil)
acc = kite_accuracy(bare, grid, inp.landcover, pd.read_csv(inp.landcover_classes), inp.landcover_classes,
                    par.bare_classes, par.excluded_classes, par.site)
write_table(acc.accuracy, out.accuracy, floatfmt=".1f")
write_table(acc.areas, out.areas, floatfmt=".1f")
write_table(acc.per_class, out.per_class, floatfmt=".1f")
