"""Rule check_inputs: every input of the site -> report.md/.json and checked GCP/checkpoint copies (thin adapter)."""

from kitegully.inputs import InputSettings, check_site_inputs, write_checkpoint_copy, write_gcp_copy, write_report
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
settings = InputSettings.from_config(snakemake.params.cfg)
found = check_site_inputs(
    settings,
    images_dir=snakemake.input.images,
    gcp_file=snakemake.input.gcp,
    checkpoints=snakemake.input.get("checkpoints"),
)
write_report(found, snakemake.output.json, snakemake.output.report, snakemake.params.site)
found.raise_for_errors()
write_gcp_copy(snakemake.input.gcp, snakemake.output.gcp, settings.gcp_format, settings.z_units)
if "checkpoints" in snakemake.output.keys():
    write_checkpoint_copy(snakemake.input.checkpoints, snakemake.output.checkpoints, settings.z_units)
log.info("inputs accepted: %d warning(s), %d note(s)", len(found.of("warning")), len(found.of("note")))
