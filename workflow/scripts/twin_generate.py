"""Rules twin_epoch1/twin_epoch2: generate one epoch of the twin (truth + observed)."""

from pathlib import Path

import numba
import pandas as pd

from kitegully.logs import setup_script_logging
from kitegully.twin import TwinParams, build_site, generate_epoch

log = setup_script_logging(snakemake.log[0])
numba.set_num_threads(max(1, min(snakemake.threads, numba.config.NUMBA_NUM_THREADS)))
epoch = int(snakemake.params.epoch)
out_dir = Path(snakemake.output.truth_dtm_tif).parent.parent
fixed = None
if epoch == 2:
    fixed = {"targets": pd.read_csv(snakemake.input.targets), "checkpoints": pd.read_csv(snakemake.input.checkpoints)}
site = build_site(TwinParams.from_config(snakemake.params.twin), snakemake.params.crs, snakemake.params.seed, epoch=epoch)
timing = generate_epoch(site, out_dir, fixed_points=fixed)
missing = [p for p in snakemake.output if not Path(p).exists()]
if missing:
    raise RuntimeError(f"twin generator did not write: {', '.join(missing)}")
log.info("epoch %d generated in %.1f s", epoch, timing["time_s"])
