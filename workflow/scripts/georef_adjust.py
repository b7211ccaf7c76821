"""Rule georef_adjust: SfM model + GCP file -> georeferenced model, residual tables, products (thin adapter)."""

import numba

from kitegully.georef import GeorefParams, georeference
from kitegully.logs import setup_script_logging
from kitegully.seeds import rng_for

log = setup_script_logging(snakemake.log[0])
# the bundle's normal-equation kernels run point chunks on the job's threads
numba.set_num_threads(max(1, min(int(snakemake.threads), numba.config.NUMBA_NUM_THREADS)))
out = {k: snakemake.output[k] for k in
       ("model", "transform", "summary", "residuals", "loo", "calibration", "cameras", "cloud", "figure")}
georeference(
    model_dir=snakemake.input.model,
    image_info_json=snakemake.input.image_info,
    gcp_file=snakemake.input.gcp,
    sfm_frame=snakemake.params.sfm_frame,
    params=GeorefParams.from_config(snakemake.params.georef),
    crs=snakemake.params.crs,
    seed=int(rng_for(snakemake.params.seed, "georef").integers(2**31 - 1)),
    out=out,
    attribution=snakemake.params.attribution,
    gcp_source=snakemake.params.gcp_source,
    camera_calibration=snakemake.input.camera or None,  # later epochs: the first epoch's camera (issue 17)
)
