"""Rule sfm_reconstruct: prepared images -> pycolmap model + summary.json (thin adapter)."""

from kitegully.logs import setup_script_logging
from kitegully.seeds import rng_for
from kitegully.sfm import SfmParams, reconstruct_model

log = setup_script_logging(snakemake.log[0])
seed = int(rng_for(snakemake.params.seed, "sfm").integers(2**31 - 1))
reconstruct_model(
    images_dir=snakemake.input.images,
    work_dir=snakemake.output.work,
    model_dir=snakemake.output.model,
    summary_json=snakemake.output.summary,
    images_csv=snakemake.output.images_csv,
    image_info_json=snakemake.output.image_info,
    params=SfmParams.from_config(snakemake.params.sfm),
    seed=seed,
    threads=snakemake.threads,
    camera_log=snakemake.input.camera_log[0] if snakemake.input.camera_log else None,
    crs=snakemake.params.crs,
)
